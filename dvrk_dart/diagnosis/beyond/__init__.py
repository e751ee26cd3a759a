"""What is fitted beyond the selected effects: J3's terms, the pitch-angle loads, the one configuration, the refit."""

"""Payloads: the point and first-moment models, their intervals, their reports."""

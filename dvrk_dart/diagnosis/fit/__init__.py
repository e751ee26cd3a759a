"""The problem (runs by role, design, Gram blocks), the selection and the re-simulation."""

"""The validations on withheld real data and on blind synthetic runs (make validate)."""

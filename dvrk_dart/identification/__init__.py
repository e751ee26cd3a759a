"""Identification of the PSM's dynamic parameters from measured runs
(`dvrk-dart identify`): `regressor` (from the identified model's Pinocchio
tree), `base` (numerical base parameters), `fit` (weighted least squares and
the physically consistent convex program), `identify` (the steps), `outputs`
(params.json, params_covariance.json -- its format is documented there --,
identification.json and .html, the validation report's section)."""

"""The pre-sliding distance of each joint's friction, chosen on the training runs.

With `--friction-law presliding` (the default) every friction link's Coulomb
column follows Dahl's state over a pre-sliding distance (model/friction.py)
instead of sign(v). The distance enters the model non-linearly, so it is not
one more column of the least squares: each link's distance is picked from the
candidates of the bounds file (`[presliding]`, 0 = sign among them) by the
training runs' residual of the weighted fit, one link after the other. The
held-out runs play no part.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dvrk_dart.metrics import rms


@dataclass(frozen=True)
class PreslidingCandidates:
    """Candidate distances (from the bounds file): rad for revolute links, m for prismatic."""

    revolute_rad: tuple[float, ...] = ()
    prismatic_m: tuple[float, ...] = ()

    def of(self, link) -> tuple[float, ...]:
        """The candidates of a link (by its joint's type)."""
        return self.prismatic_m if link.joint_type == "prismatic" else self.revolute_rad


def with_link_column(run, regressor, key: int, law):
    """`run` with the Coulomb column of link `key` recomputed under `law` (in the run's band)."""
    p = run.processed
    coeffs = regressor.model.links[key].variable.coeffs
    column = np.outer(law.reversal(p.dq @ coeffs, p.q @ coeffs, key), coeffs)
    Y = run.Y.copy()
    Y[:, :, regressor.layout.index(f"link{key}.Fc")] = p.in_band(column)
    return replace(run, Y=Y, Y_sign=run.Y if run.Y_sign is None else run.Y_sign)


def choose_distances(train: list, regressor, base, joints: np.ndarray, candidates: PreslidingCandidates, fit) -> tuple[list, object, dict]:
    """(train runs with the chosen columns, the chosen law, a record per link).
    `fit(runs)` -> WeightedFit on the base parameters; the score is the sum over
    the fitted joints of the squared training residual relative to the sign law's."""
    def residual(runs) -> np.ndarray:
        beta = fit(runs).beta
        errors = [rms(run.processed.tau - run.Y[:, :, base.independent] @ beta) for run in runs]
        return rms(errors)[joints]

    law = regressor.friction_law
    reference = residual(train)
    record = {}
    for key in regressor.layout.friction_links:
        link = regressor.model.links[key]
        scores = {}
        for distance in (0.0, *candidates.of(link)):
            trial_law = law.with_distance(key, distance)
            trial = [with_link_column(run, regressor, key, trial_law) for run in train]
            scores[distance] = float(np.sum(np.square(residual(trial) / reference)))
        best = min(scores, key=scores.get)
        law = law.with_distance(key, best)
        train = [with_link_column(run, regressor, key, law) for run in train]
        record[str(key)] = {"distance": best, "unit": "m" if link.joint_type == "prismatic" else "rad",
                            "score_by_distance": {f"{d:g}": s for d, s in scores.items()}}
    return train, law, record

"""What a joint-effort gap means at the instrument: sensorless force estimation.

The external force at the instrument point that the efforts imply is

    F = J(q)^-T (tau_measured - tau_model)

over the joints that position the point (the arm's model card,
`[force_point]`: the PSM's wrist centre from q1..q3, the MTM's handle), per
sample, in the base frame; J is the point's positional Jacobian (central
differences of the model card's forward kinematics). In free motion the true
force is zero and F is the model's *phantom* force: what a force-feedback
loop would render, or a contact detector would have to tolerate.

Near the remote centre of motion the lateral directions have a short lever:
a direction whose singular value of J is below the card's `min_lever_m` is
not determined; the sample's base-frame components are then reported as not
determined (NaN), and `determined` keeps the part along the directions that
are (for the PSM: along the shaft)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.metrics import rms
from dvrk_dart.model.description import ForcePoint, PsmModel

#: central-difference step of the Jacobian (rad, m): its error (~h^2) is far below the residuals' noise
JACOBIAN_STEP = 1e-6
PERCENTILE = 95.0


def force_point_of(model: PsmModel) -> ForcePoint:
    if model.force_point is None:
        raise DvrkDartError(f"{model.source}: the arm's model card has no [force_point]: no instrument point to estimate a force at")
    return model.force_point


def point_positions(model: PsmModel, q: np.ndarray, link: int) -> np.ndarray:
    """(N, 3) base-frame origin of `link`'s frame at each configuration (N, 7)."""
    chain = []
    key = link
    while key != 0:
        chain.append(model.links[key])
        key = model.links[key].parent
    frames = np.broadcast_to(np.eye(4), (len(q), 4, 4))
    for frame in reversed(chain):
        frames = frames @ frame.transforms(q)
    return frames[:, :3, 3]


def positional_jacobian(model: PsmModel, q: np.ndarray, point: ForcePoint) -> np.ndarray:
    """(N, 3, k): d(point position)/d(q_j) for the point's k joints."""
    q = np.asarray(q, dtype=float)
    columns = []
    for j in point.joints:
        step = np.zeros(q.shape[1])
        step[j] = JACOBIAN_STEP
        columns.append((point_positions(model, q + step, point.link) - point_positions(model, q - step, point.link)) / (2 * JACOBIAN_STEP))
    return np.stack(columns, axis=2)


@dataclass(frozen=True)
class ForceEstimate:
    """Per sample: the force (N, 3), NaN where a direction is not determined;
    the determined part (N, 3); the smallest lever arm (N,) in m."""

    force: np.ndarray
    determined: np.ndarray
    lever_m: np.ndarray

    def summary(self) -> dict:
        """RMS of |F|, its 95th percentile and the per-axis RMS over the samples where F is determined."""
        known = np.all(np.isfinite(self.force), axis=1)
        norm = np.linalg.norm(self.force[known], axis=1)
        return {
            "rms_n": float(rms(norm)) if known.any() else None,
            "p95_n": float(np.percentile(norm, PERCENTILE)) if known.any() else None,
            "rms_per_axis_n": rms(self.force[known]).tolist() if known.any() else None,
            "determined_fraction": float(known.mean()),
            "determined_part_rms_n": float(rms(np.linalg.norm(self.determined, axis=1))),
        }


def estimate_force(model: PsmModel, q: np.ndarray, effort_gap: np.ndarray) -> ForceEstimate:
    """F = J^-T tau over the force point's joints; `effort_gap` (N, 7): measured - model."""
    point = force_point_of(model)
    J = positional_jacobian(model, q, point)  # (N, 3, k)
    tau = np.asarray(effort_gap, dtype=float)[:, list(point.joints)]
    U, sigma, Vt = np.linalg.svd(J)  # J = U S V^T; J^T F = tau  ->  F = U S^-1 V^T tau
    along = np.einsum("nij,nj->ni", Vt, tau)[:, : sigma.shape[1]] / sigma
    known = sigma >= point.min_lever_m
    determined = np.einsum("nij,nj->ni", U[:, :, : sigma.shape[1]], np.where(known, along, 0.0))
    force = np.where(np.all(known, axis=1)[:, None], determined, np.nan)
    return ForceEstimate(force, determined, sigma.min(axis=1))

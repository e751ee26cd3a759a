"""The effects' regressors in one design, per-block normal equations, and the bounded least-squares fit."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.linalg
import scipy.optimize

from dvrk_dart.diagnosis.effects.effect import Effect
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.first_moment import YAW_PATH_JOINT
from dvrk_dart.model.joints import N_JOINTS

#: block length for the folds and the bootstrap (s): much longer than the
#: filtered signals' correlation time (~0.05 s), short enough for ~28 blocks a run
BLOCK_DURATION_S = 1.0
#: a longer run's blocks lengthen to keep this many: the folds and the bootstrap
#: need tens of blocks, and each holds 7 P^2 numbers (7 MB on the PSM), which
#: grew a diagnosis by 21 MB per second of recording (6.3 GB for 207 s)
MAX_BLOCKS_PER_RUN = 64
#: Occam prior of a payload: a mass m costs this fraction of the training
#: residual energy per kg^2. Far below what a real payload explains (0.1 kg:
#: 1e-4), it only chooses among explanations the data cannot tell apart: on a
#: link turning about a fixed axis gravity sees m c, not m, and the lightest
#: payload at the farthest point of the link is preferred to a heavy one near
#: the axis.
PAYLOAD_MASS_PRIOR_PER_KG2 = 0.01
#: relative Tikhonov term on the scaled normal equations: regressors of
#: different effects can be nearly collinear on a short trajectory
RIDGE_RELATIVE = 1e-9


class Design:
    """Column layout of all candidate effects in one regressor."""

    def __init__(self, effects: Sequence[Effect], every_effect_a_change: bool = False):
        """every_effect_a_change: the runs are compared with a baseline of
        their own motion only, so any effect (not only a payload) may be what
        the runs have and the baseline has not."""
        self.effects = list(effects)
        self.every_effect_a_change = every_effect_a_change
        self.slices = []
        start = 0
        for e in self.effects:
            self.slices.append(slice(start, start + e.n_columns))
            start += e.n_columns
        self.n_columns = start

    def columns(self, features: TrajectoryFeatures) -> np.ndarray:
        return np.concatenate([e.columns(features) for e in self.effects], axis=2)

    def is_withheld(self, effect: Effect) -> bool:
        """Whether an effect is under study: in the runs, absent from their baseline."""
        return self.every_effect_a_change or effect.kind in WITHHELD_KINDS

    @property
    def withheld(self) -> np.ndarray:
        """Column mask of the effects under study (`is_withheld`): absent from
        a baseline run, not cancelled by subtracting one."""
        mask = np.zeros(self.n_columns, dtype=bool)
        for e, sl in zip(self.effects, self.slices):
            mask[sl] = self.is_withheld(e)
        return mask

    def run_columns(self, role: str, features: TrajectoryFeatures, baseline_features: TrajectoryFeatures | None = None,
                    yaw_path: bool = True) -> np.ndarray:
        """(N, 7, P) columns of a run by its role (`runs.DiagnosisRun.role`): a
        run minus its baseline sample by sample has the shared effects'
        columns minus the baseline's; a baseline run has no withheld effect.
        yaw_path=False: the withheld effects' J1 rows (a payload's own J1 path,
        `first_moment`) are zero in this run."""
        Phi = self.columns(features)
        if role == "difference":  # RunRole.DIFFERENCE (a str enum)
            shared = ~self.withheld
            Phi[:, :, shared] -= self.columns(baseline_features)[:, :, shared]
        elif role == "baseline":  # RunRole.BASELINE
            Phi[:, :, self.withheld] = 0.0
        if not yaw_path:
            Phi[:, YAW_PATH_JOINT, self.withheld] = 0.0
        return Phi

    def index(self, chosen: Sequence[int]) -> np.ndarray:
        return np.concatenate([np.arange(self.slices[i].start, self.slices[i].stop) for i in chosen]) if chosen else np.zeros(0, int)


#: effect kinds under study when a baseline is given and runs of other motions
#: are fitted with it (the other effects are then the errors all runs share)
WITHHELD_KINDS = ("payload", "payload_at_position")


@dataclass
class Grams:
    """Per-block, per-joint normal equations of one or several runs."""

    A: np.ndarray  # (n_blocks, 7, P, P)
    g: np.ndarray  # (n_blocks, 7, P)
    s: np.ndarray  # (n_blocks, 7) squared residual before
    n: np.ndarray  # (n_blocks,) samples
    fold: np.ndarray  # (n_blocks,) fold index
    #: (n_blocks, 7) periodic processing: the residual's noise energy one fitted direction absorbs (None: upstream)
    noise: np.ndarray | None = None

    @staticmethod
    def of_run(design: Design, features: TrajectoryFeatures, residual: np.ndarray, folds: int, demean: np.ndarray | None = None,
               Phi: np.ndarray | None = None) -> "Grams":
        """demean: per joint, whether a constant is a nuisance term of this run;
        it is projected out of the residual and of every column on those joints
        (Frisch-Waugh-Lovell: the same fit as with the run's own offsets as free
        parameters)."""
        Phi = design.columns(features) if Phi is None else Phi  # (N, 7, P)
        P = design.n_columns
        column_means = np.zeros((N_JOINTS, P))
        if demean is not None:  # block by block below: a demeaned copy of every column costs as much as the columns
            mask = np.asarray(demean, dtype=float)
            column_means = mask[:, None] * Phi.mean(axis=0)
            residual = residual - mask * residual.mean(axis=0)
        block = max(1, int(round(BLOCK_DURATION_S * features.sample_rate_hz)))
        n_blocks = min(MAX_BLOCKS_PER_RUN, max(1, len(residual) // block))
        edges = np.linspace(0, len(residual), n_blocks + 1).astype(int)
        A = np.empty((n_blocks, N_JOINTS, P, P))
        g = np.empty((n_blocks, N_JOINTS, P))
        s = np.empty((n_blocks, N_JOINTS))
        for b in range(n_blocks):
            sl = slice(edges[b], edges[b + 1])
            X = (Phi[sl] - column_means if demean is not None else Phi[sl]).transpose(1, 0, 2)  # (7, n, P)
            A[b] = np.matmul(X.transpose(0, 2, 1), X)
            g[b] = np.einsum("jnp,nj->jp", X, residual[sl])
            s[b] = np.sum(residual[sl] ** 2, axis=0)
        fold = (np.arange(n_blocks) * min(folds, n_blocks)) // n_blocks
        return Grams(A, g, s, np.diff(edges), fold)

    def scale_in_place(self, weight: np.ndarray) -> None:
        """Joint j's rows weighted by weight[j] (squared residual units), in place: a copy of A is A's size again."""
        w = np.asarray(weight, dtype=float)
        self.A *= w[None, :, None, None]
        self.g *= w[None, :, None]
        self.s *= w[None, :]
        if self.noise is not None:
            self.noise *= w[None, :]

    @staticmethod
    def concat(parts: list["Grams"]) -> "Grams":
        if len(parts) == 1:
            return parts[0]
        noise = None if any(p.noise is None for p in parts) else np.concatenate([p.noise for p in parts])
        return Grams(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("A", "g", "s", "n", "fold")), noise)


@dataclass
class Fit:
    params: dict[int, np.ndarray]  # effect index -> physical parameters
    beta: np.ndarray  # (P,) regression coefficients, zero outside the chosen effects


class Fitter:
    """Bounded weighted least squares of a set of effects on Gram matrices."""

    def __init__(self, design: Design):
        self.design = design

    def fit(self, chosen: Sequence[int], A: np.ndarray, g: np.ndarray, warm: dict[int, np.ndarray] | None = None, energy: float = 0.0,
            linearize: bool = False) -> Fit:
        """Minimise beta^T A beta - 2 beta^T g (+ the payload mass prior, scaled by
        `energy`, the weighted residual energy before) within the bounds.

        linearize: homogeneous effects (`Effect.homogeneous`) are fitted
        linearly, their coefficients' Jacobian frozen at the warm start or the
        unconstrained solution's first guess (a selection's trial: adding one
        effect to a fitted payload barely turns it)."""
        design = self.design
        beta_full = np.zeros(design.n_columns)
        if not chosen:
            return Fit({}, beta_full)
        idx = design.index(chosen)
        A_S, g_S = A[np.ix_(idx, idx)], g[idx]
        d = np.sqrt(np.clip(np.diag(A_S), 0.0, None))
        d[d == 0.0] = 1.0
        As = A_S / np.outer(d, d) + RIDGE_RELATIVE * np.eye(len(idx))
        L = scipy.linalg.cholesky(As, lower=True)
        y = scipy.linalg.solve_triangular(L, g_S / d, lower=True)
        M = L.T  # ||M b - y||^2 + const in the scaled coefficients b = d * beta
        effects = [design.effects[i] for i in chosen]
        local = []
        start = 0
        for e in effects:
            local.append(slice(start, start + e.n_columns))
            start += e.n_columns
        if all(e.linear for e in effects):
            lb = np.concatenate([e.lower for e in effects]) * d
            ub = np.concatenate([e.upper for e in effects]) * d
            # the Occam prior of a payload: energy * prior * (beta / scale)^2 (linear: beta = p)
            weights, keep = _prior_weights(effects, energy)
            if keep.any():
                M = np.vstack([M, np.diag(weights / d)[keep]])
                y = np.concatenate([y, np.zeros(int(keep.sum()))])
            sol = scipy.optimize.lsq_linear(M, y, bounds=(lb, ub), method="bvls" if len(idx) <= 60 else "trf")
            beta = sol.x / d
            params = {i: beta[sl].copy() for i, sl in zip(chosen, local)}
        elif linearize and all(e.linear or e.homogeneous for e in effects):
            params = self._fit_frozen(chosen, effects, local, M, y, d, warm or {}, energy)
            beta = np.concatenate([e.coefficients(params[i]) for i, e in zip(chosen, effects)])
        else:
            params = self._fit_nonlinear(chosen, effects, local, M, y, d, warm or {}, energy)
            beta = np.concatenate([e.coefficients(params[i]) for i, e in zip(chosen, effects)])
        beta_full[idx] = beta
        return Fit(params, beta_full)

    def _fit_frozen(self, chosen, effects, local, M, y, d, warm, energy) -> dict[int, np.ndarray]:
        """Bounded linear least squares in the parameters, beta = T p with T the
        coefficients' Jacobian at the warm start, else at the unconstrained
        linear solution's first guess (the identity for a linear effect)."""
        linear = None if all(i in warm or e.linear for i, e in zip(chosen, effects)) else np.linalg.lstsq(M, y, rcond=None)[0] / d
        at = {i: warm[i] if i in warm else e.initial_guesses(linear[sl])[0] for i, e, sl in zip(chosen, effects, local) if not e.linear}
        T = scipy.linalg.block_diag(*[np.eye(e.n_columns) if e.linear else e.coefficients_jacobian(at[i]) for i, e in zip(chosen, effects)])
        K = M @ (d[:, None] * T)
        scale = np.linalg.norm(K, axis=0)
        scale[scale == 0.0] = 1.0
        lower, upper = (np.concatenate([getattr(e, side) for e in effects]) * scale for side in ("lower", "upper"))
        weights, keep = _prior_weights(effects, energy)
        prior = np.diag(weights / scale)[keep]
        sol = scipy.optimize.lsq_linear(np.vstack([K / scale, prior]), np.concatenate([y, np.zeros(int(keep.sum()))]),
                                        bounds=(lower, upper), method="bvls" if len(scale) <= 60 else "trf")
        p, start, params = sol.x / scale, 0, {}
        for i, e in zip(chosen, effects):
            params[i] = p[start:start + e.n_parameters].copy()
            start += e.n_parameters
        return params

    def _fit_nonlinear(self, chosen, effects, local, M, y, d, warm, energy) -> dict[int, np.ndarray]:
        lower = np.concatenate([e.lower for e in effects])
        upper = np.concatenate([e.upper for e in effects])
        p_slices, start = [], 0
        for e in effects:
            p_slices.append(slice(start, start + e.n_parameters))
            start += e.n_parameters

        def beta_of(p):
            return np.concatenate([e.coefficients(p[ps]) for e, ps in zip(effects, p_slices)])

        weights, keep = _prior_weights(effects, energy)
        P = np.diag(weights)[keep]

        def residual(p):
            return np.concatenate([M @ (d * beta_of(p)) - y, P @ p])

        def jacobian(p):
            J = np.zeros((len(d), len(p)))  # block diagonal (scipy's block_diag costs more than the fit here)
            for e, ps, sl in zip(effects, p_slices, local):
                J[sl, ps] = e.coefficients_jacobian(p[ps])
            return np.vstack([M @ (d[:, None] * J), P])

        # starting points: the unconstrained linear solution, read by each effect
        linear = np.linalg.lstsq(M, y, rcond=None)[0] / d
        per_effect_starts = []
        for i, e, sl in zip(chosen, effects, local):
            starts = [warm[i]] if i in warm else e.initial_guesses(linear[sl])
            per_effect_starts.append([np.clip(s, e.lower, e.upper) for s in starts])
        n_starts = max(len(s) for s in per_effect_starts)
        best = None
        for k in range(n_starts):
            x0 = np.concatenate([s[min(k, len(s) - 1)] for s in per_effect_starts])
            sol = scipy.optimize.least_squares(residual, x0, jac=jacobian, bounds=(lower, upper), method="trf", x_scale="jac")
            if best is None or sol.cost < best.cost:
                best = sol
        return {i: best.x[ps].copy() for i, ps in zip(chosen, p_slices)}


def _prior_weights(effects: Sequence[Effect], energy: float) -> tuple[np.ndarray, np.ndarray]:
    """The Occam prior per parameter (`prior_scales`; linear effects: per
    coefficient): its rows weigh p by sqrt(prior * energy) / scale; and which
    parameters have one."""
    scales = np.concatenate([getattr(e, "prior_scales", np.full(e.n_parameters, np.inf)) for e in effects])
    keep = np.isfinite(scales)
    return math.sqrt(PAYLOAD_MASS_PRIOR_PER_KG2 * max(energy, 0.0)) / np.where(keep, scales, 1.0) * keep, keep


def sse(beta: np.ndarray, A: np.ndarray, g: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Squared residual after subtracting Y beta, from Grams (..., P, P), (..., P), (...)."""
    nz = np.flatnonzero(beta)
    if len(nz) == 0:
        return s.copy()
    b = beta[nz]
    quad = (A[..., nz[:, None], nz[None, :]] @ b) @ b
    return np.maximum(s - 2.0 * g[..., nz] @ b + quad, 0.0)


def weighted_fraction(after: np.ndarray, before: np.ndarray, w2: np.ndarray) -> float:
    """Explained fraction of the weighted squared residual (arrays (..., 7))."""
    total = np.sum(before * w2)
    return float(1.0 - np.sum(after * w2) / total) if total > 0 else 0.0


def per_joint_fraction(after: np.ndarray, before: np.ndarray) -> list[float]:
    a, b = after.reshape(-1, N_JOINTS).sum(0), before.reshape(-1, N_JOINTS).sum(0)
    return [float(1.0 - x / y) if y > 0 else 0.0 for x, y in zip(a, b)]

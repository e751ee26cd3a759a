"""Diagnosis of the sim-to-real gap: where the simulation departs from the real
robot, which unmodelled physical effect explains it, and how much of the gap
closes once the effect is put into the simulation, judged on held-out data.

Residual r = measured - simulated effort, per joint (with a baseline run of
the same trajectory and session but without the effect under study:
r = (measured - simulated) - (baseline measured - baseline simulated), which
cancels the day-to-day effects and isolates the withheld one).

Selection (`diagnose`):
- every candidate effect of `effects.candidate_effects` is a regressor
  Y(q, dq, ddq) beta(p) with physical bounds on p;
- the training residual is cut into blocks of BLOCK_DURATION_S; per block and
  joint the Gram matrices Y^T Y, Y^T r, r^T r of all candidates are stored, so
  any fit and any held-out error is a small matrix computation;
- a fit minimises the weighted squared residual over the joints (weight
  1 / RMS of the joint's residual before, so that N and N·m and large and small
  joints count alike), with bounded least squares;
- the score of a set of effects is its explained fraction on held-out time
  segments (CV_FOLDS contiguous folds: fit on the others, score on the fold),
  with a block bootstrap over the held-out blocks for its uncertainty;
- greedy forward selection adds the effect with the best held-out score (or a
  simpler one, fewer parameters, not significantly worse) while the gain is at
  least MIN_HELDOUT_GAIN and positive with bootstrap confidence, refusing a
  candidate that makes a selected effect unstable across folds (collinear);
  at most one effect of a family is selected (a joint's friction with a sharp
  or a smooth reversal); a payload is chosen only if it beats, significantly,
  the offsets of the joints it moves fitted together (its static part), else
  those offsets are the step's choice;
- payloads on links whose efforts are identical (a family, see
  `effects.equivalent_payload_links`) are one hypothesis over the union of
  their envelopes: the member kept is the one with the lowest penalised
  training cost, and the mass interval is profiled over the whole family;
  `holdout` runs are never used for the selection, only scored.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd
import scipy.linalg
import scipy.optimize

from dvrk_dart.diagnosis.effects import (
    Effect,
    PointPayload,
    TrajectoryFeatures,
    candidate_effects,
    config_effort_by_formula,
    effects_to_sim_config,
    not_simulated,
    unsimulated_effort,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import ProcessedRun, process, zero_phase_lowpass
from dvrk_dart.metrics import rms
from dvrk_dart.model.arm import Arm, load_arm
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS, effort_unit
from dvrk_dart.sim.config import SimConfig

#: block length for the folds and the bootstrap (s): much longer than the
#: filtered signals' correlation time (~0.05 s), short enough for ~28 blocks a run
BLOCK_DURATION_S = 1.0
#: contiguous folds of the held-out scoring: a fold of a 28 s run is ~1 base
#: period (5.6 s) of the excitation, so each fold holds a full trajectory cycle
CV_FOLDS = 5
#: bootstrap resamples of the held-out blocks (interval of explained fractions)
BOOTSTRAP_RESAMPLES = 400
BOOTSTRAP_SEED = 20190802
#: central interval reported for explained fractions
INTERVAL_QUANTILES = (0.05, 0.95)
#: an effect is added only if it explains at least this fraction more of the
#: held-out (weighted) squared residual ...
MIN_HELDOUT_GAIN = 0.005
#: ... and its gain is positive in all but this fraction of bootstrap resamples
GAIN_FAILURE_QUANTILE = 0.05
#: an effect is not separable from the others when its fitted effort varies
#: from fold to fold by more than this fraction of its size (weighted norm);
#: a candidate that makes an already selected effect that unstable is refused
#: (e.g. a J2 stiffness trading off against a payload's lever arm)
STABILITY_LIMIT = 0.5
#: Occam prior of a payload: a mass m costs this fraction of the training
#: residual energy per kg^2. Far below what a real payload explains (0.1 kg:
#: 1e-4), it only chooses among explanations the data cannot tell apart: on a
#: link turning about a fixed axis gravity sees m c, not m, and the lightest
#: payload at the farthest point of the link is preferred to a heavy one near
#: the axis.
PAYLOAD_MASS_PRIOR_PER_KG2 = 0.01
#: a payload's mass counts as identified when its interval's ends are within
#: this ratio (1.3 / 0.77: within +-30 % of the interval's geometric middle)
MASS_IDENTIFIED_RATIO = 1.7
#: masses tried when profiling a selected payload's mass (kg, geometric grid)
PROFILE_MASSES_KG = tuple(float(m) for m in np.geomspace(0.01, 2.0, 24))
#: safety bound of the greedy selection
MAX_SELECTED_EFFECTS = 25
#: joint weights are 1 / max(residual RMS, this): a joint whose residual is
#: below the effort resolution (N·m or N) must not dominate the fit
EFFORT_WEIGHT_FLOOR = 1e-3
#: relative Tikhonov term on the scaled normal equations: regressors of
#: different effects can be nearly collinear on a short trajectory
RIDGE_RELATIVE = 1e-9
#: |dq| below this fraction of the run's largest |dq| counts as "near zero"
NEAR_ZERO_VELOCITY_FRACTION = 0.05
#: quantile bins of the acceleration and pose regimes (terciles)
REGIME_QUANTILES = (1 / 3, 2 / 3)
#: samples plotted per figure at most (thinned evenly): scatter plots of 6000
#: points say no more than 3000 and take twice as long
MAX_PLOTTED_SAMPLES = 3000

Simulate = Callable[[SimConfig, ProcessedRun], np.ndarray]
"""simulate(config, run) -> (N, 7) simulated efforts at the run's samples (DART replay)."""


# ------------------------------------------------------------------- the runs
@dataclass
class DiagnosisRun:
    """A measured run with the simulated efforts at its samples, and optionally
    the baseline run of the same trajectory without the effect under study."""

    name: str
    state: ProcessedRun
    simulated: np.ndarray
    baseline: "DiagnosisRun | None" = None

    def __post_init__(self):
        self.simulated = np.asarray(self.simulated, dtype=float)
        if self.simulated.shape != self.state.tau.shape:
            raise DvrkDartError(f"{self.name}: simulated efforts {self.simulated.shape} do not match the measured {self.state.tau.shape}")
        if self.baseline is not None and len(self.baseline.state) != len(self.state):
            raise DvrkDartError(f"{self.name}: baseline {self.baseline.name} has {len(self.baseline.state)} samples, not {len(self.state)}")

    def __len__(self) -> int:
        return len(self.state)

    @property
    def gap(self) -> np.ndarray:
        """measured - simulated (N, 7)."""
        return self.state.tau - self.simulated

    @property
    def residual(self) -> np.ndarray:
        """The residual to explain: the gap, minus the baseline's gap if any."""
        return self.gap if self.baseline is None else self.gap - self.baseline.gap


RunSpec = "str | Path | ProcessedRun | DiagnosisRun"


def _load_state(spec) -> tuple[str, ProcessedRun]:
    if isinstance(spec, ProcessedRun):
        return "run", spec
    path = resolve_run(spec)
    return Path(path).stem, process(load_run(path))


def simulated_efforts(arm: Arm, state: ProcessedRun, simulate: Simulate | None, config: SimConfig) -> np.ndarray:
    """Simulated efforts at the measured samples: the DART replay when given,
    else the identified model evaluated at the measured state as a stand-in
    (the replay reproduces it to < 0.01 N·m with `config`'s physics)."""
    if simulate is not None:
        return np.asarray(simulate(config, state), dtype=float)
    return config_effort_by_formula(arm, config, state.q, state.dq, state.ddq)


def prepare_run(spec, arm: Arm, simulate: Simulate | None = None, base_config: SimConfig = SimConfig(), baseline=None, name: str | None = None) -> DiagnosisRun:
    """A DiagnosisRun from a run name ('two'), a path, a ProcessedRun or a DiagnosisRun."""
    if isinstance(spec, DiagnosisRun):
        run = spec
    else:
        label, state = _load_state(spec)
        run = DiagnosisRun(name or label, state, simulated_efforts(arm, state, simulate, base_config))
    if baseline is not None:
        run = DiagnosisRun(run.name, run.state, run.simulated, prepare_run(baseline, arm, simulate, base_config))
    return run


def _features(arm: Arm, run: DiagnosisRun) -> TrajectoryFeatures:
    s = run.state
    return TrajectoryFeatures(arm, s.q, s.dq, s.ddq, run.simulated, sample_rate_hz())


# --------------------------------------------------------------------- where
def residual_regimes(state: ProcessedRun, residual: np.ndarray) -> pd.DataFrame:
    """Residual statistics per joint and motion regime (tidy: one row per
    joint, regime and bin): velocity sign / near zero, acceleration level,
    insertion depth q3 and pitch angle q2."""
    rows = []
    q3, q2 = state.q[:, JOINT_NAMES.index("q3")], state.q[:, JOINT_NAMES.index("q2")]

    def tercile_bins(values: np.ndarray, labels: tuple[str, str, str]) -> list[tuple[str, np.ndarray, float, float]]:
        edges = np.quantile(values, REGIME_QUANTILES)
        masks = [values <= edges[0], (values > edges[0]) & (values <= edges[1]), values > edges[1]]
        bounds = [(values.min(), edges[0]), (edges[0], edges[1]), (edges[1], values.max())]
        return [(lab, m, lo, hi) for lab, m, (lo, hi) in zip(labels, masks, bounds)]

    pose_bins = {
        "insertion_depth_q3": tercile_bins(q3, ("shallow", "middle", "deep")),
        "pitch_q2": tercile_bins(q2, ("low", "middle", "high")),
    }
    for j, joint in enumerate(JOINT_NAMES):
        v, a, r = state.dq[:, j], state.ddq[:, j], residual[:, j]
        near = NEAR_ZERO_VELOCITY_FRACTION * np.max(np.abs(v))
        regimes = {
            "velocity": [
                ("negative", v < -near, -np.inf, -near),
                ("near_zero", np.abs(v) <= near, -near, near),
                ("positive", v > near, near, np.inf),
            ],
            "acceleration": tercile_bins(np.abs(a), ("low", "medium", "high")),
            **pose_bins,
        }
        for regime, bins in regimes.items():
            for label, mask, lo, hi in bins:
                x = r[mask]
                rows.append(
                    {
                        "joint": joint,
                        "unit": effort_unit(joint),
                        "regime": regime,
                        "bin": label,
                        "bin_lower": float(lo),
                        "bin_upper": float(hi),
                        "samples": int(mask.sum()),
                        "mean": float(x.mean()) if len(x) else math.nan,
                        "std": float(x.std()) if len(x) else math.nan,
                        "rms": float(np.sqrt(np.mean(x**2))) if len(x) else math.nan,
                    }
                )
    return pd.DataFrame(rows)


def plot_residuals(state: ProcessedRun, residual: np.ndarray, folder: Path | str, label: str = "residual") -> list[Path]:
    """One figure per joint: the residual against q, dq and ddq of that joint."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dvrk_dart.io.atomic import atomic_path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    keep = np.linspace(0, len(state) - 1, min(len(state), MAX_PLOTTED_SAMPLES)).astype(int)
    paths = []
    for j, joint in enumerate(JOINT_NAMES):
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharey=True)
        pu = "m" if effort_unit(joint) == "N" else "rad"
        for ax, x, xlabel in zip(axes, (state.q, state.dq, state.ddq), (f"{joint} ({pu})", f"d{joint} ({pu}/s)", f"dd{joint} ({pu}/s²)")):
            ax.scatter(x[keep, j], residual[keep, j], s=2, alpha=0.4, c=state.dq[keep, j] > 0, cmap="coolwarm")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_xlabel(xlabel)
        axes[0].set_ylabel(f"{label} ({effort_unit(joint)})")
        fig.suptitle(f"{label} of {joint} (colour: velocity sign)")
        fig.tight_layout()
        target = folder / f"{label}_{joint}.png"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format="png", dpi=90)
        plt.close(fig)
        paths.append(target)
    return paths


# ------------------------------------------------------------- design matrix
class _Design:
    """Column layout of all candidate effects in one regressor."""

    def __init__(self, effects: Sequence[Effect]):
        self.effects = list(effects)
        self.slices = []
        start = 0
        for e in self.effects:
            self.slices.append(slice(start, start + e.n_columns))
            start += e.n_columns
        self.n_columns = start

    def columns(self, features: TrajectoryFeatures) -> np.ndarray:
        return np.concatenate([e.columns(features) for e in self.effects], axis=2)

    def index(self, chosen: Sequence[int]) -> np.ndarray:
        return np.concatenate([np.arange(self.slices[i].start, self.slices[i].stop) for i in chosen]) if chosen else np.zeros(0, int)


@dataclass
class _Grams:
    """Per-block, per-joint normal equations of one or several runs."""

    A: np.ndarray  # (n_blocks, 7, P, P)
    g: np.ndarray  # (n_blocks, 7, P)
    s: np.ndarray  # (n_blocks, 7) squared residual before
    n: np.ndarray  # (n_blocks,) samples
    fold: np.ndarray  # (n_blocks,) fold index

    @staticmethod
    def of_run(design: _Design, features: TrajectoryFeatures, residual: np.ndarray, folds: int) -> "_Grams":
        Phi = design.columns(features)  # (N, 7, P)
        block = max(1, int(round(BLOCK_DURATION_S * features.sample_rate_hz)))
        n_blocks = max(1, len(residual) // block)
        edges = np.linspace(0, len(residual), n_blocks + 1).astype(int)
        P = design.n_columns
        A = np.empty((n_blocks, N_JOINTS, P, P))
        g = np.empty((n_blocks, N_JOINTS, P))
        s = np.empty((n_blocks, N_JOINTS))
        for b in range(n_blocks):
            sl = slice(edges[b], edges[b + 1])
            X = Phi[sl].transpose(1, 0, 2)  # (7, n, P)
            A[b] = np.matmul(X.transpose(0, 2, 1), X)
            g[b] = np.einsum("jnp,nj->jp", X, residual[sl])
            s[b] = np.sum(residual[sl] ** 2, axis=0)
        fold = (np.arange(n_blocks) * min(folds, n_blocks)) // n_blocks
        return _Grams(A, g, s, np.diff(edges), fold)

    @staticmethod
    def concat(parts: list["_Grams"]) -> "_Grams":
        return _Grams(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("A", "g", "s", "n", "fold")))


@dataclass
class _Fit:
    params: dict[int, np.ndarray]  # effect index -> physical parameters
    beta: np.ndarray  # (P,) regression coefficients, zero outside the chosen effects


class _Fitter:
    """Bounded weighted least squares of a set of effects on Gram matrices."""

    def __init__(self, design: _Design):
        self.design = design

    def fit(self, chosen: Sequence[int], A: np.ndarray, g: np.ndarray, warm: dict[int, np.ndarray] | None = None, energy: float = 0.0) -> _Fit:
        """Minimise beta^T A beta - 2 beta^T g (+ the payload mass prior, scaled by
        `energy`, the weighted residual energy before) within the bounds."""
        design = self.design
        beta_full = np.zeros(design.n_columns)
        if not chosen:
            return _Fit({}, beta_full)
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
            sol = scipy.optimize.lsq_linear(M, y, bounds=(lb, ub), method="bvls" if len(idx) <= 60 else "trf")
            beta = sol.x / d
            params = {i: beta[sl].copy() for i, sl in zip(chosen, local)}
        else:
            params = self._fit_nonlinear(chosen, effects, local, M, y, d, warm or {}, energy)
            beta = np.concatenate([e.coefficients(params[i]) for i, e in zip(chosen, effects)])
        beta_full[idx] = beta
        return _Fit(params, beta_full)

    def _fit_nonlinear(self, chosen, effects, local, M, y, d, warm, energy) -> dict[int, np.ndarray]:
        lower = np.concatenate([e.lower for e in effects])
        upper = np.concatenate([e.upper for e in effects])
        p_slices, start = [], 0
        for e in effects:
            p_slices.append(slice(start, start + e.n_parameters))
            start += e.n_parameters

        def beta_of(p):
            return np.concatenate([e.coefficients(p[ps]) for e, ps in zip(effects, p_slices)])

        # mass prior rows: sqrt(prior * energy) * m for every payload
        mass_index = [ps.start for e, ps in zip(effects, p_slices) if isinstance(e, PointPayload)]
        prior = math.sqrt(PAYLOAD_MASS_PRIOR_PER_KG2 * max(energy, 0.0))
        P = np.zeros((len(mass_index), len(lower)))
        P[np.arange(len(mass_index)), mass_index] = prior

        def residual(p):
            return np.concatenate([M @ (d * beta_of(p)) - y, P @ p])

        def jacobian(p):
            J = scipy.linalg.block_diag(*[e.coefficients_jacobian(p[ps]) for e, ps in zip(effects, p_slices)])
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


def _sse(beta: np.ndarray, A: np.ndarray, g: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Squared residual after subtracting Y beta, from Grams (..., P, P), (..., P), (...)."""
    nz = np.flatnonzero(beta)
    if len(nz) == 0:
        return s.copy()
    b = beta[nz]
    quad = np.einsum("...pq,p,q->...", A[..., nz[:, None], nz[None, :]], b, b)
    return np.maximum(s - 2.0 * g[..., nz] @ b + quad, 0.0)


def _fraction(after: np.ndarray, before: np.ndarray, w2: np.ndarray) -> float:
    """Explained fraction of the weighted squared residual (arrays (..., 7))."""
    total = np.sum(before * w2)
    return float(1.0 - np.sum(after * w2) / total) if total > 0 else 0.0


def _per_joint_fraction(after: np.ndarray, before: np.ndarray) -> list[float]:
    a, b = after.reshape(-1, N_JOINTS).sum(0), before.reshape(-1, N_JOINTS).sum(0)
    return [float(1.0 - x / y) if y > 0 else 0.0 for x, y in zip(a, b)]


@dataclass
class _CvResult:
    after: np.ndarray  # (n_blocks, 7) held-out squared residual per block
    fraction: float
    fold_params: list[dict[int, np.ndarray]]


class _Selector:
    """Cross-validated scores, bootstrap intervals and greedy forward selection."""

    def __init__(self, design: _Design, train: _Grams, w2: np.ndarray, folds: int):
        self.design, self.train, self.w2 = design, train, w2
        self.fitter = _Fitter(design)
        self.folds = sorted(set(train.fold.tolist()))
        Aw = np.einsum("bjpq,j->bpq", train.A, w2)
        gw = np.einsum("bjp,j->bp", train.g, w2)
        self.A_total, self.g_total = Aw.sum(0), gw.sum(0)
        sw = train.s @ w2
        self.energy_total = float(sw.sum())
        self.energy_fold = {f: float(sw[train.fold == f].sum()) for f in self.folds}
        self.A_fold = {f: Aw[train.fold == f].sum(0) for f in self.folds}
        self.g_fold = {f: gw[train.fold == f].sum(0) for f in self.folds}
        rng = np.random.default_rng(BOOTSTRAP_SEED)
        n = len(train.s)
        self.resamples = rng.integers(0, n, size=(BOOTSTRAP_RESAMPLES, n))

    def fit_all(self, chosen, warm=None) -> _Fit:
        return self.fitter.fit(chosen, self.A_total, self.g_total, warm, self.energy_total)

    def cross_validate(self, chosen: list[int], warm: list[dict[int, np.ndarray]] | None = None) -> _CvResult:
        after = self.train.s.copy()
        fold_params = []
        for k, f in enumerate(self.folds):
            if len(self.folds) == 1:  # no held-out fold: in-sample
                fit = self.fit_all(chosen, warm[k] if warm else None)
                after = _sse(fit.beta, self.train.A, self.train.g, self.train.s)
                fold_params.append(fit.params)
                break
            fit = self.fitter.fit(
                chosen, self.A_total - self.A_fold[f], self.g_total - self.g_fold[f], warm[k] if warm else None, self.energy_total - self.energy_fold[f]
            )
            held = self.train.fold == f
            after[held] = _sse(fit.beta, self.train.A[held], self.train.g[held], self.train.s[held])
            fold_params.append(fit.params)
        return _CvResult(after, _fraction(after, self.train.s, self.w2), fold_params)

    def bootstrap_fractions(self, after: np.ndarray) -> np.ndarray:
        num = np.einsum("bj,j->b", after, self.w2)[self.resamples].sum(1)
        den = np.einsum("bj,j->b", self.train.s, self.w2)[self.resamples].sum(1)
        return 1.0 - num / den

    def interval(self, after: np.ndarray) -> list[float]:
        return np.quantile(self.bootstrap_fractions(after), INTERVAL_QUANTILES).tolist()

    def _index(self, name: str) -> int:
        return next(i for i, e in enumerate(self.design.effects) if e.name == name)

    def instability(self, effect: int, result: _CvResult) -> float:
        """Fold-to-fold spread of an effect's fitted effort relative to its size."""
        sl = self.design.slices[effect]
        e = self.design.effects[effect]
        betas = np.array([e.coefficients(p[effect]) for p in result.fold_params if effect in p])
        if len(betas) < 2:
            return 0.0
        A = self.A_total[sl, sl]
        mean = betas.mean(0)
        size = float(mean @ A @ mean)
        spread = float(np.mean([(b - mean) @ A @ (b - mean) for b in betas]))
        return math.sqrt(spread / size) if size > 0 else 0.0

    def _stable(self, selected: list[int], candidate: int, trial: _CvResult, current: _CvResult) -> bool:
        for i in selected:
            before = self.instability(i, current)
            if self.instability(i, trial) > max(STABILITY_LIMIT, before):
                return False
        return True

    def _parsimonious(self, trials: dict[int, _CvResult]) -> int:
        """The best-scoring candidate, unless one with fewer parameters is not
        significantly worse (bootstrap): then the simplest of those (an offset
        before a payload that mimics it over a small range of motion)."""
        best = max(trials, key=lambda i: trials[i].fraction)
        best_boot = self.bootstrap_fractions(trials[best].after)
        n_par = lambda i: self.design.effects[i].n_parameters
        rivals = []
        for i, t in trials.items():
            if n_par(i) < n_par(best) and t.fraction > 0.0:
                worse = best_boot - self.bootstrap_fractions(t.after)
                if np.mean(worse <= 0.0) > GAIN_FAILURE_QUANTILE:
                    rivals.append(i)
        if not rivals:
            return best
        fewest = min(n_par(i) for i in rivals)
        return max((i for i in rivals if n_par(i) == fewest), key=lambda i: trials[i].fraction)

    def greedy(self, max_effects: int) -> tuple[list[int], list[dict], dict[int, _CvResult], _CvResult]:
        n = len(self.design.effects)
        individual: dict[int, _CvResult] = {}
        selected: list[int] = []
        current = _CvResult(self.train.s.copy(), 0.0, [{} for _ in self.folds])
        steps = []
        while len(selected) < min(max_effects, n):
            trials = {}
            families = {self.design.effects[i].family for i in selected}
            for i in range(n):
                if i in selected or self.design.effects[i].family in families:
                    continue
                warm = [dict(p) for p in current.fold_params]
                trials[i] = self.cross_validate(selected + [i], warm)
                if not selected:
                    individual[i] = trials[i]
            self._last_trials = trials
            admissible = {i: t for i, t in trials.items() if self._stable(selected, i, t, current)}
            refused = [self.design.effects[i].name for i in trials if i not in admissible and trials[i].fraction > current.fraction]
            if not admissible:
                break
            best = self._parsimonious(admissible)
            added, trial, instead_of = [best], trials[best], None
            rival = self._offset_rival(selected, best, families, current)
            if rival is not None:
                added, trial, instead_of = rival[0], rival[1], self.design.effects[best].name
            gain = trial.fraction - current.fraction
            gains = self.bootstrap_fractions(trial.after) - self.bootstrap_fractions(current.after)
            failure = float(np.mean(gains <= 0.0))
            step = {
                "effect": " + ".join(self.design.effects[i].name for i in added),
                "effects": [self.design.effects[i].name for i in added],
                "instead_of": instead_of,
                "cross_validated_fraction": trial.fraction,
                "gain": gain,
                "gain_interval": np.quantile(gains, INTERVAL_QUANTILES).tolist(),
                "gain_not_positive_probability": failure,
                "refused_as_not_separable": [n for n in refused if trials[self._index(n)].fraction > trials[best].fraction],
            }
            if gain < MIN_HELDOUT_GAIN or failure > GAIN_FAILURE_QUANTILE:
                step["accepted"] = False
                steps.append(step)
                break
            step["accepted"] = True
            steps.append(step)
            selected.extend(added)
            current = trial
        return selected, steps, individual, current

    def _offset_rival(self, selected: list[int], best: int, families: set, current: _CvResult) -> tuple[list[int], _CvResult] | None:
        """Occam's rule for a payload: its static part is an offset on every
        joint it moves; the payload is chosen only if it explains the held-out
        residual significantly better than those offsets fitted together
        (fewer parameters). Else the offsets are the step's choice (e.g. on
        trajectory 'one' a 0.6 kg "payload" on the pitch link pinned at its
        envelope boundary only mimicked the J1 and J2 offsets)."""
        effect = self.design.effects[best]
        if not isinstance(effect, PointPayload):
            return None
        by_name = {e.name: i for i, e in enumerate(self.design.effects)}
        rival = [by_name[f"offset_{j}"] for j in effect.joints if f"offset_{j}" in by_name]
        rival = [i for i in rival if i not in selected and self.design.effects[i].family not in families]
        if not rival or sum(self.design.effects[i].n_parameters for i in rival) >= effect.n_parameters:
            return None
        trial = self.cross_validate(selected + rival, [dict(p) for p in current.fold_params])
        if trial.fraction <= current.fraction:
            return None
        payload_boot = self.bootstrap_fractions(self._last_trials[best].after) if best in self._last_trials else None
        if payload_boot is None:
            return None
        better = payload_boot - self.bootstrap_fractions(trial.after)
        if np.mean(better <= 0.0) > GAIN_FAILURE_QUANTILE:  # the payload is not significantly better
            return rival, trial
        return None


# ------------------------------------------------------------------ diagnose
def _gaps(residuals: list[np.ndarray]) -> list[float] | None:
    if not residuals:
        return None
    return rms(np.vstack(residuals)).tolist()


def _weights(residual: np.ndarray) -> np.ndarray:
    sigma = np.maximum(rms(residual), EFFORT_WEIGHT_FLOOR)
    return 1.0 / sigma**2


def _penalised_cost(selector: "_Selector", chosen: list[int], fit: _Fit) -> float:
    """Weighted training squared residual (up to a constant) plus the payloads' Occam prior."""
    masses = [fit.params[i][0] for i in chosen if isinstance(selector.design.effects[i], PointPayload)]
    prior = PAYLOAD_MASS_PRIOR_PER_KG2 * selector.energy_total
    A, g = selector.A_total, selector.g_total
    return float(fit.beta @ A @ fit.beta - 2 * fit.beta @ g + prior * np.sum(np.square(masses)))


def _best_fit(selector: "_Selector", chosen: list[int], cv: "_CvResult | None" = None) -> _Fit:
    """Fit on all training data from the effects' own starting points and from
    the folds' mean parameters; keep the better (nonlinear fits have local minima)."""
    candidates = [selector.fit_all(chosen)]
    folds = [p for p in cv.fold_params if all(i in p for i in chosen)] if cv is not None else []
    if folds and chosen:
        warm = {i: np.mean([p[i] for p in folds], axis=0) for i in chosen}
        candidates.append(selector.fit_all(chosen, warm))
    return min(candidates, key=lambda fit: _penalised_cost(selector, chosen, fit))


def _family_members(selector: "_Selector", payload: int) -> list[int]:
    family = selector.design.effects[payload].family
    return [j for j, e in enumerate(selector.design.effects) if isinstance(e, PointPayload) and e.family == family]


def _swap(chosen: list[int], old: int, new: int) -> list[int]:
    return [new if i == old else i for i in chosen]


def _choose_within_families(selector: "_Selector", selected: list[int], cv: "_CvResult") -> tuple[list[int], _Fit, "_CvResult"]:
    """A payload family (links the efforts cannot tell apart) is one hypothesis
    over the union of its links' envelopes: its member is the one with the
    lowest penalised cost, the Occam prior deciding as it does within one link,
    not the held-out score, whose differences among members are noise."""
    final, swapped = _best_fit(selector, selected, cv), False
    for payload in [i for i in selected if isinstance(selector.design.effects[i], PointPayload)]:
        for member in _family_members(selector, payload):
            if member in selected:
                continue
            trial = _swap(selected, payload, member)
            fit = _best_fit(selector, trial)
            if _penalised_cost(selector, trial, fit) < _penalised_cost(selector, selected, final):
                selected, final, payload, swapped = trial, fit, member, True
    return selected, final, (selector.cross_validate(selected) if swapped else cv)


def _mass_profile(selector: "_Selector", chosen: list[int], payload: int) -> dict:
    """Cross-validated score of the selected set with the payload's mass fixed
    on a grid (its position free in the envelopes of its family's links): where
    the score stays within the bootstrap spread of the best, the data cannot
    tell the masses apart (for a link turning about a fixed axis, gravity only
    sees m c; m alone comes from the weak inertial terms)."""
    best_scores: dict[float, _CvResult] = {}
    for member in _family_members(selector, payload):
        members_set = _swap(chosen, payload, member)
        fit = _best_fit(selector, members_set)
        effect = selector.design.effects[member]
        original = effect.parameters
        try:
            for m in PROFILE_MASSES_KG:
                if m > original[0].upper:
                    break
                effect.parameters = (replace(original[0], lower=m * (1 - 1e-9), upper=m),) + original[1:]
                warm = [{i: (np.r_[m, fit.params[i][1:]] if i == member else fit.params[i]) for i in members_set} for _ in selector.folds]
                score = selector.cross_validate(members_set, warm)
                if m not in best_scores or score.fraction > best_scores[m].fraction:
                    best_scores[m] = score
        finally:
            effect.parameters = original
    masses = sorted(best_scores)
    fractions = np.array([best_scores[m].fraction for m in masses])
    k = int(np.argmax(fractions))
    spread = float(np.std(selector.bootstrap_fractions(best_scores[masses[k]].after)))
    inside = [m for m, f in zip(masses, fractions) if f >= fractions[k] - spread]
    lo, hi = min(inside), max(inside)
    return {
        "masses_kg": masses,
        "cross_validated_fraction": fractions.tolist(),
        "bootstrap_spread": spread,
        "mass_interval_kg": [lo, hi],
        "identifiable": bool(lo > masses[0] and hi < masses[-1] and hi / lo <= MASS_IDENTIFIED_RATIO),
    }


def pitch_shaft_offsets(arm: Arm, position_base: np.ndarray) -> dict:
    """Where a base-frame point (q = 0) sits relative to the pitch shaft centre:
    horizontal distance perpendicular to the shaft and height above it (m), the
    quantities of a hand measurement."""
    pitch = next(l for l in arm.model.links.values() if l.group == "parallelogram" and l.variable is not None and l.joint_type == "revolute")
    T = arm.model.forward_kinematics(np.zeros(N_JOINTS))[pitch.key]
    up = -arm.model.gravity / np.linalg.norm(arm.model.gravity)
    v = np.asarray(position_base) - T[:3, 3]
    v_perp = v - (v @ T[:3, 2]) * T[:3, 2]  # remove the along-shaft component
    height = float(v_perp @ up)
    return {"horizontal_m": float(np.linalg.norm(v_perp - height * up)), "height_m": height, "along_shaft_m": float(v @ T[:3, 2])}


def payload_gravity_efforts_at_zero(arm: Arm, link: int, mass_kg: float, position_m: np.ndarray) -> np.ndarray:
    """Static efforts (7) a point mass needs at q = 0: what gravity identifies."""
    from dvrk_dart.diagnosis.effects import point_mass_parameters

    zero = np.zeros((1, N_JOINTS))
    features = TrajectoryFeatures(arm, zero, zero, zero, zero, sample_rate_hz())
    return (features.body_regressor[0][:, features.body_columns(link)] @ point_mass_parameters(mass_kg, position_m))


def _payload_report(effect: PointPayload, p: np.ndarray, arm: Arm, profile: dict | None = None) -> dict:
    report = effect.describe(p)
    report["first_moment_kg_m"] = (p[0] * np.asarray(p[1:4])).tolist()
    report["pitch_shaft_offsets_at_q0_m"] = pitch_shaft_offsets(arm, effect.position_base_at_zero(p))
    report["gravity_efforts_at_q0"] = payload_gravity_efforts_at_zero(arm, effect.link_key, p[0], p[1:4]).tolist()
    if profile is not None:
        report["mass_profile"] = profile
        report["mass_interval_kg"] = profile["mass_interval_kg"]
    return report


def diagnose(
    measured,
    baseline=None,
    train: Sequence | None = None,
    holdout: Sequence | None = None,
    simulate: Simulate | None = None,
    out_dir: Path | str | None = None,
    *,
    arm: Arm | None = None,
    base_config: SimConfig = SimConfig(),
    effects: Sequence[Effect] | None = None,
    max_effects: int = MAX_SELECTED_EFFECTS,
    folds: int = CV_FOLDS,
    figures: bool = True,
    profile_payload_mass: bool = True,
) -> dict:
    """Diagnose the gap of `measured` (a run name such as 'two', a path, a
    ProcessedRun or a DiagnosisRun carrying its simulated efforts).

    baseline: the same trajectory without the effect under study (its residual
        is subtracted, sample by sample);
    train: further runs to fit on (each a run spec or a (run, baseline) pair);
        `measured` is always a training run;
    holdout: runs never used for fitting nor selection, only scored;
    simulate: simulate(config, run) -> efforts, the DART replay; without it the
        identified model at the measured state stands in for the simulation and
        the gap after is computed with the effects' regressors;
    out_dir: where diagnosis.json, the regime tables and the figures go.
    Returns the diagnosis dict (the contract of diagnosis.json)."""
    arm = arm or load_arm()
    effects = list(effects) if effects is not None else candidate_effects(arm)

    def as_run(spec):
        if isinstance(spec, tuple):
            return prepare_run(spec[0], arm, simulate, base_config, baseline=spec[1])
        return prepare_run(spec, arm, simulate, base_config)

    train_runs = [prepare_run(measured, arm, simulate, base_config, baseline=baseline)]
    train_runs += [as_run(s) for s in (train or []) if not (isinstance(s, (str, Path)) and str(s) == str(measured))]
    holdout_runs = [as_run(s) for s in (holdout or [])]

    design = _Design(effects)
    train_features = [_features(arm, r) for r in train_runs]
    holdout_features = [_features(arm, r) for r in holdout_runs]
    train_grams = _Grams.concat([_Grams.of_run(design, f, r.residual, folds) for f, r in zip(train_features, train_runs)])
    holdout_grams = [_Grams.of_run(design, f, r.residual, 1) for f, r in zip(holdout_features, holdout_runs)]
    train_residuals = [r.residual for r in train_runs]
    w2 = _weights(np.vstack(train_residuals))

    selector = _Selector(design, train_grams, w2, folds)
    selected, steps, individual, selected_cv = selector.greedy(max_effects)
    selected, final, selected_cv = _choose_within_families(selector, selected, selected_cv)

    def train_fraction(beta):
        return _fraction(_sse(beta, train_grams.A.sum(0), train_grams.g.sum(0), train_grams.s.sum(0)), train_grams.s.sum(0), w2)

    def holdout_sse(beta):
        return [_sse(beta, h.A.sum(0), h.g.sum(0), h.s.sum(0)) for h in holdout_grams]

    def holdout_fraction(beta):
        if not holdout_grams:
            return None
        return _fraction(np.sum(holdout_sse(beta), axis=0), np.sum([h.s.sum(0) for h in holdout_grams], axis=0), w2)

    # every candidate alone, fitted on all training data, for its parameters and scores
    entries = []
    rank_order = selected + sorted((i for i in range(len(effects)) if i not in selected), key=lambda i: -individual[i].fraction)
    for rank, i in enumerate(rank_order, start=1):
        e = effects[i]
        alone = selector.fit_all([i])
        p = final.params[i] if i in selected else alone.params[i]
        cv = individual[i]
        hold = holdout_fraction(alone.beta)
        entry = {
            "rank": rank,
            "name": e.name,
            "kind": e.kind,
            "family": e.family,
            "joints": list(e.joints),
            "parameters": e.describe(p),
            "units": e.units(),
            "size": e.size(p),
            "explained_fraction": {
                "train": train_fraction(alone.beta),
                "holdout": hold if hold is not None else cv.fraction,
                "holdout_source": "runs" if hold is not None else "time_segments",
                "cross_validated": cv.fraction,
                "cross_validated_interval": selector.interval(cv.after),
            },
            "explained_fraction_per_joint": {"cross_validated": _per_joint_fraction(cv.after, train_grams.s)},
            "selected": i in selected,
            "selection_step": selected.index(i) + 1 if i in selected else None,
            "in_simulation": e.sim_contribution(np.asarray(p)) is not None,
            "fully_in_simulation": e.fully_simulated(np.asarray(p)),
        }
        entries.append(entry)

    chosen = [(effects[i], final.params[i]) for i in selected]
    sim_config = effects_to_sim_config(chosen, base_config)
    extra_by_regressor = not_simulated(chosen)

    def after_residual(run: DiagnosisRun, features: TrajectoryFeatures) -> np.ndarray:
        if simulate is None:
            explained = sum((e.effort(features, p) for e, p in chosen), np.zeros_like(run.residual))
            return run.residual - explained
        sim_after = np.asarray(simulate(sim_config, run.state), dtype=float)
        sim_after = sim_after + unsimulated_effort(extra_by_regressor, features)
        after = run.state.tau - sim_after
        return after if run.baseline is None else after - run.baseline.gap

    train_after = [after_residual(r, f) for r, f in zip(train_runs, train_features)]
    holdout_after = [after_residual(r, f) for r, f in zip(holdout_runs, holdout_features)]
    if simulate is None:
        source = "regressor"
    else:
        source = "simulation" if not extra_by_regressor else "simulation+regressor"

    payloads = [
        (effects[i], final.params[i], arm, _mass_profile(selector, selected, i) if profile_payload_mass else None)
        for i in selected
        if isinstance(effects[i], PointPayload)
    ]
    payload_candidates = sorted(
        (
            {
                "cross_validated_fraction": individual[i].fraction,
                **_payload_report(effects[i], selector.fit_all([i]).params[i], arm),
            }
            for i in range(len(effects))
            if isinstance(effects[i], PointPayload)
        ),
        key=lambda c: -c["cross_validated_fraction"],
    )
    result = {
        "joints": list(JOINT_NAMES),
        "units": [effort_unit(j) for j in JOINT_NAMES],
        "measured": train_runs[0].name,
        "baseline": train_runs[0].baseline.name if train_runs[0].baseline is not None else None,
        "train_runs": [r.name for r in train_runs],
        "holdout_runs": [r.name for r in holdout_runs],
        "residual_definition": "measured - simulated" + (" - (baseline measured - baseline simulated)" if baseline is not None else ""),
        "simulated_source": "simulation" if simulate is not None else "identified model at the measured state (stand-in for the DART replay)",
        "gap_before": {"train": _gaps(train_residuals), "holdout": _gaps([r.residual for r in holdout_runs])},
        "gap_after": {"train": _gaps(train_after), "holdout": _gaps(holdout_after)},
        "gap_after_source": source,
        "explained_fraction": {
            "train": train_fraction(final.beta),
            "holdout": holdout_fraction(final.beta),
            "cross_validated": selected_cv.fraction,
            "cross_validated_interval": selector.interval(selected_cv.after),
        },
        "effects": entries,
        "selection": {
            "method": (
                f"greedy forward selection on {len(selector.folds)}-fold contiguous time-segment cross-validation of the training runs, "
                f"weighted least squares (joint weight 1/RMS before), bounded to physical ranges; stop when the held-out gain < "
                f"{MIN_HELDOUT_GAIN} or not positive with probability {1 - GAIN_FAILURE_QUANTILE:.2f} (block bootstrap, "
                f"{BLOCK_DURATION_S} s blocks, {BOOTSTRAP_RESAMPLES} resamples); a payload's link among its equivalent links "
                f"(identical efforts) by the penalised training cost"
            ),
            "steps": steps,
            "selected": [effects[i].name for i in selected],
        },
        "payload": _payload_report(*payloads[0]) if payloads else None,
        "payloads": [_payload_report(*pl) for pl in payloads],
        "payload_candidates": payload_candidates,
        "sim_config": sim_config.to_dict(),
        "not_in_simulation": [e.name for e, _ in extra_by_regressor],
    }
    if out_dir is not None:
        _write_outputs(Path(out_dir), result, train_runs[0], train_after[0], figures)
    return result


def _write_outputs(out_dir: Path, result: dict, run: DiagnosisRun, after: np.ndarray, figures: bool) -> None:
    from dvrk_dart.io.atomic import write_text_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    before_table = residual_regimes(run.state, run.residual).assign(stage="before")
    after_table = residual_regimes(run.state, after).assign(stage="after")
    table = pd.concat([before_table, after_table], ignore_index=True)
    write_text_atomic(out_dir / "where.csv", table.to_csv(index=False))
    result["where"] = {"table": "where.csv", "run": run.name, "figures": []}
    if figures:
        paths = plot_residuals(run.state, run.residual, out_dir / "figures", "residual_before")
        paths += plot_residuals(run.state, after, out_dir / "figures", "residual_after")
        result["where"]["figures"] = [str(p.relative_to(out_dir)) for p in paths]
    write_json_atomic(out_dir / "diagnosis.json", result)


# ------------------------------------------------------------ synthetic data
def synthesize_measurement(
    arm: Arm,
    state: ProcessedRun,
    injected: Sequence[tuple[Effect, np.ndarray]],
    noise_rms: np.ndarray,
    seed: int = 0,
    simulate: Simulate | None = None,
    base_config: SimConfig = SimConfig(),
) -> ProcessedRun:
    """A measured run with hidden effects: the efforts of the simulation with
    the effects as physics (SimConfig) plus the regressor efforts of effects the
    simulation has no field for, plus coloured noise of the given RMS per joint
    (white noise through the upstream low-pass filter)."""
    config = effects_to_sim_config(list(injected), base_config)
    tau = simulated_efforts(arm, state, simulate, config)
    extra = not_simulated(list(injected))
    if extra:
        features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, simulated_efforts(arm, state, simulate, base_config), sample_rate_hz())
        tau = tau + unsimulated_effort(extra, features)
    rng = np.random.default_rng(seed)
    noise = zero_phase_lowpass(rng.standard_normal(tau.shape), 1.0 / sample_rate_hz())
    noise = noise / np.maximum(rms(noise), 1e-300) * np.asarray(noise_rms, dtype=float)
    return ProcessedRun(state.t, state.q, state.dq, state.ddq, tau + noise)


# ----------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m dvrk_dart.diagnosis.selection", description=__doc__.splitlines()[0])
    parser.add_argument("--measured", required=True, help="run name ('one', 'two', 'one-105g' ...) or CSV path")
    parser.add_argument("--baseline", help="same trajectory without the effect under study")
    parser.add_argument("--train", nargs="*", default=[], help="further training runs")
    parser.add_argument("--holdout", nargs="*", default=[], help="held-out runs (scored only)")
    parser.add_argument("--out", required=True, help="output folder (diagnosis.json, where.csv, figures/)")
    parser.add_argument("--no-figures", action="store_true")
    args = parser.parse_args(argv)
    try:
        result = diagnose(args.measured, args.baseline, args.train, args.holdout, out_dir=args.out, figures=not args.no_figures)
    except DvrkDartError as exc:
        print(f"dvrk-dart: {exc}", file=sys.stderr)
        return exc.exit_code
    print(f"selected: {', '.join(result['selection']['selected']) or 'none'}")
    for key in ("gap_before", "gap_after"):
        for split, values in result[key].items():
            if values is not None:
                print(f"{key:>10} {split:>7}: " + " ".join(f"{v:.4f}" for v in values))
    if result["payload"]:
        p = result["payload"]
        print(f"payload: {p['mass_kg']:.4f} kg on {p['link']} ({p['group']}) at {np.round(p['position_m'], 4).tolist()} m (link frame)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A payload read from periodic difference signals, with intervals that hold.

A run with the weight minus its baseline without it (same motion, two
sessions, `--processing periodic`) holds, on the excitation's harmonics:

    d = Y(q, dq, ddq) p + c + s + n

- Y p: the payload's efforts (its first-moment columns and J1's own path,
  `FirstMomentPayload`), linear in p;
- c: a constant per run on the joints whose constant moves between sessions
  (`session_floor.session_offset_joints`): a nuisance, fitted and dropped;
- s: what else changes between the two sessions (the arm warms, cables
  settle): repeatable within a session, not from one to the next;
- n: the noise, what does not repeat from one period to the next.

The fit is generalised least squares in the harmonic coefficients, where n is
white with the variance the periodic layer measures per harmonic
(`periodic.Noise`). The session term s is treated as a random draw per
harmonic: its variance at harmonic k is the power that the fit leaves around
k (the residual's cos/sin coefficients within `VARIANCE_WINDOW_HARMONICS`,
pooled over the pairs and the `--repeat` pair, never below the noise's),
estimated and refitted `FEASIBLE_GLS_ITERATIONS` times. Every reported
quantity (linear in p) gets a central interval of `INTERVAL_PROBABILITY`
from its HC2 standard error with Bell and McCaffrey's degrees of freedom:
the weights' own estimation error (a few harmonics per window) would make
(Y' V^-1 Y)^-1 too narrow (coverage 0.77-0.88 measured). A session change
of the payload's own shape (gravity-shaped: an offset of q2's zero, the
counterweight's cable) is not random per harmonic: it reads as a payload.
With `--repeat`, the same design fitted on the --repeat pair alone reads its
size, and the intervals count it (`interval_with_session`). A quantity the
efforts do not see is reported as null with the reason. That these intervals hold is shown by a coverage test
on simulated pairs with noise, session scatter and a session change of the
payload's shape at the measured levels (tests/test_periodic_payload.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from dvrk_dart.diagnosis.effects.features import FIRST_MOMENT_COLUMNS, TrajectoryFeatures
from dvrk_dart.diagnosis.effects.first_moment import YAW_PATH_JOINT
from dvrk_dart.diagnosis.payload.intervals import central_interval, with_session_change
from dvrk_dart.diagnosis.effects.payload import point_mass_parameters
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.model.body_regressor import BODY_PARAMETERS
from dvrk_dart.model.joints import N_JOINTS

#: the session term's variance at a harmonic is the residual power within this
#: many harmonics on either side: 2(2W+1) coefficients per joint and pair
VARIANCE_WINDOW_HARMONICS = 3
#: re-estimations of the variance and refits (the estimate settles in two)
FEASIBLE_GLS_ITERATIONS = 3
#: a quantity is determined when the part of it outside what the efforts see
#: is below this fraction (round-off of the normal equations)
ESTIMABLE_TOLERANCE = 1e-6
#: singular values of the normal equations below this fraction of the largest
#: are directions the efforts do not see (a body's unexcited inertia)
RANK_CUT = 1e-10


@dataclass(frozen=True)
class Pair:
    """One run minus its baseline, on the harmonics: y (R, 7) coefficients of
    the difference, X (R, 7, p) of the payload's columns (zero for a pair
    without the payload: the `--repeat` pair), noise (R, 7) the coefficients'
    noise variance (run's plus baseline's)."""

    name: str
    y: np.ndarray
    X: np.ndarray
    noise: np.ndarray


def harmonic_coefficients(state: ProcessedRun, x: np.ndarray) -> np.ndarray:
    """(R, ...) coefficients on the run's harmonics of a signal at its samples (N, ...)."""
    if state.periodic is None:
        raise DvrkDartError("a periodic payload fit needs periodic runs (--processing periodic)")
    x = np.asarray(x, dtype=float)
    flat = x.reshape(len(x), -1)
    coefficients = state.periodic.projector.series(flat).coefficients
    return coefficients.reshape((len(coefficients),) + x.shape[1:])


def make_pair(name: str, state: ProcessedRun, baseline: ProcessedRun, difference: np.ndarray, columns: np.ndarray | None, n_parameters: int) -> Pair:
    """A Pair from a run's difference signal (N, 7) and its payload columns (N, 7, p); None: a pair without the payload."""
    y = harmonic_coefficients(state, difference)
    X = harmonic_coefficients(state, columns) if columns is not None else np.zeros(y.shape + (n_parameters,))
    noise = sum(s.periodic.effort_noise.coefficient_variance()[: len(y)] for s in (state, baseline))
    return Pair(name, y, X, noise)


def _harmonic_of_rows(rows: int) -> np.ndarray:
    return (np.arange(rows) + 1) // 2


def _window_mean(x: np.ndarray) -> np.ndarray:
    """(R, 7): per coefficient, the mean of x over the coefficients of the
    harmonics within the window around its own (the mean's row counts once)."""
    harmonic = _harmonic_of_rows(len(x))
    top = harmonic[-1]
    sums = np.array([x[harmonic == h].sum(axis=0) for h in range(top + 1)])
    counts = np.bincount(harmonic, minlength=top + 1).astype(float)
    w = VARIANCE_WINDOW_HARMONICS
    smoothed = np.array([sums[max(0, h - w): h + w + 1].sum(axis=0) / counts[max(0, h - w): h + w + 1].sum() for h in range(top + 1)])
    return smoothed[harmonic]


def beyond_noise(squared: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """(R, 7) the power of a pair's squared residual coefficients above its noise, over the window of harmonics."""
    return _window_mean(squared) - _window_mean(noise)


def session_variance(pair: Pair, offset_joints: np.ndarray | None = None) -> np.ndarray:
    """(R, 7) the session term's variance per coefficient that a pair without
    the payload (two sessions of one motion) shows, never negative; the mean's
    row of `offset_joints` left out (a per-pair offset takes it whole in a fit)."""
    squared, noise = pair.y**2, pair.noise.copy()
    if offset_joints is not None:
        squared[0, np.asarray(offset_joints, bool)] = 0.0
        noise[0, np.asarray(offset_joints, bool)] = 0.0
    return np.maximum(beyond_noise(squared, noise), 0.0)


@dataclass(frozen=True)
class PayloadFit:
    """The GLS fit: parameters, their model covariance, the residual variance
    model, and what the robust intervals and tests are made from."""

    params: np.ndarray
    covariance: np.ndarray
    #: pinv(A) A of the payload's parameters: a linear quantity J p is estimable
    #: (the efforts determine it) when J lies in its row space
    estimable: np.ndarray
    variance: list[np.ndarray]
    offsets: dict[str, np.ndarray]
    rows: int
    #: the robust interval's pieces (weighted space): rows' influence map
    #: (P, n) = (X'WX)^+ X' W^(1/2), residuals over sqrt(1 - leverage), and the
    #: squared annihilator (I - H) elementwise, for the degrees of freedom
    influence: np.ndarray = None
    scaled_residual: np.ndarray = None
    one_minus_leverage: np.ndarray = None
    annihilator_squared: np.ndarray = None
    #: the weighted residual sum of squares and the payload parameters' rank (the link choice)
    weighted_rss: float = 0.0
    rank: int = 0

    def determined(self, jacobian: np.ndarray) -> np.ndarray:
        """Per row of `jacobian`: whether the efforts determine that quantity."""
        jacobian = np.atleast_2d(jacobian)
        lost = np.linalg.norm(jacobian - jacobian @ self.estimable, axis=1)
        return lost <= ESTIMABLE_TOLERANCE * np.maximum(np.linalg.norm(jacobian, axis=1), 1e-300)

    def p_value(self, jacobian: np.ndarray) -> float:
        """The quantities `jacobian` @ p against zero: Wald test with their HC2
        covariance (robust as the intervals)."""
        jacobian = np.atleast_2d(jacobian)
        a = jacobian @ self.influence[: jacobian.shape[1]] * np.nan_to_num(self.scaled_residual)
        covariance = a @ a.T
        value = jacobian @ self.params
        rank = int(np.linalg.matrix_rank(covariance, hermitian=True))
        statistic = float(value @ np.linalg.pinv(covariance, hermitian=True) @ value)
        return float(chi2.sf(statistic, max(rank, 1)))

    def standard_error(self, jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value, HC2 standard error and Bell and McCaffrey's degrees of freedom
        (Imbens and Kolesar 2016) of the linear quantity `jacobian` @ p: robust
        to a session spectrum the weights got wrong, and few degrees of freedom
        where few harmonics carry the quantity."""
        jacobian = np.atleast_2d(jacobian)
        value = jacobian @ self.params
        # rows the fit matches exactly (a run's offset on its mean) carry no information
        informative = np.isfinite(self.scaled_residual)
        a = jacobian @ self.influence[: jacobian.shape[1]] * informative
        se = np.sqrt(np.sum(a**2 * np.nan_to_num(self.scaled_residual) ** 2, axis=1))
        weights = a**2 / self.one_minus_leverage
        dof = np.sum(weights * self.one_minus_leverage, axis=1) ** 2 / np.maximum(
            np.sum((weights @ self.annihilator_squared) * weights, axis=1), 1e-300)
        return value, se, np.maximum(dof, 1.0)

    def interval(self, jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Value and (2, ...) central interval of the linear quantity `jacobian` @ p (`standard_error`)."""
        value, se, dof = self.standard_error(jacobian)
        return value, central_interval(value, se, dof)


def interval_with_session(fit: PayloadFit, session_fit: PayloadFit | None,
                          jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Value, (2, ...) interval, the --repeat pair's reading of the linear
    quantity `jacobian` @ p and the session spread the interval counts
    (`with_session_change`). `session_fit`: the same design fitted on the
    --repeat pair alone: what it reads is a session change of the payload's
    own shape (an offset of q2's zero, the counterweight's cable), which the
    harmonic-by-harmonic session variance does not count."""
    value, se, dof = fit.standard_error(jacobian)
    if session_fit is None:
        return value, central_interval(value, se, dof), None, None
    read, read_se, _ = session_fit.standard_error(jacobian)
    interval, spread = with_session_change(value, se, dof, read, read_se)
    return value, interval, read, spread


def _design(pairs: list[Pair], offset_joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[slice]]:
    """Stacked rows (pair, coefficient, joint): y, [X | per-pair offsets on the mean's row of the offset joints]."""
    n_params = pairs[0].X.shape[-1]
    offsets = [int(np.sum(offset_joints))] * len(pairs)
    columns = n_params + sum(offsets)
    ys, Xs, where = [], [], []
    start = n_params
    for pair, n_offsets in zip(pairs, offsets):
        rows, joints = pair.y.shape
        X = np.zeros((rows, joints, columns))
        X[:, :, :n_params] = pair.X
        for k, j in enumerate(np.flatnonzero(offset_joints)):
            X[0, j, start + k] = 1.0
        where.append(slice(start, start + n_offsets))
        start += n_offsets
        ys.append(pair.y.reshape(-1))
        Xs.append(X.reshape(rows * joints, columns))
    return np.concatenate(ys), np.vstack(Xs), where


def _weighted_inverse(X: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(X' W X)^+ and X' W X, equilibrated (columns of inertia and of first
    moments differ by orders of magnitude; a column the efforts never see is 0)."""
    A = X.T @ (X * w[:, None])
    diagonal = np.diag(A)
    scale = np.where(diagonal > 0, 1.0 / np.sqrt(np.where(diagonal > 0, diagonal, 1.0)), 0.0)
    inverse = scale[:, None] * np.linalg.pinv(A * np.outer(scale, scale), rcond=RANK_CUT, hermitian=True) * scale[None, :]
    return inverse, A


#: a joint whose noise variance is below this fraction of the noisiest joint's measured nothing: round-off (a
#: simulated run's held wrist, 1e-31 against 1e-7 N·m² on q1..q3, took weights of 1e30 and hid a 0.2 kg payload)
ROUND_OFF_VARIANCE = 1e-12


def _measured(pair: Pair) -> np.ndarray:
    """(R, 7) the coefficients the pair measured: noise above round-off on its joint (a joint not recorded: zeros)."""
    per_joint = pair.noise.max(axis=0)
    return (pair.noise > 0.0) & (per_joint > ROUND_OFF_VARIANCE * per_joint.max())


def _weights(variance: list[np.ndarray], measured: np.ndarray) -> np.ndarray:
    """1 / variance where the pairs measured something (`measured`: their noise is not nil), else no weight:
    a joint the runs did not record (zeros, no noise) has no say in the fit, whatever scatter its rows seem to have."""
    v = np.concatenate([x.reshape(-1) for x in variance])
    return np.where(measured & (v > 0.0), 1.0 / np.where(v > 0.0, v, 1.0), 0.0)


def fit_payload(pairs: list[Pair], offset_joints: np.ndarray | None = None, variance: list[np.ndarray] | None = None) -> PayloadFit:
    """Feasible GLS of the payload's parameters over the pairs (module docstring);
    `variance` (per pair, (R, 7)): fixed weights, not re-estimated."""
    if not pairs:
        raise DvrkDartError("a periodic payload fit needs at least one run minus its baseline of the same motion")
    offset_joints = np.zeros(N_JOINTS, bool) if offset_joints is None else np.asarray(offset_joints, bool)
    y, X, where = _design(pairs, offset_joints)
    bounds = np.cumsum([0] + [p.y.size for p in pairs])
    fixed = variance is not None
    variance = variance if fixed else [p.noise.copy() for p in pairs]
    n_params = pairs[0].X.shape[-1]
    measured = np.concatenate([_measured(p).reshape(-1) for p in pairs])
    for _ in range(0 if fixed else FEASIBLE_GLS_ITERATIONS):
        w = _weights(variance, measured)
        inverse, _ = _weighted_inverse(X, w)
        residual = y - X @ (inverse @ (X.T @ (w * y)))
        # each residual over sqrt(1 - its leverage): the fit took that share of
        # it, most where the payload's own harmonics are (HC2, MacKinnon and White 1985)
        leverage = np.minimum(np.sum((X @ inverse) * X, axis=1) * w, 1.0 - 1e-9)
        squared = residual**2 / (1.0 - leverage)
        # the session term's spectrum, one for all pairs (every pair is a change of session); the noise of each pair its own
        session = np.maximum(np.mean([beyond_noise(squared[b:e].reshape(p.y.shape), p.noise)
                                      for p, b, e in zip(pairs, bounds[:-1], bounds[1:])], axis=0), 0.0)
        variance = [session + p.noise for p in pairs]
    w = _weights(variance, measured)
    inverse, A = _weighted_inverse(X, w)
    beta = inverse @ (X.T @ (w * y))
    covariance = inverse[:n_params, :n_params]
    estimable = (inverse @ A)[:n_params, :n_params]
    offsets = {p.name: beta[s] for p, s in zip(pairs, where)}
    root_w = np.sqrt(w)
    influence = inverse @ (X.T * root_w)
    hat = (X * root_w[:, None]) @ influence
    one_minus = np.clip(1.0 - np.diag(hat), 0.0, 1.0)
    scaled = np.where(one_minus > 1e-9, root_w * (y - X @ beta) / np.sqrt(np.maximum(one_minus, 1e-300)), np.nan)
    annihilator = np.eye(len(y)) - hat
    return PayloadFit(beta[:n_params], covariance, estimable, variance, offsets, int(np.count_nonzero(w)),
                      influence, scaled, np.maximum(one_minus, 1e-300), annihilator**2,
                      float(np.sum(w * (y - X @ beta) ** 2)), int(np.linalg.matrix_rank(estimable)))


def linear_map(quantity, n_parameters: int) -> dict[str, np.ndarray]:
    """{name: (k, p) matrix} of a map p -> {name: value} that is linear in p (read on the unit vectors)."""
    columns = [quantity(np.eye(n_parameters)[i]) for i in range(n_parameters)]
    return {key: np.stack([np.atleast_1d(np.asarray(c[key], dtype=float)) for c in columns], axis=-1) for key in columns[0]}


# ------------------------------------------------------------------ the designs
def rigid_payload_columns(features: TrajectoryFeatures, key: int) -> np.ndarray:
    """(N, 7, 20): a rigid body on link `key` (its 10 dynamic parameters) on
    J2..J7, and J1's own rigid body (the yaw path, `first_moment`) on J1: J1's
    gravity load depends on how the real yaw axis lies, which the model fixes."""
    body = features.body_regressor[:, :, features.body_columns(key)]
    out = np.zeros(body.shape[:2] + (2 * BODY_PARAMETERS,))
    out[:, YAW_PATH_JOINT + 1:, :BODY_PARAMETERS] = body[:, YAW_PATH_JOINT + 1:]
    out[:, YAW_PATH_JOINT, BODY_PARAMETERS:] = body[:, YAW_PATH_JOINT]
    return out


def point_payload_columns(features: TrajectoryFeatures, key: int, position_m: np.ndarray) -> np.ndarray:
    """(N, 7, 11): a point mass at a given position of link `key` (its mass) on
    J2..J7, and J1's own rigid body on J1 (as `rigid_payload_columns`)."""
    body = features.body_regressor[:, :, features.body_columns(key)]
    out = np.zeros(body.shape[:2] + (1 + BODY_PARAMETERS,))
    out[:, YAW_PATH_JOINT + 1:, 0] = body[:, YAW_PATH_JOINT + 1:] @ point_mass_parameters(1.0, position_m)
    out[:, YAW_PATH_JOINT, 1:] = body[:, YAW_PATH_JOINT]
    return out


def rigid_as_first_moment(p: np.ndarray) -> np.ndarray:
    """The (m, m c, yaw path m, m c) of `identifiable`'s quantities from a rigid design's 20 parameters."""
    return np.r_[p[:FIRST_MOMENT_COLUMNS], p[BODY_PARAMETERS:BODY_PARAMETERS + FIRST_MOMENT_COLUMNS]]

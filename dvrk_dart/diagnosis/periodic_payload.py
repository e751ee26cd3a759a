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
estimated and refitted `FEASIBLE_GLS_ITERATIONS` times. The parameters'
covariance is then (Y' V^-1 Y)^-1, and every reported quantity (linear in p)
gets a central interval of `INTERVAL_PROBABILITY` from it; a quantity the
efforts do not see is reported as null with the reason. That these intervals
hold is shown by a coverage test on simulated pairs with noise and session
scatter at the measured levels (tests/test_periodic_payload.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.stats import chi2
from scipy.stats import t as student_t

from dvrk_dart.diagnosis.features import BODY_PARAMETERS, FIRST_MOMENT_COLUMNS, TrajectoryFeatures
from dvrk_dart.diagnosis.first_moment import YAW_PATH_JOINT
from dvrk_dart.diagnosis.payload import point_mass_parameters
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.model.joints import N_JOINTS

#: the session term's variance at a harmonic is the residual power within this
#: many harmonics on either side: 2(2W+1) coefficients per joint and pair
VARIANCE_WINDOW_HARMONICS = 3
#: re-estimations of the variance and refits (the estimate settles in two)
FEASIBLE_GLS_ITERATIONS = 3
#: the reported intervals' probability, and the payload's test level against
#: the session scatter (a payload is found when p < this)
INTERVAL_PROBABILITY = 0.90
PAYLOAD_TEST_LEVEL = 0.01
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


def session_variance(pair: Pair) -> np.ndarray:
    """(R, 7) the session term's variance per coefficient that a pair without
    the payload (two sessions of one motion) shows, never negative."""
    return np.maximum(beyond_noise(pair.y**2, pair.noise), 0.0)


@dataclass(frozen=True)
class PayloadFit:
    """The GLS fit: parameters, their covariance, the residual variance model,
    and the Wald statistic of the payload against the session scatter."""

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

    def interval(self, jacobian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Value and (2, ...) central interval of the linear quantity `jacobian`
        @ p: the HC2 standard error with Bell and McCaffrey's degrees of freedom
        (Imbens and Kolesar 2016): robust to a session spectrum the weights
        got wrong, and wide where few harmonics carry the quantity."""
        jacobian = np.atleast_2d(jacobian)
        value = jacobian @ self.params
        a = jacobian @ self.influence[: jacobian.shape[1]]
        s2 = a**2 * np.where(np.isfinite(self.scaled_residual), 1.0, 0.0)
        se = np.sqrt(np.sum(s2 * np.nan_to_num(self.scaled_residual) ** 2, axis=1))
        weights = a**2 / self.one_minus_leverage
        dof = np.sum(weights * self.one_minus_leverage, axis=1) ** 2 / np.maximum(
            np.einsum("ki,ij,kj->k", weights, self.annihilator_squared, weights), 1e-300)
        t = student_t.ppf(0.5 + INTERVAL_PROBABILITY / 2.0, np.maximum(dof, 1.0))
        return value, np.stack([value - t * se, value + t * se])


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
    for _ in range(0 if fixed else FEASIBLE_GLS_ITERATIONS):
        w = 1.0 / np.concatenate([v.reshape(-1) for v in variance])
        inverse, _ = _weighted_inverse(X, w)
        residual = y - X @ (inverse @ (X.T @ (w * y)))
        # each residual over sqrt(1 - its leverage): the fit took that share of
        # it, most where the payload's own harmonics are (HC2, MacKinnon and White 1985)
        leverage = np.minimum(np.einsum("ij,jk,ik->i", X, inverse, X) * w, 1.0 - 1e-9)
        squared = residual**2 / (1.0 - leverage)
        # the session term's spectrum, one for all pairs (every pair is a change of session); the noise of each pair its own
        session = np.maximum(np.mean([beyond_noise(squared[b:e].reshape(p.y.shape), p.noise)
                                      for p, b, e in zip(pairs, bounds[:-1], bounds[1:])], axis=0), 0.0)
        variance = [session + p.noise for p in pairs]
    w = 1.0 / np.concatenate([v.reshape(-1) for v in variance])
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
    return PayloadFit(beta[:n_params], covariance, estimable, variance, offsets, len(y),
                      influence, scaled, np.maximum(one_minus, 1e-300), annihilator**2,
                      float(np.sum(w * (y - X @ beta) ** 2)), int(np.linalg.matrix_rank(estimable)))


def linear_map(quantity, n_parameters: int) -> dict[str, np.ndarray]:
    """{name: (k, p) matrix} of a map p -> {name: value} that is linear in p (read on the unit vectors)."""
    columns = [quantity(np.eye(n_parameters)[i]) for i in range(n_parameters)]
    return {key: np.stack([np.atleast_1d(np.asarray(c[key], dtype=float)) for c in columns], axis=-1) for key in columns[0]}


def with_intervals(fit: PayloadFit, maps: dict[str, np.ndarray], scalars: set[str]) -> dict:
    """{key: value, key_interval: [lo, hi] (per element for vectors)} from the fit's covariance."""
    out = {}
    for key, jacobian in maps.items():
        value, interval = fit.interval(jacobian)
        if key in scalars:
            out[key], out[f"{key}_interval"] = float(value[0]), interval[:, 0].tolist()
        else:
            out[key], out[f"{key}_interval"] = value.tolist(), interval.T.tolist()
    return out



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


# ------------------------------------------------------------------ the report
def _pairs(runs, columns_of) -> list[Pair]:
    """Pairs of the runs minus their baselines (DiagnosisRun, role "difference");
    columns_of(run) -> the payload columns in the run's band, None for a run
    without the payload (the --repeat pair: it measures the session scatter)."""
    pairs = []
    for run in runs:
        columns = columns_of(run)
        n = columns.shape[-1] if columns is not None else None
        pairs.append((run, columns, n))
    n_parameters = next(n for _, _, n in pairs if n is not None)
    return [make_pair(run.name, run.state, run.baseline.state, run.residual, columns, n_parameters) for run, columns, _ in pairs]


def _report_quantities(fit: PayloadFit, maps: dict[str, np.ndarray], not_seen: dict[str, str]) -> tuple[dict, dict]:
    """Each quantity with its interval where the efforts determine it, else
    None and the reason (`not_seen`: reasons known beforehand, by key)."""
    report, reasons = {}, {}
    for key, jacobian in maps.items():
        scalar = jacobian.shape[0] == 1 and key in SCALAR_QUANTITIES
        value, interval = fit.interval(jacobian)
        determined = fit.determined(jacobian) & (key not in not_seen)
        if scalar:
            report[key] = float(value[0]) if determined[0] else None
            report[f"{key}_interval"] = interval[:, 0].tolist() if determined[0] else None
        else:
            report[key] = [float(v) if d else None for v, d in zip(value, determined)]
            report[f"{key}_interval"] = [[float(lo), float(hi)] if d else None for lo, hi, d in zip(*interval, determined)]
        if not determined.all():
            reasons[key] = not_seen.get(key, "the efforts do not determine it (the runs' motion does not excite it)")
    return report, reasons


SCALAR_QUANTITIES = {"mass_kg", "q1_gravity_slope_at_q0_nm_per_rad"}

#: what the report says of how its intervals were made
INTERVAL_METHOD = (f"{INTERVAL_PROBABILITY:.0%} intervals: generalised least squares on the harmonics of the runs minus their baseline "
                   "(weights: measured noise plus the session scatter the fit leaves, per harmonic), HC2 standard errors with "
                   "Bell-McCaffrey degrees of freedom; coverage shown on simulated pairs at the measured noise and session scatter")
MASS_NOT_SEEN = ("gravity sees m·c only on this link (it turns about fixed axes with the parallelogram) and the inertia of a small "
                 "mass is below the noise: give --payload-at LINK:x,y,z to turn the first moment into a mass")


def choose_payload_link(candidates: list, pair_runs, differences, features_of, offset_joints) -> int:
    """Index of the payload (among FirstMomentPayload candidates) whose rigid
    body explains the runs minus their baseline best on the harmonics:
    weighted residual under one variance model for all (that of no payload),
    plus log(rows) per parameter the efforts determine (BIC): a link that can
    also absorb a session change of another joint pays for its parameters."""
    def pairs_of(effect):
        return _pairs(pair_runs, lambda r: r.state.in_band(rigid_payload_columns(features_of(r), effect.link_key)) if r in differences else None)

    common = fit_payload([replace(p, X=np.zeros_like(p.X)) for p in pairs_of(candidates[0])], offset_joints).variance
    costs = []
    for effect in candidates:
        fit = fit_payload(pairs_of(effect), offset_joints, common)
        costs.append(fit.weighted_rss + fit.rank * np.log(fit.rows))
    return int(np.argmin(costs))


def periodic_payload_report(arm, candidates, runs, repeat_run, features_of, offset_joints, at=None) -> dict:
    """The payload (of the FirstMomentPayload `candidates`, the link chosen by
    `choose_payload_link`) read from the runs
    minus their baseline (and the --repeat pair) on the harmonics: every
    quantity with an interval that holds, or None with the reason; with `at`
    (a PayloadAtPosition), the mass at that position."""
    from dvrk_dart.diagnosis.identifiable import _gravity_at_zero, _gravity_efforts, _quantities, _yaw_slope
    from dvrk_dart.diagnosis.payload import mass_seen_by_gravity
    from dvrk_dart.diagnosis.payload_report import pitch_shaft_offsets

    differences = [r for r in runs if r.role == "difference"]
    if not differences:
        raise DvrkDartError("--processing periodic with --baseline: no run has the baseline's motion (a payload needs a run minus its "
                            "baseline of the same motion on the harmonics)")
    pair_runs = differences + ([repeat_run] if repeat_run is not None and repeat_run.role == "difference" else [])
    effect = candidates[choose_payload_link(candidates, pair_runs, differences, features_of, offset_joints)]
    key = effect.link_key

    def fit_with(columns) -> PayloadFit:
        return fit_payload(_pairs(pair_runs, lambda r: r.state.in_band(columns(features_of(r))) if r in differences else None), offset_joints)

    gravity = _gravity_at_zero(arm, key)
    fit = fit_with(lambda f: rigid_payload_columns(f, key))
    maps = linear_map(lambda p: _quantities(arm, effect, rigid_as_first_moment(p), gravity), 2 * BODY_PARAMETERS)
    not_seen = {} if mass_seen_by_gravity(arm, key) else {"mass_kg": MASS_NOT_SEEN}
    quantities, reasons = _report_quantities(fit, maps, not_seen)
    # the payload against none: its gravity signature the efforts determine (first moment, J1's slope)
    signature = np.vstack([maps[k][fit.determined(maps[k])] for k in ("first_moment_base_at_q0_kg_m", "q1_gravity_slope_at_q0_nm_per_rad")])
    p_value = fit.p_value(signature)
    report = {**effect.describe(np.zeros(effect.n_parameters)), **quantities, "not_determined": reasons,
              "first_moment_reference_link": arm.model.links[effect.reference_key].name,
              "mass_identified": quantities["mass_kg"] is not None, "position_m": None,
              "payload_p_value": p_value, "found": bool(p_value < PAYLOAD_TEST_LEVEL),
              "pairs": [p.name for p in pair_runs], "session_pair": pair_runs[-1].name if len(pair_runs) > len(differences) else None,
              "interval_method": INTERVAL_METHOD}
    report.pop("first_moment_link_kg_m", None), report.pop("yaw_path_mass_and_first_moment_link", None)  # not determined apart
    moment = report["first_moment_base_at_q0_kg_m"]
    report["pitch_shaft_offsets_of_first_moment_m_kg"] = (pitch_shaft_offsets(arm, np.asarray(moment)) if None not in moment else None)
    if at is not None:
        at_fit = fit_with(lambda f: point_payload_columns(f, at.link_key, at.position))
        at_gravity = _gravity_at_zero(arm, at.link_key)
        unit = point_mass_parameters(1.0, at.position)[:FIRST_MOMENT_COLUMNS]
        at_maps = linear_map(lambda p: {"mass_kg": p[0], "gravity_efforts_at_q0": _gravity_efforts(at_gravity[:, :, :FIRST_MOMENT_COLUMNS], p[0] * unit,
                                                                                                      p[1:1 + FIRST_MOMENT_COLUMNS]),
                                        "q1_gravity_slope_at_q0_nm_per_rad": _yaw_slope(at_gravity, p[1:1 + FIRST_MOMENT_COLUMNS])}, 1 + BODY_PARAMETERS)
        at_quantities, at_reasons = _report_quantities(at_fit, at_maps, {})
        report["payload_at"] = {"link": at.link_name, "position_m": at.position.tolist(), **at_quantities, "not_determined": at_reasons}
        report["position_m"] = at.position.tolist()
    report["words"] = _words(report)
    return report


def _interval_text(value, interval, unit: str, digits: int = 3) -> str:
    if value is None:
        return "not determined"
    return f"{value:+.{digits}f} {unit} ({interval[0]:+.{digits}f} to {interval[1]:+.{digits}f})"


def _words(report: dict) -> list[str]:
    from dvrk_dart.model.joints import JOINT_NAMES, effort_unit

    words = []
    if not report["found"]:
        words.append(f"No payload stands out from the session-to-session scatter (p = {report['payload_p_value']:.2g}): what the runs "
                     "differ by from their baseline is what two sessions differ by.")
    moment, intervals = report["first_moment_base_at_q0_kg_m"], report["first_moment_base_at_q0_kg_m_interval"]
    words.append("First moment m·c (base frame, q = 0, as a body on " + report["first_moment_reference_link"] + "): "
                 + ", ".join(f"{a} {_interval_text(v, i, 'kg·m', 4)}" for a, v, i in zip("xyz", moment, intervals)) + ".")
    words.append("Gravity efforts at q = 0: " + ", ".join(
        f"{j} {_interval_text(v, i, effort_unit(j))}" for j, v, i in
        zip(JOINT_NAMES[:3], report["gravity_efforts_at_q0"], report["gravity_efforts_at_q0_interval"])) + ".")
    words.append(f"J1's effort changes with q1 at {_interval_text(report['q1_gravity_slope_at_q0_nm_per_rad'], report['q1_gravity_slope_at_q0_nm_per_rad_interval'], 'N·m/rad')} "
                 "at q = 0 (J1's own path: how the real yaw axis lies relative to gravity).")
    if report["mass_kg"] is None:
        words.append(f"The mass is not determined: {report['not_determined'].get('mass_kg', '')}.")
    else:
        words.append(f"Mass {_interval_text(report['mass_kg'], report['mass_kg_interval'], 'kg')}.")
    at = report.get("payload_at")
    if at:
        words.append(f"At the given position ({at['link']}, {np.round(at['position_m'], 3).tolist()} m in its frame) the mass is "
                     f"{_interval_text(at['mass_kg'], at['mass_kg_interval'], 'kg')}.")
    words.append(f"Intervals: {report['interval_method']}.")
    if report["session_pair"] is None:
        words.append("Without --repeat (the baseline's motion in another session) the session scatter is read only from what the payload "
                     "leaves: a change between the sessions shaped like gravity (an offset of q2's zero, the counterweight's cable) "
                     "reads as a payload, and the intervals do not count it.")
    return words

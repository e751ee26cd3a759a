"""The floor of a model's residual: two recordings of one trajectory in two sessions.

What the identified model leaves of a run (measured - predicted) holds what
any fixed effect could explain, plus what changes from one recording to the
next. Two recordings of the same trajectory share the first: the difference
of their residuals is the floor no fixed effect can remove, on the very
signals a comparison uses (the same processing). Its parts:

- noise: each run's measured efforts (the lines between the harmonics, io/
  periodic.py) and the model's inputs (position noise through the model,
  drawn from the positions' own harmonic noise); a difference of independent
  noises adds in squares, so the two runs predict
  sqrt(noise_a^2 + noise_b^2) of RMS difference;
- a session effect: what the difference holds beyond that (a constant that
  moves: `rms_difference_demeaned` takes it out; a shape that moves: left).

In periodic processing the two residuals are compared over one period on a
common phase (the second run shifted to where its positions best match the
first's); in upstream processing sample by sample.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.optimize

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.period import harmonic_design, spanning_columns
from dvrk_dart.io.csv_run import say_once
from dvrk_dart.io.signal import SAME_MOTION_POSITION_RMS, ProcessedRun, not_comparable_sample_by_sample, same_motion
from dvrk_dart.metrics import moved_constants, per_measured_joint, rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES

#: draws of the positions' noise through the model (the spread of their RMS is ~1/sqrt(2 x draws x samples))
PREDICTION_NOISE_DRAWS = 8
#: the difference is "noise" when within this factor of what the noise predicts
NOISE_AGREEMENT_FACTOR = 1.5
#: two recordings of one trajectory have the same period to this fraction (the
#: supplied recordings of "one": 1e-5)
SAME_PERIOD_FRACTION = 1e-3
#: phase samples of the one-period comparison, per second of period
PHASE_SAMPLES_PER_S = 200.0


def residual(arm: Arm, run: ProcessedRun) -> np.ndarray:
    """measured - predicted, in the run's band (N, 7)."""
    return run.tau - run.in_band(arm.identified.predict(run.q, run.dq, run.ddq))


def prediction_noise(arm: Arm, run: ProcessedRun, seed: int = 0, draws: int = PREDICTION_NOISE_DRAWS) -> np.ndarray:
    """Per joint, the RMS of what the positions' noise moves the model's prediction by, in the band (periodic runs):
    the series' coefficients drawn from their measured variance, added to the run's positions (a window of a run keeps
    its phase); a joint the run did not record has no noise."""
    analysis = run.periodic
    t = run.t - run.t[0]
    nominal = arm.identified.predict(run.q, run.dq, run.ddq)
    std = np.sqrt(np.nan_to_num(analysis.position_noise.coefficient_variance()))
    design = [harmonic_design(t, analysis.period.frequency_hz, analysis.harmonics, derivative) for derivative in range(3)]
    rng = np.random.default_rng(seed)
    moved = []
    for _ in range(draws):
        drawn = std * rng.standard_normal(std.shape)
        moved.append(run.in_band(arm.identified.predict(*(x + d @ drawn for x, d in zip((run.q, run.dq, run.ddq), design))) - nominal))
    return np.where(run.measured, rms(np.concatenate(moved)), 0.0)


def residual_noise(arm: Arm, run: ProcessedRun, draws: int = PREDICTION_NOISE_DRAWS) -> np.ndarray:
    """Per joint, the noise of a periodic run's model residual: its efforts' and its inputs' in squares (the
    simulation is driven by the projected positions, whose noise the accelerations raise by (k w)^2 at harmonic k:
    on "two", J1..J3 0.007 / 0.010 / 0.005 N·m against the efforts' 0.005 / 0.010 / 0.007)."""
    return np.hypot(np.nan_to_num(run.periodic.effort_noise.projected_rms), prediction_noise(arm, run, draws=draws))


def _phase_shift(a: ProcessedRun, b: ProcessedRun, phase: np.ndarray) -> float:
    """The fraction of a period by which b's positions lag a's (best match in
    the least-squares sense); refused when they do not match there."""
    qa = a.periodic.positions(phase * a.periodic.period.period_s)
    scale = 1.0 / np.maximum(qa.std(axis=0), 1e-12)

    def mismatch(shift: float) -> float:
        qb = b.periodic.positions(((phase + shift) % 1.0) * b.periodic.period.period_s)
        return float(np.sum(((qa - qb) * scale) ** 2))

    coarse = phase[np.argmin([mismatch(s) for s in phase])]
    step = phase[1] - phase[0]
    found = scipy.optimize.minimize_scalar(mismatch, bounds=(coarse - step, coarse + step), method="bounded")
    qb = b.periodic.positions(((phase + found.x) % 1.0) * b.periodic.period.period_s)
    if float(rms(qa - qb, axis=None)) > SAME_MOTION_POSITION_RMS:
        raise DvrkDartError(f"the positions differ by {float(rms(qa - qb, axis=None)):.3g} RMS (rad, m) at the best phase: not the same trajectory")
    return float(found.x)


def _one_period(arm: Arm, run: ProcessedRun, phase: np.ndarray) -> np.ndarray:
    series = run.periodic.projector.series(residual(arm, run))
    return series(phase * run.periodic.period.period_s)


def aligned_residuals(arm: Arm, a: ProcessedRun, b: ProcessedRun) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(phase, a's residual, b's residual) over one period of a, b shifted to where its positions match a's (periodic runs)."""
    samples = int(math.ceil(a.periodic.period.period_s * PHASE_SAMPLES_PER_S))
    phase = np.arange(samples) / samples
    shift = _phase_shift(a, b, phase)
    return phase, _one_period(arm, a, phase), _one_period(arm, b, (phase + shift) % 1.0)


def residual_difference(arm: Arm, a: ProcessedRun, b: ProcessedRun) -> np.ndarray:
    """a's residual minus b's: over one period on a common phase (periodic), or sample by sample (upstream)."""
    if a.periodic is None:
        n = min(len(a), len(b))
        return residual(arm, a)[:n] - residual(arm, b)[:n]
    _, ra, rb = aligned_residuals(arm, a, b)
    return ra - rb


def floor_table(arm: Arm, a: ProcessedRun, b: ProcessedRun) -> dict:
    """Per joint: the RMS difference of the residuals, the same after each run's
    mean, what the runs' noise predicts for it, and which it is."""
    difference = residual_difference(arm, a, b)
    both = np.asarray(a.measured) & np.asarray(b.measured)  # no figure on a joint either run did not record

    def figures(values) -> list:
        return per_measured_joint(values, both)

    result = {
        "joints": list(JOINT_NAMES), "units": [arm.model.effort_unit(j) for j in JOINT_NAMES],
        "rms_difference": figures(rms(difference)),
        "rms_difference_demeaned": figures(rms(difference - difference.mean(axis=0))),
        # one session's deviation: the difference carries two (diagnose --repeat's floor; demeaned where it fits each run's constant)
        "one_session": figures(rms(difference) / np.sqrt(2.0)),
        "noise_predicted_rms": None, "ratio_to_noise": None, "verdict": None,
        "noise_reason": "upstream processing measures no noise (use --processing periodic)",
    }
    if a.periodic is None:
        return result
    predicted = np.hypot(residual_noise(arm, a), residual_noise(arm, b))
    demeaned = rms(difference - difference.mean(axis=0))
    ratio = demeaned / np.maximum(predicted, np.finfo(float).tiny)
    moved_constant = moved_constants(difference, a.rate_hz)
    result.update({
        "noise_predicted_rms": figures(predicted), "ratio_to_noise": figures(ratio),
        "noise_reason": "each run's effort noise (lines between harmonics) and its positions' noise through the model, in squares",
        "verdict": [_verdict(r, m) if on else None for r, m, on in zip(ratio, moved_constant, both)],
    })
    return result


def _verdict(ratio: float, moved_constant: bool) -> str:
    constant = "; the constant moves between sessions" if moved_constant else ""
    if ratio <= NOISE_AGREEMENT_FACTOR:
        return f"noise{constant}"
    return f"a session effect beyond the noise ({ratio:.1f}x the noise after the means){constant}"


def check_repeat(a: ProcessedRun, b: ProcessedRun) -> None:
    """Two recordings of one trajectory: the same period (periodic; the
    positions are compared at the best phase later) or the same motion
    (upstream), with the same joints' positions (a joint one run holds at 0
    would read as a session change); the efforts are compared on the joints
    both recorded."""
    moving = [spanning_columns(run.q) for run in (a, b)]
    if not np.array_equal(*moving):
        joints = [", ".join(n for n, on in zip(JOINT_NAMES, m) if on) or "none" for m in moving]
        raise DvrkDartError(f"its positions move {joints[1]} but the measured run's positions move {joints[0]}: two sessions are compared "
                            "on runs that record the same joints' positions (a joint one run holds at 0 reads as a session change)")
    if a.periodic is not None:
        pa, pb = a.periodic.period, b.periodic.period
        if abs(pa.period_s - pb.period_s) > SAME_PERIOD_FRACTION * pa.period_s:
            raise DvrkDartError(f"period {pb.period_s:.4f} s, not {pa.period_s:.4f} s: not the same trajectory")
        return
    if why := not_comparable_sample_by_sample(a, b):
        raise DvrkDartError(why)
    n = min(len(a), len(b))
    if not same_motion(a.head(n), b.head(n)):
        raise DvrkDartError("not the same motion sample by sample")
    if len(a) != len(b):
        say_once([f"the two runs compared on the first {n} processed samples ({n / a.rate_hz:.1f} s), which both have"])


def processed_pair(names: tuple[str, str], processing: str | None, model: PsmModel, topics: BagTopics = BagTopics()) -> list[ProcessedRun]:
    """Two recordings of `model`'s arm through one processing (None: every
    command's default); periodic ones on their common (smaller) harmonic
    cutoff. The same file twice is refused."""
    from dvrk_dart.io.reference_data import distinct_inputs, load_run, resolve_run
    from dvrk_dart.io.signal import process, process_all

    distinct_inputs([("--measured", names[0]), ("--repeat", names[1])], model, topics)  # a floor needs two sessions
    paths = [resolve_run(name) for name in names]
    measured = [load_run(path, model, topics) for path in paths]
    runs, _ = process_all(measured, processing)
    processing = runs[0].processing
    if processing == "periodic":
        harmonics = min(run.periodic.harmonics for run in runs)
        runs = [process(run, processing, harmonics) for run in measured]
    return runs

"""The one RMS and relative-error definitions used everywhere."""

from __future__ import annotations

import math

import numpy as np


def rms(error: np.ndarray, axis: int | None = 0) -> np.ndarray:
    """Root mean square along `axis` (per joint for an (N, 7) array; None: over every element)."""
    error = np.asarray(error, dtype=float)
    return np.sqrt(np.mean(error**2, axis=axis))


#: N·m or N: a reference effort whose RMS is below this is no effort (a joint
#: a simulation leaves unloaded: ~1e-9), and a ratio to it is round-off
NEGLIGIBLE_EFFORT_RMS = 1e-6


def relative_error(actual: np.ndarray, reference: np.ndarray, axis: int = 0) -> np.ndarray:
    """||actual - reference|| / ||reference|| per joint (the upstream metric);
    NaN (not determined) where the reference is negligible throughout."""
    actual, reference = np.asarray(actual, dtype=float), np.asarray(reference, dtype=float)
    size = np.linalg.norm(reference, axis=axis)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(rms(reference, axis=axis) > NEGLIGIBLE_EFFORT_RMS, np.linalg.norm(actual - reference, axis=axis) / size, np.nan)


def per_measured_joint(values, measured) -> list:
    """Per-joint figures as a list, `None` (not measured) where the run did not record the joint."""
    return [float(v) if m else None for v, m in zip(np.asarray(values, dtype=float), measured)]


#: the largest lag (samples) of an autocorrelation summed
MAX_AUTOCORRELATION_LAG = 2000


def integrated_autocorrelation_time(x: np.ndarray) -> float:
    """1 + 2 sum of the autocorrelation up to its first non-positive value (samples)."""
    x = np.asarray(x, dtype=float) - np.mean(x)
    n = len(x)
    if n < 2 or not np.any(x):
        return 1.0
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    acf = acf / acf[0]
    lags = acf[1:min(n, MAX_AUTOCORRELATION_LAG)]
    stop = np.flatnonzero(lags <= 0.0)
    return float(1.0 + 2.0 * np.sum(lags[: stop[0] if len(stop) else len(lags)]))


#: torque-mode tracking is judged after the closed loop's initial transient (s)
TORQUE_TRANSIENT_S = 1.0

#: the motion regime of whole-run values (the analysis's other regimes select samples)
REGIME_ALL = "all"


#: a joint's constant effort moves from session to session when two sessions'
#: mean efforts differ by more than this many standard errors: a level over the
#: seven joints together (noise alone, 13-60 s at 200 Hz, 2000 draws: 2 flagged
#: some joint in 31-40 % of the pairs, a nuisance offset that then took a
#: payload's J1 gravity; 3 flags one in 2-7 %). The real repeat pair's q2, q3,
#: q4 stand at 10.5, 4.1 and 3.4, the others under 2 (models/psm/psm.toml)
SESSION_OFFSET_STANDARD_ERRORS = 3.0
#: blocks of a residual whose means are independent (the samples are correlated over ~0.05 s)
MEAN_BLOCK_S = 1.0


def mean_standard_error(residual: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per joint, the standard error of a run's mean effort, from the spread of
    its block means (the samples are correlated over ~0.05 s, blocks are not)."""
    block = max(1, int(round(MEAN_BLOCK_S * rate_hz)))
    n_blocks = max(2, len(residual) // block)
    means = np.array([part.mean(axis=0) for part in np.array_split(residual, n_blocks)])
    return means.std(axis=0, ddof=1) / math.sqrt(n_blocks)


def moved_constants(difference: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per joint, whether a session moves its constant effort: the mean
    difference of two runs of the same motion in two sessions (their gaps, or
    their residuals) is more than SESSION_OFFSET_STANDARD_ERRORS standard errors
    from zero. The one rule of the diagnosis and of `session-floor`."""
    return np.abs(difference.mean(axis=0)) > SESSION_OFFSET_STANDARD_ERRORS * mean_standard_error(difference, rate_hz)


def constant_move_bound(difference: np.ndarray, rate_hz: float) -> np.ndarray:
    """Per joint, the largest constant move two sessions' mean difference leaves possible: its size plus
    SESSION_OFFSET_STANDARD_ERRORS standard errors."""
    return np.abs(difference.mean(axis=0)) + SESSION_OFFSET_STANDARD_ERRORS * mean_standard_error(difference, rate_hz)


def moves_ruled_out(difference: np.ndarray, rate_hz: float, sizes) -> np.ndarray:
    """Per joint, whether two sessions' mean difference rules out a constant move of `sizes`; nowhere without sizes."""
    if sizes is None:
        return np.zeros(difference.shape[1], dtype=bool)
    return constant_move_bound(difference, rate_hz) < np.asarray(sizes, dtype=float)

"""The base period of a periodic excitation, fitted from the positions (io/periodic.py
is the layer built on it): a coarse search from the positions' autocorrelation,
then a Gauss-Newton fit of the frequency of their harmonic series, with a
standard error, checked (periodic, two whole periods or more, stable); and the
design's harmonics read from the positions."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize

from dvrk_dart.errors import DvrkDartError

#: a position span at or below this (rad or m) is a still joint's round-off, far below any encoder's step
STILL_SPAN = 1e-9
#: the fewest whole periods a run must hold (the noise is their scatter)
MIN_PERIODS = 2
#: a run is periodic when its positions' harmonic series at the fitted period
#: explains at least this fraction of their variance (every joint pooled, each
#: scaled to unit variance); trajectories "one" and "two": > 0.9999
MIN_EXPLAINED_VARIANCE = 0.99
#: the positions repeat when their autocorrelation at the period's lag (each
#: joint at unit variance) reaches this; trajectories "one" and "two": > 0.99
MIN_REPEAT_CORRELATION = 0.8
#: harmonics of the positions in the coarse-to-fine period search (the
#: identification's excitations are 5- and 6-harmonic series)
SEARCH_HARMONICS = 6
#: a joint moves when its positions' standard deviation is at least this
#: fraction of the most moving joint's (rad and m alike: a held joint's servo
#: error is < 0.1 % of a moving one's, an excited insertion ~5 %)
MOTION_FRACTION = 0.01
#: the design's harmonics read from the positions: the fewest whose series
#: explains the moving joints' positions (each at unit variance) to this
#: fraction of their variance (the supplied excitations: 0.2-0.9 below their
#: 5 or 6 harmonics, 0.9997-0.99997 at them: the tracking error is the rest)
DESIGN_EXPLAINED_VARIANCE = 0.999
DESIGN_MAX_HARMONICS = 20
#: a run plays an --excitation when its fitted period is the design's within this fraction (a controller's clock: < 1e-4)
DESIGN_PERIOD_TOLERANCE = 0.01
#: harmonics of the positions in the final Gauss-Newton fit of the period (the
#: measured positions of "one" and "two" stand above their noise up to ~30-60),
#: and its iterations (it converges in two or three)
REFINE_HARMONICS = 40
REFINE_ITERATIONS = 5
#: the period fitted on each half of a run is unstable when the halves differ
#: by more than this many combined standard errors and by enough to drift the
#: fundamental's phase by more than MAX_DRIFT_CYCLES over the run (harmonic k:
#: k times that); the supplied runs drift by < 1e-4 cycle, a 1 % chirp by 0.02
STABLE_PERIOD_STANDARD_ERRORS = 5.0
MAX_DRIFT_CYCLES = 0.005



@dataclass(frozen=True)
class Period:
    """A fitted base period: value and standard error (s), and the whole periods in the run."""

    period_s: float
    standard_error_s: float
    whole_periods: int

    @property
    def frequency_hz(self) -> float:
        return 1.0 / self.period_s


def harmonic_design(t: np.ndarray, frequency_hz: float, harmonics: int, derivative: int = 0) -> np.ndarray:
    """(N, 2K+1) columns [1, cos w t, sin w t, ..., cos K w t, sin K w t], or their time derivative."""
    w = 2.0 * math.pi * frequency_hz * np.arange(1, harmonics + 1)
    # e^{i k w1 t} as powers of e^{i w1 t}: far cheaper than K cosines and sines per sample
    powers = np.cumprod(np.broadcast_to(np.exp(1j * w[0] * np.asarray(t, dtype=float))[:, None], (len(t), harmonics)), axis=1) \
        if harmonics else np.zeros((len(t), 0), complex)
    if derivative < 0:
        raise ValueError(f"derivative {derivative}: not a derivative")
    powers = powers * (1j * w) ** derivative
    columns = np.empty((len(t), 2 * harmonics + 1))
    columns[:, 0] = 1.0 if derivative == 0 else 0.0
    columns[:, 1::2], columns[:, 2::2] = powers.real, powers.imag
    return columns


def least_squares(A: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """argmin ||A C - Y|| through the normal equations: harmonic columns over
    two periods or more are nearly orthogonal, so A^T A is well conditioned."""
    factor = scipy.linalg.cho_factor(A.T @ A)
    return scipy.linalg.cho_solve(factor, A.T @ Y)


def _unit_variance(x: np.ndarray) -> np.ndarray:
    x = x - x.mean(axis=0)
    scale = x.std(axis=0)
    return x[:, scale > 0] / scale[scale > 0]


def _coarse_period_samples(x: np.ndarray) -> int:
    """The lag (samples) of the autocorrelation's highest peak, or of the
    shortest lag that repeats as well (a peak at 2T is as high as at T)."""
    n = len(x)
    spectrum = np.fft.rfft(x, 2 * n, axis=0)
    acf = np.fft.irfft(np.abs(spectrum) ** 2, axis=0)[:n].sum(axis=1)
    acf = acf / (acf[0] * (n - np.arange(n)) / n)  # unbiased: each lag over its overlap
    # a little past half the run: a run of exactly two periods peaks at its middle,
    # and a peak just beyond it is refused by the count of whole periods, with its figure
    usable = acf[: int(n / MIN_PERIODS * 1.05) + 3]
    first_negative = np.flatnonzero(usable < 0)
    if not len(first_negative):
        raise DvrkDartError("its positions never decorrelate within half the run: not a periodic excitation of two periods or more")
    start = first_negative[0]
    peaks = start + np.flatnonzero((usable[start + 1 : -1] >= usable[start:-2]) & (usable[start + 1 : -1] >= usable[start + 2 :])) + 1
    if not len(peaks):
        raise DvrkDartError("its positions do not repeat within half the run: not a periodic excitation of two periods or more")
    best = usable[peaks].max()
    if best < MIN_REPEAT_CORRELATION:
        raise DvrkDartError(f"its positions do not repeat within half the run (autocorrelation at most {best:.2f}): "
                            "not a periodic excitation of two periods or more")
    return int(peaks[usable[peaks] >= 0.95 * best][0])


def _residual_energy(frequency_hz: float, t: np.ndarray, x: np.ndarray, harmonics: int) -> float:
    A = harmonic_design(t, frequency_hz, harmonics)
    return float(np.sum((x - A @ least_squares(A, x)) ** 2))


def _gauss_newton(frequency_hz: float, t: np.ndarray, x: np.ndarray, harmonics: int) -> tuple[float, float]:
    """(step, standard error) of the base frequency at `frequency_hz`: one
    Gauss-Newton step of the variable-projection problem (the coefficients
    fitted at each frequency), each joint weighted by its residual variance,
    the information divided by the residuals' correlation time."""
    from dvrk_dart.metrics import integrated_autocorrelation_time

    A = harmonic_design(t, frequency_hz, harmonics)
    factor = scipy.linalg.cho_factor(A.T @ A)
    coefficients = scipy.linalg.cho_solve(factor, A.T @ x)
    residual = x - A @ coefficients
    # d(series)/d(frequency) = t * d(series)/dt / frequency, less what the coefficients absorb
    sensitivity = (t[:, None] * (harmonic_design(t, frequency_hz, harmonics, 1) @ coefficients)) / frequency_hz
    sensitivity -= A @ scipy.linalg.cho_solve(factor, A.T @ sensitivity)
    variance = residual.var(axis=0)
    used = variance > 0
    weight = 1.0 / variance[used]
    gradient = float(np.sum(weight * np.sum(sensitivity[:, used] * residual[:, used], axis=0)))
    curvature = float(np.sum(weight * np.sum(sensitivity[:, used] ** 2, axis=0)))
    correlation = np.array([integrated_autocorrelation_time(residual[:, j]) for j in np.flatnonzero(used)])
    information = float(np.sum(weight * np.sum(sensitivity[:, used] ** 2, axis=0) / correlation))
    if curvature <= 0 or information <= 0:
        return 0.0, math.inf
    return gradient / curvature, 1.0 / math.sqrt(information)


def _fit_frequency(t: np.ndarray, x: np.ndarray, rate_hz: float, start_hz: float | None = None) -> tuple[float, float]:
    """(frequency, its standard error) from positions scaled to unit variance:
    a bounded search with few harmonics around the autocorrelation's lag
    (unless a start is given), then Gauss-Newton with many (the harmonics
    left out would bias it on a span of a non-integer number of periods)."""
    if start_hz is None:
        lag = _coarse_period_samples(x)
        # the coarse lag is within a sample of the period
        bounds = (rate_hz / (lag + 1), rate_hz / (lag - 1))
        found = scipy.optimize.minimize_scalar(_residual_energy, bounds=bounds, args=(t, x, SEARCH_HARMONICS), method="bounded",
                                               options={"xatol": rate_hz / lag * 1e-9})
        start_hz = float(found.x)
    frequency = start_hz
    harmonics = min(REFINE_HARMONICS, max(SEARCH_HARMONICS, int(rate_hz / frequency) // 2 - 1))
    for _ in range(REFINE_ITERATIONS):
        step, standard_error = _gauss_newton(frequency, t, x, harmonics)
        frequency += step
        if abs(step) < 0.01 * standard_error:
            break
    return frequency, standard_error


def spanning_columns(q: np.ndarray) -> np.ndarray:
    """(n,) bool: the columns of positions that move at all (beyond STILL_SPAN)."""
    return np.ptp(q, axis=0) > STILL_SPAN


def moving_joints(q: np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
    """(n,) bool: the measured joints whose positions move (`MOTION_FRACTION`)."""
    spread = np.std(q, axis=0)
    if measured is not None:
        spread = np.where(measured, spread, 0.0)
    return (spread > 0) & (spread >= MOTION_FRACTION * spread.max())


def fit_period(t: np.ndarray, q: np.ndarray, rate_hz: float, where: str, start_period_s: float | None = None,
               checked: bool = True) -> Period:
    """The base period of a run's positions (the moving joints' columns),
    checked (`check_periodic`; `checked` False: two whole periods only, for a
    first estimate whose run may still have a start or end transient).
    `start_period_s`: the design's period, where it is known (refined on the data)."""
    x = _unit_variance(q)
    if x.shape[1] == 0:
        raise DvrkDartError(f"{where}: the arm does not move: not a periodic excitation")
    try:
        start_hz = None if start_period_s is None else 1.0 / start_period_s
        frequency, standard_error = _fit_frequency(t, x, rate_hz, start_hz)
    except DvrkDartError as exc:
        raise DvrkDartError(f"{where}: {exc}") from None
    # N samples span N sample intervals: a run of exactly two periods holds two whole ones, and a fitted
    # period longer by its standard error must not lose one (a run of 3 periods read as 2.9999991 of them):
    # a period short of half a sample counts whole
    span_s = len(t) / rate_hz
    whole = int(math.floor((span_s + 0.5 / rate_hz) * frequency))
    if whole < MIN_PERIODS:
        raise DvrkDartError(f"{where}: {span_s * frequency:.2f} periods of {1 / frequency:.3f} s, at least {MIN_PERIODS} needed")
    period = Period(1.0 / frequency, standard_error / frequency**2, whole)
    if checked:
        check_periodic(t, q, rate_hz, where, period)
    return period


def check_periodic(t: np.ndarray, q: np.ndarray, rate_hz: float, where: str, period: Period) -> None:
    """One line unless the positions are a periodic excitation of `period`: its series explains them, and the
    period is the same in both halves of the run."""
    x = _unit_variance(q)
    frequency = period.frequency_hz
    # as many harmonics as a design may have: an 8-harmonic excitation is periodic too
    explained = 1.0 - _residual_energy(frequency, t, x, DESIGN_MAX_HARMONICS) / float(np.sum(x**2))
    if explained < MIN_EXPLAINED_VARIANCE:
        raise DvrkDartError(f"{where}: a {DESIGN_MAX_HARMONICS}-harmonic series of period {1 / frequency:.3f} s explains "
                            f"{explained:.1%} of the positions' variance (< {MIN_EXPLAINED_VARIANCE:.0%}): not a periodic excitation")
    half = len(t) // 2
    halves = [_fit_frequency(t[part], x[part], rate_hz, frequency) for part in (slice(0, half), slice(half, None))]
    (f1, s1), (f2, s2) = halves
    drift_cycles = abs(f1 - f2) * (t[-1] - t[0])
    if abs(f1 - f2) > STABLE_PERIOD_STANDARD_ERRORS * math.hypot(s1, s2) and drift_cycles > MAX_DRIFT_CYCLES:
        raise DvrkDartError(f"{where}: unstable period: {1 / f1:.4f} s in the first half, {1 / f2:.4f} s in the second "
                            f"(standard errors {s1 / f1**2:.1e}, {s2 / f2**2:.1e} s)")


def design_harmonics(t: np.ndarray, q_moving: np.ndarray, period: Period) -> int:
    """The fewest harmonics whose series explains the moving joints' positions
    to `DESIGN_EXPLAINED_VARIANCE` (the excitation's design, read from the run)."""
    x = _unit_variance(q_moving)
    total = float(np.sum(x**2))
    for k in range(1, DESIGN_MAX_HARMONICS + 1):
        if 1.0 - _residual_energy(period.frequency_hz, t, x, k) / total >= DESIGN_EXPLAINED_VARIANCE:
            return k
    return DESIGN_MAX_HARMONICS

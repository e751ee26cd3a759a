"""The periodic signal layer: an excitation run as its harmonic series.

The identification's excitations repeat a Fourier series; a run holds several
periods of it. On such a run the classical practice of identification with
periodic excitation (Swevers et al. 1997; Pintelon and Schoukens, noise from
the scatter between periods) gives signals far cleaner than filtering and
differentiating (io/signal.py, upstream's processing):

- the base period is fitted from the positions (no nominal frequency: a lab's
  excitation has its own), with a standard error;
- positions and efforts are projected on the harmonics of that period up to a
  cutoff read from the data; velocities and accelerations are the analytic
  derivatives of the position series, so no noise is differentiated;
- the noise is measured, not assumed: in the DFT of whole periods, the lines
  between the harmonics hold only what does not repeat from one period to the
  next (noise, drift), and their level around each harmonic is that
  harmonic's noise;
- a model's prediction is projected on the same harmonics (`ProcessedRun.in_band`),
  so that both sides of a comparison see the same band.

The cutoff: a joint's efforts' harmonics stand above their noise up to some
order, then sink into it. Each joint's cutoff is read from its own spectrum:
the last harmonic before the first run of `CUTOFF_RUN` consecutive harmonics
whose power is less than `CUTOFF_SNR` times the local noise power. The run's
band (`harmonics`) is the smallest cutoff of the joints that move and were
recorded: every such joint's efforts are then clearly above their noise in
the kept band, and the analytic accelerations (which weigh harmonic k by k^2)
carry little position noise. A joint the run did not record, or that does not
move (a held wrist: its efforts are coupling and noise), has no say. One band
for every joint, because a joint's efforts depend on every joint's motion:
the regressor and the predictions are projected on the same harmonics as the
measured efforts. A moving joint's efforts carry at least the excitation's
design harmonics (its motion's own), so the band keeps at least those, known
from `--excitation` or read from the positions (`design_harmonics`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.optimize

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.transient import TRANSIENT_RATIO, WINDOW_PERIOD_FRACTION, steady_span

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
#: the cutoff rule (module docstring): power ratio and run length
CUTOFF_SNR = 10.0
CUTOFF_RUN = 3
#: harmonics fitted before the noise is read (and the highest cutoff): the
#: efforts of "one" and "two" sink into their noise at ~30-60
NOISE_FIT_HARMONICS = 80
#: noise around a harmonic: the non-harmonic DFT lines within this many
#: harmonics on either side
NOISE_WINDOW_HARMONICS = 2
#: ... and at least this many DFT lines on either side: a run of two or three
#: periods has only one or two noise lines between harmonics, too few to
#: average (four periods, as "one" and "two", already reach it)
MIN_NOISE_WINDOW_LINES = 8
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


@dataclass(frozen=True)
class Noise:
    """What does not repeat from one period to the next, per joint (columns).

    `per_sample_rms`: the noise of one raw sample; `projected_rms`: what of it
    is left in the projection on the kept harmonics; `harmonic_variance[k]`:
    the variance of harmonic k's cosine (or sine) coefficient as the whole run
    estimates it (k = 0: the mean). Estimated from `whole_periods` periods.
    """

    per_sample_rms: np.ndarray
    projected_rms: np.ndarray
    harmonic_variance: np.ndarray
    whole_periods: int

    def coefficient_variance(self) -> np.ndarray:
        """(2K+1, n) the variance of each coefficient of `harmonic_design`'s columns: the mean's, then each harmonic's for its cosine and its sine."""
        return np.repeat(self.harmonic_variance, 2, axis=0)[1:]


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


def moving_joints(q: np.ndarray, measured: np.ndarray | None = None) -> np.ndarray:
    """(n,) bool: the measured joints whose positions move (`MOTION_FRACTION`)."""
    spread = np.std(q, axis=0)
    if measured is not None:
        spread = np.where(measured, spread, 0.0)
    return (spread > 0) & (spread >= MOTION_FRACTION * spread.max())


def fit_period(t: np.ndarray, q: np.ndarray, rate_hz: float, where: str, start_period_s: float | None = None) -> Period:
    """The base period of a run's positions (the moving joints' columns),
    checked: periodic, two whole periods or more, stable. `start_period_s`:
    the design's period, where it is known (refined on the data)."""
    x = _unit_variance(q)
    if x.shape[1] == 0:
        raise DvrkDartError(f"{where}: the arm does not move: not a periodic excitation")
    try:
        start_hz = None if start_period_s is None else 1.0 / start_period_s
        frequency, standard_error = _fit_frequency(t, x, rate_hz, start_hz)
    except DvrkDartError as exc:
        raise DvrkDartError(f"{where}: {exc}") from None
    # N samples span N sample intervals: a run of exactly two periods holds two whole ones
    span_s = len(t) / rate_hz
    whole = int(math.floor(span_s * frequency + 1e-9))
    if whole < MIN_PERIODS:
        raise DvrkDartError(f"{where}: {span_s * frequency:.2f} periods of {1 / frequency:.3f} s, at least {MIN_PERIODS} needed")
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
    return Period(1.0 / frequency, standard_error / frequency**2, whole)


@dataclass(frozen=True)
class _Spectrum:
    """Per joint: each harmonic's power and the local noise power (DFT of whole periods)."""

    harmonic_power: np.ndarray  # (K_max + 1, n)
    noise_power: np.ndarray  # (K_max + 1, n), per DFT line
    per_sample_variance: np.ndarray  # (n,)


def _spectrum(t: np.ndarray, x: np.ndarray, period: Period, rate_hz: float) -> _Spectrum:
    """Harmonic powers from the least-squares series (the first NOISE_FIT_HARMONICS),
    noise from the DFT lines between harmonics of what the series leaves over
    whole periods (the series removed first: a span of a non-integer number of
    samples per period would leak the strong harmonics into the noise lines)."""
    periods = period.whole_periods
    span = min(int(round(periods * period.period_s * rate_hz)), len(t))
    harmonics = min(NOISE_FIT_HARMONICS, int(period.period_s * rate_hz) // 2 - 1)
    A = harmonic_design(t, period.frequency_hz, harmonics)
    coefficients = least_squares(A, x)
    left = (x - A @ coefficients)[:span]
    lines = np.abs(np.fft.rfft(left - left.mean(axis=0), axis=0)) ** 2 / span
    index = np.arange(len(lines))
    noise_line = (index % periods != 0) & (index > 0)
    window = max(NOISE_WINDOW_HARMONICS * periods, MIN_NOISE_WINDOW_LINES)
    noise = np.empty((harmonics + 1, x.shape[1]))
    for k in range(harmonics + 1):
        around = slice(max(1, k * periods - window), k * periods + window + 1)
        noise[k] = lines[around][noise_line[around]].mean(axis=0)
    # a harmonic's power in DFT-line units over the span: span (a^2 + b^2) / 4
    power = np.vstack([np.zeros((1, x.shape[1])), span * (coefficients[1::2] ** 2 + coefficients[2::2] ** 2) / 4.0])
    return _Spectrum(power, noise, lines[noise_line].mean(axis=0))


def joint_cutoffs(spectrum: _Spectrum) -> np.ndarray:
    """(n,) the module docstring's cutoff rule on each column's own spectrum (at least 1)."""
    ratio = spectrum.harmonic_power[1:] / np.maximum(spectrum.noise_power[1:], np.finfo(float).tiny)
    below = (ratio < CUTOFF_SNR).astype(int)
    runs = np.apply_along_axis(lambda b: np.convolve(b, np.ones(CUTOFF_RUN, dtype=int), "valid"), 0, below)
    cutoffs = np.empty(ratio.shape[1], dtype=int)
    for j in range(ratio.shape[1]):
        sunk = np.flatnonzero(runs[:, j] >= CUTOFF_RUN)
        cutoffs[j] = max(1, int(sunk[0]) if len(sunk) else ratio.shape[0])
    return cutoffs


def design_harmonics(t: np.ndarray, q_moving: np.ndarray, period: Period) -> int:
    """The fewest harmonics whose series explains the moving joints' positions
    to `DESIGN_EXPLAINED_VARIANCE` (the excitation's design, read from the run)."""
    x = _unit_variance(q_moving)
    total = float(np.sum(x**2))
    for k in range(1, DESIGN_MAX_HARMONICS + 1):
        if 1.0 - _residual_energy(period.frequency_hz, t, x, k) / total >= DESIGN_EXPLAINED_VARIANCE:
            return k
    return DESIGN_MAX_HARMONICS


def _noise(spectrum: _Spectrum, harmonics: int, samples: int, periods: int) -> Noise:
    variance = 2.0 * spectrum.noise_power[: harmonics + 1] / samples
    variance[0] /= 2.0  # the mean has one coefficient, not a cos/sin pair
    projected = variance[0] + variance[1:].sum(axis=0)
    return Noise(np.sqrt(spectrum.per_sample_variance), np.sqrt(projected), variance, periods)


@dataclass(frozen=True)
class HarmonicSeries:
    """Columns as series of harmonics of one base frequency: coefficients (2K+1, n) of `harmonic_design`."""

    frequency_hz: float
    coefficients: np.ndarray

    @property
    def harmonics(self) -> int:
        return (len(self.coefficients) - 1) // 2

    def __call__(self, t: np.ndarray, derivative: int = 0) -> np.ndarray:
        return harmonic_design(np.asarray(t, dtype=float), self.frequency_hz, self.harmonics, derivative) @ self.coefficients


@dataclass(frozen=True)
class Projector:
    """Least-squares projection of columns sampled at `t` on the harmonics (what `in_band` applies)."""

    t: np.ndarray
    frequency_hz: float
    harmonics: int
    _design: np.ndarray = field(repr=False, compare=False, default=None)
    _factors: tuple = field(repr=False, compare=False, default=None)

    def __post_init__(self):
        design = harmonic_design(self.t, self.frequency_hz, self.harmonics)
        object.__setattr__(self, "_design", design)
        # factored once: a run's every column (a regressor has hundreds) is projected with it
        object.__setattr__(self, "_factors", np.linalg.qr(design))

    def series(self, x: np.ndarray) -> HarmonicSeries:
        Q, R = self._factors
        coefficients = scipy.linalg.solve_triangular(R, Q.T @ np.asarray(x, dtype=float))
        return HarmonicSeries(self.frequency_hz, coefficients)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        flat = x.reshape(len(x), -1)
        return (self._design @ self.series(flat).coefficients).reshape(x.shape)


@dataclass(frozen=True)
class PeriodicAnalysis:
    """What the periodic layer found in a run: period, cutoff, series and noise."""

    period: Period
    harmonics: int
    positions: HarmonicSeries
    efforts: HarmonicSeries
    effort_noise: Noise
    position_noise: Noise
    projector: Projector
    #: each joint's own cutoff (0: not recorded); which joints move (they set the band)
    joint_cutoffs: tuple[int, ...] = ()
    moving: tuple[bool, ...] = ()
    design_harmonics: int = 0
    design_from: str = ""
    #: the run's samples analysed (start, stop): a start or end transient left out (`transient`)
    kept: tuple[int, int] = (0, 0)

    @property
    def measured(self) -> tuple[bool, ...]:
        return tuple(k > 0 for k in self.joint_cutoffs)

    def summary(self) -> dict:
        """The figures every output records (per joint: `None` where the run did not record it)."""
        def per_joint(values):
            return [v if recorded else None for v, recorded in zip(values, self.measured)]

        return {
            "processing": "periodic",
            "period_s": self.period.period_s,
            "period_standard_error_s": self.period.standard_error_s,
            "whole_periods": self.period.whole_periods,
            "harmonics": self.harmonics,
            "joint_cutoffs": per_joint(self.joint_cutoffs),
            "moving_joints": [bool(m) for m in self.moving],
            "design_harmonics": self.design_harmonics,
            "design_from": self.design_from,
            "cutoff_rule": f"per joint: the last harmonic before {CUTOFF_RUN} consecutive harmonics of its efforts below "
                           f"{CUTOFF_SNR:g} x their local noise power; the band: the smallest of the moving, recorded joints', "
                           "at least the design's harmonics",
            "noise_rms": per_joint(self.effort_noise.projected_rms.tolist()),
            "noise_per_sample_rms": per_joint(self.effort_noise.per_sample_rms.tolist()),
            "position_noise_per_sample_rms": per_joint(self.position_noise.per_sample_rms.tolist()),
            "noise_periods": self.effort_noise.whole_periods,
            "samples_analysed": list(self.kept),
            "transient_rule": f"a start or end window ({WINDOW_PERIOD_FRACTION:.3g} of a period) whose efforts differ from a period "
                              f"away over {TRANSIENT_RATIO:g} x the run's median window is left out",
        }


def band_harmonics(cutoffs: np.ndarray, deciding: np.ndarray, floor: int) -> int:
    """The run's band: the smallest cutoff of the `deciding` joints (moving and recorded), at least `floor`."""
    if not deciding.any():
        return max(1, floor)
    return max(int(cutoffs[deciding].min()), floor)


def analyse(t: np.ndarray, q: np.ndarray, tau: np.ndarray, rate_hz: float, where: str, harmonics: int | None = None,
            measured: np.ndarray | None = None, design=None) -> PeriodicAnalysis:
    """The periodic layer on one run (raises a one-line DvrkDartError naming `where` if it is not periodic).
    `harmonics` imposes the band (runs compared with each other share the
    smaller one); `measured` (n,) bool: the joints the run recorded (default
    all); `design`: an ExcitationDesign (the commanded period and harmonics) where it is known."""
    t = np.asarray(t, dtype=float) - float(t[0])
    measured = np.ones(q.shape[1], bool) if measured is None else np.asarray(measured, bool)
    moving = moving_joints(q, measured)
    period = fit_period(t, q[:, moving], rate_hz, where)  # from the run itself: a design is checked against it, never imposed
    steady = steady_span(tau[:, measured], int(round(period.period_s * rate_hz)))
    if steady.stop - steady.start < len(t):  # a transient left out, the period fitted again without it
        t, q, tau = t[steady] - t[steady.start], q[steady], tau[steady]
        period = fit_period(t, q[:, moving], rate_hz, where)
    if design is not None and abs(period.period_s / design.period_s - 1.0) > DESIGN_PERIOD_TOLERANCE:
        raise DvrkDartError(f"--excitation {design.source}: its period {design.period_s:.4f} s is not the run's ({where}: "
                            f"{period.period_s:.4f} s fitted from it): the run did not play this excitation")
    floor = design.harmonics if design is not None else design_harmonics(t, q[:, moving], period)
    effort_spectrum = _spectrum(t, tau, period, rate_hz)
    top = len(effort_spectrum.harmonic_power) - 1
    own = joint_cutoffs(effort_spectrum)
    cutoffs = np.where(measured, np.minimum(np.where(moving, np.maximum(own, floor), own), top), 0)
    band = band_harmonics(cutoffs, moving, min(floor, top)) if harmonics is None else min(int(harmonics), top)
    projector = Projector(t, period.frequency_hz, band)
    position_spectrum = _spectrum(t, q, period, rate_hz)
    return PeriodicAnalysis(
        period, band, projector.series(q), projector.series(tau),
        _noise(effort_spectrum, band, len(t), period.whole_periods),
        _noise(position_spectrum, band, len(t), period.whole_periods),
        projector, tuple(int(k) for k in cutoffs), tuple(bool(m) for m in moving), int(floor),
        "--excitation " + design.source if design is not None else "the positions", (steady.start, steady.stop),
    )

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

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.optimize

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.csv_run import say_once
from dvrk_dart.io.excitation_design import harmonic_amplitudes
from dvrk_dart.io.transient import TRANSIENT_RATIO, WINDOW_PERIOD_FRACTION, steady_span
from dvrk_dart.io.period import DESIGN_PERIOD_TOLERANCE, Period, check_periodic, design_harmonics, fit_period, harmonic_design, least_squares, moving_joints

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


def silent_efforts(spectrum: _Spectrum, harmonics: int) -> np.ndarray:
    """(n,) bool: columns none of whose first `harmonics` (the design's: the motion's own) stands `CUTOFF_SNR`
    times above its noise: a moving joint's efforts carry its motion's harmonics (inertia, friction), so such a
    column holds no effort of this motion (a channel not logged, or noise): it has no say in the band. (The
    first 3 alone were too few: "two"'s J1 sits mostly on its 4th-6th.)"""
    top = max(1, harmonics) + 1
    ratio = spectrum.harmonic_power[1:top] / np.maximum(spectrum.noise_power[1:top], np.finfo(float).tiny)
    return np.all(ratio < CUTOFF_SNR, axis=0)


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
    #: moving joints whose efforts show nothing at the motion's first harmonics (`silent_efforts`): no say in the band
    silent: tuple[bool, ...] = ()

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
            "silent_efforts": [bool(x) for x in self.silent],
            "design_harmonics": self.design_harmonics,
            "design_from": self.design_from,
            "cutoff_rule": f"per joint: the last harmonic before {CUTOFF_RUN} consecutive harmonics of its efforts below "
                           f"{CUTOFF_SNR:g} x their local noise power; the band: the smallest of the moving, recorded joints', "
                           "at least the design's harmonics; a moving joint whose efforts are below that at every one of "
                           "the design's harmonics holds no effort of the motion (silent_efforts) and has no say",
            "noise_rms": per_joint(self.effort_noise.projected_rms.tolist()),
            "noise_per_sample_rms": per_joint(self.effort_noise.per_sample_rms.tolist()),
            "position_noise_per_sample_rms": per_joint(self.position_noise.per_sample_rms.tolist()),
            "noise_periods": self.effort_noise.whole_periods,
            "samples_analysed": list(self.kept),
            "transient_rule": f"a start or end window ({WINDOW_PERIOD_FRACTION:.3g} of a period) whose efforts differ from a period "
                              f"away over {TRANSIENT_RATIO:g} x the run's median window is left out",
        }


#: a joint's cutoff within this multiple of the design's harmonics and under 1 / this of every other deciding
#: joint's sets the band alone, as a dead-but-noisy channel would (joints' own cutoffs differ 2.5x on synthetic
#: DART runs of random designs: 28 against 72, the note is not for that)
LONE_BAND_FACTOR = 3


def _say_lone_band(cutoffs: np.ndarray, deciding: np.ndarray, band: int, floor: int, where: str) -> None:
    """A band near the design's harmonics that cuts other moving joints under a third of their own cutoffs: said,
    with the joints that set it (a weak or noisy channel of the wrist cut "two"'s band from 35 to 6 harmonics, and
    q2's figure by half; noisy wrist channels cut "one"'s from 33 to 8-10, unsaid while q4 was not alone)."""
    own = {j: int(k) for j, k in enumerate(cutoffs) if deciding[j]}
    cut = [j for j, k in own.items() if k > LONE_BAND_FACTOR * band]
    if band > LONE_BAND_FACTOR * floor or not cut:
        return
    setting = ", ".join(f"q{j + 1}" for j, k in own.items() if k <= band)
    reach = sorted({min(own[j] for j in cut), max(own[j] for j in cut)})
    say_once([f"{where}: the band ({band} harmonics) is {setting}'s own cutoff; {', '.join(f'q{j + 1}' for j in cut)} reach "
              f"{'-'.join(map(str, reach))} on their own, and every joint's figures are cut at the band (a weak or noisy "
              f"channel on {setting}?); --harmonics compares at another band"])


def _say_silent(silent: np.ndarray, where: str) -> None:
    if silent.any():
        names = [f"q{j + 1}" for j in np.flatnonzero(silent)]
        plural = len(names) > 1
        say_once([f"{where}: {', '.join(names)} {'move' if plural else 'moves'} but {'their' if plural else 'its'} efforts show "
                  "nothing at the motion's harmonics (a channel not logged, or noise): no say in the band (unless no joint has "
                  f"more); {'their' if plural else 'its'} figures compare the model with that channel"])


def _position_amplitudes(t: np.ndarray, q: np.ndarray, period: Period, harmonics: int) -> np.ndarray:
    """(harmonics, n) the run's position amplitudes on the design's first harmonics (excitation_design's layout)."""
    return harmonic_amplitudes(least_squares(harmonic_design(t, period.frequency_hz, harmonics), q), harmonics)


def _check_design_period(design, period: Period, where: str) -> None:
    """A commanded file whose period is not the run's: refused, with a hint where it is a rate's multiple."""
    if abs(period.period_s / design.period_s - 1.0) <= DESIGN_PERIOD_TOLERANCE:
        return
    ratio = design.period_s / period.period_s
    rate = next((f" (its period {1 / r:g}x the run's: a rate read wrong? a commanded log without a time column is read at "
                 "200 Hz, and a time column is in s)" for r in (0.001, 0.2, 0.5, 2.0, 5.0, 1000.0) if abs(ratio * r - 1.0) < 0.02), "")
    raise DvrkDartError(f"--excitation {design.source}: its period {design.period_s:.4f} s is not the run's ({where}: "
                        f"{period.period_s:.4f} s fitted from it): the run did not play this excitation{rate}")


def _band(cutoffs: np.ndarray, deciding: np.ndarray, floor: int, top: int, harmonics: int | None, where: str) -> int:
    """The run's band: `harmonics` where imposed (said when under the design's `floor`), else band_harmonics
    of the deciding joints (said when one joint alone sets it low)."""
    if harmonics is None:
        band = band_harmonics(cutoffs, deciding, min(floor, top))
        _say_lone_band(cutoffs, deciding, band, floor, where)
        return band
    band = min(int(harmonics), top)
    if band < floor:
        say_once([f"{where}: {band} harmonics imposed, fewer than the excitation's design ({floor}): the band cuts the motion "
                  "itself, and every figure with it"])
    return band


def band_harmonics(cutoffs: np.ndarray, deciding: np.ndarray, floor: int) -> int:
    """The run's band: the smallest cutoff of the `deciding` joints (moving and recorded), at least `floor`."""
    if not deciding.any():
        return max(1, floor)
    return max(int(cutoffs[deciding].min()), floor)


def analyse(t: np.ndarray, q: np.ndarray, tau: np.ndarray, rate_hz: float, where: str, harmonics: int | None = None,
            measured: np.ndarray | None = None, design=None, coupled: np.ndarray | None = None) -> PeriodicAnalysis:
    """The periodic layer on one run (raises a one-line DvrkDartError naming `where` if it is not periodic).
    `harmonics` imposes the band (runs compared with each other share the
    smaller one); `measured` (n,) bool: the joints the run recorded (default
    all); `design`: an ExcitationDesign (the commanded period and harmonics) where it is known; `coupled`: the
    joints whose dVRK values mix (a commanded file's may be either coordinates: not checked against the run)."""
    t = np.asarray(t, dtype=float) - float(t[0])
    measured = np.ones(q.shape[1], bool) if measured is None else np.asarray(measured, bool)
    coupled = np.zeros(q.shape[1], bool) if coupled is None else np.asarray(coupled, bool)
    moving = moving_joints(q, measured)
    # from the run itself (a design is checked against it, never imposed); checked once a transient is left out:
    # a run that goes from rest into the excitation (as `dvrk-dart excitation`'s bags play) is periodic after it
    period = fit_period(t, q[:, moving], rate_hz, where, checked=False)
    steady = steady_span(tau[:, measured], int(round(period.period_s * rate_hz)))
    if steady.stop - steady.start < len(t):  # a transient left out, the period fitted again without it
        t, q, tau = t[steady] - t[steady.start], q[steady], tau[steady]
        period = fit_period(t, q[:, moving], rate_hz, where)
    else:
        check_periodic(t, q[:, moving], rate_hz, where, period)
    if design is not None:
        _check_design_period(design, period, where)
    floor = design.harmonics if design is not None else design_harmonics(t, q[:, moving], period)
    effort_spectrum = _spectrum(t, tau, period, rate_hz)
    top = len(effort_spectrum.harmonic_power) - 1
    own = joint_cutoffs(effort_spectrum)
    cutoffs = np.where(measured, np.minimum(np.where(moving, np.maximum(own, floor), own), top), 0)
    silent = measured & moving & silent_efforts(effort_spectrum, min(floor, top))
    _say_silent(silent, where)
    if silent[measured & moving].all():
        silent[:] = False  # nothing else to decide the band: the run's own rules stand
    band = _band(cutoffs, moving & ~silent, floor, top, harmonics, where + ("" if design is None else f" (--excitation {design.source})"))
    projector = Projector(t, period.frequency_hz, band)
    if design is not None:
        design.check_played(_position_amplitudes(t, q, period, design.harmonics), measured & ~coupled, where)
    position_spectrum = _spectrum(t, q, period, rate_hz)
    return PeriodicAnalysis(
        period, band, projector.series(q), projector.series(tau),
        _noise(effort_spectrum, band, len(t), period.whole_periods),
        _noise(position_spectrum, band, len(t), period.whole_periods),
        projector, tuple(int(k) for k in cutoffs), tuple(bool(m) for m in moving), int(floor),
        "--excitation " + design.source if design is not None else "the positions", (steady.start, steady.stop),
        tuple(bool(x) for x in silent),
    )

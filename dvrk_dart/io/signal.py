"""Signal processing identical to the upstream identification (Wang et al. 2019,
`identification/data_processing.py`), so that our numbers compare with theirs.

- a 6th-order Butterworth low-pass with Wn = 2 pi fc / 200, fc the arm's
  ([processing] of its model card: the PSM's 5.4, a fraction of Nyquist: the
  effective cut-off is about 17 Hz, not 5.4 Hz),
- applied forward-backward with their odd extension of 3 * 7 = 21 samples,
- to q, to the *measured* dq and to tau; ddq is the 5-point central difference
  of the measured dq, then filtered the same way;
- 200 samples are cut from each end.

`process(run, "periodic")` gives the same ProcessedRun through the periodic
layer (io/periodic.py) instead: analytic q, dq, ddq and efforts projected on
the excitation's harmonics, with `in_band` projecting a prediction likewise.
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.periodic import PeriodicAnalysis, analyse
from dvrk_dart.io.measured_run import MeasuredRun, sample_rate_hz
from dvrk_dart.metrics import rms
from dvrk_dart.model.description import UpstreamProcessing

FILTER_ORDER = 6
CUT_SAMPLES = 200
#: the fewest samples a figure is computed on (an RMS of fewer is no statistic)
MIN_KEPT_SAMPLES = 10
#: the fewest rows a run needs: the processing's trimmed ends and those samples
MIN_ROWS = 2 * CUT_SAMPLES + MIN_KEPT_SAMPLES
#: the processings a measured run can go through
PROCESSINGS = ("upstream", "periodic")
#: periodic analyses kept by the content they were made of (a replay chooses its processing, then processes)
_ANALYSES: OrderedDict[tuple, PeriodicAnalysis] = OrderedDict()
_ANALYSES_KEPT = 8


@dataclass(frozen=True)
class ProcessedRun:
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    #: the periodic layer's findings (None: upstream processing)
    periodic: PeriodicAnalysis | None = field(default=None, compare=False)
    #: upstream's first period of this arm (samples; its model card's [processing]), None where not known
    upstream_first_period: int | None = field(default=None, compare=False)
    #: (7,) bool: the joints the run recorded (the others carry no figure, fit or cutoff)
    measured: np.ndarray | None = field(default=None, compare=False)
    #: the recording's row of the first sample (None: samples of no recording's rows, e.g. resampled)
    first_row: int | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.measured is None:
            object.__setattr__(self, "measured", np.ones(self.tau.shape[1], bool))

    def __len__(self) -> int:
        return len(self.t)

    @property
    def rate_hz(self) -> float:
        return float(1.0 / (self.t[1] - self.t[0]))

    @property
    def processing(self) -> str:
        return "upstream" if self.periodic is None else "periodic"

    def in_band(self, x: np.ndarray) -> np.ndarray:
        """A prediction at this run's samples, in the band the measured efforts
        were given (periodic: projected on the same harmonics; upstream: as it is)."""
        return x if self.periodic is None else self.periodic.projector(x)

    def first_period_samples(self) -> int:
        """Upstream: the arm's nominal first period (the PSM's 1111 samples); periodic: the fitted period's."""
        if self.periodic is None:
            if self.upstream_first_period is None:
                raise DvrkDartError("a run processed without its arm's [processing] has no first period")
            return self.upstream_first_period
        return int(round(self.periodic.period.period_s / (self.t[1] - self.t[0])))

    def head(self, n: int) -> "ProcessedRun":
        """The first n samples (a periodic run's band no longer applies: project before)."""
        return ProcessedRun(*(a[:n] for a in (self.t, self.q, self.dq, self.ddq, self.tau)), upstream_first_period=self.upstream_first_period,
                            measured=self.measured, first_row=self.first_row)

    def window(self, start: int, n: int) -> "ProcessedRun":
        """Samples start..start+n; a periodic run's band is then that of the
        same harmonics over the window (`in_band` projects on them there)."""
        part = slice(start, start + n)
        periodic = None
        if self.periodic is not None:
            projector = self.periodic.projector
            periodic = replace(self.periodic, projector=type(projector)(projector.t[part], projector.frequency_hz, projector.harmonics))
        return ProcessedRun(*(a[part] for a in (self.t, self.q, self.dq, self.ddq, self.tau)), periodic, self.upstream_first_period,
                            self.measured, None if self.first_row is None else self.first_row + start)

    def at_rate(self, rate_hz: float) -> "ProcessedRun":
        """A periodic run on samples at `rate_hz` over the same span: its harmonic series evaluated there (exact in
        its band), so a baseline or repeat logged at another rate is subtracted sample by sample."""
        if self.periodic is None:
            raise DvrkDartError("only a periodic run is put on another rate (its series); upstream's filtered samples are not")
        elapsed = np.arange(int(np.floor((len(self) - 1) / self.rate_hz * rate_hz)) + 1) / rate_hz
        analysis = self.periodic
        projector = type(analysis.projector)(elapsed, analysis.projector.frequency_hz, analysis.projector.harmonics)
        q, dq, ddq = (analysis.positions(elapsed, derivative) for derivative in range(3))
        return ProcessedRun(self.t[0] + elapsed, q, dq, ddq, analysis.efforts(elapsed), replace(analysis, projector=projector),
                            self.upstream_first_period, self.measured)

    def summary(self) -> dict:
        """What every output records of the processing."""
        if self.periodic is None:
            rows = {} if self.first_row is None else {
                "samples_analysed": [self.first_row, self.first_row + len(self)],
                "transient_rule": f"upstream's zero-phase filter: the recording's first and last {CUT_SAMPLES} rows left out, as upstream did"}
            return {"processing": "upstream", "period_s": None, "harmonics": None, "noise_rms": None, **rows, **self._rows_note()}
        return self.periodic.summary()

    def _rows_note(self) -> dict:
        """Upstream processing works in rows, as upstream did: at another rate
        its cut-off and first period scale with the rate (a log at another rate is
        read as the excitation at another speed: upstream's half-speed runs)."""
        scale = self.rate_hz / sample_rate_hz()
        if abs(scale - 1.0) < 1e-3:
            return {}
        period = f" and its first period ({self.upstream_first_period} rows) lasts {1 / scale:.3g}x as long" if self.upstream_first_period else ""
        return {"rate_note": f"upstream processing works in rows, as upstream did: at {self.rate_hz:g} Hz its filter's cut-off in Hz is "
                             f"{scale:.3g}x the one at {sample_rate_hz():g} Hz{period}, as if the excitation were played {scale:.3g}x as "
                             "fast (how upstream read its half-speed runs); for the same motion logged at another rate, --processing periodic"}


def central_difference(x: np.ndarray, h: float) -> np.ndarray:
    """Upstream's 5-point central difference along axis 0, lower order at the ends."""
    d = np.empty_like(x)
    d[2:-2] = (-x[4:] + 8 * x[3:-1] - 8 * x[1:-3] + x[:-4]) / (12 * h)
    d[0] = (x[1] - x[0]) / h
    d[1] = (x[2] - x[0]) / (2 * h)
    d[-2] = (x[-1] - x[-3]) / (2 * h)
    d[-1] = (x[-1] - x[-2]) / h
    return d


def zero_phase_lowpass(x: np.ndarray, upstream: UpstreamProcessing) -> np.ndarray:
    """Upstream's filtfilt: odd extension of 3 * ntaps samples, lfilter_zi start, along axis 0.
    Its Wn is upstream's at the reference rate whatever the run's: a run at
    another rate (the half-speed run's 100 Hz rows) keeps its cut-off at the
    same multiple of its excitation's base frequency. `upstream`: the arm's
    fc and that rate (the model card's [processing]; the PSM's 5.4 Hz, 200 Hz)."""
    b, a = scipy.signal.butter(FILTER_ORDER, upstream.cutoff_parameter_hz * 2 * math.pi / upstream.filter_rate_hz)
    edge = 3 * max(len(a), len(b))
    zi = scipy.signal.lfilter_zi(b, a)[:, None]
    s = np.concatenate([2 * x[0] - x[edge:1:-1], x, 2 * x[-1] - x[-1:-edge:-1]])
    y, _ = scipy.signal.lfilter(b, a, s, axis=0, zi=zi * s[0])
    y, _ = scipy.signal.lfilter(b, a, y[::-1], axis=0, zi=zi * y[-1])
    return y[::-1][edge - 1 : -edge + 1]


def process(run: MeasuredRun, processing: str = "upstream", harmonics=None, design=None) -> ProcessedRun:
    """q, dq, ddq, tau of a measured run: filtered and trimmed like upstream (with
    the current arm's fc and first period, its model card's [processing]), or
    through the periodic layer (`harmonics` imposes its cutoffs, `design` the
    excitation's period and harmonics where known)."""
    if processing == "periodic":
        return process_periodic(run, harmonics, design)
    if processing != "upstream":
        raise DvrkDartError(f"--processing {processing}: one of {', '.join(PROCESSINGS)}")
    h = 1.0 / run.rate_hz
    if len(run) < MIN_ROWS:
        raise DvrkDartError(f"{run.path}: {len(run)} rows, at least {MIN_ROWS} needed for processing")
    model = run.model
    upstream = model.processing
    q = zero_phase_lowpass(run.q, upstream)
    dq = zero_phase_lowpass(run.dq, upstream)
    ddq = zero_phase_lowpass(central_difference(run.dq, h), upstream)
    tau = zero_phase_lowpass(run.tau - model.cable_efforts(run.q), upstream)
    keep = slice(CUT_SAMPLES, -CUT_SAMPLES)
    return ProcessedRun(run.t[keep], q[keep], dq[keep], ddq[keep], tau[keep], upstream_first_period=upstream.first_period_samples,
                        measured=run.measured_mask, first_row=CUT_SAMPLES)


def process_periodic(run: MeasuredRun, harmonics=None, design=None) -> ProcessedRun:
    """Analytic q, dq, ddq and the efforts projected on the harmonics (io/periodic.py)."""
    tau = run.tau - run.model.cable_efforts(run.q)  # what the identification removed before fitting
    coupled = np.isin(np.arange(run.q.shape[1]), np.arange(run.q.shape[1])[run.model.motor_map.columns])
    analysis = _analysis(run.t, run.q, tau, run.rate_hz, f"{run.path}: --processing periodic", harmonics, run.measured_mask, design, coupled)
    kept = slice(*analysis.kept)  # without a start or end transient (io/transient.py)
    t = run.t[kept] - run.t[kept][0]
    q, dq, ddq = (analysis.positions(t, derivative) for derivative in range(3))
    return ProcessedRun(run.t[kept], q, dq, ddq, analysis.efforts(t), analysis, measured=run.measured_mask, first_row=analysis.kept[0])


def _analysis(t, q, tau, rate_hz: float, where: str, harmonics, measured: np.ndarray, design, coupled: np.ndarray) -> PeriodicAnalysis:
    """`analyse`, once per content: keyed by a digest of the arrays and the options (an analysis is frozen; a
    run given its excitation's design is analysed each time)."""
    if design is not None:
        return analyse(t, q, tau, rate_hz, where, harmonics, measured, design, coupled)
    digest = hashlib.blake2b(digest_size=16)
    for array in (t, q, tau, measured, coupled):
        digest.update(np.ascontiguousarray(array).tobytes())
    key = (digest.hexdigest(), rate_hz, where, harmonics)
    if key not in _ANALYSES:
        _ANALYSES[key] = analyse(t, q, tau, rate_hz, where, harmonics, measured, design, coupled)
        while len(_ANALYSES) > _ANALYSES_KEPT:
            _ANALYSES.popitem(last=False)
    return _ANALYSES[key]


def forget_analyses() -> None:
    """Drop the analyses kept by content (io/reference_data.forget_read_runs)."""
    _ANALYSES.clear()


def process_all(runs: list[MeasuredRun], processing: str | None, design=None,
                harmonics: int | None = None) -> tuple[list[ProcessedRun], str | None]:
    """Runs through one processing, and a note when the choice was not the user's:
    `None` is periodic where every run is a periodic excitation, else upstream
    (the note says which run is not periodic and why). With a `design` (the
    user's --excitation) or imposed `harmonics` (--harmonics) every run is read
    periodic, or a one-line error."""
    for given, option, what in ((design, "--excitation", "the excitation's design sets"), (harmonics, "--harmonics", "it imposes")):
        if given is not None and processing == "upstream":
            raise DvrkDartError(f"{option}: {what} the periodic processing's harmonics; not with --processing upstream")
        if given is not None:
            processing = "periodic"
    if processing is not None:
        return [process(run, processing, harmonics, design=design) for run in runs], None
    try:
        return [process_periodic(run, design=design) for run in runs], None
    except DvrkDartError as exc:
        return [process(run) for run in runs], f"upstream processing: {not_periodic_reason(exc)}"


def chosen_because(processing: str | None, excitation=None, harmonics: int | None = None, note: str | None = None) -> str:
    """Why a run went through its processing (`process_all`'s choice), in the options' words."""
    if processing is not None:
        return f"--processing {processing}"
    if excitation is not None:
        return f"--excitation {excitation}: the design sets the periodic band"
    if harmonics is not None:
        return f"--harmonics {harmonics}"
    return note or "the default: the run is a periodic excitation"


def not_periodic_reason(exc: DvrkDartError) -> str:
    """Why a run was read upstream by default: the periodic layer's refusal,
    without the option the user did not give."""
    return str(exc).replace("--processing periodic: ", "periodic processing: ")


#: two runs share their motion (a baseline's gap is subtracted sample by sample)
#: when their positions differ by less than this RMS (rad or m; two recordings
#: of trajectory one differ by ~1e-3, the half-speed run by ~0.5) ...
SAME_MOTION_POSITION_RMS = 0.01
#: ... and their velocities by less than this fraction of the velocity RMS
SAME_MOTION_VELOCITY_FRACTION = 0.1


def same_rate(a_hz: float, b_hz: float) -> bool:
    """Two logs at one rate (to a millionth: rates read from time columns or manifests)."""
    return abs(a_hz - b_hz) <= 1e-6 * a_hz


def not_comparable_sample_by_sample(a: ProcessedRun, b: ProcessedRun) -> str | None:
    """Why `b` cannot be compared with `a` sample by sample, when it is their rates (upstream processing)."""
    if a.periodic is not None or same_rate(a.rate_hz, b.rate_hz):
        return None
    return (f"logged at {b.rate_hz:.6g} Hz, the run it is compared with at {a.rate_hz:.6g} Hz: the upstream processing compares "
            "runs sample by sample (the periodic processing puts a run on another's rate)")


def same_motion(a: ProcessedRun, b: ProcessedRun) -> bool:
    """Whether two runs of one length follow the same motion sample by sample, on the joints both recorded
    (a baseline's gap can then be subtracted as it is)."""
    if len(a) != len(b):
        return False
    both = a.measured & b.measured  # a joint one log does not have is held there: it says nothing of the motion
    if not both.any():
        return False
    position = float(rms(a.q[:, both] - b.q[:, both], axis=None))
    velocity = float(rms(a.dq[:, both] - b.dq[:, both], axis=None) / max(rms(b.dq[:, both], axis=None), 1e-12))
    return position < SAME_MOTION_POSITION_RMS and velocity < SAME_MOTION_VELOCITY_FRACTION

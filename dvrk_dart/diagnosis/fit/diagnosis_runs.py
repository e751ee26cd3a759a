"""A measured run prepared for the diagnosis: its simulated efforts, its baseline, its features."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from dvrk_dart.analysis.residual_floor import residual_noise
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.library import (
    config_effort_by_formula,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import load_run, resolve_run, run_label
from dvrk_dart.io.signal import SAME_MOTION_POSITION_RMS, ProcessedRun, not_periodic_reason, process, same_motion, same_rate
from dvrk_dart.io.period import spanning_columns
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.model_file import load_model
from dvrk_dart.sim.config import SimConfig

#: a payload's mass is printed to the gram, and a lighter one is none: a fit held at its bound of zero
#: (3.55e-19 kg, beside a baseline of another motion of the same arm) was named "a payload ... (3.55e-19 kg)"
MIN_PAYLOAD_KG = 1e-3
#: two recordings of one motion may start this far apart (a share of the shorter
#: one): the baseline is aligned on the run by whole samples within it, then both
#: cut to their common span (at least half the shorter run)
MAX_START_OFFSET_SHARE = 0.25
#: draws of the positions' noise a run's noise energy averages (`residual_noise`; ~0.5 s a run of 6000 samples): fewer
#: than the session floor's (made twice a validation; a diagnosis makes it for every run, a campaign for hundreds)
NOISE_DRAWS = 4


Simulate = Callable[[SimConfig, ProcessedRun], np.ndarray]
"""simulate(config, run) -> (N, 7) simulated efforts at the run's samples (DART replay)."""


# ------------------------------------------------------------- the processing
@dataclass(frozen=True)
class RunProcessing:
    """How every run of a diagnosis is read and processed: upstream, or
    periodic on one common harmonic cutoff (runs subtracted or compared see
    one band); bags read with `topics`."""

    name: str = "upstream"
    harmonics: int | None = None
    why: str = "--processing upstream"
    topics: BagTopics = BagTopics()

    def summary(self) -> dict:
        return {"processing": self.name, "harmonics": self.harmonics, "chosen_because": self.why}


def choose_processing(specs, processing: str | None, model: PsmModel, topics: BagTopics = BagTopics(), held_out=()) -> RunProcessing:
    """`processing` None: periodic where every run (name or path) of `model`'s
    arm is a periodic excitation, else upstream, with the reason; periodic:
    every run must be. The band is the smallest cutoff of `specs`, the runs the
    fit sees: the `held_out` runs must be periodic too, but they are scored on
    that band, never choose it."""
    if processing == "upstream":
        return RunProcessing(topics=topics)
    fitted = [Path(resolve_run(s)) for s in flat_specs(specs) if isinstance(s, (str, Path))]
    scored = [Path(resolve_run(s)) for s in flat_specs(held_out) if isinstance(s, (str, Path))]
    if not fitted + scored and processing is None:
        return RunProcessing(why="no measured file among the runs", topics=topics)
    try:
        own_band = RunProcessing("periodic", why="each run's own cutoff", topics=topics)  # cached: a diagnosis meets the runs again
        cutoffs = [_load_state(path, model, own_band)[1].periodic.harmonics for path in fitted + scored][:len(fitted)]
    except DvrkDartError as exc:
        if processing == "periodic":
            raise
        return RunProcessing(why=f"upstream: {not_periodic_reason(exc)}", topics=topics)
    why = "--processing periodic" if processing == "periodic" else "every run is a periodic excitation"
    return RunProcessing("periodic", min(cutoffs) if cutoffs else None,
                         f"{why}; the smallest cutoff of the runs fitted{' (not the held-out runs)' if scored else ''}", topics)


#: why the default processing falls back to upstream with a baseline of another motion
NO_BASELINE_MOTION = ("upstream: no run has the baseline's motion, which a payload read on the harmonics needs "
                      "(a run minus its baseline of the same motion)")


def with_baseline_motion(processing: RunProcessing, baseline, measured_list: list, model: PsmModel) -> RunProcessing:
    """The default periodic processing kept where a measured run has the
    baseline's motion; else upstream, with the reason (a chosen default,
    never the user's --processing: call it only when none was given)."""
    if processing.name != "periodic" or baseline is None or isinstance(baseline, DiagnosisRun):
        return processing
    states = [s.state if isinstance(s, DiagnosisRun) else _load_state(s, model, processing)[1] for s in measured_list if not isinstance(s, tuple)]
    base = _load_state(baseline, model, processing)[1]
    if any(motion_offset(state, on_rate(base, state.rate_hz)) is not None for state in states):
        return processing
    rates = sorted({f"{state.rate_hz:g}" for state in states if not same_rate(state.rate_hz, base.rate_hz)})
    other_rate = (f"; the baseline is logged at {base.rate_hz:g} Hz, the runs at {', '.join(rates)} Hz (put on their rate by its "
                  "harmonic series, it still differs)") if rates else ""
    return RunProcessing(why=NO_BASELINE_MOTION + other_rate, topics=processing.topics)


def processing_of(result: dict, topics: BagTopics = BagTopics()) -> RunProcessing:
    """The processing a diagnosis (its result dict) read and processed its runs with."""
    return RunProcessing(result["processing"]["processing"], result["processing"].get("harmonics"), topics=topics)


def flat_specs(specs) -> list:
    """Run specs with (run, baseline) pairs and lists opened, None left out."""
    out = []
    for spec in specs:
        out += flat_specs(spec) if isinstance(spec, (tuple, list)) else [spec] if spec is not None else []
    return out


# ------------------------------------------------------------------- the runs
class RunRole(str, enum.Enum):
    """How a run's residual is made and which effects' columns it has."""

    RAW = "raw"  # the gap itself
    DIFFERENCE = "difference"  # minus its baseline's gap, sample by sample (same motion)
    BASELINE = "baseline"  # a run without the effect under study, fitted with the others: no withheld-effect columns
    OTHER_MOTION = "other_motion"  # its gap, fitted with its baseline run of another motion


@dataclass
class DiagnosisRun:
    """A measured run with the simulated efforts at its samples, and optionally
    the baseline run of the same trajectory without the effect under study."""

    name: str
    state: ProcessedRun
    simulated: np.ndarray
    baseline: "DiagnosisRun | None" = None
    role: RunRole = RunRole.RAW
    #: how a baseline of the same motion was put on the run's samples (or why one at another rate is another motion)
    alignment: str | None = None
    #: the run's regressor features, made once (`features`)
    _features: TrajectoryFeatures | None = field(default=None, repr=False, compare=False)
    #: its own state's noise energy per sample (`noise_energy`), made once
    _noise: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        self.simulated = np.asarray(self.simulated, dtype=float)
        self.role = RunRole(self.role)
        if self.simulated.shape != self.state.tau.shape:
            raise DvrkDartError(f"{self.name}: simulated efforts {self.simulated.shape} do not match the measured {self.state.tau.shape}")
        if self.baseline is not None and self.role is RunRole.RAW:
            self.role = RunRole.DIFFERENCE
        if self.role is RunRole.DIFFERENCE and len(self.baseline.state) != len(self.state):
            raise DvrkDartError(f"{self.name}: baseline {self.baseline.name} has {len(self.baseline.state)} samples, not {len(self.state)}")

    def __len__(self) -> int:
        return len(self.state)

    def noise_energy(self, arm: Arm) -> np.ndarray | None:
        """(7,) periodic processing: the noise energy per sample the run's residual carries, its efforts' and its
        positions' through the arm's model (`residual_noise`), a run minus its baseline carrying both's;
        None upstream."""
        parts = [self._own_noise(arm), *([self.baseline._own_noise(arm)] if self.role is RunRole.DIFFERENCE else [])]
        return None if any(part is None for part in parts) else sum(parts)

    def _own_noise(self, arm: Arm) -> np.ndarray | None:
        if self.state.periodic is None:
            return None
        if self._noise is None:
            self._noise = residual_noise(arm, self.state, draws=NOISE_DRAWS) ** 2
        return self._noise

    @property
    def gap(self) -> np.ndarray:
        """measured - simulated (N, 7); zero on a joint the run did not record (nothing to explain)."""
        return np.where(self.state.measured, self.state.tau - self.simulated, 0.0)

    @property
    def baseline_effort(self) -> np.ndarray:
        """What is subtracted from the gap: the baseline's gap, sample by sample (N, 7)."""
        return self.baseline.gap if self.role is RunRole.DIFFERENCE else np.zeros_like(self.state.tau)

    @property
    def baseline_source(self) -> str | None:
        note = f" ({self.alignment})" if self.alignment else ""
        return {RunRole.DIFFERENCE: "subtracted sample by sample" + note, RunRole.OTHER_MOTION: "fitted together with the baseline run (another motion)" + note,
                RunRole.BASELINE: "the baseline itself (withheld effects absent)"}.get(self.role)

    def features(self, arm: Arm) -> TrajectoryFeatures:
        """The regressor features of the run's samples (made once per run)."""
        if self._features is None:
            s = self.state
            self._features = TrajectoryFeatures(arm, s.q, s.dq, s.ddq, self.simulated, s.rate_hz, self._exerted_effort())
        return self._features

    def _exerted_effort(self) -> np.ndarray:
        """What the arm exerts as well as the runs tell it (a scale of the measurement multiplies it): the simulated
        effort, or the measured one of the baseline of the same motion, which a change of scale in the run has not
        touched (the run's own would put its noise and its session's gap in the column that is to explain them)."""
        if self.role is RunRole.DIFFERENCE:
            return np.where(self.baseline.state.measured, self.baseline.state.tau, self.simulated)
        return self.simulated

    @property
    def residual(self) -> np.ndarray:
        """The residual to explain: the gap, minus the baseline's gap if any."""
        return self.gap - self.baseline_effort


def _load_state(spec, model: PsmModel, processing: RunProcessing) -> tuple[str, ProcessedRun]:
    if isinstance(spec, ProcessedRun):
        return "run", spec
    path = Path(resolve_run(spec))
    stat = path.stat()
    state = _load_processed(str(path), stat.st_mtime_ns, stat.st_size, processing, model.source)
    if not spanning_columns(state.q[:, state.measured]).any():  # nothing moves: no effect of motion can be told
        raise DvrkDartError(f"{path}: no recorded joint moves (every position is constant): a gap is diagnosed along a motion")
    return run_label(spec), state


@lru_cache(maxsize=16)
def _load_processed(path: str, mtime_ns: int, size: int, processing: RunProcessing, model_file: Path) -> ProcessedRun:
    """One processing per file version: the batch re-simulation prefetches the
    states that prepare_run then meets again (keyed by the file's version)."""
    return process(load_run(path, load_model(model_file), processing.topics), processing.name, processing.harmonics)


def loaded_states(specs, model: PsmModel, processing: RunProcessing = RunProcessing()) -> list[ProcessedRun]:
    """The processed states of run specs of `model`'s arm not yet simulated
    (names, paths, ProcessedRun, (run, baseline) pairs), for a batch of replays."""
    states = []
    for spec in specs:
        if isinstance(spec, tuple):
            states += loaded_states(spec, model, processing)
        elif spec is not None and not isinstance(spec, DiagnosisRun):
            states.append(_load_state(spec, model, processing)[1])
    return states


def simulated_efforts(arm: Arm, state: ProcessedRun, simulate: Simulate | None, config: SimConfig) -> np.ndarray:
    """Simulated efforts at the measured samples, in the band of the measured
    efforts: the DART replay when given, else the identified model evaluated
    at the measured state as a stand-in (the replay reproduces it to < 0.01
    N·m with `config`'s physics)."""
    if simulate is not None:
        return state.in_band(np.asarray(simulate(config, state), dtype=float))
    return state.in_band(config_effort_by_formula(arm, config, state.q, state.dq, state.ddq))


def on_rate(state: ProcessedRun, rate_hz: float | None) -> ProcessedRun:
    """A periodic run put on `rate_hz` (its series, exact in its band) where it was logged at another rate;
    otherwise as it is (upstream's filtered samples are not resampled: such runs stay another motion)."""
    if rate_hz is None or state.periodic is None or same_rate(state.rate_hz, rate_hz):
        return state
    return state.at_rate(rate_hz)


def prepare_run(spec, arm: Arm, simulate: Simulate | None = None, base_config: SimConfig = SimConfig(), baseline=None, name: str | None = None,
                processing: RunProcessing = RunProcessing(), rate_hz: float | None = None) -> DiagnosisRun:
    """A DiagnosisRun from a run name ('two'), a path, a ProcessedRun or a DiagnosisRun (`rate_hz`: the rate a
    baseline or repeat is put on, that of the runs it is subtracted from or compared with)."""
    if isinstance(spec, DiagnosisRun):
        run = spec
    else:
        label, state = _load_state(spec, arm.model, processing)
        state = on_rate(state, rate_hz)
        run = DiagnosisRun(name or label, state, simulated_efforts(arm, state, simulate, base_config))
    if baseline is not None:
        base = baseline if isinstance(baseline, DiagnosisRun) else prepare_run(baseline, arm, simulate, base_config, processing=processing)
        offset = motion_offset(run.state, base.state)
        if offset is None:
            return DiagnosisRun(run.name, run.state, run.simulated, None, role=RunRole.OTHER_MOTION, alignment=_other_rate(run.state, base))
        if offset == 0 and len(run) == len(base):
            return DiagnosisRun(run.name, run.state, run.simulated, base)
        return _on_common_span(run, base, offset)
    return run


def _other_rate(state: ProcessedRun, base: DiagnosisRun) -> str | None:
    """Why a baseline at another rate is fitted as another motion (upstream's filtered samples are not resampled)."""
    if same_rate(state.rate_hz, base.state.rate_hz):
        return None
    return (f"{base.name} is logged at {base.state.rate_hz:g} Hz, the run at {state.rate_hz:g} Hz: the upstream processing does not "
            "resample a baseline, so one of the same motion at another rate is read as another motion; give it at the run's rate, or "
            "--processing periodic (which puts it on the run's rate)")


def _on_common_span(run: DiagnosisRun, base: DiagnosisRun, offset: int) -> DiagnosisRun:
    """The run minus its baseline on their common span, the baseline shifted by `offset` samples."""
    start_run, start_base = max(0, -offset), max(0, offset)
    n = min(len(run) - start_run, len(base) - start_base)
    part_run, part_base = slice(start_run, start_run + n), slice(start_base, start_base + n)
    shifted = DiagnosisRun(base.name, base.state.window(start_base, n), base.simulated[part_base])
    note = f"common span of {n} samples: {run.name} from sample {start_run}, {base.name} from sample {start_base}"
    return DiagnosisRun(run.name, run.state.window(start_run, n), run.simulated[part_run], shifted, alignment=note)


def motion_offset(a: ProcessedRun, b: ProcessedRun) -> int | None:
    """The shift (samples) that puts b on a's samples when both record the same
    motion (decided from the positions over their common span), else None."""
    if not same_rate(a.rate_hz, b.rate_hz):
        return None
    limit = int(min(len(a), len(b)) * MAX_START_OFFSET_SHARE)
    end = min(len(a), len(b)) - limit
    if end <= 2 * limit:
        return None
    # a's positions inside its margins against b's shifted by k (every shift stays inside b)
    shifts = np.arange(-limit, limit + 1)
    both = a.measured & b.measured  # the joints both logs have
    errors = np.array([np.mean((a.q[limit:end, both] - b.q[limit + k : end + k, both]) ** 2) for k in shifts])
    # a periodic motion matches itself a period later too: of the best shifts of
    # each match (the local minima where the positions agree), the smallest
    # keeps the longest common span
    inner = errors[1:-1]
    minima = shifts[1:-1][(inner <= errors[:-2]) & (inner <= errors[2:]) & (inner < SAME_MOTION_POSITION_RMS**2)]
    if not len(minima):
        return None
    offset = int(minima[np.argmin(np.abs(minima))])
    start_a, start_b = max(0, -offset), max(0, offset)
    span = min(len(a) - start_a, len(b) - start_b)
    return offset if same_motion(a.window(start_a, span), b.window(start_b, span)) else None


def run_features(arm: Arm, run: DiagnosisRun) -> TrajectoryFeatures:
    return run.features(arm)

"""A measured run prepared for the diagnosis: its simulated efforts, its baseline, its features."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from dvrk_dart.diagnosis.features import TrajectoryFeatures
from dvrk_dart.diagnosis.library import (
    config_effort_by_formula,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import ProcessedRun, process
from dvrk_dart.model.arm import Arm
from dvrk_dart.sim.config import SimConfig

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


def run_features(arm: Arm, run: DiagnosisRun) -> TrajectoryFeatures:
    s = run.state
    return TrajectoryFeatures(arm, s.q, s.dq, s.ddq, run.simulated, sample_rate_hz())

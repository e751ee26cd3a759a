"""Synthetic measurements: the simulator with hidden effects plus realistic noise."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.library import (
    effects_to_sim_config,
    not_simulated,
    unsimulated_effort,
)
from dvrk_dart.diagnosis.fit.diagnosis_runs import Simulate, simulated_efforts
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import ProcessedRun, process, zero_phase_lowpass
from dvrk_dart.metrics import rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.sim.config import SimConfig


def synthesize_measurement(
    arm: Arm,
    state: ProcessedRun,
    injected: Sequence[tuple[Effect, np.ndarray]],
    noise_rms: np.ndarray,
    seed: int = 0,
    simulate: Simulate | None = None,
    base_config: SimConfig = SimConfig(),
    extra_effort: np.ndarray | None = None,
) -> ProcessedRun:
    """A measured run with hidden effects: the efforts of the simulation with
    the effects as physics (SimConfig) plus the regressor efforts of effects the
    simulation has no field for, plus coloured noise of the given RMS per joint
    (white noise through the upstream low-pass filter); `extra_effort` (N, 7)
    is physics outside the effect library (`out_of_library`), added as is."""
    config = effects_to_sim_config(list(injected), base_config)
    tau = simulated_efforts(arm, state, simulate, config)
    extra = not_simulated(list(injected))
    if extra:
        features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, simulated_efforts(arm, state, simulate, base_config), state.rate_hz)
        tau = tau + unsimulated_effort(extra, features)
    if extra_effort is not None:
        tau = tau + np.asarray(extra_effort, dtype=float)
    rng = np.random.default_rng(seed)
    noise = zero_phase_lowpass(rng.standard_normal(tau.shape), arm.model.processing)
    noise = noise / np.maximum(rms(noise), 1e-300) * np.asarray(noise_rms, dtype=float)
    return ProcessedRun(state.t, state.q, state.dq, state.ddq, tau + noise, upstream_first_period=state.upstream_first_period)


def time_scaled(state: ProcessedRun, speed: float) -> ProcessedRun:
    """The same path played at `speed` times the rate, over the same number of
    samples (same positions, velocities x speed, accelerations x speed^2): what
    a run of the same trajectory at another speed measures. Efforts are those
    of the original (overwrite them with synthesize_measurement)."""
    t = state.t
    source = t[0] + (t - t[0]) * speed  # time along the original path
    if source[-1] > t[-1] + 1e-12:
        raise ValueError(f"speed {speed}: the path is {t[-1] - t[0]:.1f} s long, {source[-1] - t[0]:.1f} s asked")

    def at(x: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(source, t, x[:, j]) for j in range(x.shape[1])])

    return ProcessedRun(t.copy(), at(state.q), speed * at(state.dq), speed**2 * at(state.ddq), at(state.tau),
                        upstream_first_period=state.upstream_first_period)


def real_segment(arm: Arm, run: str, base_periods: int) -> tuple[ProcessedRun, np.ndarray]:
    """The first `base_periods` periods of a real run of `arm` (upstream processing),
    and the identified model's residual RMS on them per joint: the motion and the
    noise level of the synthetic checks' runs."""
    processed = process(load_run(resolve_run(run), arm.model))
    segment = processed.head(base_periods * processed.first_period_samples())
    return segment, rms(segment.tau - arm.identified.predict(segment.q, segment.dq, segment.ddq, "all"))

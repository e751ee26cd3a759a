"""The simulator's speed alone (`make bench`: sim_realtime_factor)."""

from __future__ import annotations

import time

import numpy as np

from dvrk_dart.model.description import PsmModel
from dvrk_dart.sim.config import SimConfig
from dvrk_dart.sim.simulator import PsmSimulator


def measure_realtime_factor(model: PsmModel, seconds: float = 5.0, config: SimConfig = SimConfig()) -> float:
    """Simulated seconds per wall second of the full arm (velocity servo on a
    smooth multi-joint motion), for the benchmark."""
    from dvrk_dart.io.reference_data import resolve
    from dvrk_dart.model.parameters import load_parameters

    params = load_parameters(resolve(model.default_parameters), model)
    sim = PsmSimulator(model, params, config)
    centre = 0.5 * (model.joint_lower + model.joint_upper)
    amplitude = 0.2 * (model.joint_upper - model.joint_lower)
    sim.reset(centre)
    steps = int(round(seconds / sim.dt))
    omega = 2.0 * np.pi * 0.5  # rad/s, a motion of the kind of the excitation trajectories
    start = time.perf_counter()
    for k in range(steps):
        t = (k + 1) * sim.dt
        sim.step_velocity(amplitude * omega * np.cos(omega * t))
    return seconds / (time.perf_counter() - start)

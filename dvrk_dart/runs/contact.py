"""A contact scenario in DART: the instrument presses on a compliant surface.

The arm replays a measured excitation under the velocity servo (the paper's
replay controller) while a tissue-like surface, a horizontal plane under the
lowest part of the instrument point's path, pushes back on the point with a
spring-damper force (stiffness and damping stated, no adhesion). DART applies
that force to the instrument's body; it is the truth. The estimate
`F = J^-T (tau - tau_model)` (model/force.py) from the simulated efforts,
with the model the simulation was built from evaluated at the simulated
states, must give it back (sim-to-sim); a held-out run's real residual added
to the efforts estimates the error on the real arm, if the free-motion residual carries into contact unchanged."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from dvrk_dart.model.force import estimate_force, point_positions
from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.metrics import rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.runs.replay import VELOCITY_TARGET_STAGGER_STEPS, ReplayDriver
from dvrk_dart.sim.config import SimConfig
from dvrk_dart.sim.simulator import PsmSimulator


@dataclass(frozen=True)
class Surface:
    """A horizontal compliant plane (base frame z up): force k * depth - c * dz/dt upward, never pulling."""

    height_m: float
    stiffness_n_per_m: float = 500.0
    damping_n_s_per_m: float = 5.0

    def force(self, point: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        depth = self.height_m - point[2]
        if depth <= 0.0:
            return np.zeros(3)
        return np.array([0.0, 0.0, max(self.stiffness_n_per_m * depth - self.damping_n_s_per_m * velocity[2], 0.0)])


@dataclass(frozen=True)
class ContactRun:
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    effort: np.ndarray
    contact_force: np.ndarray  # (N, 3) the surface's force on the instrument (DART's applied force)


def surface_under(arm: Arm, state: ProcessedRun, depth_m: float, **kwargs) -> Surface:
    """A surface `depth_m` above the lowest point of the instrument's path: the arm presses into it there."""
    lowest = float(point_positions(arm.model, state.q, arm.model.force_point.link)[:, 2].min())
    return Surface(lowest + depth_m, **kwargs)


def simulate_contact(arm: Arm, state: ProcessedRun, surface: Surface, duration_s: float, config: SimConfig = SimConfig()) -> ContactRun:
    """The velocity replay of `state` with the surface acting on the instrument point, every step logged."""
    t_meas = state.t - state.t[0]
    dt = config.dt_s
    steps = int(round(duration_s / dt))
    grid = np.arange(steps + 1) * dt
    q_ref, dq_ref = CubicSpline(t_meas, state.q), CubicSpline(t_meas, state.dq)
    sim = PsmSimulator(arm.model, arm.params, config)
    sim.reset(q_ref(0.0), dq_ref(grid[0] - VELOCITY_TARGET_STAGGER_STEPS * dt))
    sim.external_force = surface.force
    driver = ReplayDriver("velocity", q_ref(grid), dq_ref(grid - VELOCITY_TARGET_STAGGER_STEPS * dt), dt)
    rows = {name: [] for name in ("q", "dq", "ddq", "effort", "force")}
    for k in range(steps):
        rows["q"].append(sim.q)
        rows["dq"].append(sim.dq)
        ddq, effort = driver.advance(k, sim)
        rows["ddq"].append(np.array(ddq))
        rows["effort"].append(np.array(effort))
        rows["force"].append(sim.last_external_force.copy())
    arrays = {name: np.array(values) for name, values in rows.items()}
    return ContactRun(grid[:steps], arrays["q"], arrays["dq"], arrays["ddq"], arrays["effort"], arrays["force"])


def contact_check(arm: Arm, run: ContactRun, model_efforts: np.ndarray, real_residual: np.ndarray | None = None) -> dict:
    """The estimate against DART's force: the instrument's force on the surface is
    minus the surface's on it. `model_efforts` at the simulated states; a real
    residual (N, 7) added to the efforts gives the error to expect on the real arm."""
    truth = -run.contact_force
    gap = run.effort - model_efforts
    estimate = estimate_force(arm.model, run.q, gap)
    known = np.all(np.isfinite(estimate.force), axis=1)
    in_contact = np.linalg.norm(truth, axis=1) > 0
    result = {"samples": int(len(run.t)), "in_contact_fraction": float(np.mean(in_contact)),
              "contact_force_rms_n": _norm_rms(truth, known), "contact_force_in_contact_rms_n": _norm_rms(truth, known & in_contact),
              "sim_to_sim_error_rms_n": _norm_rms(estimate.force - truth, known), "determined_fraction": float(known.mean())}
    if real_residual is not None:
        noisy = estimate_force(arm.model, run.q, gap + real_residual)
        ok = np.all(np.isfinite(noisy.force), axis=1)
        result["with_real_residual_error_rms_n"] = _norm_rms(noisy.force - truth, ok)
        result["with_real_residual_error_per_axis_n"] = rms(noisy.force[ok] - truth[ok]).tolist()
        result["with_real_residual_error_in_contact_rms_n"] = _norm_rms(noisy.force - truth, ok & in_contact)
    return result


def _norm_rms(force: np.ndarray, where: np.ndarray) -> float | None:
    """RMS of a force's norm over the samples `where` (None where there are none)."""
    return float(rms(np.linalg.norm(force[where], axis=1))) if where.any() else None

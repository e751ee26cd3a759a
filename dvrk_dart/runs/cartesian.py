"""The Cartesian tasks of the paper (rectilinear, spiral): the tool tip
follows a path with the start's orientation, in one of three modes:
- kinematic: positions imposed, the Eq. 5 controller's ODE integrated with RK4;
- velocity: the Eq. 5 joint velocities are the velocity servo's reference;
- torque: feedback linearisation (Eq. 6-7) drives J1..J3, the servo holds the tool.
"""

from __future__ import annotations

import math
import time

import numpy as np

from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.runs.loop import simulate
from dvrk_dart.io.record import RunRecord, pose_vector
from dvrk_dart.runs.scenarios import Scenario
from dvrk_dart.sim.config import SimConfig
from dvrk_dart.sim.controllers import CartesianTorqueController, KinematicController
from dvrk_dart.sim.readout import raise_if_out_of_range

#: a Cartesian run logs at most this rate (a smaller step is for the physics) ...
MAX_LOG_RATE_HZ = 1000.0
#: ... and at most this many samples: a logged sample costs some 20 kB on its way to the MCAP and Rerun logs
MAX_LOGGED_SAMPLES = 100_000

#: joints held by the velocity servo under torque control (the paper drives
#: J1..J3 only; the identified tool links are massless)
TOOL_JOINTS = tuple(range(3, N_JOINTS))


def _rk4_step(f, t: float, q: np.ndarray, dt: float) -> np.ndarray:
    k1 = f(t, q)
    k2 = f(t + dt / 2, q + dt / 2 * k1)
    k3 = f(t + dt / 2, q + dt / 2 * k2)
    k4 = f(t + dt, q + dt * k3)
    return q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _twist(velocity: np.ndarray) -> np.ndarray:
    """The tool tip's twist (linear; angular) at a constant orientation."""
    return np.concatenate((velocity, np.zeros(3)))


class CartesianDriver:
    def __init__(self, arm: Arm, scenario: Scenario, mode: str, dt: float, steps: int):
        self.mode, self.dt = mode, dt
        self.q0 = np.asarray(scenario.start_pose, dtype=float)
        pose0 = arm.identified.tool_tip_pose(self.q0)
        self.path = scenario.cartesian_path(pose0[:3, 3])
        self.R_d = pose0[:3, :3]
        self.reference_pose_at_start = pose_vector(pose0)  # the orientation stays the start's
        self.kinematic = KinematicController(arm)
        self.torque = CartesianTorqueController(arm)
        self.q_kin = self.q0.copy()
        self.joint_lower, self.joint_upper = arm.model.joint_lower, arm.model.joint_upper
        self.reference_pose = np.zeros((steps, 7))
        self.command = np.full((steps, N_JOINTS), np.nan)

    def reference(self, t: float):
        p, v, a = self.path.position_velocity_acceleration(t)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.R_d, p
        return T, _twist(v), a

    def closed_loop_velocity(self, t: float, q: np.ndarray) -> np.ndarray:
        T_d, twist_d, _ = self.reference(t)
        return self.kinematic.joint_velocity(q, T_d, twist_d)

    def impose(self, k: int, sim) -> None:
        t = k * self.dt
        self.reference_pose[k] = self.reference_pose_at_start
        self.reference_pose[k, :3] = self.path.position_velocity_acceleration(t)[0]
        if self.mode == "kinematic":
            # imposed, not simulated: nothing else stops a path that leaves the joints' ranges
            raise_if_out_of_range(self.q_kin, self.joint_lower, self.joint_upper, f"step {k} (t = {t:.3f} s)",
                                  ": the path leaves what the arm can reach")
            sim.set_kinematic(self.q_kin, self.closed_loop_velocity(t, self.q_kin))

    def advance(self, k: int, sim):
        t = k * self.dt
        if self.mode == "kinematic":
            self.q_kin = _rk4_step(self.closed_loop_velocity, t, self.q_kin, self.dt)
            return None
        T_d, twist_d, acc_d = self.reference(t)
        q, dq = sim.q, sim.dq
        if self.mode == "velocity":
            # the step's velocity is its mean over [t, t + dt] (semi-implicit Euler, below):
            # feed forward the reference's velocity there, centred at t + dt/2
            _, v_half, _ = self.path.position_velocity_acceleration(t + self.dt / 2)
            sim.step_velocity(self.kinematic.joint_velocity(q, T_d, _twist(v_half)))
        else:
            # semi-implicit Euler: q_k = q_(k-1) + dt dq_k, so the sampled velocity is the
            # mean over the previous step, centred at t - dt/2: compare it with the
            # reference velocity there (else a Kd a dt / 2Kp lag remains)
            _, v_half, _ = self.path.position_velocity_acceleration(t - self.dt / 2)
            u, _ = self.torque.efforts(q, dq, T_d[:3, 3], v_half, acc_d)
            self.command[k] = 0.0
            self.command[k, :3] = u
            sim.step_torque(self.command[k], hold=TOOL_JOINTS)
        return sim.last_ddq, sim.last_effort


def run_cartesian(arm: Arm, scenario: Scenario, mode: str, config: SimConfig, duration_s: float | None = None) -> RunRecord:
    """A Cartesian task -> its RunRecord (metrics["error"] on divergence)."""
    from dvrk_dart.sim.simulator import PsmSimulator

    duration = duration_s or scenario.duration_s
    steps = int(round(duration / config.dt_s))
    driver = CartesianDriver(arm, scenario, mode, config.dt_s, steps)
    sim = PsmSimulator(arm.model, arm.params, config)
    sim.reset(driver.q0)
    start = time.perf_counter()
    log = simulate(sim, driver, steps, log_every(config.dt_s, steps))
    wall = time.perf_counter() - start
    logged = np.asarray(log.steps, dtype=int)
    record = RunRecord(
        name="",
        config={},
        t=np.asarray(log.steps, dtype=float) * config.dt_s,
        q=log.array("q"),
        dq=log.array("dq"),
        ddq=log.array("ddq"),
        effort_sim=log.array("effort"),
        effort_command=driver.command[logged] if mode == "torque" else None,
        tool_pose=log.tool_pose(),
        tool_pose_ref=driver.reference_pose[logged],
        closure_residual_m=np.asarray(log.closure, dtype=float),
        body_positions=log.body_positions(),
    )
    record.metrics = log.figures(config.dt_s, wall)
    if log.error is not None:
        record.metrics["error"] = str(log.error)
    return record


def log_every(dt_s: float, steps: int) -> int:
    """Steps between logged samples: every step at 1 ms, fewer for a smaller step or a long run."""
    return max(1, round(1.0 / (MAX_LOG_RATE_HZ * dt_s)), math.ceil(steps / MAX_LOGGED_SAMPLES))

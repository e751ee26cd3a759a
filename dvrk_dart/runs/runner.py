"""One run of a scenario: the simulation loop, the controller, the identified
model at the simulated states, and the metrics -> a RunRecord.

The identified model is evaluated at the simulated (q, dq, ddq) of each step,
where ddq is the acceleration the step produced: a "simulated" column is
always read from DART, never from the model.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_dart.model.arm import Arm
from dvrk_dart.sim.controllers import CartesianTorqueController, KinematicController
from dvrk_dart.errors import DvrkDartError, SimulationDiverged
from dvrk_dart.model.identified import TERMS
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.metrics import rms
from dvrk_dart.runs.record import RunRecord
from dvrk_dart.runs.scenarios import Scenario
from dvrk_dart.sim.config import SimConfig, simulated_terms

#: joints held by the velocity servo under torque control (the paper drives
#: J1..J3 only; the identified tool links are massless)
TOOL_JOINTS = tuple(range(3, N_JOINTS))
#: the torque-mode verdict looks at the error after the initial transient
TORQUE_TRANSIENT_S = 1.0


def run_name(scenario: str, mode: str, counterweight: str) -> str:
    return f"{scenario}_{mode}_cw-{counterweight}"


def pose_vector(T: np.ndarray) -> np.ndarray:
    """4x4 -> position (m) + quaternion (x, y, z, w)."""
    return np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_quat()]


def _rk4_step(f, t: float, q: np.ndarray, dt: float) -> np.ndarray:
    k1 = f(t, q)
    k2 = f(t + dt / 2, q + dt / 2 * k1)
    k3 = f(t + dt / 2, q + dt / 2 * k2)
    k4 = f(t + dt, q + dt * k3)
    return q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def run_cartesian(arm: Arm, scenario: Scenario, mode: str, config: SimConfig, duration_s: float | None = None) -> RunRecord:
    """The Cartesian tasks (rectilinear, spiral) in kinematic, velocity or torque mode."""
    from dvrk_dart.sim.simulator import PsmSimulator

    duration = duration_s or scenario.duration_s
    dt = config.dt_s
    steps = int(round(duration / dt))
    q0 = np.asarray(scenario.start_pose, dtype=float)
    pose0 = arm.identified.tool_tip_pose(q0)
    path = scenario.cartesian_path(pose0[:3, 3])
    R_d = pose0[:3, :3]
    kinematic = KinematicController(arm)
    torque = CartesianTorqueController(arm)

    def reference(t: float):
        p, v, a = path.position_velocity_acceleration(t)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R_d, p
        return T, np.r_[v, np.zeros(3)], a

    def closed_loop_velocity(t: float, q: np.ndarray) -> np.ndarray:
        T_d, twist_d, _ = reference(t)
        return kinematic.joint_velocity(q, T_d, twist_d)

    sim = PsmSimulator(arm.model, arm.params, config)
    sim.reset(q0)
    log = {k: np.full((steps, N_JOINTS), np.nan) for k in ("q", "dq", "ddq", "effort", "command")}
    tool_pose, tool_ref = np.zeros((steps, 7)), np.zeros((steps, 7))
    residual = np.zeros(steps)
    bodies: dict[str, np.ndarray] = {}
    t_log = np.arange(steps) * dt
    q_kin = q0.copy()
    completed = 0
    error: SimulationDiverged | None = None
    try:
        for k in range(steps):
            t = k * dt
            T_d, twist_d, acc_d = reference(t)
            if mode == "kinematic":
                # positions imposed; the controller ODE integrated with RK4 (exact to O(dt^4))
                dq = closed_loop_velocity(t, q_kin)
                sim.set_kinematic(q_kin, dq)
                log["q"][k], log["dq"][k] = q_kin, dq
            else:
                log["q"][k], log["dq"][k] = sim.q, sim.dq
            # every logged quantity refers to the start of the step, time t
            tool_pose[k] = pose_vector(sim.tool_tip_pose())
            tool_ref[k] = pose_vector(T_d)
            residual[k] = sim.closure_residual_m()
            for name, xyz in sim.body_positions().items():
                bodies.setdefault(name, np.full((steps, 3), np.nan))[k] = xyz
            if mode == "kinematic":
                q_kin = _rk4_step(closed_loop_velocity, t, q_kin, dt)
            else:
                q, dq = log["q"][k], log["dq"][k]
                if mode == "velocity":
                    sim.step_velocity(kinematic.joint_velocity(q, T_d, twist_d))
                else:
                    # semi-implicit Euler: q_k = q_(k-1) + dt dq_k, so the sampled velocity is the
                    # mean over the previous step, centred at t - dt/2: compare it with the
                    # reference velocity there (else a Kd a dt / 2Kp lag remains)
                    _, v_half, _ = path.position_velocity_acceleration(t - dt / 2)
                    u, _ = torque.efforts(q, dq, T_d[:3, 3], v_half, acc_d)
                    command = np.zeros(N_JOINTS)
                    command[:3] = u
                    log["command"][k] = command
                    sim.step_torque(command, hold=TOOL_JOINTS)
                # the effort of the step and the acceleration it produced
                log["ddq"][k], log["effort"][k] = sim.last_ddq, sim.last_effort
            completed = k + 1
    except SimulationDiverged as exc:
        error = exc
    n = completed
    record = RunRecord(
        name="",
        config={},
        t=t_log[:n],
        q=log["q"][:n],
        dq=log["dq"][:n],
        ddq=log["ddq"][:n],
        effort_sim=log["effort"][:n],
        effort_command=log["command"][:n] if mode == "torque" else None,
        tool_pose=tool_pose[:n],
        tool_pose_ref=tool_ref[:n],
        closure_residual_m=residual[:n],
        body_positions={k: v[:n] for k, v in bodies.items()},
    )
    if error is not None:
        record.metrics["error"] = str(error)
    return record


def tracking_errors(record: RunRecord) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample position (m) and orientation (rad, rotation vector) errors, reference - actual."""
    position = record.tool_pose_ref[:, :3] - record.tool_pose[:, :3]
    # the rotation vector of R_ref R^T, sample by sample (controllers.orientation_error, batched)
    orientation = (Rotation.from_quat(record.tool_pose_ref[:, 3:]) * Rotation.from_quat(record.tool_pose[:, 3:]).inv()).as_rotvec()
    return position, orientation


def add_model_efforts(arm: Arm, record: RunRecord) -> None:
    """The identified model, term by term, at the simulated states (dynamic modes)."""
    valid = np.all(np.isfinite(record.ddq), axis=1)
    if not valid.any():
        return
    efforts = arm.identified.efforts(record.q, record.dq, np.where(valid[:, None], record.ddq, 0.0), TERMS)
    record.effort_model = {k: np.where(valid[:, None], v, np.nan) for k, v in efforts.terms.items()}


def cartesian_metrics(record: RunRecord, mode: str, config: SimConfig) -> dict:
    position, orientation = tracking_errors(record)
    metrics = {
        "tracking_rms_position_m": rms(position).tolist(),
        "tracking_rms_orientation_rad": rms(orientation).tolist(),
    }
    if mode == "torque":
        after = record.t >= TORQUE_TRANSIENT_S
        metrics["tracking_rms_position_after_1s_m"] = rms(position[after]).tolist()
        norm = np.linalg.norm(position, axis=1)
        metrics["position_error_max_first_s_m"] = float(norm[~after].max()) if (~after).any() else None
    if mode != "kinematic" and record.effort_model:
        model = record.model_total(simulated_terms(config))
        ok = np.all(np.isfinite(record.effort_sim), axis=1) & np.all(np.isfinite(model), axis=1)
        metrics["rms_sim_vs_model"] = rms(record.effort_sim[ok] - model[ok]).tolist()
    return metrics


def run(arm: Arm, scenario: Scenario, mode: str, counterweight: str, config: SimConfig | None = None, duration_s: float | None = None) -> RunRecord:
    """Run one scenario variant; the record carries its resolved config and metrics."""
    if mode not in scenario.modes:
        raise DvrkDartError(f"--mode: scenario '{scenario.name}' runs in {', '.join(scenario.modes)}, not '{mode}'")
    if counterweight not in scenario.counterweights:
        raise DvrkDartError(
            f"--counterweight: scenario '{scenario.name}' runs with {', '.join(scenario.counterweights)}, not '{counterweight}'"
        )
    config = replace(config or SimConfig(), counterweight=counterweight)
    start = time.perf_counter()
    if scenario.kind == "replay":
        from dvrk_dart.runs.replay import replay

        try:
            record = replay(scenario.measured, mode=mode, config=config, duration_s=duration_s or scenario.duration_s)
        except SimulationDiverged as exc:  # keep what was logged up to the divergence
            record = exc.record
            record.metrics["error"] = str(exc)
    else:
        record = run_cartesian(arm, scenario, mode, config, duration_s)
        if mode != "kinematic":
            add_model_efforts(arm, record)
        record.metrics.update(cartesian_metrics(record, mode, config))
    record.name = run_name(scenario.name, mode, counterweight)
    record.config = {
        "scenario": scenario.to_dict(),
        "mode": mode,
        "counterweight": counterweight,
        "duration_s": float(record.t[-1] + config.dt_s) if len(record) else 0.0,
        "sim": config.to_dict(),
        "model_file": str(arm.model.source.name),
        "params_file": str(arm.params.source.name),
    }
    record.markers.setdefault("rcm", rcm_position(arm))
    record.metrics.update(
        {
            "scenario": scenario.name,
            "mode": mode,
            "counterweight": counterweight,
            "dt_s": config.dt_s,
            "duration_s": record.config["duration_s"],
            "samples": len(record),
            "wall_time_s": time.perf_counter() - start,
        }
    )
    if record.closure_residual_m is not None and len(record):
        record.metrics["closure_residual_max_m"] = float(np.max(record.closure_residual_m))
    return record


def rcm_position(arm: Arm) -> np.ndarray:
    """The remote centre of motion: where the tool axis crosses itself for any pitch."""
    frames_a = arm.model.forward_kinematics(np.zeros(N_JOINTS))
    frames_b = arm.model.forward_kinematics(np.r_[0.0, 0.3, np.zeros(N_JOINTS - 2)])
    (pa, za), (pb, zb) = ((f[8][:3, 3], f[8][:3, 2]) for f in (frames_a, frames_b))
    # closest points of the two tool axes
    A = np.column_stack([za, -zb])
    s, _ = np.linalg.lstsq(A, pb - pa, rcond=None)[0]
    return pa + s * za

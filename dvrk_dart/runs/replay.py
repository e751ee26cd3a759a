"""Replay of a measured run in the simulator (the paper's Sect. IV-B test):
the measured joint velocities, processed like upstream (or, with the periodic
processing, the analytic velocities of the excitation's harmonic series) and
interpolated onto the simulation grid, are the velocity servo's reference
(with position feedback to the measured q), starting at the measured pose.
With the periodic processing the efforts are compared in the band of the
excitation's harmonics: the simulated and model efforts at the measured
samples are projected on them, like the measured efforts.  The result is a RunRecord with
the simulated efforts, the identified model at the simulated state, the
measured efforts at the logged times, and the metrics of metrics.json."""

from __future__ import annotations

import math
from dataclasses import replace

import time
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.reference_data import load_run, resolve, resolve_run, run_label
from dvrk_dart.identification.effort_convention import effort_convention_notes
from dvrk_dart.identification.unrecorded_joints import unrecorded_joint_notes
from dvrk_dart.io.signal import MIN_KEPT_SAMPLES, ProcessedRun, process
from dvrk_dart.io.period import spanning_columns
from dvrk_dart.metrics import per_measured_joint, rms
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.identified import TERMS, IdentifiedModel
from dvrk_dart.model.parameters import IdentifiedParameters, load_parameters
from dvrk_dart.runs.loop import LoopLog, simulate
from dvrk_dart.io.record import RunRecord
from dvrk_dart.sim.config import MODES, SimConfig, simulated_terms
from dvrk_dart.sim.simulator import PsmSimulator

#: torque-mode replay: the bandwidth of the computed-torque controller (the
#: paper's Eq. 6-7 with the simulated arm's own inertia, critically damped,
#: every joint alike: kp = w^2, kd = 2 w)
TORQUE_REPLAY_BANDWIDTH_HZ = 10.0
#: velocity and torque replays: the velocity references sit half a step before
#: the position grid. DART integrates semi-implicitly (x_k+1 = x_k + dt v_k+1), so
#: v_k+1 is the velocity over [t_k, t_k+1], at its midpoint, and the step's
#: acceleration (v_k+1 - v_k) / dt is then centred on t_k, where the state's
#: positions and the logged effort are. Velocity targets at t_k+1 put the
#: inertial effort half a step late (inertia x jerk x dt/2: 0.002 N·m RMS on J1
#: of the excitation runs, tests/test_replay.py); the torque mode's damping
#: against unstaggered velocities tracked the positions to 7e-5 rad, not 3e-8
VELOCITY_TARGET_STAGGER_STEPS = 0.5


def replay(
    measured: str | Path,
    model: PsmModel,
    mode: str = "velocity",
    config: SimConfig = SimConfig(),
    duration_s: float | None = None,
    log_every: int = 5,
    params: IdentifiedParameters | None = None,
    processing: str = "upstream",
    harmonics: int | None = None,
    topics: BagTopics = BagTopics(),
) -> RunRecord:
    """Replay a measured run of `model`'s arm ('two', a manifest name or a CSV
    path; a bag read with `topics`).

    On divergence, raises SimulationDiverged whose `record` attribute holds the
    RunRecord of what was logged so far (metrics["error"] = the message)."""
    if mode not in MODES:
        raise DvrkDartError(f"mode must be one of {', '.join(MODES)}, not '{mode}'")
    if log_every < 1:
        raise DvrkDartError("log_every must be >= 1")
    params = params or load_parameters(resolve(model.default_parameters), model)
    processed = process(load_run(resolve_run(measured), model, topics), processing, harmonics)
    return replay_processed(processed, measured, mode, config, duration_s, log_every, model, params)


def replay_duration(processed: ProcessedRun, duration_s: float | None) -> float:
    """The replayed span: `duration_s`, or the whole processed run (checked against it)."""
    available = float(processed.t[-1] - processed.t[0])
    duration = available if duration_s is None else float(duration_s)
    if not 0.0 < duration <= available + 1e-12:
        raise DvrkDartError(f"--duration: {duration:g} s outside (0, {available:.3f}] s, what the {processed.processing} processing keeps "
                            "of the measured run (without the ends it trims or a transient it leaves out)")
    shortest = (MIN_KEPT_SAMPLES - 1) / processed.rate_hz
    if duration < shortest - 1e-12:
        raise DvrkDartError(f"--duration: {duration:g} s holds fewer than {MIN_KEPT_SAMPLES} samples of the measured run "
                            f"(one every {1e3 / processed.rate_hz:g} ms): at least {shortest:g} s to compare anything")
    return duration


def replay_processed(
    processed: ProcessedRun,
    measured: str | Path,
    mode: str,
    config: SimConfig,
    duration_s: float | None,
    log_every: int,
    model: PsmModel,
    params: IdentifiedParameters,
    through_last_sample: bool = False,
) -> RunRecord:
    """The replay of an already processed run (`measured` names it).

    through_last_sample: one more step so that the logged samples cover every
    measured sample (the last step's position reference is extrapolated by a
    step, its velocity reference by half a step)."""
    identified = IdentifiedModel(model, params)
    t_meas = processed.t - processed.t[0]
    duration = replay_duration(processed, duration_s)

    dt = config.dt_s
    steps = int(round(duration / dt)) + (1 if through_last_sample else 0)
    q_ref = CubicSpline(t_meas, processed.q)
    # torque mode: the measured positions' spline and its derivatives (a consistent trajectory:
    # the measured velocities differ from d/dt q by 0.01-0.08 rad/s, which costs tracking)
    dq_ref = q_ref.derivative() if mode == "torque" else CubicSpline(t_meas, processed.dq)
    # references on the simulation grid, evaluated once (t_k = k dt, k = 0..steps); the
    # simulated velocities are staggered half a step (VELOCITY_TARGET_STAGGER_STEPS)
    grid = np.arange(steps + 1) * dt
    velocity_grid = grid if mode == "kinematic" else grid - VELOCITY_TARGET_STAGGER_STEPS * dt
    sim = PsmSimulator(model, params, config)
    sim.reset(q_ref(0.0), dq_ref(velocity_grid[0]))
    driver = ReplayDriver(mode, q_ref(grid), dq_ref(velocity_grid), dt)
    if mode == "torque":
        driver.ddq_grid = q_ref(grid, 2)
        omega = 2.0 * np.pi * TORQUE_REPLAY_BANDWIDTH_HZ
        driver.kp, driver.kd = omega**2, 2.0 * omega
    wall_start = time.perf_counter()
    log = simulate(sim, driver, steps, log_every)
    wall = time.perf_counter() - wall_start

    record = _record(measured, mode, config, log, identified, processed, t_meas, duration, wall)
    if log.error is not None:
        log.error.record = record
        raise log.error
    return record


class ReplayDriver:
    """Velocity servo to the measured velocities (with position feedback),
    computed torque with the simulated arm's own inertia, or imposed positions."""

    def __init__(self, mode: str, q_grid: np.ndarray, dq_grid: np.ndarray, dt: float):
        self.mode, self.q_grid, self.dq_grid, self.dt = mode, q_grid, dq_grid, dt
        self.ddq_grid = self.kp = self.kd = None

    def impose(self, k: int, sim) -> None:
        pass

    def advance(self, k: int, sim) -> tuple[np.ndarray, np.ndarray]:
        if self.mode == "velocity":
            sim.step_velocity(self.dq_grid[k + 1], self.q_grid[k])  # feedback on the position at the state's own time
            return sim.last_ddq, sim.last_effort
        if self.mode == "torque":
            # Eq. 6-7 with DART's own M (near-massless wrist links included: exact, no gain floor)
            M, b, explicit = sim.joint_space_dynamics()
            a = self.ddq_grid[k] + self.kd * (self.dq_grid[k] - sim.dq) + self.kp * (self.q_grid[k] - sim.q)
            sim.step_torque(M @ a + b + explicit)
            return sim.last_ddq, sim.last_effort
        dq_before = sim.dq
        sim.set_kinematic(self.q_grid[k + 1], self.dq_grid[k + 1])
        return (sim.dq - dq_before) / self.dt, sim.last_effort


def _not_recorded_as_nan(processed: ProcessedRun, tau: np.ndarray, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, ...]:
    """The measured columns as logged: a joint the run did not record is not measured (null in run.mcap, no
    series in run.rrd), not zeros a viewer draws as measured; its positions stay where the log has them."""
    recorded = np.asarray(processed.measured, dtype=bool)
    unlogged = ~(recorded | spanning_columns(processed.q))
    tau[:, ~recorded], q[:, unlogged], dq[:, unlogged] = np.nan, np.nan, np.nan
    return tau, q, dq


def _record(measured, mode, config, log: LoopLog, identified, processed, t_meas, duration, wall) -> RunRecord:
    dt = config.dt_s
    t = np.asarray(log.steps, dtype=float) * dt
    shape = (len(t), 7)
    q, dq, ddq, effort = (log.array(k) for k in ("q", "dq", "ddq", "effort"))
    model_terms = identified.efforts(q, dq, ddq, TERMS).terms if len(t) else {name: np.zeros(shape) for name in TERMS}

    # measured values at the logged times (exact samples when logging at the data's 200 Hz)
    def at_logged_times(x: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, t_meas, x[:, j]) for j in range(x.shape[1])]) if len(t) else np.zeros(shape)

    tau_meas, q_meas, dq_meas = _not_recorded_as_nan(processed, *(at_logged_times(x) for x in (processed.tau, processed.q, processed.dq)))
    recorded = np.asarray(processed.measured, dtype=bool)  # a joint the run did not record has no figure against the run
    record = RunRecord(
        name=f"replay-{run_label(measured)}_{mode}_cw-{config.counterweight}",
        config={**config.to_dict(), "mode": mode, "measured": str(measured)},
        t=t,
        q=q,
        dq=dq,
        ddq=ddq,
        effort_sim=effort,
        effort_model=model_terms,
        q_measured=q_meas,
        dq_measured=dq_meas,
        effort_measured=tau_meas,
        tool_pose=log.tool_pose(),
        closure_residual_m=np.asarray(log.closure, dtype=float),
        body_positions=log.body_positions(),
    )
    in_window = t_meas <= duration + 1e-9
    full_model = identified.predict(processed.q[in_window], processed.dq[in_window], processed.ddq[in_window], TERMS)
    sim_terms = simulated_terms(config)
    dynamic = mode != "kinematic" and len(t) > 0
    metrics = {
        "scenario": run_label(measured),
        "mode": mode,
        "counterweight": config.counterweight,
        "dt_s": dt,
        "wall_time_s": wall,
        **log.figures(dt, wall),
        "model_terms_compared": list(sim_terms),
        "rms_sim_vs_model": per_measured_joint(rms(effort - record.model_total(sim_terms)), recorded) if dynamic else None,
        "rms_sim_vs_measured": per_measured_joint(rms(effort - tau_meas), recorded) if dynamic else None,
        "rms_model_vs_measured": per_measured_joint(rms(full_model - processed.tau[in_window]), recorded),
        "unrecorded_joint_notes": unrecorded_joint_notes(identified, processed, rms(full_model - processed.tau[in_window])),
        "effort_convention_notes": effort_convention_notes(full_model, processed.tau[in_window], processed.measured),
        "measured_samples": int(in_window.sum()),  # the model's figure's; the log's stop a step short of the last
        "rms_q_sim_vs_measured": per_measured_joint(rms(q - q_meas), recorded) if len(t) else None,
        "tracking_notes": not_following_notes(q, q_meas, recorded) if len(t) else [],
        "closure_residual_max_m": float(np.max(record.closure_residual_m, initial=0.0)),
    }
    metrics |= processed.summary()
    metrics["measured_joints"] = [name for name, on in zip(JOINT_NAMES, processed.measured) if on]
    if processed.periodic is not None and dynamic:
        metrics |= _in_band_metrics(processed, t, effort, full_model, in_window)
    if log.error is not None:
        metrics["error"] = str(log.error)
    record.metrics = metrics
    return record


#: a replayed joint whose position error's RMS passes this share of its measured motion's (about its mean) does not
#: follow the motion: its simulated efforts are another motion's (a torque-mode wrist held by friction the gains
#: do not overcome: 1.7 rad off a +-1 rad motion, its efforts 200 times the measured)
NOT_FOLLOWING_SHARE = 0.25


def not_following_notes(q: np.ndarray, q_measured: np.ndarray, recorded: np.ndarray) -> list[str]:
    """A note naming the recorded joints whose simulated motion does not follow the measured one."""
    error, motion = rms(q - q_measured), rms(q_measured - q_measured.mean(axis=0))
    moving = spanning_columns(q_measured)  # a still joint's 1e-14 of round-off is no motion to follow
    lost = [j for j in range(len(error)) if recorded[j] and moving[j] and error[j] > NOT_FOLLOWING_SHARE * motion[j]]
    if not lost:
        return []
    return [f"{', '.join(JOINT_NAMES[j] for j in lost)}: the simulation does not follow the measured motion (position error RMS "
            f"{', '.join(f'{error[j]:.3g}' for j in lost)} against the motion's {', '.join(f'{motion[j]:.3g}' for j in lost)}, "
            f"rad or m): their simulated efforts are not the measured motion's"]


def in_band_at_samples(processed: ProcessedRun, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Logged values at the measured samples, in the measured efforts' band
    (the log stops a step short of the last sample: its last value is held there)."""
    t_meas = processed.t - processed.t[0]
    return processed.in_band(np.column_stack([np.interp(t_meas, t, x[:, j]) for j in range(x.shape[1])]))


def _in_band_metrics(processed: ProcessedRun, t: np.ndarray, effort: np.ndarray, full_model: np.ndarray, in_window: np.ndarray) -> dict:
    """Periodic processing: simulated and model efforts at the measured samples,
    projected on the excitation's harmonics like the measured efforts (a whole
    run only: a part of it has no projection of its own)."""
    if not in_window.all() or len(t) < 2:
        return {"rms_sim_vs_measured": None, "rms_model_vs_measured": None,
                "in_band_note": "a part of the run: the periodic comparison needs the whole run"}
    return {
        "rms_sim_vs_measured": per_measured_joint(rms(in_band_at_samples(processed, t, effort) - processed.tau), processed.measured),
        "rms_model_vs_measured": per_measured_joint(rms(processed.in_band(full_model) - processed.tau), processed.measured),
        "in_band_note": "simulated and model efforts at the measured samples, projected on the excitation's harmonics",
    }


#: a step may be this fraction longer than the configured one to fit a whole number
#: of times in a sample period (199.995 Hz: 1.00002 ms, not 0.83 ms and 6 steps)
STEP_LENGTHENING = 1e-3


def simulate_efforts(arm, config: SimConfig, processed: ProcessedRun) -> np.ndarray:
    """Simulated efforts at every sample of a processed run (velocity replay):
    the `simulate` hook of the diagnosis. A run whose sample period is not a
    multiple of the step (a time column read at 199.995 Hz, a 300 Hz logger) is
    simulated with the step shortened to a whole fraction of its period: the
    efforts are then read at its samples, not beside them."""
    period = float(processed.t[1] - processed.t[0])
    every = max(1, math.ceil(period / config.dt_s - STEP_LENGTHENING))
    if abs(every * config.dt_s - period) > 1e-9:
        config = replace(config, dt_s=period / every)
    record = replay_processed(
        processed, "diagnosis", "velocity", config, None, every, arm.model, arm.params, through_last_sample=True
    )
    return record.effort_sim[: len(processed)]

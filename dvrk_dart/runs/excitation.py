"""Trajectories for a real dVRK to play: the identification's excitations
("one", "two") and the Cartesian scenarios' joint trajectories, in the dVRK's
joints and units, checked against the joint and velocity limits.

The excitations are periodic Fourier series of 6 harmonics (data README).
Upstream's optimised coefficients are binary pickles that this project does not
fetch, so the series are *fitted* here to the measured runs: for a base
frequency, linear least squares of each joint's measured position (dVRK
coordinates) on a constant and the sines and cosines of the 6 harmonics over the
whole run; the base frequency is the one whose fit leaves the smallest residual.
It is 0.1543 Hz in the data's time (rows at 200 Hz: a period of 1296 rows), not
the nominal 0.18 Hz (1111 rows), with which no 6-harmonic series fits (residuals
of 0.2-0.8 rad). The fit's residuals (position and velocity against the
measured ones) and both frequencies are recorded in excitation.json.

The Cartesian scenarios' joint trajectories are those of their kinematic mode:
the Eq. 5 controller integrated with RK4 (runs/cartesian.py), no simulation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.provenance import arm_model_record, file_record, software_versions
from dvrk_dart.model.description import PsmModel, resolve_arm_model
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.metrics import rms

#: the identification's excitation (data README): nominal base frequency and harmonics
EXCITATION_BASE_HZ = 0.18
EXCITATION_HARMONICS = 6
#: where the fitted base frequency is searched (Hz): wide around the nominal one,
#: on a grid finer than the fit's sharpness (its residual doubles within 2e-4 Hz)
BASE_SEARCH_HZ = (0.10, 0.25)
BASE_SEARCH_STEP_HZ = 1e-4
SEARCH_DECIMATION = 10
#: the slowest setpoint stream a dVRK can play smoothly: servo_jp jumps to each
#: setpoint (no interpolation), so setpoints more than 20 ms apart jerk the arm
MIN_SERVO_RATE_HZ = 50.0
#: the measured runs whose excitations can be played
EXCITATIONS = ("one", "two")
#: integration step of the Cartesian scenarios' kinematic controller: the
#: simulator's default step, with which the kinematic runs track to ~1e-15 m
MAX_KINEMATIC_STEP_S = 1e-3
#: the played bag speeds up from rest along the trajectory, and slows to rest at its end, over this long (s): a
#: trajectory cut from a periodic series starts and ends mid-motion ("two": the pitch at -1.28 rad/s, the jaw at
#: 1.56), which played from rest is a velocity step on the real arm. 1 s: accelerations within the series' own
#: ("one", "two": up to 5.5 rad/s^2 on the yaw, 8.4 in the series), and short enough that the periodic layer's
#: transient windows (an eighth of a period) take nearly all of it (2 s left a period 4e-4 long)
LEAD_S = 1.0


@dataclass
class Excitation:
    """A joint trajectory in the model's coordinates (q1..q7), on a uniform grid."""

    name: str
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    source: dict = field(default_factory=dict)  # how it was made (recorded in excitation.json)


def fourier_basis(t: np.ndarray, base_hz: float = EXCITATION_BASE_HZ, harmonics: int = EXCITATION_HARMONICS) -> tuple[np.ndarray, np.ndarray]:
    """(position basis, velocity basis), each (len(t), 1 + 2 * harmonics):
    columns 1, sin(l w t), cos(l w t) for l = 1..harmonics and their derivatives."""
    w = 2 * math.pi * base_hz
    lw = w * np.arange(1, harmonics + 1)
    phase = np.outer(t, lw)
    position = np.hstack([np.ones((len(t), 1)), np.sin(phase), np.cos(phase)])
    velocity = np.hstack([np.zeros((len(t), 1)), lw * np.cos(phase), -lw * np.sin(phase)])
    return position, velocity


def _fit_residual(t: np.ndarray, q: np.ndarray, base_hz: float) -> float:
    basis, _ = fourier_basis(t, base_hz)
    coefficients, *_ = np.linalg.lstsq(basis, q, rcond=None)
    return float(rms(basis @ coefficients - q, axis=None))


def fitted_base_frequency(t: np.ndarray, q: np.ndarray) -> float:
    """The base frequency whose 6-harmonic series fits q(t) best (grid, then refined)."""
    from scipy.optimize import minimize_scalar

    grid = np.arange(BASE_SEARCH_HZ[0], BASE_SEARCH_HZ[1], BASE_SEARCH_STEP_HZ)
    # the grid on every SEARCH_DECIMATION-th sample (20 Hz still resolves the 6th
    # harmonic, 0.9 Hz), the refinement on all of them
    coarse_t, coarse_q = t[::SEARCH_DECIMATION], q[::SEARCH_DECIMATION]
    best = grid[int(np.argmin([_fit_residual(coarse_t, coarse_q, f) for f in grid]))]
    refined = minimize_scalar(lambda f: _fit_residual(t, q, f), bounds=(best - BASE_SEARCH_STEP_HZ, best + BASE_SEARCH_STEP_HZ), method="bounded")
    return float(refined.x)


def fitted_excitation(name: str, rate_hz: float, model: PsmModel) -> Excitation:
    """The Fourier series fitted to the measured run `name` of `model`'s arm, sampled at rate_hz."""
    from dvrk_dart.io.reference_data import RUNS, load_run, resolve_run
    if name not in EXCITATIONS:
        raise DvrkDartError(f"unknown excitation '{name}' (known: {', '.join(EXCITATIONS)})")
    path = resolve_run(name)
    run = load_run(path, model)
    motor_map = model.motor_map
    q_dvrk, dq_dvrk = motor_map.positions_to_dvrk(run.q), motor_map.positions_to_dvrk(run.dq)
    base_hz = fitted_base_frequency(run.t, q_dvrk)
    basis, dbasis = fourier_basis(run.t, base_hz)
    coefficients, *_ = np.linalg.lstsq(basis, q_dvrk, rcond=None)
    t = np.arange(int(math.floor(run.t[-1] * rate_hz + 1e-9)) + 1) / rate_hz
    position, velocity = fourier_basis(t, base_hz)
    q = motor_map.positions_to_model(position @ coefficients)
    dq = motor_map.positions_to_model(velocity @ coefficients)
    source = {
        "kind": "fourier series fitted to a measured run",
        "measured": RUNS[name],
        "measured_file": file_record(path),
        "base_frequency_hz": base_hz,
        "nominal_base_frequency_hz": EXCITATION_BASE_HZ,
        "harmonics": EXCITATION_HARMONICS,
        "joints": list(model.dvrk_topics.joint_names),
        # rows: constant, sin(l w t) for l = 1..6, cos(l w t) for l = 1..6; columns: dVRK joints
        "coefficients": coefficients.tolist(),
        "fit_rms_position": rms(basis @ coefficients - q_dvrk).tolist(),
        "fit_rms_velocity": rms(dbasis @ coefficients - dq_dvrk).tolist(),
    }
    return Excitation(name, t, q, dq, source)


def cartesian_excitation(name: str, rate_hz: float, arm: Arm) -> Excitation:
    """A Cartesian scenario's joint trajectory (its kinematic mode on `arm`), at rate_hz."""
    from dvrk_dart.runs.cartesian import CartesianDriver
    from dvrk_dart.runs.scenarios import available_scenarios, load_scenario

    if not name.endswith(".toml") and name not in available_scenarios():
        cartesian = [n for n in available_scenarios() if load_scenario(n).kind == "cartesian"]
        raise DvrkDartError(f"excitation '{name}': one of {', '.join(EXCITATIONS)} (the identification's excitations), "
                            f"a Cartesian scenario ({', '.join(cartesian)}) or a scenario's .toml file")
    scenario = load_scenario(name)
    if scenario.kind != "cartesian":
        raise DvrkDartError(f"'{name}' is a {scenario.kind} scenario: an excitation is {', '.join(EXCITATIONS)} or a Cartesian scenario")
    if scenario.arm_model and resolve_arm_model(scenario.arm_model).resolve() != arm.model.source.resolve():
        raise DvrkDartError(f"{scenario.source}: a path of the arm {scenario.arm_model} (its arm_model), not of {arm.model.source.name}'s")
    substeps = max(1, math.ceil(1.0 / (rate_hz * MAX_KINEMATIC_STEP_S) - 1e-9))
    dt = 1.0 / (rate_hz * substeps)
    samples = int(math.floor(scenario.duration_s * rate_hz + 1e-9)) + 1
    if samples < 2:
        raise DvrkDartError(f"{scenario.source}: duration_s {scenario.duration_s:g} s holds no two samples at {rate_hz:g} Hz")
    steps = (samples - 1) * substeps + 1
    driver = CartesianDriver(arm, scenario, "kinematic", dt, steps)
    q, dq = np.empty((samples, N_JOINTS)), np.empty((samples, N_JOINTS))
    for k in range(steps):
        if k % substeps == 0:
            q[k // substeps] = driver.q_kin
            dq[k // substeps] = driver.closed_loop_velocity(k * dt, driver.q_kin)
        if k < steps - 1:
            driver.advance(k, None)
    source = {"kind": "Cartesian scenario, kinematic mode (Eq. 5 controller, RK4)", "scenario": str(scenario.source),
              "scenario_file": file_record(scenario.source), "integration_step_s": dt}
    return Excitation(scenario.name, np.arange(samples) / rate_hz, q, dq, source)


def build_excitation(name: str, rate_hz: float, arm: Arm) -> Excitation:
    """The excitation `name` (a measured run's Fourier fit, or a Cartesian scenario) of `arm`, checked."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise DvrkDartError(f"--rate: {rate_hz!r} is not a positive rate (Hz)")
    if rate_hz < MIN_SERVO_RATE_HZ:
        raise DvrkDartError(f"--rate: {rate_hz:g} Hz is below {MIN_SERVO_RATE_HZ:g} Hz: servo_jp jumps to each setpoint, "
                            f"{1 / rate_hz:.3g} s apart would jerk the arm")
    excitation = fitted_excitation(name, rate_hz, arm.model) if name in EXCITATIONS else cartesian_excitation(name, rate_hz, arm)
    check_limits(excitation, arm.model)  # the played bag's path and speeds are within the trajectory's
    return excitation


def _path_time(t: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory's time s(t) a played bag is at, and ds/dt: the speed along the path rises from rest over
    LEAD_S (a quintic smoothstep: no velocity or acceleration step), stays 1, and falls to rest over the last
    LEAD_S; the path covers the whole trajectory in duration + LEAD_S."""
    def rise(x):  # the smoothstep and its integral (LEAD_S * 0.5 at x = 1)
        x = np.clip(x, 0.0, 1.0)
        return x**3 * (10 - 15 * x + 6 * x**2), LEAD_S * x**4 * (2.5 - 3 * x + x**2)

    up, up_path = rise(t / LEAD_S)
    down, down_path = rise((t - duration) / LEAD_S)
    speed = up - down
    s = up_path + np.clip(t - LEAD_S, 0.0, None) - (down_path + np.clip(t - duration - LEAD_S, 0.0, None))
    return s, speed


def played(excitation: Excitation) -> Excitation:
    """What the bag plays: the trajectory's own path, speeding up from rest over LEAD_S and slowing to rest over
    the last LEAD_S (never faster than the trajectory, never off its positions: its checks hold)."""
    from scipy.interpolate import CubicSpline

    dt = float(excitation.t[1] - excitation.t[0])
    duration = float(excitation.t[-1] - excitation.t[0])
    t = np.arange(int(round((duration + LEAD_S) / dt)) + 1) * dt
    s, speed = _path_time(t, duration)
    path = CubicSpline(excitation.t - excitation.t[0], excitation.q, axis=0)
    return Excitation(excitation.name, t, path(np.clip(s, 0.0, duration)), path(np.clip(s, 0.0, duration), 1) * speed[:, None],
                      excitation.source)


def check_limits(excitation: Excitation, model: PsmModel) -> None:
    """Joint limits (the model's ranges, as for every measured run) and the dVRK's
    velocity limits ([dvrk_velocity_limits] of the model): one-line refusal."""
    from dvrk_dart.io.reference_data import check_joint_ranges
    if not (np.isfinite(excitation.q).all() and np.isfinite(excitation.dq).all()):
        raise DvrkDartError(f"excitation {excitation.name}: the trajectory has non-finite values")
    check_joint_ranges(excitation.q, f"excitation {excitation.name}", model)
    if model.dvrk_velocity_limits is None:
        raise DvrkDartError(f"{model.source}: no [dvrk_velocity_limits]: cannot check the excitation's velocities")
    speed = np.abs(model.motor_map.positions_to_dvrk(excitation.dq))
    over = speed > model.dvrk_velocity_limits
    if over.any():
        k, j = np.argwhere(over)[0]
        unit = model.velocity_unit(JOINT_NAMES[j])
        raise DvrkDartError(
            f"excitation {excitation.name}: {model.dvrk_topics.joint_names[j]} moves at {speed[k, j]:.3f} {unit} at t = {excitation.t[k]:.3f} s, "
            f"over the velocity limit {model.dvrk_velocity_limits[j]:g} {unit} ({model.source.name}, [dvrk_velocity_limits])"
        )


def write_excitation(excitation: Excitation, folder, model: PsmModel, namespace: str | None) -> dict:
    """NAME.csv (time + dVRK joint names, dVRK units), NAME_servo_jp (a ROS 2 bag
    of servo_jp commands of `model`'s arm in `namespace`, the jaw on
    jaw/servo_jp) and excitation.json, in `folder`."""
    from dvrk_dart.io.atomic import write_json_atomic, write_text_atomic
    from dvrk_dart.io.bag_writer import arm_joint_states, write_bag
    if Path(excitation.name).name != excitation.name or excitation.name in ("", ".", ".."):
        raise DvrkDartError(f"excitation name '{excitation.name}' cannot name a file")
    dvrk = model.motor_map.positions_to_dvrk(excitation.q)
    joints = model.dvrk_topics.joint_names
    header = ",".join(["time", *joints])
    rows = "\n".join(",".join(f"{v:.17g}" for v in row) for row in np.column_stack([excitation.t, dvrk]))
    csv = folder / f"{excitation.name}.csv"
    write_text_atomic(csv, header + "\n" + rows + "\n")
    bag = folder / f"{excitation.name}_servo_jp"
    playing = played(excitation)
    states = arm_joint_states(model, namespace, playing.t, playing.q, suffix="servo_jp")
    write_bag(bag, states)
    start = model.motor_map.positions_to_dvrk(playing.q[0])
    summary = {
        "versions": software_versions(),
        "arm_model": arm_model_record(model),
        "name": excitation.name,
        "samples": len(excitation.t),
        "duration_s": float(excitation.t[-1]),
        "rate_hz": float(1.0 / (excitation.t[1] - excitation.t[0])),
        "csv": csv.name,
        "bag": bag.name,
        "topics": [state.topic for state in states],
        "lead_s": LEAD_S,
        "bag_definition": ("the bag plays the CSV's positions along its path, from rest at its first row (start_pose), "
                           "speeding up over lead_s and slowing to rest at its last row over lead_s: the CSV's time "
                           "minus lead_s / 2 between them, lead_s / 2 longer in all"),
        "start_pose": dict(zip(joints, start.tolist())),
        "max_speed": dict(zip(joints, np.abs(model.motor_map.positions_to_dvrk(playing.dq)).max(axis=0).tolist())),
        "source": excitation.source,
    }
    write_json_atomic(folder / "excitation.json", summary)
    return summary

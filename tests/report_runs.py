"""Small runs folders for the analysis and report tests: run folders as the
campaign writes them (run.mcap, config.json, metrics.json), from real short
simulations and from synthetic records with known answers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.mcap_log import write_mcap
from dvrk_dart.io.record import RunRecord
from dvrk_dart.sim.config import SimConfig
from arms import PSM, PSM_ARM  # noqa: F401

#: synthetic torque run: the x error is this constant after the transient, so
#: its RMS after 1 s is known exactly
SYNTHETIC_ERROR_AFTER_1S_M = 5e-5
SYNTHETIC_DT_S = 0.01
SYNTHETIC_DURATION_S = 2.0
#: synthetic velocity run: simulated = model + this offset on every joint
SYNTHETIC_EFFORT_OFFSET = 0.1


def write_run(record: RunRecord, runs_dir: Path) -> Path:
    """The run folder of `record`, like campaign.write_run_folder without the .rrd."""
    folder = runs_dir / record.name
    folder.mkdir(parents=True, exist_ok=True)
    write_json_atomic(folder / "config.json", {"run": record.name, **record.config, "inputs_sha256": None})
    write_json_atomic(folder / "metrics.json", record.metrics)
    write_mcap(record, folder / "run.mcap", PSM)
    return folder


def _config(scenario: str, mode: str, counterweight: str, duration_s: float, **sim) -> dict:
    return {
        "scenario": {"name": scenario, "kind": "cartesian"},
        "mode": mode,
        "counterweight": counterweight,
        "duration_s": duration_s,
        "sim": SimConfig(dt_s=SYNTHETIC_DT_S, counterweight=counterweight, **sim).to_dict(),
    }


def synthetic_torque_record() -> RunRecord:
    """A torque-mode Cartesian run whose x error decays to a known constant after 1 s."""
    t = np.arange(0.0, SYNTHETIC_DURATION_S, SYNTHETIC_DT_S)
    n = len(t)
    ref = np.zeros((n, 7))
    ref[:, 0] = 0.01 * t
    ref[:, 6] = 1.0  # identity quaternion (x, y, z, w)
    pose = ref.copy()
    pose[:, 0] -= np.where(t < 1.0, 1e-3 * np.exp(-5 * t), SYNTHETIC_ERROR_AFTER_1S_M)
    command = np.zeros((n, 7))
    command[:, :3] = np.column_stack([np.sin(t), np.cos(t), 2.0 + 0.1 * t])
    effort = command.copy()
    model = {"inertia": np.zeros((n, 7)), "coriolis": np.zeros((n, 7)), "gravity": command.copy()}
    name = "rectilinear_torque_cw-on"
    return RunRecord(
        name=name,
        config=_config("rectilinear", "torque", "on", SYNTHETIC_DURATION_S),
        t=t,
        q=np.zeros((n, 7)),
        dq=np.zeros((n, 7)),
        ddq=np.zeros((n, 7)),
        effort_sim=effort,
        effort_model=model,
        effort_command=command,
        tool_pose=pose,
        tool_pose_ref=ref,
        closure_residual_m=np.full(n, 1e-12),
        metrics={"scenario": "rectilinear", "mode": "torque", "counterweight": "on"},
    )


def synthetic_velocity_record(friction: bool = False) -> RunRecord:
    """A velocity run: simulated = model (simulated terms) + a constant offset; some NaN rows.

    Joint 1 moves slowly for the first half (near-zero velocity regime) and joint 2's
    acceleration has a known spike set (high-acceleration regime)."""
    t = np.arange(0.0, SYNTHETIC_DURATION_S, SYNTHETIC_DT_S)
    n = len(t)
    rng = np.random.default_rng(0)
    terms = {name: rng.normal(size=(n, 7)) for name in ("inertia", "coriolis", "gravity", "friction", "offset", "spring", "motor_inertia")}
    simulated = ("inertia", "coriolis", "gravity") + (("friction",) if friction else ())
    effort = sum(terms[k] for k in simulated) + SYNTHETIC_EFFORT_OFFSET
    effort[:3] = np.nan  # e.g. the first steps of a run that logs no effort yet
    dq = np.full((n, 7), 1.0)
    dq[: n // 2, 0] = 0.0
    ddq = np.ones((n, 7))
    name = "synthetic_velocity_cw-on"
    return RunRecord(
        name=name,
        config=_config("synthetic", "velocity", "on", SYNTHETIC_DURATION_S, friction=friction),
        t=t,
        q=np.zeros((n, 7)),
        dq=dq,
        ddq=ddq,
        effort_sim=effort,
        effort_model=terms,
        closure_residual_m=np.full(n, 2e-12),
        metrics={"scenario": "synthetic", "mode": "velocity", "counterweight": "on"},
    )


def real_short_runs(runs_dir: Path, duration_s: float = 1.0) -> list[str]:
    """Short runs of the real simulator: kinematic, velocity with and without the
    counterweight, and replays of the measured run 'two' with the paper's arm
    and with every identified term simulated."""
    from dvrk_dart.runs.config import RunConfig
    from dvrk_dart.runs.runner import run

    arm = PSM_ARM
    names = []
    for scenario, mode, counterweight, dynamics in (
        ("rectilinear", "kinematic", "on", "inertial"),
        ("rectilinear", "velocity", "on", "inertial"),
        ("rectilinear", "velocity", "off", "inertial"),
        ("replay", "velocity", "on", "inertial"),
        ("replay", "velocity", "on", "identified"),
    ):
        measured = "two" if scenario == "replay" else None
        record = run(RunConfig(scenario, mode, counterweight, dynamics, duration_s=duration_s, measured=measured), arm)
        record.name = record.name.removesuffix(f"_first-{duration_s:g}s")  # short stand-ins, under the check runs' names
        write_run(record, runs_dir)
        names.append(record.name)
    return names

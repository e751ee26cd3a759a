"""Scenarios end to end: tracking, efforts against the model, logs, CLI."""

import json
import subprocess
import sys

import numpy as np
import pytest

from dvrk_dart.analysis.checks import load_checks
from dvrk_dart.io.mcap_read import read_mcap
from dvrk_dart.runs.config import RunConfig
from dvrk_dart.runs.runner import run
from arms import PSM_ARM

#: the thresholds are the validation's own (pipelines/checks.toml)
THRESHOLDS = {check["id"]: check["threshold"] for check in load_checks()}
TRACKING_POSITION_M = THRESHOLDS["kinematic-tracking-position"]
TRACKING_ORIENTATION_RAD = THRESHOLDS["kinematic-tracking-orientation"]
#: RMS(sim - model) on J1..J3 with the counterweight (N·m, N·m, N)
SIM_VS_MODEL = THRESHOLDS["velocity-sim-vs-model-with-counterweight"]
CLOSURE_M = THRESHOLDS["loop-closure"]


@pytest.fixture(scope="module")
def runs(arm):
    cache = {}

    def get(scenario, mode, cw="on", duration=None):
        key = (scenario, mode, cw, duration)
        if key not in cache:
            cache[key] = run(RunConfig(scenario, mode, cw, duration_s=duration), arm)
        return cache[key]

    return get


@pytest.mark.parametrize("scenario", ["rectilinear", "spiral"])
def test_kinematic_tracking(runs, scenario):
    m = runs(scenario, "kinematic").metrics
    assert max(m["tracking_rms_position"]) <= TRACKING_POSITION_M
    assert max(m["tracking_rms_orientation"]) <= TRACKING_ORIENTATION_RAD
    assert m["closure_residual_max_m"] <= CLOSURE_M


@pytest.mark.parametrize("scenario", ["rectilinear", "spiral"])
def test_velocity_mode_efforts_match_the_model(runs, scenario):
    record = runs(scenario, "velocity")
    assert "error" not in record.metrics
    assert max(record.metrics["rms_sim_vs_model"][:3]) <= SIM_VS_MODEL
    # the efforts are non-trivial: the check is not passed by zeros
    assert np.sqrt(np.mean(record.effort_sim[:, 2] ** 2)) > 0.1


def test_velocity_mode_feeds_forward_the_step_s_own_velocity(runs):
    """A step's velocity is its mean over [t, t + dt] (DART's semi-implicit
    Euler): fed forward at t + dt/2, the spiral's horizontal tracking is about
    1e-5 m; fed at t, the circle lags v dt / 2 behind the loop's gain (8.5e-5 m)."""
    m = runs("spiral", "velocity").metrics
    assert max(m["tracking_rms_position"][:2]) <= 2e-5, m["tracking_rms_position"]


def test_without_counterweight_j3_error_is_large(runs):
    record = runs("rectilinear", "velocity", "off")
    assert record.metrics["rms_sim_vs_model"][2] > 1.0  # N: the counterweight's weight is ~3.4 N


@pytest.mark.parametrize("scenario", ["rectilinear", "spiral"])
def test_torque_mode_error_decays(runs, scenario):
    record = runs(scenario, "torque")
    m = record.metrics
    assert "error" not in m
    assert max(m["tracking_rms_position_after_1s"]) <= TRACKING_POSITION_M
    error = np.linalg.norm(record.tool_pose_ref[:, :3] - record.tool_pose[:, :3], axis=1)
    # exponential decay: after its peak the error stays under the envelope of
    # the closed loop's slow pole (s^2 + Kd s + Kp = 0) down to the tolerance
    gains = PSM_ARM.model.controller_gains
    slow_pole = (gains["torque_kd"] - np.sqrt(gains["torque_kd"] ** 2 - 4 * gains["torque_kp"])) / 2  # 20 1/s
    peak = int(np.argmax(error))
    t = record.t[peak:] - record.t[peak]
    envelope = 2 * error[peak] * np.exp(-slow_pole * t) + TRACKING_POSITION_M
    one_second = int(round(1.0 / m["dt_s"]))
    assert error[peak] > 10 * np.max(error[one_second:])  # a transient that decays, not a constant error
    assert np.all(error[peak:] <= envelope)


def test_mcap_log_of_a_real_run_reads_back(runs, arm, tmp_path):
    from dvrk_dart.runs.campaign import write_run_folder

    record = runs("spiral", "velocity", "on", 0.5)
    write_run_folder(record, tmp_path / "run", arm.model)
    back = read_mcap(tmp_path / "run" / "run.mcap")
    assert len(back) == len(record) == 500
    for field in ("q", "dq", "ddq", "effort_sim"):
        np.testing.assert_array_equal(getattr(back, field), getattr(record, field))
    assert set(back.effort_model) == set(record.effort_model)
    np.testing.assert_array_equal(back.tool_pose, record.tool_pose)
    from mcap.reader import make_reader

    with open(tmp_path / "run" / "run.mcap", "rb") as f:
        counts = make_reader(f).get_summary().statistics.channel_message_counts
    assert set(counts.values()) == {500}
    assert (tmp_path / "run" / "run.rrd").stat().st_size > 50_000
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["versions"]["dartpy"] and config["mode"] == "velocity"


def test_cli_runs_a_short_scenario_end_to_end(tmp_path):
    out = tmp_path / "rect"
    done = subprocess.run(
        [sys.executable, "-m", "dvrk_dart.cli", "run", "rectilinear", "--mode", "velocity", "--duration", "0.3", "--out", str(out)],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["samples"] == 300 and max(metrics["rms_sim_vs_model"][:3]) <= SIM_VS_MODEL
    assert {p.name for p in out.iterdir()} >= {"run.mcap", "run.rrd", "metrics.json", "config.json"}
    assert not list(out.glob(".*partial"))


def test_cli_unknown_mode_is_a_clear_error(tmp_path):
    scenario = tmp_path / "velocity-only.toml"
    scenario.write_text('name = "velocity-only"\nkind = "replay"\nmeasured = "two"\nmodes = ["velocity"]\n')
    done = subprocess.run(
        [sys.executable, "-m", "dvrk_dart.cli", "run", str(scenario), "--mode", "torque", "--out", str(tmp_path / "x")],
        capture_output=True, text=True,
    )
    assert done.returncode == 2 and "--mode: scenario 'velocity-only' runs in velocity, not 'torque'" in done.stderr
    assert not (tmp_path / "x").exists()


def test_campaign_skips_unchanged_runs_and_lists_failures(tmp_path):
    from dvrk_dart.runs.campaign import config_name, run_campaign

    good = RunConfig("rectilinear", "kinematic", "on", duration_s=0.2)
    bad = RunConfig("replay", "velocity", "on", measured="two", duration_s=100.0)  # longer than the measured run
    first = run_campaign([good, bad], tmp_path, jobs=1)
    assert first["ran"] == [config_name(good)] and list(first["failures"]) == [config_name(bad)]
    assert "--duration: 100 s outside" in first["failures"][config_name(bad)]
    assert not (tmp_path / config_name(bad) / "inputs.sha256").exists()
    second = run_campaign([good], tmp_path, jobs=1)
    assert second["skipped_up_to_date"] == [config_name(good)] and second["ran"] == []


def test_the_bench_reads_the_whole_validation_s_time(tmp_path):
    """make bench's campaign figure read campaign.json, the simulation runs alone (36 s of a 345 s validation), against
    the target of the whole: the whole is validate.json's, a validation that did not complete none."""
    from dvrk_dart.bench import bench_campaign

    (tmp_path / "campaign.json").write_text(json.dumps({"wall_time_s": 36.0}))
    (tmp_path / "validate.json").write_text(json.dumps({"wall_time_s": 345.0, "completed": True}))
    assert bench_campaign(tmp_path) == {"validate_s": 345.0, "campaign_runs_s": 36.0}
    (tmp_path / "validate.json").write_text(json.dumps({"wall_time_s": 12.0, "completed": False}))
    assert bench_campaign(tmp_path) == {"campaign_runs_s": 36.0}

"""Excitation trajectories to play on a real dVRK: the fitted Fourier series of
"one"/"two" and the Cartesian scenarios' joint trajectories, as a CSV and a
ROS 2 bag of servo_jp commands, refused when over the joint or velocity limits."""

import json

import numpy as np
import pandas as pd
import pytest
from rosbags.highlevel import AnyReader

from dvrk_dart.cli import main
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.runs.excitation import fourier_basis
from arms import PSM

#: a 6-harmonic series reproduces the measured positions to this (rad, m) on the
#: arm and wrist joints: the tracking error and noise of the recording, ~1e-3
FIT_POSITION_RMS = 5e-3
#: the jaw is tracked less well by the robot (its fit leaves ~0.03 rad)
FIT_JAW_RMS = 0.05


def test_fourier_velocity_basis_is_the_derivative():
    t = np.linspace(0.0, 6.0, 6001)
    position, velocity = fourier_basis(t, 0.17)
    numeric = np.gradient(position, t, axis=0)
    np.testing.assert_allclose(numeric[5:-5], velocity[5:-5], atol=2e-4)


def test_excitation_two(tmp_path, capsys):
    out = tmp_path / "two"
    assert main(["excitation", "two", "--out", str(out)]) == 0
    summary = json.loads((out / "excitation.json").read_text())
    source = summary["source"]
    # the base frequency the data has (1296 rows at 200 Hz), not the nominal 0.18 Hz
    assert source["base_frequency_hz"] == pytest.approx(200 / 1296, rel=2e-3)
    assert max(source["fit_rms_position"][:6]) < FIT_POSITION_RMS
    assert source["fit_rms_position"][6] < FIT_JAW_RMS
    csv = pd.read_csv(out / "two.csv")
    assert list(csv.columns) == ["time", *PSM.dvrk_topics.joint_names]
    assert len(csv) == 5999 and csv.time.iloc[1] == pytest.approx(0.005)
    # the trajectory follows the measured run (in the dVRK's joints)
    measured = PSM.motor_map.positions_to_dvrk(load_run(resolve_run("two"), PSM).q)
    rms = np.sqrt(np.mean((csv[list(PSM.dvrk_topics.joint_names)].to_numpy() - measured) ** 2, axis=0))
    assert rms[:6].max() < FIT_POSITION_RMS
    # within the limits it was checked against
    limits = PSM.dvrk_velocity_limits
    assert all(summary["max_speed"][n] <= limit for n, limit in zip(PSM.dvrk_topics.joint_names, limits))
    # the bag: servo_jp commands (positions only) with the same values
    with AnyReader([out / "two_servo_jp"]) as reader:
        assert set(reader.topics) == {"/PSM1/servo_jp", "/PSM1/jaw/servo_jp"}
        arm = [c for c in reader.connections if c.topic == "/PSM1/servo_jp"]
        positions = []
        for connection, _, raw in reader.messages(connections=arm):
            msg = reader.deserialize(raw, connection.msgtype)
            assert tuple(msg.name) == PSM.dvrk_topics.arm_joints and len(msg.velocity) == 0
            positions.append(msg.position)
    # played from rest along the path, back to rest at its end: "two" starts with the pitch at -1.28 rad/s, the jaw at 1.56
    lead = round(summary["lead_s"] / 0.005)
    positions, design = np.array(positions), csv[list(PSM.dvrk_topics.arm_joints)].to_numpy()
    np.testing.assert_allclose(positions[[0, -1]], design[[0, -1]], atol=1e-9)  # its first and last row, at rest
    np.testing.assert_allclose(positions[lead:len(design) - lead // 2], design[lead // 2:len(design) - lead], atol=1e-6)  # between: the CSV, lead / 2 late
    speed = np.abs(np.diff(positions, axis=0)) / 0.005
    assert speed[[0, -1]].max() < 1e-3 and speed.max(axis=0).max() <= np.abs(np.diff(design, axis=0)).max() / 0.005 + 1e-6
    assert np.abs(np.diff(speed, axis=0)).max() / 0.005 < 20.0  # no velocity step anywhere (rad/s^2, m/s^2)


def _scenario(tmp_path, name, start_pose, path_table, duration_s=0.2):
    text = f'''name = "{name}"
kind = "cartesian"
duration_s = {duration_s}
modes = ["kinematic"]
counterweights = ["on"]
start_pose = {start_pose}

[path]
{path_table}
'''
    file = tmp_path / f"{name}.toml"
    file.write_text(text)
    return file


SPIRAL = 'type = "spiral"\nradius_m = 0.05\nheight_m = 0.03\nradius_frequency_hz = 1.5\nheight_frequency_hz = 0.5'
DEEPER = 'type = "line"\nlength_m = 0.02\ndirection = [0.0, 0.0, -1.0]'
LINE = 'type = "line"\nlength_m = 0.0005\ndirection = [-1.0, -1.0, 1.0]'


def test_cartesian_excitation(tmp_path, capsys):
    scenario = _scenario(tmp_path, "short-line", [0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0], LINE)
    out = tmp_path / "line"
    assert main(["excitation", str(scenario), "--out", str(out), "--arm", "PSM2"]) == 0
    csv = pd.read_csv(out / "short-line.csv")
    assert len(csv) == 41 and csv.outer_insertion.iloc[0] == pytest.approx(0.14)
    with AnyReader([out / "short-line_servo_jp"]) as reader:
        assert set(reader.topics) == {"/PSM2/servo_jp", "/PSM2/jaw/servo_jp"}


@pytest.mark.parametrize(
    "case, pose, path, words",
    [
        # the paper's spiral needs the pitch at 3.8 rad/s from the start: over 180 deg/s
        ("spiral", [0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0], SPIRAL, ["outer_pitch moves at 3.7", "velocity limit 3.1416 rad/s"]),
        # a line that pushes the insertion past its 0.24 m stop
        ("too-deep", [0.0, 0.0, 0.235, 0.0, 0.0, 0.0, 0.0], DEEPER, ["column q3", "outside the joint range"]),
    ],
)
def test_excitation_over_the_limits_is_refused(tmp_path, capsys, case, pose, path, words):
    scenario = _scenario(tmp_path, case, pose, path)
    out = tmp_path / "out"
    assert main(["excitation", str(scenario), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    for word in words:
        assert word in err, err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{case}.toml"]


def test_unknown_excitation_and_replay_scenario(tmp_path, capsys):
    assert main(["excitation", "replay", "--out", str(tmp_path / "o")]) == 2
    assert "replay scenario" in capsys.readouterr().err
    assert main(["excitation", "nonexistent", "--out", str(tmp_path / "o")]) == 2
    capsys.readouterr()
    assert not (tmp_path / "o").exists()


def test_a_recording_of_the_played_bag_is_read_periodic(arm):
    """The bag from rest to rest, recorded (positions as played, the identified model's efforts plus noise): the
    period fit over the whole run explained 97.9 % of its positions (< 99 %: "not a periodic excitation"); the
    speeding up and slowing down are transients, left out, and the period is the design's."""
    from dvrk_dart.io.measured_run import CSV_COLUMNS, MeasuredRun
    from dvrk_dart.io.signal import process_periodic
    from dvrk_dart.runs.excitation import LEAD_S, build_excitation, played

    excitation = build_excitation("two", 200.0, arm)
    bag = played(excitation)
    tau = arm.identified.efforts(bag.q, bag.dq, np.gradient(bag.dq, 0.005, axis=0)).total()
    tau += np.random.default_rng(0).normal(0.0, 0.01, tau.shape)
    data = pd.DataFrame(np.hstack([bag.q, bag.dq, tau]), columns=CSV_COLUMNS)
    data.insert(0, "t", bag.t)
    periodic = process_periodic(MeasuredRun(PSM.source, data, arm.model)).periodic
    assert periodic.period.period_s == pytest.approx(1.0 / excitation.source["base_frequency_hz"], rel=1e-5)
    start, stop = periodic.kept
    assert 0.5 * LEAD_S * 200 < start < LEAD_S * 200 and 0.5 * LEAD_S * 200 < len(bag.t) - stop < LEAD_S * 200

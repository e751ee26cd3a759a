"""Scenario files: validated on load with clear errors."""

import pytest

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.runs.campaign import load_campaign
from dvrk_dart.runs.scenarios import available_scenarios, load_scenario

GOOD = """
name = "line"
kind = "cartesian"
duration_s = 1.0
modes = ["kinematic"]
start_pose = [0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0]
[path]
type = "line"
length_m = 0.01
direction = [1.0, 0.0, 0.0]
"""


def test_every_shipped_scenario_and_the_campaign_load():
    names = available_scenarios()
    assert {"rectilinear", "spiral", "spiral-peer", "replay"} <= set(names)
    for name in names:
        load_scenario(name)
    specs = load_campaign()
    assert {s.mode for s in specs} == {"kinematic", "velocity", "torque"}
    assert {"on", "off", "pid"} <= {s.counterweight for s in specs}


def test_paper_values_are_the_scenario_data():
    spiral = load_scenario("spiral")
    assert spiral.path == {"type": "spiral", "radius_m": 0.05, "height_m": 0.03, "radius_frequency_hz": 1.5, "height_frequency_hz": 0.5}
    line = load_scenario("rectilinear")
    assert line.path["length_m"] == 0.09 and line.duration_s == 10.0


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda s: "speed = 3\n" + s, "unknown key"),
        (lambda s: s.replace('kind = "cartesian"', 'kind = "circle"'), "kind must be"),
        (lambda s: s.replace('modes = ["kinematic"]', 'modes = ["fast"]'), "modes must be"),
        (lambda s: s.replace("duration_s = 1.0", "duration_s = -1.0"), "duration_s must be a positive number"),
        (lambda s: s.replace("length_m = 0.01", "length_m = 0.0"), "path.length_m must be a positive number"),
        (lambda s: s.replace("[0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0]", "[0.0, 0.0]"), "start_pose must be a list of 7 finite numbers"),
        (lambda s: s.replace("[0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0]", '"home"'), "start_pose must be a list of 7 finite numbers"),
        (lambda s: s.replace("[0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0]", "[0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 0.0]"), "start_pose: q3 = 5.0 outside the joint range"),
        (lambda s: s.replace('modes = ["kinematic"]', "modes = 5"), "modes must be a non-empty list"),
        (lambda s: s.replace("[1.0, 0.0, 0.0]", '"up"'), "path.direction must be a list of 3 finite numbers"),
        (lambda s: s.replace("length_m = 0.01", "length_m = 0.01\nradius_m = 0.1"), "takes exactly"),
    ],
)
def test_bad_scenario_files_give_clear_errors(tmp_path, edit, message):
    path = tmp_path / "bad.toml"
    path.write_text(edit(GOOD))
    with pytest.raises(DvrkDartError, match=message) as info:
        load_scenario(str(path))
    assert str(path) in str(info.value)


def test_unreadable_scenario_files_give_clear_errors(tmp_path):
    binary = tmp_path / "latin1.toml"
    binary.write_bytes("name = 'caf\xe9'".encode("latin-1"))
    with pytest.raises(DvrkDartError, match="not UTF-8 text"):
        load_scenario(str(binary))
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    with pytest.raises(DvrkDartError, match="is a folder, not a scenario file"):
        load_scenario(str(folder))


def test_unknown_scenario_names_the_known_ones():
    with pytest.raises(DvrkDartError, match="unknown scenario 'nope' \\(known: .*rectilinear"):
        load_scenario("nope")


LINE = """name = "fz"
kind = "cartesian"
duration_s = {duration}
modes = ["velocity"]
start_pose = [0.0, 0.0, 0.14, 0.0, 0.0, 0.0, 0.0]
[path]
type = "line"
length_m = 0.01
direction = {direction}
"""


def test_a_scenario_whose_duration_holds_too_few_or_too_many_steps_is_refused_before_running(tmp_path, capsys):
    """A 1 µs scenario ran 0 samples and exited 0 (excitation: a traceback); an hour at --dt 1e-5 ran out of memory."""
    from dvrk_dart.cli import main

    tiny, hour = tmp_path / "tiny.toml", tmp_path / "hour.toml"
    tiny.write_text(LINE.format(duration=1e-6, direction=[1, 0, 0]))
    hour.write_text(LINE.format(duration=3600, direction=[1, 0, 0]))
    for argv, words in ((["run", str(tiny)], "scenario fz's duration_s: 1e-06 s is fewer than 10 steps"),
                        (["run", str(hour), "--dt", "1e-5"], "is 3.6e+08 steps, more than 3.6e+06"),
                        (["excitation", str(tiny)], "duration_s 1e-06 s holds no two samples")):
        capsys.readouterr()
        assert main([*argv, "--out", str(tmp_path / "never")]) == 2
        assert words in capsys.readouterr().err
        assert not (tmp_path / "never").exists()


def test_a_line_direction_of_any_scale_gives_the_same_path(tmp_path):
    """[1e300, 1e300, 0] overflowed to a still path; [1e-300, 0, 0] was refused as zero."""
    import numpy as np

    paths = []
    for i, direction in enumerate(([1, 1, 0], [1e300, 1e300, 0], [1e-300, 1e-300, 0])):
        (tmp_path / f"s{i}.toml").write_text(LINE.format(duration=1.0, direction=direction))
        paths.append(load_scenario(str(tmp_path / f"s{i}.toml")).cartesian_path(np.zeros(3)).position_velocity_acceleration(0.5)[0])
    assert np.allclose(paths[1], paths[0]) and np.allclose(paths[2], paths[0]) and np.linalg.norm(paths[0]) == pytest.approx(0.005)


def test_a_scenario_file_names_itself_for_its_arm_and_its_run_and_sets_the_counterweight_default(tmp_path, capsys):
    """arm_model = "nosuch" was blamed on --arm-model, a measured run not found on no file; a scenario run only
    with the PID mirror was refused for the default --counterweight on."""
    from dvrk_dart.cli import main

    replay = 'name = "fz"\nkind = "replay"\nduration_s = 0.2\nmodes = ["velocity"]\nmeasured = "nosuch"\n'
    other_arm = LINE.format(duration=1.0, direction=[1, 0, 0]).replace("[path]", 'arm_model = "nosuch"\n[path]')
    for text, words in ((other_arm, "arm_model: nosuch: no such arm"), (replay, "measured = 'nosuch': not a reference run")):
        (tmp_path / "s.toml").write_text(text)
        with pytest.raises(DvrkDartError, match=rf"s.toml: {words}"):
            load_scenario(str(tmp_path / "s.toml"))
    pid = LINE.format(duration=1.0, direction=[1, 0, 0]).replace('modes = ["velocity"]', 'modes = ["velocity"]\ncounterweights = ["pid"]')
    (tmp_path / "pid.toml").write_text(pid)
    assert main(["run", str(tmp_path / "pid.toml"), "--duration", "0.05", "--out", str(tmp_path / "run")]) == 0
    assert "cw-pid" in capsys.readouterr().out

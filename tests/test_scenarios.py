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

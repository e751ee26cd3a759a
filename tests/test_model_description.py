"""The model as data: loading, linear relations, parameter checks."""

import json

import numpy as np
import pytest

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import resolve
from dvrk_dart.model.model_file import load_model
from dvrk_dart.model.parameters import load_parameters
from arms import MTM, PSM


def test_every_link_has_a_group_and_the_tree_is_ordered(arm):
    seen = {0}
    for key, link in arm.model.links.items():
        assert link.group in arm.model.groups
        assert link.parent in seen
        seen.add(key)


def test_parallelogram_links_keep_their_orientation_relations(arm):
    """Pitch-front (4) translates; pitch-bottom (6) and pitch-top (7) stay parallel to pitch (2)."""
    for q2 in (-0.6, 0.0, 0.5):
        frames = arm.model.forward_kinematics(np.array([0.3, q2, 0.1, 0, 0, 0, 0]))
        frames0 = arm.model.forward_kinematics(np.array([0.3, 0.0, 0.1, 0, 0, 0, 0]))
        np.testing.assert_allclose(frames[4][:3, :3], frames0[4][:3, :3], atol=1e-12)
        for k in (6, 7):
            R_rel = frames[2][:3, :3].T @ frames[k][:3, :3]
            R_rel0 = frames0[2][:3, :3].T @ frames0[k][:3, :3]
            np.testing.assert_allclose(R_rel, R_rel0, atol=1e-12)


def test_remote_centre_of_motion_is_fixed(arm):
    """The tool axis passes through the same point whatever q1, q2, q3."""
    rcm = None
    for q in ([0, 0, 0.1, 0, 0, 0, 0], [0.4, -0.5, 0.15, 0, 0, 0, 0], [-0.7, 0.6, 0.05, 0, 0, 0, 0]):
        T = arm.model.forward_kinematics(np.array(q, dtype=float))[8]
        p, z = T[:3, 3], T[:3, 2]
        # closest point of the tool axis to the yaw axis (base y through the origin)
        if rcm is None:
            t = -(p[2]) / z[2] if abs(z[2]) > 1e-9 else 0.0
            rcm = p + t * z
        else:
            assert np.linalg.norm(np.cross(rcm - p, z)) < 1e-9


def test_loop_closure_points_coincide_in_every_configuration(arm):
    for q in ([0, 0, 0.1, 0, 0, 0, 0], [0.5, -0.6, 0.2, 0, 0, 0, 0], [-0.5, 0.7, 0.0, 0, 0, 0, 0]):
        frames = arm.model.forward_kinematics(np.array(q, dtype=float))
        for closure in arm.model.loop_closures:
            on_link = frames[closure.link] @ np.r_[closure.point_in_link, 1.0]
            reference = arm.model.forward_kinematics(np.zeros(7))
            # the point is fixed in the other link's frame
            on_link0 = reference[closure.link] @ np.r_[closure.point_in_link, 1.0]
            in_other = np.linalg.solve(frames[closure.other], on_link)
            in_other0 = np.linalg.solve(reference[closure.other], on_link0)
            np.testing.assert_allclose(in_other, in_other0, atol=1e-12)


def test_parameters_are_converted_to_link_frames(arm, tmp_path):
    raw = json.loads(resolve("params.json").read_text())
    for key in (2, 8, 9):
        R0 = arm.model.rotations_at_zero[key]
        np.testing.assert_allclose(R0 @ arm.params[key].com, raw[str(key)]["r"], atol=1e-15)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda p: p["8"].__setitem__("m", -0.1), "negative mass"),
        (lambda p: p["8"].__setitem__("r", [0.0, float("nan"), 0.0]), "not finite"),
        (lambda p: p["8"].__setitem__("I", [1.0, 0, 0, 1.0, 0, 3.0]), "not physically consistent"),
        (lambda p: p.pop("9"), r"link 9 \(counterweight\): missing"),
        (lambda p: p["8"].__setitem__("I", [1.0, 0.0]), "list of 6 numbers"),
        (lambda p: p["8"].__setitem__("fc", 0.1), r"link 8 \(.*\): unknown 'fc' \(a link holds m, r, I, Fc"),
    ],
)
def test_bad_parameters_give_a_clear_error(arm, tmp_path, mutate, message):
    raw = json.loads(resolve("params.json").read_text())
    mutate(raw)
    path = tmp_path / "params.json"
    path.write_text(json.dumps(raw))
    with pytest.raises(DvrkDartError, match=message) as info:
        load_parameters(path, arm.model)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_oddities_are_reported(arm):
    notes = "\n".join(arm.params.oddities(arm.model))
    for fragment in ("link 2 (pitch): mass", "link 4 (pitch_front): inertia of 90.1", "negative motor inertia", "not quite physical"):
        assert fragment in notes


def test_malformed_model_file(tmp_path):
    bad = tmp_path / "psm.toml"
    bad.write_text("groups = ['yaw']\n[constants]\nl = 1\n[[links]]\nkey = 1\nname='x'\nparent = 0\ngroup='yaw'\ntheta = { q9 = 1 }\n")
    with pytest.raises(DvrkDartError, match="unknown name 'q9'"):
        load_model(bad)


def test_sessions_name_known_joints(tmp_path):
    model = PSM
    assert model.session_offset_joints == ("q2", "q3", "q4")  # J1's constant does not move between sessions
    bad = tmp_path / "psm.toml"
    bad.write_text(model.source.read_text().replace('offset_joints = ["q2", "q3", "q4"]', 'offset_joints = ["q2", "yaw"]'))
    with pytest.raises(DvrkDartError, match=r"\[sessions\] offset_joints: unknown joint\(s\) yaw"):
        load_model(bad)


def test_a_repeat_pair_names_two_files(tmp_path):
    """[sessions] repeat_pair: two manifest names, else a one-line error naming the file."""
    import re

    from dvrk_dart.paths import PROJECT_DIR

    card = (PROJECT_DIR / "models" / "psm" / "psm.toml").read_text()
    assert load_model(PROJECT_DIR / "models" / "psm" / "psm.toml").session_repeat_pair == ("one_no_weight_results.csv", "one_results.csv")
    bad = tmp_path / "psm.toml"
    bad.write_text(re.sub(r"repeat_pair = \[.*\]", 'repeat_pair = ["one_results.csv"]', card))
    with pytest.raises(DvrkDartError, match="repeat_pair names 1 files"):
        load_model(bad)


@pytest.mark.parametrize("entry, edited, message", [
    ("gravity_m_s2 = [0.0, 0.0, -9.81]", "gravity_m_s2 = [0.0, -9.81]", r"gravity_m_s2 must be 3 finite numbers"),
    ("lower = [-1.6, -0.9, 0.0, -3.0, -3.2, -3.2, -3.2]", "lower = [-1.6, -0.9]", r"\[joint_limits\] lower must be 7"),
    ("lower = [-1.6, -0.9, 0.0, -3.0, -3.2, -3.2, -3.2]", "lower = [1.6, -0.9, 0.0, -3.0, -3.2, -3.2, -3.2]",
     r"each lower must be below its upper"),
    ("matrix = [[1.0186, 0.0, 0.0], [-0.8306, 0.6089, 0.6089], [0.0, -1.2177, 1.2177]]", "matrix = [[1.0, 0.0], [0.0, 1.0]]",
     r"\[dvrk_coupling\] matrix must be 3x3"),
    ("matrix = [[1.0186, 0.0, 0.0], [-0.8306, 0.6089, 0.6089], [0.0, -1.2177, 1.2177]]", "matrix = [[0, 0, 0], [0, 0, 0], [0, 0, 0]]",
     r"matrix is singular"),
    ("cutoff_parameter_hz = 5.4", "cutoff_parameter_hz = 0.0", r"cutoff_parameter_hz must be in \(0, 31.8\)"),
    ("cutoff_parameter_hz = 5.4", "cutoff_parameter_hz = 5000.0", r"cutoff_parameter_hz must be in \(0, 31.8\)"),
    ("first_period_samples = 1111", "first_period_samples = 0", r"first_period_samples must be a positive"),
    ("filter_rate_hz = 200.0", "filter_rate_hz = 0.0", r"filter_rate_hz must be a positive rate"),
    ("identification_mass_bounds_kg = { 2 = 10.0,", 'identification_mass_bounds_kg = { 2 = "x",', r"identification_mass_bounds_kg: 2 = 'x'"),
    ('namespace = "PSM1"', 'namespace = "PSM 1"', r"namespace 'PSM 1' is not a ROS name"),
    ("ratio = 1.0", "ratio = 0.0", r"\[counterweight\] ratio must be a finite non-zero"),
    ('leader = "q3"', 'leader = "q9"', r"\[counterweight\] leader 'q9'"),
    ("kinematic_gain = 15.0", "kinematic_gain = -15.0", r"\[controllers\] kinematic_gain must be a positive number"),
    ("counterweight_pid = [2000.0, 0.0, 60.0]", "counterweight_pid = [2000.0]", r"counterweight_pid must be \[Kp, Ki, Kd\]"),
    ("min_lever_m = 0.05", "min_lever_m = -1", r"min_lever_m must be a positive length"),
    ('q4 = "torsion_spring" }', 'q9 = "torsion_spring" }', r"\[diagnosis\]: unknown joint q9"),
    ('q4 = "torsion_spring" }', 'q4 = "spring" }', r"\[diagnosis\] elastic: q4 = 'spring'"),
    ('position_friction = ["q1", "q2", "q3"]', 'position_friction = "q1"', r"\[diagnosis\] elastic is a table"),
    ("q1_slope_at_q0 = 0.197 }", "q1_slope_at_q0 = -0.197 }", r"\[sessions\] payload_reading: \{q1_effort_at_q0 = a non-negative"),
    ("q1_effort_at_q0 = 0.039, ", "", r"\[sessions\] payload_reading: "),
])
def test_a_card_value_no_command_could_use_is_refused_in_one_line(tmp_path, entry, edited, message):
    """Shapes and signs of the card's values, checked when it is read (they ended in tracebacks deep in a command)."""
    card = PSM.source.read_text()
    assert card.count(entry) == 1
    bad = tmp_path / "psm.toml"
    bad.write_text(card.replace(entry, edited))
    with pytest.raises(DvrkDartError, match=rf"^{bad}: .*{message}"):
        load_model(bad)


def test_the_tool_tip_and_the_force_point_name_what_the_card_has(tmp_path):
    import re

    card = PSM.source.read_text()
    tip = re.search(r"\[tool_tip\]\nparent = (\d+)", card)
    bad = tmp_path / "psm.toml"
    bad.write_text(card[:tip.start(1)] + "99" + card[tip.end(1):])
    with pytest.raises(DvrkDartError, match=r"\[tool_tip\] parent 99 is not a link"):
        load_model(bad)
    bad.write_text(re.sub(r'(\[force_point\][^\[]*?joints = )\[[^\]]*\]', r'\1["q1", "q9"]', card))
    with pytest.raises(DvrkDartError, match=r"\[force_point\] joints: unknown q9"):
        load_model(bad)


def test_a_card_without_its_identification_file_is_told_so_not_blamed_on_bounds(tmp_path):
    """The arm's own bounds (no --bounds given) missing: the message named --bounds, an option the user never gave."""
    from dvrk_dart.identification.fit import load_bounds

    card = tmp_path / "psm.toml"
    card.write_text(PSM.source.read_text())
    with pytest.raises(DvrkDartError, match=r"^the arm's identification file \(psm.toml's folder\): .*identification.toml: bounds file not found"):
        load_bounds(None, load_model(card))
    with pytest.raises(DvrkDartError, match=r"^--bounds: .*nothing.toml: bounds file not found"):
        load_bounds(tmp_path / "nothing.toml", load_model(card))


def test_the_base_frame_in_words_is_the_cards(tmp_path):
    """The MTM's payload words quoted the PSM's pitch shaft and remote centre of motion (a blind round): the frame's
    words are the card's, and a card without them says none."""
    assert "remote centre of motion" in PSM.frame_words and MTM.frame_words == ""
    text = PSM.source.read_text()
    line = next(l for l in text.splitlines() if l.startswith("frame_words = "))
    bad = tmp_path / "psm.toml"
    bad.write_text(text.replace(line, "frame_words = 3"))
    with pytest.raises(DvrkDartError, match=r"\[diagnosis\] frame_words is a text"):
        load_model(bad)

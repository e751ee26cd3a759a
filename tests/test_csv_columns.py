"""The columns of a measured-run CSV: headers, time columns and rates, velocity and effort columns
that are not what they say, and the notes or one-line refusals each gets."""

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from dvrk_dart.cli import main
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.reference_data import load_run, resolve_run
from arms import PSM
from recordings import TEST1, cli_json, columns_of, needs_2018, refusal, write_header_csv


def test_a_header_names_any_subset_of_joints(tmp_path):
    """q1, q2 with their velocities and efforts, a time column at 100 Hz: the
    file's own rate, the rest not measured (zeros, no say)."""
    two = load_run(resolve_run("two"), PSM)
    half = type(two)(two.path, two.data.iloc[::2].reset_index(drop=True), PSM)  # every other row: 100 Hz
    path = write_header_csv(tmp_path / "two_q1q2.csv", half, ["q1", "q2", "dq1", "dq2", "tau1", "tau2"])
    run = load_run(path, PSM)
    assert run.measured == ("q1", "q2") and abs(run.rate_hz - 100.0) < 1e-6
    assert np.allclose(run.q[:, :2], half.q[:, :2]) and not run.q[:, 2:].any() and not run.tau[:, 2:].any()


def test_a_time_column_of_unix_stamps_gives_the_rate_of_its_span(tmp_path):
    """Stamps near 1.7e9 s are quantised to ~0.2 us: the median step moved the rate by 2e-5 (a period by 40 times
    its stated error); the span over all rows does not."""
    two = load_run(resolve_run("two"), PSM)
    path = tmp_path / "unix_time.csv"
    table = pd.DataFrame({"t": 1.7e9 + np.arange(len(two)) / 200.0, **{f"{f}1": v[:, 0] for f, v in (("q", two.q), ("dq", two.dq), ("tau", two.tau))}})
    table.to_csv(path, index=False, float_format="%.17g")
    assert abs(load_run(path, PSM).rate_hz / 200.0 - 1.0) < 1e-7


def test_a_header_with_the_dvrk_joint_names(tmp_path):
    """position.<joint>/velocity.<joint>/effort.<joint>: the dVRK's coordinates, mapped to the model's."""
    import pandas as pd


    one = load_run(resolve_run("one"), PSM)
    model = PSM
    names = model.dvrk_topics.joint_names
    motor = model.motor_map
    columns = {"time": one.t}
    for field, values in (("position", motor.positions_to_dvrk(one.q)), ("velocity", motor.positions_to_dvrk(one.dq)),
                          ("effort", motor.efforts_to_dvrk(one.tau))):
        columns.update({f"{field}.{name}": values[:, j] for j, name in enumerate(names)})
    path = tmp_path / "one_dvrk.csv"
    pd.DataFrame(columns).to_csv(path, index=False)
    run = load_run(path, PSM)
    assert np.allclose(run.q, one.q, atol=1e-9) and np.allclose(run.tau, one.tau, atol=1e-9)


@pytest.mark.parametrize("header, words", [
    ("t,q1,dq1", "q1 without tau1"),
    ("t,position.outer_yaw,velocity.outer_yaw", "outer_yaw without effort.outer_yaw"),  # named as the header names it
    ("t,q1,dq1,tau1,bogus", "'bogus' is not a known name"),
    ("t,q1,q1,dq1,tau1", "q of q1 given twice"),
    (",t,q1,dq1,tau1", r"column 1 is empty \(an index column\? \(pandas"),  # to_csv's default index
    ("t,q1,dq1,tau1,", "column 5 is empty .a trailing comma"),
    ("t;q1;dq1;tau1", "separated by commas; this file's by ';'"),
    ("t,time,q1,dq1,tau1", r"two time columns \(t, column 1; time, column 2\)"),  # the last one won, silently
    ("time,outer_yaw,outer_pitch", "'outer_yaw' is a bare joint name: a trajectory .* give it as --excitation"),
])
def test_bad_headers_are_refused_in_one_line(tmp_path, header, words):
    width = len(header.split(","))
    rows = "\n".join(",".join(str(0.001 * (i + j)) for j in range(width)) for i in range(500))
    path = tmp_path / "bad.csv"
    path.write_text(header + "\n" + rows + "\n")
    with pytest.raises(DvrkDartError, match=words):
        load_run(path, PSM)


def test_an_uneven_time_column_is_refused(tmp_path):
    two = load_run(resolve_run("two"), PSM)
    path = write_header_csv(tmp_path / "uneven.csv", two, ["q1", "dq1", "tau1"])
    text = path.read_text().splitlines()
    fields = text[300].split(",")
    fields[0] = str(float(fields[0]) + 0.003)
    text[300] = ",".join(fields)
    path.write_text("\n".join(text) + "\n")
    # line 301 of the file: its 300th data row, the step into it from the 299th
    with pytest.raises(DvrkDartError, match=r"time column, row 300 \(line 301 of the file\)"):
        load_run(path, PSM)


def test_a_header_file_counts_its_rows_as_a_file_without_one(tmp_path):
    """A missing value is named by its data row, as every check counts them, and by its line in the file."""
    two = load_run(resolve_run("two"), PSM)
    path = write_header_csv(tmp_path / "gap.csv", two, ["q1", "dq1", "tau1"])
    text = path.read_text().splitlines()
    text[101] = text[101].rsplit(",", 1)[0] + ",nan"
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DvrkDartError, match=r"row 101 \(line 102 of the file\), column tau1: missing"):
        load_run(path, PSM)


@needs_2018
def test_a_three_joint_log_of_an_arm_that_couples_them_is_refused(tmp_path):
    """The MTM's q2..q4 mix in the dVRK's values: joints 1..3 alone cannot be put in its coordinates."""
    from arms import MTM

    with pytest.raises(DvrkDartError, match="couples q2, q3, q4"):
        load_run(TEST1, MTM)


def test_rate_is_for_the_files_without_a_time_column(tmp_path, capsys):
    """--rate sets the rate of a log without a time column; a file with one keeps its stamps' rate (a note
    names it), so that a 100 Hz log without stamps and a 200 Hz one with them go into one command."""
    two = load_run(resolve_run("two"), PSM)
    timed = write_header_csv(tmp_path / "timed.csv", two, ["q1", "dq1", "tau1"])
    every_other = SimpleNamespace(t=two.t[::2], q=two.q[::2], dq=two.dq[::2], tau=two.tau[::2])
    untimed = write_header_csv(tmp_path / "untimed.csv", every_other, ["q1", "dq1", "tau1"], t=False)
    assert load_run(untimed, PSM, BagTopics(rate_hz=100.0)).rate_hz == 100.0
    assert main(["model-errors", "--measured", str(timed), "--rate", "100"]) == 0
    err = capsys.readouterr().err
    assert "--rate 100 is for the files whose rate is not known" in err and "timed.csv keeps its own 200 Hz" in err, err
    # within 1 % the stamps set the rate too (--rate 199 read the run 0.5 % slow)
    assert load_run(timed, PSM, BagTopics(rate_hz=199.0)).rate_hz == pytest.approx(200.0)


def test_rate_leaves_a_reference_run_at_its_recorded_rate(tmp_path, capsys):
    """A reference run's rate is known (the manifest's, by its content), so a 100 Hz log of the user's goes into
    one command with it; a copy whose content differs is the user's file, read at --rate."""
    assert load_run(resolve_run("two"), PSM, BagTopics(rate_hz=100.0)).rate_hz == 200.0
    assert "two_results.csv is the reference data's two_results.csv, recorded at 200 Hz" in capsys.readouterr().err
    half = resolve_run("one-105g-half")  # the manifest pins its rows at 10 ms
    assert load_run(half, PSM, BagTopics(rate_hz=100.0)).rate_hz == 100.0
    two = load_run(resolve_run("two"), PSM)
    every_other = SimpleNamespace(t=two.t[::2], q=two.q[::2], dq=two.dq[::2], tau=two.tau[::2])
    edited = write_header_csv(tmp_path / "two_results.csv", every_other, ["q1", "dq1", "tau1"], t=False)
    assert load_run(edited, PSM, BagTopics(rate_hz=100.0)).rate_hz == 100.0


def test_a_wrong_time_column_is_named_as_what_to_correct(tmp_path, capsys):
    """A t column at twice the rows' real spacing: the error says to correct the
    column (a --rate beside it would not apply to this file), and which rate fits."""
    two = load_run(resolve_run("two"), PSM)
    path = write_header_csv(tmp_path / "timed.csv", two, ["q1", "dq1", "tau1"])
    frame = pd.read_csv(path)
    frame["t"] = frame["t"] * 2.0  # 100 Hz written, 200 Hz recorded
    frame.to_csv(path, index=False)
    assert main(["model-errors", "--measured", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "correct the time column, or remove it and give --rate 200" in err, err


@needs_2018
def test_wrist_columns_padded_with_zeros_are_not_recorded(tmp_path, capsys):
    """A 2018 log padded to 21 columns as a user would: the 9-column file's
    figures, and none on the padded joints (their relative errors printed NaN)."""
    log = np.loadtxt(TEST1, delimiter=",")
    zeros = np.zeros((len(log), 4))
    padded = tmp_path / "padded.csv"
    np.savetxt(padded, np.hstack([log[:, 0:3], zeros, log[:, 3:6], zeros, log[:, 6:9], zeros]), delimiter=",")
    assert load_run(padded, PSM).measured == ("q1", "q2", "q3")
    figures = cli_json(capsys, "model-errors", "--measured", str(padded), "--processing", "upstream")
    assert np.allclose(figures["rms"][:3], [0.1245, 0.1395, 0.5565], atol=5e-4) and figures["rms"][3:] == [None] * 4


def test_an_effort_column_that_never_changes_is_not_recorded(tmp_path, capsys):
    """q7's effort all zero in "one" (a logger that did not read it): q7 set the
    band of every joint (6 harmonics instead of 33) and lowered q3's figure 3x."""
    values = np.loadtxt(resolve_run("one"), delimiter=",")
    values[:, 20] = 0.0
    np.savetxt(tmp_path / "q7_effort_zero.csv", values, delimiter=",")
    figures = cli_json(capsys, "model-errors", "--measured", str(tmp_path / "q7_effort_zero.csv"))
    whole = cli_json(capsys, "model-errors", "--measured", "one")
    assert figures["rms"][6] is None and figures["harmonics"] == whole["harmonics"]
    assert np.allclose(figures["rms"][:6], whole["rms"][:6], rtol=1e-4)  # its start transient is read on q1..q6
    values[:, 14:] = 0.0
    np.savetxt(tmp_path / "no_effort.csv", values, delimiter=",")
    assert "no_effort.csv: no joint's effort can be read (q1, q2, q3, q4, q5, q6, q7: the effort never changes)" in refusal(capsys, "model-errors", "--measured", str(tmp_path / "no_effort.csv"))


@pytest.mark.parametrize("broken, words", [
    (lambda dq: dq * 0.0, "dq2 is zero while q2 moves"),
    (lambda dq: -dq, "dq2 runs against the finite differences of q2 (correlation -1.00, scale -1): its sign flipped?"),
])
def test_a_zero_or_flipped_velocity_column_is_refused_naming_it(tmp_path, capsys, broken, words):
    """One joint's velocity column broken: the clock check reads the cleanest
    joints and passed it, and q2's upstream relative error became 1.1-2.2."""
    values = np.loadtxt(resolve_run("one"), delimiter=",")
    values[:, 8] = broken(values[:, 8])
    np.savetxt(tmp_path / "broken.csv", values, delimiter=",")
    assert words in refusal(capsys, "model-errors", "--measured", str(tmp_path / "broken.csv"), "--processing", "upstream")


@pytest.mark.parametrize("odd", [lambda dq: np.roll(dq, 600), np.degrees])
def test_a_velocity_column_that_hardly_follows_its_positions_is_noted(tmp_path, capsys, odd):
    """Another joint's column or another unit: noted, not refused (a slow
    drift under a noisy velocity reads as poorly, and is still a log)."""
    values = np.loadtxt(resolve_run("one"), delimiter=",")
    values[:, 8] = odd(values[:, 8])
    np.savetxt(tmp_path / "odd.csv", values, delimiter=",")
    capsys.readouterr()
    assert main(["model-errors", "--measured", str(tmp_path / "odd.csv"), "--processing", "upstream"]) == 0
    [note] = capsys.readouterr().err.strip().splitlines()
    assert "dq2 hardly follows the finite differences of q2" in note


def test_a_coupled_dvrk_joint_without_its_effort_takes_its_partners_with_it(tmp_path, capsys):
    """effort.outer_wrist_pitch all zero in a dVRK-name header: the coupling
    mixed the zero into q6 and q7's model efforts (q5 relative 1.2, no note)."""
    one = load_run(resolve_run("one"), PSM)
    to_dvrk = PSM.motor_map
    columns = {"position": to_dvrk.positions_to_dvrk(one.q), "velocity": to_dvrk.positions_to_dvrk(one.dq),
               "effort": to_dvrk.efforts_to_dvrk(one.tau)}
    columns["effort"][:, 4] = 0.0  # outer_wrist_pitch's effort not read
    table = {f"{field}.{name}": columns[field][:, j] for field in columns for j, name in enumerate(PSM.dvrk_topics.joint_names)}
    pd.DataFrame(table).to_csv(tmp_path / "dvrk_names.csv", index=False)
    figures = cli_json(capsys, "model-errors", "--measured", str(tmp_path / "dvrk_names.csv"), "--processing", "upstream")
    assert figures["rms"][4:] == [None] * 3 and all(v is not None for v in figures["rms"][:4]), figures["rms"]
    whole = cli_json(capsys, "model-errors", "--measured", "one", "--processing", "upstream")
    assert np.allclose(figures["rms"][:4], whole["rms"][:4], rtol=1e-6)


def test_a_dvrk_name_header_without_the_jaw_gives_the_joints_it_can(tmp_path, capsys):
    """The dVRK's columns without the jaw's (it was refused: "the model's
    coordinates need every coupled joint"): q1..q4 with the full file's
    figures; the wrist's coupled coordinates, each mixing the jaw, are not measured, said."""
    one = load_run(resolve_run("one"), PSM)
    to_dvrk = PSM.motor_map
    columns = {"position": to_dvrk.positions_to_dvrk(one.q), "velocity": to_dvrk.positions_to_dvrk(one.dq),
               "effort": to_dvrk.efforts_to_dvrk(one.tau)}
    table = {f"{field}.{name}": columns[field][:, j] for field in columns for j, name in enumerate(PSM.dvrk_topics.arm_joints)}
    pd.DataFrame(table).to_csv(tmp_path / "no_jaw.csv", index=False, float_format="%.17g")
    capsys.readouterr()
    assert load_run(tmp_path / "no_jaw.csv", PSM).measured == ("q1", "q2", "q3", "q4")
    assert "q5, q6: coupled to the dVRK's jaw, not logged" in capsys.readouterr().err
    figures = cli_json(capsys, "model-errors", "--measured", str(tmp_path / "no_jaw.csv"), "--processing", "upstream")
    whole = cli_json(capsys, "model-errors", "--measured", "one", "--processing", "upstream")
    assert figures["rms"][4:] == [None] * 3 and np.allclose(figures["rms"][:4], whole["rms"][:4], rtol=1e-6), figures["rms"]


def test_model_coordinates_without_the_jaw_say_what_the_wrist_shares_with_it(tmp_path, capsys):
    """q1..q6 in the model's names: q5 and q6 read 0.26 and 0.33 (relative) against the full file's 0.18 and 0.17 with
    no word; their identified friction (the jaw's blades) follows q7's motion, which the file does not give."""
    one = load_run(resolve_run("one"), PSM)
    path = write_header_csv(tmp_path / "one_q1q6.csv", one, [f"{f}{j}" for f in ("q", "dq", "tau") for j in range(1, 7)])
    figures = cli_json(capsys, "model-errors", "--measured", str(path))
    notes = " ".join(figures["unrecorded_joint_notes"])
    assert "q7 is not recorded and held at 0 rad: q5, q6 share the identified friction of tool_yaw_jaw_2, jaw_coupling" in notes, notes
    assert not cli_json(capsys, "model-errors", "--measured", "one")["unrecorded_joint_notes"]


def test_a_held_joints_velocity_is_noise_and_is_not_checked(tmp_path):
    """q4 held by its servo (encoder counts around 0.1 rad, a noisy velocity):
    its velocity does not follow its positions, and the file is read without a note."""
    values = np.loadtxt(resolve_run("one"), delimiter=",")
    rng = np.random.default_rng(0)
    values[:, 3] = 0.1 + 1e-4 * np.round(rng.standard_normal(len(values)))
    values[:, 10] = 1e-3 * rng.standard_normal(len(values))
    np.savetxt(tmp_path / "held_q4.csv", values, delimiter=",")
    from dvrk_dart.io.measured_run import check_velocity_columns

    assert load_run(tmp_path / "held_q4.csv", PSM).measured[3] == "q4"
    [note] = check_velocity_columns(values[:, 3:4], values[:, 10:11], 200.0, "held_q4.csv")  # were it checked alone: a note
    assert "hardly follows" in note


def test_velocity_columns_in_another_unit_are_named_not_a_rate(tmp_path, capsys):
    """dq1, dq2 in deg/s and dq3 in m/s: the tool offered '--rate 393.4' (a median of the joints' scales), which
    read the run 2x fast. A rate scales every joint alike: the columns are named."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    path = write_header_csv(tmp_path / "deg.csv", test1, columns_of(1, 2, 3))
    frame = pd.read_csv(path)
    frame[["dq1", "dq2"]] = np.degrees(frame[["dq1", "dq2"]])
    frame.to_csv(path, index=False)
    capsys.readouterr()
    load_run(path, PSM)  # the columns are noted (check_velocity_columns), the rate is the file's
    err = capsys.readouterr().err
    assert "dq1" in err and "dq2" in err and "dq3" not in err and "--rate" not in err, err


def test_a_position_that_never_changes_beside_a_changing_effort_is_said(tmp_path, capsys):
    """q3 and dq3 all zero, tau3 logged: q1's and q2's figures doubled (q3 = 0 in every joint's model) with no word."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    path = write_header_csv(tmp_path / "q3_zero.csv", test1, columns_of(1, 2, 3))
    frame = pd.read_csv(path)
    frame[["q3", "dq3"]] = 0.0
    frame.to_csv(path, index=False)
    capsys.readouterr()
    load_run(path, PSM)
    assert "q3's position is 0 for the whole run while its effort changes" in capsys.readouterr().err
    load_run(resolve_run("2018-test1"), PSM)
    assert "for the whole run" not in capsys.readouterr().err


def test_space_separated_numbers_and_comment_lines(tmp_path):
    """numpy.savetxt's default (spaces, no header) read as a header 'not a known name' (an exponent's e is a
    letter); '#' comment lines were 'not a CSV file'."""
    values = np.loadtxt(TEST1, delimiter=",") if TEST1.is_file() else np.loadtxt(resolve_run("two"), delimiter=",")
    spaced = tmp_path / "spaced.txt"
    np.savetxt(spaced, values)
    with pytest.raises(DvrkDartError, match="separated by spaces or tabs; the layouts are comma-separated"):
        load_run(spaced, PSM)
    commented = tmp_path / "commented.csv"
    np.savetxt(commented, values, delimiter=",", header="logged by hand", comments="# ")
    assert load_run(commented, PSM).q.shape == (len(values), 7)


def test_a_log_in_the_dvrk_coordinates_without_names_is_said(tmp_path, capsys):
    """'two' with its wrist columns in the dVRK's values, 21 columns without a header (read as the model's
    coordinates): q5..q7 read 0.63 / 0.46 / 2.01 instead of 0.22 / 0.22 / 0.24, with no hint."""
    values = np.loadtxt(resolve_run("two"), delimiter=",")
    motor_map = PSM.motor_map
    values[:, :7], values[:, 7:14] = motor_map.positions_to_dvrk(values[:, :7]), motor_map.positions_to_dvrk(values[:, 7:14])
    values[:, 14:] = motor_map.efforts_to_dvrk(values[:, 14:])
    path = tmp_path / "two_dvrk.csv"
    np.savetxt(path, values, delimiter=",")
    result = cli_json(capsys, "model-errors", "--measured", str(path))
    assert "read as the dVRK's joint values" in result["coordinates_note"] and "0.223 / 0.220 / 0.238" in result["coordinates_note"]
    assert cli_json(capsys, "model-errors", "--measured", "two")["coordinates_note"] is None


def test_a_trailing_comma_on_every_line_is_named(tmp_path):
    lines = resolve_run("two").read_text().splitlines()[:300]
    path = tmp_path / "trailing.csv"
    path.write_text("".join(line.rstrip("\r") + ",\n" for line in lines))
    with pytest.raises(DvrkDartError, match="a trailing comma"):
        load_run(path, PSM)


@needs_2018
def test_rate_leaves_the_2018_and_mtm_reference_runs_at_their_recorded_rate(capsys):
    """Found by content, not by name: the 2018 and MTM files' manifest names (2018/..., mtm/...) are not their file names."""
    from arms import MTM

    assert load_run(resolve_run("2018-test1"), PSM, BagTopics(rate_hz=100.0)).rate_hz == 200.0
    assert load_run(resolve_run("mtm-one"), MTM, BagTopics(rate_hz=100.0)).rate_hz == 200.0
    err = capsys.readouterr().err
    assert "reference data's 2018/psm1_fourier_test1.csv, recorded at 200 Hz" in err and "mtm/one_results.csv" in err, err


def test_a_written_nan_row_is_named_not_dropped(tmp_path, capsys):
    """A row of NaN (what numpy writes for a missing sample) was dropped as a blank spreadsheet row: the run was
    joined across the hole and its period read 6.4789 s instead of 6.4806 s, silently. It is named now; a row of
    empty cells (",,,,") still goes as a blank line."""
    rows = np.loadtxt(resolve_run("one"), delimiter=",")
    rows[3000] = np.nan
    np.savetxt(tmp_path / "nan_row.csv", rows, delimiter=",")
    line = refusal(capsys, "model-errors", "--measured", str(tmp_path / "nan_row.csv"))
    assert "row 3001, column q1: missing, NaN or infinite value" in line
    text = (tmp_path / "nan_row.csv").read_text().splitlines()
    (tmp_path / "blank_row.csv").write_text("\n".join([*text[:3000], ",," * 10, *text[3001:]]) + "\n")
    assert cli_json(capsys, "model-errors", "--measured", str(tmp_path / "blank_row.csv"))["samples"] == 5998
    for cell, said in (("NA", "missing, NaN or infinite value"), ("1_000", "'1_000' is not a number")):  # R's missing; float() reads 1_000
        (tmp_path / "cell.csv").write_text("\n".join([*text[:10], cell + text[10][text[10].index(","):], *text[11:400]]) + "\n")
        assert f"row 11, column q1: {said}" in refusal(capsys, "model-errors", "--measured", str(tmp_path / "cell.csv"))


def test_hints_of_a_spreadsheets_csv(tmp_path, capsys):
    """Semicolons and decimal commas without a header get the hint the header version gets; a joint's missing column
    is named beside those the header has."""
    lines = resolve_run("one").read_text().splitlines()[:400]
    (tmp_path / "semi.csv").write_text("\n".join(line.replace(",", ";").replace(".", ",") for line in lines) + "\n")
    assert "semicolons between the columns and decimal commas?" in refusal(capsys, "model-errors", "--measured", str(tmp_path / "semi.csv"))
    run = load_run(resolve_run("one"), PSM)
    write_header_csv(tmp_path / "no_q2.csv", SimpleNamespace(t=run.t, q=run.q, dq=run.dq, tau=run.tau),
                     [c for c in columns_of(1, 2, 3) if c != "q2"])
    assert "the header has dq2, tau2 without q2:" in refusal(capsys, "model-errors", "--measured", str(tmp_path / "no_q2.csv"))


def test_what_a_rate_cannot_fix_is_said(tmp_path, capsys):
    """Every row written twice halves the finite differences, and a rate of 400.8 Hz seemed to fit: the repeats are
    named first. Stamps rounded to 1 ms at 150 Hz are refused as uneven, and said to look rounded; one gap is not."""
    rows = np.loadtxt(resolve_run("one"), delimiter=",")
    np.savetxt(tmp_path / "twice.csv", np.repeat(rows, 2, axis=0), delimiter=",")
    line = refusal(capsys, "model-errors", "--measured", str(tmp_path / "twice.csv"))
    assert "50% of the rows repeat the one before: each sample written twice?" in line and "--rate 400." in line
    run = load_run(resolve_run("one"), PSM)
    for name, t in (("rounded", np.round(np.arange(len(run.t)) / 150.0, 3)), ("gap", np.r_[run.t[:100], run.t[100:] + 0.005]),
                    ("pause", np.r_[run.t[:100], run.t[100:] + 10.0]), ("every_tenth_lost", 0.005 * (np.arange(len(run.t)) + np.arange(len(run.t)) // 9))):
        write_header_csv(tmp_path / f"{name}.csv", SimpleNamespace(t=t, q=run.q, dq=run.dq, tau=run.tau), columns_of(1, 2, 3))
        line = refusal(capsys, "model-errors", "--measured", str(tmp_path / f"{name}.csv"))
        assert "must be evenly spaced, to 5% of their step" in line and (("the stamps look rounded" in line) == (name == "rounded")), line

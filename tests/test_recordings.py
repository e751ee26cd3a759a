"""Every real recording, not only the development set: the 2018 dataset's
9-column logs, CSVs with a header and a time column, joints not recorded, and
what model-errors, identify and diagnose make of them."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dvrk_dart.cli import main
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.reference_data import SHARED_ROOT, load_run, resolve_run
from arms import PSM, PSM_ARM

DATA_2018 = SHARED_ROOT / "wpi-2018"
TEST1, TEST2 = DATA_2018 / "psm1_fourier_test1.csv", DATA_2018 / "psm1_fourier_test2.csv"
needs_2018 = pytest.mark.skipif(not TEST1.is_file(), reason="the 2018 dataset (../shared/reference_data/wpi-2018) is not here")


def cli_json(capsys, *args) -> dict:
    capsys.readouterr()
    assert main([*args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@needs_2018
def test_a_three_joint_log_reads_as_it_is(capsys):
    """No conversion: the data README's upstream figures, and no figure on the joints not recorded."""
    upstream = cli_json(capsys, "model-errors", "--measured", str(TEST1), "--processing", "upstream")
    assert np.allclose(upstream["rms"][:3], [0.1245, 0.1395, 0.5565], atol=5e-4), upstream["rms"][:3]
    assert upstream["rms"][3:] == [None] * 4 and upstream["relative_error"][3:] == [None] * 4
    periodic = cli_json(capsys, "model-errors", "--measured", str(TEST1), "--processing", "periodic")
    assert all(k >= 5 for k in periodic["joint_cutoffs"][:3]) and periodic["harmonics"] >= 5, periodic["joint_cutoffs"]
    assert periodic["joint_cutoffs"][3:] == [None] * 4 and periodic["rms"][3:] == [None] * 4
    assert abs(periodic["period_s"] - 10.0) < 0.01


@needs_2018
def test_the_start_transients_of_the_2018_runs_are_left_out():
    """Both runs start with the arm going from rest into the excitation (J2's
    effort in test1's first 1.25 s differs from the next period's by ~1 N·m,
    later periods by 0.03): left out, the noise the periodic layer reads on J2
    is the steady cycle's, not the transient's (0.39 N·m with it)."""
    from dvrk_dart.io.reference_data import load_run
    from dvrk_dart.io.signal import process_periodic

    for path, period_s in ((TEST1, 10.0), (TEST2, 1 / 0.13)):
        analysis = process_periodic(load_run(path, PSM)).periodic
        start, stop = analysis.kept
        assert 0 < start <= 0.25 * period_s * 200 and stop == 5990, (path.name, analysis.kept)
        assert analysis.effort_noise.per_sample_rms[1] < 0.05, analysis.effort_noise.per_sample_rms[:3]


@needs_2018
def test_the_commanded_trajectory_gives_the_design(capsys):
    from dvrk_dart.io.excitation_design import read_design

    for run, period in ((1, 10.0), (2, 1 / 0.13)):
        design = read_design(DATA_2018 / f"psm1_fourier_test{run}_commanded.csv")
        assert design.harmonics == 5 and abs(design.period_s - period) < 1e-3 * period
    given = cli_json(capsys, "model-errors", "--measured", str(TEST2), "--processing", "periodic",
                     "--excitation", str(DATA_2018 / "psm1_fourier_test2_commanded.csv"))
    assert given["design_harmonics"] == 5 and given["design_from"].startswith("--excitation")
    # a design is for the periodic processing: never silently dropped
    capsys.readouterr()
    assert main(["model-errors", "--measured", str(TEST2), "--processing", "upstream",
                 "--excitation", str(DATA_2018 / "psm1_fourier_test2_commanded.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--excitation" in err[0] and "upstream" in err[0], err


def _write_header_csv(path: Path, run, columns: list[str], t: bool = True) -> Path:
    table = {"t": run.t}
    for name in columns:
        field, joint = name.rstrip("1234567"), int(name[-1]) - 1
        table[name] = {"q": run.q, "dq": run.dq, "tau": run.tau}[field][:, joint]
    import pandas as pd

    frame = pd.DataFrame({k: v for k, v in table.items() if t or k != "t"})
    frame.to_csv(path, index=False)
    return path


def _columns(*joints: int) -> list[str]:
    """A header's q, dq and tau columns of the joints given (1-based)."""
    return [f"{field}{j}" for j in joints for field in ("q", "dq", "tau")]


def _refusal(capsys, *argv: str) -> str:
    """The one line a refused command prints (exit 2)."""
    capsys.readouterr()
    assert main(list(argv)) == 2
    [line] = capsys.readouterr().err.strip().splitlines()
    return line


def test_a_header_names_any_subset_of_joints(tmp_path):
    """q1, q2 with their velocities and efforts, a time column at 100 Hz: the
    file's own rate, the rest not measured (zeros, no say)."""
    two = load_run(resolve_run("two"), PSM)
    half = type(two)(two.path, two.data.iloc[::2].reset_index(drop=True), PSM)  # every other row: 100 Hz
    path = _write_header_csv(tmp_path / "two_q1q2.csv", half, ["q1", "q2", "dq1", "dq2", "tau1", "tau2"])
    run = load_run(path, PSM)
    assert run.measured == ("q1", "q2") and abs(run.rate_hz - 100.0) < 1e-6
    assert np.allclose(run.q[:, :2], half.q[:, :2]) and not run.q[:, 2:].any() and not run.tau[:, 2:].any()


def test_a_replay_says_what_a_joint_held_at_zero_costs_the_others(tmp_path, capsys):
    """q1, q2 of "two" without q3: the replay printed q1/q2 figures three times the
    full file's with no word (model-errors said it)."""
    two = load_run(resolve_run("two"), PSM)
    path = _write_header_csv(tmp_path / "two_q1q2.csv", two, ["q1", "q2", "dq1", "dq2", "tau1", "tau2"])
    assert main(["replay", "--measured", str(path), "--duration", "2", "--out", str(tmp_path / "r")]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("note: q3 is not recorded"))
    assert "held at 0 m" in note and "q1" in note
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["unrecorded_joint_notes"] == [note.removeprefix("note: ")]


def test_a_q1_only_log_is_diagnosed_with_figures_on_q1_only(tmp_path, capsys):
    """t, q1, dq1, tau1 of 10 s of a real 2018 run: q3 held at its lower limit
    (0) is no divergence (it stopped the diagnosis at 1e-13 m past it), and the
    payload-shaped fit's gravity effort has no figure on the joints not recorded."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    short = type(test1)(test1.path, test1.data.iloc[:2000].reset_index(drop=True), PSM)
    path = _write_header_csv(tmp_path / "q1_only.csv", short, ["q1", "dq1", "tau1"])
    later = type(test1)(test1.path, test1.data.iloc[2000:4000].reset_index(drop=True), PSM)
    held_out = _write_header_csv(tmp_path / "q1_q2.csv", later, ["q1", "dq1", "tau1", "q2", "dq2", "tau2"])  # q2 recorded there only
    out = tmp_path / "diagnosis"
    assert main(["diagnose", "--measured", str(path), "--holdout", str(held_out), "--out", str(out), "--processing", "upstream"]) == 0
    printed = capsys.readouterr().out
    result = json.loads((out / "diagnosis.json").read_text())
    assert result["gap_before"]["train"][1:] == [None] * 6 and result["gap_before"]["train"][0] > 0.1
    # a joint the held-out run has and the training run not: said, not silently left (nor fitted blind and shown)
    assert result["not_recorded_by"] == {"q2": ["q1_only"]} and "q2: not recorded by q1_only" in printed
    printed = printed.replace("q2: not recorded by q1_only", "").replace(f"effect on q2; what the effects do to q2", "")
    fit = result["gravity_mismatch"] or result["payload"]
    if fit is not None:  # a payload-shaped fit: its efforts on q2..q7 are not given, with the reason
        assert fit["gravity_efforts_at_q0"][1:] == [None] * 6 and "q2: not recorded" in fit["not_determined"]["gravity_efforts_at_q0"]
    assert "on q2" not in printed and "on q3" not in printed
    figures = [Path(f).stem for f in result["where"]["figures"]]
    assert "residual_before_q1" in figures and not any(f.endswith(("_q2", "_q4", "_q7")) for f in figures)
    assert set(pd.read_csv(out / "where.csv").joint) == {"q1"}
    assert all("q1" in effect["joints"] for effect in result["effects"])  # no candidate on joints it cannot see
    _replay_figures_on_q1_only(out / "replay_before")


def _replay_figures_on_q1_only(run_dir: Path) -> None:
    """A replay of the log (the diagnosis's before): metrics.json and the report's table have no figure on q2..q7 (held, not measured)."""
    from dvrk_dart.analysis.run_folders import load_run_folder
    from dvrk_dart.analysis.tables import run_metrics

    metrics = json.loads((run_dir / "metrics.json").read_text())
    for key in ("rms_sim_vs_measured", "rms_model_vs_measured", "rms_sim_vs_model"):
        assert metrics[key][0] is not None and metrics[key][1:] == [None] * 6, (key, metrics[key])
    assert metrics["rms_sim_vs_measured"][0] > 0.05
    table = run_metrics(load_run_folder(run_dir))
    assert set(table.joint) & {"q1", "q2", "q3", "q4", "q5", "q6", "q7"} == {"q1"}, sorted(set(table.joint))


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
    ("t,q1,dq1", "q1 without tau"),
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
    path = _write_header_csv(tmp_path / "uneven.csv", two, ["q1", "dq1", "tau1"])
    text = path.read_text().splitlines()
    fields = text[300].split(",")
    fields[0] = str(float(fields[0]) + 0.003)
    text[300] = ",".join(fields)
    path.write_text("\n".join(text) + "\n")
    with pytest.raises(DvrkDartError, match="time column, row"):
        load_run(path, PSM)


@needs_2018
def test_identify_fits_what_the_runs_excite(tmp_path, capsys):
    """The 3-joint runs: the wrist left out with a line each, no refusal, its
    own parameters the published ones in params.json. Its
    start transient left out, test1 alone determines the arm better than the
    published parameters on test2 (J1..J3); 3 s of it do not, and say so."""
    published = cli_json(capsys, "model-errors", "--measured", str(TEST2))["rms"][:3]
    assert main(["identify", "--runs", str(TEST1), "--holdout", str(TEST2), "--out", str(tmp_path / "one_run")]) == 0
    out = capsys.readouterr().out
    assert "q5 left out: not recorded" in out and "1 run(s)" in out
    summary = json.loads((tmp_path / "one_run" / "identification.json").read_text())
    assert summary["fitted_joints"] == ["q1", "q2", "q3"] and summary["data"]["whole_periods"] == 2
    (held_out_errors,) = summary["errors"]["holdout"].values()
    held_out = held_out_errors["whole_run"]["rms"][:3]
    assert np.all(np.array(held_out) < np.array(published)), (held_out, published)
    # the wrist's own friction, offsets and motor inertia: the published values, not zeros a 7-joint run would take as an arm
    fitted, reference = (json.loads(path.read_text()) for path in (tmp_path / "one_run" / "params.json", PSM_ARM.params.source))
    assert all(fitted[k][name] == reference[k][name] for k in ("11", "14") for name in ("Fc", "Fv", "Fo", "Im")), fitted["11"]
    assert "26 parameters act on no fitted joint" in out
    # and the tables say where their values come from (they read 'constraints and prior', prior 0.0)
    held = {p["name"]: p for p in summary["standard_parameters"] if p["held_at_reference"]}
    assert len(held) == 26 == len(summary["held_at_reference"]) and not set(held) & set(summary["set_by_constraints_and_prior"])
    assert held["link11.Im"]["prior"] == held["link11.Im"]["value"] == reference["11"]["Im"]
    three_seconds = tmp_path / "three_seconds.csv"
    np.savetxt(three_seconds, np.loadtxt(TEST1, delimiter=",")[500:1100], delimiter=",")
    assert main(["identify", "--runs", str(three_seconds), "--holdout", str(TEST2), "--processing", "upstream",
                 "--out", str(tmp_path / "short")]) == 0
    assert "warning: q1: held-out RMS" in capsys.readouterr().out
    assert main(["identify", "--runs", str(TEST1), str(TEST2), "--out", str(tmp_path / "two_runs"), "--processing", "upstream"]) == 0
    summary = json.loads((tmp_path / "two_runs" / "identification.json").read_text())
    assert summary["condition_number"] < 1e5 and summary["errors"]["train"]


@needs_2018
def test_a_three_joint_log_of_an_arm_that_couples_them_is_refused(tmp_path):
    """The MTM's q2..q4 mix in the dVRK's values: joints 1..3 alone cannot be put in its coordinates."""
    from arms import MTM

    with pytest.raises(DvrkDartError, match="couples q2, q3, q4"):
        load_run(TEST1, MTM)


def test_rate_and_a_time_column_must_agree(tmp_path, capsys):
    two = load_run(resolve_run("two"), PSM)
    path = _write_header_csv(tmp_path / "timed.csv", two, ["q1", "dq1", "tau1"])
    assert main(["model-errors", "--measured", str(path), "--rate", "100"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rate 100" in err and "time column at 200 Hz" in err
    # within 1 % it agrees, and the stamps set the rate (--rate 199 read the run 0.5 % slow)
    assert load_run(path, PSM, BagTopics(rate_hz=199.0)).rate_hz == pytest.approx(200.0)


def test_a_wrong_time_column_is_named_as_what_to_correct(tmp_path, capsys):
    """A t column at twice the rows' real spacing: the error says to correct the
    column (a --rate beside it would be refused), and which rate fits."""
    two = load_run(resolve_run("two"), PSM)
    path = _write_header_csv(tmp_path / "timed.csv", two, ["q1", "dq1", "tau1"])
    frame = pd.read_csv(path)
    frame["t"] = frame["t"] * 2.0  # 100 Hz written, 200 Hz recorded
    frame.to_csv(path, index=False)
    assert main(["model-errors", "--measured", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "correct the time column, or remove it and give --rate 200" in err, err


def test_a_baseline_of_another_motion_makes_the_default_processing_upstream():
    """Periodic by default reads a payload on a run minus its baseline of the
    same motion; 2018 test2 is another motion than test1: upstream, with why."""
    from dvrk_dart.diagnosis.fit.diagnosis_runs import NO_BASELINE_MOTION, choose_processing, with_baseline_motion

    periodic = choose_processing(["2018-test1", "2018-test2"], None, PSM)
    assert periodic.name == "periodic"
    assert with_baseline_motion(periodic, "2018-test2", ["2018-test1"], PSM).why == NO_BASELINE_MOTION
    assert with_baseline_motion(periodic, "2018-test1", ["2018-test1"], PSM) is periodic


@needs_2018
def test_a_periodic_replay_is_reported_in_its_band(tmp_path):
    """The measured efforts of a periodic replay are in the harmonics' band: the
    report's figures against them are metrics.json's in-band ones (the model's at
    the measured state 0.191 N on q3, the simulation's within 1 mN of it), never
    the log's raw efforts against them (0.225 N on q3: the model looked worse
    than the simulation reproducing it)."""
    from dvrk_dart.analysis.run_folders import load_run_folder
    from dvrk_dart.analysis.tables import run_metrics

    out = tmp_path / "replay"
    assert main(["replay", "--measured", str(TEST2), "--dynamics", "identified", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["processing"] == "periodic"
    table = run_metrics(load_run_folder(out)).set_index(["quantity", "joint"])
    for j, joint in enumerate(("q1", "q2", "q3")):
        simulated = table.loc[("rms_sim_vs_measured", joint)].value
        model = table.loc[("rms_model_full_vs_measured_at_measured_state", joint)].value
        assert simulated == pytest.approx(metrics["rms_sim_vs_measured"][j], rel=1e-12)
        assert abs(simulated - model) < 1e-3, (joint, simulated, model)
    assert not {"rms_model_full_vs_measured", "rms_model_inertial_vs_measured", "rel_sim_vs_measured"} & set(table.index.get_level_values(0))


@needs_2018
def test_a_joint_left_out_that_moves_the_others_efforts_is_said(tmp_path, capsys):
    """2018 trajectory 1 without its q3 columns: held at 0, q3 moves the model's
    efforts on q1 and q2 by more than their RMS (0.38 and 0.17 N·m instead of
    0.10 and 0.12 with q3): said, naming q3; the 9-column file (the wrist held,
    which moves nothing) says nothing."""
    run = load_run(TEST1, PSM)
    path = _write_header_csv(tmp_path / "q1_q2.csv", run, _columns(1, 2))
    without_q3 = cli_json(capsys, "model-errors", "--measured", str(path))
    [note] = without_q3["unrecorded_joint_notes"]
    assert note.startswith("q3 is not recorded") and "on q1 " in note and ", q2 " in note, note
    assert without_q3["rms"][0] > 2 * cli_json(capsys, "model-errors", "--measured", str(TEST1))["rms"][0]
    assert cli_json(capsys, "model-errors", "--measured", str(TEST1))["unrecorded_joint_notes"] == []


def test_upstream_processing_of_another_rate_says_it_works_in_rows(tmp_path, capsys):
    """The same motion logged at 100 Hz: upstream processing scales its cut-off
    with the rate (upstream's half-speed runs), and says so; at 200 Hz nothing."""
    one = load_run(resolve_run("one"), PSM)
    every_other = type(one)(one.path, one.data.iloc[::2].reset_index(drop=True), PSM)
    path = _write_header_csv(tmp_path / "one_100hz.csv", every_other, _columns(*range(1, 8)))
    slow = cli_json(capsys, "model-errors", "--measured", str(path), "--processing", "upstream")
    assert "at 100 Hz its filter's cut-off in Hz is 0.5x the one at 200 Hz" in slow["rate_note"] and "--processing periodic" in slow["rate_note"]
    assert "rate_note" not in cli_json(capsys, "model-errors", "--measured", "one", "--processing", "upstream")


def test_runs_without_a_joint_in_common_are_refused_in_one_line(tmp_path, capsys):
    """q2 in one file, q4..q7 in the other: no joint to diagnose them on (it ended in a traceback)."""
    one = load_run(resolve_run("one"), PSM)
    short = type(one)(one.path, one.data.iloc[:1200].reset_index(drop=True), PSM)
    only_q2 = _write_header_csv(tmp_path / "only_q2.csv", short, _columns(2))
    wrist = _write_header_csv(tmp_path / "wrist.csv", short, _columns(*range(4, 8)))
    out = tmp_path / "diagnosis"
    line = _refusal(capsys, "diagnose", "--measured", str(only_q2), str(wrist), "--processing", "upstream", "--out", str(out))
    assert "no joint is recorded in every run (only_q2: q2; wrist: q4, q5, q6, q7)" in line and not out.exists()


def test_a_session_floor_needs_the_same_joints_recorded(tmp_path, capsys):
    """q2 of "one" against "one-no-weight": the joints one holds at 0 are no session change (it read 0.44 RMS apart)."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = _write_header_csv(tmp_path / "only_q2.csv", one, _columns(2))
    line = _refusal(capsys, "session-floor", "--measured", str(only_q2), "--repeat", "one-no-weight")
    assert "--repeat one-no-weight: its positions move q1, q2, q3, q4, q5, q6, q7, the measured run's q2" in line, line


def test_a_session_floor_gives_no_figure_on_a_joint_without_its_effort(tmp_path, capsys):
    """Two 3-joint logs of one trajectory (q1..q3 of "one" and "one-no-weight"):
    q4..q7 got verdicts of 1e290 times the noise; and an effort missing in one
    run, its positions there, is compared on the joints both recorded."""
    for name in ("one", "one-no-weight"):
        values = np.loadtxt(resolve_run(name), delimiter=",")
        np.savetxt(tmp_path / f"{name}_9.csv", np.hstack([values[:, 0:3], values[:, 7:10], values[:, 14:17]]), delimiter=",")
    three = cli_json(capsys, "session-floor", "--measured", str(tmp_path / "one_9.csv"), "--repeat", str(tmp_path / "one-no-weight_9.csv"))
    whole = cli_json(capsys, "session-floor", "--measured", "one", "--repeat", "one-no-weight")
    assert three["rms_difference"][3:] == [None] * 4 and three["verdict"][3:] == [None] * 4
    assert np.allclose(three["rms_difference"][:3], whole["rms_difference"][:3], rtol=0.05), (three["rms_difference"], whole["rms_difference"])
    values = np.loadtxt(resolve_run("one"), delimiter=",")
    values[:, 17] = 0.0  # q4's effort not read
    np.savetxt(tmp_path / "one_no_tau4.csv", values, delimiter=",")
    partial = cli_json(capsys, "session-floor", "--measured", str(tmp_path / "one_no_tau4.csv"), "--repeat", "one-no-weight")
    assert partial["rms_difference"][3] is None and all(v is not None for i, v in enumerate(partial["rms_difference"]) if i != 3)


def test_a_still_arm_is_not_diagnosed(tmp_path, capsys):
    """Every position constant: 7 effects were fitted to its zero gap, and the held-out run got worse by 2.5 N·m."""
    one = load_run(resolve_run("one"), PSM)
    still = type(one)(one.path, one.data.iloc[:1200].reset_index(drop=True), PSM)
    still.data.iloc[:, 1:8] = one.data.iloc[0, 1:8].to_numpy()  # positions held, efforts as measured
    still.data.iloc[:, 8:15] = 0.0  # no velocity
    path = _write_header_csv(tmp_path / "still.csv", still, _columns(*range(1, 8)), t=False)
    out = tmp_path / "diagnosis"
    line = _refusal(capsys, "diagnose", "--measured", str(path), "--out", str(out))
    assert "still.csv: no recorded joint moves" in line and not out.exists()


def test_some_columns_of_a_recording_are_that_recording(tmp_path, capsys):
    """Held out on q2 of the training run itself: refused as the same recording (it was scored as held out)."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = _write_header_csv(tmp_path / "only_q2.csv", one, _columns(2))
    line = _refusal(capsys, "identify", "--runs", "one", "--holdout", str(only_q2), "--out", str(tmp_path / "id"))
    assert "the same recording as --runs one (same positions)" in line


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
    assert "no_effort.csv: no effort column changes" in _refusal(capsys, "model-errors", "--measured", str(tmp_path / "no_effort.csv"))


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
    assert words in _refusal(capsys, "model-errors", "--measured", str(tmp_path / "broken.csv"), "--processing", "upstream")


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


@needs_2018
def test_the_data_readmes_ten_harmonic_figures(capsys):
    """--harmonics imposes the band: the data README's figures at 10 harmonics
    (computed by others, not by this project), J1..J3 of both runs, to 4 %."""
    quoted = {TEST1: [0.095, 0.104, 0.216], TEST2: [0.082, 0.139, 0.164]}
    for path, figures in quoted.items():
        result = cli_json(capsys, "model-errors", "--measured", str(path), "--harmonics", "10")
        assert result["harmonics"] == 10 and result["chosen_because"] == "--harmonics 10"
        assert np.allclose(result["rms"][:3], figures, rtol=0.04), (path.name, result["rms"][:3])
    assert "--harmonics: it imposes" in _refusal(capsys, "model-errors", "--measured", str(TEST1), "--harmonics", "10",
                                                 "--processing", "upstream")


def test_identify_says_when_joints_held_at_zero_move_the_fitted_ones(tmp_path, capsys):
    """q2 alone (q1 and q3 not recorded, held at 0 by the fit): model-errors
    said so, identify did not, and its held-out q2 was 10x its training figure."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = _write_header_csv(tmp_path / "only_q2.csv", one, _columns(2))
    capsys.readouterr()
    assert main(["identify", "--runs", str(only_q2), "--holdout", "two", "--out", str(tmp_path / "id")]) == 0
    out = capsys.readouterr().out
    assert "warning: only_q2: q1 is not recorded and held at 0 rad" in out.replace(str(only_q2), "only_q2"), out
    assert "q3 is not recorded and held at 0 m" in out
    two_rows = [line.split() for line in out.splitlines() if line.startswith("two whole")]
    assert two_rows and two_rows[0][2:9:2] == ["-", "-", "-", "-"], two_rows  # no figure on a joint not fitted


def test_a_run_whose_sample_period_is_not_a_whole_number_of_steps_is_simulated(tmp_path):
    """Absolute ROS stamps read at 199.995 Hz: the diagnosis's re-simulation
    refused ("sample period 0.0050001 s is not a multiple of the step"); its
    step is now a whole fraction of the period, and the efforts are the 200 Hz run's."""
    from dvrk_dart.io.signal import process
    from dvrk_dart.runs.replay import simulate_efforts
    from dvrk_dart.sim.config import SimConfig

    one = load_run(resolve_run("one"), PSM)
    part = type(one)(one.path, one.data.iloc[:1000].reset_index(drop=True), PSM)
    part.data["t"] = np.arange(len(part.data)) / 199.995
    path = _write_header_csv(tmp_path / "stamped.csv", part, _columns(*range(1, 8)))
    stamped, even = (process(load_run(p, PSM)) for p in (path, _write_header_csv(tmp_path / "even.csv", part, _columns(*range(1, 8)), t=False)))
    assert abs(stamped.rate_hz - 199.995) < 1e-6
    efforts = simulate_efforts(PSM_ARM, SimConfig(), stamped)
    assert efforts.shape == stamped.tau.shape
    assert np.max(np.abs(efforts - simulate_efforts(PSM_ARM, SimConfig(), even))[100:-100]) < 0.01


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


def test_a_diagnosis_gives_no_session_floor_on_a_joint_not_recorded(tmp_path):
    """3-joint logs with a --repeat: diagnosis.json's session floor, the effects'
    explained fractions and the payload candidates' efforts read 0.0 on q4..q7."""
    from dvrk_dart.diagnosis.diagnose import diagnose

    for name in ("one", "one-no-weight"):
        values = np.loadtxt(resolve_run(name), delimiter=",")
        np.savetxt(tmp_path / f"{name}_9.csv", np.hstack([values[:, 0:3], values[:, 7:10], values[:, 14:17]]), delimiter=",")
    result = diagnose(str(tmp_path / "one_9.csv"), repeat=str(tmp_path / "one-no-weight_9.csv"), arm=PSM_ARM, max_effects=2,
                      figures=False, profile_payload_mass=False)
    assert result["session_floor"][3:] == [None] * 4 and all(v > 0 for v in result["session_floor"][:3]), result["session_floor"]
    for effect in result["effects"]:  # nor an explained fraction (they read 0.0)
        assert effect["explained_fraction_per_joint"]["cross_validated"][3:] == [None] * 4
    for candidate in result["payload_candidates"]:
        assert candidate["gravity_efforts_at_q0"][3:] == [None] * 4, candidate["gravity_efforts_at_q0"]


def test_velocity_columns_in_another_unit_are_named_not_a_rate(tmp_path, capsys):
    """dq1, dq2 in deg/s and dq3 in m/s: the tool offered '--rate 393.4' (a median of the joints' scales), which
    read the run 2x fast. A rate scales every joint alike: the columns are named."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    path = _write_header_csv(tmp_path / "deg.csv", test1, _columns(1, 2, 3))
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
    path = _write_header_csv(tmp_path / "q3_zero.csv", test1, _columns(1, 2, 3))
    frame = pd.read_csv(path)
    frame[["q3", "dq3"]] = 0.0
    frame.to_csv(path, index=False)
    capsys.readouterr()
    load_run(path, PSM)
    assert "q3's position is 0 for the whole run while its effort changes" in capsys.readouterr().err
    load_run(resolve_run("2018-test1"), PSM)
    assert "for the whole run" not in capsys.readouterr().err


@needs_2018
def test_an_excitation_the_run_did_not_play_is_refused_though_its_period_matches(tmp_path, capsys):
    """test1's commanded file with q1 and q2 swapped (or 'one''s design given for 'two', same period) passed the
    period check and set the band. The commanded harmonics' amplitudes are the run's to 1 % on test1 and test2;
    swapped they are 85 % apart."""
    commanded = np.loadtxt(DATA_2018 / "psm1_fourier_test1_commanded.csv", delimiter=",")
    swapped = commanded.copy()
    swapped[[0, 1]] = commanded[[1, 0]]
    path = tmp_path / "swapped_commanded.csv"
    np.savetxt(path, swapped, delimiter=",")
    line = _refusal(capsys, "model-errors", "--measured", str(TEST1), "--excitation", str(path))
    assert "q1's harmonics in it are not the run's" in line and "did not play this excitation" in line
    assert main(["model-errors", "--measured", str(TEST1), "--excitation", str(DATA_2018 / "psm1_fourier_test1_commanded.csv")]) == 0


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

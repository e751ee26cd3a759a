"""Every real recording, not only the development set: the 2018 dataset's
9-column logs, CSVs with a header and a time column, joints not recorded, and
what model-errors, identify and diagnose make of them (the checks of a CSV's
columns themselves: test_csv_columns.py)."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dvrk_dart.cli import main
from dvrk_dart.io.csv_run import notes_kept, say_once
from dvrk_dart.io.reference_data import load_run, resolve_run
from arms import PSM, PSM_ARM
from recordings import TEST1, TEST2, DATA_2018, cli_json, columns_of, needs_2018, refusal, write_header_csv


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


def test_a_replay_says_what_a_joint_held_at_zero_costs_the_others(tmp_path, capsys):
    """q1, q2 of "two" without q3: the replay printed q1/q2 figures three times the
    full file's with no word (model-errors said it)."""
    two = load_run(resolve_run("two"), PSM)
    path = write_header_csv(tmp_path / "two_q1q2.csv", two, ["q1", "q2", "dq1", "dq2", "tau1", "tau2"])
    assert main(["replay", "--measured", str(path), "--duration", "2", "--out", str(tmp_path / "r")]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("note: q3 is not recorded"))
    assert "held at 0 m" in note and "q1" in note
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["unrecorded_joint_notes"] == [note.removeprefix("note: ")]
    # the log's measured trace: q3..q7 not measured (null), not zeros a viewer would draw as measured
    from dvrk_dart.io.mcap_read import read_mcap

    record = read_mcap(tmp_path / "r" / "run.mcap")
    for values in (record.effort_measured, record.q_measured, record.dq_measured):
        assert np.isfinite(values[:, :2]).all() and np.isnan(values[:, 2:]).all()


def test_a_q1_only_log_is_diagnosed_with_figures_on_q1_only(tmp_path, capsys):
    """t, q1, dq1, tau1 of 10 s of a real 2018 run: q3 held at its lower limit
    (0) is no divergence (it stopped the diagnosis at 1e-13 m past it), and the
    payload-shaped fit's gravity effort has no figure on the joints not recorded."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    short = type(test1)(test1.path, test1.data.iloc[:2000].reset_index(drop=True), PSM)
    path = write_header_csv(tmp_path / "q1_only.csv", short, ["q1", "dq1", "tau1"])
    later = type(test1)(test1.path, test1.data.iloc[2000:4000].reset_index(drop=True), PSM)
    held_out = write_header_csv(tmp_path / "q1_q2.csv", later, ["q1", "dq1", "tau1", "q2", "dq2", "tau2"])  # q2 recorded there only
    out = tmp_path / "diagnosis"
    assert main(["diagnose", "--measured", str(path), "--holdout", str(held_out), "--out", str(out), "--processing", "upstream"]) == 0
    printed = capsys.readouterr().out
    result = json.loads((out / "diagnosis.json").read_text())
    assert result["gap_before"]["train"][1:] == [None] * 6 and result["gap_before"]["train"][0] > 0.1
    # a joint the held-out run has and the training run not: said, not silently left (nor fitted blind and shown)
    assert result["not_recorded_by"] == {"q2": ["q1_only"]} and "q2: not recorded by q1_only" in printed
    printed = printed.replace("q2: not recorded by q1_only", "").replace("effect on q2; what the effects do to q2", "")
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
    path = write_header_csv(tmp_path / "q1_q2.csv", run, columns_of(1, 2))
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
    path = write_header_csv(tmp_path / "one_100hz.csv", every_other, columns_of(*range(1, 8)))
    slow = cli_json(capsys, "model-errors", "--measured", str(path), "--processing", "upstream")
    assert "at 100 Hz its filter's cut-off in Hz is 0.5x the one at 200 Hz" in slow["rate_note"] and "--processing periodic" in slow["rate_note"]
    assert "rate_note" not in cli_json(capsys, "model-errors", "--measured", "one", "--processing", "upstream")


def test_runs_without_a_joint_in_common_are_refused_in_one_line(tmp_path, capsys):
    """q2 in one file, q4..q7 in the other: no joint to diagnose them on (it ended in a traceback)."""
    one = load_run(resolve_run("one"), PSM)
    short = type(one)(one.path, one.data.iloc[:1200].reset_index(drop=True), PSM)
    only_q2 = write_header_csv(tmp_path / "only_q2.csv", short, columns_of(2))
    wrist = write_header_csv(tmp_path / "wrist.csv", short, columns_of(*range(4, 8)))
    out = tmp_path / "diagnosis"
    line = refusal(capsys, "diagnose", "--measured", str(only_q2), str(wrist), "--processing", "upstream", "--out", str(out))
    assert "no joint is recorded in every run (only_q2: q2; wrist: q4, q5, q6, q7)" in line and not out.exists()


def test_a_session_floor_needs_the_same_joints_recorded(tmp_path, capsys):
    """q2 of "one" against "one-no-weight": the joints one holds at 0 are no session change (it read 0.44 RMS apart)."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = write_header_csv(tmp_path / "only_q2.csv", one, columns_of(2))
    line = refusal(capsys, "session-floor", "--measured", str(only_q2), "--repeat", "one-no-weight")
    assert "--repeat one-no-weight: its positions move q1, q2, q3, q4, q5, q6, q7 but the measured run's positions move q2" in line, line


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
    path = write_header_csv(tmp_path / "still.csv", still, columns_of(*range(1, 8)), t=False)
    out = tmp_path / "diagnosis"
    line = refusal(capsys, "diagnose", "--measured", str(path), "--out", str(out))
    assert "still.csv: no recorded joint moves" in line and not out.exists()


def test_some_columns_of_a_recording_are_that_recording(tmp_path, capsys):
    """Held out on q2 of the training run itself: refused as the same recording (it was scored as held out)."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = write_header_csv(tmp_path / "only_q2.csv", one, columns_of(2))
    line = refusal(capsys, "identify", "--runs", "one", "--holdout", str(only_q2), "--out", str(tmp_path / "id"))
    assert "the same recording as --runs one (same positions)" in line


@needs_2018
def test_the_data_readmes_ten_harmonic_figures(capsys):
    """--harmonics imposes the band: the data README's figures at 10 harmonics
    (computed by others, not by this project), J1..J3 of both runs, to 4 %."""
    quoted = {TEST1: [0.095, 0.104, 0.216], TEST2: [0.082, 0.139, 0.164]}
    for path, figures in quoted.items():
        result = cli_json(capsys, "model-errors", "--measured", str(path), "--harmonics", "10")
        assert result["harmonics"] == 10 and result["chosen_because"] == "--harmonics 10"
        assert np.allclose(result["rms"][:3], figures, rtol=0.04), (path.name, result["rms"][:3])
    assert "--harmonics: it imposes" in refusal(capsys, "model-errors", "--measured", str(TEST1), "--harmonics", "10",
                                                 "--processing", "upstream")


def test_identify_says_when_joints_held_at_zero_move_the_fitted_ones(tmp_path, capsys):
    """q2 alone (q1 and q3 not recorded, held at 0 by the fit): model-errors
    said so, identify did not, and its held-out q2 was 10x its training figure."""
    one = load_run(resolve_run("one"), PSM)
    only_q2 = write_header_csv(tmp_path / "only_q2.csv", one, columns_of(2))
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
    path = write_header_csv(tmp_path / "stamped.csv", part, columns_of(*range(1, 8)))
    stamped, even = (process(load_run(p, PSM)) for p in (path, write_header_csv(tmp_path / "even.csv", part, columns_of(*range(1, 8)), t=False)))
    assert abs(stamped.rate_hz - 199.995) < 1e-6
    efforts = simulate_efforts(PSM_ARM, SimConfig(), stamped)
    assert efforts.shape == stamped.tau.shape
    assert np.max(np.abs(efforts - simulate_efforts(PSM_ARM, SimConfig(), even))[100:-100]) < 0.01


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
    line = refusal(capsys, "model-errors", "--measured", str(TEST1), "--excitation", str(path))
    assert "q1's harmonics in it are not the run's" in line and "did not play this excitation" in line
    assert main(["model-errors", "--measured", str(TEST1), "--excitation", str(DATA_2018 / "psm1_fourier_test1_commanded.csv")]) == 0




def test_the_notes_of_a_stage_on_runs_it_made_go_to_its_output_not_the_terminal(capsys):
    with notes_kept([]) as kept:
        say_once(["a note only this test says"])
    assert kept == ["a note only this test says"]
    assert "a note only this test says" not in capsys.readouterr().err


@needs_2018
def test_a_diagnosis_opens_with_what_a_joint_the_log_left_out_may_have_put_there(tmp_path, capsys):
    """q1 and q2 of 10 s of a 2018 run, q3 (which moved over its whole stroke) not recorded: held at 0 in the
    simulation, it moves the model's q2 efforts more than q2's gap. The answer says so before any finding
    (a fuzzed "two" without q3 was answered "a gravity mismatch on insertion_carriage" with nothing else)."""
    test1 = load_run(resolve_run("2018-test1"), PSM)
    short = type(test1)(test1.path, test1.data.iloc[:2000].reset_index(drop=True), PSM)
    path = write_header_csv(tmp_path / "q1_q2.csv", short, columns_of(1, 2))
    out = tmp_path / "diagnosis"
    assert main(["diagnose", "--measured", str(path), "--out", str(out), "--processing", "upstream"]) == 0
    printed = capsys.readouterr().out
    notes = json.loads((out / "diagnosis.json").read_text())["unrecorded_joint_notes"]
    assert notes and all(note.startswith("q1_q2: q3 is not recorded") for note in notes) and "q2 " in notes[0]
    assert printed.startswith("First: q1_q2: q3 is not recorded")


def test_an_upstream_session_floor_names_the_rates_and_the_samples_it_compares(tmp_path, capsys):
    """The same motion logged at 100 Hz read "not the same motion" upstream (which does not resample), and a
    longer run was cut to the shorter's samples without a word."""
    from types import SimpleNamespace

    nw = load_run(resolve_run("one-no-weight"), PSM)
    every_other = SimpleNamespace(t=nw.t[::2], q=nw.q[::2], dq=nw.dq[::2], tau=nw.tau[::2])
    slow = write_header_csv(tmp_path / "nw_100hz.csv", every_other, columns_of(*range(1, 8)))
    line = refusal(capsys, "session-floor", "--measured", "one", "--repeat", str(slow), "--processing", "upstream")
    assert "logged at 100 Hz, the run it is compared with at 200 Hz: the upstream processing compares runs sample by sample" in line, line
    values = np.loadtxt(resolve_run("one-no-weight"), delimiter=",")
    np.savetxt(tmp_path / "nw_half.csv", values[:3000], delimiter=",")
    assert main(["session-floor", "--measured", "one", "--repeat", str(tmp_path / "nw_half.csv"), "--processing", "upstream"]) == 0
    assert "compared on the first 2600 processed samples (13.0 s), which both have" in capsys.readouterr().err

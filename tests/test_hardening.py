"""Hostile-but-fair input: every command answers bad input with one line on
stderr and exit code 2, loses nothing it did not make, and leaves nothing
half-written. One test per item of the hardening issue."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dvrk_dart.cli import main
from dvrk_dart.io.reference_data import resolve, resolve_run
from dvrk_dart.io.signal import MIN_ROWS
from dvrk_dart.sim.simulator import PsmSimulator
from arms import PSM_ARM


def tree_digest(folder: Path) -> dict[str, str]:
    """Every file under `folder` (names included) with its sha256: a byte-identity check."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def cli(capsys, *argv: str) -> tuple[int, list[str]]:
    """Run the CLI in-process: (exit code, stderr lines)."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    return code, [line for line in err.splitlines() if line.strip()]


def assert_one_line_error(code: int, lines: list[str], *fragments: str) -> None:
    assert code == 2, lines
    assert len(lines) == 1 and lines[0].startswith("dvrk-dart: "), lines
    assert "Traceback" not in lines[0]
    for fragment in fragments:
        assert fragment in lines[0], lines


def measured_csv(tmp_path: Path, name: str, edit=None, rows: int | None = None) -> Path:
    values = np.loadtxt(resolve_run("two"), delimiter=",")[:rows]
    if edit is not None:
        edit(values)
    path = tmp_path / name
    np.savetxt(path, values, delimiter=",")
    return path


@pytest.fixture(scope="module")
def a_run_folder(tmp_path_factory) -> Path:
    runs = tmp_path_factory.mktemp("runs")
    assert main(["run", "rectilinear", "--mode", "kinematic", "--duration", "0.05", "--out", str(runs / "rect")]) == 0
    return runs / "rect"


# ---------------------------------------------------------------- 1. report never deletes what it did not make


def test_report_refuses_an_out_folder_holding_its_runs_and_leaves_it_byte_identical(tmp_path, capsys, a_run_folder):
    project = tmp_path / "P"
    (project / "runs").mkdir(parents=True)
    subprocess.run(["cp", "-r", str(a_run_folder), str(project / "runs")], check=True)
    (project / "notes.txt").write_text("keep\n")
    before = tree_digest(project)
    code, lines = cli(capsys, "report", "--runs", project / "runs", "--out", project)
    assert_one_line_error(code, lines, "--out", "contains --runs")
    assert tree_digest(project) == before


def test_report_refuses_a_folder_or_file_it_did_not_make(tmp_path, capsys, a_run_folder):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("\\documentclass{article}\n")
    code, lines = cli(capsys, "report", "--runs", a_run_folder.parent, "--out", foreign)
    assert_one_line_error(code, lines, "not made by dvrk-dart")
    assert (foreign / "thesis.tex").read_text().startswith("\\documentclass")
    a_file = tmp_path / "report.html"
    a_file.write_text("mine")
    code, lines = cli(capsys, "report", "--runs", a_run_folder.parent, "--out", a_file)
    assert_one_line_error(code, lines, "is a file")
    assert a_file.read_text() == "mine" and not list(tmp_path.glob(".report.html*"))


def test_report_replaces_its_own_report(tmp_path, capsys, a_run_folder):
    out = tmp_path / "report"
    assert cli(capsys, "report", "--runs", a_run_folder.parent, "--out", out)[0] == 0
    assert cli(capsys, "report", "--runs", a_run_folder.parent, "--out", out)[0] == 0
    assert (out / "index.html").is_file() and not list(tmp_path.glob(".report*"))


# ---------------------------------------------------------------- 2. a run folder is replaced whole or not at all


def test_a_failed_rerun_leaves_the_previous_run_folder_intact(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    assert cli(capsys, "run", "rectilinear", "--mode", "velocity", "--duration", "0.05", "--out", out)[0] == 0
    before = tree_digest(out)

    def broken_rrd(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr("dvrk_dart.io.rerun_log.write_rrd", broken_rrd)
    code, lines = cli(capsys, "run", "rectilinear", "--mode", "velocity", "--duration", "0.1", "--out", out)
    assert code == 2 and lines == ["dvrk-dart: disk full"]
    assert tree_digest(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["run"]


def test_a_default_replay_folder_of_another_file_of_the_same_name_is_kept(tmp_path, capsys, monkeypatch):
    """out/runs/<name> is named after the file's name: another folder's x.csv does not replace its replay."""
    monkeypatch.chdir(tmp_path)
    for folder in ("a", "b"):
        (tmp_path / folder).mkdir()
        measured_csv(tmp_path / folder, "x.csv", rows=600)
    assert cli(capsys, "replay", "--measured", "a/x.csv", "--duration", "0.5")[0] == 0
    (out,) = (tmp_path / "out" / "runs").iterdir()
    before = tree_digest(out)
    code, lines = cli(capsys, "replay", "--measured", "b/x.csv", "--duration", "0.5")
    assert_one_line_error(code, lines, "a/x.csv", "give --out")
    assert capsys.readouterr().out == "" and tree_digest(out) == before
    assert cli(capsys, "replay", "--measured", "a/x.csv", "--duration", "0.5")[0] == 0  # its own file: replaced


# ---------------------------------------------------------------- 3. a divergence at the first step


def test_a_divergence_at_the_first_step_says_why_and_keeps_strict_json(tmp_path, capsys):
    def fling(values):  # q1 just inside its range, driven out of it at once
        values[:, 0] = 1.599
        values[:, 7] = 50.0

    from dvrk_dart.runs.campaign import write_run_folder
    from dvrk_dart.runs.config import RunConfig
    from dvrk_dart.runs.runner import run

    bad = measured_csv(tmp_path, "fling.csv", fling)
    out = tmp_path / "X"
    # upstream: the raw velocity column drives the replay (the periodic layer would smooth the fling away)
    code, lines = cli(capsys, "replay", "--measured", bad, "--out", out, "--processing", "upstream")
    assert any("q1's position is 1.599 for the whole run" in line for line in lines)  # a frozen q1 beside its effort: noted
    lines = [line for line in lines if not line.startswith("dvrk-dart: note:")]
    assert_one_line_error(code, lines, "step 1", "joint q1 at 1.6", "outside its range [-1.6, 1.6]", "nothing written")
    assert not out.exists()  # a run that stopped is no result
    # validate's campaign keeps what was logged up to the divergence, as strict JSON
    record = run(RunConfig("replay", "velocity", measured=str(bad), processing="upstream"), PSM_ARM)
    write_run_folder(record, out, PSM_ARM.model)
    metrics = json.loads((out / "metrics.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in metrics.json"))
    assert "step 1" in metrics["error"] and metrics["samples"] == 0
    assert (out / "config.json").is_file()


def test_a_kinematic_path_out_of_the_joint_ranges_stops(tmp_path, capsys):
    """A 50 m rectilinear path: the imposed joints left their ranges (q3 up to
    50 m) with exit 0 and a tool tip on its path; now the run stops there."""
    text = (Path(__file__).parents[1] / "pipelines" / "scenarios" / "rectilinear.toml").read_text()
    assert "length_m = 0.09" in text
    scenario = tmp_path / "long.toml"
    scenario.write_text(text.replace("length_m = 0.09", "length_m = 50.0"))
    code, lines = cli(capsys, "run", scenario, "--mode", "kinematic", "--duration", "0.5", "--out", tmp_path / "run")
    assert_one_line_error(code, lines, "outside its range", "the path leaves what the arm can reach")


# ---------------------------------------------------------------- 4. unreadable run logs are named


@pytest.mark.parametrize("damage", ["corrupt", "truncated", "empty", "foreign"])
def test_report_refuses_unreadable_runs_unless_allowed_then_names_them(tmp_path, capsys, a_run_folder, damage):
    runs = tmp_path / "runs"
    runs.mkdir()
    subprocess.run(["cp", "-r", str(a_run_folder), str(runs / "good")], check=True)
    subprocess.run(["cp", "-r", str(a_run_folder), str(runs / "bad")], check=True)
    log = runs / "bad" / "run.mcap"
    content = log.read_bytes()
    log.write_bytes({"corrupt": content[:100] + b"\0" * 500 + content[600:], "truncated": content[: len(content) // 2],
                     "empty": b"", "foreign": b"PK\x03\x04 a zip file"}[damage])
    code, lines = cli(capsys, "report", "--runs", runs, "--out", tmp_path / "report")
    assert code == 2 and len(lines) == 1 and "bad" in lines[0] and "--allow-unreadable" in lines[0], lines
    assert not (tmp_path / "report").exists()
    code, lines = cli(capsys, "report", "--runs", runs, "--out", tmp_path / "report", "--allow-unreadable")
    assert code == 0 and any("unreadable run bad" in line for line in lines), lines
    assert "bad" in (tmp_path / "report" / "index.html").read_text()


# ---------------------------------------------------------------- 5. bad --out, before any work


@pytest.mark.parametrize("command", [
    ["replay", "--measured", "two"],
    ["run", "spiral"],
    ["diagnose", "--measured", "two"],
    ["report", "--runs", "RUNS"],
    ["validate", "--report", "REPORT"],
])
@pytest.mark.parametrize("where", ["a file", "under a file"])
def test_a_bad_out_is_refused_before_any_work(tmp_path, capsys, monkeypatch, a_run_folder, command, where):
    a_file = tmp_path / "file.txt"
    a_file.write_text("mine")
    out = a_file if where == "a file" else a_file / "sub"
    argv = [str(a_run_folder.parent) if a == "RUNS" else str(tmp_path / "report") if a == "REPORT" else a for a in command]

    def no_simulation(*args, **kwargs):
        raise AssertionError("a simulation started before --out was checked")

    monkeypatch.setattr(PsmSimulator, "__init__", no_simulation)  # refused up front, not after a simulation
    code, lines = cli(capsys, *argv, "--out", out)
    assert_one_line_error(code, lines, "--out", "file")
    assert a_file.read_text() == "mine" and sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_out_is_refused(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    code, lines = cli(capsys, "run", "spiral", "--out", locked / "run")
    assert_one_line_error(code, lines, "not writable")


# ---------------------------------------------------------------- 6. unreadable parameter files


def test_a_non_utf8_parameter_file_is_a_one_line_error(tmp_path, capsys):
    params = tmp_path / "params.json"
    params.write_bytes(b'{"1": {"m": "caf\xe9"}}')
    code, lines = cli(capsys, "model-errors", "--measured", "two", "--params", params)
    assert_one_line_error(code, lines, str(params), "not UTF-8")


# ---------------------------------------------------------------- 7. durations


@pytest.mark.parametrize("duration", ["-1", "0", "1e12", "nan"])
def test_an_impossible_duration_is_a_one_line_error(tmp_path, capsys, duration):
    code, lines = cli(capsys, "run", "spiral", "--duration", duration, "--out", tmp_path / "x")
    assert_one_line_error(code, lines, "--duration")
    assert not (tmp_path / "x").exists()


# ---------------------------------------------------------------- 8. parameter files: missing keys, implausible values


def edited_params(tmp_path: Path, edit) -> Path:
    raw = json.loads(resolve(PSM_ARM.model.default_parameters).read_text())
    edit(raw)
    path = tmp_path / "params.json"
    path.write_text(json.dumps(raw))
    return path


@pytest.mark.parametrize("edit, fragments", [
    (lambda raw: raw["4"].pop("m"), ("link 4", "'m' is missing")),
    (lambda raw: raw["2"].pop("Fc"), ("link 2", "'Fc' is missing")),
    (lambda raw: raw["5"].pop("r"), ("link 5", "'r' is missing")),
    (lambda raw: raw["4"].update(m=1e30), ("link 4", "mass 1e+30 kg above the plausible")),
    (lambda raw: raw["4"].update(r=[1e6, 0.0, 0.0]), ("link 4", "centre of mass", "above the plausible")),
])
def test_parameter_files_missing_keys_or_implausible_values_are_refused(tmp_path, capsys, edit, fragments):
    params = edited_params(tmp_path, edit)
    code, lines = cli(capsys, "model-errors", "--measured", "two", "--params", params)
    assert_one_line_error(code, lines, str(params), *fragments)


# ---------------------------------------------------------------- 9. measured positions outside the joint ranges


@pytest.mark.parametrize("column, value", [(2, 5.0), (0, 1e300)])
@pytest.mark.parametrize("command", [["replay", "--mode", "kinematic"], ["model-errors"]])
def test_measured_positions_outside_the_joint_ranges_are_refused(tmp_path, capsys, column, value, command):
    def edit(values):
        values[10, column] = value

    bad = measured_csv(tmp_path, "far.csv", edit)
    extra = ["--out", str(tmp_path / "out")] if command[0] == "replay" else []
    code, lines = cli(capsys, command[0], "--measured", bad, *command[1:], *extra)
    assert_one_line_error(code, lines, "row 11", f"q{column + 1}", "outside the joint range")
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------- 10. shorthands take no --measured


def test_one_replay_command(capsys):
    """The reference runs are replayed with `replay --measured NAME`: no alias commands beside it."""
    assert main(["replay-two"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid choice: 'replay-two'" in err[0]


# ---------------------------------------------------------------- 11. the minor ones


def test_the_row_count_message_states_what_the_processing_needs(tmp_path, capsys):
    short = measured_csv(tmp_path, "short.csv", rows=1)
    code, lines = cli(capsys, "model-errors", "--measured", short)
    assert_one_line_error(code, lines, f"1 rows, at least {MIN_ROWS} needed")
    assert MIN_ROWS == 410  # 200 trimmed from each end, 10 kept


def test_a_header_without_rows_is_one_line(tmp_path, capsys):
    """A header and no data rows was a traceback (a reduction over zero rows) in every command that reads a run."""
    header_only = tmp_path / "header_only.csv"
    header_only.write_text("q1,dq1,tau1\n")
    code, lines = cli(capsys, "model-errors", "--measured", header_only)
    assert_one_line_error(code, lines, "header_only.csv: a header row and no data rows")


def test_diagnose_leaves_no_out_folder_on_input_errors(tmp_path, capsys):
    code, lines = cli(capsys, "diagnose", "--measured", tmp_path / "missing.csv", "--out", tmp_path / "diag")
    assert_one_line_error(code, lines, "missing.csv")
    assert list(tmp_path.iterdir()) == []


def test_report_extra_must_be_a_folder(tmp_path, capsys, a_run_folder):
    extra = tmp_path / "extra.html"
    extra.write_text("<p>x</p>")
    code, lines = cli(capsys, "report", "--runs", a_run_folder.parent, "--out", tmp_path / "report", "--extra", extra)
    assert_one_line_error(code, lines, "--extra", "not a folder")
    assert not (tmp_path / "report").exists()


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_an_interrupted_run_leaves_no_partial_folder(tmp_path, signum):
    out = tmp_path / "run"
    process = subprocess.Popen([sys.executable, "-m", "dvrk_dart.cli", "replay", "--measured", "two", "--out", str(out)],
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".run.building-*")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)  # interrupt while the folder is being written
    process.send_signal(signum)
    _, err = process.communicate(timeout=60)
    assert process.returncode in (130, 143) or (process.returncode == 0 and out.is_dir()), err
    assert "Traceback" not in err
    assert not list(tmp_path.glob(".run.*")), "a partial folder was left"


def test_a_command_stopped_after_writing_a_folder_says_that_folder_is_complete(tmp_path):
    """A SIGTERM while diagnose printed its summary said "partial outputs removed" of a complete folder."""
    from dvrk_dart.cli import _stopped
    from dvrk_dart.io.outputs import FOLDERS_WRITTEN, building_folder

    before = len(FOLDERS_WRITTEN)
    assert _stopped("terminated", before) == "dvrk-dart: terminated (partial outputs removed)"
    with building_folder(tmp_path / "done", "run") as folder:
        (folder / "a.json").write_text("{}")
    assert _stopped("terminated", before) == f"dvrk-dart: terminated (partial outputs removed; {tmp_path / 'done'} written before it, complete)"


def test_divergence_values_show_enough_digits(tmp_path, capsys):
    def edge(values):  # just past the pitch limit after the first step
        values[:, 1] = 0.8999999
        values[:, 8] = 0.5

    code, lines = cli(capsys, "replay", "--measured", measured_csv(tmp_path, "edge.csv", edge), "--out", tmp_path / "x",
                      "--processing", "upstream")
    assert code == 2
    lines = [line for line in lines if not line.startswith("dvrk-dart: note:")]  # the frozen q2 is noted
    value, bounds = lines[0].split(" at ")[1].split(" outside its range ")
    low, high = (float(b) for b in bounds.split("]")[0].strip("[").split(","))
    assert not (low <= float(value) <= high), lines[0]  # the printed value itself shows the violation


# ---------------------------------------------------------------- 12. the second pass's one-liners


def _covariance_file(tmp_path: Path, damage: str) -> Path:
    from dvrk_dart.identification.outputs import COVARIANCE_FORMAT
    from dvrk_dart.identification.regressor import parameter_layout, standard_vector

    arm = PSM_ARM
    layout = parameter_layout(arm.model)
    n = len(layout)
    covariance = np.diag(np.full(n, 1e-6))
    if damage == "asymmetric":
        covariance[0, 1] = 1e-7
    else:  # an eigenvalue far below zero
        covariance[0, 0] = -1e-3
    path = tmp_path / f"{damage}.json"
    path.write_text(json.dumps({"format": COVARIANCE_FORMAT, "names": list(layout.names),
                                "nominal": standard_vector(arm.params, layout).tolist(), "covariance": covariance.tolist()}))
    return path


@pytest.mark.parametrize("argv, fragments", [
    (["export", "x", "--bag", "y", "--arm", "PSM 1"], ["--arm", "not an arm's namespace"]),
    (["export", "x", "--bag", "y", "--arm", "/PSM1/"], ["--arm"]),
    (["report", "--runs", "x", "--out", "y", "--jobs", "0"], ["--jobs", "at least 1"]),
    (["uncertainty", "--measured", "two", "--out", "y", "--jobs", "-1"], ["--jobs", "at least 1"]),
])
def test_option_values_are_checked_in_one_line(tmp_path, capsys, argv, fragments):
    code, lines = cli(capsys, *argv)
    assert code == 2 and len(lines) == 1 and "Traceback" not in lines[0], lines
    for fragment in fragments:
        assert fragment in lines[0], lines


@pytest.mark.parametrize("damage, words", [("asymmetric", "not symmetric"), ("indefinite", "not positive semidefinite")])
def test_a_covariance_that_is_no_covariance_is_refused(tmp_path, capsys, damage, words):
    code, lines = cli(capsys, "uncertainty", "--measured", "two", "--samples", "2", "--duration", "0.2",
                      "--params-cov", _covariance_file(tmp_path, damage), "--out", tmp_path / "mc")
    assert_one_line_error(code, lines, "--params-cov", words)
    assert not (tmp_path / "mc").exists()


def test_a_large_relative_std_draws_real_bodies(tmp_path, capsys):
    """The help allows (0, 1): 0.99 draws bodies, projected where they must be, no traceback."""
    from dvrk_dart.identification.sampling import sample_parameters

    drawn = sample_parameters(PSM_ARM, 8, seed=2, relative_std=0.99)
    assert len(drawn.samples) == 8 and drawn.projected_bodies >= 0


def test_a_short_first_period_and_a_folder_for_a_csv_are_refused(tmp_path, capsys):
    short = measured_csv(tmp_path, "short.csv", rows=1300)  # fewer processed samples than one period
    code, lines = cli(capsys, "model-errors", "--measured", short, "--first-period")
    assert_one_line_error(code, lines, "--first-period", "fewer than one period")
    folder = tmp_path / "a_folder"
    folder.mkdir()
    code, lines = cli(capsys, "import", resolve_run("two"), "--out", folder, "--force")
    assert code == 2 and len(lines) == 1


def test_a_report_of_two_folders_holding_one_run_is_refused(tmp_path, capsys, a_run_folder):
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copytree(a_run_folder, runs / "first")
    shutil.copytree(a_run_folder, runs / "second")
    code, lines = cli(capsys, "report", "--runs", runs, "--out", tmp_path / "site")
    assert_one_line_error(code, lines, "hold the same run")


def test_a_user_named_copy_of_a_campaign_run_is_left_out_and_listed(tmp_path, capsys, a_run_folder):
    """`dvrk-dart run spiral --out out/runs/spiral` beside the campaign's own
    out/runs/spiral_velocity_cw-on: the report keeps the folder named after the
    run and lists the other, instead of refusing the whole validation at its end."""
    runs = tmp_path / "runs"
    runs.mkdir()
    name = json.loads((a_run_folder / "config.json").read_text())["run"]
    shutil.copytree(a_run_folder, runs / "mine")
    shutil.copytree(a_run_folder, runs / name)
    code, _ = cli(capsys, "report", "--runs", runs, "--out", tmp_path / "site")
    assert code == 0
    page = (tmp_path / "site" / "index.html").read_text()
    assert f"mine: holds the run {name}, as {runs / name} does: left out" in page


def test_a_cartesian_run_longer_than_its_scenario_is_refused(tmp_path, capsys):
    """`run rectilinear --duration 12` drew the 10 s line on to 0.108 m and named it first-12s."""
    code, lines = cli(capsys, "run", "rectilinear", "--duration", "12", "--out", tmp_path / "d12")
    assert_one_line_error(code, lines, "--duration 12", "rectilinear lasts 10 s")
    assert not (tmp_path / "d12").exists()


def test_a_hand_written_dynamics_file_is_type_checked(tmp_path, capsys):
    """"friction": "false" switched friction on; a 3-angle tilt and a string limit ended in tracebacks."""
    for sim_config, words in (({"friction": "false"}, "sim_config.friction: true or false"),
                              ({"gravity_tilt_rad": [1, 2, 3]}, "sim_config.gravity_tilt_rad: a list of 2 numbers"),
                              ({"closure_residual_limit_m": "x"}, "sim_config.closure_residual_limit_m: not finite numbers"),
                              ({"dt_s": -0.001}, "sim_config.dt_s: above zero"),
                              ({"extra": {"coulomb": [0.1] * 6}}, "sim_config.extra.coulomb: a list of 7 numbers"),
                              ({"bogus": 1}, "unknown key 'bogus'"),
                              # the entries' layouts (an index out of range or a short entry ended in IndexError)
                              ({"extra": {"position_friction": [[9, 1e-4, 0.0, 1.0, 0.1, 0.1]]}}, "its number 1 is a coordinate, 0..6"),
                              ({"extra": {"position_friction": [[1.0]]}}, "increasing knots and as many values"),
                              ({"extra": {"position_load": [[1, 1, 0.5, 0.2, 0.1, 0.1]]}}, "increasing knots"),
                              ({"extra": {"angle_load": [[1.0]]}}, "angle_load: entries of 4 numbers"),
                              ({"extra": {"angle_load": [[1.5, 1, 0.1, 0.0]]}}, "its number 1 is a coordinate"),
                              ({"extra": {"link_friction": [[99, 1.0, 1.0]]}}, "link_friction: entries of 4 numbers"),
                              ({"extra": {"link_mass_scale": [[2.5, 0.1]]}}, "its number 1 is a link's key")):
        dynamics = tmp_path / "d.json"
        dynamics.write_text(json.dumps({"sim_config": sim_config}))
        for command in (["replay", "--duration", "0.2"], ["force"]):
            code, lines = cli(capsys, *command, "--measured", "two", "--dynamics", dynamics, "--out", tmp_path / "never")
            assert_one_line_error(code, lines, "d.json", words)
            assert not (tmp_path / "never").exists()


def test_a_diagnosis_of_another_arm_is_refused(tmp_path, capsys):
    """An MTM diagnosis given to a PSM replay or force estimate ran, its effects on the PSM's joints and links."""
    for recorded, words in (({"units": ["N·m"] * 7}, "a diagnosis of another arm (efforts in N·m"),
                            ({"arm_model": {"name": "dVRK MTM"}}, "a diagnosis of the arm 'dVRK MTM', not of psm.toml's"),
                            ({"sim_config": {"extra": {"link_friction": [[99, 0.1, 0.1, 0.1]]}}},  # force: KeyError 99
                             "sim_config.extra.link_friction names link 99, not a link of psm.toml")):
        dynamics = tmp_path / "d.json"
        dynamics.write_text(json.dumps({"sim_config": {}, **recorded}))
        for command in (["replay", "--duration", "0.2"], ["force"]):
            code, lines = cli(capsys, *command, "--measured", "two", "--dynamics", dynamics, "--out", tmp_path / "never")
            assert_one_line_error(code, lines, "d.json", words)
            assert not (tmp_path / "never").exists()


def test_a_diagnosis_fitted_on_other_parameters_is_said(tmp_path, capsys):
    """--dynamics of a diagnosis with --params other than those it was fitted on ran without a word."""
    dynamics = tmp_path / "d.json"
    dynamics.write_text(json.dumps({"sim_config": {}, "params": {"path": "/elsewhere/params.json", "sha256": "0" * 64}}))
    code, lines = cli(capsys, "replay", "--measured", "two", "--duration", "0.2", "--dynamics", dynamics, "--out", tmp_path / "run")
    assert code == 0 and any("fitted on other identified parameters (params.json, sha256 000000000000...)" in line for line in lines), lines


def test_validate_refuses_a_dynamics_file_of_another_arm_and_a_report_inside_its_out_before_any_run(tmp_path, capsys):
    dynamics = tmp_path / "d.json"
    dynamics.write_text(json.dumps({"sim_config": {"extra": {"link_friction": [[99, 0.1, 0.1, 0.1]]}}}))
    for extra, words in ((["--dynamics", dynamics], "names link 99"), ([], "is inside --out")):
        report = tmp_path / "out" / "runs" if not extra else tmp_path / "report"
        code, lines = cli(capsys, "validate", "--out", tmp_path / "out", "--report", report, *extra)
        assert_one_line_error(code, lines, words)
        assert not (tmp_path / "out").exists()


def test_a_sim_config_reads_back_from_memory_and_from_json():
    from dvrk_dart.sim.config import JointEffects, Payload, SimConfig

    config = SimConfig(extra=JointEffects(position_friction=((2, 1e-4, 0.0, 0.1, 1.0, 2.0),)), payloads=(Payload(2, 0.1, (0.0, 0.0, 0.0)),),
                       counterweight_pid=(1.0, 2.0, 3.0))
    assert SimConfig.from_dict(config.to_dict()) == config
    assert SimConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config

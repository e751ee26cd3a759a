"""Inputs that look fine but are not: the same recording in two roles (under any
name), a baseline of another length, a payload position in millimetres or on
an axis, a band of another recording. Each is refused in one line, or the
right method is chosen and said."""

import os
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dvrk_dart.cli import main
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import distinct_inputs, resolve_run
from arms import PSM

DIAGNOSE_ROLES = ("--measured", "--baseline", "--repeat", "--holdout", "--train")
IDENTIFY_ROLES = ("--runs", "--holdout")
NAMES = st.text(alphabet="abcdé _-0", min_size=1, max_size=10).map(lambda s: s.strip() or "x")


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(roles=st.sampled_from([DIAGNOSE_ROLES, IDENTIFY_ROLES]).flatmap(lambda r: st.lists(st.sampled_from(r), min_size=2, max_size=2)),
       names=st.lists(NAMES, min_size=2, max_size=2, unique=True),
       form=st.sampled_from(["copy", "link", "crlf", "trimmed", "fewer digits"]))
def test_one_recording_in_two_roles_is_refused_whatever_its_names(tmp_path_factory, roles, names, form):
    """Under any name, and however the copy was written (its bytes differ)."""
    folder = tmp_path_factory.mktemp("runs")
    source = resolve_run("two")
    first = folder / f"{names[0]}.csv"
    shutil.copy(source, first)
    second = folder / f"{names[1]}.csv"
    lines = source.read_text().splitlines()
    if form == "link":
        os.symlink(first, second)
    elif form == "crlf":
        second.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    elif form == "trimmed":
        second.write_text("\n".join(lines[37:-11]) + "\n")
    elif form == "fewer digits":
        np.savetxt(second, np.loadtxt(source, delimiter=","), delimiter=",", fmt="%.9g")
    else:
        shutil.copy(source, second)
    with pytest.raises(DvrkDartError, match="the same recording as"):
        distinct_inputs([(roles[0], str(first)), (roles[1], str(second))], PSM)


@pytest.mark.parametrize("argv", [
    ["diagnose", "--measured", "one", "--baseline", "one"],
    ["diagnose", "--measured", "one", "--repeat", "one"],
    ["diagnose", "--measured", "one", "one"],
    ["identify", "--runs", "one", "--holdout", "one"],
])
def test_the_cli_refuses_a_recording_in_two_roles(tmp_path, capsys, argv):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the same recording as" in err[0]
    assert not out.exists()


def test_a_baseline_one_sample_longer_is_still_the_same_motion(arm, tmp_path):
    """Real recordings never have equal lengths: the baseline is put on the
    run's samples (common span) and subtracted, and the output says so."""
    from dvrk_dart.diagnosis.fit.diagnosis_runs import prepare_run

    values = np.loadtxt(resolve_run("one-no-weight"), delimiter=",")
    longer = tmp_path / "baseline_longer.csv"
    np.savetxt(longer, np.vstack([values, values[-1:]]), delimiter=",")
    shifted = tmp_path / "baseline_late.csv"
    np.savetxt(shifted, values[7:], delimiter=",")
    started_late = tmp_path / "baseline_5s_late.csv"  # started 5 s into the periodic motion: aligned a period apart or not
    np.savetxt(started_late, values[1000:], delimiter=",")
    for baseline, expected in ((longer, "from sample 0"), (shifted, "baseline_late from sample 0"), (started_late, "baseline_5s_late from sample")):
        run = prepare_run("one-105g", arm, baseline=str(baseline))
        assert run.role == "difference", baseline
        assert expected in run.baseline_source and "common span" in run.baseline_source
        assert len(run.baseline.state) == len(run.state)
        # the shifted baseline lines up: its positions follow the run's to the recordings' own spread
        assert np.sqrt(np.mean((run.state.q - run.baseline.state.q) ** 2)) < 0.01
    other = prepare_run("one-105g", arm, baseline="two")
    assert other.role == "other_motion" and "Hz" not in other.baseline_source
    # the same motion logged at 100 Hz: upstream does not resample it; read as another motion, and said why (it was silent)
    half_rate = tmp_path / "baseline_100hz.csv"
    table = np.column_stack([np.arange(len(values[::2])) / 100.0, values[::2]])
    header = ",".join(["t"] + [f"{f}{j}" for f in ("q", "dq", "tau") for j in range(1, 8)])
    np.savetxt(half_rate, table, delimiter=",", header=header, comments="")
    slower = prepare_run("one-105g", arm, baseline=str(half_rate))
    assert slower.role == "other_motion" and "logged at 100 Hz, the run at 200 Hz" in slower.baseline_source


@pytest.mark.parametrize("position, words", [
    ("pitch:-165,20,0", "positions are in metres"),
    ("pitch:0,0,0", "not determinable"),
])
def test_a_payload_position_gravity_cannot_use_is_refused(tmp_path, capsys, position, words):
    out = tmp_path / "d"
    assert main(["diagnose", "--measured", "one-105g", "--baseline", "one-no-weight", "--payload-at", position, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert not out.exists()


@settings(max_examples=50, deadline=None)
@given(paths=st.lists(st.lists(st.sampled_from(["a", "b", "run", "x.y"]), min_size=1, max_size=4).map(lambda p: "/".join(p) + ".csv"),
                      min_size=1, max_size=5, unique=True))
def test_two_runs_get_two_labels_whatever_their_folders(paths):
    """a/run.csv and b/run.csv were both 'run' in diagnosis.json (one processing record for both) and in identify's table."""
    from dvrk_dart.io.reference_data import distinct_labels

    labels = distinct_labels([*paths, *(p[:-4] for p in paths[:1]), "two"])  # a bag folder beside its CSV
    assert len(set(labels.values())) == len(labels) and labels["two"] == "two"
    assert all(os.path.basename(path).startswith(label.rsplit("/", 1)[-1]) for path, label in labels.items())

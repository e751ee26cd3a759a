"""A log of another sign or unit than the project's (the dVRK's measured effort, N·m and N) is said, not read as the
arm's error: on every real run the measured efforts' least-squares gain on the model (each less its mean) stays within 0.87-1.93, a
flipped or rescaled log's is -1 or 1000."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dvrk_dart.cli import main
from dvrk_dart.identification.effort_convention import convention_gains, effort_convention_notes
from dvrk_dart.io.reference_data import RUNS, load_run, resolve_run
from dvrk_dart.io.signal import process
from dvrk_dart.io.arm import load_arm
from dvrk_dart.model.description import resolve_arm_model
from arms import PSM_ARM
from recordings import cli_json


@pytest.fixture(scope="module")
def arms():
    return {"psm": PSM_ARM, "mtm": load_arm(resolve_arm_model("mtm"))}


@pytest.mark.parametrize("processing", ["upstream", "periodic"])
def test_no_real_run_reads_as_another_convention(arms, processing):
    for name in RUNS:
        arm = arms["mtm" if name.startswith("mtm") else "psm"]
        run = process(load_run(resolve_run(name), arm.model), processing)
        model = run.in_band(arm.identified.predict(run.q, run.dq, run.ddq))
        assert convention_gains(model, run.tau, run.measured) == {}, name
        flipped = run.tau * np.where(np.arange(run.tau.shape[1]) == 1, -1.0, 1.0)  # q2's sign flipped
        assert set(convention_gains(model, flipped, run.measured)) == {1}, name
        gains = convention_gains(model, run.tau * 1000.0, run.measured)  # mN·m
        assert set(gains) == set(np.flatnonzero(run.measured)) and all(800 < g < 2000 for g in gains.values()), name


def test_model_errors_says_a_flipped_log(tmp_path, capsys):
    rows = np.loadtxt(resolve_run("two"), delimiter=",")
    rows[:, 14:] *= -1.0
    np.savetxt(tmp_path / "flipped.csv", rows, delimiter=",")
    [note] = cli_json(capsys, "model-errors", "--measured", str(tmp_path / "flipped.csv"))["effort_convention_notes"]
    assert "opposite to the model's on q1 (-" in note and "q7 (-" in note
    assert cli_json(capsys, "model-errors", "--measured", "two")["effort_convention_notes"] == []
    assert main(["replay", "--measured", str(tmp_path / "flipped.csv"), "--duration", "2", "--out", str(tmp_path / "replay")]) == 0
    [note] = json.loads((tmp_path / "replay" / "metrics.json").read_text())["effort_convention_notes"]
    assert "opposite to the model's on q1 (-" in note and f"note: {note}" in capsys.readouterr().out
    assert effort_convention_notes(np.ones((5, 7)), np.zeros((5, 7)), np.ones(7, bool)) == []  # nothing measured: no gain


def test_an_offset_or_a_partial_model_is_no_convention(capsys):
    """Each signal less its mean: a still joint's constant against a model's small one is no gain; a model of some
    terms misses the others' efforts by any gain, so model-errors says nothing of it; the answer opens with the note."""
    from dvrk_dart.diagnosis.output.answer import _caution

    t = np.linspace(0.0, 10.0, 2000)[:, None]
    model, recorded = np.hstack([0.002 + 0.001 * np.sin(t), np.sin(t)]), np.ones(2, bool)
    rng = np.random.default_rng(0)
    assert convention_gains(model, np.hstack([0.05 + 0.005 * rng.standard_normal(t.shape), np.sin(t)]), recorded) == {}
    assert convention_gains(model, np.hstack([model[:, :1], -np.sin(t)]), recorded).keys() == {1}
    # noise where the model has friction (a DART run's wrist): a gain of ~0.001, and no convention
    assert convention_gains(model, np.hstack([model[:, :1], 0.002 * rng.standard_normal(t.shape)]), recorded) == {}
    assert cli_json(capsys, "model-errors", "--measured", "two", "--terms", "gravity")["effort_convention_notes"] == []
    words = _caution({"effort_convention_notes": ["x: the measured efforts run opposite"], "unrecorded_joint_notes": []})
    assert words == "First: x: the measured efforts run opposite. No effect of the arm explains that."


def test_identify_warns_of_a_flipped_training_run():
    """identify's warning, on a processed real run and its copy with q3's sign flipped (no fit needed to say it)."""
    from dataclasses import replace
    from types import SimpleNamespace

    from dvrk_dart.identification.identify import IdentificationResult

    run = process(load_run(resolve_run("2018-test1"), PSM_ARM.model), "periodic")
    flipped = replace(run, tau=run.tau * np.where(np.arange(run.tau.shape[1]) == 2, -1.0, 1.0))
    result = SimpleNamespace(reference_model=PSM_ARM.identified,
                             train=[SimpleNamespace(name="test1", processed=run), SimpleNamespace(name="flipped", processed=flipped)])
    [warning] = IdentificationResult.effort_convention_warnings(result)
    assert warning.startswith("flipped: the measured efforts run opposite to the model's on q3 (-")

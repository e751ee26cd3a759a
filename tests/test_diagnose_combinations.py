"""No traceback for any combination of diagnose's options (--baseline,
--processing, --payload-at, --repeat, --holdout): short periodic runs made
in DART (a friction of 0.25 N·m on q2 in the measured run, none in its
baseline and repeat), walked through a set of combinations that covers every
pair of option values. A result (a one-line refusal for --payload-at without
a baseline), never a traceback; each run is its own recording (its own
noise on efforts and positions), so no role is refused as a copy of another."""

import itertools
import json
import sys
from dataclasses import replace

import numpy as np
import pytest

sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent))
from test_periodic_designs import EFFORT_NOISE, POSITION_NOISE, design_run  # noqa: E402

from dvrk_dart.cli import main  # noqa: E402
from dvrk_dart.runs.replay import simulate_efforts  # noqa: E402
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS, JointEffects  # noqa: E402
from arms import PSM_ARM

MOVING = np.array([True, True, True, False, False, False, False])
FRICTION_Q2_N_M = 0.25


def _write(path, state, efforts, seed):
    """A recording: the measured noise on its efforts and on the moving joints' positions (its own
    session: two recordings of one motion never agree sample for sample, and are not refused as one)."""
    rng = np.random.default_rng(seed)
    q = state.q + rng.standard_normal(state.q.shape) * POSITION_NOISE * MOVING
    np.savetxt(path, np.hstack([q, state.dq, efforts + rng.standard_normal(efforts.shape) * EFFORT_NOISE]), delimiter=",")
    return str(path)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("combinations")
    arm = PSM_ARM
    state, base = design_run(arm, 2, 0.5, 5, MOVING, 200.0, 11)
    friction = replace(IDENTIFIED_PHYSICS, extra=JointEffects(coulomb=(0.0, FRICTION_Q2_N_M) + (0.0,) * 5))
    other, other_base = design_run(arm, 2, 0.45, 5, MOVING, 200.0, 12)
    return {"measured": _write(folder / "measured.csv", state, simulate_efforts(arm, friction, state), 1),
            "baseline": _write(folder / "baseline.csv", state, base, 2),
            "repeat": _write(folder / "repeat.csv", state, base, 3),
            "holdout": _write(folder / "holdout.csv", other, simulate_efforts(arm, friction, other), 4),
            "folder": folder}


OPTIONS = {"baseline": (False, True), "processing": ("upstream", "periodic"), "payload_at": (False, True),
           "repeat": (False, True), "holdout": (False, True)}


def _covering_pairs() -> list[dict]:
    """Combinations that hold every pair of option values at least once (greedy)."""
    names = list(OPTIONS)
    wanted = {((a, va), (b, vb)) for a, b in itertools.combinations(names, 2) for va in OPTIONS[a] for vb in OPTIONS[b]}
    chosen = []
    candidates = [dict(zip(names, values)) for values in itertools.product(*OPTIONS.values())]
    while wanted:
        best = max(candidates, key=lambda c: len({p for p in wanted if all(c[k] == v for k, v in p)}))
        chosen.append(best)
        wanted -= {p for p in wanted if all(best[k] == v for k, v in p)}
    return chosen


@pytest.mark.parametrize("combination", _covering_pairs(), ids=lambda c: "-".join(f"{k}={v}" for k, v in c.items()))
def test_every_combination_ends_in_a_result_or_one_line(runs, combination, capsys, tmp_path):
    args = ["diagnose", "--measured", runs["measured"], "--out", str(tmp_path / "out"), "--processing", combination["processing"],
            "--jobs", "1"]
    for option in ("baseline", "repeat", "holdout"):
        if combination[option]:
            args += [f"--{option}", runs[option]]
    if combination["payload_at"]:
        args += ["--payload-at", "pitch:-0.165,0.02,0"]
    code = main(args)
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    if combination["payload_at"] and not combination["baseline"]:  # the combinations the options refuse, in one line
        assert code == 2 and len(captured.err.strip().splitlines()) == 1 and "--payload-at" in captured.err, captured.err
        return
    if combination["baseline"] and combination["holdout"]:  # a held-out run of another motion than the baseline's
        errors = [line for line in captured.err.strip().splitlines() if "note:" not in line]  # the notes on the runs come first
        assert code == 2 and len(errors) == 1 and "--holdout" in errors[0] and "another motion" in errors[0], captured.err
        assert not (tmp_path / "out" / "diagnosis.json").exists()
        return
    assert code == 0, captured.err  # every other combination is diagnosed
    result = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert result["explanation"]["words"] in ("mostly explained", "partly explained", "not explained")
    assert result["effort_scale_rival"] is None  # a friction change is not read as a scale of the efforts
    assert (tmp_path / "out" / "diagnosis.html").is_file()
    if combination["payload_at"]:  # a friction change, no weight: no payload, and the position says why it reads none
        assert result["payload"] is None and (result["payload_not_distinguished"] or result["payload_at_unused"]), result["payload"]


def test_a_payload_between_two_three_joint_logs_is_named_on_its_link(tmp_path):
    """9-column logs (q1..q3 recorded, the wrist held) of one motion, one with 0.2 kg on the insertion carriage
    (near its frame: 30 cm along the shaft, where the tool's frame is, the efforts choose the tool's link),
    diagnosed against the other on the harmonics without a --repeat: the joints not recorded had infinite weights
    in the payload fit (an eigensolver's traceback), and the link comparison counted the payload's own efforts as
    session scatter, so every link fitted as well and the answer read it on yaw."""
    from dvrk_dart.sim.config import Payload

    state, base = design_run(PSM_ARM, 2, 0.5, 5, MOVING, 200.0, 11)
    loaded = simulate_efforts(PSM_ARM, replace(IDENTIFIED_PHYSICS, payloads=(Payload(8, 0.2, (0.02, -0.03, 0.02)),)), state)
    paths = {}
    for name, efforts, seed in (("loaded", loaded, 1), ("baseline", base, 2)):
        rng = np.random.default_rng(seed)
        q = state.q[:, :3] + rng.standard_normal((len(state), 3)) * POSITION_NOISE[:3]
        tau = efforts[:, :3] + rng.standard_normal((len(state), 3)) * EFFORT_NOISE[:3]
        paths[name] = tmp_path / f"{name}.csv"
        np.savetxt(paths[name], np.hstack([q, state.dq[:, :3], tau]), delimiter=",")
    out = tmp_path / "diagnosis"
    assert main(["diagnose", "--measured", str(paths["loaded"]), "--baseline", str(paths["baseline"]), "--processing", "periodic",
                 "--out", str(out), "--jobs", "1"]) == 0
    payload = json.loads((out / "diagnosis.json").read_text())["payload"]
    assert payload["group"] == "insertion", payload["link"]
    assert payload["mass_kg"] == pytest.approx(0.2, rel=0.2)


def test_a_scale_of_the_measured_efforts_is_weighed_when_asked(tmp_path):
    """Every effort of a run read 8 % high against the same motion (a configuration's effort scale changed between
    them): with --effort-scale the scale is the finding, at its size; without it, no scale is a candidate, and where
    the effects selected instead explain no more than the scale alone, the answer says so. Beside a run of another
    motion, which the baseline's measured efforts do not describe, a one-line refusal."""
    state, base = design_run(PSM_ARM, 2, 0.5, 5, MOVING, 200.0, 11)
    paths = {name: _write(tmp_path / f"{name}.csv", state, efforts, seed) for name, efforts, seed in
             (("scaled", base * 1.08, 1), ("baseline", base, 2))}
    for flag in ([], ["--effort-scale"]):
        out = tmp_path / f"out{len(flag)}"
        assert main(["diagnose", "--measured", paths["scaled"], "--baseline", paths["baseline"], "--processing", "periodic",
                     "--out", str(out), "--jobs", "1", *flag]) == 0
        result = json.loads((out / "diagnosis.json").read_text())
        effects, rival = result["effects"], result["effort_scale_rival"]
        if flag:
            assert effects[0]["name"] == "effort_scale" and effects[0]["size"] == pytest.approx(0.08, abs=0.01), effects[0]
        else:
            assert not [e for e in effects if e["kind"] == "effort_scale"]
            assert len([e for e in effects if e["selected"]]) > 1  # several effects for one scale: the answer names it
            assert rival["scale_error"] == pytest.approx(0.08, abs=0.01) and "--effort-scale" in rival["words"], rival
    other, other_efforts = design_run(PSM_ARM, 2, 0.45, 5, MOVING, 200.0, 12)
    code = main(["diagnose", "--measured", paths["scaled"], _write(tmp_path / "other.csv", other, other_efforts, 3), "--baseline",
                 paths["baseline"], "--effort-scale", "--out", str(tmp_path / "mixed"), "--jobs", "1"])
    assert code == 2 and not (tmp_path / "mixed").exists()

"""The session-to-session floor, and a joint's gap split by what explains it.

Two recordings of the same trajectory in different sessions (`one_results.csv`
and `one_no_weight_results.csv`) differ by what changes from day to day
(cable tension, temperature, the controller's offsets ...). A fixed effect,
the same in every session, cannot explain that difference: with independent
session deviations of RMS s, the two runs differ by RMS s sqrt(2), so
s = RMS(tau_A - tau_B) / sqrt(2) per joint bounds from below what any fixed
effect leaves of a run's gap.

A joint's gap (RMS before) is split in energy: explained by the selected
effects (before^2 - after^2), session-to-session (the part of after^2 up to
s^2), and left over (the rest), each reported as an RMS-equivalent sqrt.

The same pair tells on which joints a session moves the constant effort
(`session_offset_joints`). On those, each run of a study has its own offset,
a nuisance term; on the others (J1 of the upstream arm: 0.001 N·m between
sessions) a constant change of the effort belongs to the effects: a payload's
J1 effort at q = 0 is then determined.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.fit.diagnosis_runs import DiagnosisRun, RunProcessing, RunRole, loaded_states, motion_offset, on_rate, same_motion
from dvrk_dart.io.measured_run import EFFORT_RESOLUTION
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import RUNS, manifest, resolve_run, run_label, sha256_of
from dvrk_dart.io.signal import not_comparable_sample_by_sample
from dvrk_dart.metrics import constant_move_bound, moved_constants, moves_ruled_out, rms
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES



def session_floor(a: DiagnosisRun, b: DiagnosisRun, constant_joints: np.ndarray | None = None) -> np.ndarray:
    """Per-joint RMS of one session's deviation, from two runs of the same
    motion (`constant_joints`: where a diagnosis fits each run's constant, the
    difference's mean is no part of the floor)."""
    pair = paired_gaps(a, b)
    if pair is None:
        raise DvrkDartError(_not_a_repeat(a.name, b.name))
    difference = pair[0] - pair[1]
    if constant_joints is not None:
        difference = difference - np.asarray(constant_joints, dtype=float) * difference.mean(axis=0)
    return rms(difference) / math.sqrt(2.0)


def _not_a_repeat(reference: str, repeat: str) -> str:
    return f"--repeat {repeat}: not the same motion as {reference} (a repeat is the same trajectory at the same speed)"


def check_repeat_motion(reference, repeat, model: PsmModel, processing: RunProcessing, rate_hz: float | None, aligned: bool) -> None:
    """--repeat records the reference run's motion (checked on the processed runs, before any replay; `aligned`:
    the repeat is put on the reference's samples, a baseline's, so it may start elsewhere)."""
    if not all(isinstance(spec, (str, Path)) for spec in (reference, repeat)):
        return
    a, b = (on_rate(state, rate_hz) for state in loaded_states([reference, repeat], model, processing))
    if not aligned and (why := not_comparable_sample_by_sample(a, b)):
        raise DvrkDartError(f"--repeat {run_label(repeat)}: {why}")
    n = min(len(a), len(b))
    if not (motion_offset(a, b) is not None if aligned else same_motion(a.head(n), b.head(n))):
        raise DvrkDartError(_not_a_repeat(run_label(reference), run_label(repeat)))


def paired_gaps(a: DiagnosisRun, b: DiagnosisRun) -> tuple[np.ndarray, np.ndarray] | None:
    """The two runs' gaps on their common samples where they record the same motion, else None (a repeat
    logged at another rate and put on the runs' may be a sample shorter; one put on a baseline's samples,
    which may start elsewhere in the motion, is paired as it was aligned)."""
    for run, other, swap in ((b, a, False), (a, b, True)):  # a repeat already put on the other's samples as its baseline
        if run.role is RunRole.DIFFERENCE and run.baseline.name == other.name:
            return (run.gap, run.baseline.gap) if swap else (run.baseline.gap, run.gap)
    n = min(len(a.state), len(b.state))
    if not same_motion(a.state.head(n), b.state.head(n)):
        return None
    return a.gap[:n], b.gap[:n]


def session_offset_joints(model: PsmModel, repeat: DiagnosisRun | None, reference: DiagnosisRun) -> tuple[np.ndarray, str]:
    """(per-joint mask, where it comes from) of the joints whose constant effort
    moves between sessions: those `repeat` shows moved against `reference`
    (the same motion in another session), and the model card's [sessions]
    unless the repeat rules out a move of the card's size there
    (`constant_change`); without either, all. A short pair misses a small move
    (the card's q3, 0.008 N: 4 standard errors on its 30 s pair, under 2 on
    the blind suite's 13 s ones), and a session's constant left to the effects
    bends them (a counterweight payload took it; the suite's parallelogram
    payload, with a --repeat, was missed)."""
    pair = paired_gaps(repeat, reference) if repeat is not None else None
    card = None if model.session_offset_joints is None else np.isin(JOINT_NAMES, model.session_offset_joints)
    if pair is None:
        if card is None:
            return np.ones(len(JOINT_NAMES), dtype=bool), "all joints (no --repeat, no [sessions] in the model card)"
        return card, "model card [sessions]"
    difference = pair[0] - pair[1]
    measured = moved_constants(difference, reference.state.rate_hz)
    source = f"measured: {repeat.name} vs {reference.name}"
    if card is None:
        return measured, source
    kept = card & ~moves_ruled_out(difference, reference.state.rate_hz, model.session_constant_change)
    return measured | kept, f"{source}, and the model card's [sessions] where the pair does not rule out their move"


#: a run's constant against its baseline (its nuisance offset) over this many times the constant change the repeat
#: pair shows between sessions is more than a session's change: it is said, not silently taken out
BEYOND_SESSION_FACTOR = 2.0


def constants_beyond_session(offsets: dict | None, runs: list[DiagnosisRun], repeat: DiagnosisRun | None,
                             reference: DiagnosisRun, model: PsmModel, units: list[str], expected: list[float] | None = None) -> list[dict]:
    """The nuisance offsets of `runs` that a session's change does not reach:
    the mean of `repeat` - `reference` (the same motion in two sessions) on
    that joint, else the model card's `[sessions] constant_change`, times
    BEYOND_SESSION_FACTOR. Runs minus their baseline are read against zero;
    runs of their own against `expected` (the identified offsets the simulation
    leaves out, else zero), their scale at least their constants' own spread
    (2019's "one" and "two": q3 +0.004 and -0.021 N, which the card's 0.008
    alone called a constant beyond a session's change). Such a constant may be part of an effect (a load, a
    payload's mean gravity) or a changed offset that the nuisance term took
    out: a J2 load of +0.125 N·m beside a session change of 0.03, and a J3
    offset changed by 0.35 N, were read 'no effect selected', with no word (two
    runs of their own: 'J3's own friction refitted ... carries', no word)."""
    if not offsets or not runs:
        return []
    pair = paired_gaps(repeat, reference) if repeat is not None else None
    if pair is not None:
        session, source = _pair_session_change(pair[0] - pair[1], reference.state.rate_hz, model), "the repeat pair"
    elif model.session_constant_change is not None:
        session, source = np.asarray(model.session_constant_change), "the model card's repeat pair"
    else:
        return []
    own = any(run.role is not RunRole.DIFFERENCE for run in runs)
    against = np.asarray(expected if own and expected is not None else np.zeros(len(JOINT_NAMES)), dtype=float)
    if own:  # runs of their own differ by their motions' mean errors too: their constants' own spread is a change as well
        table = np.array([[(offsets.get(run.name) or {}).get(joint, 0.0) for joint in JOINT_NAMES] for run in runs])
        session, source = np.maximum(session, np.ptp(table, axis=0)), f"{source} (or the runs' own spread, where larger)"
    return [{"run": run.name, "joint": joint, "offset": value, "against": "the identified offset" if own else "the baseline",
             "expected": float(against[j]), "session_change": float(session[j]), "session_change_source": source, "unit": units[j]}
            for run in runs for j, joint in enumerate(JOINT_NAMES)
            if (value := (offsets.get(run.name) or {}).get(joint, 0.0)) != 0.0
            and abs(value - against[j]) > max(BEYOND_SESSION_FACTOR * session[j], EFFORT_RESOLUTION)]  # 6e-5 N·m was "beyond"


def _pair_session_change(difference: np.ndarray, rate_hz: float, model: PsmModel) -> np.ndarray:
    """The constant change a repeat pair shows per joint; on the card's joints it does not show moved (a short pair's
    mean is noise there: a 13 s pair's q3 read 0.006 N against the card's 0.008), what it cannot rule out: the larger
    of its mean's bound and the card's change."""
    change = np.abs(difference.mean(axis=0))
    if model.session_offset_joints is None or model.session_constant_change is None:
        return change
    unseen = np.isin(JOINT_NAMES, model.session_offset_joints) & ~moved_constants(difference, rate_hz)
    return np.where(unseen, np.maximum(constant_move_bound(difference, rate_hz), model.session_constant_change), change)


def gap_split(before: np.ndarray, after: np.ndarray, floor: np.ndarray | None, model: PsmModel) -> list[dict]:
    """Per joint: the gap before, split into explained, session-to-session, left over (RMS-equivalents)."""
    rows = []
    for j, joint in enumerate(JOINT_NAMES):
        b2, a2 = float(before[j]) ** 2, float(after[j]) ** 2
        session2 = min(a2, float(floor[j]) ** 2) if floor is not None else None
        row = {"joint": joint, "unit": model.effort_unit(joint), "before": float(before[j]), "after": float(after[j]),
               "explained": math.sqrt(max(b2 - a2, 0.0)), "session_to_session": None, "left_over": None}
        if session2 is not None:
            row["session_to_session"] = math.sqrt(session2)
            row["left_over"] = math.sqrt(max(a2 - session2, 0.0))
            row["session_floor"] = float(floor[j])
        rows.append(row)
    return rows


#: a gap within this multiple of the session floor is what a session's change alone can leave: no share of it is counted
AT_FLOOR_RATIO = 1.5


def above_floor(gap, floor):
    """The RMS-equivalent of a gap above the session floor, sqrt(gap^2 - floor^2) (0 at or below it)."""
    gap, floor = np.asarray(gap, dtype=float), np.asarray(floor, dtype=float)
    return np.sqrt(np.maximum(np.square(gap) - np.square(floor), 0.0))


def repeatable_share(before, after, floor):
    """The share of a gap's repeatable part (above the session floor) that is
    gone after, per joint: 1 - above_floor(after) / above_floor(before), in
    RMS-equivalents as the diagnosis's words weigh it (output/wording.py);
    NaN where no repeatable gap is shown: the gap before within AT_FLOOR_RATIO
    of the floor, which a session's change alone can leave (a joint at 1.34x
    its floor read "100 % removed" once the effects took it under the floor)."""
    before = np.asarray(before, dtype=float)
    repeatable, left = above_floor(before, floor), above_floor(after, floor)
    shown = before > AT_FLOOR_RATIO * np.asarray(floor, dtype=float)
    return np.where(shown, 1.0 - left / np.where(shown, repeatable, 1.0), np.nan)


def card_repeat(model: PsmModel, baseline, given_runs: list) -> tuple[str | None, str]:
    """(the --repeat the model card gives a baseline, where it comes from): a
    baseline that is one of [sessions] repeat_pair's files (by content) gets
    the other, unless that one is among the runs given (then it is no second
    session of them); else None and why."""
    pair = model.session_repeat_pair
    files = manifest()["files"]
    digests = {name: files[name]["sha256"] for name in pair if name in files}
    if len(digests) != 2:
        return None, "none: no --repeat, and the model card names no repeat pair"
    if not isinstance(baseline, (str, Path)):
        return None, "none: no --repeat, and the baseline is no file to compare with the model card's repeat pair"
    specs = [part for spec in given_runs for part in (spec if isinstance(spec, tuple) else (spec,))]  # (run, its baseline) pairs too
    given = {sha256_of(resolve_run(spec)) for spec in specs if isinstance(spec, (str, Path))}
    mine = sha256_of(resolve_run(baseline))
    for name, other in zip(pair, reversed(pair)):
        if digests[name] != mine:
            continue
        if digests[other] in given:
            return None, f"none: no --repeat, and the model card's repeat pair's other run ({other}) is among the runs studied"
        shorthand = next((short for short, file in RUNS.items() if file == other), other)
        return shorthand, f"the model card's repeat pair ([sessions] repeat_pair: {name} and {other}, one motion in two sessions)"
    return None, "none: no --repeat, and the baseline is not one of the model card's repeat pair"

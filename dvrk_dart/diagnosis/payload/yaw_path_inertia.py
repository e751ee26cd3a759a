"""How far a payload's J1 figures rest on the inertia its path to J1 is given.

J1 sees a payload through a first moment of its own, the yaw path
(`first_moment`): the model's geometry does not hold on J1. The upstream fit
gives that path no inertia (a hand position: the model geometry's inertia per
kg); the periodic fit gives it a rigid body's (`periodic_payload`). A payload's
inertia has centripetal efforts whose mean on J1 a path without inertia reads
as gravity (0.2 kg on the pitch link: -0.02 N·m, tests/test_diagnosis.py). On
the real 105 g pitch-link runs (one-105g minus one-no-weight) the two models
fit J1 about as well (0.015 / 0.013 N·m RMS left) and read its gravity effort
at q = 0 as -0.043 and -0.007 N·m: the upstream and periodic diagnoses of that
run gave -0.035 [-0.037, -0.033] and -0.003 [-0.026, +0.019], neither interval
holding the other's value. The runs do not tell the two models apart, so every
J1 figure's interval spans both: the other model's reading is the figure moved
by the difference of the two models' J1-only fits (`path_inertia_shift`).
"""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.effects.features import BODY_PARAMETERS, FIRST_MOMENT_COLUMNS
from dvrk_dart.diagnosis.effects.geometry import joints_moving_link
from dvrk_dart.diagnosis.fit.diagnosis_runs import RunRole
from dvrk_dart.diagnosis.fit.design import WITHHELD_KINDS
from dvrk_dart.diagnosis.payload.first_moment import YAW_PATH_JOINT
from dvrk_dart.diagnosis.payload.identifiable import _gravity_at_zero, _yaw_slope
from dvrk_dart.model.joints import JOINT_NAMES

#: the J1 figures a path gives: (report key, index in it or None for a scalar)
J1_PATH_FIGURES = (("gravity_efforts_at_q0", YAW_PATH_JOINT), ("q1_gravity_slope_at_q0_nm_per_rad", None))
#: which path model each processing's fit gives the payload (the other is the one its intervals must also span)
FIRST_MOMENT_PATH, RIGID_PATH = "first_moment", "rigid"


def j1_targets(problem, params: dict) -> list[tuple]:
    """Per training run whose J1 efforts carry the path (the runs minus their baseline, else the runs of their
    own; none beside a baseline of another motion, where J1's figures are not determined): its J1 gap with
    every selected effect but the payloads taken out, its features, the run."""
    runs = [r for r in problem.train_runs if r.role is RunRole.DIFFERENCE] or [r for r in problem.train_runs if r.role is RunRole.RAW]
    design = problem.design
    beta = np.zeros(design.n_columns)
    for i, p in params.items():
        if problem.effects[i].kind not in WITHHELD_KINDS:
            beta[design.slices[i]] = problem.effects[i].coefficients(p)
    return [(_j1_gap(problem, r) - problem.columns_of(r)[:, YAW_PATH_JOINT, :] @ beta, problem.features_of(r), r) for r in runs]


def _j1_gap(problem, run) -> np.ndarray:
    """A run's J1 gap; upstream, a run minus its baseline's measured efforts alone: the simulated difference of
    one motion is its two states' noise through the differentiated accelerations (0.059 N·m RMS on J1 for
    one-105g), which a rigid path's inertia fits (it read J1 at q = 0 as -0.067 N·m there, -0.007 without it)."""
    if run.role is RunRole.DIFFERENCE and run.state.periodic is None:
        return run.state.tau[:, YAW_PATH_JOINT] - run.baseline.state.tau[:, YAW_PATH_JOINT]
    return problem.before_residual(run)[:, YAW_PATH_JOINT]


def _body_rows(key: int, targets: list) -> np.ndarray:
    """(N, 10) J1's efforts per unit dynamic parameter of a body on link `key` over the runs, in their band."""
    return np.concatenate([run.state.in_band(features.body_regressor[:, :, features.body_columns(key)])[:, YAW_PATH_JOINT, :]
                           for _, features, run in targets])


def _path_reading(gravity: np.ndarray, X: np.ndarray, effort: np.ndarray) -> dict[str, float]:
    """J1's figures of the path whose columns `X` fit `effort` (a column J1 never feels left out)."""
    seen = np.abs(X).max(axis=0) > 0.0  # (the link's mass on the yaw axis)
    path = np.zeros(X.shape[1])
    path[seen] = np.linalg.lstsq(X[:, seen], effort, rcond=None)[0]
    moment = path[:FIRST_MOMENT_COLUMNS]
    return {"gravity_efforts_at_q0": float(gravity[0, YAW_PATH_JOINT, :FIRST_MOMENT_COLUMNS] @ moment),
            "q1_gravity_slope_at_q0_nm_per_rad": float(_yaw_slope(gravity, moment))}


def rigid_path_shift(arm, key: int, targets: list) -> dict[str, float]:
    """J1's figures read by a rigid path on link `key` minus those read by a path without inertia, each fitted
    alone to the runs' J1 gaps (`j1_targets`)."""
    rows, gap, gravity = _body_rows(key, targets), np.concatenate([t for t, _, _ in targets]), _gravity_at_zero(arm, key)
    rigid, bare = (_path_reading(gravity, rows[:, :n], gap) for n in (BODY_PARAMETERS, FIRST_MOMENT_COLUMNS))
    return {name: rigid[name] - bare[name] for name in rigid}


def point_inertia_shift(arm, effect, p: np.ndarray, targets: list) -> dict[str, float]:
    """What a path without inertia reads of a first-moment payload's own inertia (a point mass's, tied to its
    (m, m c)), taken off: the J1 figures if the payload's inertia reaches J1 as the model's geometry says."""
    rows, gravity = _body_rows(effect.link_key, targets), _gravity_at_zero(arm, effect.link_key)
    inertia = rows[:, FIRST_MOMENT_COLUMNS:] @ effect.coefficients(p)[FIRST_MOMENT_COLUMNS:BODY_PARAMETERS]
    return {name: -value for name, value in _path_reading(gravity, rows[:, :FIRST_MOMENT_COLUMNS], inertia).items()}


def span_readings(report: dict, shifts: dict[str, dict[str, float]], own: str) -> bool:
    """Every J1 figure's interval in `report` also holds the other models' readings (the figure moved by each
    shift); the shifts are recorded. Whether an interval grew."""
    grew = False
    for name, index in J1_PATH_FIGURES:
        value = report.get(name) if index is None else (report.get(name) or [None] * (index + 1))[index]
        intervals = report.get(f"{name}_interval")
        interval = intervals if index is None else (intervals or [None] * (index + 1))[index]
        if value is None or interval is None:
            continue
        others = [value + shift[name] for shift in shifts.values()]
        spanned = [float(min(interval[0], *others)), float(max(interval[1], *others))]
        grew |= spanned != [float(interval[0]), float(interval[1])]
        if index is None:
            report[f"{name}_interval"] = spanned
        else:
            report[f"{name}_interval"][index] = spanned
    report["yaw_path_models"] = {"fitted": own, "other_readings_minus_fitted": shifts}
    return grew


def path_words(moved: list[tuple[str, dict[str, dict[str, float]]]], unit: str) -> str:
    """The sentence that says J1's figures span the path models, where it moved them (`moved`: where, shifts)."""
    moves = "; ".join(f"{where}, {model}: {shift['gravity_efforts_at_q0']:+.3f} {unit}"
                      for where, shifts in moved for model, shift in shifts.items())
    return (f"J1's figures rest on the inertia given to the payload's own path to J1, which these runs do not determine: "
            f"J1's effort at q = 0 moves with it ({moves}); the intervals of J1's figures hold every reading.")


def span_both_path_models(problem, params: dict, reports: list[dict], at_key: int | None, own: str,
                          payloads: list[int] | None = None) -> None:
    """Each payload report's J1 figures, and its hand position's, span the path models (module docstring):
    the other of a rigid path and none, and for a first moment fitted with none (`payloads`: each report's
    effect index), its own inertia as a point mass's. A payload J1 alone sees (on the yaw link) has its own
    inertia on J1, no path: left as it is."""
    targets = j1_targets(problem, params)
    if not targets:
        return
    sign = 1.0 if own == FIRST_MOMENT_PATH else -1.0
    for n, report in enumerate(reports):
        parts = [(report, report.get("link_key"))] + ([(report["payload_at"], at_key)] if report.get("payload_at") else [])
        parts = [(part, key) for part, key in parts
                 if key is not None and joints_moving_link(problem.arm.model, key) != (JOINT_NAMES[YAW_PATH_JOINT],)]
        moved = []
        for part, key in parts:
            rigid = rigid_path_shift(problem.arm, key, targets)
            shifts = {"a rigid path" if own == FIRST_MOMENT_PATH else "a path without inertia": {f: sign * v for f, v in rigid.items()}}
            if part is report and payloads is not None:  # a first moment fitted with a path without inertia
                shifts["its inertia as a point mass's"] = point_inertia_shift(problem.arm, problem.effects[payloads[n]], params[payloads[n]], targets)
            if span_readings(part, shifts, own):
                moved.append(("the payload-shaped fit" if part is report else "at the hand position", shifts))
        if moved:
            report.setdefault("words", []).append(path_words(moved, problem.arm.model.effort_unit(JOINT_NAMES[YAW_PATH_JOINT])))

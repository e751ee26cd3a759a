"""How far a payload's J1 figures rest on the inertia its path to J1 is given.

J1 sees a payload through a first moment of its own, the yaw path
(`first_moment`): the model's geometry does not hold on J1. Its inertia is a
choice the runs do not settle: the upstream first moment gives the path none;
upstream, a hand position gives it the point's inertia as the model's geometry
has it; the periodic fit gives it a free rigid body's (`periodic_payload`). A
payload's inertia has centripetal efforts whose mean on J1 a path without
inertia reads as gravity (205 g in the pitch plane, synthetic: -0.009 N·m
where gravity gives none, its interval holding zero in 0 of 8 pairs). On the
real 105 g pitch-link runs the upstream and periodic diagnoses read J1 at
q = 0 at the hand position as -0.035 [-0.037, -0.033] and -0.003
[-0.026, +0.019] N·m, neither interval holding the other's value.

So each J1 figure's interval also holds what the other models read
(`path_readings`: each fitted alone to the runs' J1 gaps, on the payload's
link and on its equivalent and tied links, between which the readings differ
as much as between the models), the figure moved by their difference from
its own model's reading.
The shifts compare fits on one target (the J1 gap less the other selected
effects), not the diagnosis's own fit of it.
"""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.effects.features import FIRST_MOMENT_COLUMNS
from dvrk_dart.diagnosis.effects.geometry import joints_moving_link
from dvrk_dart.diagnosis.fit.diagnosis_runs import RunRole
from dvrk_dart.diagnosis.fit.design import WITHHELD_KINDS
from dvrk_dart.diagnosis.effects.first_moment import YAW_PATH_JOINT
from dvrk_dart.diagnosis.payload.identifiable import _gravity_at_zero, _yaw_slope, j1_sentences
from dvrk_dart.diagnosis.payload.payload_report import renew_sentences
from dvrk_dart.diagnosis.payload.periodic_payload_report import j1_sentences as periodic_j1_sentences
from dvrk_dart.diagnosis.effects.payload import point_mass_parameters
from dvrk_dart.model.body_regressor import BODY_PARAMETERS
from dvrk_dart.model.joints import JOINT_NAMES

#: the J1 figures a path gives: (report key, index in it or None for a scalar)
J1_PATH_FIGURES = (("gravity_efforts_at_q0", YAW_PATH_JOINT), ("q1_gravity_slope_at_q0_nm_per_rad", None))
#: the path models (`path_readings`)
RIGID_PATH, BARE_PATH, POINT_INERTIA = "a rigid path", "a path without inertia", "the payload's inertia as a point mass's"


def j1_targets(problem, params: dict) -> list[tuple]:
    """Per training run whose J1 efforts carry the path (the runs minus their baseline, else the runs of their
    own; none beside a baseline of another motion, where J1's figures are not determined): its J1 gap with
    every selected effect but the payloads taken out, its features, the run, and whether the fit takes a
    constant out of its J1 (then the readings do too)."""
    runs = [r for r in problem.train_runs if r.role is RunRole.DIFFERENCE] or [r for r in problem.train_runs if r.role is RunRole.RAW]
    design = problem.design
    beta = np.zeros(design.n_columns)
    for i, p in params.items():
        if problem.effects[i].kind not in WITHHELD_KINDS:
            beta[design.slices[i]] = problem.effects[i].coefficients(p)
    targets = []
    for run in runs:
        demean = problem.demean_of(run)
        targets.append((_j1_gap(problem, run) - problem.columns_of(run)[:, YAW_PATH_JOINT, :] @ beta, problem.features_of(run), run,
                        bool(demean is not None and demean[YAW_PATH_JOINT])))
    return targets


def _j1_gap(problem, run) -> np.ndarray:
    """A run's J1 gap; upstream, a run minus its baseline's measured efforts alone: the simulated difference of
    one motion is its two states' noise through the differentiated accelerations (0.059 N·m RMS on J1 for
    one-105g), which a rigid path's inertia fits (it moved J1 at q = 0 by -0.027 N·m there, +0.030 without it)."""
    if run.role is RunRole.DIFFERENCE and run.state.periodic is None:
        return run.state.tau[:, YAW_PATH_JOINT] - run.baseline.state.tau[:, YAW_PATH_JOINT]
    return problem.before_residual(run)[:, YAW_PATH_JOINT]


def _stacked(key: int, targets: list) -> tuple[np.ndarray, np.ndarray]:
    """(N, 10) J1's efforts per unit dynamic parameter of a body on link `key` and (N,) the J1 gaps, over the
    runs in their band, each run's mean taken out where the fit takes a constant out of its J1."""
    rows, gaps = [], []
    for gap, features, run, demean in targets:
        row = run.state.in_band(features.body_regressor[:, :, features.body_columns(key)])[:, YAW_PATH_JOINT, :]
        rows.append(row - row.mean(axis=0) if demean else row)
        gaps.append(gap - gap.mean() if demean else gap)
    return np.concatenate(rows), np.concatenate(gaps)


def _path_reading(gravity: np.ndarray, X: np.ndarray, effort: np.ndarray) -> dict[str, float]:
    """J1's figures of the path whose columns `X` fit `effort` (a column J1 never feels left out)."""
    seen = np.abs(X).max(axis=0) > 0.0  # (the link's mass on the yaw axis)
    path = np.zeros(X.shape[1])
    path[seen] = np.linalg.lstsq(X[:, seen], effort, rcond=None)[0]
    moment = path[:FIRST_MOMENT_COLUMNS]
    return {"gravity_efforts_at_q0": float(gravity[0, YAW_PATH_JOINT, :FIRST_MOMENT_COLUMNS] @ moment),
            "q1_gravity_slope_at_q0_nm_per_rad": float(_yaw_slope(gravity, moment))}


def path_readings(arm, key: int, targets: list, inertia: np.ndarray | None = None) -> dict[str, dict[str, float]]:
    """J1's figures a path on link `key` reads from the runs' J1 gaps (`j1_targets`) per path model: a rigid
    body, a first moment without inertia, and (`inertia`: the payload's second moment, (6,)) a first moment
    beside that inertia as the model's geometry carries it to J1."""
    rows, gap = _stacked(key, targets)
    gravity = _gravity_at_zero(arm, key)
    readings = {RIGID_PATH: _path_reading(gravity, rows, gap), BARE_PATH: _path_reading(gravity, rows[:, :FIRST_MOMENT_COLUMNS], gap)}
    if inertia is not None:
        carried = rows[:, FIRST_MOMENT_COLUMNS:] @ np.asarray(inertia, dtype=float)
        readings[POINT_INERTIA] = _path_reading(gravity, rows[:, :FIRST_MOMENT_COLUMNS], gap - carried)
    return readings


def span_readings(report: dict, shifts: dict[str, dict[str, float]], own: str) -> list[str]:
    """Every J1 figure's interval in `report` also holds the other models' readings (the figure moved by each
    shift); the shifts are recorded. The figures whose interval grew."""
    grew = []
    for name, index in J1_PATH_FIGURES:
        value = report.get(name) if index is None else (report.get(name) or [None] * (index + 1))[index]
        intervals = report.get(f"{name}_interval")
        interval = intervals if index is None else (intervals or [None] * (index + 1))[index]
        if value is None or interval is None:
            continue
        others = [value + shift[name] for shift in shifts.values()]
        spanned = [float(min(interval[0], *others)), float(max(interval[1], *others))]
        if spanned != [float(interval[0]), float(interval[1])]:
            grew.append(name)
        if index is None:
            report[f"{name}_interval"] = spanned
        else:
            report[f"{name}_interval"][index] = spanned
    report["yaw_path_models"] = {"fitted": own, "other_readings_minus_fitted": shifts}
    return grew


def path_words(moved: list[tuple[str, str, dict[str, dict[str, float]]]], unit: str) -> str:
    """The sentence that says J1's figures span the path models where an interval grew (`moved`: where,
    the figure that grew, the shifts): per place, the largest move of its first figure that grew."""
    first = {}
    for item in moved:
        first.setdefault(item[0], item)
    parts = []
    for where, name, shifts in first.values():
        model, shift = max(shifts.items(), key=lambda item: abs(item[1][name]))
        what = "J1's effort at q = 0" if name == "gravity_efforts_at_q0" else "J1's slope at q = 0"
        parts.append(f"{where}, {what} by {shift[name]:+.3g} {unit if name == 'gravity_efforts_at_q0' else unit + '/rad'} ({model})")
    return ("J1's figures rest on the inertia given to the payload's own path to J1, which these runs do not determine; another "
            f"model moves them ({'; '.join(parts)}): their intervals hold every model's reading.")


def _part_shifts(arm, keys: list[int], targets: list, own: str, inertia, models: tuple[str, ...]) -> dict[str, dict[str, float]]:
    """Per other model of `models` (and other link, named), its J1 readings minus the part's own model's on its own link."""
    readings = {k: path_readings(arm, k, targets, inertia if k == keys[0] else None) for k in keys}
    base = readings[keys[0]][own]
    shifts = {}
    for k in keys:
        where = "" if k == keys[0] else f", on {arm.model.links[k].name}"
        for model, reading in readings[k].items():
            if model in models and (k != keys[0] or model != own):
                shifts[model + where] = {name: reading[name] - base[name] for name in base}
    return shifts


def span_both_path_models(problem, params: dict, reports: list[dict], at_key: int | None, periodic: bool,
                          payloads: list[int] | None = None) -> None:
    """Each payload report's J1 figures, and its hand position's, span the path models (module docstring): the
    fit's own model is a rigid path periodic, else none for the first moment and the point's inertia at the
    hand position; `payloads` (upstream): each report's effect index, whose tied second moment is its point
    inertia. The payload's link counts with its equivalent and tied links. A payload J1 alone sees (the yaw
    link) has its own inertia on J1, no path: left as it is; so is a J1 the runs did not record."""
    if not reports or not problem.recorded[YAW_PATH_JOINT]:
        return
    targets = j1_targets(problem, params)
    if not targets:
        return
    model = problem.arm.model

    def on_path(key) -> bool:
        return key is not None and joints_moving_link(model, key) != (JOINT_NAMES[YAW_PATH_JOINT],)

    for n, report in enumerate(reports):
        moved = []
        if on_path(report.get("link_key")):
            keys = [report["link_key"]] + [model.link_by_name(name).key for name in
                                           dict.fromkeys([*report.get("equivalent_links", ()), *report.get("tied_links", ())])]
            inertia = None if periodic else problem.effects[payloads[n]].coefficients(params[payloads[n]])[FIRST_MOMENT_COLUMNS:BODY_PARAMETERS]
            own = RIGID_PATH if periodic else BARE_PATH
            shifts = _part_shifts(problem.arm, keys, targets, own, inertia, (RIGID_PATH, BARE_PATH, POINT_INERTIA))
            moved += [("the payload-shaped fit", name, shifts) for name in span_readings(report, shifts, own)]
        at = report.get("payload_at")
        if at and on_path(at_key):
            mass = at.get("mass_kg")
            inertia = point_mass_parameters(mass, np.asarray(at["position_m"]))[FIRST_MOMENT_COLUMNS:] if mass is not None else None
            own = RIGID_PATH if periodic else (POINT_INERTIA if inertia is not None else BARE_PATH)
            # a point has inertia: where its mass is known, the models are a free one and the point's as the geometry carries it
            models = (RIGID_PATH, POINT_INERTIA) if inertia is not None else (RIGID_PATH, BARE_PATH)
            shifts = _part_shifts(problem.arm, [at_key], targets, own, inertia, models)
            moved += [("at the hand position", name, shifts) for name in span_readings(at, shifts, own)]
        if moved:  # the sentences that quote J1's figures written again, then why they grew
            renew_sentences(report, periodic_j1_sentences(report, model) if periodic else j1_sentences(report))
            report.setdefault("words", []).append(path_words(moved, model.effort_unit(JOINT_NAMES[YAW_PATH_JOINT])))

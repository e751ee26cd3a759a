"""What the data determine of a selected payload, with cross-validated intervals.

Intervals are delete-one-fold jackknife intervals over the cross-validation
folds (each fold's fit leaves out one contiguous time segment of every run),
with Student's t of the folds' degrees of freedom (`intervals.jackknife_error`);
with a --repeat pair, the session change it reads is counted as the periodic
processing counts its own (`intervals.with_session_change`).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.first_moment import (
    FIRST_MOMENT_COLUMNS,
    YAW_PATH_JOINT,
    FirstMomentPayload,
    PayloadAtPosition,
)
from dvrk_dart.diagnosis.effects.payload import (
    first_moment_map,
    mass_seen_by_gravity,
    point_mass_parameters,
)
from dvrk_dart.diagnosis.payload.payload_report import (
    J1_SLOPE_SENTENCE,
    MASS_IDENTIFIED_RATIO,
    MASS_NOT_SEEN,
    PAYLOAD_AT_HINT,
    SWAMPED,
    WITHOUT_REPEAT,
    at_position_sentence,
    effort_not_determined,
    position_figures_without_repeat,
    pitch_shaft_offsets,
    swamp,
)
from dvrk_dart.diagnosis.payload.intervals import central_interval, jackknife_error, with_session_change
from dvrk_dart.diagnosis.fit.selection import (
    GAIN_FAILURE_QUANTILE,
    Selector,
)
from dvrk_dart.io.reference_data import sample_rate_hz
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS

#: step of the central difference of J1's gravity effort in q1 (rad)
YAW_SLOPE_STEP_RAD = 1e-4
#: fit(chosen effects, reverse) -> their parameters, on two sessions of the run without the weight
#: (reverse: the first session minus the second)
SessionFit = Callable[..., dict[int, np.ndarray]]


def _gravity_at_zero(arm: Arm, link: int) -> np.ndarray:
    """(3, 7, 10) efforts at rest per unit dynamic parameter of a link's body,
    at q = 0 and at q1 = +-YAW_SLOPE_STEP_RAD (for J1's slope)."""
    q = np.zeros((3, N_JOINTS))
    q[1:, YAW_PATH_JOINT] = (YAW_SLOPE_STEP_RAD, -YAW_SLOPE_STEP_RAD)
    zero = np.zeros_like(q)
    f = TrajectoryFeatures(arm, q, zero, zero, zero, sample_rate_hz())
    return f.body_regressor[:, :, f.body_columns(link)]


def _gravity_efforts(gravity: np.ndarray, body: np.ndarray, yaw_path: np.ndarray) -> np.ndarray:
    """(7,) gravity efforts at q = 0 of a body's parameters, J1's from its own path's (m, m c)."""
    efforts = gravity[0] @ body
    efforts[YAW_PATH_JOINT] = gravity[0, YAW_PATH_JOINT, :FIRST_MOMENT_COLUMNS] @ yaw_path
    return efforts


def _yaw_slope(gravity: np.ndarray, yaw_path: np.ndarray) -> np.ndarray:
    """d(J1 gravity effort)/dq1 at q = 0 of the yaw path (N·m/rad): the J1 signature
    that scales with the weight, determined even where per-run offsets take J1's value at q = 0."""
    rows = gravity[1:, YAW_PATH_JOINT, :FIRST_MOMENT_COLUMNS] @ yaw_path
    return np.array((rows[0] - rows[1]) / (2.0 * YAW_SLOPE_STEP_RAD))


def reference_first_moment(arm: Arm, key: int, reference_key: int, body: np.ndarray) -> np.ndarray:
    """m (p_origin + R c) in the base frame at q = 0 of the body on `reference_key`
    whose gravity efforts are those of (m, m c) on `key`: what the efforts see."""
    m_c = first_moment_map(arm, key, reference_key) @ np.asarray(body[:FIRST_MOMENT_COLUMNS], dtype=float)
    T = arm.model.forward_kinematics(np.zeros(N_JOINTS))[reference_key]
    return m_c[0] * T[:3, 3] + T[:3, :3] @ m_c[1:4]


def _quantities(arm: Arm, effect: FirstMomentPayload, p: np.ndarray, gravity: np.ndarray) -> dict[str, np.ndarray]:
    return {"mass_kg": np.array(p[0]), "first_moment_base_at_q0_kg_m": reference_first_moment(arm, effect.link_key, effect.reference_key, p),
            "gravity_efforts_at_q0": _gravity_efforts(gravity[:, :, :FIRST_MOMENT_COLUMNS], p[:FIRST_MOMENT_COLUMNS], p[FIRST_MOMENT_COLUMNS:]),
            "q1_gravity_slope_at_q0_nm_per_rad": _yaw_slope(gravity, p[FIRST_MOMENT_COLUMNS:])}


def _with_intervals(values: dict, folds: list[dict], session: dict[str, np.ndarray]) -> dict:
    """Each value with its jackknife interval over the folds, counting the
    --repeat pair's reading of it where `session` has one."""
    out = {}
    for key, v in values.items():
        se, dof = jackknife_error(np.array([f[key] for f in folds]))
        interval = with_session_change(v, se, dof, session[key])[0] if key in session else central_interval(v, se, dof)
        out[key] = v.tolist()
        out[f"{key}_interval"] = interval.T.tolist() if v.ndim else interval.tolist()
    return out


def _mass_unseen(arm: Arm, selector: Selector, index: int) -> bool:
    """Whether the efforts see the payload's mass only through its (sub-noise) inertia."""
    return not mass_seen_by_gravity(arm, selector.design.effects[index].link_key)


def tied_payloads(selector: Selector, chosen: list[int], index: int) -> list[tuple[int, dict]]:
    """Other links' payloads of the selected one's kind (first moment, point) that explain the held-out residual
    not significantly worse than the selected one (bootstrap, as the selection
    decides), each swapped in for it: (index, its quantities with intervals
    are built by the caller from these fits). The efforts cannot tell these
    links apart, so what differs among them is not determined."""
    current = selector.cross_validate(chosen)
    reference = selector.bootstrap_fractions(current.after)
    ties = []
    for j, effect in enumerate(selector.design.effects):
        if j == index or type(effect) is not type(selector.design.effects[index]) or j in chosen:
            continue
        swapped = [j if i == index else i for i in chosen]
        trial = selector.cross_validate(swapped)
        if np.mean(reference - selector.bootstrap_fractions(trial.after) <= 0.0) > GAIN_FAILURE_QUANTILE:
            ties.append((j, selector.fit_all(swapped).params[j]))
    return ties


def with_point_ties(report: dict, selector: Selector, chosen: list[int], index: int) -> dict:
    """A point payload's report with the links whose point payloads explain the efforts as well (a held wrist: a
    mass on tool_roll and one on insertion_carriage give the same efforts): the link is not determined."""
    effect = selector.design.effects[index]
    others = [e for e in (selector.design.effects[j] for j, _ in tied_payloads(selector, chosen, index)) if e.link_name not in effect.equivalent_links]
    if others:  # (an equivalent link is the same hypothesis, not a tie)
        report["tied_links"] = [e.link_name for e in others]
        report["tied_groups"] = sorted({e.group for e in [effect, *others]})
    return report


def _session_change(read: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The size of what the --repeat pair alone reads as each quantity (per component)."""
    return {key: np.abs(v) for key, v in read.items()}


def _first_moment_session_change(arm: Arm, effect: FirstMomentPayload, session_fit: SessionFit, chosen: list[int], index: int,
                                 gravity: np.ndarray, mass_unseen: bool) -> dict[str, np.ndarray]:
    """What the --repeat pair reads as the first moment's quantities. A change
    towards a lighter weight puts the mass on its bound (zero) and the change
    in the first moment: where the efforts see the mass, its mirror is read in
    the reverse order, where the mass is free (carriage, -20 g: 0 kg and
    (0.0005, -0.0045, 0.0073) kg·m one way, 0.020 kg and its point's
    (-0.0004, -0.0004, -0.0020) the other). Where they do not see it, the
    reverse fit lands elsewhere (pitch link, -30 g: 0.583 kg), and any
    reading of the mass is the prior's: none is counted."""
    read = session_fit(chosen)[index]
    if not mass_unseen and read[0] <= effect.lower[0] + 1e-9 * effect.upper[0]:  # on its bound, to the solver's round-off
        read = session_fit(chosen, reverse=True)[index]
    session = _session_change(_quantities(arm, effect, read, gravity))
    if mass_unseen:
        session.pop("mass_kg", None)
    return session


def _span_tied_links(report: dict, arm: Arm, selector: Selector, ties: list[tuple[int, dict]], effect: FirstMomentPayload) -> None:
    """Every interval spans the tied links' estimates: the link is not determined."""
    others = [(selector.design.effects[j], q) for j, q in ties]
    report["tied_links"] = [e.link_name for e, _ in others]
    report["tied_groups"] = sorted({e.group for e, _ in [(effect, None), *others]})
    unseen = [e.link_name for (j, _), (e, _) in zip(ties, others) if _mass_unseen(arm, selector, j)]
    if report["mass_kg"] is not None and unseen:  # a tied link whose efforts do not see m: any mass
        _mass_not_determined(report, f"a link that explains the efforts as well ({', '.join(unseen)}) turns about fixed axes: gravity "
                                     "sees m·c only there, and the inertia of a small mass is below the noise")
    for e, q in others:
        for key, v in _quantities(arm, e, q, _gravity_at_zero(arm, e.link_key)).items():
            if report[f"{key}_interval"] is None:  # not determined already
                continue
            interval = np.asarray(report[f"{key}_interval"], dtype=float)
            v = np.asarray(v, dtype=float)
            if interval.ndim == 1:
                report[f"{key}_interval"] = [float(min(interval[0], v)), float(max(interval[1], v))]
            else:
                report[f"{key}_interval"] = np.stack([np.minimum(interval[:, 0], v), np.maximum(interval[:, 1], v)], axis=1).tolist()


def _mass_not_determined(report: dict, reason: str) -> None:
    """The mass and its interval null, with the reason (any mass the search allows fit: its bound is no interval)."""
    report["mass_kg"] = report["mass_kg_interval"] = None
    report.setdefault("not_determined", {})["mass_kg"] = reason


def first_moment_report(arm: Arm, selector: Selector, chosen: list[int], index: int, fit_params: dict, fold_params: list[dict],
                        at_index: int | None = None, session_fit: SessionFit | None = None,
                        efforts_not_determined: dict[int, str] | None = None) -> dict:
    """The payload as the efforts determine it: first moment (base frame, q = 0)
    and gravity efforts at q = 0 per joint, each with its interval; the mass
    with its interval and whether it is identified; with a payload at a given
    position (`at_index`, a PayloadAtPosition in the design), its mass.

    session_fit: the same effects fitted on two sessions of the run without the
    weight (`--repeat` against the baseline): what they read there is counted in
    every interval (`with_session_change`; the time-segment folds of one session
    cannot see it), and a quantity it reaches is not determined (`swamp`).
    efforts_not_determined: joint -> why its gravity effort at q = 0 is not determined."""
    effect: FirstMomentPayload = selector.design.effects[index]
    gravity = _gravity_at_zero(arm, effect.link_key)
    p = fit_params[index]
    report = effect.describe(p)
    report["first_moment_reference_link"] = arm.model.links[effect.reference_key].name
    mass_unseen = _mass_unseen(arm, selector, index)
    session = _first_moment_session_change(arm, effect, session_fit, chosen, index, gravity, mass_unseen) if session_fit is not None else {}
    report.update(_with_intervals(_quantities(arm, effect, p, gravity), [_quantities(arm, effect, f[index], gravity) for f in fold_params if index in f],
                                  session))
    if session:
        report["session_to_session"] = {key: v.tolist() for key, v in session.items()}
    if mass_unseen:  # the efforts do not depend on m at all (a link about a fixed axis): any mass the search allows fits
        _mass_not_determined(report, MASS_NOT_SEEN)
    ties = tied_payloads(selector, chosen, index)
    if ties:  # the link is not determined: every interval spans the tied links' estimates
        _span_tied_links(report, arm, selector, ties, effect)
    for key, spread in session.items():
        swamp(report, key, spread, report.setdefault("not_determined", {}))
    for joint, reason in (efforts_not_determined or {}).items():
        if report["gravity_efforts_at_q0"][joint] not in (None, 0.0):
            effort_not_determined(report, joint, reason)
    mass, mass_interval = report["mass_kg"], report["mass_kg_interval"]
    mass_identified = bool(mass is not None and mass_interval[0] > 0.0 and mass_interval[1] / mass_interval[0] <= MASS_IDENTIFIED_RATIO)
    report["mass_identified"] = mass_identified
    report["position_m"] = (np.asarray(p[1:4]) / p[0]).tolist() if mass_identified else None
    moment = report["first_moment_base_at_q0_kg_m"]
    report["pitch_shaft_offsets_of_first_moment_m_kg"] = pitch_shaft_offsets(arm, np.asarray(moment)) if None not in moment else None
    words = _first_moment_words(report, arm, effect, bool(ties), at_index is not None)
    if at_index is not None:
        report["payload_at"] = _at_position(arm, selector, chosen, index, at_index, session_fit)
        report["position_m"] = report["payload_at"]["position_m"]
        at = report["payload_at"]
        if session_fit is None:
            position_figures_without_repeat(at)
        words.append(at_position_sentence(at, _text(at['mass_kg'], at['mass_kg_interval'], 'kg', '.3f')))
    if session_fit is None:
        words.append("Without --repeat (the baseline's motion in another session) the intervals come from time segments of the runs, "
                     "which share their sessions: " + WITHOUT_REPEAT)
    if report.get("not_determined"):
        words.append("Not determined: " + "; ".join(f"{key} ({reason})" for key, reason in report["not_determined"].items()) + ".")
    report["words"] = words
    return report


def _text(value, interval, unit: str, number: str) -> str:
    """A value with its interval, or "not determined"."""
    if value is None:
        return "not determined"
    return f"{value:{number}} {unit} (interval {interval[0]:{number}} to {interval[1]:{number}})"


def j1_sentences(report: dict) -> list[str]:
    """The sentence that quotes J1's slope at q = 0 with its interval (the efforts at q = 0 are quoted without)."""
    slope = _text(report["q1_gravity_slope_at_q0_nm_per_rad"], report["q1_gravity_slope_at_q0_nm_per_rad_interval"], "N·m/rad", "+.3f")
    return [f"{J1_SLOPE_SENTENCE}{slope} at q = 0: the J1 signature that scales with the weight."]


def _first_moment_words(report: dict, arm: Arm, effect: FirstMomentPayload, tied: bool, at_given: bool) -> list[str]:
    units = [arm.model.effort_unit(j) for j in JOINT_NAMES]
    intervals = report.get("first_moment_base_at_q0_kg_m_interval") or [None] * 3
    moment = ", ".join("not determined" if v is None else f"{v:+.4f}" + ("" if i is None else f" [{i[0]:+.4f}, {i[1]:+.4f}"
                                                                          f"{', holding zero' if i[0] <= 0.0 <= i[1] else ''}]")
                       for v, i in zip(report["first_moment_base_at_q0_kg_m"], intervals))
    efforts = ", ".join(f"{j} {'not determined' if v is None else f'{v:+.3f} {u}'}" for j, v, u in zip(JOINT_NAMES[:3], report["gravity_efforts_at_q0"], units))
    words = [
        ("The best-fitting payload's first moment" if tied else "The efforts determine the payload's first moment") + f" m·c = ({moment}) kg·m "
        f"(base frame, q = 0, as a body on {report['first_moment_reference_link']}{'; ' + arm.model.frame_words if arm.model.frame_words else ''}) "
        f"and its gravity efforts at q = 0: {efforts}.",
        *j1_sentences(report),
    ]
    if effect.equivalent_links:
        words.append(f"The link is one of {', '.join((effect.link_name,) + effect.equivalent_links)}: payloads on these links give identical efforts.")
    elif not tied:
        words.append(f"The link ({effect.link_name}) is the only one whose payload gives these efforts.")
    if tied:
        words.append(f"Payloads on {', '.join(report['tied_links'])} explain the efforts as well (held-out scores within the bootstrap noise): "
                     "the link is not determined, and every interval spans their estimates too.")
    if report["mass_identified"]:
        words.append(f"The mass is identified: {_text(report['mass_kg'], report['mass_kg_interval'], 'kg', '.3f')}, "
                     "seen through the link's translation or the inertia at several speeds.")
    elif report["mass_kg"] is None:
        reason = (report.get("not_determined") or {}).get("mass_kg", SWAMPED)
        words.append(f"The mass is not determined{' by the efforts alone' if at_given and reason != SWAMPED else ''}: {reason}"
                     + ("" if at_given or reason == SWAMPED else f"; {PAYLOAD_AT_HINT}") + ".")
    else:
        lo, hi = report["mass_kg_interval"]
        words.append(f"The mass is not identified (interval {max(lo, 0.0):.3f}-{hi:.3f} kg): gravity on a link turning about a fixed "
                     "axis sees m·c only, and the inertia of a small mass is below the noise" + ("" if at_given else
                                                                                               f"; {PAYLOAD_AT_HINT}") + ".")
    words.append("J1's gravity load depends on how the real first axis lies relative to gravity, which the model fixes: J1's efforts get a "
                 "first moment of their own (the yaw path), fitted with the payload so that a J1 effort scaling with the weight is counted as "
                 "the payload's whatever its path (a tilted mount, a coupling in the transmission); the first moment and the mass above are "
                 "read from the other joints, where the model's geometry holds.")
    return words


def _at_position(arm: Arm, selector: Selector, chosen: list[int], index: int, at_index: int, session_fit: SessionFit | None) -> dict:
    """The selected payload as a point mass at the given position: its mass and
    gravity efforts at q = 0, each with its jackknife interval counting the
    --repeat pair's reading, or None where that swamps it."""
    at: PayloadAtPosition = selector.design.effects[at_index]
    at_set = [at_index if i == index else i for i in chosen]
    at_cv = selector.cross_validate(at_set)
    gravity = _gravity_at_zero(arm, at.link_key)

    def quantities(q: np.ndarray) -> dict[str, np.ndarray]:
        return {"mass_kg": np.array(q[0]), "gravity_efforts_at_q0": _gravity_efforts(gravity, point_mass_parameters(q[0], at.position), q[1:])}

    session = _session_change(quantities(session_fit(at_set)[at_index])) if session_fit is not None else {}
    report = {"link": at.link_name, "position_m": at.position.tolist(), "cross_validated_fraction": at_cv.fraction}
    report.update(_with_intervals(quantities(selector.fit_all(at_set).params[at_index]),
                                  [quantities(f[at_index]) for f in at_cv.fold_params if at_index in f], session))
    if session:
        report["session_to_session"] = {key: v.tolist() for key, v in session.items()}
    for key, spread in session.items():
        swamp(report, key, spread, report.setdefault("not_determined", {}))
    return report

"""What a selected payload is: its mass profile, its report (its member among equivalent links: fit/families.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dvrk_dart.diagnosis.fit.diagnosis_runs import MIN_PAYLOAD_KG
from dvrk_dart.diagnosis.fit.families import best_fit, family_members, swap
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.payload import PointPayload, point_mass_parameters
from dvrk_dart.diagnosis.fit.selection import CvResult, Selector
from dvrk_dart.io.reference_data import sample_rate_hz
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.description import SessionPayloadReading
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS, PITCH

#: a payload's mass counts as identified when its interval's ends are within
#: this ratio (1.3 / 0.77: within +-30 % of the interval's geometric middle)
MASS_IDENTIFIED_RATIO = 1.7
#: what a payload report without --repeat (the baseline's motion in another session) says of its intervals
WITHOUT_REPEAT = ("a change between the sessions shaped like gravity (an offset of a joint's zero, a cable's tension) reads as a "
                  "payload, and the intervals do not count it.")
#: why the mass of a payload on a link turning about fixed axes is not determined
MASS_NOT_SEEN = ("gravity sees m·c only on this link (it turns about fixed axes with the parallelogram) and the inertia of a small "
                 "mass is below the noise")
#: what turns the first moment into a mass, said where no --payload-at was given
PAYLOAD_AT_HINT = "give --payload-at LINK:x,y,z to turn the first moment into a mass"
#: why a quantity the session change swamps is not determined
SWAMPED = ("a session change alone (the --repeat pair: the same motion in two sessions, no weight) reads it at least as large: "
           "the runs do not tell the payload's share from a session's")


def swamp(report: dict, key: str, session_share, reasons: dict) -> None:
    """Each component of report[key] whose size the session change the repeat
    pair reads (`session_share`: the spread the interval counts for it) reaches
    is not determined: None, its interval None, the reason in `reasons`."""
    values = report[key]
    scalar = not isinstance(values, list)
    values, intervals = ([values], [report[f"{key}_interval"]]) if scalar else (list(values), list(report[f"{key}_interval"]))
    shares = np.atleast_1d(np.abs(np.asarray(session_share, dtype=float)))
    swamped = [v is not None and s > 0.0 and abs(v) <= s for v, s in zip(values, shares)]
    if not any(swamped):
        return
    values = [None if w else v for v, w in zip(values, swamped)]
    intervals = [None if w else i for i, w in zip(intervals, swamped)]
    report[key], report[f"{key}_interval"] = (values[0], intervals[0]) if scalar else (values, intervals)
    reasons[key] = SWAMPED


def effort_not_determined(report: dict, joint: int, reason: str) -> None:
    """report's gravity effort at q = 0 on `joint` as None, with the reason (joined to any other joint's)."""
    report["gravity_efforts_at_q0"][joint] = None
    if report.get("gravity_efforts_at_q0_interval") is not None:
        report["gravity_efforts_at_q0_interval"][joint] = None
    reasons = report.setdefault("not_determined", {})
    text = f"{JOINT_NAMES[joint]}: {reason}"
    reasons["gravity_efforts_at_q0"] = f"{reasons['gravity_efforts_at_q0']}; {text}" if "gravity_efforts_at_q0" in reasons else text


#: why a --payload-at position's figures are not determined without a --repeat pair: a session's change of gravity's
#: shape reads as a mass there (the real null pair, two sessions without a weight, both orders, at the pitch link's hand
#: position and the origins of tool_roll, insertion_carriage and pitch_top: upstream, 4 of 8 diagnoses read 12 to 54 g,
#: intervals excluding zero, the other 4 a negative mass; periodic, the tool roll's origin read 7 g, 3 to 11 g)
AT_POSITION_WITHOUT_REPEAT = ("without a --repeat pair (the baseline's motion in another session) nothing measures how sessions change "
                              "gravity's shape (a joint's zero, the base's tilt), which reads as a mass at the position (docs/diagnosis.md: "
                              "the PSM's two sessions without any weight read tens of grams, intervals excluding zero): give --repeat")


#: why a --payload-at position reads nothing: no payload-shaped effect was selected
PAYLOAD_AT_UNUSED = "no payload-shaped effect is selected: the --payload-at position reads no mass"


def position_figures_without_repeat(at: dict) -> None:
    """A --payload-at report's mass, gravity efforts at q = 0 and J1 slope not determined (AT_POSITION_WITHOUT_REPEAT)."""
    at["mass_kg"] = at["mass_kg_interval"] = None
    at["gravity_efforts_at_q0"] = [None] * len(at["gravity_efforts_at_q0"])
    at["gravity_efforts_at_q0_interval"] = [None] * len(at["gravity_efforts_at_q0"])
    keys = ["mass_kg", "gravity_efforts_at_q0"]
    if YAW_SLOPE in at:
        at[YAW_SLOPE] = at[f"{YAW_SLOPE}_interval"] = None
        keys.append(YAW_SLOPE)
    at["not_determined"] = {**at.get("not_determined", {}), **dict.fromkeys(keys, AT_POSITION_WITHOUT_REPEAT)}


def not_a_payload_because(fit: dict, sessions_read: SessionPayloadReading | None = None) -> str | None:
    """Why a payload-shaped fit is no payload, or None: the mass it gives (at the hand position when one was given, else its
    own where the data identify one) under a gram (at or below zero: a session change read as a payload), a hand position
    given without a --repeat pair to tell a mass there from a session's change (`position_figures_without_repeat`), or,
    without a --repeat pair (`sessions_read`: what the model card's repeat pair reads, given then), nothing beyond it."""
    at = fit.get("payload_at") or {}
    if (at.get("not_determined") or {}).get("mass_kg") == AT_POSITION_WITHOUT_REPEAT:
        return "no --repeat pair measures how sessions change gravity's shape, which reads as a mass at the --payload-at position"
    mass = at.get("mass_kg") if at.get("mass_kg") is not None else (fit.get("mass_kg") if fit.get("mass_identified") else None)
    if mass is not None and mass < MIN_PAYLOAD_KG:
        where = "at the --payload-at position" if at.get("mass_kg") is not None else "the fit identifies"
        return f"the mass {where} is under {MIN_PAYLOAD_KG * 1e3:g} g: a session change read as a payload"
    if sessions_read is not None and not _beyond_sessions(fit, sessions_read):
        return _within_sessions_reason(fit, sessions_read)
    return None


def _beyond_sessions(fit: dict, sessions_read: SessionPayloadReading) -> bool:
    """Whether J1's gravity effort at q = 0 or its slope with q1 has an interval beyond (excluding) +-what the sessions
    read, or the fit identifies a mass whose interval is above a gram (the sessions' pair identified none; 2018 test1
    against test2, no weight, read 3.5e-19 kg "identified" at its bound)."""
    figures = (((fit.get("gravity_efforts_at_q0_interval") or [None])[0], sessions_read.q1_effort_at_q0),
               (fit.get(f"{YAW_SLOPE}_interval"), sessions_read.q1_slope_at_q0),
               (fit.get("mass_kg_interval") if fit.get("mass_identified") else None, MIN_PAYLOAD_KG))
    return any(interval is not None and (interval[0] > size or interval[1] < -size) for interval, size in figures)


def _within_sessions_reason(fit: dict, sessions_read: SessionPayloadReading) -> str:
    """Why a fit without a --repeat is no payload: nothing of it beyond what the model card's sessions read."""
    if fit.get(YAW_SLOPE) is None and (fit.get("gravity_efforts_at_q0") or [None])[0] is None:
        return ("without a --repeat pair, only J1's figures and an identified mass tell a payload from a session's change, and "
                "this fit has neither (q1 not recorded or not determined): give --repeat")
    return (f"without a --repeat pair, neither J1's effort at q = 0 nor its slope with q1 is beyond "
            f"+-{sessions_read.q1_effort_at_q0:.3f} N·m and +-{sessions_read.q1_slope_at_q0:.3f} N·m/rad, what two sessions of "
            "the model card's arm without a weight read, and no mass is identified: give --repeat")


#: why a payload's gravity effort is not given on a joint the runs did not record
NOT_RECORDED = "not recorded by the runs: no figure on it"


#: a payload report's J1 slope with q1 at q = 0 (diagnosis.json key)
YAW_SLOPE = "q1_gravity_slope_at_q0_nm_per_rad"


#: how the sentences that quote J1's figures begin (their intervals grow after the words are written: yaw_path_inertia)
J1_EFFORTS_SENTENCE = "Gravity efforts at q = 0: "
J1_SLOPE_SENTENCE = "J1's effort changes with q1 at "


def at_position_sentence(at: dict, mass_text: str) -> str:
    """The mass a point at the hand position reads (`mass_text`: it with its interval), not determined where that holds zero."""
    zero = at["mass_kg"] is not None and at["mass_kg_interval"] is not None and at["mass_kg_interval"][0] <= 0.0
    why = (at.get("not_determined") or {}).get("mass_kg") if at["mass_kg"] is None else None
    return (f"At the given position ({at['link']}, {np.round(at['position_m'], 3).tolist()} m in its frame) the mass is {mass_text}"
            + (": not determined, its interval holds zero" if zero else f": {why}" if why else "") + ".")


def renew_sentences(report: dict, fresh: list[str]) -> None:
    """The report's sentences on J1's figures replaced by `fresh` (written again from the final figures)."""
    by_start = {start: f for f in fresh for start in (J1_EFFORTS_SENTENCE, J1_SLOPE_SENTENCE) if f.startswith(start)}
    report["words"] = [next((f for start, f in by_start.items() if w.startswith(start)), w) for w in report.get("words", [])]


def without_unrecorded_joints(report: dict, recorded: np.ndarray) -> None:
    """A payload report's gravity efforts at q = 0 (and at the hand position's)
    null, with the reason, on the joints the runs did not record; J1's slope
    with q1 likewise where q1 was not recorded (its sentence goes too)."""
    for part in (report, report.get("payload_at")):
        if part and part.get("gravity_efforts_at_q0") is not None:
            for j in np.flatnonzero(~recorded[:len(part["gravity_efforts_at_q0"])]):
                effort_not_determined(part, int(j), NOT_RECORDED)
    if not recorded[0] and report.get(YAW_SLOPE) is not None:
        report[YAW_SLOPE] = report[f"{YAW_SLOPE}_interval"] = None
        report.setdefault("not_determined", {})[YAW_SLOPE] = f"q1: {NOT_RECORDED}"
        report["words"] = [w for w in report.get("words", []) if not w.startswith("J1's effort changes with q1")]


def flag_payload_at_link(report: dict, at_link: str, same_efforts: tuple[str, ...]) -> None:
    """Whether the hand position given with --payload-at (on `at_link`, whose
    payloads give the efforts of those on `same_efforts` too) is on a link the
    efforts choose: the chosen link, one tied with it, or one they cannot tell
    from these. Its mass assumes a payload there; a position on another link
    read as a mass with no word (a mass on a link the efforts fit worse)."""
    at = report.get("payload_at")
    if not at or not report.get("link"):
        return
    chosen = list(dict.fromkeys([report["link"], *(report.get("tied_links") or ()), *(report.get("equivalent_links") or ())]))
    at["link_chosen_by_the_efforts"] = bool({at_link, *same_efforts}.intersection(chosen))
    if not at["link_chosen_by_the_efforts"]:
        report.setdefault("words", []).append(
            f"The given position is on {at_link}, which the efforts do not choose (they choose {', '.join(chosen)}): its mass assumes a "
            f"payload on {at_link}, which fits them less well.")


#: masses tried when profiling a selected payload's mass (kg, geometric grid)
PROFILE_MASSES_KG = tuple(float(m) for m in np.geomspace(0.01, 2.0, 24))


def mass_profile(selector: "Selector", chosen: list[int], payload: int) -> dict:
    """Cross-validated score of the selected set with the payload's mass fixed
    on a grid (its position free in the envelopes of its family's links): where
    the score stays within the bootstrap spread of the best, the data cannot
    tell the masses apart (for a link turning about a fixed axis, gravity only
    sees m c; m alone comes from the weak inertial terms)."""
    best_scores: dict[float, CvResult] = {}
    for member in family_members(selector, payload):
        members_set = swap(chosen, payload, member)
        fit = best_fit(selector, members_set)
        effect = selector.design.effects[member]
        original = effect.parameters
        try:
            for m in PROFILE_MASSES_KG:
                if m > original[0].upper:
                    break
                effect.parameters = (replace(original[0], lower=m * (1 - 1e-9), upper=m),) + original[1:]
                warm = [{i: (np.r_[m, fit.params[i][1:]] if i == member else fit.params[i]) for i in members_set} for _ in selector.folds]
                score = selector.cross_validate(members_set, warm)
                if m not in best_scores or score.fraction > best_scores[m].fraction:
                    best_scores[m] = score
        finally:
            effect.parameters = original
    masses = sorted(best_scores)
    fractions = np.array([best_scores[m].fraction for m in masses])
    k = int(np.argmax(fractions))
    spread = float(np.std(selector.bootstrap_fractions(best_scores[masses[k]].after)))
    lo, hi = _interval_within(np.array(masses), fractions, fractions[k] - spread)
    return {
        "masses_kg": masses,
        "cross_validated_fraction": fractions.tolist(),
        "bootstrap_spread": spread,
        "mass_interval_kg": [lo, hi],
        "identifiable": bool(lo > masses[0] and hi < masses[-1] and hi / lo <= MASS_IDENTIFIED_RATIO),
    }


def _interval_within(masses: np.ndarray, fractions: np.ndarray, threshold: float) -> tuple[float, float]:
    """The masses whose score reaches `threshold`: each end where the score
    crosses it, interpolated in log mass between the grid's last mass inside
    and first outside (a grid point as the end put a fit between two grid
    points outside its own interval), or the grid's end."""
    inside = np.flatnonzero(fractions >= threshold)
    first, last = int(inside[0]), int(inside[-1])

    def crossing(i_in: int, i_out: int) -> float:
        share = (fractions[i_in] - threshold) / (fractions[i_in] - fractions[i_out])
        return float(np.exp(np.log(masses[i_in]) + share * (np.log(masses[i_out]) - np.log(masses[i_in]))))

    lo = crossing(first, first - 1) if first > 0 else float(masses[0])
    hi = crossing(last, last + 1) if last < len(masses) - 1 else float(masses[-1])
    return lo, hi


def pitch_shaft_offsets(arm: Arm, position_base: np.ndarray) -> dict:
    """Where a base-frame point (q = 0) sits relative to the pitch shaft centre
    (the joint of the first link that q2 alone turns: the PSM's pitch, the
    MTM's upper arm): horizontal distance perpendicular to the shaft and height
    above it (m), the quantities of a hand measurement."""
    pitch = next(l for l in arm.model.links.values() if l.joint_type == "revolute"
                 and np.count_nonzero(l.variable.coeffs) == 1 and l.variable.coeffs[PITCH] != 0.0)
    T = arm.model.forward_kinematics(np.zeros(N_JOINTS))[pitch.key]
    up = -arm.model.gravity / np.linalg.norm(arm.model.gravity)
    v = np.asarray(position_base) - T[:3, 3]
    v_perp = v - (v @ T[:3, 2]) * T[:3, 2]  # remove the along-shaft component
    height = float(v_perp @ up)
    return {"horizontal_m": float(np.linalg.norm(v_perp - height * up)), "height_m": height, "along_shaft_m": float(v @ T[:3, 2])}


def payload_gravity_efforts_at_zero(arm: Arm, link: int, mass_kg: float, position_m: np.ndarray) -> np.ndarray:
    """Static efforts (7) a point mass needs at q = 0: what gravity identifies."""
    zero = np.zeros((1, N_JOINTS))
    features = TrajectoryFeatures(arm, zero, zero, zero, zero, sample_rate_hz())
    return (features.body_regressor[0][:, features.body_columns(link)] @ point_mass_parameters(mass_kg, position_m))


def describe_payload(effect: PointPayload, p: np.ndarray, arm: Arm, profile: dict | None = None) -> dict:
    report = effect.describe(p)
    report["first_moment_kg_m"] = (p[0] * np.asarray(p[1:4])).tolist()
    report["pitch_shaft_offsets_at_q0_m"] = pitch_shaft_offsets(arm, effect.position_base_at_zero(p))
    report["gravity_efforts_at_q0"] = payload_gravity_efforts_at_zero(arm, effect.link_key, p[0], p[1:4]).tolist()
    if profile is not None:
        report["mass_profile"] = profile
        # the profile's masses are those whose cross-validated score the bootstrap cannot tell from the best one's; the
        # fit's own mass minimises the training error instead, and may lie outside them (0.571 kg beside [0.60, 2.0]):
        # the interval holds both, and the mass is then not identified
        lo, hi = profile["mass_interval_kg"]
        report["mass_interval_kg"] = [min(lo, float(p[0])), max(hi, float(p[0]))]
        if not lo <= p[0] <= hi:
            profile["identifiable"] = False
    return report

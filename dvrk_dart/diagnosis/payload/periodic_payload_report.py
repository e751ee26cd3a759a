"""What the periodic payload fit (`periodic_payload`) reports: the link the
efforts choose, the links they cannot tell from it, every quantity with an
interval that holds or None with the reason, and the sentences."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from dvrk_dart.diagnosis.effects.features import FIRST_MOMENT_COLUMNS
from dvrk_dart.diagnosis.payload.identifiable import _gravity_at_zero, _gravity_efforts, _quantities, _yaw_slope
from dvrk_dart.diagnosis.effects.payload import equivalents_of, mass_seen_by_gravity, point_mass_parameters
from dvrk_dart.diagnosis.payload.payload_report import (
    J1_EFFORTS_SENTENCE,
    J1_SLOPE_SENTENCE,
    MASS_NOT_SEEN,
    PAYLOAD_AT_HINT,
    SWAMPED,
    WITHOUT_REPEAT,
    position_figures_without_repeat,
    at_position_sentence,
    effort_not_determined,
    pitch_shaft_offsets,
    swamp,
)
from dvrk_dart.diagnosis.payload.intervals import INTERVAL_PROBABILITY
from dvrk_dart.diagnosis.payload.periodic_payload import (
    Pair,
    PayloadFit,
    fit_payload,
    interval_with_session,
    linear_map,
    make_pair,
    point_payload_columns,
    rigid_as_first_moment,
    rigid_payload_columns,
    session_variance,
)
from dvrk_dart.diagnosis.fit.diagnosis_runs import RunRole
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.body_regressor import BODY_PARAMETERS
from dvrk_dart.model.joints import JOINT_NAMES

#: the payload is found when its gravity signature stands out of the session
#: scatter at this level (Wald test, HC2 covariance)
PAYLOAD_TEST_LEVEL = 0.01
#: links whose payloads explain the efforts within this BIC of the best are
#: tied (Kass and Raftery 1995: beyond 10, "very strong" evidence)
TIED_BIC = 10.0
#: why a joint's gravity effort at q = 0 has no interval without a --repeat pair (the real null pair, two sessions
#: without a weight, read q2's as +0.26 N·m, its interval [+0.14, +0.38] excluding zero)
SESSION_SHAPE_NOT_COUNTED = ("sessions move this joint's constant (each run's offset takes it) and can change its gravity's shape (an offset "
                             "of its zero); without a --repeat pair nothing measures that change, and the interval would not count it")
SCALAR_QUANTITIES = {"mass_kg", "q1_gravity_slope_at_q0_nm_per_rad"}
INTERVAL_METHOD = (f"{INTERVAL_PROBABILITY:.0%} intervals: generalised least squares on the harmonics of the runs minus their baseline "
                   "(weights: measured noise plus the session scatter the fit leaves, per harmonic), HC2 standard errors with "
                   "Bell-McCaffrey degrees of freedom")
#: what the intervals add with a --repeat pair, and without one
SESSION_CHANGE_COUNTED = ("plus the session change of the payload's shape that the --repeat pair reads (one degree of freedom); coverage "
                          "shown on simulated pairs at the measured noise, session scatter and session change")
SESSION_CHANGE_NOT_COUNTED = "no session change of the payload's shape: without a --repeat pair nothing measures it"


def _pairs(pair_runs, differences, columns) -> list[Pair]:
    """The runs minus their baselines on the harmonics; `columns(features)` the
    payload's columns on a run with it, none on the --repeat pair (it measures the session scatter)."""
    n = None
    built = []
    for run in pair_runs:
        x = run.state.in_band(columns(run)) if run in differences else None
        n = x.shape[-1] if x is not None else n
        built.append((run, x))
    return [make_pair(run.name, run.state, run.baseline.state, run.residual, x, n) for run, x in built]


def _common_variance(candidate_pairs: list[list[Pair]], n_differences: int, offset_joints) -> list[np.ndarray]:
    """One variance model to compare links by: the --repeat pair's session
    scatter (no payload there) plus each pair's noise; without it, what every
    candidate's columns together leave (the largest model's, as Mallows' Cp
    takes its variance). What no payload leaves counted the payload's own
    efforts as scatter and left every link as good as another (a payload on
    the insertion carriage was read on yaw)."""
    first = candidate_pairs[0]
    if len(first) > n_differences:
        session = session_variance(first[-1], offset_joints)
        return [session + p.noise for p in first]
    union = [replace(pair, X=np.concatenate([pairs[i].X for pairs in candidate_pairs], axis=-1)) for i, pair in enumerate(first)]
    return fit_payload(union, offset_joints).variance


def link_costs(candidates: list, pair_runs, differences, features_of, offset_joints) -> np.ndarray:
    """BIC of each candidate's first moment (and J1's path, `FirstMomentPayload`)
    under one variance model: the weighted residual plus log(rows) per
    parameter the efforts determine."""
    pairs = [_pairs(pair_runs, differences, lambda r, e=e: e.first_moment_columns(features_of(r))) for e in candidates]
    common = _common_variance(pairs, len(differences), offset_joints)
    costs = []
    for candidate_pairs in pairs:
        fit = fit_payload(candidate_pairs, offset_joints, common)
        costs.append(fit.weighted_rss + fit.rank * np.log(fit.rows))
    return np.array(costs)


@dataclass(frozen=True)
class Fits:
    """One payload design fitted on the runs minus their baseline (`main`) and
    on the --repeat pair alone (`session`: what two sessions read as that payload; None without --repeat)."""

    main: PayloadFit
    session: PayloadFit | None


def _repeat_alone(repeat_run, columns: np.ndarray, offset_joints) -> PayloadFit:
    """The payload design fitted on the --repeat pair alone (two sessions without the payload)."""
    x = repeat_run.state.in_band(columns)
    return fit_payload([make_pair(repeat_run.name, repeat_run.state, repeat_run.baseline.state, repeat_run.residual, x, x.shape[-1])],
                       offset_joints)


def _report_quantities(fits: Fits, maps: dict[str, np.ndarray], not_seen: dict[str, str]) -> tuple[dict, dict, dict]:
    """Each quantity with its interval where the efforts determine it, else
    None and the reason (`not_seen`: reasons known beforehand, by key); and
    what the --repeat pair alone reads of each (None without it)."""
    report, reasons, session = {}, {}, {}
    for key, jacobian in maps.items():
        value, interval, read, spread = interval_with_session(fits.main, fits.session, jacobian)
        determined = fits.main.determined(jacobian) & (key not in not_seen)
        values = [float(v) if d else None for v, d in zip(value, determined)]
        intervals = [[float(lo), float(hi)] if d else None for lo, hi, d in zip(*interval, determined)]
        reads = [None] * len(values) if read is None else [float(v) if d else None for v, d in zip(read, determined)]
        scalar = key in SCALAR_QUANTITIES
        report[key], report[f"{key}_interval"] = (values[0], intervals[0]) if scalar else (values, intervals)
        session[key] = reads[0] if scalar else reads
        if not determined.all():
            reasons[key] = not_seen.get(key, "the efforts do not determine it (the runs' motion does not excite it)")
        if spread is not None:  # the session change's spread, as the interval counts it
            swamp(report, key, spread, reasons)
    return report, reasons, session


def _rigid_report(arm, effect, fit_with) -> tuple[dict, dict, PayloadFit, dict, dict]:
    """A rigid body on the effect's link: its quantities, the reasons of those
    not determined, the fit, the maps and what the --repeat pair reads."""
    gravity = _gravity_at_zero(arm, effect.link_key)
    fits = fit_with(lambda r: rigid_payload_columns(r, effect.link_key))
    maps = linear_map(lambda p: _quantities(arm, effect, rigid_as_first_moment(p), gravity), 2 * BODY_PARAMETERS)
    not_seen = {} if mass_seen_by_gravity(arm, effect.link_key) else {"mass_kg": MASS_NOT_SEEN}
    quantities, reasons, session = _report_quantities(fits, maps, not_seen)
    return quantities, reasons, fits.main, maps, session


#: a first moment "as a body on" a link means something else on another link
FRAME_DEPENDENT = "first_moment_base_at_q0_kg_m"


def _span_ties(report: dict, reasons: dict, tied: list[tuple[object, dict]], effect) -> None:
    """Every interval widened to hold the tied links' intervals; a quantity one
    of them does not determine (or reads in another frame) is not determined."""
    for key in [k for k in report if k.endswith("_interval")]:
        name = key[: -len("_interval")]
        scalar = name in SCALAR_QUANTITIES
        mine = [report[key]] if scalar else report[key]
        for other_effect, other in tied:
            theirs = [other[key]] if scalar else other[key]
            if name == FRAME_DEPENDENT and other_effect.reference_key != effect.reference_key:
                theirs = [None] * len(theirs)
            for k, (a, b) in enumerate(zip(mine, theirs)):
                if a is None:
                    continue
                if b is None:
                    mine[k] = None
                    reasons[name] = f"a payload on {other_effect.link_name} explains the efforts as well and does not determine it the same way"
                else:
                    mine[k] = [min(a[0], b[0]), max(a[1], b[1])]
        report[key] = mine[0] if scalar else mine
        values = [report[name]] if scalar else report[name]
        values = [v if i is not None else None for v, i in zip(values, mine)]
        report[name] = values[0] if scalar else values


def _at_position(arm, at, fit_with) -> tuple[dict, dict]:
    """A point mass at the given position: its mass and gravity efforts, with
    intervals; and what the --repeat pair reads of them."""
    fits = fit_with(lambda r: point_payload_columns(r, at.link_key, at.position))
    gravity = _gravity_at_zero(arm, at.link_key)
    unit = point_mass_parameters(1.0, at.position)[:FIRST_MOMENT_COLUMNS]

    def quantities(p):
        yaw_path = p[1:1 + FIRST_MOMENT_COLUMNS]
        return {"mass_kg": p[0], "gravity_efforts_at_q0": _gravity_efforts(gravity[:, :, :FIRST_MOMENT_COLUMNS], p[0] * unit, yaw_path),
                "q1_gravity_slope_at_q0_nm_per_rad": _yaw_slope(gravity, yaw_path)}

    values, reasons, session = _report_quantities(fits, linear_map(quantities, 1 + BODY_PARAMETERS), {})
    return {"link": at.link_name, "position_m": at.position.tolist(), **values, "not_determined": reasons}, session


def periodic_payload_report(arm, candidates, runs, repeat_run, features_of, offset_joints, at=None, selected=None) -> dict:
    """The payload read from the runs minus their baseline on the harmonics (and
    the --repeat pair for the session scatter): the link of the lowest BIC among
    the FirstMomentPayload `candidates`, intervals spanning the tied links'; with
    `at` (a PayloadAtPosition), the mass at that position; `selected`: the
    payload the selection over time segments took (named where it differs)."""
    differences = [r for r in runs if r.role is RunRole.DIFFERENCE]
    if not differences:
        raise DvrkDartError("--processing periodic with --baseline: no run has the baseline's motion (a payload needs a run minus its "
                            "baseline of the same motion on the harmonics)")
    repeat = repeat_run if repeat_run is not None and repeat_run.role is RunRole.DIFFERENCE else None
    pair_runs = differences + ([repeat] if repeat is not None else [])

    def fit_with(columns) -> Fits:
        main = fit_payload(_pairs(pair_runs, differences, lambda r: columns(features_of(r))), offset_joints)
        return Fits(main, None if repeat is None else _repeat_alone(repeat, columns(features_of(repeat)), offset_joints))

    costs = link_costs(candidates, pair_runs, differences, features_of, offset_joints)
    best = int(np.argmin(costs))
    effect = candidates[best]
    quantities, reasons, fit, maps, session = _rigid_report(arm, effect, fit_with)
    tied_effects = [e for e, c in zip(candidates, costs) if e is not effect and c - costs[best] <= TIED_BIC]
    _span_ties(quantities, reasons, [(e, _rigid_report(arm, e, fit_with)[0]) for e in tied_effects], effect)
    # the payload against none: its gravity signature the efforts determine (first moment, J1's slope)
    signature = np.vstack([maps[k][fit.determined(maps[k])] for k in ("first_moment_base_at_q0_kg_m", "q1_gravity_slope_at_q0_nm_per_rad")])
    p_value = fit.p_value(signature)
    groups = sorted({e.group for e in [effect, *tied_effects]})
    report = {"link": effect.link_name, "link_key": effect.link_key, "group": effect.group, **equivalents_of(arm.model, effect.equivalent_links), "tied_links": [e.link_name for e in tied_effects], "group_determined": len(groups) == 1, "tied_groups": groups,
              "link_bic": dict(zip((e.link_name for e in candidates), costs.tolist())),
              "selection_link": selected.link_name if selected is not None else None,
              **quantities, "not_determined": reasons,
              "first_moment_reference_link": arm.model.links[effect.reference_key].name,
              "mass_identified": quantities["mass_kg"] is not None, "position_m": None,
              "payload_p_value": p_value, "found": bool(p_value < PAYLOAD_TEST_LEVEL),
              "pairs": [r.name for r in pair_runs], "session_pair": repeat.name if repeat is not None else None,
              "left_out": [r.name for r in runs if r.role is RunRole.OTHER_MOTION],
              "interval_method": f"{INTERVAL_METHOD}, {SESSION_CHANGE_COUNTED if repeat is not None else SESSION_CHANGE_NOT_COUNTED}"}
    moment = report["first_moment_base_at_q0_kg_m"]
    report["pitch_shaft_offsets_of_first_moment_m_kg"] = pitch_shaft_offsets(arm, np.asarray(moment)) if None not in moment else None
    if at is not None:
        report["payload_at"], session_at = _at_position(arm, at, fit_with)
        report["position_m"] = at.position.tolist()
        session["mass_kg_at_position"] = session_at["mass_kg"]
    if repeat is None:  # nothing measures a session's change of these joints' gravity shape: their intervals do not hold it
        for j in np.flatnonzero(np.asarray(offset_joints)[:3]):
            effort_not_determined(report, int(j), SESSION_SHAPE_NOT_COUNTED)
        if at is not None:
            position_figures_without_repeat(report["payload_at"])
    if repeat is not None:
        # what the --repeat pair alone reads as this payload: a session change of its shape, counted in every interval
        report["session_change_as_payload"] = {key: session[key] for key in ("first_moment_base_at_q0_kg_m", "gravity_efforts_at_q0",
                                                                             "mass_kg_at_position") if key in session}
    report["words"] = _words(report, arm.model)
    return report


def _interval_text(value, interval, unit: str, digits: int = 3, say_zero: bool = False) -> str:
    """A value with its interval; say_zero: an interval that holds zero says so (the value is not told from none)."""
    if value is None:
        return "not determined"
    zero = ", holding zero" if say_zero and interval[0] <= 0.0 <= interval[1] else ""
    return f"{value:+.{digits}f} {unit} ({interval[0]:+.{digits}f} to {interval[1]:+.{digits}f}{zero})"


def j1_sentences(report: dict, model) -> list[str]:
    """The sentences that quote the gravity efforts at q = 0 and J1's slope, with their intervals."""
    slope = _interval_text(report["q1_gravity_slope_at_q0_nm_per_rad"], report["q1_gravity_slope_at_q0_nm_per_rad_interval"], "N·m/rad",
                           say_zero=True)
    return [J1_EFFORTS_SENTENCE + ", ".join(f"{j} {_interval_text(v, i, model.effort_unit(j), say_zero=True)}" for j, v, i in
                                            zip(JOINT_NAMES[:3], report["gravity_efforts_at_q0"], report["gravity_efforts_at_q0_interval"])) + ".",
            f"{J1_SLOPE_SENTENCE}{slope} at q = 0 (J1's own path: how the real yaw axis lies relative to gravity)."]


def _words(report: dict, model) -> list[str]:
    words = []
    if not report["found"]:
        words.append(f"No payload stands out from the session-to-session scatter (p = {report['payload_p_value']:.2g}, not under the test's "
                     f"level {PAYLOAD_TEST_LEVEL:g}): in the payload's shape, what the runs differ by from their baseline is what two "
                     "sessions differ by.")
    # where none stands out, the link is where one would be, not a finding (it read as one beside "no payload stands out")
    chosen_words = "The efforts choose a payload on" if report["found"] else "Were there one, the efforts would put it on"
    words.append(f"{chosen_words} {report['link']} ({report['group']})" + (
        f"; payloads on {', '.join(report['tied_links'])} explain them as well (within {TIED_BIC:g} of BIC), and every interval "
        "spans theirs" if report["tied_links"] else "") + ".")
    chosen = {report["link"], *report["tied_links"]}
    if report["selection_link"] is not None and report["selection_link"] not in chosen:
        words.append(f"The selection over time segments of the runs' residual (session changes included) took a payload on "
                     f"{report['selection_link']}, which the simulation after carries; weighed against the session scatter on the "
                     f"harmonics, the efforts choose {report['link']}: the numbers below are {report['link']}'s.")
    moment, intervals = report["first_moment_base_at_q0_kg_m"], report["first_moment_base_at_q0_kg_m_interval"]
    words.append("First moment m·c (base frame, q = 0, as a body on " + report["first_moment_reference_link"] + "): "
                 + ", ".join(f"{a} {_interval_text(v, i, 'kg·m', 4, say_zero=True)}" for a, v, i in zip("xyz", moment, intervals)) + ".")
    words += j1_sentences(report, model)
    at = report.get("payload_at")
    if report["mass_kg"] is None:
        reason = report["not_determined"].get("mass_kg", "")
        at_size = at and at.get("mass_kg") is not None and at["mass_kg_interval"][0] > 0.0  # the position's mass is a size
        alone = " by the efforts alone (the position below gives one)" if at_size else ""
        words.append(f"The mass is not determined{alone}: {reason}" + (f": {PAYLOAD_AT_HINT}." if reason == MASS_NOT_SEEN and not at else "."))
    else:
        words.append(f"Mass {_interval_text(report['mass_kg'], report['mass_kg_interval'], 'kg')}.")
    if at:
        words.append(at_position_sentence(at, _interval_text(at['mass_kg'], at['mass_kg_interval'], 'kg')))
    words.append(f"Intervals: {report['interval_method']}.")
    if report["left_out"]:
        words.append(f"Left out of this fit: {', '.join(report['left_out'])} (another motion than the baseline's: the model's error "
                     "changes with the speed by more than a small weight's signal; a baseline of its own motion would let it in).")
    session = report.get("session_change_as_payload")
    if session:
        j2 = session["gravity_efforts_at_q0"][1]
        size = "" if j2 is None else f" (J2's effort at q = 0 {j2:+.3f} N·m)"
        words.append(f"The --repeat pair alone (two sessions, no weight) reads as a payload of its own{size}: a session change of the payload's shape. Every interval counts "
                     "it, known to one degree of freedom from one pair: where it is large the intervals are wide.")
    swamped = [key for key, reason in report["not_determined"].items() if reason == SWAMPED]
    if swamped:
        words.append(f"Not determined: {', '.join(swamped)}: {SWAMPED}.")
    if report["session_pair"] is None:
        words.append("Without --repeat (the baseline's motion in another session) the session scatter is read only from what the "
                     "payload leaves: " + WITHOUT_REPEAT)
    return words

"""The diagnosis as a reader sees it: the answer in one sentence, effects by
their plain names, the ranked effects as bars of explained share, and
diagnosis.html in the report's page style (io/html.py).

Everything here reads a `diagnosis.json` dict: the page can be rebuilt from
the file alone (the report does so for the withheld-data diagnoses)."""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from dvrk_dart.io.html import STYLE, fmt
from dvrk_dart.diagnosis.payload.parameter_band import band_sentence
from dvrk_dart.diagnosis.output.wording import explanation
from dvrk_dart.model.joints import JOINT_NAMES

#: the joints the answer sentence speaks of (the arm's main joints)
ANSWER_JOINTS = 3
#: what is left counts as at the floor below this multiple of the session floor
AT_FLOOR_RATIO = 1.5
#: effects shown in the ranked table (the rest are in diagnosis.json)
SHOWN_EFFECTS = 12
#: the figure of the residual over one period (diagnose writes it; the page shows it first)
PERIOD_FIGURE = "residual_over_one_period"

_KIND_WORDS = {
    "offset": "a constant effort offset on {joints}",
    "armature": "extra reflected motor inertia on {joints}",
    "gravity_tilt": "gravity tilted against the model (base not level)",
    "time_shift": "efforts recorded late against the positions",
    "counterweight_transmission": "an error in the counterweight cable's transmission to {joints}",
}


#: an effect's role in a diagnosis with a baseline (diagnosis.json `effects[].role`)
_ROLE_WORDS = {"finding": "finding", "common_model_error": "model error common to the runs and their baseline"}


def _unit(result: dict, joint: str) -> str:
    """The effort unit of `joint` on the diagnosed arm (diagnosis.json `units`)."""
    return result["units"][JOINT_NAMES.index(joint)]


def plain_name(entry: dict) -> str:
    """An effect of diagnosis.json's `effects` in words (its `name` is the
    library's identifier, e.g. friction_q3_presliding0.0001)."""
    name, kind, joints = entry["name"], entry.get("kind", ""), ", ".join(entry.get("joints", ()))
    reversal = (entry.get("parameters") or {}).get("reversal")
    how = "" if reversal in (None, "sign") else f", reversing over {reversal.removeprefix('Dahl over ').split(',')[0]}" + (
        " (pre-sliding)" if reversal.startswith("Dahl") else "")
    if kind == "friction":
        if name.startswith("position_friction"):
            return f"friction of {joints} that changes along its range{how}"
        if name.startswith("presliding_of_"):
            return f"the identified friction of {joints} reversing gradually{how}"
        if len(entry.get("joints", ())) > 1:
            return f"friction of the coupled joints {joints}{how}"
        return f"{'Stribeck ' if name.startswith('stribeck') else ''}friction of {joints}{how}"
    if kind == "elastic":
        return f"{'a torsion spring' if name.startswith('torsion') else 'cable elasticity'} on {joints}"
    if kind in ("payload", "payload_at_position"):
        link = name.split("_on_")[-1].split("_at_")[-1]
        return f"a payload on the {link} link"
    return _KIND_WORDS.get(kind, name).format(joints=joints)


def _size_words(entry: dict) -> str:
    size, units = entry.get("size"), entry.get("units") or {}
    unit = next(iter(units.values()), "")
    return "" if not isinstance(size, (int, float)) else f", size {size:.3g} {unit}".rstrip()


def _payload_size_words(payload: dict) -> str:
    """The payload's mass where the efforts determine it, at the hand position
    when one was given, else its gravity effort on J2 at q = 0."""
    at = payload.get("payload_at") or {}
    if at.get("mass_kg") is not None:
        return f", {at['mass_kg']:.3g} kg at the hand position"
    if payload.get("mass_identified") and payload.get("mass_kg") is not None:
        return f", {payload['mass_kg']:.3g} kg"
    efforts = payload.get("gravity_efforts_at_q0")
    return "" if not efforts or efforts[1] is None else f", {efforts[1]:+.3g} N·m on q2 at q = 0"


def repeatable_share(before, after, floor):
    """The share of a gap's repeatable part (above the session floor, in
    squares) that is gone after: 1 - (after^2 - floor^2) / (before^2 - floor^2),
    per joint; NaN where nothing repeatable was there."""
    before, after, floor = (np.asarray(x, dtype=float) for x in (before, after, floor))
    repeatable = np.square(before) - np.square(floor)
    left = np.maximum(np.square(after) - np.square(floor), 0.0)
    return np.where(repeatable > 0.0, 1.0 - left / np.where(repeatable > 0.0, repeatable, 1.0), np.nan)


def share_words(share: float | None) -> str:
    """A repeatable_share in words: a percentage, or why there is none."""
    return "not determined (no repeatable gap above the session floor)" if share is None or math.isnan(share) else f"{share:.0%}"


def _row_share(split_row: dict) -> float | None:
    """repeatable_share of a row of diagnosis.json's gap_split (None without a floor)."""
    if split_row.get("session_floor") is None:
        return None
    share = float(repeatable_share(split_row["before"], split_row["after"], split_row["session_floor"]))
    return None if math.isnan(share) else share


def beyond_identified_sentence(result: dict) -> str:
    """What the data show beyond the identified model, first: its gap on the
    held-out runs and what the diagnosis's simulation leaves ('' without held-out runs)."""
    bar = result.get("identified_model_gap_holdout")
    combined = result.get("one_configuration")
    after, what = ((combined["gap_holdout"], "one DART configuration: the selected effects, J3's terms and the pitch-angle loads")
                   if combined else ((result.get("gap_after") or {}).get("holdout"), "the selected effects simulated in DART"))
    if not bar or not after:
        return ""
    shown = [j for j in range(ANSWER_JOINTS) if bar[j] is not None and after[j] is not None]
    gaps = ", ".join(f"{JOINT_NAMES[j]} {bar[j]:.3g} -> {after[j]:.3g} {result['units'][j]}" for j in shown)
    processing = result.get("processing") or {}
    band = f"{processing.get('processing')}" + (f", {processing['harmonics']} harmonics" if processing.get("harmonics") else "")
    return f"Beyond the identified model ({Path(str((result.get('params') or {}).get('path', 'params.json'))).name}), on the held-out runs ({band}): {gaps} ({what}). "


def answer_sentence(result: dict) -> str:
    """The diagnosis in one sentence: the main effect (what, where, how big),
    how far the gap shrinks on the main joints (held-out runs when there are),
    the share of the repeatable gap removed, and what is left against the
    session floor when a --repeat measured it."""
    split = "holdout" if (result.get("gap_after") or {}).get("holdout") else "train"
    shown = [j for j in range(ANSWER_JOINTS) if result["gap_before"][split][j] is not None]  # the joints the runs recorded
    before, after = ([result[key][split][j] for j in shown] for key in ("gap_before", "gap_after"))
    joints = [JOINT_NAMES[j] for j in shown]
    selected = list(result["selection"]["selected"])
    entries = {e["name"]: e for e in result.get("effects", [])}
    payload, mismatch = result.get("payload"), result.get("gravity_mismatch")
    if result.get("payload_not_distinguished"):  # the payload-shaped fit is no finding: the other effects lead
        selected = [n for n in selected if not n.startswith("payload")] or selected
    # the effect selected first (the largest gain) leads, a payload as any other
    payload_first = bool(selected) and selected[0].startswith("payload")
    if payload_first and payload:
        lead = f"a payload on {payload['link']} ({payload['group']}{_payload_size_words(payload)})"
    elif payload_first and mismatch:  # no baseline: the same fit is the arm's gravity, not something attached
        efforts = mismatch.get("gravity_efforts_at_q0") or [None, None]
        size = "" if efforts[1] is None else f", {efforts[1]:+.3g} N·m on q2 at q = 0"
        lead = f"a gravity mismatch on {mismatch['link']} ({mismatch['group']}{size}: the arm's mass distribution against the parameters)"
    elif selected:
        first = entries.get(selected[0], {"name": selected[0]})
        lead = f"{plain_name(first)} ({selected[0]}{_size_words(first)})"
    else:
        lead = "no effect"
    others = selected[1:]
    more = f" with {len(others)} more effect{'s' if len(others) > 1 else ''} ({', '.join(others[:2])}{', ...' if len(others) > 2 else ''})" if others else ""
    gaps = "; ".join(f"{j} {b:.3g} -> {a:.3g} {_unit(result, j)}" for j, b, a in zip(joints, before, after))
    where = "on the held-out runs" if split == "holdout" else "on the training runs"
    words = (result.get("explanation") or explanation(result["gap_before"], result["gap_after"], list(JOINT_NAMES),
                                                        [e for e in result.get("effects", []) if e["name"] in selected]))["words"]
    if result.get("payload_not_distinguished"):
        where = "no payload is distinguished from none (every interval contains zero); " + where
    beyond = beyond_identified_sentence(result)  # what the data show beyond the identified model, first
    if beyond and result.get("diagnosis_base", "inertial") == "inertial":
        where += ", against the simulation of the identified inertia alone"
    if lead == "no effect":
        sentence = beyond + f"The gap is not explained: no effect of the library was selected; {where}, {gaps}"
    elif words == "not explained":
        sentence = beyond + f"The gap is not explained: the best effects, {lead}{more}, remove less than a fifth of it: {where}, {gaps}"
    else:
        sentence = beyond + f"The gap is {words} by {lead}{more}: {where}, {gaps}"
    by_joint = {r.get("joint", JOINT_NAMES[i]): _row_share(r) for i, r in enumerate((result.get("gap_split") or {}).get("joints") or [])}
    shares = [by_joint.get(j) for j in joints] if by_joint else []
    if shares and any(s is not None for s in shares):
        sentence += "; removed: " + ", ".join(f"{j} {'—' if s is None else f'{s:.0%}'}" for j, s in zip(joints, shares)) + " of the repeatable gap"
    floor = result.get("session_floor")
    if floor is None:
        return sentence + "." + _refit_clause(result) + _insertion_clause(result)
    above = [j for j, a, f in zip(joints, after, floor) if a > AT_FLOOR_RATIO * f]
    return sentence + (f". What is left is above the session floor on {', '.join(above)}: an unmodelled effect remains there."
                       if above else ". What is left is at the session floor: no fixed effect can remove more.") + _refit_clause(result) + _insertion_clause(result)


def _refit_clause(result: dict) -> str:
    """With --refit: the joints whose held-out gap the refit at least halves (the published fit's bias)."""
    refit = result.get("refit")
    if not refit:
        return ""
    pairs = list(zip(JOINT_NAMES[:ANSWER_JOINTS], refit["gap_holdout_arm_params"], refit["gap_holdout_refit"]))
    biased = [f"{j} {b:.3g} -> {a:.3g} {_unit(result, j)}" for j, b, a in pairs if a * a <= 0.5 * b * b]
    if not biased:
        return " Refitting the identified parameters on the training runs does not halve any held-out gap in squares."
    return f" The published fit's bias: the identified parameters refitted on the training runs leave {'; '.join(biased)} on the held-out runs."


def _row(cells, tag="td") -> str:
    return "<tr>" + "".join(f"<{tag}>{c}</{tag}>" for c in cells) + "</tr>"


def _bar(share) -> str:
    """An explained share as a bar (CSS only) with its number."""
    if share is None or math.isnan(share):
        return "-"
    width = max(0.0, min(1.0, share)) * 100
    return (f"<div style='display:inline-block;width:8em;background:#eee;vertical-align:middle'>"
            f"<div style='width:{width:.1f}%;background:#4a7fb5;height:0.8em'></div></div> {share:.1%}")


def _gap_table(result: dict) -> list[str]:
    parts = ["<table>", _row(["gap (RMS measured - simulated)", *(f"{j} ({_unit(result, j)})" for j in JOINT_NAMES)], "th")]
    for key in ("gap_before", "gap_after"):
        for split in ("train", "holdout"):
            values = (result.get(key) or {}).get(split)
            if values is not None:
                parts.append(_row([f"{key.replace('gap_', '')}, {split}", *("not measured" if v is None else fmt(v) for v in values)]))
    return parts + ["</table>", f"<p class='note'>after: {html.escape(str(result.get('gap_after_source', '')))}</p>"]


#: what the joint names mean (the identification model's coordinates)
JOINT_WORDS = ("Joints: q1 yaw, q2 pitch, q3 insertion, q4 tool roll; q5, q6, q7 are the wrist pitch, wrist yaw and jaw "
               "motor coordinates (the dVRK's wrist values through the instrument's coupling), not the wrist joints themselves.")


def _effects_table(result: dict) -> list[str]:
    """The ranked effects: plain name, explained share as a bar; the parameters folded away."""
    e = html.escape
    effects = result.get("effects", [])
    # every selected effect, then the best of the others up to SHOWN_EFFECTS rows
    shown = [x for x in effects if x.get("selected")]
    shown += [x for x in effects if not x.get("selected")][:max(0, SHOWN_EFFECTS - len(shown))]
    parts = [f"<p class='note'>{len([x for x in effects if x.get('selected')])} effects selected, all listed; {len(shown)} of "
             f"{len(effects)} candidates shown. {JOINT_WORDS}</p>", "<table>",
             _row(["rank", "effect", "identifier", "joints", "selected", "role", "explained (train)", "explained (held out)"], "th")]
    for effect in shown:
        rank = effects.index(effect) + 1
        frac = effect.get("explained_fraction", {})
        parts.append(_row([rank, e(plain_name(effect)), f"<code>{e(effect['name'])}</code>", e(", ".join(effect.get("joints", []))),
                           "yes" if effect.get("selected") else "no", _ROLE_WORDS.get(effect.get("role"), "finding"),
                           _bar(frac.get("train")), _bar(frac.get("holdout"))]))
    parts.append("</table>")
    dump = "".join(_row([f"<code>{e(effect['name'])}</code>", e(", ".join(
        f"{k} = {fmt(v) if isinstance(v, (int, float)) else v} {(effect.get('units') or {}).get(k, '')}".rstrip()
        for k, v in effect.get("parameters", {}).items()))]) for effect in shown)
    return parts + [f"<details><summary>fitted parameters of the ranked effects</summary><table>{_row(['effect', 'parameters'], 'th')}{dump}</table></details>"]


def diagnosis_html(result: dict, image_sources: list[str], title: str) -> str:
    """An HTML fragment: the answer in one sentence, the residual over one
    period, gaps before/after per joint, the ranked effects, the payload, and
    the other figures at `image_sources`."""
    e = html.escape
    period = [s for s in image_sources if Path(s).stem == PERIOD_FIGURE]
    parts = [f"<h3>{e(title)}</h3>", f"<p class='summary'>{e(answer_sentence(result))}</p>"]
    parts += [f"<figure><img src='{e(s)}' alt='{PERIOD_FIGURE}'><figcaption>The residual (measured - simulated) over one period of the "
              "run the answer speaks of, before and after the selected effects; the band is ± the session floor.</figcaption></figure>" for s in period]
    parts += _gap_table(result) + _refit_html(result) + _insertion_html(result) + _effects_table(result)
    parts += _split_and_nuisance_html(result) + _band_html(result) + _payload_html(result)
    for source in (s for s in image_sources if s not in period):
        parts.append(f"<figure><img src='{e(source)}' alt='{e(Path(source).stem)}'><figcaption>{e(Path(source).stem)}</figcaption></figure>")
    return "\n".join(parts)


def _insertion_clause(result: dict) -> str:
    """On a PSM's periodic held-out runs: what J3's repeatable gap is made of, simulated."""
    study = result.get("insertion_terms")
    if not study:
        return ""
    combined = result.get("one_configuration")
    together = "" if not combined else (
        "; with the effects above and the loads the pitch angle sets on q1 and q2, in one simulation: "
        + ", ".join(f"{name} {gap:.3g} {_unit(result, name)}" for name, gap in zip(JOINT_NAMES[:3], combined["gap_holdout"])))
    return (f" J3's repeatable gap is friction along the stroke, in ddq3·sign(dq3) and a load in q2: simulated, they leave J3 at "
            f"{study['gap_holdout_simulated']:.3g} N on the held-out runs (identified model {study['gap_holdout_identified']:.3g} N){together}.")


def _insertion_html(result: dict) -> list[str]:
    """What J3's repeatable gap is made of (`insertion_terms`) and the one
    configuration (`one_configuration`), in words."""
    return [f"<p>{html.escape(result[key]['words'])}</p>" for key in ("insertion_terms", "one_configuration") if result.get(key)]


def _refit_html(result: dict) -> list[str]:
    """The refit of the identified parameters (`--refit`), in words."""
    refit = result.get("refit")
    if not refit:
        return []
    return [f"<p>{html.escape(refit['words'])} Parameters: <code>{html.escape(refit['params']['path'])}</code>.</p>"]


def diagnosis_page(result: dict, image_sources: list[str], title: str) -> str:
    """diagnosis.html: the fragment as a page in the report's style."""
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
            + diagnosis_html(result, image_sources, title) + "</body></html>\n")


def _value_interval(value, interval) -> str:
    """A value with its interval; 'not determined' where the data do not give one."""
    if value is None:
        return "not determined"
    return fmt(value) + ("" if not interval or None in interval else f" ({fmt(interval[0])} .. {fmt(interval[1])})")


def _payload_html(result: dict) -> list[str]:
    e = html.escape
    payload = result.get("payload")
    if payload and payload.get("words"):  # the identifiable quantity first (first_moment payload)
        g, gi = payload["gravity_efforts_at_q0"], payload["gravity_efforts_at_q0_interval"]
        return ["<p>" + " ".join(e(w) for w in payload["words"]) + "</p>", "<table>",
                _row(["payload at q = 0", *(f"{j} ({_unit(result, j)})" for j in JOINT_NAMES[:3])], "th"),
                _row(["gravity effort (interval)", *(_value_interval(v, i) for v, i in zip(g[:3], gi[:3]))]), "</table>"]
    if not payload:
        return []
    text = (f"payload: {payload['mass_kg']:.3f} kg on {e(payload['link'])} ({e(payload['group'])}), "
            f"at {[round(x, 3) for x in payload['position_m']]} m in the link frame")
    if payload.get("equivalent_links"):
        text += f"; the efforts cannot tell it from the same payload on {e(', '.join(payload['equivalent_links']))}"
    if payload.get("mass_profile"):
        lo, hi = payload["mass_profile"]["mass_interval_kg"]
        pinned = "identified" if payload["mass_profile"]["identifiable"] else "not identified by these runs"
        text += f"; cross-validated mass interval {lo:.3f}-{hi:.3f} kg ({pinned})"
    return [f"<p>{text}</p>"]


def _split_and_nuisance_html(result: dict) -> list[str]:
    """The gap split per joint (explained, session-to-session, left over) and the per-run nuisance offsets."""
    e = html.escape
    parts = []
    split = (result.get("gap_split") or {}).get("joints") or []
    if split and split[0].get("session_to_session") is not None:
        parts.append(f"<p>Gap of the {e(result['gap_split']['runs'])} runs split per joint (RMS, adding in squares): explained by the selected "
                     f"effects, session-to-session (floor from two sessions of the same trajectory, {e(str(result.get('repeat')))}: no fixed "
                     "effect can remove it), left over; and the share of the repeatable gap (above the floor) the effects remove.</p>")
        parts.append("<table>" + _row(["joint", "before", "explained", "session-to-session", "left over", "after", "repeatable gap removed"], "th"))
        for r in split[:ANSWER_JOINTS]:
            parts.append(f"<tr><td>{r['joint']} ({e(r['unit'])})</td>" + "".join(f"<td>{r[k]:.4f}</td>" for k in ("before", "explained", "session_to_session", "left_over", "after"))
                         + f"<td>{_bar(_row_share(r))}</td></tr>")
        parts.append("</table>")
    if result.get("nuisance_offset_joints"):
        parts.append(f"<p>{e(offset_joints_sentence(result['nuisance_offset_joints']))}</p>")
    for run, offsets in (result.get("nuisance_offsets") or {}).items():
        parts.append(f"<p>nuisance offsets of {e(run)} (a constant per run, fitted, not an effect): "
                     + ", ".join(f"{j} {v:+.3f}" for j, v in list(offsets.items())[:3]) + "</p>")
    return parts


def offset_joints_sentence(offset_joints: dict) -> str:
    joints = ", ".join(offset_joints["joints"]) or "none"
    return (f"Joints whose constant effort moves between sessions ({offset_joints['source']}): {joints}. A run minus its baseline "
            "has a nuisance offset on these only; a run of another motion has one on every joint.")


def _band_html(result: dict) -> list[str]:
    """Per joint: is the measured run inside the parameters' uncertainty band?"""
    band = result.get("parameter_band")
    if band is None:
        return []
    e = html.escape
    rows = "".join(f"<tr><td>{j} ({e(_unit(result, j))})</td><td>{band['measured_inside_band_fraction'][j]:.3f}</td>"
                   f"<td>{band['rms_measured_outside_band'][j]:.4f}</td><td>{'outside' if j in band['joints_outside_band'] else 'inside'}</td></tr>"
                   for j in JOINT_NAMES[:3])
    return [f"<p>{e(band_sentence(result))}. Rule: {e(band['rule'])}. Parameters: {e(str(band['parameters']))}.</p>",
            "<table><tr><th>joint</th><th>measured inside the 5-95 % band</th><th>RMS outside the band</th><th>verdict</th></tr>",
            rows, "</table>"]

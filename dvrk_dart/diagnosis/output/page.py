"""diagnosis.html: the diagnosis as a reader sees it, from the templates of
dvrk_dart/templates/diagnosis/ in the report's page style (io/html.py): the
answer in its paragraphs (answer.py), the residual over one period, the gaps
before and after per joint, the ranked effects as bars of explained share,
the gap split, the parameter band and the payload.

Everything here reads a `diagnosis.json` dict: the page can be rebuilt from
the file alone (the report does so for the withheld-data diagnoses)."""

from __future__ import annotations

import math
from pathlib import Path

from markupsafe import Markup

from dvrk_dart.diagnosis.output.answer import _row_share, answer_paragraphs, offset_joints_sentence
from dvrk_dart.diagnosis.output.effect_words import plain_name
from dvrk_dart.diagnosis.output.clauses import ANSWER_JOINTS, effort_unit
from dvrk_dart.diagnosis.payload.parameter_band import band_sentence
from dvrk_dart.io.html import code_cell, fmt, render, table, text_cell
from dvrk_dart.model.joints import JOINT_NAMES

#: effects shown in the ranked table (the rest are in diagnosis.json)
SHOWN_EFFECTS = 12
#: the figure of the residual over one period (diagnose writes it; the page shows it first)
PERIOD_FIGURE = "residual_over_one_period"
#: an effect's role in a diagnosis with a baseline (diagnosis.json `effects[].role`)
_ROLE_WORDS = {"finding": "finding", "common_model_error": "model error common to the runs and their baseline"}

#: what the table's "after" is (diagnosis.json's gap_after_source)
AFTER_WORDS = {"simulation": "every selected effect simulated in DART",
               "simulation+regressor": ("the selected effects simulated in DART; those it has no physics for (not_in_simulation) "
                                        "by their fitted efforts"),
               "regressor": "the selected effects' fitted efforts (no re-simulation)"}


def _bar(share) -> Markup:
    """An explained share as a bar (CSS only) with its number."""
    missing = share is None or math.isnan(share)
    return render("diagnosis/bar.html", share=None if missing else share, width=0.0 if missing else max(0.0, min(1.0, share)) * 100)


#: what the simulation of the gap before simulates (diagnosis.json `diagnosis_base`)
_BASE_WORDS = {"inertial": "the identified inertia", "identified": "every identified term"}


def _gap_table(result: dict) -> Markup:
    """The gaps before and after the selected effects, each row saying what was simulated; on held-out runs
    also the full identified model and the one configuration (the figures the answer's first sentence compares)."""
    base = _BASE_WORDS.get(result.get("diagnosis_base", "inertial"), "the base simulation")
    what = {"gap_before": f"before: {base} only", "gap_after": f"after: {base} + the selected effects"}
    rows = []
    for key in ("gap_before", "gap_after"):
        for split in ("train", "holdout"):
            values = (result.get(key) or {}).get(split)
            if values is not None:
                rows.append([f"{what[key]} ({'held-out' if split == 'holdout' else 'training'} runs)", values])
    rows += [[label, values] for label, values in (
        ("the identified model, every term (held-out runs)", result.get("identified_model_gap_holdout")),
        ("one configuration: effects, J3's terms, pitch loads (held-out runs)", (result.get("one_configuration") or {}).get("gap_holdout")))
        if values is not None]
    cells = [[text_cell(label), *(text_cell("not measured" if v is None else fmt(v)) for v in values)] for label, values in rows]
    return table(["gap (RMS measured - simulated)", *(f"{j} ({effort_unit(result, j)})" for j in JOINT_NAMES)], cells, css="")


def _shown_effects(result: dict) -> list[dict]:
    """Every selected effect, then the best of the others up to SHOWN_EFFECTS."""
    effects = result.get("effects", [])
    shown = [x for x in effects if x.get("selected")]
    return shown + [x for x in effects if not x.get("selected")][:max(0, SHOWN_EFFECTS - len(shown))]


def _effects_tables(result: dict, shown: list[dict]) -> tuple[Markup, Markup]:
    """The ranked effects (plain name, explained share as a bar) and their fitted parameters."""
    effects = result.get("effects", [])
    ranked = [[text_cell(effects.index(e) + 1), text_cell(plain_name(e)), code_cell(e["name"]), text_cell(", ".join(e.get("joints", []))),
               text_cell("yes" if e.get("selected") else "no"), text_cell(_ROLE_WORDS.get(e.get("role"), "finding")),
               text_cell(_bar(e.get("explained_fraction", {}).get("train"))), text_cell(_bar(e.get("explained_fraction", {}).get("holdout")))]
              for e in shown]
    parameters = [[code_cell(e["name"]), text_cell(", ".join(_parameter_words(k, v, (e.get("units") or {}).get(k, ""))
                                                             for k, v in e.get("parameters", {}).items()))] for e in shown]
    held = "held-out runs" if result.get("holdout_runs") else "held-out time segments"
    return (table(["rank", "effect", "identifier", "joints", "selected", "role", "fit's share of the squared gap, alone (train)",
                   f"alone ({held})"], ranked, css=""),
            table(["effect", "parameters"], parameters, css=""))


def _parameter_words(name: str, value, unit: str) -> str:
    """'coulomb = 0.25 N·m'; a flag as yes/no (not 1/0), a dimensionless value without its unit '1'."""
    if isinstance(value, bool):
        return f"{name}: {'yes' if value else 'no'}"
    if isinstance(value, dict) and all(isinstance(why, str) for why in value.values()):  # not_determined: each parameter's reason
        return f"{name}: " + "; ".join(f"{key} ({why})" for key, why in value.items())
    if isinstance(value, list) and len(value) == 2 and all(isinstance(x, (int, float)) for x in value):  # a range: coulomb_within_runs
        return f"{name} = " + " to ".join(fmt(x) for x in value) + ("" if unit in ("", "1") else f" {unit}")
    shown = fmt(value) if isinstance(value, (int, float)) else value
    return f"{name} = {shown} {'' if unit == '1' else unit}".rstrip()


def _split_table(result: dict) -> Markup | None:
    """The gap split per joint (explained, session-to-session, left over), with a floor only."""
    split = (result.get("gap_split") or {}).get("joints") or []
    if not split or split[0].get("session_to_session") is None:
        return None
    rows = [[text_cell(f"{r['joint']} ({r['unit']})"), *(text_cell(f"{r[k]:.4f}") for k in ("before", "explained", "session_to_session", "left_over", "after")),
             text_cell(_bar(_row_share(r)))] for r in split[:ANSWER_JOINTS]]
    return table(["joint", "before", "explained", "session-to-session", "left over", "after", "repeatable gap removed"], rows, css="")


def _floor_words(result: dict) -> str:
    """How the split's floor was made from the repeat pair's (the report gives a pair's floor in several forms)."""
    one = result.get("session_floor")
    rows = (result.get("gap_split") or {}).get("joints") or []
    words = []
    if one and rows and rows[0].get("session_floor") and one[JOINT_NAMES.index(rows[0]["joint"])]:
        if rows[0]["session_floor"] / one[JOINT_NAMES.index(rows[0]["joint"])] > 1.2:  # sqrt(2): not one session's
            words.append("times sqrt(2): runs minus their baseline carry two sessions' deviations")
    offsets = (result.get("nuisance_offset_joints") or {}).get("joints")
    if offsets:
        words.append(f"without the constant each run's offset takes out on {', '.join(offsets)}")
    return "".join(f"; {w}" for w in words)


def _band(result: dict) -> dict | None:
    """Per joint: is the measured run inside the parameters' uncertainty band?"""
    band = result.get("parameter_band")
    if band is None:
        return None
    rows = [[text_cell(f"{j} ({effort_unit(result, j)})"), text_cell(f"{band['measured_inside_band_fraction'][j]:.3f}"),
             text_cell(f"{band['rms_measured_outside_band'][j]:.4f}"), text_cell("outside" if j in band["joints_outside_band"] else "inside")]
            for j in JOINT_NAMES[:3] if band["measured_inside_band_fraction"][j] is not None]
    return {"sentence": band_sentence(result), "rule": band["rule"], "parameters": str(band["parameters"]),
            "table": table(["joint", "measured inside the 5-95 % band", "RMS outside the band", "verdict"], rows, css="")}


def _value_interval(value, interval) -> str:
    """A value with its interval; 'not determined' where the data do not give one."""
    if value is None:
        return "not determined"
    return fmt(value) + ("" if not interval or None in interval else f" ({fmt(interval[0])} .. {fmt(interval[1])})")


def _payload(result: dict) -> tuple[str, Markup | None]:
    """The payload in words, and the table of its gravity efforts at q = 0 (the identifiable quantity) when there is one."""
    payload = result.get("payload")
    if not payload:  # without a baseline, a payload-shaped fit is the arm's gravity against the parameters (if there is a gap)
        unresolved = (result.get("explanation") or {}).get("below_resolution")
        return "" if unresolved else " ".join((result.get("gravity_mismatch") or {}).get("words") or []), None
    if payload.get("words"):
        g, gi = payload["gravity_efforts_at_q0"], payload["gravity_efforts_at_q0_interval"]
        efforts = table(["payload at q = 0", *(f"{j} ({effort_unit(result, j)})" for j in JOINT_NAMES[:3])],
                        [[text_cell("gravity effort (interval)"), *(text_cell(_value_interval(v, i)) for v, i in zip(g[:3], gi[:3]))]], css="")
        return " ".join(payload["words"]), efforts
    profile = payload.get("mass_profile")
    mass = f"{payload['mass_kg']:.3f} kg" if not profile or profile["identifiable"] else \
        f"a mass not identified by these runs (the fit's {payload['mass_kg']:.3f} kg)"
    text = f"payload: {mass} on {payload['link']} ({payload['group']}), at {[round(x, 3) for x in payload['position_m']]} m in the link frame"
    if payload.get("equivalent_links"):
        text += f"; the efforts cannot tell it from the same payload on {', '.join(payload['equivalent_links'])}"
    if profile:
        lo, hi = payload["mass_interval_kg"]
        text += f"; the masses cross-validation cannot tell apart, with the fit's: {lo:.3f}-{hi:.3f} kg"
    return text, None


def diagnosis_html(result: dict, image_sources: list[str], title: str) -> Markup:
    """An HTML fragment (templates/diagnosis/fragment.html): the answer in one
    sentence, the residual over one period, gaps before/after per joint, the
    ranked effects, the payload, and the other figures at `image_sources`."""
    period = [s for s in image_sources if Path(s).stem == PERIOD_FIGURE]
    shown = _shown_effects(result)
    effects_table, parameters_table = _effects_tables(result, shown)
    payload_words, payload_table = _payload(result)
    offset_joints = result.get("nuisance_offset_joints")
    return render("diagnosis/fragment.html", title=title, answer=answer_paragraphs(result), period_figures=period, period_figure=PERIOD_FIGURE,
                  floor_measured=result.get("session_floor") is not None,
                  gap_table=_gap_table(result),
                  gap_after_source=AFTER_WORDS.get(result.get("gap_after_source"), str(result.get("gap_after_source", ""))),
                  refit=result.get("refit"),
                  beyond_words=[result[key]["words"] for key in ("insertion_terms", "one_configuration") if result.get(key)],
                  n_selected=len([x for x in result.get("effects", []) if x.get("selected")]), n_shown=len(shown),
                  n_effects=len(result.get("effects", [])), joint_words=result.get("joint_words", ""), effects_table=effects_table,
                  parameters_table=parameters_table, split_table=_split_table(result), split_runs=(result.get("gap_split") or {}).get("runs"),
                  floor_words=_floor_words(result),
                  repeat=str(result.get("repeat")), offset_joints=offset_joints_sentence(offset_joints) if offset_joints else "",
                  nuisance_offsets=[(run, ", ".join(f"{j} {v:+.3f}" for j, v in list(offsets.items())[:3]))
                                    for run, offsets in (result.get("nuisance_offsets") or {}).items()],
                  band=_band(result), payload_words=payload_words, payload_table=payload_table,
                  other_figures=[(s, figure_caption(Path(s).stem, result)) for s in image_sources if s not in period])


def figure_caption(stem: str, result: dict) -> str:
    """A residual figure's caption (`residual_before_q1`: the stage, the joint, the run, the unit), else its name."""
    stage, _, joint = stem.rpartition("_")
    if stage not in ("residual_before", "residual_after") or joint not in JOINT_NAMES:
        return stem
    when = "the simulation before the selected effects" if stage == "residual_before" else "the simulation with the selected effects"
    run = ((result.get("where") or {}).get("run")) or "the training run"
    return (f"{joint}: the residual (measured - simulated, {effort_unit(result, joint)}) on {run} against {joint}'s position, velocity and "
            f"acceleration, {when}; colour: the velocity's sign.")


def diagnosis_page(result: dict, image_sources: list[str], title: str) -> str:
    """diagnosis.html: the fragment as a page in the report's style."""
    return render("diagnosis/page.html", title=title, fragment=diagnosis_html(result, image_sources, title))

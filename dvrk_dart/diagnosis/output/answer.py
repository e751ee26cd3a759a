"""The diagnosis in words: the answer (beyond the identified model with held-out runs; the main effect, how far
the gap shrinks, what is left against the session floor), effects by their
plain names (the clauses after the main sentence: clauses.py). Everything reads
a `diagnosis.json` dict, so the words can be rebuilt from the file alone."""

from __future__ import annotations

from dvrk_dart.diagnosis.fit.session_floor import AT_FLOOR_RATIO
from dvrk_dart.diagnosis.output.beyond_identified import beyond_identified_sentence, identified_values_words
from dvrk_dart.diagnosis.output.clauses import constants_clause, effort_unit, identified_terms_clause, insertion_clause, main_joints, refit_clause
from dvrk_dart.diagnosis.output.effect_words import plain_name, size_words
from dvrk_dart.diagnosis.output.wording import (EFFORT_RESOLUTION, NOT_DETERMINED, PARTLY_SHARE, explanation, gap_change, joints_apart, percent,
                                                 share_above_floor)
from dvrk_dart.model.joints import JOINT_NAMES

#: an effort at q = 0 below this is round-off, not a size (an MTM mismatch's q2 read +2.36e-19 N·m)
ROUND_OFF_EFFORT = 1e-9


def effort_at_zero_words(efforts: list | None, units: list[str], intervals: list | None = None, every: bool = False) -> str:
    """', +0.25 N·m on q2 at q = 0': a payload's gravity effort at q = 0 on J2
    (where a payload shows most), else on the first of J1..J3 that has one
    (J2 not recorded or not determined); '' when none has. With `intervals`,
    only an effort whose interval excludes zero is a size; when none does, the
    size is said to be not determined. `every`: each of J1..J3's non-zero
    efforts, J2 first (a gravity mismatch's J1 part is part of what it is)."""
    efforts = list(efforts or [])[:3]
    shown = [j for j in (1, 0, 2) if j < len(efforts) and efforts[j] is not None]
    if intervals is not None and any(interval is not None for interval in intervals[:3]):
        shown = [j for j in shown if intervals[j] is not None and not intervals[j][0] <= 0.0 <= intervals[j][1]]
        if not shown:
            return ", size not determined: no gravity effort at q = 0 is told from zero"
    if not shown:
        return ""
    shown = [j for j in shown if abs(efforts[j]) > ROUND_OFF_EFFORT] if every else shown[:1]
    return (", " + ", ".join(f"{efforts[j]:+.3g} {units[j]} on {JOINT_NAMES[j]}" for j in shown) + " at q = 0") if shown else ""


def offsets_words(efforts: list | None, offsets: list | None, units: list[str]) -> str:
    """'; the simulation leaves out the identified offsets (-0.3 N·m on q1), ...': beside a gravity
    mismatch's efforts at q = 0 (J1..J3), the constant the identified model has there and the base
    simulation lacks, which a fit's constant part takes as readily ('' where none)."""
    efforts, offsets = list(efforts or [])[:3], list(offsets or [])
    joints = [j for j in (1, 0, 2) if j < len(efforts) and j < len(offsets) and efforts[j] and offsets[j]]
    if not joints:
        return ""
    listed = ", ".join(f"{offsets[j]:+.3g} {units[j]} on {JOINT_NAMES[j]}" for j in joints)
    return f"; the simulation leaves out the identified offsets ({listed}), which a constant part of these efforts may be"


def _payload_size_words(payload: dict, units: list[str]) -> str:
    """The payload's mass where the efforts determine it, at the hand position
    when one was given, else its gravity effort at q = 0 (effort_at_zero_words)."""
    at = payload.get("payload_at") or {}
    if at.get("link_chosen_by_the_efforts") is False:  # the fit's own size; the hand position's mass assumes another link
        own = _payload_size_words({**payload, "payload_at": None}, units)
        return f"{own}; the hand position is on {at['link']}, a link the efforts do not choose"
    if at.get("mass_kg") is not None:
        interval = at.get("mass_kg_interval")
        if interval is not None and not interval[0] > 0.0:  # a mass that may be none is no size
            return f", its mass at the hand position not determined (interval {interval[0]:.3g} to {interval[1]:.3g} kg)"
        return f", {at['mass_kg']:.3g} kg at the hand position"
    if payload.get("mass_identified") and payload.get("mass_kg") is not None:
        return f", {payload['mass_kg']:.3g} kg"
    return effort_at_zero_words(payload.get("gravity_efforts_at_q0"), units, payload.get("gravity_efforts_at_q0_interval"))


def _row_share(split_row: dict) -> float | None:
    """The rule's share above the floor of a row of diagnosis.json's gap_split (None without a floor, or nothing above it)."""
    if split_row.get("session_floor") is None:
        return None
    return share_above_floor(split_row["before"], split_row["after"], split_row["session_floor"])


def _floor_source(result: dict) -> str:
    """Where the session floor was read when no --repeat gave it: a repeat without the option is the model card's pair
    (`session_floor.card_repeat`)."""
    return "" if result.get("repeat") is None or result.get("repeat_source") == "--repeat" else " of the model card's repeat pair (no --repeat)"


def _in_answer_order(result: dict) -> list[str]:
    """The selected effects as the answer names them: with a baseline the findings (what the runs have and the
    baseline lacks) first, the model errors the runs share with it after (a friction on q7 led a payload study's
    answer); within each, those that explain a joint the answer speaks of (J1..J3) first (an offset of 0.024 N·m on a
    held wrist joint led an answer whose J1 offset of 0.1 N·m came seventh), else the selection's order (a q5
    friction change, 95 % of q5's gap, came after three effects of 10-18 % of J1..J3's floor-level gaps); then the
    largest share of the gap first, as the page's table gives it (a q1 offset that entered with q2's, 23 %, led a
    q3 friction of 33 %); a payload-shaped fit that is no payload, or that stands out from no session scatter, is
    not named first."""
    entries = {e["name"]: e for e in result.get("effects", [])}
    spoken = _spoken_joints(result)

    def share(name: str) -> float:
        return ((entries.get(name) or {}).get("explained_fraction") or {}).get("cross_validated") or 0.0

    selected = sorted(result["selection"]["selected"], key=lambda n: ((entries.get(n) or {}).get("role", "finding") != "finding",
                                                                      not _explains_a_main_joint(entries.get(n) or {}, spoken),
                                                                      -share(n)))
    if result.get("payload_not_distinguished") or (result.get("payload") or {}).get("found") is False:
        selected = [n for n in selected if not n.startswith("payload")] + [n for n in selected if n.startswith("payload")]
    return selected


def _spoken_joints(result: dict) -> list[int]:
    """The main joints the runs recorded whose gap is above the effort resolution (q1's 0.0007 N·m made a 6e-5 kg·m²
    armature the lead)."""
    recorded = [JOINT_NAMES.index(j) for j in result.get("recorded_joints", JOINT_NAMES)]
    split = "holdout" if (result.get("gap_after") or {}).get("holdout") else "train"
    before = (result.get("gap_before") or {}).get(split) or []
    return [j for j in main_joints(recorded) if j >= len(before) or before[j] is None or before[j] > EFFORT_RESOLUTION]


def _explains_a_main_joint(entry: dict, main: list[int]) -> bool:
    """Whether an effect acts on a main joint and (where its per-joint shares are known) removes alone at least
    PARTLY_SHARE of one's gap there (cross-validated)."""
    acting = [j for j in main if JOINT_NAMES[j] in entry.get("joints", ())]
    shares = (entry.get("explained_fraction_per_joint") or {}).get("cross_validated")
    return bool(acting) and (shares is None or any(shares[j] is not None and shares[j] >= PARTLY_SHARE for j in acting))


def _lead_words(result: dict, selected: list[str]) -> str:
    """The effect that leads the answer, in words, with its size (a payload as any other effect)."""
    payload, mismatch = result.get("payload"), result.get("gravity_mismatch")
    payload_first = bool(selected) and selected[0].startswith("payload")
    if payload_first and payload:
        # the harmonic fit's link, where the selection (whose effect the figures simulate) took another the fit tells apart
        carried = payload.get("selection_link")
        elsewhere = "" if carried in (None, payload["link"], *(payload.get("tied_links") or ()), *(payload.get("equivalent_links") or ())) else (
            f"; the figures simulate it on {carried}, where the selection over time segments put it")
        return f"a payload on {links_words(payload)}{_payload_size_words(payload, result['units'])}{elsewhere})"
    if payload_first and mismatch:  # no baseline: the same fit is the arm's gravity, not something attached
        size = effort_at_zero_words(mismatch.get("gravity_efforts_at_q0"), result["units"], every=True)
        size += offsets_words(mismatch.get("gravity_efforts_at_q0"), mismatch.get("identified_offsets_left_out"), result["units"])
        return (f"a gravity mismatch on {links_words(mismatch)}{size}: the arm's mass distribution against the parameters, "
                "an attached mass not told apart without a baseline)")
    if selected:
        first = next((e for e in result.get("effects", []) if e["name"] == selected[0]), {"name": selected[0]})
        return f"{plain_name(first)} ({selected[0]}{size_words(first)}{identified_values_words(result, first)})"
    return "no effect"


def links_words(report: dict) -> str:
    """'link (group' of a payload-shaped fit, with the links the runs do not tell from it in other groups: one body
    with it on these runs (a held wrist moves the tool with the insertion carriage), or tied with it."""
    groups = dict(zip(report.get("equivalent_links") or (), report.get("equivalent_link_groups") or ()))
    others = [name for name, group in groups.items() if group != report["group"]]
    others += [name for name in report.get("tied_links") or () if name not in groups]
    if not others:
        return f"{report['link']} ({report['group']}"
    in_groups = " or ".join(sorted({report["group"], *(groups[name] for name in others if name in groups), *(report.get("tied_groups") or ())}))
    return f"{' or '.join([report['link'], *others])}: the runs do not tell these links apart ({in_groups}"


def _names(names: list[str], sizes: dict[str, str] | None = None) -> str:
    """The first two names (with their sizes where given), and '...' for the rest."""
    shown = [f"{name} ({sizes[name]})" if sizes and sizes.get(name) else name for name in names[:2]]
    return f"{', '.join(shown)}{', ...' if len(names) > 2 else ''}"


def _sized(result: dict, names: list[str]) -> dict[str, str]:
    """With a baseline, the sizes of the other effects that explain a main joint (a second change: a q3 Coulomb of
    0.2 N beside the q1 one that led had its size in diagnosis.json only)."""
    if not result.get("baseline"):
        return {}
    entries = {e["name"]: e for e in result.get("effects", [])}
    spoken = _spoken_joints(result)
    return {name: size_words(entries[name])[2:] for name in names if name in entries and _explains_a_main_joint(entries[name], spoken)}


def _effects_words(result: dict, selected: list[str], weigh_lead: bool = True) -> str:
    """The selected effects in words, the lead first. With a baseline, the
    findings and the model errors the runs share with it are told apart, and
    the share is said to be theirs together (a payload found beside nine common
    frictions did not remove most of the gap alone)."""
    lead = _lead_words(result, selected)
    roles = {e["name"]: e.get("role", "finding") for e in result.get("effects", [])}
    findings = [n for n in selected[1:] if roles.get(n, "finding") == "finding"]
    common = [n for n in selected[1:] if n not in findings]
    if not common or roles.get(selected[0], "finding") != "finding":
        others = selected[1:]
        minor = _minor_lead(result, selected) if weigh_lead else None
        if minor:  # no effect to lead: the first named removed under a fifth of each main joint's gap alone
            return f"{len(selected)} effects together, none removing a fifth of {minor}'s gap alone ({_names(selected)})"
        return lead + (f" with {len(others)} more effect{'s' if len(others) > 1 else ''} ({_names(others, _sized(result, others))})"
                       if others else "")
    also = f" and {len(findings)} more change{'s' if len(findings) > 1 else ''} ({_names(findings)})" if findings else ""
    return (f"{len(selected)} effects together: {lead}, what the runs have and their baseline lacks{also}, and {len(common)} model "
            f"error{'s' if len(common) > 1 else ''} the runs share with their baseline ({_names(common)})")


def _minor_lead(result: dict, selected: list[str]) -> str | None:
    """The main joints ('q1, q2 or q3') where several effects were selected and the one the answer would lead with
    removes, alone, under PARTLY_SHARE of each one's gap (cross-validated): naming it first would say it explains
    them (a 0.6 ms time shift, 11 % of the null pair's q1, led an answer whose q2 a session change explained);
    None otherwise, and for a payload-shaped lead, whose words are its own."""
    first = next((e for e in result.get("effects", []) if e["name"] == selected[0]), None)
    shares = ((first or {}).get("explained_fraction_per_joint") or {}).get("cross_validated")
    if len(selected) < 2 or shares is None or selected[0].startswith("payload"):
        return None
    recorded = [JOINT_NAMES.index(j) for j in result.get("recorded_joints", JOINT_NAMES)]
    main = [j for j in main_joints(recorded) if JOINT_NAMES[j] in first.get("joints", ())]
    if not main or any(shares[j] is not None and shares[j] >= PARTLY_SHARE for j in main):
        return None
    names = [JOINT_NAMES[j] for j in main]
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"


def split_floors(result: dict) -> list | None:
    """Per joint, the session floor of the gaps the answer speaks of (gap_split's
    rows: a run minus its baseline carries two sessions'); None without a floor."""
    rows = {row["joint"]: row.get("session_floor") for row in (result.get("gap_split") or {}).get("joints") or []}
    floors = [rows.get(j) for j in JOINT_NAMES]
    return floors if any(f is not None for f in floors) else None


def answer_sentence(result: dict) -> str:
    """The answer as one string (its paragraphs joined): for checks and tests that read its words."""
    return " ".join(answer_paragraphs(result))


def answer_paragraphs(result: dict) -> list[str]:
    """The diagnosis's answer: with held-out runs, first what the simulation
    shows beyond the identified model; then the main effect (what, where, how
    big), how far the gap shrinks on the main joints (held-out runs when there
    are), the share of the repeatable gap removed, and what is left against
    the session floor when a --repeat measured it."""
    split = "holdout" if (result.get("gap_after") or {}).get("holdout") else "train"
    selected = _in_answer_order(result)
    explained = result.get("explanation") or explanation(result["gap_before"], result["gap_after"], list(JOINT_NAMES),
                                                          [e for e in result.get("effects", []) if e["name"] in selected],
                                                          split_floors(result))
    # J1..J3; where the effects mostly explain none of them, a joint past them they do (a blind q5 friction change, 95 %,
    # had no figure; the 2019 held-out wrist, beside J1..J3 mostly explained, is not added)
    shown = main_joints([j for j, gap in enumerate(result["gap_before"][split]) if gap is not None])
    mostly = [JOINT_NAMES.index(name) for name, row in (explained.get("by_joint") or {}).items() if row["words"] == "mostly explained"]
    shown += [] if set(mostly) & set(shown) else mostly
    before, after = ([result[key][split][j] for j in shown] for key in ("gap_before", "gap_after"))
    joints = [JOINT_NAMES[j] for j in shown]
    # "not explained" already says the best effects remove less than a fifth: no lead to weigh
    effects = _effects_words(result, selected, explained["words"] != "not explained") if selected else "no effect"
    gaps = "; ".join(gap_change(j, b, a, effort_unit(result, j)) for j, b, a in zip(joints, before, after))
    where = "on the held-out runs" if split == "holdout" else "on the training runs"
    if result.get("payload_not_distinguished"):
        not_one = result["payload_not_distinguished"]
        where = f"no payload is distinguished from none ({not_one.get('why') or not_one['meaning']}); " + where
    beyond = beyond_identified_sentence(result)  # what the data show beyond the identified model, first
    # the words below are against the paper's simulation, not the identified model: their subject says so
    gap = "The gap to the simulation of the identified inertia alone" if beyond and result.get("diagnosis_base", "inertial") == "inertial" \
        else "The gap"
    sentence = _opening(result, explained, gap, effects, f"{where}, {gaps}")
    by_joint = {r.get("joint", JOINT_NAMES[i]): _row_share(r) for i, r in enumerate((result.get("gap_split") or {}).get("joints") or [])}
    shares = [by_joint.get(j) for j in joints] if by_joint else []
    if shares and any(s is not None for s in shares):
        counted = explained.get("joints") or []
        mean = (f"; {percent(explained['removed_share'])} on average over {', '.join(counted)}, as the words weigh it"
                if explained.get("removed_share") is not None and counted != joints else "")
        sentence += ("; removed: " + ", ".join(f"{j} {f'— (within {AT_FLOOR_RATIO:g}x its floor)' if s is None else f'{s:.0%}'}" for j, s in zip(joints, shares))
                     + " of that gap above the session floor" + mean)
    constants_first = explained["words"] in ("not explained", NOT_DETERMINED)  # then a constant beyond a session leads
    if not explained.get("below_resolution"):  # nothing found: nothing for the identified terms to carry
        sentence += identified_terms_clause(result) + ("" if constants_first else constants_clause(result))
    floor = split_floors(result)
    if floor is None:
        sentence += "."
    else:
        # (and above the effort resolution: two noise-free replays' floor made 0.00065 N·m "an unmodelled effect")
        above = [j for j, a in zip(joints, after) if floor[JOINT_NAMES.index(j)] is not None
                 and a > max(AT_FLOOR_RATIO * floor[JOINT_NAMES.index(j)], EFFORT_RESOLUTION)]
        sentence += (f". What is left is over {AT_FLOOR_RATIO:g}x the session floor on {', '.join(above)}: an unmodelled effect remains there."
                     if above else f". What is left on {', '.join(joints)} is within {AT_FLOOR_RATIO:g}x the session floor, where a session's "
                     "change alone can leave it: no fixed effect is shown to remove more there.")
    caution = _caution(result)
    constant = constants_clause(result, lead=True) if constants_first else ""
    scale = (result.get("effort_scale_rival") or {}).get("words", "")
    return [paragraph for paragraph in (caution, beyond.strip(), constant, sentence + refit_clause(result) + insertion_clause(result), scale)
            if paragraph]


def _caution(result: dict) -> str:
    """Before any finding: a log's sign or unit (no effect of the arm's), and what a joint the log left out may have put there."""
    convention = result.get("effort_convention_notes") or []
    held = result.get("unrecorded_joint_notes") or []
    sentences = ([f"{'; '.join(convention)}. No effect of the arm explains that."] if convention else []) + (
        [f"{'; '.join(held)}. The effects found on those joints may stand for that error."] if held else [])
    return "First: " + " ".join(sentences) if sentences else ""


def _opening(result: dict, explained: dict, gap: str, effects: str, figures: str) -> str:
    """The answer's words on `gap`: explained, not, or not determined (and why), by which effects, then `figures`."""
    words, apart = explained["words"], joints_apart(explained)
    qualifiers = [f"of the gap above the session floor{_floor_source(result)}"] if explained.get("above_session_floor") else []
    qualifiers += [f"on average over {', '.join(explained['joints'])}; {apart}"] if apart else []
    if qualifiers:
        words += f" ({'; '.join(qualifiers)})"
    if effects == "no effect" and explained["words"] != NOT_DETERMINED:
        return f"{gap} is not explained: no effect of the library was selected; {figures}"
    if explained.get("below_resolution"):
        return (f"{gap} is {NOT_DETERMINED}: before any effect it is below the effort resolution ({EFFORT_RESOLUTION:g} N·m or N) on "
                f"every joint{'' if effects == 'no effect' else ' the effects act on'}, nothing to explain; {figures}")
    if explained["words"] == NOT_DETERMINED:
        level, leaves = (("the session floor" + _floor_source(result), "a session's change") if explained.get("within_floor")
                         else ("the noise the periodic projection leaves", "the noise"))
        within = explained.get("within_floor") or explained.get("within_noise") or []
        chosen = "no effect of the library was selected" if effects == "no effect" else f"the effects selected, {effects}"
        return (f"{gap} is {NOT_DETERMINED} by these runs: before any effect it is within {AT_FLOOR_RATIO:g}x {level} on "
                f"{', '.join(within)}, which {leaves} alone can leave; {chosen}: {figures}")
    if explained["words"] == "not explained":
        return f"{gap} is {words}: the best effects, {effects}, remove less than a fifth of it: {figures}"
    return f"{gap} is {words} by {effects}: {figures}"


def offset_joints_sentence(offset_joints: dict) -> str:
    joints = ", ".join(offset_joints["joints"]) or "none"
    return (f"Joints whose constant effort moves between sessions ({offset_joints['source']}): {joints}. A run of its own, or minus "
            "its baseline, has a nuisance offset on these only; a run fitted beside a baseline of another motion has one on every joint.")

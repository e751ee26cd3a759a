"""What `dvrk-dart diagnose` prints: the answer, the gaps, the effects, the payload."""

from __future__ import annotations

from dvrk_dart.diagnosis.output.answer import answer_paragraphs, offset_joints_sentence
from dvrk_dart.diagnosis.output.clauses import effects_with_constant_on
from dvrk_dart.diagnosis.payload.parameter_band import band_sentence
from dvrk_dart.model.joints import JOINT_NAMES


def print_diagnosis(result: dict) -> None:
    """What `dvrk-dart diagnose` prints of its result: the answer, the gaps, the effects, the payload."""
    print("\n\n".join(answer_paragraphs(result)))
    print(f"processing: {result['processing']['processing']} ({result['processing'].get('chosen_because') or 'as given'})")
    for name, run in (result["processing"].get("runs") or {}).items():
        if run.get("rate_note"):
            print(f"note: {name}: {run['rate_note']}")
    for name, source in (result.get("baseline_source") or {}).items():  # how each run met the baseline (another motion: why)
        print(f"baseline of {name}: {source}")
    for joint, runs in (result.get("not_recorded_by") or {}).items():
        print(f"{joint}: not recorded by {', '.join(runs)} (its simulation holds it where the log does, at zero without a column): no figure, weight or "
              f"effect on {joint}; what the effects do to {joint} is not checked")
    for key, stage in (("gap_before", "before"), ("gap_after", "after")):
        for split, values in (result.get(key) or {}).items():
            if values is not None:  # diagnosis.json's key beside the words
                runs = "held-out" if split == "holdout" else "training"
                print(f"gap {stage} the effects, {runs} runs ({key}): "
                      + ", ".join(f"{j} {v:.4f} {u}" for j, v, u in zip(JOINT_NAMES, values, result["units"]) if v is not None))
    selected = [e["name"] + (" (a gravity mismatch: no baseline isolates a payload)" if e.get("kind") == "gravity_mismatch" else "")
                for e in result["effects"] if e.get("selected")]
    print(f"selected effects: {', '.join(selected) or 'none'}")
    if result.get("refit"):
        print(result["refit"]["words"])
    if result.get("insertion_terms"):
        print(result["insertion_terms"]["words"])
    if result.get("one_configuration"):
        print(result["one_configuration"]["words"])
    if band_sentence(result):
        print(band_sentence(result))
    if result.get("payload"):
        p = result["payload"]
        mass = _heading_mass(p)
        found = p.get("found") is not False  # the harmonic test's: "mass not determined on yaw" read as a payload found
        print(f"payload: {mass} on {p['link']} ({p['group']})" if found else
              f"payload: none stands out from the session scatter (p = {p['payload_p_value']:.2g}); its fit:")
        for sentence in p.get("words", []):
            print(f"  {sentence}")
    if result.get("payload_not_distinguished"):
        print(f"no payload: {result['payload_not_distinguished']['meaning']}")
    if result.get("payload_at_unused"):
        print(f"no payload: {result['payload_at_unused']}")
    if result.get("gravity_mismatch") and not (result.get("explanation") or {}).get("below_resolution"):
        for sentence in result["gravity_mismatch"]["words"]:
            print(sentence)
    if result.get("nuisance_offset_joints"):
        print(offset_joints_sentence(result["nuisance_offset_joints"]))
    if result.get("nuisance_offsets"):
        for run, offsets in result["nuisance_offsets"].items():
            joints = (result.get("nuisance_offset_joints") or {}).get("joints") or list(offsets)
            print(f"nuisance offsets of {run}: " + ", ".join(f"{j} {offsets[j]:+.3f} {result['units'][JOINT_NAMES.index(j)]}" for j in joints if j in offsets))
    for line in constant_lines(result):
        print(line)
    for row in (result.get("gap_split") or {}).get("joints", [])[:3]:
        if row.get("session_to_session") is not None:
            print(f"gap split {row['joint']}: before {row['before']:.3f} = explained {row['explained']:.3f} + session-to-session "
                  f"{row['session_to_session']:.3f} + left over {row['left_over']:.3f} {row['unit']} (RMS, added in squares)")


def constant_lines(result: dict) -> list[str]:
    """A line per constant the fit took out of a run beyond a session's change (constants_beyond_session)."""
    lines = []
    for c in result.get("constants_beyond_session") or []:
        beside = effects_with_constant_on(result, c["joint"])
        if beside:  # the null pair's q2 offset of +0.235 N·m beside a declined payload's mean read as 3.2x a session's change
            lines.append(f"{c['joint']}: the fit takes {c['offset']:+.3f} {c['unit']} out of {c['run']} as a session's offset beside "
                         f"{', '.join(beside)}, whose effort has a constant part on {c['joint']}: the runs do not split the constant "
                         "between them, so it is not compared with a session's change")
            continue
        against = f"against the identified offset {c['expected']:+.3f}" if c.get("against") == "the identified offset" else "minus its baseline"
        lines.append(f"{c['joint']}: the fit takes {c['offset']:+.3f} {c['unit']} out of {c['run']} ({against}) as a session's offset, on "
                     f"top of the effects: {abs(c['offset'] - c.get('expected', 0.0)) / max(c['session_change'], 1e-12):.1f}x the constant "
                     f"change {c.get('session_change_source', 'the repeat pair')} shows between sessions ({c['session_change']:.3f}); it may "
                     "be a changed offset or part of an effect (a load, a payload's mean gravity), not diagnosed")
    return lines


def _heading_mass(payload: dict) -> str:
    """The payload line's mass: at the --payload-at position where it is a size there (on a link the efforts choose,
    its interval above zero: the answer's rule, _payload_size_words), else the fit's where identified."""
    at = payload.get("payload_at") or {}
    interval = at.get("mass_kg_interval")
    if at.get("mass_kg") is not None and at.get("link_chosen_by_the_efforts") is not False and interval is not None and interval[0] > 0.0:
        return f"{at['mass_kg']:.3f} kg at the --payload-at position ({at['link']})"
    return "mass not determined" if payload["mass_kg"] is None or not payload.get("mass_identified", True) else f"{payload['mass_kg']:.3f} kg"

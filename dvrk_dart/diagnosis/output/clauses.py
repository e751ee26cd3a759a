"""The clauses the answer (answer.py) adds after its main sentence: what the
identified model's own terms carry, constants beyond a session's change, the
refit's bias, J3's terms; and what every clause shares (the effort unit, the
joints an answer speaks of)."""

from __future__ import annotations

from dvrk_dart.diagnosis.output.wording import gap_change, terms_beside_own_friction, words_for
from dvrk_dart.model.joints import JOINT_NAMES

#: the joints the answer sentence speaks of (the arm's main joints)
ANSWER_JOINTS = 3


def main_joints(recorded: list[int]) -> list[int]:
    """The joints an answer speaks of among those the runs recorded: J1..J3, else the wrist's."""
    return [j for j in recorded if j < ANSWER_JOINTS] or recorded


def effort_unit(result: dict, joint: str) -> str:
    """The effort unit of `joint` on the diagnosed arm (diagnosis.json `units`)."""
    return result["units"][JOINT_NAMES.index(joint)]


#: the one rule's words (output/wording.py) for the share of the found efforts the identified terms carry
CARRIED_WORDS = {"mostly explained": ("most of", "mostly what the identified model already has and the simulation lacks"),
                 "partly explained": ("part of", "partly what the identified model already has"),
                 "not explained": ("little of", "beyond the identified model's terms")}


#: effects whose effort has no constant part of its own: they cannot account for a run's constant (friction reverses
#: with the motion, an armature and a time shift follow accelerations and rates)
NO_CONSTANT_KINDS = ("friction", "armature", "time_shift")


def effects_with_constant_on(result: dict, joint: str) -> list[str]:
    """The selected effects with a constant part of their own on `joint`: the run's constant there is split between them
    and its nuisance offset, a split the efforts do not determine."""
    return [e["name"] for e in result.get("effects", [])
            if e.get("selected") and e.get("kind") not in NO_CONSTANT_KINDS and joint in e.get("joints", ())]


def constants_beyond(result: dict) -> list[dict]:
    """The runs' constants beyond a session's change on joints no selected effect with a constant part acts on."""
    return [c for c in result.get("constants_beyond_session") or [] if not effects_with_constant_on(result, c["joint"])]


def constants_clause(result: dict, lead: bool = False) -> str:
    """A constant of the runs against their baseline beyond a session's change (constants_beyond_session), which the
    nuisance term took out of the gap (a J3 offset changed by 0.35 N read 'not explained', with no word), on a joint
    no selected effect with a constant part acts on (a payload's mean gravity on q3 is the payload's: printed, not in the
    answer); friction reverses with the motion (two runs' J3 offset of +0.35 N beside J3's friction had no word)."""
    beyond = constants_beyond(result)
    if not beyond:
        return ""
    listed = ", ".join(f"{c['joint']} {c['offset']:+.3g} {c['unit']} in {c['run']}"
                       + (f" ({abs(c['offset'] - c.get('expected', 0.0)) / c['session_change']:.3g}x that change)" if c.get("session_change") else "")
                       for c in beyond)
    whose = ("the identified offset ({})".format(", ".join(dict.fromkeys(f"{c['joint']} {c['expected']:+.3g} {c['unit']}" for c in beyond)))
             if beyond[0].get("against") == "the identified offset" else "their baseline's")
    words = (f"beyond a session's change (as {beyond[0].get('session_change_source', 'the repeat pair')} shows it), the runs' constant "
             f"effort differs from {whose}: {listed}")
    if lead:  # the answer's first finding where the effects explain little (a J3 offset changed by 0.2 N came last)
        return f"{words[0].upper()}{words[1:]}: a changed offset or part of an effect, taken out of the gap below as a session's offset."
    return f"; {words}, taken out as a session's offset: a changed offset or part of an effect, not diagnosed"


def identified_terms_clause(result: dict) -> str:
    """Whether what was found is the identified model's own friction, offsets,
    springs and motor inertia, which the inertia-only simulation leaves out."""
    carried = result.get("identified_terms")
    if not carried:
        return ""
    def percent(share: float) -> str:  # below zero the terms reproduce none of it (diagnosis.json keeps the value)
        return f"{max(share, 0.0):.0%}"

    joints = ", ".join(f"{name} {percent(share)}" for name, share in carried["by_joint"].items())
    how, meaning = CARRIED_WORDS[words_for(carried["share"])]
    whose, where = (("the model errors' efforts", "on the baseline run") if carried.get("runs") == "baseline"
                    else ("these effects' efforts", "on the training runs"))
    beyond = carried.get("beyond_rms") or {}
    rest = (" (the effects' efforts minus those terms, in RMS: " + ", ".join(f"{name} {rms:.2g} {result['units'][JOINT_NAMES.index(name)]}"
                                                                       for name, rms in beyond.items()) + ")") if beyond else ""
    return (f"; the identified model's own {', '.join(carried['terms']).replace('_', ' ')} terms, which the simulation leaves out, "
            f"carry {how} {whose} ({percent(carried['share'])} {where}: {joints}): {meaning}{rest}")


def refit_clause(result: dict) -> str:
    """With --refit: the joints whose held-out gap the refit at least halves (the published fit's bias)."""
    refit = result.get("refit")
    if not refit:
        return ""
    pairs = list(zip(JOINT_NAMES[:ANSWER_JOINTS], refit["gap_holdout_arm_params"], refit["gap_holdout_refit"]))
    biased = [gap_change(j, b, a, effort_unit(result, j)) for j, b, a in pairs if a * a <= 0.5 * b * b]
    if not biased:
        return " Refitting the identified parameters on the training runs does not halve any held-out gap in squares."
    return f" The published fit's bias: the identified parameters refitted on the training runs leave {'; '.join(biased)} on the held-out runs."


def insertion_clause(result: dict) -> str:
    """On a PSM's periodic held-out runs: what J3's repeatable gap is made of, simulated."""
    study = result.get("insertion_terms")
    if not study:
        return ""
    combined = result.get("one_configuration")
    together = "" if not combined else (
        "; with the effects above and the loads the pitch angle sets on q1 and q2, in one simulation: "
        + ", ".join(f"{name} {gap:.3g} {effort_unit(result, name)}" for name, gap in zip(JOINT_NAMES[:3], combined["gap_holdout"])))
    left = f"{study['gap_holdout_simulated']:.3g} N on the held-out runs (identified model {study['gap_holdout_identified']:.3g} N)"
    if study.get("gap_holdout_terms", 0.0) >= study["gap_holdout_own_friction"]:  # the terms do no better than J3's friction alone
        carried = "carries" if study["gap_holdout_own_friction"] < study["gap_holdout_identified"] else "does not carry"
        return (f" J3's own friction refitted on the training runs {carried} to the held-out runs ({study['gap_holdout_own_friction']:.3g} N, "
                f"identified model {study['gap_holdout_identified']:.3g} N); J3's terms (friction along the stroke, an effort in "
                f"ddq3·sign(dq3), a load in q2) {terms_beside_own_friction(study)} there: simulated with them, J3 is at {study['gap_holdout_simulated']:.3g} N"
                f"{together}.")
    if study["gap_holdout_simulated"] >= study["gap_holdout_identified"]:  # fitted, but not what the held-out runs show
        return (f" J3's terms fitted on the training runs (friction along the stroke, an effort in ddq3·sign(dq3), a load in q2) do not carry "
                f"to the held-out runs: simulated, they leave J3 at {left}; what J3's gap is made of is not determined by these runs{together}.")
    return (f" J3's terms fitted on the training runs (friction along the stroke, an effort in ddq3·sign(dq3), a load in q2) carry to the "
            f"held-out runs: simulated, they leave J3 at {left}; which physical effect each stands for is not determined by the runs{together}.")

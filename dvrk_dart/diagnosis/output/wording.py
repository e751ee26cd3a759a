"""One rule for the words of a diagnosis (the CLI, the page and
diagnosis.json's `explanation` say the same): how much of the gap the
selected effects remove, on the joints they act on.

- "mostly explained": they remove more than half of the gap there;
- "partly explained": 20 % to 50 %;
- "not explained": less than 20 %, or no effect selected where some joint
  has a gap beyond the floor, the noise and the resolution below;
- "not determined": where a --repeat measured the session floor, every joint
  they act on had a gap within 1.5x that floor before them (AT_FLOOR_RATIO):
  a session's change alone can leave such a gap, so what they remove of it
  says nothing (a joint at 1.34x its floor read "100 % removed, mostly
  explained" once the effects took it under the floor); with no effect
  selected, every joint's gap within the floor, the noise or the resolution
  (nothing to explain).

The share is 1 - after / before of the gap's RMS, averaged over the joints the
selected effects act on (each joint in its own unit), on the held-out runs
when there are, else on the training runs: the figures the answer prints.
Where a --repeat measured the session floor, before and after are the gap
above it (RMS-equivalents, sqrt(gap^2 - floor^2)): no fixed effect removes a
session's change, so a payload found to within the floor was "not explained"
(a joint with nothing above its floor does not count). A joint whose gap is
at round-off against the largest before and after the effects
(NOTHING_TO_EXPLAIN: a joint a simulated run models exactly, such as a held
wrist without noise) has nothing to explain and does not count either: its
share, 1 - 4e-7 / 5e-12, sank an average of 84 %, 77 % and 60 % to "not
explained". Where the effects leave a real gap on it, it counts; a joint whose
gap before and after is below the effort resolution (EFFORT_RESOLUTION, the
weights' floor) does not: nothing to explain there either.
Each joint's own share is kept beside it, and the joints whose own words
differ from the average's are named with the words."""

from __future__ import annotations

import math

import numpy as np

from dvrk_dart.io.measured_run import EFFORT_RESOLUTION
from dvrk_dart.diagnosis.fit.session_floor import AT_FLOOR_RATIO, above_floor, repeatable_share

MOSTLY_SHARE = 0.5
#: the words where every joint the effects act on has its gap within AT_FLOOR_RATIO of the session floor
NOT_DETERMINED = "not determined"
#: a joint's gap at or below this fraction of the largest joint's is round-off, not a gap (0.1 N·m: 10 µN·m)
NOTHING_TO_EXPLAIN = 1e-4
PARTLY_SHARE = 0.2
RULE = (f"1 - after/before of the gap's RMS (above the session floor where a --repeat measured it), averaged over the joints the "
        f"selected effects act on: above {MOSTLY_SHARE:.0%} 'mostly explained', {PARTLY_SHARE:.0%}-{MOSTLY_SHARE:.0%} 'partly explained', "
        f"below {PARTLY_SHARE:.0%} 'not explained'; a joint whose gap before is within {AT_FLOOR_RATIO:g}x the session floor does not "
        f"count (a session's change alone can leave it), nor, without a session floor, one within {AT_FLOOR_RATIO:g}x the noise the "
        f"periodic projection leaves, and where no joint is left, '{NOT_DETERMINED}'; nor does a joint whose gap "
        f"before and after is below the effort resolution ({EFFORT_RESOLUTION:g} N·m or N), and where every such joint's is, "
        f"'{NOT_DETERMINED}' (a simulated run replayed); with no effect selected every joint is weighed so, and "
        f"'{NOT_DETERMINED}' where none is left, else 'not explained'")


def words_for(share: float | None) -> str:
    if share is None or not share >= PARTLY_SHARE:
        return "not explained"
    return "mostly explained" if share > MOSTLY_SHARE else "partly explained"


def share_above_floor(before: float, after: float, floor: float) -> float | None:
    """1 - after/before of the gap above the floor (the rule's share); None where nothing is above it."""
    share = float(repeatable_share(before, after, floor))
    return None if math.isnan(share) else share


def explanation(gap_before: dict, gap_after: dict, joint_names: list[str], selected_entries: list[dict],
                floor: list | None = None, noise: list | None = None) -> dict:
    """diagnosis.json's `explanation`: the words, the share they rest on, the joints and the split
    (`floor`: the session floor per joint, None where not measured; `noise`: without a floor, the noise the
    periodic projection leaves on the split's gaps, None upstream)."""
    split = "holdout" if gap_after.get("holdout") else "train"
    acted = {j for entry in selected_entries for j in entry.get("joints", ())}
    before, after = list(gap_before.get(split) or []), list(gap_after.get(split) or [])
    # with no effect selected every joint is weighed: a gap left within the noise on each is nothing to explain (a run
    # minus its copy with J3's offset changed, 0.002 N left, read "not explained")
    weighed = acted or {name for j, name in enumerate(joint_names) if j < len(before) and before[j] is not None}
    at_floor = []  # the weighed joints whose gap before is within AT_FLOOR_RATIO of the floor: nothing repeatable shown there
    for j, f in enumerate(floor or []):
        if f is not None and j < len(before) and before[j] is not None and after[j] is not None:
            if before[j] <= AT_FLOOR_RATIO * f and joint_names[j] in weighed:
                at_floor.append(joint_names[j])
            before[j], after[j] = float(above_floor(before[j], f)), float(above_floor(after[j], f))
    # without a floor, a gap within the noise is the noise (a blind q5 friction change, 95 % removed, read "partly
    # explained" beside q2's and q3's 9-10 % of their 0.0014 and 0.0022 at the noise); the shares stay raw
    at_noise = [name for j, name in enumerate(joint_names) if floor is None and noise and name in weighed and j < len(before)
                and before[j] is not None and noise[j] is not None and before[j] <= AT_FLOOR_RATIO * noise[j]]
    largest = max((b for b in before if b is not None), default=0.0)
    joints = [j for j, name in enumerate(joint_names)
              if name in weighed and name not in at_floor + at_noise and j < len(before) and before[j] is not None and after[j] is not None
              and max(before[j], after[j]) > NOTHING_TO_EXPLAIN * largest]
    # a joint whose gap is below the effort resolution before and after has nothing to explain (a blind q2 friction
    # change, 99 % removed, read "partly explained" beside the 6-10 % of four joints at 5e-4 N·m); none above it:
    # round-off of a replayed simulated run (1e-6 N·m read "partly explained by a gravity mismatch")
    resolved = [j for j in joints if max(gap_before[split][j], gap_after[split][j]) > EFFORT_RESOLUTION]
    unresolved = bool(joints) and not resolved
    shares = {joint_names[j]: float(1.0 - after[j] / before[j]) for j in resolved} if acted else {}
    share = float(np.mean(list(shares.values()))) if shares else None
    words = NOT_DETERMINED if not resolved and (at_floor or at_noise or unresolved) else words_for(share)
    return {"words": words, "removed_share": share, "joints": list(shares), "runs": split, "rule": RULE,
            "above_session_floor": floor is not None and any(f is not None for f in floor), "within_floor": at_floor,
            "within_noise": at_noise, "below_resolution": unresolved,
            "by_joint": {name: {"removed_share": s, "words": words_for(s)} for name, s in shares.items()}}


def gap_change(joint: str, before: float, after: float, unit: str) -> str:
    """'q2 0.0952 -> 0.100 N·m': three significant digits each, kept when they are zeros ('0.1' beside '0.0952'
    read as a rounder figure than it is)."""
    return f"{joint} {before:#.3g} -> {after:#.3g} {unit}"


def percent(share: float) -> str:
    """A share as a percentage, with a decimal where the whole number would sit on a boundary of the words
    (0.5008 printed "50 %" beside "mostly explained")."""
    text = f"{share:.0%}"
    return f"{share:.1%}" if text in (f"{PARTLY_SHARE:.0%}", f"{MOSTLY_SHARE:.0%}") else text


def joints_apart(explained: dict) -> str:
    """The joints whose own share earns other words than the average's, named
    (an average of 75 %, 69 % and 37 % is 'mostly', but not on the third joint)."""
    apart = {}
    for name, joint in (explained.get("by_joint") or {}).items():
        if joint["words"] != explained["words"]:
            apart.setdefault(joint["words"].split()[0], []).append(f"{name} {percent(joint['removed_share'])}")
    return "; ".join(f"{words} on {', '.join(names)}" for words, names in apart.items())


def share_words(share: float | None) -> str:
    """A repeatable_share in words: a percentage, or why there is none."""
    return (f"not determined (the gap within {AT_FLOOR_RATIO:g}x the session floor: no repeatable gap shown)" if share is None or math.isnan(share)
            else f"{share:.0%}")


def terms_beside_own_friction(study: dict) -> str:
    """J3's terms on the held-out runs against J3's own friction refitted alone (`insertion_terms`' study):
    what the terms do to it where they do no better (2018: 0.220 N alone, 0.414 N with them was "add nothing")."""
    return "make it worse" if study["gap_holdout_simulated"] > study["gap_holdout_own_friction"] else "add nothing to it"

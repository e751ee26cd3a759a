"""One rule for the words of a diagnosis (the CLI, the page and
diagnosis.json's `explanation` say the same): how much of the gap the
selected effects remove, on the joints they act on.

- "mostly explained": they remove more than half of the gap there;
- "partly explained": 20 % to 50 %;
- "not explained": less than 20 %, or no effect selected.

The share is 1 - after / before of the gap's RMS, averaged over the joints the
selected effects act on (each joint in its own unit), on the held-out runs
when there are, else on the training runs: the figures the answer prints."""

from __future__ import annotations

import math

import numpy as np

MOSTLY_SHARE = 0.5
PARTLY_SHARE = 0.2
RULE = (f"1 - after/before of the gap's RMS, averaged over the joints the selected effects act on: above {MOSTLY_SHARE:.0%} "
        f"'mostly explained', {PARTLY_SHARE:.0%}-{MOSTLY_SHARE:.0%} 'partly explained', below {PARTLY_SHARE:.0%} 'not explained'")


def words_for(share: float | None) -> str:
    if share is None or not share >= PARTLY_SHARE:
        return "not explained"
    return "mostly explained" if share > MOSTLY_SHARE else "partly explained"


def explanation(gap_before: dict, gap_after: dict, joint_names: list[str], selected_entries: list[dict]) -> dict:
    """diagnosis.json's `explanation`: the words, the share they rest on, the joints and the split."""
    split = "holdout" if gap_after.get("holdout") else "train"
    acted = {j for entry in selected_entries for j in entry.get("joints", ())}
    before, after = gap_before.get(split) or [], gap_after.get(split) or []
    joints = [j for j, name in enumerate(joint_names)
              if name in acted and j < len(before) and before[j] is not None and after[j] is not None and before[j] > 0]
    share = float(np.mean([1.0 - after[j] / before[j] for j in joints])) if joints else None
    return {"words": words_for(share), "removed_share": share, "joints": [joint_names[j] for j in joints], "runs": split, "rule": RULE}


def share_words(share: float | None) -> str:
    """A repeatable_share in words: a percentage, or why there is none."""
    return "not determined (no repeatable gap above the session floor)" if share is None or math.isnan(share) else f"{share:.0%}"

"""One scale of every measured effort against the selected effects, where the scale was not a candidate.

A torque constant or the controller's effort scale off multiplies every effort; without `--effort-scale` the
selection reads it as several small effects whose shares are right and whose causes are not (2018 test1 x 1.1
against test1: seven effects). The scale is in the design as a probe (`EffortScale(candidate=False)`): where it
alone, one parameter, removes as much of the gap (cross-validated) as the selection's several parameters, by the
share the selection asks of a simpler rival (`PARSIMONY_GAIN_SHARE`; not its bootstrap test), the answer says so.
"""

from __future__ import annotations

from dvrk_dart.diagnosis.effects.arm_effects import EffortScale
from dvrk_dart.diagnosis.fit.problem import Problem
from dvrk_dart.diagnosis.fit.result import Selection
from dvrk_dart.diagnosis.fit.selection import PARSIMONY_GAIN_SHARE


def effort_scale_rival(problem: Problem, selection: Selection) -> dict | None:
    """The probe's scale and share where it rivals a selection of more than one parameter, else None."""
    probe = next((i for i, e in enumerate(problem.effects) if isinstance(e, EffortScale) and not e.candidate), None)
    if probe is None or sum(problem.effects[i].n_seen_parameters for i in selection.selected) <= 1:
        return None
    # both scored by the final selector (its weights; the greedy one's score of the selection was fitted with others)
    chosen = selection.selector.cross_validate(selection.selected).fraction
    alone = selection.selector.cross_validate([probe]).fraction
    if chosen <= 0.0 or alone < PARSIMONY_GAIN_SHARE * chosen:
        return None
    scale = float(selection.selector.fit_all([probe]).params[probe][0])
    return {"scale_error": scale, "cross_validated_fraction": alone, "selected_cross_validated_fraction": chosen,
            "words": f"One scale of every measured effort ({scale:+.1%}) alone removes {alone:.0%} of the gap (cross-validated), where "
                     f"the effects above ({len(selection.selected)}) remove {chosen:.0%}: if a torque constant or the controller's effort "
                     "scale may differ from what the runs are compared with, diagnose again with --effort-scale."}

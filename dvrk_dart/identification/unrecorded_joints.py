"""What holding a joint a log did not record may cost the others' figures
(model-errors and identify say it, from the identified model's efforts)."""

from __future__ import annotations

import numpy as np

from dvrk_dart.io.period import spanning_columns
from dvrk_dart.model.identified import IdentifiedModel
from dvrk_dart.model.joints import JOINT_NAMES


def unrecorded_joint_notes(identified: IdentifiedModel, processed, figures: np.ndarray) -> list[str]:
    """A joint the run did not record is held where the log leaves it (0;
    a joint with positions but no effort follows them): where sweeping it over
    its range moves the model's rigid-body efforts on a recorded joint by more
    than that joint's figure (`figures`, per joint), the figure may be that
    joint's error, not the model's; one line per such joint. `processed`: a
    processed run (q, dq, ddq, measured)."""
    every = max(1, len(processed.q) // 200)  # the run's states, every ~0.5 % of it
    states = (processed.q[::every], processed.dq[::every], processed.ddq[::every])
    positions_logged = spanning_columns(processed.q)  # an effort not recorded, its joint's positions were
    model, notes = identified.model, []
    for j in np.flatnonzero(~np.asarray(processed.measured) & ~positions_logged):
        change = identified.held_joint_change(*states, j)
        hurt = [k for k in np.flatnonzero(processed.measured) if change[k] > figures[k]]
        held = f"{JOINT_NAMES[j]} is not recorded and held at 0 {model.position_unit(JOINT_NAMES[j])}"
        if hurt:
            moves = ", ".join(f"{JOINT_NAMES[k]} {change[k]:.3g} {model.effort_unit(JOINT_NAMES[k])}" for k in hurt)
            notes.append(f"{held}: over its range it moves the model's efforts on {moves}, more than their figures: where the arm "
                         "moved it, they carry that error")
        # a shared friction follows the held joint's velocity, which no position sweep shows (q5, q6 without the jaw: their
        # relative figures 0.26 and 0.33 against 0.18 and 0.17 with it, on "one")
        shared = {k: links for k, links in identified.friction_partners(j).items() if processed.measured[k]}
        if shared:
            links = ", ".join(dict.fromkeys(name for names in shared.values() for name in names))
            notes.append(f"{held}: {', '.join(JOINT_NAMES[k] for k in shared)} share the identified friction of {links} with it, "
                         f"which then misses its motion: where the arm moved {JOINT_NAMES[j]}, their figures carry that friction")
    return notes

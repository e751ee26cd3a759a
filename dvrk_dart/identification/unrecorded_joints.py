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
        if hurt:
            moves = ", ".join(f"{JOINT_NAMES[k]} {change[k]:.3g} {model.effort_unit(JOINT_NAMES[k])}" for k in hurt)
            notes.append(f"{JOINT_NAMES[j]} is not recorded and held at 0 {model.position_unit(JOINT_NAMES[j])}: over its range it "
                         f"moves the model's efforts on {moves}, more than their figures: where the arm moved it, they carry that error")
    return notes

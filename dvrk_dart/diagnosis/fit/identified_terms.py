"""How much of what the diagnosis found the identified model already has.

With the paper's base (DART simulating the identified inertia alone), the gap
holds the identified model's own friction, offsets, springs and motor
inertia, which the simulation leaves out; the selected effects then often
rebuild them (an offset on q1 of -0.27 N·m where the published model's Fo is
-0.30). That is no finding about the arm, and the answer says so: the share
of the selected effects' efforts on the training runs that the identified
model's non-inertial terms reproduce, per joint and over the joints the
effects act on, in the diagnosis's one rule of words (output/wording.py's
bounds). Only the terms the base simulation leaves out are compared (none on
the identified base, `--dynamics identified`'s physics); not with a baseline
(both runs carry the identified terms: their difference has none)."""

from __future__ import annotations

import numpy as np

from dvrk_dart.model.identified import NON_INERTIAL_TERMS
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.sim.config import SimConfig, simulated_terms


def identified_terms_share(problem, selection, base_config: SimConfig) -> dict | None:
    """diagnosis.json's `identified_terms`: share per joint (1 - |found -
    identified|^2 / |found|^2 on the training runs), over the acted joints
    (energy-weighted), or None where it does not apply."""
    left_out = tuple(term for term in NON_INERTIAL_TERMS if term not in simulated_terms(base_config))
    if problem.has_baseline or not left_out or not selection.selected:
        return None
    found, carried = [], []
    for run, columns in zip(problem.train_runs, problem.train_columns):
        state = run.state
        effort = columns @ selection.final.beta
        identified = state.in_band(problem.arm.identified.predict(state.q, state.dq, state.ddq, left_out))
        demean = problem.demean_of(run)
        if demean is not None:  # a run's own constant is a nuisance: neither side keeps it
            effort, identified = (x - demean * x.mean(axis=0) for x in (effort, identified))
        found.append(effort)
        carried.append(identified)
    found, carried = np.vstack(found), np.vstack(carried)
    acted = sorted({JOINT_NAMES.index(j) for i in selection.selected for j in problem.effects[i].joints} & set(np.flatnonzero(problem.recorded)))
    energy, error = np.sum(found**2, axis=0), np.sum((found - carried) ** 2, axis=0)
    by_joint = {JOINT_NAMES[j]: float(1.0 - error[j] / energy[j]) for j in acted if energy[j] > 0}
    if not by_joint:
        return None
    joints = [JOINT_NAMES.index(name) for name in by_joint]
    return {"share": float(1.0 - error[joints].sum() / energy[joints].sum()), "by_joint": by_joint,
            "terms": list(left_out), "runs": "train",
            "definition": "1 - |selected effects' efforts - the identified model's efforts of the terms the base simulation leaves out|^2 / |selected effects' efforts|^2, "
                          "summed over the joints the selected effects act on, on the training runs"}

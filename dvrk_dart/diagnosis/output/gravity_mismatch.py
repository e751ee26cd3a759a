"""A payload-shaped fit without a baseline, reported as what it is: this
arm's gravity (its mass distribution) against the parameters, by its efforts,
beside the identified offsets the simulation leaves out (a constant part of
those efforts may be them: 2018's J1 -0.300 N·m where the published offset is
-0.300)."""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.output.answer import effort_at_zero_words, links_words, offsets_words
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES


def offsets_left_out(arm, carried: dict | None, recorded: np.ndarray) -> list[float | None] | None:
    """The identified model's constant efforts (its offsets, N·m or N per joint; None on a joint the runs did not
    record) where the base simulation leaves them out (`carried`: identified_terms_share's answer), else None."""
    if not carried or "offset" not in carried.get("terms", ()):
        return None
    zero = np.zeros((1, len(JOINT_NAMES)))
    offsets = arm.identified.predict(zero, zero, zero, ("offset",))[0]
    return [float(x) if seen else None for x, seen in zip(offsets, recorded)]


def gravity_mismatch_of(fit: dict, model: PsmModel, left_out_offsets: list[float] | None = None) -> dict:
    """A payload-shaped fit without a baseline: the arm's own gravity against
    the parameters (its mass distribution: another arm, instrument or session),
    reported by its efforts, not as a mass that was attached. Beside each effort
    at q = 0, the identified offset of that joint when the simulation leaves it
    out: a constant the fit's effort at q = 0 is not told apart from."""
    units = [model.effort_unit(j) for j in JOINT_NAMES]
    size = effort_at_zero_words(fit.get("gravity_efforts_at_q0"), units, every=True).lstrip(",")
    size += offsets_words(fit.get("gravity_efforts_at_q0"), left_out_offsets, units)
    return {**fit, "identified_offsets_left_out": left_out_offsets,
            "meaning": "without a baseline run (the same motion without an attached mass), a payload-shaped fit is this arm's "
                       "gravity (mass distribution) against the parameters, an attached mass included if there is one: the "
                       "two are not told apart; record a baseline to isolate a payload",
            "words": [f"The arm's gravity differs from the parameters' like a mass on {links_words(fit)})"
                      + (f":{size}" if size else "")
                      + "; without a baseline run the arm's mass distribution and an attached mass are not told apart."]}

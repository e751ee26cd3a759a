"""Measured efforts of another sign or unit than the model's: a log's
convention, said where it shows (model-errors, identify and diagnose quote
it), rather than read as the arm's error (a log with every effort's sign
flipped was diagnosed as a cable's elasticity, "not explained")."""

from __future__ import annotations

import numpy as np

from dvrk_dart.model.joints import JOINT_NAMES

#: a joint's measured efforts, less their mean, are `gain` times the model's, less theirs, in the least-squares
#: sense; a gain outside [1 / CONVENTION_GAIN, CONVENTION_GAIN] (or negative) that leaves at most
#: CONVENTION_FIT_SHARE of the model's miss and of the measured efforts themselves is a convention (every real run
#: of wpi/, wpi-2018/ and wpi-mtm/, both processings: gains 0.87-1.93, tests/test_effort_convention.py). Means
#: apart: an offset is no gain (a still joint's 0.05 N·m against a model's 0.002 read as 25 times the model's); and
#: noise is no small gain (DART runs' wrists, noise beside the identified model's friction, read 0.001 times it).
CONVENTION_GAIN = 5.0
CONVENTION_FIT_SHARE = 0.5


def convention_gains(predicted: np.ndarray, measured: np.ndarray, recorded: np.ndarray) -> dict[int, float]:
    """Joint -> the gain of its measured efforts on the model's, where it is a convention (above)."""
    gains = {}
    for j in np.flatnonzero(recorded):
        p, m = predicted[:, j] - predicted[:, j].mean(), measured[:, j] - measured[:, j].mean()
        if not (p @ p > 0 and m @ m > 0):
            continue
        gain = float(p @ m / (p @ p))
        if 1.0 / CONVENTION_GAIN < gain < CONVENTION_GAIN:
            continue
        left = np.linalg.norm(gain * p - m)  # the scaled model must explain the measured efforts, not only miss less:
        if left <= CONVENTION_FIT_SHARE * min(np.linalg.norm(p - m), np.linalg.norm(m)):  # noise against a model's friction reads ~0
            gains[int(j)] = gain
    return gains


def effort_convention_notes(predicted: np.ndarray, measured: np.ndarray, recorded: np.ndarray, of: str = "model") -> list[str]:
    """One line for the joints whose measured efforts run opposite to the `of` efforts (the model's, the simulation's),
    one for those of another scale."""
    gains = convention_gains(predicted, measured, recorded)

    def listed(joints):
        return ", ".join(f"{JOINT_NAMES[j]} ({gains[j]:.3g})" for j in joints)

    opposite = [j for j, gain in gains.items() if gain < 0]
    scaled = [j for j, gain in gains.items() if gain > 0]
    notes = []
    if opposite:
        notes.append(f"the measured efforts run opposite to the {of}'s on {listed(opposite)}, the least-squares gain of "
                     f"measured on {of}: a log of another sign convention? (efforts here have the sign of the dVRK's measured effort)")
    if scaled:
        notes.append(f"the measured efforts are a multiple of the {of}'s on {listed(scaled)}, the least-squares gain of "
                     f"measured on {of}: a log of another unit? (efforts here are in N·m, N on a prismatic joint)")
    return notes

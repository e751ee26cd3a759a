"""How Coulomb friction reverses: at once (sign of the velocity, the upstream
model) or over a pre-sliding distance (Dahl's model).

Real joints do not switch their friction at the instant the velocity changes
sign: the contacts (cable, bearings, the insertion guide) first deflect
elastically, and the friction follows the *displacement* since the reversal,
reaching its sliding value over a pre-sliding distance x_s (Dahl 1968; Armstrong
et al. 1994). The state z in [-1, 1] multiplies Fc:

    z <- s + (z - s) exp(-|dx| / x_s),   s = sign(dx)

for each increment dx of the joint's position. x_s = 0 is the sign law. The
state depends on the path, not on the instantaneous velocity: a model of q, dq
and ddq alone cannot reproduce it, which is why the gap it leaves repeats from
session to session and is still no function of the state. The simulator steps
the same law with each of its steps (`sim/kernels.py` `dahl_step`).
"""

from __future__ import annotations

import math

import numpy as np


def reversal(position: np.ndarray, rate: np.ndarray, presliding: float) -> np.ndarray:
    """The factor of Fc along a trajectory (samples in time order): sign(rate)
    for presliding = 0, else Dahl's state over the position increments, started
    sliding in the direction of the first sample's rate."""
    rate = np.asarray(rate, dtype=float)
    if presliding <= 0.0:
        return np.sign(rate)
    steps = np.diff(np.asarray(position, dtype=float)).tolist()
    z = np.empty(len(rate))
    state = float(np.sign(rate[0])) if len(rate) else 0.0
    if len(rate):
        z[0] = state
    for k, step in enumerate(steps, start=1):
        if step != 0.0:
            s = 1.0 if step > 0.0 else -1.0
            state = s + (state - s) * math.exp(-abs(step) / presliding)
        z[k] = state
    return z

"""The velocity servo's per-step arithmetic, compiled (numba).

A step of the replay spends about as long in numpy's per-call overhead (some
twenty operations on 7- and 12-vectors) as DART spends integrating the closed
chain; these three kernels do the same arithmetic in three calls.  They are
the implementation (no numpy twin to drift from): `simulator.py` calls them
and adds the optional identified effects in numpy.  Compiled once per machine
(`cache=True`, under the package's __pycache__ or the user's cache folder), at
import: a process pays it with its imports, not inside a run.  A user who can
write neither (a read-only install, no home) compiles them in every process.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from dvrk_dart.model.joints import INSERTION


def _compiled(function):
    try:
        return njit(cache=True)(function)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        return njit(function)


@_compiled
def counterweight_acceleration(ddq3, dq3, q3, v_cw, x_cw, ratio, dt):
    """The ideal tendon's counterweight acceleration for a given ddq3: ratio·ddq3
    plus the deadbeat correction that makes the end-of-step velocity and position
    (semi-implicit Euler) equal ratio·q3 exactly:
    v_cw' = ratio dq3' + (ratio q3 - x_cw)/dt  =>  x_cw' = x_cw + dt v_cw' = ratio q3'."""
    return ratio * ddq3 + (ratio * dq3 - v_cw) / dt + (ratio * q3 - x_cw) / (dt * dt)


@_compiled
def servo_accelerations(x, v, q, dq, dq_des, q_des, inv_time_constant, dt, G, counterweight_dof, ratio):
    """(dq_target, ddq, xdd) of the deadbeat servo: the coordinates' target velocity
    (with position feedback when q_des has entries), the acceleration that reaches
    it in one step, and the dofs' accelerations (xdd = G ddq; the ideal tendon's
    counterweight row makes its next velocity and position ratio·q3 exactly)."""
    n = dq.shape[0]
    dq_target = np.empty(n)
    ddq = np.empty(n)
    for i in range(n):
        dq_target[i] = dq_des[i] + (q_des[i] - q[i]) * inv_time_constant if q_des.shape[0] else dq_des[i]
        ddq[i] = (dq_target[i] - dq[i]) / dt
    xdd = G @ ddq
    if counterweight_dof >= 0:
        cw = counterweight_dof
        xdd[cw] = counterweight_acceleration(ddq[INSERTION], dq[INSERTION], q[INSERTION], v[cw], x[cw], ratio, dt)
    return dq_target, ddq, xdd


@_compiled
def split_inverse_dynamics(F, effort_of_F, dof_forces_of_F):
    """(actuator efforts, forces on the dofs) from DART's inverse dynamics F."""
    return effort_of_F @ F, dof_forces_of_F @ F


@_compiled
def observe(x, v, coordinates_of_x, dq_before, dt, range_mid, range_half):
    """(q, dq, ddq of the step, whether every coordinate is finite and in its range)."""
    q = coordinates_of_x @ x
    dq = coordinates_of_x @ v
    ddq = (dq - dq_before) / dt
    in_range = True
    for i in range(q.shape[0]):
        if not abs(q[i] - range_mid[i]) <= range_half[i]:  # also False for NaN
            in_range = False
    return q, dq, ddq, in_range


def _compile() -> None:
    """Compile (or load from the cache) at import, on arrays of the right kinds."""
    n, m = 4, 3
    x, q, e = np.zeros(n), np.zeros(m), np.zeros(0)
    servo_accelerations(x, x, q, q, q, e, 1.0, 1e-3, np.zeros((n, m)), -1, 1.0)
    servo_accelerations(x, x, q, q, q, q, 1.0, 1e-3, np.zeros((n, m)), -1, 1.0)
    split_inverse_dynamics(x, np.zeros((m, n)), np.zeros((n, n)))
    counterweight_acceleration(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1e-3)
    observe(x, x, np.zeros((m, n)), q, 1e-3, q, q)


_compile()

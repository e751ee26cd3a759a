"""The simulator's per-step arithmetic, compiled (numba).

A step of the replay spends about as long in numpy's per-call overhead (some
twenty operations on 7- and 12-vectors) as DART spends integrating the closed
chain; these kernels do the same arithmetic in a few calls: the velocity
servo's, and the explicit efforts of the identified and diagnosed effects
(`effects.py`), which in numpy took longer than DART's step (a replay with a
diagnosis's effects ran at 8x real time, 27x without them: docs/speed.md).  They are the
implementation (no numpy twin to drift from).  Compiled once per machine
(`cache=True`, under the package's __pycache__ or the user's cache folder), at
import: a process pays it with its imports, not inside a run.  A user who can
write neither (a read-only install, no home) compiles them in every process.
"""

from __future__ import annotations

import math

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
def add_implicit(F, xdd, x, v, implicit_diag, damping, stiffness, dt):
    """DART's inverse dynamics F plus the implicit joint damping and springs at the end-of-step state (in place)."""
    F += implicit_diag * xdd + damping * v + stiffness * (x + dt * v)


@_compiled
def servo_efforts(F, xdd, x, v, dq, ddq, dq_target, explicit, effort_of_F, dof_forces_of_F, armature, directional_armature,
                  G, coulomb_x, damping, stiffness, dt):
    """(actuator efforts, forces on the dofs) of a servo step from the dofs' inverse dynamics F: the
    armature's (its directional part with the sign of dq) and the explicit efforts added; the Coulomb
    friction opposes the target velocity (in velocity mode DART has no Coulomb rows: the prescribed motion
    leaves the friction to the actuators' efforts), and the implicit damping and springs act at the
    end-of-step state, so the dofs' forces leave them to DART (terms that are zero cost a few flops)."""
    tau, forces = split_inverse_dynamics(F, effort_of_F, dof_forces_of_F)
    tau += (armature + directional_armature * np.sign(dq)) * ddq
    tau += explicit
    tau += G.T @ (coulomb_x * np.sign(G @ dq_target))
    v_next = v + dt * xdd
    forces -= damping * v_next + stiffness * (x + dt * v_next)
    return tau, forces


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


@_compiled
def explicit_effort(q, dq, presliding_state, per_joint, links, presliding, presliding_tables, angle_loads, loads, load_tables):
    """The explicit efforts (q space) of `effects.ExplicitEffects.tables`:
    per_joint rows offset, viscous, Coulomb, stiffness, smooth Coulomb, its velocity scale;
    links rows (coefficients..., Coulomb, viscous) of a friction on a linear combination of q;
    presliding rows (coefficients..., Coulomb, viscous) times the Dahl state, their Coulomb
    piecewise linear in the position where presliding_tables (count, knots..., values...) has knots;
    angle_loads rows (target, source, c_sin, c_cos); loads rows (target, source) with
    load_tables (count, knots..., values...): zero outside the knots."""
    n = q.shape[0]
    offset, viscous, coulomb, stiffness, smooth, reversal = per_joint
    effort = offset + viscous * dq + coulomb * np.sign(dq) + stiffness * q
    effort = effort + smooth * np.tanh(dq / reversal)
    for row in links:
        c = row[:n]
        rate = np.sum(dq * c)
        effort = effort + (row[n] * np.sign(rate) + row[n + 1] * rate) * c
    for i in range(presliding.shape[0]):
        c = presliding[i, :n]
        level = presliding[i, n]
        count = int(presliding_tables[i, 0])
        if count:
            level = np.interp(np.sum(q * c), presliding_tables[i, 1:1 + count], presliding_tables[i, 1 + count:1 + 2 * count])
        effort = effort + (level * presliding_state[i] + presliding[i, n + 1] * np.sum(dq * c)) * c
    for row in angle_loads:
        source = int(row[1])
        effort[int(row[0])] += row[2] * np.sin(q[source]) + row[3] * np.cos(q[source])
    for i in range(loads.shape[0]):
        count = int(load_tables[i, 0])
        knots, values = load_tables[i, 1:1 + count], load_tables[i, 1 + count:1 + 2 * count]
        x = q[int(loads[i, 1])]
        if knots[0] <= x <= knots[count - 1]:  # zero outside the table
            effort[int(loads[i, 0])] += np.interp(x, knots, values)
    return effort


@_compiled
def dahl_step(q, coefficients, position, state, distance):
    """Each pre-sliding friction's Dahl state after its position (coefficients·q) moved from `position`
    (model/friction.py's law; distance 0: the sign of the step); `position` and `state` updated in place."""
    n = q.shape[0]
    for i in range(coefficients.shape[0]):
        now = np.sum(q * coefficients[i, :n])
        step = now - position[i]
        position[i] = now
        if step != 0.0:
            s = 1.0 if step > 0.0 else -1.0
            state[i] = s if distance[i] <= 0.0 else s + (state[i] - s) * math.exp(-abs(step) / distance[i])


def _compile() -> None:
    """Compile (or load from the cache) at import, on arrays of the right kinds."""
    n, m = 4, 3
    x, q, e = np.zeros(n), np.zeros(m), np.zeros(0)
    servo_accelerations(x, x, q, q, q, e, 1.0, 1e-3, np.zeros((n, m)), -1, 1.0)
    servo_accelerations(x, x, q, q, q, q, 1.0, 1e-3, np.zeros((n, m)), -1, 1.0)
    split_inverse_dynamics(x, np.zeros((m, n)), np.zeros((n, n)))
    add_implicit(x, x, x, x, x, x, x, 1e-3)
    servo_efforts(x, x, x, x, q, q, q, q, np.zeros((m, n)), np.zeros((n, n)), q, q, np.zeros((n, m)), x, x, x, 1e-3)
    counterweight_acceleration(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1e-3)
    observe(x, x, np.zeros((m, n)), q, 1e-3, q, q)
    rows, tables = np.zeros((1, m + 2)), np.array([[2.0, 0.0, 1.0, 0.0, 1.0]])
    explicit_effort(q, q, np.zeros(1), np.ones((6, m)), rows, rows, tables, np.array([[0.0, 1.0, 0.0, 0.0]]), np.zeros((1, 2)), tables)
    dahl_step(q, rows, np.zeros(1), np.zeros(1), np.ones(1))


_compile()

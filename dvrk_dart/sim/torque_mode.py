"""Torque mode of the simulator (`PsmSimulator.step_torque`): the actuator
efforts are given and the step's accelerations, the ideal tendon's force and
the held joints' efforts come from one KKT solve of the closed-chain dynamics."""

from __future__ import annotations

import numpy as np

from dvrk_dart.model.joints import INSERTION, N_JOINTS


class TorqueMode:
    """The torque-mode step of `simulator.PsmSimulator` (a mixin: it reads the
    simulator's state, its reduced dynamics and its environment efforts)."""

    _held: tuple[int, ...] = ()

    def step_torque(self, tau: np.ndarray, hold: tuple[int, ...] = ()) -> None:
        """Torque mode: the 7 actuator efforts (N·m, N for q3) for this step.

        Joints in `hold` are instead kept still by the velocity servo (the
        paper torque-controls J1..J3 only); their entries of `last_effort` are
        the efforts the servo needed."""
        self._held = tuple(hold)
        self._dart_coulomb_rows(True)
        try:
            self._step_torque(np.asarray(tau, dtype=float))
        finally:
            self._held = ()

    def _prescribed_accelerations(self, size: int, q, dq, x, v) -> tuple[list[np.ndarray], list[float]]:
        """The rows c . ddz = d the step must meet (their multipliers are forces
        c lam): the ideal tendon's counterweight acceleration, and zero velocity
        at the end of the step for each held joint."""
        n = N_JOINTS
        rows, targets = [], []
        if self._free_dofs and self._tendon_ideal:
            c = np.zeros(n + 1)
            c[INSERTION], c[n] = -self.model.counterweight_ratio, 1.0
            rows.append(c)
            targets.append(self._counterweight_acceleration(self._zeros, q, dq, x, v))
        for j in self._held:
            c = np.zeros(size)
            c[j] = 1.0
            rows.append(c)
            targets.append(-dq[j] / self.dt)
        return rows, targets

    def _step_torque(self, tau: np.ndarray) -> None:
        """One torque-mode step: the actuator effort `tau` is given (joints in
        `self._held` are instead kept still by the velocity servo).

        Reduced dynamics in z = (q, x_cw):
            Mz ddz + bz = [tau - e_q - ratio·lam·e3 ; lam]
        with e_q the explicit (environment) efforts the actuators must overcome
        and lam the tendon force on the counterweight."""
        x, v = self._positions(), self._velocities()
        q, dq = self._coordinates(), self._coordinate_rates()
        Mz, bz = self._reduced_dynamics(x, v)
        n = N_JOINTS
        Ia = self._explicit.armature_at(dq)
        if self._has_armature:
            Mz[self._diag_q] += Ia
        explicit = self._explicit.effort(q, dq, self._presliding_z) if self._has_explicit else self._zeros
        ratio = self.model.counterweight_ratio
        has_cw = bool(self._free_dofs)
        lam = 0.0
        tau = tau.copy()
        rows, targets = self._prescribed_accelerations(Mz.shape[0], q, dq, x, v)
        tau[list(self._held)] = 0.0
        rhs = tau - explicit - bz[:n]
        if has_cw and not self._tendon_ideal:
            lam = self._counterweight_pid(q, dq, x, v)
            rhs[INSERTION] -= ratio * lam
            rhs = np.append(rhs, lam - bz[n])
        elif has_cw:
            rhs = np.append(rhs, -bz[n])
        sol = _solve_with_prescribed(Mz, rhs, rows, targets)
        ddq = sol[:n]
        ddf = float(sol[n]) if has_cw else 0.0
        multipliers = sol[len(rhs) :]
        if has_cw and self._tendon_ideal:
            lam, multipliers = float(multipliers[0]), multipliers[1:]
        for j, effort in zip(self._held, multipliers):
            tau[j] = effort  # the servo's effort on a held joint
        # generalized forces on the dofs: actuators, environment terms, armature, tendon
        force_q = tau - explicit if self._has_explicit else tau.copy()
        if self._has_armature:
            force_q = force_q - Ia * ddq
        force_q[INSERTION] -= ratio * lam
        forces = self._force_map @ force_q
        if has_cw:
            forces[self._free_dofs[0]] += lam
        if self._has_implicit:
            # joint damping and springs at the end-of-step velocity and position
            # (implicit, as DART's own would be), from the step's predicted acceleration
            ddx = self._Gz[:, :n] @ ddq
            if has_cw:
                ddx[self._free_dofs[0]] += ddf
            v_next = v + self.dt * ddx
            forces -= self._implicit_damping * v_next + self._implicit_stiffness * (x + self.dt * v_next)
        self.skeleton.setForces(forces)
        self.world.step()
        self._after_step(dq, tau, lam)

    def joint_space_dynamics(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(M, b, e) at the current state, in the coordinates q: DART's own
        closed-chain inertia (with the armature, and the counterweight folded in
        through the ideal tendon), its bias, and the explicit efforts, so that
        tau = M ddq + b + e (the computed torque of a controller, the paper's Eq. 6-7)."""
        x, v = self._positions(), self._velocities()
        q, dq = self._coordinates(), self._coordinate_rates()
        Mz, bz = self._reduced_dynamics(x, v)
        n = N_JOINTS
        if self._has_armature:
            Mz[self._diag_q] += self._explicit.armature_at(dq)
        explicit = self._explicit.effort(q, dq, self._presliding_z) if self._has_explicit else self._zeros
        if self._free_dofs and self._tendon_ideal:  # the counterweight follows q3: x_cw = ratio q3
            T = np.zeros((n + 1, n))
            T[:n, :n] = np.eye(n)
            T[n, INSERTION] = self.model.counterweight_ratio
            return T.T @ Mz @ T, T.T @ bz, explicit
        return Mz[:n, :n], bz[:n], explicit


def _solve_with_prescribed(Mz: np.ndarray, rhs: np.ndarray, rows: list, targets: list) -> np.ndarray:
    """Accelerations and multipliers of Mz ddz = rhs + C^T mu with C ddz = targets
    (the held joints' and an ideal tendon's prescribed accelerations): one KKT solve."""
    n, m = len(rhs), len(rows)
    kkt = np.zeros((n + m, n + m))
    kkt[:n, :n] = Mz
    if m:
        C = np.array(rows)
        kkt[:n, n:] = -C.T
        kkt[n:, :n] = C
    return np.linalg.solve(kkt, np.concatenate([rhs, targets]))

"""The DART simulator of the PSM: the closed-chain arm of `dart_builder.py`
driven in one of three modes, with the efforts read cleanly.

Modes
    kinematic  positions imposed (`set_kinematic`), no dynamics; every passive
               joint set from the model's linear relations.
    velocity   `step_velocity`: a joint velocity servo with unbounded effort on
               the 7 actuated coordinates.
    torque     `step_torque`: the 7 actuator efforts are commanded.

Reading efforts (library-notes: a VELOCITY/SERVO actuator reports 0 in
getForces() and its effort is mixed with the loop closures' in
getConstraintForces()).  Every DART joint is a FORCE actuator; the velocity
servo is computed here each step and commanded, so the recorded effort IS the
effort the simulation applied.  The servo is the discrete-time deadbeat law of
DART's own semi-implicit Euler step: the effort that brings the actuated
velocities to the target in one step,
    tau = M_c (dq_target - dq) / dt + b,
with M_c = G^T M G the closed-chain joint-space inertia built from DART's own
tree inertia M (G: the dofs as linear functions of q, whose range the loop
closure rows annihilate, so their forces drop out of G^T) and b = G^T h the
bias.  It is what DART's VELOCITY actuator does with its constraint impulse,
done as a force.  The loop closures are still enforced by DART's constraint
solver, and the acceleration logged is the one the step produced,
(dq_{k+1} - dq_k) / dt, so "model at the simulated state vs commanded effort"
checks DART's closed-chain dynamics, not the servo.

Counterweight variants (SimConfig.counterweight)
    on   ideal bilateral tendon: the counterweight joint and J3 receive equal
         and opposite tendon forces (+lambda on the counterweight, -ratio·lambda
         on J3), lambda solved each step from DART's own inertia so that the
         counterweight's next velocity and position equal ratio·q3 exactly
         (deadbeat, round-off level).  Why not DART's mimic joint with coupler
         constraint: see `COUNTERWEIGHT_NOTES`.
    off  no counterweight body.
    pid  the paper's mirror: the counterweight joint is driven by a PID tracking
         q3 and the force it needs is applied to J3 with the opposite sign (the
         tendon's reaction).

Identified non-inertial terms (SimConfig flags, JointEffects extras)
    - viscous friction, Coulomb friction and the J4 spring act on the DART
      joints whose own variable is the link's variable (yaw, pitch, carriage,
      tool roll, wrist pitch, jaws): the mapping is exact.  Coulomb friction is
      DART's joint friction (an LCP row bounded by Fc).  Viscous friction and
      the spring are NOT DART's joint damping/stiffness: DART applies those
      implicitly in its forward dynamics but its constraint impulses (the
      Coulomb rows) see the inertia without them, which on the near-massless
      tool dofs is off by orders of magnitude (measured: Coulomb + viscous on
      the tool roll gave a 0.5 N·m error, each alone was exact).  They are
      applied here the same implicit way (at the end-of-step velocity and
      position, acceleration solved with DART's closed-chain inertia plus
      dt·D + dt²·K), which is consistent with every constraint.  Against the
      model evaluated at the start-of-step state they differ by Fv·dt·ddq.
    - a smooth Coulomb reversal (JointEffects.coulomb_reversal_velocity > 0:
      Fc tanh(dq / v_r), the pre-sliding of a cable transmission found by the
      diagnosis) has no LCP row: it is a joint effort computed each step from
      the simulated velocity, like the terms below.
    - friction of the motor-side pseudo links (14, 15, 16: no DART body),
      the offsets Fo and every JointEffects term on the motor coordinates q5..q7
      (not a DART joint variable) are explicit model-based efforts computed from
      the state at the start of each step and applied as joint forces mapped with
      A^-T (A: the actuated dofs as functions of q; W^T for the wrist).
    - motor inertia: DART 6.20 has no joint armature (no API), and the identified
      Im are partly negative.  Both are applied as the model-based effort
      -I_a·ddq, with ddq of the step solved implicitly from DART's closed-chain
      inertia (M_c + I_a) ddq = tau - b: exactly an armature (and the identified
      negative values too).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from dvrk_dart.errors import DvrkDartError, SimulationDiverged
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES, N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters
from dvrk_dart.sim.builder import DartPsm, build
from dvrk_dart.sim.config import SimConfig

#: position feedback of the velocity servo when a reference position is given:
#: the target velocity is dq_des + (q_des - q) / tau_pos. The measured dq is not
#: exactly d/dt of the measured q (0.013 rad/s RMS apart, drifting up to 9 mrad
#: over a run): 1 s removes the drift without turning that mismatch into
#: acceleration noise (at 50 ms it cost 0.05 N·m of replay noise).
POSITION_FEEDBACK_TIME_CONSTANT_S = 1.0

#: the loop-closure residual is checked for divergence every this many steps
#: (10 ms at 1 ms); NaN and joint ranges are checked every step
CLOSURE_CHECK_EVERY_STEPS = 10

COUNTERWEIGHT_NOTES = """Why the tendon is not DART's mimic joint with coupler
constraint (Joint.setProperties(..., MIMIC, leader = J3, 1, 0) +
setUseCouplerConstraint(True)).  Measured on this arm, torque mode, J1..J7
holding g(q) with a 1 N cosine on J3 for 2 s at 1 ms: the counterweight strays
up to 2.2e-4 m from q3 (the coupler is a velocity-level motor row whose target
is the leader's start-of-step velocity: a lag of one step, no position
correction).  The same test with the constraint solved here: 6e-13 m.  Under the
deadbeat velocity servo the coupler oscillated and diverged within 12 steps."""


@dataclass(frozen=True)
class _Explicit:
    """Per-coordinate explicit terms (q coordinates, 7 each)."""

    coulomb: np.ndarray
    viscous: np.ndarray
    stiffness: np.ndarray
    offset: np.ndarray
    armature: np.ndarray
    smooth_coulomb: np.ndarray  # Fc of the joints with a smooth reversal
    reversal_velocity: np.ndarray  # their velocity scale (1 where unused)


class PsmSimulator:
    """The closed-chain PSM in DART.

    Coordinates are the identification model's (q1..q7, joints.py); efforts
    carry the sign of the generalized force the actuator applies."""

    def __init__(self, model: PsmModel, params: IdentifiedParameters, config: SimConfig = SimConfig()):
        self.model = model
        self.params = params
        self.config = config
        self.dt = float(config.dt_s)
        self.psm: DartPsm = build(model, params, config)
        self.skeleton = self.psm.skeleton
        self.world = self.psm.world
        n = self.psm.n_dofs
        self._A_inv = np.linalg.inv(self.psm.A)
        # generalized force on the dofs from a q-space force on the actuators: tau_x = S^T A^-T f
        self._force_map = np.zeros((n, N_JOINTS))
        self._force_map[self.psm.actuated_dofs] = self._A_inv.T
        # reduced coordinates z = (q, free dofs): x = Gz z; the counterweight is a free dof
        # of the tree, tied to q3 by the tendon force of `_tendon`
        self._free_dofs = [] if self.psm.counterweight_dof is None else [self.psm.counterweight_dof]
        Gz = np.zeros((n, N_JOINTS + len(self._free_dofs)))
        Gz[:, :N_JOINTS] = self.psm.G
        for i, dof in enumerate(self._free_dofs):
            Gz[dof, N_JOINTS + i] = 1.0
        self._Gz = Gz
        self._implicit_damping = np.zeros(n)
        self._implicit_stiffness = np.zeros(n)
        self._coulomb_x = np.zeros(n)
        self._explicit = self._setup_effects()
        self._pid_integral = 0.0
        self._state: tuple[np.ndarray, np.ndarray] | None = None  # (x, v) after the last step
        self._feedback_q: np.ndarray | None = None
        self._act = self.psm.actuated_dofs
        self._implicit_diag = self.dt * self._implicit_damping + self.dt**2 * self._implicit_stiffness
        self._has_implicit = bool(np.any(self._implicit_diag))
        self._diag = np.diag_indices(n)
        self._diag_q = np.diag_indices(N_JOINTS)
        self._zeros = np.zeros(N_JOINTS)
        self._range_mid = 0.5 * (model.joint_upper + model.joint_lower)
        self._range_half = 0.5 * (model.joint_upper - model.joint_lower)
        self._tendon_ideal = config.counterweight == "on"
        e = self._explicit
        self._has_armature = bool(np.any(e.armature))
        self._has_coulomb = bool(np.any(self._coulomb_x))
        self._has_explicit = bool(
            np.any(e.coulomb) or np.any(e.viscous) or np.any(e.stiffness) or np.any(e.offset) or np.any(e.smooth_coulomb) or self._explicit_friction_links
        )
        self.step_index = 0
        self.last_effort = np.full(N_JOINTS, np.nan)
        self.last_ddq = np.zeros(N_JOINTS)
        self.last_counterweight_force = 0.0
        self.reset(np.zeros(N_JOINTS))

    # ----------------------------------------------------------------- setup
    def _setup_effects(self) -> _Explicit:
        """Put the selected physical effects on DART joints where the mapping is
        exact; return the rest as explicit per-coordinate terms."""
        cfg, model, params = self.config, self.model, self.params
        coulomb, viscous, stiffness, offset, armature = (np.zeros(N_JOINTS) for _ in range(5))
        dof_of = {key: i for i, key in enumerate(self.psm.dof_links)}
        self._explicit_friction_links = []  # motor-side links: explicit, on their variable's rate
        for link in model.links.values():
            p = params[link.key]
            dof = dof_of.get(link.key)
            on_own_dof = dof is not None and dof in set(self.psm.actuated_dofs)
            if cfg.friction and link.friction and (p.coulomb or p.viscous):
                if on_own_dof:
                    self._set_damping(dof, p.viscous)
                    self._set_coulomb(dof, p.coulomb)
                else:
                    self._explicit_friction_links.append(link)
            if cfg.offsets and link.friction and p.offset:
                offset += p.offset * link.variable.coeffs
            if cfg.spring and link.spring and p.spring:
                if not on_own_dof:
                    raise DvrkDartError(f"link {link.key}: a spring on a variable without its own joint is not supported")
                self._set_stiffness(dof, p.spring)
            if cfg.motor_inertia and link.motor_inertia and p.motor_inertia:
                j = int(np.flatnonzero(link.variable.coeffs)[0])
                armature[j] += p.motor_inertia * link.variable.coeffs[j]
        extra = cfg.extra
        extra_arm = np.asarray(extra.armature, dtype=float)
        if np.any(extra_arm < 0.0):
            raise DvrkDartError("SimConfig.extra.armature must be >= 0 (a physical armature)")
        armature += extra_arm
        offset += np.asarray(extra.offset, dtype=float)
        # extras on q1..q4 are DART joint physics (the actuated dof is the coordinate);
        # on the motor coordinates q5..q7 they are explicit.
        reversal = np.asarray(extra.coulomb_reversal_velocity, dtype=float)
        if np.any(reversal < 0.0):
            raise DvrkDartError("SimConfig.extra.coulomb_reversal_velocity must be >= 0")
        smooth = reversal > 0.0
        smooth_coulomb = np.where(smooth, np.asarray(extra.coulomb, dtype=float), 0.0)
        for j in range(N_JOINTS):
            dof = self.psm.actuated_dofs[j]
            direct = np.count_nonzero(self.psm.A[j]) == 1 and self.psm.A[j, j] == 1.0
            sharp_coulomb = 0.0 if smooth[j] else extra.coulomb[j]  # a smooth reversal has no LCP row
            if direct:
                self._set_damping(dof, self._implicit_damping[dof] + extra.viscous[j])
                self._set_coulomb(dof, self._coulomb_x[dof] + sharp_coulomb)
                self._set_stiffness(dof, self._implicit_stiffness[dof] + extra.stiffness[j])
            else:
                coulomb[j] += sharp_coulomb
                viscous[j] += extra.viscous[j]
                stiffness[j] += extra.stiffness[j]
        return _Explicit(coulomb, viscous, stiffness, offset, armature, smooth_coulomb, np.where(smooth, reversal, 1.0))

    def _set_damping(self, dof: int, value: float) -> None:
        # not DART's joint damping: see the module docstring (implicit, applied in _step)
        self._implicit_damping[dof] = value

    def _set_coulomb(self, dof: int, value: float) -> None:
        self._coulomb_x[dof] = value
        self.skeleton.getDof(dof).setCoulombFriction(value)

    def _set_stiffness(self, dof: int, value: float) -> None:
        # not DART's joint spring: see the module docstring (implicit, rest at 0, applied in _step)
        self._implicit_stiffness[dof] = value

    # ------------------------------------------------------------- state
    def _x_of(self, q: np.ndarray) -> np.ndarray:
        x = self.psm.G @ q
        for dof in self._free_dofs:  # the counterweight starts on ratio·q3
            x[dof] = q[INSERTION] * self.model.counterweight_ratio
        return x

    def reset(self, q: np.ndarray, dq: np.ndarray | None = None) -> None:
        """Put the arm at q (closed loops, passive joints on their relations), velocity dq."""
        self.set_kinematic(q, dq)
        self.skeleton.resetAccelerations()
        self.skeleton.resetGeneralizedForces()
        self.world.setTime(0.0)
        self.step_index = 0
        self._pid_integral = 0.0
        self.last_ddq = np.zeros(N_JOINTS)
        self.last_counterweight_force = 0.0

    def set_kinematic(self, q: np.ndarray, dq: np.ndarray | None = None) -> None:
        """Kinematic mode: impose the pose (and velocity); no dynamics, no effort."""
        q = np.asarray(q, dtype=float)
        dq = np.zeros(N_JOINTS) if dq is None else np.asarray(dq, dtype=float)
        self.skeleton.setPositions(self._x_of(q))
        self.skeleton.setVelocities(self._x_of(dq))
        self._state = None
        self.last_effort = np.full(N_JOINTS, np.nan)

    @property
    def time_s(self) -> float:
        return float(self.world.getTime())

    @property
    def q(self) -> np.ndarray:
        """The 7 coordinates, from DART's actuated joints."""
        return self._A_inv @ self.skeleton.getPositions()[self.psm.actuated_dofs]

    @property
    def dq(self) -> np.ndarray:
        return self._A_inv @ self.skeleton.getVelocities()[self.psm.actuated_dofs]

    @property
    def counterweight_position_m(self) -> float | None:
        cw = self.psm.counterweight_dof
        return None if cw is None else float(self.skeleton.getPosition(cw))

    # ---------------------------------------------------------- dynamics
    def _reduced_dynamics(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closed-chain inertia and bias in z = (q, free dofs), including DART's
        implicit joint damping and stiffness (applied at the end-of-step state)."""
        M = self.skeleton.getMassMatrix()
        h = self.skeleton.getCoriolisAndGravityForces()
        if self._has_implicit:
            D, K = self._implicit_damping, self._implicit_stiffness
            M[self._diag] += self._implicit_diag
            h = h + D * v + K * (x + self.dt * v)  # DART's spring rest position is 0
        Gz = self._Gz
        return Gz.T @ M @ Gz, Gz.T @ h

    def _explicit_effort(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Model-based efforts the actuators must supply beyond DART's physics (q space)."""
        e = self._explicit
        effort = e.offset + e.viscous * dq + e.coulomb * np.sign(dq) + e.stiffness * q
        effort = effort + e.smooth_coulomb * np.tanh(dq / e.reversal_velocity)
        for link in self._explicit_friction_links:
            p = self.params[link.key]
            rate = float(dq @ link.variable.coeffs)
            effort = effort + (p.coulomb * np.sign(rate) + p.viscous * rate) * link.variable.coeffs
        return effort

    def _counterweight_pid(self, q: np.ndarray, dq: np.ndarray, x: np.ndarray, v: np.ndarray) -> float:
        kp, ki, kd = self.config.counterweight_pid
        cw = self.psm.counterweight_dof
        ratio = self.model.counterweight_ratio
        error = ratio * q[INSERTION] - x[cw]
        self._pid_integral += error * self.dt
        return kp * error + ki * self._pid_integral + kd * (ratio * dq[INSERTION] - v[cw])

    def _step(self, tau: np.ndarray | None, dq_target: np.ndarray | None) -> None:
        """One step: either the actuator effort `tau` is given (torque mode) or
        the velocity `dq_target` the servo must reach at the end of the step.

        Reduced dynamics in z = (q, x_cw):
            Mz ddz + bz = [tau - e_q - ratio·lam·e3 ; lam]
        with e_q the explicit (environment) efforts the actuators must overcome
        and lam the tendon force on the counterweight."""
        x, v = self._state if self._state is not None else (self.skeleton.getPositions(), self.skeleton.getVelocities())
        q = self._A_inv @ x[self._act]
        dq = self._A_inv @ v[self._act]
        Mz, bz = self._reduced_dynamics(x, v)
        n = N_JOINTS
        Ia = self._explicit.armature
        if self._has_armature:
            Mz[self._diag_q] += Ia
        explicit = self._explicit_effort(q, dq) if self._has_explicit else self._zeros
        ratio = self.model.counterweight_ratio
        has_cw = bool(self._free_dofs)
        lam = 0.0
        ddf = 0.0
        if dq_target is not None:
            if self._feedback_q is not None:  # position feedback: the target depends on q
                dq_target = dq_target + (self._feedback_q - q) / POSITION_FEEDBACK_TIME_CONSTANT_S
            ddq = (dq_target - dq) / self.dt
            tau = Mz[:n, :n] @ ddq + bz[:n] + explicit
            if self._has_coulomb:  # DART's Coulomb rows sit at their bound, opposing the target velocity
                tau += self.psm.G.T @ (self._coulomb_x * np.sign(self.psm.G @ dq_target))
            if has_cw:
                if self._tendon_ideal:
                    ddf = self._counterweight_acceleration(ddq, q, dq, x, v)
                    lam = float(Mz[n, :n] @ ddq + Mz[n, n] * ddf + bz[n])  # the tension that produces ddf
                else:
                    lam = self._counterweight_pid(q, dq, x, v)
                    ddf = (lam - bz[n] - Mz[n, :n] @ ddq) / Mz[n, n]
                tau += Mz[:n, n] * ddf
                tau[INSERTION] += ratio * lam
        else:
            tau = tau.copy()
            rows, targets = [], []  # prescribed-acceleration rows c . ddz = d; their multipliers are forces c lam
            if has_cw and self._tendon_ideal:
                c = np.zeros(n + 1)
                c[INSERTION], c[n] = -ratio, 1.0
                rows.append(c)
                targets.append(self._counterweight_acceleration(self._zeros, q, dq, x, v))
            for j in self._held:  # joints held by the velocity servo: reach zero velocity in this step
                c = np.zeros(Mz.shape[0])
                c[j] = 1.0
                rows.append(c)
                targets.append(-dq[j] / self.dt)
                tau[j] = 0.0
            rhs = tau - explicit - bz[:n]
            if has_cw and not self._tendon_ideal:
                lam = self._counterweight_pid(q, dq, x, v)
                rhs[INSERTION] -= ratio * lam
                rhs = np.append(rhs, lam - bz[n])
            elif has_cw:
                rhs = np.append(rhs, -bz[n])
            m = len(rows)
            kkt = np.zeros((len(rhs) + m, len(rhs) + m))
            kkt[: len(rhs), : len(rhs)] = Mz
            if m:
                C = np.array(rows)
                kkt[: len(rhs), len(rhs) :] = -C.T
                kkt[len(rhs) :, : len(rhs)] = C
            sol = np.linalg.solve(kkt, np.concatenate([rhs, targets]))
            ddq = sol[:n]
            ddf = float(sol[n]) if has_cw else 0.0
            multipliers = sol[len(rhs) :]
            if has_cw and self._tendon_ideal:
                lam, multipliers = float(multipliers[0]), multipliers[1:]
            for j, effort in zip(self._held, multipliers):
                tau[j] = effort  # the servo's effort on a held joint
        # generalized forces on the dofs: actuators, environment terms, armature, tendon
        force_q = tau - explicit
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
        self.step_index += 1
        x_next = self.skeleton.getPositions()
        v_next = self.skeleton.getVelocities()
        self._state = (x_next, v_next)  # DART's state only changes in step/reset/set_kinematic
        self.last_ddq = (self._A_inv @ v_next[self._act] - dq) / self.dt
        self.last_effort = tau if dq_target is not None else tau.copy()
        self.last_counterweight_force = lam
        self._check(x_next, v_next)

    def _counterweight_acceleration(self, ddq: np.ndarray, q, dq, x, v) -> float:
        """Counterweight acceleration of the ideal tendon for a given ddq:
        ratio·ddq3 plus the deadbeat correction that makes the end-of-step
        velocity and position (semi-implicit Euler) equal ratio·q3 exactly."""
        cw, r = self._free_dofs[0], self.model.counterweight_ratio
        dt = self.dt
        # v_cw' = ratio dq3' + (ratio q3 - x_cw)/dt  =>  x_cw' = x_cw + dt v_cw' = ratio q3'
        return r * ddq[INSERTION] + (r * dq[INSERTION] - v[cw]) / dt + (r * q[INSERTION] - x[cw]) / (dt * dt)

    def step_velocity(self, dq_des: np.ndarray, q_des: np.ndarray | None = None) -> None:
        """Velocity mode: reach dq_des in this step (position feedback to q_des if given)."""
        self._feedback_q = None if q_des is None else np.asarray(q_des, dtype=float)
        self._step(None, np.asarray(dq_des, dtype=float))

    def step_torque(self, tau: np.ndarray, hold: tuple[int, ...] = ()) -> None:
        """Torque mode: the 7 actuator efforts (N·m, N for q3) for this step.

        Joints in `hold` are instead kept still by the velocity servo (the
        paper torque-controls J1..J3 only); their entries of `last_effort` are
        the efforts the servo needed."""
        self._held = tuple(hold)
        try:
            self._step(np.asarray(tau, dtype=float), None)
        finally:
            self._held = ()

    # ---------------------------------------------------------- checks
    def closure_residuals_m(self) -> dict[str, float]:
        out = {}
        for c in self.psm.closures:
            Ta = self.psm.bodies[c.link].getWorldTransform().matrix()
            Tb = self.psm.bodies[c.other].getWorldTransform().matrix()
            pa = Ta[:3, :3] @ c.point_in_link + Ta[:3, 3]
            pb = Tb[:3, :3] @ c.point_in_other + Tb[:3, 3]
            out[c.name] = float(np.linalg.norm(pa - pb))
        return out

    def closure_residual_m(self) -> float:
        """Largest loop-closure gap (m) over the loops."""
        return max(self.closure_residuals_m().values(), default=0.0)

    def passive_joint_errors(self) -> dict[str, float]:
        """Passive dof (and coupled counterweight) minus the model's linear relation (rad, m)."""
        x = self.skeleton.getPositions()
        expected = self.psm.G @ self.q
        dofs = list(self.psm.passive_dofs)
        if self.psm.counterweight_dof is not None:
            dofs.append(self.psm.counterweight_dof)
            expected[self.psm.counterweight_dof] = self.q[INSERTION] * self.model.counterweight_ratio
        return {self.model.links[self.psm.dof_links[d]].name: float(x[d] - expected[d]) for d in dofs}

    def counterweight_error_m(self) -> float | None:
        """Counterweight position minus ratio·q3 (the transmission's exactness)."""
        cw = self.counterweight_position_m
        return None if cw is None else cw - self.model.counterweight_ratio * float(self.q[INSERTION])

    def _check(self, x: np.ndarray, v: np.ndarray) -> None:
        """Divergence checks: NaN and joint range every step, loop closure every
        CLOSURE_CHECK_EVERY_STEPS steps (its frame queries cost more than a step)."""
        q = self._A_inv @ x[self._act]
        lower, upper = self.model.joint_lower, self.model.joint_upper
        finite = math.isfinite(x.sum() + v.sum())
        in_range = finite and bool((np.abs(q - self._range_mid) <= self._range_half).all())
        check_loops = self.step_index % CLOSURE_CHECK_EVERY_STEPS == 0
        if in_range and not check_loops:
            return
        where = f"step {self.step_index} (t = {self.time_s:.3f} s)"
        if not finite:
            bad = int(np.flatnonzero(~(np.isfinite(x) & np.isfinite(v)))[0])
            raise SimulationDiverged(f"{where}: joint {self.skeleton.getDof(bad).getName()} is not finite")
        outside = np.flatnonzero((q < lower) | (q > upper))
        if outside.size:
            j = int(outside[0])
            # repr: the shortest text that is the exact value, so the violation shows
            raise SimulationDiverged(f"{where}: joint {JOINT_NAMES[j]} at {float(q[j])!r} outside its range [{float(lower[j])!r}, {float(upper[j])!r}]")
        residuals = self.closure_residuals_m()
        name, worst = max(residuals.items(), key=lambda kv: kv[1], default=("", 0.0))
        if worst > self.config.closure_residual_limit_m:
            raise SimulationDiverged(f"{where}: loop {name} open by {worst:.3g} m (limit {self.config.closure_residual_limit_m:g} m)")

    # ------------------------------------------------------------ frames
    def link_transform(self, key: int) -> np.ndarray:
        """4x4 base-frame transform of a link frame (DART bodies and fixed frames)."""
        if key in self.psm.bodies:
            return self.psm.bodies[key].getWorldTransform().matrix()
        if key in self.psm.fixed_frames:
            parent, offset = self.psm.fixed_frames[key]
            return (self.link_transform(parent) if parent else np.eye(4)) @ offset
        raise DvrkDartError(f"link {key} has no frame in this simulation")

    def tool_tip_pose(self) -> np.ndarray:
        tip = self.model.tool_tip
        return self.link_transform(tip.parent) @ tip.transform(self.q)

    def body_positions(self) -> dict[str, np.ndarray]:
        """Link name -> frame origin (base frame, m) of every simulated link frame."""
        keys = list(self.psm.fixed_frames) + list(self.psm.bodies)
        return {self.model.links[k].name: self.link_transform(k)[:3, 3].copy() for k in sorted(keys)}


def measure_realtime_factor(seconds: float = 5.0, config: SimConfig = SimConfig()) -> float:
    """Simulated seconds per wall second of the full arm (velocity servo on a
    smooth multi-joint motion), for the benchmark."""
    from dvrk_dart.io.reference_data import resolve
    from dvrk_dart.model.description import load_model
    from dvrk_dart.model.parameters import load_parameters

    model = load_model()
    params = load_parameters(resolve(model.default_parameters), model)
    sim = PsmSimulator(model, params, config)
    centre = 0.5 * (model.joint_lower + model.joint_upper)
    amplitude = 0.2 * (model.joint_upper - model.joint_lower)
    sim.reset(centre)
    steps = int(round(seconds / sim.dt))
    omega = 2.0 * np.pi * 0.5  # rad/s, a motion of the kind of the excitation trajectories
    start = time.perf_counter()
    for k in range(steps):
        t = (k + 1) * sim.dt
        sim.step_velocity(amplitude * omega * np.cos(omega * t))
    return seconds / (time.perf_counter() - start)

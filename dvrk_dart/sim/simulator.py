"""The DART simulator of the PSM: the closed-chain arm of `builder.py`
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
done as a force.  Evaluated as G^T F, with F = M G ddq + h from DART's inverse
dynamics (one recursive pass, cheaper than forming M); the per-step arithmetic
is compiled (kernels.py).  The loop closures are still enforced by DART's constraint
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

Identified non-inertial terms (SimConfig flags, JointEffects extras): where
each acts (a DART joint, the implicit damping and springs applied here, or an
explicit model-based effort) is decided in `effects.py`; its docstring says why.
Frames, closure residuals and divergence checks: `readout.py`.
"""

from __future__ import annotations

import numpy as np

from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import INSERTION, N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters
from dvrk_dart.sim import kernels
from dvrk_dart.sim.builder import DartPsm, build
from dvrk_dart.sim.config import SimConfig
from dvrk_dart.sim.effects import place_effects
from dvrk_dart.sim.readout import RANGE_TOLERANCE, ClosedChainReadout
from dvrk_dart.sim.torque_mode import TorqueMode

#: position feedback of the velocity servo when a reference position is given:
#: the target velocity is dq_des + (q_des - q) / tau_pos. The measured dq is not
#: exactly d/dt of the measured q (0.013 rad/s RMS apart, drifting up to 9 mrad
#: over a run): 1 s removes the drift without turning that mismatch into
#: acceleration noise (at 50 ms it cost 0.05 N·m of replay noise).
POSITION_FEEDBACK_TIME_CONSTANT_S = 1.0

COUNTERWEIGHT_NOTES = """Why the tendon is not DART's mimic joint with coupler
constraint (Joint.setProperties(..., MIMIC, leader = J3, 1, 0) +
setUseCouplerConstraint(True)).  Measured on this arm, torque mode, J1..J7
holding g(q) with a 1 N cosine on J3 for 2 s at 1 ms: the counterweight strays
up to 2.2e-4 m from q3 (the coupler is a velocity-level motor row whose target
is the leader's start-of-step velocity: a lag of one step, no position
correction).  The same test with the constraint solved here: 6e-13 m.  Under the
deadbeat velocity servo the coupler oscillated and diverged within 12 steps."""


class PsmSimulator(ClosedChainReadout, TorqueMode):
    """The closed-chain PSM in DART.

    Coordinates are the identification model's (q1..q7, joints.py); efforts
    carry the sign of the generalized force the actuator applies."""

    def __init__(self, model: PsmModel, params: IdentifiedParameters, config: SimConfig = SimConfig()):
        self.model = model
        self.params = params
        self.config = config
        self.dt = float(config.dt_s)
        self.psm: DartPsm = build(model, params, config)
        #: the environment's force on the instrument point, a function of its position and velocity
        #: (base frame), or None; `last_external_force` is the one of the last step (runs/contact.py)
        self.external_force = None
        self.last_external_force = np.zeros(3)
        self.skeleton = self.psm.skeleton
        self.world = self.psm.world
        self._setup_coordinates(model)
        self._setup_effects(model, params, config)
        self.step_index = 0
        self.last_effort = np.full(N_JOINTS, np.nan)
        self.last_ddq = np.zeros(N_JOINTS)
        self.last_counterweight_force = 0.0
        self._setup_readout()
        self.reset(np.zeros(N_JOINTS))

    def _setup_coordinates(self, model: PsmModel) -> None:
        """The maps between the joint coordinates q, the tree's dofs x and the reduced coordinates z."""
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
        self._GzT = Gz.T
        # velocity servo by DART's inverse dynamics F = M xdd + h (one recursive pass,
        # cheaper than forming M): with the dofs' acceleration xdd = Gz ddz, the
        # reduced efforts are Gz^T F, i.e. the actuator effort (the tendon's share
        # ratio·F_cw added on J3) and the tendon force F_cw itself
        G = self.psm.G
        self._effort_of_F = G.T.copy()  # tau = Q F
        self._dof_forces_of_F = self._force_map @ G.T  # forces on the dofs = P F (+ coulomb)
        if self.psm.counterweight_dof is not None:
            cw = self.psm.counterweight_dof
            self._effort_of_F[INSERTION, cw] += model.counterweight_ratio
            self._dof_forces_of_F[cw, cw] = 1.0
        self._coordinates_of_x = self._A_inv @ np.eye(n)[self.psm.actuated_dofs]  # q = B x
        self._counterweight_dof = -1 if self.psm.counterweight_dof is None else int(self.psm.counterweight_dof)
        self._no_reference = np.zeros(0)
        self._diag = np.diag_indices(n)
        self._diag_q = np.diag_indices(N_JOINTS)
        self._zeros = np.zeros(N_JOINTS)
        self._range_mid = 0.5 * (model.joint_upper + model.joint_lower)
        self._range_half = 0.5 * (model.joint_upper - model.joint_lower) + RANGE_TOLERANCE

    def _setup_effects(self, model: PsmModel, params: IdentifiedParameters, config: SimConfig) -> None:
        """The identified friction and the configured effects, placed on the dofs, and the state they keep."""
        effects = place_effects(model, params, config, self.psm)
        self._implicit_damping = effects.damping
        self._implicit_stiffness = effects.stiffness
        self._coulomb_x = effects.coulomb
        self._coulomb_rows_on = True  # place_effects set them on DART's joints
        self._explicit = effects.explicit
        self._pid_integral = 0.0
        self._implicit_diag = self.dt * self._implicit_damping + self.dt**2 * self._implicit_stiffness
        self._has_implicit = bool(np.any(self._implicit_diag))
        self._tendon_ideal = config.counterweight == "on"
        e = self._explicit
        self._has_armature = bool(np.any(e.armature) or np.any(e.directional_armature))
        self._has_explicit = e.any_effort
        self._has_terms = self._has_armature or self._has_explicit or self._has_implicit or bool(np.any(self._coulomb_x))
        self._presliding = bool(e.presliding)
        self._presliding_position = np.zeros(len(e.presliding))  # where each Dahl state last moved from
        self._presliding_z = np.zeros(len(e.presliding))

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
        self._state_changed()
        self.last_effort = np.full(N_JOINTS, np.nan)
        # an imposed state starts each pre-sliding friction sliding the way it moves
        coefficients = self._explicit.presliding_coefficients
        self._presliding_position = coefficients @ q
        self._presliding_z = np.sign(coefficients @ dq)

    @property
    def time_s(self) -> float:
        return float(self.world.getTime())

    @property
    def q(self) -> np.ndarray:
        """The 7 coordinates, from DART's actuated joints."""
        return self._coordinates().copy()

    @property
    def dq(self) -> np.ndarray:
        return self._coordinate_rates().copy()

    def dof_positions(self) -> np.ndarray:
        """DART's dof positions (shared: do not modify)."""
        return self._positions()

    # DART's state (dofs x, v) and the coordinates (q, dq), read once per state:
    # DART's state only changes in a step, reset or set_kinematic (_state_changed)
    def _state_changed(self) -> None:
        super()._state_changed()
        self._x = self.skeleton.getPositions()
        self._v = self.skeleton.getVelocities()
        self._q = self._coordinates_of_x @ self._x
        self._dq = self._coordinates_of_x @ self._v

    def _positions(self) -> np.ndarray:
        return self._x

    def _velocities(self) -> np.ndarray:
        return self._v

    def _coordinates(self) -> np.ndarray:
        return self._q

    def _coordinate_rates(self) -> np.ndarray:
        return self._dq

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
        GzT = self._GzT
        return GzT @ M @ self._Gz, GzT @ h

    def _counterweight_pid(self, q: np.ndarray, dq: np.ndarray, x: np.ndarray, v: np.ndarray) -> float:
        kp, ki, kd = self.config.counterweight_pid or self.model.controller_gain("counterweight_pid")
        cw = self.psm.counterweight_dof
        ratio = self.model.counterweight_ratio
        error = ratio * q[INSERTION] - x[cw]
        self._pid_integral += error * self.dt
        return kp * error + ki * self._pid_integral + kd * (ratio * dq[INSERTION] - v[cw])

    def _counterweight_acceleration(self, ddq: np.ndarray, q, dq, x, v) -> float:
        """Counterweight acceleration of the ideal tendon for a given ddq (kernels.py)."""
        cw = self._counterweight_dof
        return kernels.counterweight_acceleration(ddq[INSERTION], dq[INSERTION], q[INSERTION], v[cw], x[cw],
                                                  self.model.counterweight_ratio, self.dt)

    def step_velocity(self, dq_des: np.ndarray, q_des: np.ndarray | None = None) -> None:
        """Velocity mode: reach dq_des in this step (position feedback to q_des if given).

        The deadbeat servo of the module docstring, evaluated with DART's inverse
        dynamics F = M xdd + h at the dofs' accelerations xdd = G ddq (+ the
        counterweight's): tau = G^T F + ratio·F_cw on J3, F_cw being the tendon
        force.  The ideal tendon sets the counterweight's acceleration; the PID
        tendon sets its force, and the acceleration follows from M's column."""
        self._dart_coulomb_rows(False)
        x, v, q, dq = self._x, self._v, self._q, self._dq
        ideal_cw = self._counterweight_dof if self._tendon_ideal else -1
        dq_target, ddq, xdd = kernels.servo_accelerations(
            x, v, q, dq, np.asarray(dq_des, dtype=float), self._no_reference if q_des is None else np.asarray(q_des, dtype=float),
            1.0 / POSITION_FEEDBACK_TIME_CONSTANT_S, self.dt, self.psm.G, ideal_cw, self.model.counterweight_ratio)
        skeleton = self.skeleton
        skeleton.setAccelerations(xdd)
        touching = self._apply_external_force()
        skeleton.computeInverseDynamics(touching, False, False)
        F = skeleton.getForces()
        if self._has_implicit:  # DART's implicit damping and springs at the end-of-step state
            kernels.add_implicit(F, xdd, x, v, self._implicit_diag, self._implicit_damping, self._implicit_stiffness, self.dt)
        if self._free_dofs and not self._tendon_ideal:  # the PID's tension gives the counterweight's acceleration
            cw = self._counterweight_dof
            column = skeleton.getMassMatrix()[:, cw].copy()
            column[cw] += self._implicit_diag[cw]
            xdd[cw] = (self._counterweight_pid(q, dq, x, v) - F[cw]) / column[cw]
            F += column * xdd[cw]
        if self._has_terms:
            explicit = self._explicit.effort(q, dq, self._presliding_z) if self._has_explicit else self._zeros
            e = self._explicit
            tau, forces = kernels.servo_efforts(F, xdd, x, v, dq, ddq, dq_target, explicit, self._effort_of_F, self._dof_forces_of_F,
                                                e.armature, e.directional_armature, self.psm.G, self._coulomb_x,
                                                self._implicit_damping, self._implicit_stiffness, self.dt)
        else:  # the rigid bodies alone
            tau, forces = kernels.split_inverse_dynamics(F, self._effort_of_F, self._dof_forces_of_F)
        skeleton.setForces(forces)
        self.world.step()
        self._after_step(dq, tau, float(F[self._counterweight_dof]) if self._free_dofs else 0.0)

    def _dart_coulomb_rows(self, on: bool) -> None:
        """DART's Coulomb rows (LCP rows bounded by Fc) for the torque mode's stick-slip; off in velocity mode,
        where the motion is prescribed and the servo's efforts carry the friction: on a near-massless wrist dof
        the row held the dof still where the servo had it slide, the step's forces then threw its coupled dofs
        (the tool yaw at 0.31 rad/s against 0.09 on "one", `replay --dynamics identified`)."""
        if on == self._coulomb_rows_on:
            return
        for dof in np.flatnonzero(self._coulomb_x):
            self.skeleton.getDof(int(dof)).setCoulombFriction(float(self._coulomb_x[dof]) if on else 0.0)
        self._coulomb_rows_on = on

    def _apply_external_force(self) -> bool:
        """The environment's force on the force point's body (`external_force(point, velocity) -> F`, base frame,
        N), set for this step; the actuators' efforts then hold the motion against it. True when one is set."""
        if self.external_force is None:
            return False
        point = self.model.force_point
        body = self.psm.bodies[point.link]
        position = np.asarray(body.getWorldTransform().translation(), dtype=float)
        velocity = np.asarray(body.getLinearVelocity(np.zeros(3)), dtype=float)
        force = np.asarray(self.external_force(position, velocity), dtype=float)
        body.setExtForce(force, np.zeros(3), False, True)  # base-frame force at the body frame's origin (the point)
        self.last_external_force = force
        return True

    def _after_step(self, dq_before: np.ndarray, effort: np.ndarray, counterweight_force: float) -> None:
        self.step_index += 1
        ClosedChainReadout._state_changed(self)  # the frames of the previous state are gone
        self._x = self.skeleton.getPositions()
        self._v = self.skeleton.getVelocities()
        self._q, self._dq, self.last_ddq, in_range = kernels.observe(
            self._x, self._v, self._coordinates_of_x, dq_before, self.dt, self._range_mid, self._range_half)
        self.last_effort = effort
        self.last_counterweight_force = counterweight_force
        if self._presliding:
            kernels.dahl_step(self._q, self._explicit.presliding_coefficients, self._presliding_position, self._presliding_z,
                              self._explicit.presliding_distances)
        self._check(self._x, self._v, self._q, in_range)

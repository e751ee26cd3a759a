"""Candidate physical effects of the sim-to-real gap, each a small physical model.

An effect adds a joint effort that the simulation (the identified inertial
parameters only, as in the CoppeliaSim paper) does not produce. Each one has
- physical parameters p with physical bounds (Coulomb >= 0, a payload's mass
  > 0 and its position inside the link, a small tilt ...),
- a regressor: effort = Y(q, dq, ddq) . beta(p), Y of shape (N*7, n_columns),
  with beta = p for the linear effects; for a payload beta is the point mass's
  10 dynamic parameters (m, m c, inertia about the link frame origin), linear in
  (m, m c) except for the small second moment m (|c|^2 I - c c^T),
- a mapping to the simulation as physics: the SimConfig fields it sets
  (JointEffects, Payload, gravity_tilt_rad); None for an effect the simulation
  has no field for (a measurement time shift, a counterweight transmission loss).

The per-sample quantities the regressors need (Pinocchio's body regressor of
every moving link, the efforts of unit gravity ...) are computed once per
trajectory by `TrajectoryFeatures`.

Sign conventions (those of the measured efforts and of SimConfig): an effort is
what the actuator supplies. Coulomb friction Fc sign(dq), viscous Fv dq, a
spring K q (rest at q = 0), an armature Ia ddq, an offset o are all *added* to
the efforts the actuator must supply.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import pinocchio as pin

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.arm import Arm
from dvrk_dart.model.description import PsmModel, dh_transform
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS, PRISMATIC_JOINTS, effort_unit
from dvrk_dart.sim.config import JointEffects, Payload, SimConfig, simulated_terms

#: a payload heavier than this is not a "forgotten" mass on a 1 m arm (kg)
PAYLOAD_MAX_MASS_KG = 2.0
#: margin around a link's DH skeleton (joint origins, closure points) inside
#: which a payload may sit: bar width plus a clamp, m
ENVELOPE_MARGIN_M = 0.05
#: the largest base mounting tilt considered (rad, about 2.9 degrees): a
#: larger one would be visible by eye and is not a plausible unknown
TILT_LIMIT_RAD = 0.05
#: the largest time shift between positions and efforts considered (s):
#: 10 samples at 200 Hz, far beyond any controller latency of the dVRK
TIME_SHIFT_LIMIT_S = 0.05
#: velocity scale of the Stribeck drop of friction near zero velocity
#: (rad/s or m/s): about the resolution of the measured velocities
STRIBECK_VELOCITY = 0.02
#: velocity scales (rad/s or m/s) of a smooth Coulomb reversal, Fc tanh(dq / v_r):
#: in a cable-driven joint the friction does not flip at dq = 0 but builds up
#: while the cable stretch is taken up (pre-sliding, Dahl). The scale is a
#: property of the joint, unknown: these candidates span sharp (0.01, about the
#: velocity resolution) to very soft (0.3, a third of the joints' RMS rates) and
#: the held-out score of the training run chooses. On 'one' the free
#: Stribeck term comes out *negative* on J1-J3 (less friction near zero
#: velocity), the signature of such a smooth reversal, not of stiction.
REVERSAL_VELOCITIES = (0.01, 0.03, 0.1, 0.3)
#: the counterweight tendon cannot transmit more than +-50 % of its force wrongly
COUNTERWEIGHT_SCALE_LIMIT = 0.5
#: a tension-proportional tendon loss beyond 50 % is not a transmission
COUNTERWEIGHT_LOSS_LIMIT = 0.5
#: coordinates of the 10 dynamic parameters of a body in Pinocchio's regressor
#: (m, m cx, m cy, m cz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz about the joint frame origin)
BODY_PARAMETERS = 10
#: the links whose bending cables make an elastic effort (J1, J2); J4 has the
#: tool's torsion spring (identified upstream)
CABLE_ELASTICITY_JOINTS = ("q1", "q2")
TORSION_SPRING_JOINT = "q4"


def _rate_unit(joint: str) -> str:
    return "m/s" if joint in PRISMATIC_JOINTS else "rad/s"


def _position_unit(joint: str) -> str:
    return "m" if joint in PRISMATIC_JOINTS else "rad"


def gravity_tilt_directions(gravity: np.ndarray) -> np.ndarray:
    """d(gravity in base)/d(tilt_x, tilt_y) at zero tilt, (3, 2).

    Convention of `dart_builder.gravity_in_base`: the base frame is
    R = Rx(tilt_x) Ry(tilt_y) in the world and gravity in base coordinates is
    R^T g, so to first order g_base = g - (tilt_x e_x + tilt_y e_y) x g."""
    g = np.asarray(gravity, dtype=float)
    return np.column_stack([-np.cross([1.0, 0.0, 0.0], g), -np.cross([0.0, 1.0, 0.0], g)])


def point_mass_parameters(mass_kg: float, position_m: np.ndarray) -> np.ndarray:
    """The 10 dynamic parameters (Pinocchio order) of a point mass at c in a link frame."""
    c = np.asarray(position_m, dtype=float)
    cx, cy, cz = c
    second = mass_kg * np.array([cy * cy + cz * cz, -cx * cy, cx * cx + cz * cz, -cx * cz, -cy * cz, cx * cx + cy * cy])
    return np.concatenate([[mass_kg], mass_kg * c, second])


def point_mass_parameters_jacobian(mass_kg: float, position_m: np.ndarray) -> np.ndarray:
    """d(point_mass_parameters)/d(m, cx, cy, cz), (10, 4)."""
    cx, cy, cz = np.asarray(position_m, dtype=float)
    m = mass_kg
    J = np.zeros((BODY_PARAMETERS, 4))
    J[:, 0] = point_mass_parameters(1.0, position_m)
    J[1:4, 1:4] = m * np.eye(3)
    # second moment rows: Ixx, Ixy, Iyy, Ixz, Iyz, Izz
    J[4, 1:4] = m * np.array([0.0, 2 * cy, 2 * cz])
    J[5, 1:4] = m * np.array([-cy, -cx, 0.0])
    J[6, 1:4] = m * np.array([2 * cx, 0.0, 2 * cz])
    J[7, 1:4] = m * np.array([-cz, 0.0, -cx])
    J[8, 1:4] = m * np.array([0.0, -cz, -cy])
    J[9, 1:4] = m * np.array([2 * cx, 2 * cy, 0.0])
    return J


# ------------------------------------------------------------------ geometry
@dataclass(frozen=True)
class LinkEnvelope:
    """Axis-aligned box in a link's own frame where a payload may sit (m)."""

    link: int
    lower: np.ndarray
    upper: np.ndarray
    skeleton_points: np.ndarray  # (k, 3) the DH points the box was built from

    def contains(self, point: np.ndarray, tolerance_m: float = 1e-9) -> bool:
        p = np.asarray(point)
        return bool(np.all(p >= self.lower - tolerance_m) and np.all(p <= self.upper + tolerance_m))

    def on_boundary(self, point: np.ndarray, tolerance_m: float = 1e-4) -> bool:
        p = np.asarray(point)
        return bool(np.any(np.abs(p - self.lower) < tolerance_m) or np.any(np.abs(p - self.upper) < tolerance_m))


def _variable_range(expr, model: PsmModel) -> tuple[float, float]:
    """Range of a linear expression of q over the joint limits."""
    lo = expr.const + np.sum(np.minimum(expr.coeffs * model.joint_lower, expr.coeffs * model.joint_upper))
    hi = expr.const + np.sum(np.maximum(expr.coeffs * model.joint_lower, expr.coeffs * model.joint_upper))
    return float(lo), float(hi)


def _child_origins(model: PsmModel, key: int, T_key_to_link: np.ndarray, points: list) -> None:
    """Origins of the children of `key`, in the frame of the envelope's link, at
    the ends of their joint ranges; fixed children are part of the same body."""
    zero = np.zeros(N_JOINTS)
    for child in model.children(key):
        a, alpha = float(child.a(zero)), float(child.alpha(zero))
        if child.joint_type == "prismatic":
            d_values = _variable_range(child.d, model)
            thetas = (float(child.theta(zero)),)
        else:  # a revolute child's origin does not depend on its angle
            d_values = (float(child.d(zero)),)
            thetas = (float(child.theta(zero)),)
        for d in d_values:
            for theta in thetas:
                T = T_key_to_link @ dh_transform(a, alpha, d, theta)
                points.append(T[:3, 3])
                if child.joint_type == "fixed":
                    _child_origins(model, child.key, T, points)


def link_envelope(model: PsmModel, key: int, margin_m: float = ENVELOPE_MARGIN_M) -> LinkEnvelope:
    """Bounding box of a link's DH skeleton, widened by `margin_m`.

    The skeleton: the link's own joint origin, the origins of its children
    (prismatic children at both ends of their travel, fixed children with their
    own children), the loop-closure points on the link, and, for a revolute link
    whose axis passes through its parent's origin (the tool shaft), that origin."""
    link = model.links[key]
    points: list[np.ndarray] = [np.zeros(3)]
    _child_origins(model, key, np.eye(4), points)
    frames = model.forward_kinematics(np.zeros(N_JOINTS))
    for closure in model.loop_closures:
        if closure.link == key:
            points.append(closure.point_in_link)
        elif closure.other == key:
            p_base = frames[closure.link] @ np.r_[closure.point_in_link, 1.0]
            points.append((np.linalg.inv(frames[key]) @ p_base)[:3])
    zero = np.zeros(N_JOINTS)
    if link.joint_type == "revolute" and abs(float(link.a(zero))) < 1e-12:
        points.append(np.array([0.0, 0.0, -float(link.d(zero))]))
    pts = np.array(points)
    return LinkEnvelope(key, pts.min(axis=0) - margin_m, pts.max(axis=0) + margin_m, pts)


def joints_moving_link(model: PsmModel, key: int) -> tuple[str, ...]:
    """The coordinates that move a link (its own and its ancestors' variables)."""
    coeffs = np.zeros(N_JOINTS)
    k = key
    while k != 0:
        link = model.links[k]
        if link.variable is not None:
            coeffs = coeffs + np.abs(link.variable.coeffs)
        k = link.parent
    return tuple(JOINT_NAMES[j] for j in np.flatnonzero(coeffs))


# ------------------------------------------------------------ trajectory data
class TrajectoryFeatures:
    """Per-sample quantities of one trajectory that the regressors are built from.

    `reference_effort` is the simulated effort at the measured samples (the
    time-shift effect differentiates it)."""

    def __init__(self, arm: Arm, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, reference_effort: np.ndarray, sample_rate_hz: float):
        self.arm = arm
        self.q, self.dq, self.ddq = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, dq, ddq))
        self.reference_effort = np.asarray(reference_effort, dtype=float)
        if self.reference_effort.shape != self.q.shape:
            raise DvrkDartError(f"reference efforts {self.reference_effort.shape} do not match the states {self.q.shape}")
        self.sample_rate_hz = float(sample_rate_hz)

    def __len__(self) -> int:
        return len(self.q)

    @cached_property
    def _pin_joint_of_link(self) -> dict[int, int]:
        im = self.arm.identified
        out = {}
        for link in im.tree_links:
            if hasattr(link, "key") and link.key in self.arm.model.links:
                out[link.key] = im.pin_model.getJointId(f"link{link.key}_{link.name}")
        return out

    def body_columns(self, key: int) -> slice:
        """Columns of `body_regressor` belonging to a moving link's body."""
        if key not in self._pin_joint_of_link:
            raise DvrkDartError(f"link {key} has no joint of its own in the identified model tree")
        j = self._pin_joint_of_link[key]
        return slice(BODY_PARAMETERS * (j - 1), BODY_PARAMETERS * j)

    @cached_property
    def body_regressor(self) -> np.ndarray:
        """(N, 7, 10 n_joints): efforts per unit dynamic parameter of every tree body,
        projected onto the 7 coordinates (tau = G^T tau_tree)."""
        im = self.arm.identified
        pm, data = im.pin_model, im.pin_model.createData()
        qt, vt, at = im.tree_q(self.q), im.tree_v(self.dq), im.tree_v(self.ddq)
        out = np.empty((len(qt), N_JOINTS, BODY_PARAMETERS * (pm.njoints - 1)))
        GT = im.G.T
        for k in range(len(qt)):
            out[k] = GT @ pin.computeJointTorqueRegressor(pm, data, qt[k], vt[k], at[k])
        return out

    @cached_property
    def unit_gravity_efforts(self) -> np.ndarray:
        """(N, 7, 3): gravity efforts of the identified bodies for a unit gravity
        vector along base x, y, z (efforts are linear in the gravity vector)."""
        im = self.arm.identified
        model = pin.Model(im.pin_model)
        data = model.createData()
        qt = im.tree_q(self.q)
        out = np.empty((len(qt), N_JOINTS, 3))
        for axis in range(3):
            model.gravity = pin.Motion(np.r_[np.eye(3)[axis], np.zeros(3)])
            for k in range(len(qt)):
                out[k, :, axis] = im.G.T @ pin.computeGeneralizedGravity(model, data, qt[k])
        return out

    @cached_property
    def reference_rate(self) -> np.ndarray:
        """d/dt of the simulated effort (N, 7), per second."""
        if len(self) < 2:
            return np.zeros_like(self.reference_effort)
        return np.gradient(self.reference_effort, 1.0 / self.sample_rate_hz, axis=0)

    @cached_property
    def counterweight_effort(self) -> np.ndarray:
        """(N, 7) efforts due to the counterweight body alone (identified inertia)."""
        im = self.arm.identified
        key = self.arm.model.counterweight_link
        j = self._pin_joint_of_link[key]
        return self.body_regressor[:, :, self.body_columns(key)] @ im.pin_model.inertias[j].toDynamicParameters()


# -------------------------------------------------------------------- effects
@dataclass(frozen=True)
class Parameter:
    name: str
    unit: str
    lower: float = -math.inf
    upper: float = math.inf


@dataclass
class SimContribution:
    """SimConfig fields an effect sets (added to those of other effects)."""

    coulomb: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    viscous: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    armature: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    coulomb_reversal_velocity: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    payloads: tuple[Payload, ...] = ()
    gravity_tilt_rad: np.ndarray = field(default_factory=lambda: np.zeros(2))


class Effect(ABC):
    """A candidate physical effect: parameters, regressor and simulation mapping."""

    name: str
    kind: str
    joints: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    linear = True  # effort linear in the parameters (beta = p)

    @property
    def n_parameters(self) -> int:
        return len(self.parameters)

    @property
    def n_columns(self) -> int:
        return self.n_parameters

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @abstractmethod
    def columns(self, features: TrajectoryFeatures) -> np.ndarray:
        """(N, 7, n_columns): effort per unit regression coefficient."""

    def regressor(self, features: TrajectoryFeatures) -> np.ndarray:
        """Y of effort = Y beta, (N*7, n_columns), rows sample-major (sample k, joint j)."""
        return self.columns(features).reshape(-1, self.n_columns)

    def coefficients(self, p: np.ndarray) -> np.ndarray:
        """Regression coefficients beta(p)."""
        return np.asarray(p, dtype=float)

    def coefficients_jacobian(self, p: np.ndarray) -> np.ndarray:
        return np.eye(self.n_parameters)

    def effort(self, features: TrajectoryFeatures, p: np.ndarray) -> np.ndarray:
        """(N, 7) effort of the effect with parameters p."""
        return self.columns(features) @ self.coefficients(p)

    def initial_guesses(self, linear_solution: np.ndarray) -> list[np.ndarray]:
        """Starting points of a nonlinear fit (only nonlinear effects need them)."""
        return [np.clip(linear_solution, self.lower, self.upper)]

    @abstractmethod
    def sim_contribution(self, p: np.ndarray) -> SimContribution | None:
        """The SimConfig fields of this effect, None if the simulation has no field for it."""

    @property
    def family(self) -> str:
        """Effects of one family are alternative models of the same physics
        (e.g. the friction of one joint with a sharp or a smooth reversal): at
        most one of a family is selected."""
        return self.name

    def fully_simulated(self, p: np.ndarray) -> bool:
        """Whether the simulation produces all of this effect's effort."""
        return self.sim_contribution(np.asarray(p, dtype=float)) is not None

    def unsimulated_effort(self, features: TrajectoryFeatures, p: np.ndarray) -> np.ndarray | None:
        """(N, 7) part of the effort the simulation does not produce from
        `sim_contribution` (added to the simulated efforts as a model-based
        effort), None when the simulation produces all of it."""
        if self.sim_contribution(np.asarray(p, dtype=float)) is None:
            return self.effort(features, p)
        return None

    def describe(self, p: np.ndarray) -> dict:
        return {par.name: float(v) for par, v in zip(self.parameters, p)}

    def units(self) -> dict:
        return {par.name: par.unit for par in self.parameters}

    def size(self, p: np.ndarray) -> float:
        """One number for "how big": the first parameter (overridden where needed)."""
        return float(p[0])


def _unit_column(features: TrajectoryFeatures, joint: int, values: np.ndarray) -> np.ndarray:
    out = np.zeros((len(features), N_JOINTS, 1))
    out[:, joint, 0] = values
    return out


class JointFriction(Effect):
    """Coulomb + viscous friction on one coordinate: Fc s(dq) + Fv dq, with
    s = sign (a sharp reversal) or s = tanh(dq / v_r) (a smooth reversal over
    the velocity scale v_r: pre-sliding of a cable transmission), optionally a
    Stribeck drop near zero velocity Fs s(dq) exp(-(dq/vs)^2).

    Simulation: the viscous part is DART's joint damping; a sharp Coulomb
    part is DART's joint friction; a smooth reversal is the simulator's
    friction law Fc tanh(dq / v_r), applied as a joint effort each step from
    the simulated velocity (SimConfig.extra.coulomb_reversal_velocity). A
    Stribeck curve has no counterpart in the simulation: its effort is added
    by regressor (and reported as such)."""

    kind = "friction"

    def __init__(self, joint: str, stribeck: bool = False, reversal_velocity: float | None = None):
        self.joint_index = JOINT_NAMES.index(joint)
        self.joints = (joint,)
        self.stribeck = stribeck
        self.reversal_velocity = None if reversal_velocity is None else float(reversal_velocity)
        base = "stribeck_friction" if stribeck else "friction"
        suffix = "" if self.reversal_velocity is None else f"_smooth{self.reversal_velocity:g}"
        self.name = f"{base}_{joint}{suffix}"
        eu = effort_unit(joint)
        pars = [Parameter("coulomb", eu, 0.0), Parameter("viscous", f"{eu}/({_rate_unit(joint)})", 0.0)]
        if stribeck:
            pars.append(Parameter("stribeck", eu, 0.0))
        self.parameters = tuple(pars)

    @property
    def family(self) -> str:
        return f"friction_{self.joints[0]}"

    def _sign(self, v: np.ndarray) -> np.ndarray:
        return np.sign(v) if self.reversal_velocity is None else np.tanh(v / self.reversal_velocity)

    def columns(self, features):
        v = features.dq[:, self.joint_index]
        cols = [self._sign(v), v]
        if self.stribeck:
            cols.append(self._sign(v) * np.exp(-((v / STRIBECK_VELOCITY) ** 2)))
        out = np.zeros((len(features), N_JOINTS, len(cols)))
        out[:, self.joint_index, :] = np.column_stack(cols)
        return out

    def sim_contribution(self, p):
        c = SimContribution()
        if not self.stribeck:
            c.coulomb[self.joint_index] = p[0]
            if self.reversal_velocity is not None:
                c.coulomb_reversal_velocity[self.joint_index] = self.reversal_velocity
        c.viscous[self.joint_index] = p[1]
        return c

    def fully_simulated(self, p):
        return not self.stribeck

    def unsimulated_effort(self, features, p):
        if self.fully_simulated(p):
            return None
        q = np.array(p, dtype=float)
        q[1] = 0.0  # the viscous part is simulated
        return self.effort(features, q)

    def describe(self, p):
        out = super().describe(p)
        out["reversal"] = "sign" if self.reversal_velocity is None else f"tanh(dq/{self.reversal_velocity:g} {_rate_unit(self.joints[0])})"
        return out


class JointOffset(Effect):
    """A constant effort on one coordinate (cable preload, sensor offset, gravity
    compensation mismatch of the controller)."""

    kind = "offset"

    def __init__(self, joint: str):
        self.joint_index = JOINT_NAMES.index(joint)
        self.joints = (joint,)
        self.name = f"offset_{joint}"
        self.parameters = (Parameter("offset", effort_unit(joint)),)

    def columns(self, features):
        return _unit_column(features, self.joint_index, np.ones(len(features)))

    def sim_contribution(self, p):
        c = SimContribution()
        c.offset[self.joint_index] = p[0]
        return c


class JointStiffness(Effect):
    """An elastic effort K q on one coordinate, rest at q = 0 (the tool's torsion
    spring on J4, the bending cables on J1 and J2); a shifted rest position is
    a stiffness plus an offset."""

    kind = "elastic"

    def __init__(self, joint: str):
        self.joint_index = JOINT_NAMES.index(joint)
        self.joints = (joint,)
        self.name = f"{'torsion_spring' if joint == TORSION_SPRING_JOINT else 'cable_elasticity'}_{joint}"
        self.parameters = (Parameter("stiffness", f"{effort_unit(joint)}/{_position_unit(joint)}", 0.0),)

    def columns(self, features):
        return _unit_column(features, self.joint_index, features.q[:, self.joint_index])

    def sim_contribution(self, p):
        c = SimContribution()
        c.stiffness[self.joint_index] = p[0]
        return c


class JointArmature(Effect):
    """Motor (rotor) inertia reflected through the transmission: Ia ddq."""

    kind = "armature"

    def __init__(self, joint: str):
        self.joint_index = JOINT_NAMES.index(joint)
        self.joints = (joint,)
        self.name = f"armature_{joint}"
        self.parameters = (Parameter("armature", "kg" if joint in PRISMATIC_JOINTS else "kg·m²", 0.0),)

    def columns(self, features):
        return _unit_column(features, self.joint_index, features.ddq[:, self.joint_index])

    def sim_contribution(self, p):
        c = SimContribution()
        c.armature[self.joint_index] = p[0]
        return c


class PointPayload(Effect):
    """A point mass m at position c (link frame) rigidly attached to a link.

    Its efforts are those of a body with the dynamic parameters
    (m, m c, m (|c|^2 I - c c^T)): Pinocchio's joint-torque regressor of the
    link's tree body times those parameters, projected with G. The position is
    kept inside the link's envelope (a box around its DH skeleton)."""

    kind = "payload"
    linear = False

    def __init__(
        self, model: PsmModel, key: int, envelope: LinkEnvelope | None = None, max_mass_kg: float = PAYLOAD_MAX_MASS_KG,
        equivalent_keys: tuple[int, ...] = (),
    ):
        link = model.links[key]
        if not link.body or link.joint_type == "fixed":
            raise DvrkDartError(f"link {key} ({link.name}): a payload needs a moving link with a body")
        self.model = model
        self.link_key = key
        self.link_name = link.name
        self.group = link.group
        self.envelope = envelope if envelope is not None else link_envelope(model, key)
        self.name = f"payload_on_{link.name}"
        #: links on which a payload gives exactly the same efforts (`equivalent_payload_links`)
        self.equivalent_links = tuple(model.links[k].name for k in equivalent_keys if k != key)
        self.joints = joints_moving_link(model, key)
        self.parameters = (
            Parameter("mass_kg", "kg", 0.0, max_mass_kg),
            Parameter("x_m", "m", float(self.envelope.lower[0]), float(self.envelope.upper[0])),
            Parameter("y_m", "m", float(self.envelope.lower[1]), float(self.envelope.upper[1])),
            Parameter("z_m", "m", float(self.envelope.lower[2]), float(self.envelope.upper[2])),
        )

    @property
    def family(self) -> str:
        """Payloads on equivalent links are one family: the data cannot tell them apart."""
        return "payload_on_" + "|".join(sorted((self.link_name,) + self.equivalent_links))

    @property
    def n_columns(self) -> int:
        return BODY_PARAMETERS

    def columns(self, features):
        return features.body_regressor[:, :, features.body_columns(self.link_key)]

    def coefficients(self, p):
        return point_mass_parameters(p[0], p[1:4])

    def coefficients_jacobian(self, p):
        return point_mass_parameters_jacobian(p[0], p[1:4])

    def initial_guesses(self, linear_solution):
        """From the unconstrained first-moment solution (m, m c), and from the box centre."""
        centre = 0.5 * (self.envelope.lower + self.envelope.upper)
        m = float(np.clip(linear_solution[0], 1e-3, self.upper[0]))
        c = linear_solution[1:4] / linear_solution[0] if abs(linear_solution[0]) > 1e-6 else centre
        c = np.clip(c, self.envelope.lower, self.envelope.upper)
        return [np.r_[m, c], np.r_[m, centre]]

    def sim_contribution(self, p):
        return SimContribution(payloads=(Payload(link=self.link_key, mass_kg=float(p[0]), position_m=tuple(float(x) for x in p[1:4])),))

    def position_base_at_zero(self, p) -> np.ndarray:
        T = self.model.forward_kinematics(np.zeros(N_JOINTS))[self.link_key]
        return (T @ np.r_[p[1:4], 1.0])[:3]

    def describe(self, p):
        return {
            "mass_kg": float(p[0]),
            "link": self.link_name,
            "link_key": self.link_key,
            "group": self.group,
            "equivalent_links": list(self.equivalent_links),
            "position_m": [float(x) for x in p[1:4]],
            "position_base_at_q0_m": self.position_base_at_zero(p).tolist(),
            "envelope_m": {"lower": self.envelope.lower.tolist(), "upper": self.envelope.upper.tolist()},
            "at_envelope_boundary": self.envelope.on_boundary(p[1:4]),
        }


class TimeShift(Effect):
    """Efforts recorded late (delta > 0) relative to the positions:
    tau_meas(t) = tau(t - delta) ~ tau(t) - delta dtau/dt, tau the simulated effort."""

    kind = "time_shift"
    name = "time_shift"
    joints = JOINT_NAMES
    parameters = (Parameter("delay_s", "s", -TIME_SHIFT_LIMIT_S, TIME_SHIFT_LIMIT_S),)

    def columns(self, features):
        return -features.reference_rate[:, :, None]

    def sim_contribution(self, p):
        return None  # a property of the measurement, not of the physics


class GravityTilt(Effect):
    """Base mounted with a small tilt about base x, then y (dart_builder's
    convention): the gravity efforts of the identified bodies for the gravity
    direction change, linearised in the two angles."""

    kind = "gravity_tilt"
    name = "gravity_tilt"
    parameters = (
        Parameter("tilt_x_rad", "rad", -TILT_LIMIT_RAD, TILT_LIMIT_RAD),
        Parameter("tilt_y_rad", "rad", -TILT_LIMIT_RAD, TILT_LIMIT_RAD),
    )

    def __init__(self, arm: Arm):
        self.directions = gravity_tilt_directions(arm.model.gravity)
        massive = [k for k, l in arm.model.links.items() if l.body and arm.params[k].mass > 0.0]
        moved = set().union(*(joints_moving_link(arm.model, k) for k in massive))
        self.joints = tuple(j for j in JOINT_NAMES if j in moved)

    def columns(self, features):
        return features.unit_gravity_efforts @ self.directions

    def sim_contribution(self, p):
        return SimContribution(gravity_tilt_rad=np.array([p[0], p[1]], dtype=float))

    def size(self, p):
        return float(np.hypot(p[0], p[1]))


class CounterweightTransmission(Effect):
    """The counterweight tendon transmits its force F to J3 with a scale error
    (1 + kappa) and a tension-proportional loss mu |F| sign(dq3)."""

    kind = "counterweight_transmission"
    name = "counterweight_transmission"
    joints = ("q3",)
    parameters = (
        Parameter("force_scale_error", "1", -COUNTERWEIGHT_SCALE_LIMIT, COUNTERWEIGHT_SCALE_LIMIT),
        Parameter("loss_coefficient", "1", 0.0, COUNTERWEIGHT_LOSS_LIMIT),
    )

    def __init__(self, arm: Arm):
        self.leader = JOINT_NAMES.index("q3")

    def columns(self, features):
        force = features.counterweight_effort[:, self.leader]
        out = np.zeros((len(features), N_JOINTS, 2))
        out[:, self.leader, 0] = force
        out[:, self.leader, 1] = np.abs(force) * np.sign(features.dq[:, self.leader])
        return out

    def sim_contribution(self, p):
        return None  # SimConfig's tendon is ideal (or the paper's PID)


def payload_links(model: PsmModel) -> list[int]:
    """Every moving link with a rigid body: where a payload can be clamped."""
    return [k for k, l in model.links.items() if l.body and l.joint_type != "fixed"]


#: random states (q within the joint limits, dq and ddq standard normal) on
#: which the effort signatures of two payload links are compared
EQUIVALENCE_STATES = 24
EQUIVALENCE_SEED = 20190802
#: a link's body regressor lies in another's span when its residual after
#: projection is below this fraction of its largest column (measured: round-off
#: ~2e-15; the weakest real difference, the inertia of the two translating
#: parallelogram links with cranks of different length, ~8e-3)
EQUIVALENCE_TOLERANCE = 1e-6
#: singular values below this fraction of the largest are round-off (the span
#: of a body regressor omits the unexcitable inertia directions)
RANK_CUT = 1e-12


def _column_space(Y: np.ndarray) -> np.ndarray:
    U, sv, _ = np.linalg.svd(Y, full_matrices=False)
    return U[:, sv > sv[0] * RANK_CUT]


def equivalent_payload_links(arm: Arm) -> dict[int, tuple[int, ...]]:
    """For each payload link, the payload links (itself included) on which a
    body produces exactly the efforts some body on it produces: no effort
    measurement can tell them apart. E.g. the pitch link and the parallelogram
    links turning with q2 about pivots that only translate along the yaw axis
    relative to it: same kinetic energy, same potential up to a constant.

    Decided numerically, not by name: the body regressors of both links over
    random states must span the same space."""
    model = arm.model
    rng = np.random.default_rng(EQUIVALENCE_SEED)
    q = rng.uniform(model.joint_lower, model.joint_upper, size=(EQUIVALENCE_STATES, N_JOINTS))
    dq, ddq = rng.standard_normal((2, EQUIVALENCE_STATES, N_JOINTS))
    features = TrajectoryFeatures(arm, q, dq, ddq, np.zeros_like(q), 1.0)
    links = payload_links(model)
    regressors = {k: features.body_regressor[:, :, features.body_columns(k)].reshape(-1, BODY_PARAMETERS) for k in links}
    spaces = {k: _column_space(Y) for k, Y in regressors.items()}

    def inside(Y: np.ndarray, U: np.ndarray) -> bool:
        residual = np.linalg.norm(Y - U @ (U.T @ Y), axis=0)
        return bool(np.all(residual <= EQUIVALENCE_TOLERANCE * np.linalg.norm(Y, axis=0).max()))

    return {i: tuple(j for j in links if inside(regressors[j], spaces[i]) and inside(regressors[i], spaces[j])) for i in links}


def candidate_effects(
    arm: Arm, stribeck: bool = False, payload_margin_m: float = ENVELOPE_MARGIN_M, reversal_velocities: tuple[float, ...] = REVERSAL_VELOCITIES
) -> list[Effect]:
    """The library of candidate effects, in a fixed order."""
    effects: list[Effect] = []
    effects += [JointFriction(j) for j in JOINT_NAMES]
    effects += [JointFriction(j, reversal_velocity=v) for j in JOINT_NAMES for v in reversal_velocities]
    if stribeck:
        effects += [JointFriction(j, stribeck=True) for j in JOINT_NAMES]
    effects += [JointOffset(j) for j in JOINT_NAMES]
    effects += [JointStiffness(j) for j in CABLE_ELASTICITY_JOINTS + (TORSION_SPRING_JOINT,)]
    effects += [JointArmature(j) for j in JOINT_NAMES]
    equivalents = equivalent_payload_links(arm)
    effects += [
        PointPayload(arm.model, k, link_envelope(arm.model, k, payload_margin_m), equivalent_keys=equivalents[k]) for k in payload_links(arm.model)
    ]
    effects += [GravityTilt(arm), TimeShift(), CounterweightTransmission(arm)]
    return effects


# ----------------------------------------------------------- to the simulator
def effects_to_sim_config(selected: list[tuple[Effect, np.ndarray]], base: SimConfig = SimConfig()) -> SimConfig:
    """SimConfig with the effects added as physics on top of `base`.

    Effects the simulation has no field for are skipped: `not_simulated` lists
    them (the caller adds their regressor effort)."""
    extra = base.extra
    fields = {
        name: np.array(getattr(extra, name), dtype=float)
        for name in ("coulomb", "viscous", "offset", "stiffness", "armature", "coulomb_reversal_velocity")
    }
    payloads = list(base.payloads)
    tilt = np.array(base.gravity_tilt_rad, dtype=float)
    for effect, p in selected:
        contribution = effect.sim_contribution(np.asarray(p, dtype=float))
        if contribution is None:
            continue
        for name in fields:
            fields[name] += getattr(contribution, name)
        payloads += list(contribution.payloads)
        tilt += contribution.gravity_tilt_rad
    new_extra = JointEffects(**{name: tuple(float(v) for v in values) for name, values in fields.items()})
    return replace(base, extra=new_extra, payloads=tuple(payloads), gravity_tilt_rad=(float(tilt[0]), float(tilt[1])))


def not_simulated(selected: list[tuple[Effect, np.ndarray]]) -> list[tuple[Effect, np.ndarray]]:
    """The effects that `effects_to_sim_config` cannot put (wholly) into a
    SimConfig: their `unsimulated_effort` is added to the simulated efforts."""
    return [(e, p) for e, p in selected if not e.fully_simulated(np.asarray(p, dtype=float))]


def unsimulated_effort(selected: list[tuple[Effect, np.ndarray]], features: TrajectoryFeatures) -> np.ndarray:
    """(N, 7) sum of the efforts of `selected` that the simulation does not produce."""
    total = np.zeros((len(features), N_JOINTS))
    for e, p in selected:
        part = e.unsimulated_effort(features, p)
        if part is not None:
            total = total + part
    return total


def config_effort_by_formula(arm: Arm, config: SimConfig, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    """The efforts a SimConfig's physics should produce, from the model's formulas.

    An independent statement of what the simulator must do with the identified
    flags, JointEffects, payloads (exact point masses) and the tilt (exact, not
    linearised), for checking the DART replay and the effect mapping. Ideal
    counterweight only."""
    im = arm.identified
    terms = simulated_terms(config)
    efforts = im.efforts(q, dq, ddq, terms)
    tilt = np.asarray(config.gravity_tilt_rad, dtype=float)
    features = TrajectoryFeatures(arm, q, dq, ddq, np.zeros_like(np.atleast_2d(q)), 1.0)
    total = efforts.total(terms)
    if np.any(tilt != 0.0):
        g_tilted = _gravity_in_base(arm.model, tilt)
        total = total - efforts.terms["gravity"] + features.unit_gravity_efforts @ g_tilted
    x = config.extra
    reversal = np.asarray(x.coulomb_reversal_velocity, dtype=float)
    reversal_law = np.where(reversal > 0.0, np.tanh(features.dq / np.where(reversal > 0.0, reversal, 1.0)), np.sign(features.dq))
    total = total + np.asarray(x.coulomb) * reversal_law + np.asarray(x.viscous) * features.dq
    total = total + np.asarray(x.offset) + np.asarray(x.stiffness) * features.q + np.asarray(x.armature) * features.ddq
    for payload in config.payloads:
        params = point_mass_parameters(payload.mass_kg, np.asarray(payload.position_m))
        total = total + features.body_regressor[:, :, features.body_columns(payload.link)] @ params
        if np.any(tilt != 0.0):  # the body regressor carries the nominal gravity
            total = total + _payload_gravity_correction(arm, features, payload, tilt)
    return total


def _gravity_in_base(model: PsmModel, tilt: np.ndarray) -> np.ndarray:
    """Gravity in the base frame of a tilted base: the simulator's own definition."""
    from dvrk_dart.sim.builder import (
        gravity_in_base,  # imports dartpy: only when a tilt is simulated
    )

    return np.asarray(gravity_in_base(model, (float(tilt[0]), float(tilt[1]))), dtype=float)


def _payload_gravity_correction(arm: Arm, features: TrajectoryFeatures, payload: Payload, tilt: np.ndarray) -> np.ndarray:
    """Gravity efforts of a payload under tilted minus nominal gravity (N, 7)."""
    im = arm.identified
    model = pin.Model(im.pin_model)
    key = payload.link
    j = features._pin_joint_of_link[key]
    for i in range(1, model.njoints):
        model.inertias[i] = pin.Inertia.Zero()
    model.inertias[j] = pin.Inertia.FromDynamicParameters(point_mass_parameters(payload.mass_kg, np.asarray(payload.position_m)))
    data = model.createData()
    qt = im.tree_q(features.q)
    delta_g = _gravity_in_base(arm.model, tilt) - arm.model.gravity
    model.gravity = pin.Motion(np.r_[delta_g, np.zeros(3)])
    return np.array([im.G.T @ pin.computeGeneralizedGravity(model, data, qk) for qk in qt])

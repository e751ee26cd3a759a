"""A payload as what the efforts determine: its first moment (and its mass where seen).

A point mass m at c on a link gives efforts linear in (m, m c) and its
second moment m (|c|^2 I - c c^T), the inertia about the link's origin.
`FirstMomentPayload` fits (m, m c), with no envelope on c (on a link turning
about a fixed axis gravity sees m c only), and ties the second moment to them
as a point mass's: (|m c|^2 I - (m c)(m c)^T) / m, a nonlinear fit. Left out
(as it was), it is small only where the link's origin lies near the payload;
the insertion carriage's origin lies 0.3 m from a weight on the carriage (0.2
kg there: 0.018 kg·m² about it), and a payload on the tool roll link, whose
origin is nearer, was named instead (blind suite, with a baseline).

It is reported as the first moment *the efforts* determine, in the base frame
at q = 0 as a body on the reference link of its family of equivalent links,
with the gravity efforts it causes per joint; the mass only where gravity sees
it apart from m c (a link translating along q3), else an interval.

`PayloadAtPosition` is a point mass at a given (hand-measured) position: its
efforts are linear in m, so a first moment becomes a mass with an interval.

The yaw joint sees a payload through a first moment of its own (`yaw_path`):
in the model the yaw axis is horizontal, so J1's gravity load depends on how
the real yaw axis lies relative to gravity, which the model fixes. On the real
105 g parallelogram runs the J1 difference to the no-weight run is about
-0.3 sin(q1) N·m, some fifteen times what the model's geometry predicts for the
hand placement, with the other sign: a weight-scaling signature whose path to
J1 the model does not have (a tilted mount, a coupling in the transmission).
Fitting it with the payload, not with offsets, springs or time shifts, keeps
it where it scales with the weight; the placement and the mass are then read
from J2..J7, where the model's geometry holds (the insertion-stage weight:
J2 efforts at 0.91 of the hand placement's prediction, correlation 0.98).
A payload on the yaw link, whose efforts J1 alone sees, has J1's row of its
tied second moment too: left out (as it was), it had no inertia but q1's
armature (blind suite, with a baseline: q1 left at 1.7x the noise). On the
other links J1 sees the path's first moment only: J1's row of the tied
second moment there (tried) named a parallelogram payload on the tool roll
link (the equivalent links' origins differ, their second moments too), and
tied to the path's own (m, m c) (tried) the path's free mass let the inertia
take J1's constant and slope (a 105 g J1 effort at q = 0 of -0.041 N·m read
as -0.002). `PayloadAtPosition`'s point mass, whose position is given, has its
inertia in J1's row (per kg).
"""

from __future__ import annotations

import math

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect, Parameter, SimContribution
from dvrk_dart.diagnosis.effects.features import FIRST_MOMENT_COLUMNS, TrajectoryFeatures
from dvrk_dart.diagnosis.effects.geometry import LinkEnvelope, arm_reach_m, joints_moving_link, link_envelope
from dvrk_dart.diagnosis.effects.payload import PAYLOAD_MAX_MASS_KG, equivalents_of, point_mass_parameters, point_mass_parameters_jacobian
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.body_regressor import BODY_PARAMETERS
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.sim.config import Payload

#: the joint whose payload efforts get a first moment of their own (the yaw joint)
YAW_PATH_JOINT = 0
#: the Occam prior (design.PAYLOAD_MASS_PRIOR_PER_KG2 per kg^2) counts a first
#: moment in units of kg at this lever: it only decides directions the efforts
#: do not see (e.g. along the yaw axis of a link that only translates in the
#: parallelogram), which would otherwise run to their bounds
FIRST_MOMENT_PRIOR_LENGTH_M = 0.1
#: a body's second moment: its last six dynamic parameters
SECOND_MOMENT_COLUMNS = BODY_PARAMETERS - FIRST_MOMENT_COLUMNS
#: the tied second moment (|m c|^2 I - (m c)(m c)^T) / m divides by at least
#: this mass (kg): a first moment with no mass is a point at infinity
TIED_MASS_FLOOR_KG = 1e-3


def _yaw_path_parameters(max_mass_kg: float, reach: np.ndarray) -> tuple[Parameter, ...]:
    """The yaw joint's own (m, m c): a path of either sign, bounded like the payload's."""
    return (Parameter("yaw_path_mass_kg", "kg", -max_mass_kg, max_mass_kg),) + tuple(
        Parameter(f"yaw_path_first_moment_{a}_kg_m", "kg·m", -max_mass_kg * r, max_mass_kg * r) for a, r in zip("xyz", reach))


def _with_yaw_path(features: TrajectoryFeatures, key: int, columns: np.ndarray) -> np.ndarray:
    """`columns` (N, 7, k) with their yaw row moved to the yaw path's four columns."""
    out = np.concatenate([columns, np.zeros(columns.shape[:2] + (FIRST_MOMENT_COLUMNS,))], axis=2)
    out[:, YAW_PATH_JOINT, :] = 0.0
    out[:, YAW_PATH_JOINT, -FIRST_MOMENT_COLUMNS:] = features.first_moment_columns(key)[:, YAW_PATH_JOINT, :]
    return out


def _moving_body_link(model: PsmModel, key: int):
    link = model.links[key]
    if not link.body or link.joint_type == "fixed":
        raise DvrkDartError(f"link {key} ({link.name}): a payload needs a moving link with a body")
    return link


class FirstMomentPayload(Effect):
    """A payload on a link as its mass and first moment (m, m c), c in the link frame."""

    kind = "payload"
    linear = False  # the second moment tied to (m, m c) (module docstring)
    homogeneous = True  # (|m c|^2 I - (m c)(m c)^T) / m: of degree one in (m, m c)

    def __init__(self, model: PsmModel, key: int, envelope: LinkEnvelope | None = None, max_mass_kg: float = PAYLOAD_MAX_MASS_KG,
                 equivalent_keys: tuple[int, ...] = (), mass_seen: bool = True):
        link = _moving_body_link(model, key)
        self.model, self.link_key, self.link_name, self.group = model, key, link.name, link.group
        self.envelope = envelope if envelope is not None else link_envelope(model, key)
        self.name = f"payload_on_{link.name}"
        self.equivalent_links = tuple(model.links[k].name for k in equivalent_keys if k != key)
        #: the family's link its first moment is reported on (equivalent links
        #: give the same efforts, not the same base-frame first moment)
        self.reference_key = min((key,) + tuple(equivalent_keys))
        #: whether gravity sees the mass apart from m c (`payload.mass_seen_by_gravity`)
        self.mass_seen = mass_seen
        self.joints = joints_moving_link(model, key)
        #: J1 alone sees the payload (the yaw link): J1's row carries its tied inertia too
        self.j1_inertia = tuple(self.joints) == (JOINT_NAMES[YAW_PATH_JOINT],)
        # the largest first moment a plausible payload has: the heaviest mass at
        # the far end of the link's envelope, along each axis
        reach = np.maximum(np.abs(self.envelope.lower), np.abs(self.envelope.upper))
        #: the farthest point of the envelope from the link's origin (m)
        self.reach_m = float(np.linalg.norm(reach))
        self.parameters = (Parameter("mass_kg", "kg", 0.0, max_mass_kg),) + tuple(
            Parameter(f"first_moment_{a}_kg_m", "kg·m", -max_mass_kg * r, max_mass_kg * r) for a, r in zip("xyz", reach)
        ) + _yaw_path_parameters(max_mass_kg, reach)

    #: scales of the Occam prior on (m, m c) (`design.Fitter`); none on the yaw
    #: path: J1's data determine what J1 sees of it, and a prior relative to
    #: all runs' residual energy would shrink J1's share (a run minus its
    #: baseline holds a fraction of it): the rest does not reach any report
    prior_scales = np.array([1.0] + [FIRST_MOMENT_PRIOR_LENGTH_M] * 3 + [np.inf] * FIRST_MOMENT_COLUMNS)

    @property
    def family(self) -> str:
        return "payload_on_" + "|".join(sorted((self.link_name,) + self.equivalent_links))

    @property
    def n_seen_parameters(self) -> int:
        """Without the mass where gravity sees m c only: between links that fit
        as well, the payload the efforts pin with fewer numbers is chosen."""
        return self.n_parameters - (0 if self.mass_seen else 1)

    @property
    def selection_group(self) -> str:
        """The weight under study is one body (its yaw path with it): one payload is selected."""
        return self.kind

    @property
    def n_columns(self) -> int:
        return BODY_PARAMETERS + FIRST_MOMENT_COLUMNS + (SECOND_MOMENT_COLUMNS if self.j1_inertia else 0)

    def columns(self, features: TrajectoryFeatures) -> np.ndarray:
        """The body's ten columns and J1's path; on the yaw link, J1's row of the
        body's second moment (the payload's inertia: J1 alone sees it)."""
        body = features.body_regressor[:, :, features.body_columns(self.link_key)]
        columns = _with_yaw_path(features, self.link_key, body)
        if not self.j1_inertia:
            return columns
        inertia = np.zeros(body.shape[:2] + (SECOND_MOMENT_COLUMNS,))
        inertia[:, YAW_PATH_JOINT] = body[:, YAW_PATH_JOINT, FIRST_MOMENT_COLUMNS:]
        return np.concatenate([columns, inertia], axis=2)

    def first_moment_columns(self, features: TrajectoryFeatures) -> np.ndarray:
        """(N, 7, 8) the efforts linear in the parameters, the second moment left out."""
        return _with_yaw_path(features, self.link_key, features.first_moment_columns(self.link_key))

    def _tied_mass(self, mh) -> tuple[float, np.ndarray]:
        """The mass a tied second moment divides by, and its gradient in (m, m c):
        at least |m c| / reach (no part of a payload lies beyond the link's
        envelope, so a small mass far out, all inertia, is not a payload) and
        TIED_MASS_FLOOR_KG."""
        h = np.asarray(mh[1:FIRST_MOMENT_COLUMNS], dtype=float)
        norm = float(np.linalg.norm(h))
        candidates = (float(mh[0]), norm / self.reach_m, TIED_MASS_FLOOR_KG)
        gradients = (np.eye(FIRST_MOMENT_COLUMNS)[0], np.r_[0.0, h / max(norm * self.reach_m, 1e-300)], np.zeros(FIRST_MOMENT_COLUMNS))
        k = int(np.argmax(candidates))
        return candidates[k], gradients[k]

    def _tied_second_moment(self, mh) -> np.ndarray:
        """A point mass's second moment (|m c|^2 I - (m c)(m c)^T) / m (6,) from (m, m c)."""
        return point_mass_parameters(1.0 / self._tied_mass(mh)[0], np.asarray(mh[1:FIRST_MOMENT_COLUMNS], dtype=float))[FIRST_MOMENT_COLUMNS:]

    def _tied_second_moment_jacobian(self, mh) -> np.ndarray:
        """(6, 4): d(_tied_second_moment)/d(m, m c)."""
        m, dm = self._tied_mass(mh)
        h = np.asarray(mh[1:FIRST_MOMENT_COLUMNS], dtype=float)
        k = FIRST_MOMENT_COLUMNS
        J = np.zeros((SECOND_MOMENT_COLUMNS, k))
        J[:, 1:] = point_mass_parameters_jacobian(1.0 / m, h)[k:, 1:]
        return J - np.outer(point_mass_parameters(1.0 / m ** 2, h)[k:], dm)

    def coefficients(self, p):
        body, second = p[:FIRST_MOMENT_COLUMNS], self._tied_second_moment(p[:FIRST_MOMENT_COLUMNS])
        return np.concatenate([body, second, p[FIRST_MOMENT_COLUMNS:]] + ([second] if self.j1_inertia else []))

    def coefficients_jacobian(self, p):
        k = FIRST_MOMENT_COLUMNS
        J = np.zeros((self.n_columns, self.n_parameters))
        J[:k, :k] = np.eye(k)  # (m, m c), then their tied second moment (and J1's row of it on the yaw link)
        J[k:BODY_PARAMETERS, :k] = self._tied_second_moment_jacobian(p[:k])
        J[BODY_PARAMETERS:BODY_PARAMETERS + k, k:] = np.eye(k)  # J1's path
        J[BODY_PARAMETERS + k:, :k] = J[k:BODY_PARAMETERS, :k] if self.j1_inertia else 0.0
        return J

    def initial_guesses(self, linear_solution):
        """The unconstrained solution's (m, m c) and J1's path, and the same with
        the mass raised to put the payload within FIRST_MOMENT_PRIOR_LENGTH_M; a
        payload J1 alone sees (on the yaw link) starts its (m, m c) from J1's
        path: seen only through the tied inertia, they have no gradient at zero."""
        path = linear_solution[BODY_PARAMETERS:BODY_PARAMETERS + FIRST_MOMENT_COLUMNS]
        body = path if self.j1_inertia else linear_solution[:FIRST_MOMENT_COLUMNS]
        start = np.clip(np.r_[body, path], self.lower, self.upper)
        raised = max(start[0], np.linalg.norm(start[1:FIRST_MOMENT_COLUMNS]) / FIRST_MOMENT_PRIOR_LENGTH_M)
        return [start, np.r_[raised, start[1:]].clip(self.lower, self.upper)]

    def sim_contribution(self, p):
        return None  # a first moment without a position is not a body: added by regressor

    def first_moment_base_at_zero(self, p) -> np.ndarray:
        """m (p_origin + R c) in the base frame at q = 0 (kg·m)."""
        T = self.model.forward_kinematics(np.zeros(N_JOINTS))[self.link_key]
        return p[0] * T[:3, 3] + T[:3, :3] @ np.asarray(p[1:4], dtype=float)

    def describe(self, p):
        return {"mass_kg": float(p[0]), "link": self.link_name, "link_key": self.link_key, "group": self.group,
                **equivalents_of(self.model, self.equivalent_links),
                "first_moment_link_kg_m": [float(x) for x in p[1:4]],
                "first_moment_base_at_q0_kg_m": self.first_moment_base_at_zero(p).tolist(),
                "yaw_path_mass_and_first_moment_link": [float(x) for x in p[4:8]]}

    def size(self, p):
        return float(np.linalg.norm(p[1:4]))


class PayloadAtPosition(Effect):
    """A point mass of unknown mass at a known position (link frame): efforts linear in m."""

    kind = "payload_at_position"
    candidate = False  # never selected: it turns a selected payload into a mass

    def __init__(self, model: PsmModel, key: int, position_m, max_mass_kg: float = PAYLOAD_MAX_MASS_KG):
        link = _moving_body_link(model, key)
        self.link_key, self.link_name, self.group = key, link.name, link.group
        self.position = np.asarray(position_m, dtype=float)
        self.name = f"payload_at_{link.name}"
        self.joints = joints_moving_link(model, key)
        envelope = link_envelope(model, key)
        reach = np.maximum(np.abs(envelope.lower), np.abs(envelope.upper))
        # the mass a point there reads, of either sign (as the periodic fit's): a bound at zero read a session
        # change towards a lighter weight as 0 g, in the --repeat pair's reading and in the time folds
        self.parameters = (Parameter("mass_kg", "kg", -max_mass_kg, max_mass_kg),) + _yaw_path_parameters(max_mass_kg, reach)

    #: the mass is what is asked: no prior on it, nor on the yaw path (as the payload's)
    prior_scales = np.full(1 + FIRST_MOMENT_COLUMNS, np.inf)

    def columns(self, features):
        """The point mass per kg, J1's row its path's (m, m c) and its own inertia about the link's origin (known per kg)."""
        body = features.body_regressor[:, :, features.body_columns(self.link_key)]
        unit = point_mass_parameters(1.0, self.position)
        columns = _with_yaw_path(features, self.link_key, (body @ unit)[:, :, None])
        columns[:, YAW_PATH_JOINT, 0] = body[:, YAW_PATH_JOINT, FIRST_MOMENT_COLUMNS:] @ unit[FIRST_MOMENT_COLUMNS:]
        return columns

    def sim_contribution(self, p):
        return SimContribution(payloads=(Payload(link=self.link_key, mass_kg=float(p[0]), position_m=tuple(float(x) for x in self.position)),))

    def fully_simulated(self, p) -> bool:
        return False  # the yaw path is not a body

    def unsimulated_effort(self, features, p):
        """The yaw path's J1 effort, less the simulated body's own J1 effort (the path replaces it)."""
        columns = self.columns(features)
        body = features.body_regressor[:, :, features.body_columns(self.link_key)] @ point_mass_parameters(float(p[0]), self.position)
        return columns @ np.asarray(p, dtype=float) - body


def parse_payload_at(text: str, model: PsmModel) -> tuple[int, np.ndarray]:
    """'LINK:x,y,z' (link name or key; position in the link frame, m) -> (key, position)."""
    try:
        name, coords = text.split(":")
        position = np.array([float(v) for v in coords.split(",")])
    except ValueError:
        raise DvrkDartError(f"--payload-at {text!r}: expected LINK:x,y,z (link name, position in its frame in m)") from None
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise DvrkDartError(f"--payload-at {text!r}: expected three finite coordinates")
    key = int(name) if name.isdigit() else None
    if key is None:
        try:
            key = model.link_by_name(name).key
        except (KeyError, DvrkDartError):
            raise DvrkDartError(f"--payload-at {text!r}: unknown link '{name}' (links with a body: {_body_link_names(model)})") from None
    if key not in model.links:
        raise DvrkDartError(f"--payload-at {text!r}: unknown link {key} (links with a body: {_body_link_names(model)})")
    try:
        _moving_body_link(model, key)
    except DvrkDartError as exc:
        raise DvrkDartError(f"--payload-at {text!r}: {exc}") from None
    reach = arm_reach_m(model, key)
    distance = math.hypot(*position)  # (no overflow for 1e200, unlike a norm through the squares)
    if distance > reach:
        raise DvrkDartError(f"--payload-at {text!r}: ({', '.join(f'{v:g}' for v in position)}) m is {distance:.3g} m "
                            f"from the link's origin, farther than any part of the arm ({reach:.2f} m): positions are in metres")
    return key, position


#: 1 kg at the position must load some joint by at least this at some pose (N·m
#: or N): else gravity cannot see its mass from there (a point on the axes that move the link)
MIN_GRAVITY_EFFORT_PER_KG = 1e-3
#: poses the check samples, spread over the joint ranges
GRAVITY_CHECK_POSES = 64


def check_mass_determinable(arm, key: int, position: np.ndarray, text: str) -> None:
    """Refuse a --payload-at position from which gravity cannot see a mass."""
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.model.joint_lower, arm.model.joint_upper, (GRAVITY_CHECK_POSES, N_JOINTS))
    zero = np.zeros_like(q)
    features = TrajectoryFeatures(arm, q, zero, zero, zero, 1.0)
    body = features.body_regressor[:, :, features.body_columns(key)]
    gravity = body @ point_mass_parameters(1.0, position)
    if np.max(np.abs(gravity)) < MIN_GRAVITY_EFFORT_PER_KG:
        raise DvrkDartError(f"--payload-at {text!r}: mass not determinable: gravity does not load any joint through a mass at "
                            "that point (it lies on the axes that move the link)")


def _body_link_names(model) -> str:
    return ", ".join(link.name for link in model.links.values() if link.body and link.joint_type != "fixed")  # as _moving_body_link

"""A point mass clamped on a link, and which links a payload cannot be told apart on."""

from __future__ import annotations

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect, Parameter, SimContribution
from dvrk_dart.diagnosis.effects.features import FIRST_MOMENT_COLUMNS, TrajectoryFeatures
from dvrk_dart.diagnosis.effects.geometry import LinkEnvelope, joints_moving_link, link_envelope
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.body_regressor import BODY_PARAMETERS
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.sim.config import Payload

#: a payload heavier than this is not a "forgotten" mass on a 1 m arm (kg)
PAYLOAD_MAX_MASS_KG = 2.0


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


class PointPayload(Effect):
    """A point mass m at position c (link frame) rigidly attached to a link.

    Its efforts are those of a body with the dynamic parameters
    (m, m c, m (|c|^2 I - c c^T)): Pinocchio's joint-torque regressor of the
    link's tree body times those parameters, projected with G. The position is
    kept inside the link's envelope (a box around its DH skeleton)."""

    kind = "payload"
    linear = False
    #: the Occam prior on the mass (`design.PAYLOAD_MASS_PRIOR_PER_KG2`), none on the position
    prior_scales = np.array([1.0, np.inf, np.inf, np.inf])

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
            **equivalents_of(self.model, self.equivalent_links),
            "position_m": [float(x) for x in p[1:4]],
            "position_base_at_q0_m": self.position_base_at_zero(p).tolist(),
            "envelope_m": {"lower": self.envelope.lower.tolist(), "upper": self.envelope.upper.tolist()},
            "at_envelope_boundary": self.envelope.on_boundary(p[1:4]),
        }


def equivalents_of(model: PsmModel, equivalent_links) -> dict:
    """A payload report's equivalent links with their groups (the answer names those of other groups)."""
    return {"equivalent_links": list(equivalent_links), "equivalent_link_groups": [model.link_by_name(n).group for n in equivalent_links]}


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


def equivalent_payload_links(arm: Arm, held: dict[int, float] | None = None, recorded: np.ndarray | None = None) -> dict[int, tuple[int, ...]]:
    """For each payload link, the payload links (itself included) on which a
    body produces exactly the efforts some body on it produces: no effort
    measurement can tell them apart. E.g. the pitch link and the parallelogram
    links turning with q2 about pivots that only translate along the yaw axis
    relative to it: same kinetic energy, same potential up to a constant.
    On given runs (`held`: joint index -> the position every run holds it at;
    `recorded`: the joints whose efforts they measure) more links can be one
    body: a 3-joint log's held wrist moves the tool with the insertion carriage.

    Decided numerically, not by name: the body regressors of both links over
    random states must span the same space."""
    model = arm.model
    rng = np.random.default_rng(EQUIVALENCE_SEED)
    q = rng.uniform(model.joint_lower, model.joint_upper, size=(EQUIVALENCE_STATES, N_JOINTS))
    dq, ddq = rng.standard_normal((2, EQUIVALENCE_STATES, N_JOINTS))
    for j, position in (held or {}).items():
        q[:, j], dq[:, j], ddq[:, j] = position, 0.0, 0.0
    features = TrajectoryFeatures(arm, q, dq, ddq, np.zeros_like(q), 1.0)
    links = payload_links(model)
    rows = np.ones(N_JOINTS, bool) if recorded is None else np.asarray(recorded, bool)
    regressors = {k: features.body_regressor[:, rows][:, :, features.body_columns(k)].reshape(-1, BODY_PARAMETERS) for k in links}
    spaces = {k: _column_space(Y) for k, Y in regressors.items()}

    def inside(Y: np.ndarray, U: np.ndarray) -> bool:
        residual = np.linalg.norm(Y - U @ (U.T @ Y), axis=0)
        return bool(np.all(residual <= EQUIVALENCE_TOLERANCE * np.linalg.norm(Y, axis=0).max()))

    return {i: tuple(j for j in links if inside(regressors[j], spaces[i]) and inside(regressors[i], spaces[j])) for i in links}


def _gravity_first_moment_columns(arm: Arm, key: int) -> np.ndarray:
    """(states * 7, 4) gravity efforts per unit (m, m c) of a link's body over random states."""
    rng = np.random.default_rng(EQUIVALENCE_SEED)
    q = rng.uniform(arm.model.joint_lower, arm.model.joint_upper, size=(EQUIVALENCE_STATES, N_JOINTS))
    zero = np.zeros_like(q)
    features = TrajectoryFeatures(arm, q, zero, zero, zero, 1.0)
    return features.first_moment_columns(key).reshape(-1, FIRST_MOMENT_COLUMNS)


def mass_seen_by_gravity(arm: Arm, key: int) -> bool:
    """Whether gravity sees a payload's mass on a link apart from its first
    moment: not on a link turning about fixed axes, nor on one equivalent to
    it (a parallelogram link); there the mass shows only in the inertia, a
    few mN·m for 0.1 kg, below the noise."""
    Y = _gravity_first_moment_columns(arm, key)
    residual = Y[:, 0] - Y[:, 1:] @ np.linalg.lstsq(Y[:, 1:], Y[:, 0], rcond=RANK_CUT)[0]
    return bool(np.linalg.norm(residual) > EQUIVALENCE_TOLERANCE * max(np.linalg.norm(Y, axis=0).max(), 1e-300))


def first_moment_map(arm: Arm, from_key: int, to_key: int) -> np.ndarray:
    """(4, 4) map of a body's (m, m c) on `from_key` to the (m, m c) on `to_key`
    whose gravity efforts are the same (least squares over random states; exact
    for equivalent links, whose base-frame first moments differ by what the
    efforts do not see, e.g. the constant height of a link's origin)."""
    return np.linalg.lstsq(_gravity_first_moment_columns(arm, to_key), _gravity_first_moment_columns(arm, from_key), rcond=RANK_CUT)[0]

"""The identification regressor: efforts = Y(q, dq, ddq) . theta, linear in the
standard parameters theta of the links that `models/psm/psm.toml` gives
inertia, friction, a motor inertia or a spring.

Standard parameters, in this order, named `link<key>.<name>` (SI units):
- each link with `inertia = true`: m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz,
  Izz -- Pinocchio's dynamic parameters: mass (kg), first moment m c (kg m)
  and inertia about the link frame origin (kg m^2), link-frame axes;
- each link with `friction = true`: Fc, Fv, Fo (Coulomb, viscous, offset);
- each link with `motor_inertia = true`: Im (kg m^2);
- each link with `spring = true`: K (N m/rad).

The rigid-body columns are Pinocchio's joint-torque regressor of the very tree
model that evaluates the identified model (`IdentifiedModel.pin_model`),
projected onto the seven coordinates with G^T exactly as `IdentifiedModel`
projects its efforts (theta_tree = G q + c). The non-inertial columns are the
derivatives of `IdentifiedModel.efforts` with respect to each coefficient (the
terms are linear in them); `tests/test_identification.py` checks that
Y theta(params) equals `IdentifiedModel.predict` for the published parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model import friction
from dvrk_dart.model.body_regressor import BODY_PARAMETER_NAMES, BODY_PARAMETERS, body_columns, body_regressor
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.identified import IdentifiedModel, body_inertia, spring_torque
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters, LinkParameters

FRICTION_NAMES = ("Fc", "Fv", "Fo")
#: the class of each parameter name (keys of [prior_std] in the bounds file)
PARAMETER_CLASSES = {
    "m": "mass_kg", "mcx": "first_moment_kg_m", "mcy": "first_moment_kg_m", "mcz": "first_moment_kg_m",
    **{n: "inertia_kg_m2" for n in BODY_PARAMETER_NAMES[4:]},
    "Fc": "coulomb", "Fv": "viscous", "Fo": "offset", "Im": "motor_inertia_kg_m2", "K": "spring_n_m_per_rad",
}
FRICTION_LAWS = ("sign", "tanh", "presliding")


@dataclass(frozen=True)
class FrictionLaw:
    """How Coulomb friction reverses: sign(v) (upstream), tanh(v / reversal_velocity)
    (a smooth reversal in velocity, rad/s or m/s), or over a pre-sliding distance
    per link (Dahl's state on the link's position, model/friction.py; `presliding`
    holds (link key, distance) pairs, links not named reverse at once)."""

    kind: str = "sign"
    reversal_velocity: float | None = None
    presliding: tuple[tuple[int, float], ...] = ()

    def __post_init__(self):
        if self.kind not in FRICTION_LAWS:
            raise DvrkDartError(f"--friction-law: unknown law '{self.kind}' (known: {', '.join(FRICTION_LAWS)})")
        if self.kind == "tanh" and not (self.reversal_velocity is not None and self.reversal_velocity > 0.0):
            raise DvrkDartError("--reversal-velocity: a positive velocity scale is needed with --friction-law tanh")

    @classmethod
    def of_distances(cls, distances: dict[int, float]) -> "FrictionLaw":
        """The pre-sliding law of these (link key -> distance) pairs; sign(v) when none is positive."""
        positive = tuple(sorted((int(k), float(d)) for k, d in distances.items() if d > 0.0))
        return cls("presliding", presliding=positive) if positive else cls()

    def distance(self, key: int) -> float:
        return dict(self.presliding).get(key, 0.0) if self.kind == "presliding" else 0.0

    def with_distance(self, key: int, distance: float) -> "FrictionLaw":
        return replace(self, presliding=tuple(sorted({**dict(self.presliding), key: distance}.items())))

    def reversal(self, rate: np.ndarray, position: np.ndarray | None = None, key: int | None = None) -> np.ndarray:
        if self.kind == "tanh":
            return np.tanh(rate / self.reversal_velocity)
        distance = self.distance(key) if key is not None else 0.0
        return friction.reversal(position, rate, distance) if distance > 0.0 else np.sign(rate)

    def describe(self) -> str:
        if self.kind == "tanh":
            return f"tanh(v / {self.reversal_velocity:g})"
        if self.kind == "presliding":
            return "Dahl pre-sliding over " + (", ".join(f"link{k} {d:g}" for k, d in self.presliding if d > 0) or "no link") + \
                ", else sign(v)"
        return "sign(v)"


@dataclass(frozen=True)
class ParameterLayout:
    """Which standard parameters exist, in which order."""

    names: tuple[str, ...]
    inertial_links: tuple[int, ...]
    friction_links: tuple[int, ...]
    motor_links: tuple[int, ...]
    spring_links: tuple[int, ...]

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def body_slice(self, key: int) -> slice:
        start = self.inertial_links.index(key) * BODY_PARAMETERS
        return slice(start, start + BODY_PARAMETERS)

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(PARAMETER_CLASSES[n.split(".", 1)[1]] for n in self.names)


def parameter_layout(model: PsmModel) -> ParameterLayout:
    links = model.links.values()
    inertial = tuple(l.key for l in links if l.inertia)
    friction = tuple(l.key for l in links if l.friction)
    motor = tuple(l.key for l in links if l.motor_inertia)
    spring = tuple(l.key for l in links if l.spring)
    names = [f"link{k}.{n}" for k in inertial for n in BODY_PARAMETER_NAMES]
    names += [f"link{k}.{n}" for k in friction for n in FRICTION_NAMES]
    names += [f"link{k}.Im" for k in motor] + [f"link{k}.K" for k in spring]
    return ParameterLayout(tuple(names), inertial, friction, motor, spring)


def zero_parameters(model: PsmModel) -> IdentifiedParameters:
    """A parameter set of zeros: the regressor does not depend on the values."""
    zero = {k: LinkParameters(k, 0.0, np.zeros(3), np.zeros((3, 3)), 0.0, 0.0, 0.0, 0.0, 0.0) for k in model.links}
    return IdentifiedParameters(source=Path("zeros"), links=zero)


def standard_vector(params: IdentifiedParameters, layout: ParameterLayout) -> np.ndarray:
    """theta (layout order) of a parameter set (link frames, as the loader gives)."""
    parts = []
    for key in layout.inertial_links:
        p = params[key]
        parts.append(body_inertia(p.mass, p.com, p.inertia_com).toDynamicParameters())
    parts += [[params[k].coulomb, params[k].viscous, params[k].offset] for k in layout.friction_links]
    parts += [[params[k].motor_inertia] for k in layout.motor_links]
    parts += [[params[k].spring] for k in layout.spring_links]
    return np.concatenate([np.asarray(p, dtype=float) for p in parts])


def body_of(theta: np.ndarray, layout: ParameterLayout, key: int) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre of mass, inertia about the centre of mass) of a link, link
    frame; the centre of mass of a massless link is its origin."""
    p = theta[layout.body_slice(key)]
    mass, first = float(p[0]), np.asarray(p[1:4], dtype=float)
    xx, xy, yy, xz, yz, zz = p[4:]
    inertia_origin = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    com = first / mass if mass > 0.0 else np.zeros(3)
    # parallel axis: I_origin = I_com + m (|c|^2 1 - c c^T)
    inertia_com = inertia_origin - mass * (com @ com * np.eye(3) - np.outer(com, com))
    return mass, com, inertia_com


def params_json(theta: np.ndarray, layout: ParameterLayout, model: PsmModel, friction_law: FrictionLaw = FrictionLaw()) -> dict:
    """The upstream params.json layout: every link of the model, r and I about the
    centre of mass with the base-frame axes at q = 0 (the loader's inverse); a
    link whose friction reverses over a pre-sliding distance gains "xs"."""
    out = {}
    for key in model.links:
        entry = {"m": 0.0, "r": [0.0, 0.0, 0.0], "I": [0.0] * 6, "Fc": 0.0, "Fv": 0.0, "Fo": 0.0, "Im": 0.0, "K": 0.0}
        if key in layout.inertial_links:
            mass, com, inertia_com = body_of(theta, layout, key)
            R0 = model.rotations_at_zero[key]
            I = R0 @ inertia_com @ R0.T
            entry.update(m=mass, r=(R0 @ com).tolist(), I=[I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2]])
        if key in layout.friction_links:
            entry.update(zip(FRICTION_NAMES, (float(theta[layout.index(f"link{key}.{n}")]) for n in FRICTION_NAMES)))
            if friction_law.distance(key) > 0.0:
                entry["xs"] = friction_law.distance(key)
        if key in layout.motor_links:
            entry["Im"] = float(theta[layout.index(f"link{key}.Im")])
        if key in layout.spring_links:
            entry["K"] = float(theta[layout.index(f"link{key}.K")])
        out[str(key)] = entry
    return out


class Regressor:
    """Y(q, dq, ddq): (N, 7, n_parameters), from the identified model's Pinocchio tree."""

    def __init__(self, model: PsmModel, friction_law: FrictionLaw = FrictionLaw()):
        self.model = model
        self.layout = parameter_layout(model)
        self.friction_law = friction_law
        self.evaluator = IdentifiedModel(model, zero_parameters(model))
        self._body_columns = np.r_[tuple(body_columns(self.evaluator, k) for k in self.layout.inertial_links)]

    def __call__(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        q, dq, ddq = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, dq, ddq))
        layout = self.layout
        Y = np.zeros((len(q), N_JOINTS, len(layout)))
        n_body = BODY_PARAMETERS * len(layout.inertial_links)
        Y[:, :, :n_body] = body_regressor(self.evaluator, q, dq, ddq, self._body_columns)
        c = n_body
        links = self.model.links
        for key in layout.friction_links:  # f = Fc s(v) + Fv v + Fo on the link's own rate v, projected by dv/dq
            coeffs = links[key].variable.coeffs
            rate = dq @ coeffs
            Y[:, :, c] = np.outer(self.friction_law.reversal(rate, q @ coeffs, key), coeffs)
            Y[:, :, c + 1] = np.outer(rate, coeffs)
            Y[:, :, c + 2] = coeffs
            c += 3
        for key in layout.motor_links:  # Im times the variable's acceleration, on its one coordinate
            coeffs = links[key].variable.coeffs
            j = int(np.flatnonzero(coeffs)[0])
            Y[:, j, c] = coeffs[j] * ddq[:, j]
            c += 1
        for key in layout.spring_links:  # K times its law (q from rest, or a linkage's), projected like a friction
            coeffs = links[key].variable.coeffs
            Y[:, :, c] = np.outer(spring_torque(1.0, q @ coeffs, links[key].spring_linkage), coeffs)
            c += 1
        return Y

"""The PSM model description: `models/psm/psm.toml` read into typed objects.

Every link's joint variable (theta or d of its modified-DH transform) is a
linear function of the seven coordinates q1..q7; this module resolves the
file's small linear expressions into (coefficients, constant) pairs and offers
the forward kinematics of the tree. It is the single reader of the model file:
the DART builder and the Pinocchio model are both built from `PsmModel`.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.joints import (
    JOINT_NAMES,
    N_JOINTS,
    WRIST_COLUMNS,
    MotorCoordinateMap,
)
from dvrk_dart.paths import MODELS_DIR

DEFAULT_MODEL_FILE = MODELS_DIR / "psm" / "psm.toml"

GROUPS = ("yaw", "parallelogram", "insertion", "counterweight", "tool")


@dataclass(frozen=True)
class LinearExpr:
    """value = coeffs . q + const, with q the seven joint coordinates."""

    coeffs: np.ndarray
    const: float

    @staticmethod
    def constant(value: float) -> "LinearExpr":
        return LinearExpr(np.zeros(N_JOINTS), float(value))

    def __call__(self, q: np.ndarray) -> np.ndarray | float:
        """Evaluate at one configuration (7,) or a batch (N, 7)."""
        return np.asarray(q) @ self.coeffs + self.const

    @property
    def depends_on_q(self) -> bool:
        return bool(np.any(self.coeffs != 0.0))

    def __add__(self, other: "LinearExpr") -> "LinearExpr":
        return LinearExpr(self.coeffs + other.coeffs, self.const + other.const)

    def scaled(self, k: float) -> "LinearExpr":
        return LinearExpr(self.coeffs * k, self.const * k)


@dataclass(frozen=True)
class DHFrame:
    """A modified-DH frame: T(parent -> this) = Rx(alpha) Tx(a) Rz(theta) Tz(d)."""

    parent: int
    a: LinearExpr
    alpha: LinearExpr
    d: LinearExpr
    theta: LinearExpr

    @property
    def joint_type(self) -> str:
        if self.theta.depends_on_q and self.d.depends_on_q:
            raise DvrkDartError("a link cannot have both theta and d depend on q")
        if self.theta.depends_on_q:
            return "revolute"
        if self.d.depends_on_q:
            return "prismatic"
        return "fixed"

    @property
    def variable(self) -> LinearExpr | None:
        """The link's own joint variable (theta or d), None for a fixed frame."""
        return {"revolute": self.theta, "prismatic": self.d, "fixed": None}[self.joint_type]

    def transform(self, q: np.ndarray) -> np.ndarray:
        return dh_transform(float(self.a(q)), float(self.alpha(q)), float(self.d(q)), float(self.theta(q)))

    def transforms(self, q: np.ndarray) -> np.ndarray:
        """(N, 4, 4) transforms at a batch of configurations (N, 7)."""
        return dh_transforms(self.a(q), self.alpha(q), self.d(q), self.theta(q))


@dataclass(frozen=True)
class Link(DHFrame):
    key: int = 0
    name: str = ""
    group: str = ""
    body: bool = True
    inertia: bool = False
    friction: bool = False
    motor_inertia: bool = False
    spring: bool = False


@dataclass(frozen=True)
class LoopClosure:
    name: str
    link: int
    other: int
    point_in_link: np.ndarray  # metres, in the frame of `link`


@dataclass(frozen=True)
class PsmModel:
    name: str
    source: Path
    constants: dict[str, float]
    gravity: np.ndarray
    default_parameters: str
    links: dict[int, Link]
    tool_tip: DHFrame
    loop_closures: tuple[LoopClosure, ...]
    counterweight_link: int
    counterweight_ratio: float
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    dvrk_wrist_matrix: np.ndarray
    dvrk_velocity_limits: np.ndarray | None = None  # (7,) rad/s, m/s, dVRK joints ([dvrk_velocity_limits])
    inertia_tolerance: float = 0.0  # kg m^2, see [parameter_checks]
    max_link_mass_kg: float = float("inf")  # plausibility bounds of a parameter file
    max_com_distance_m: float = float("inf")
    model_angles: dict[str, LinearExpr] = field(default_factory=dict)
    session_offset_joints: tuple[str, ...] | None = None  # joints whose constant effort moves between sessions ([sessions])

    @property
    def body_links(self) -> list[Link]:
        return [link for link in self.links.values() if link.body]

    def children(self, key: int) -> list[Link]:
        return [link for link in self.links.values() if link.parent == key]

    def link_by_name(self, name: str) -> Link:
        for link in self.links.values():
            if link.name == name:
                return link
        raise DvrkDartError(f"unknown link '{name}' (known: {', '.join(l.name for l in self.links.values())})")

    def forward_kinematics(self, q: np.ndarray) -> dict[int, np.ndarray]:
        """Base-frame 4x4 transform of every link frame (key 0 is the base)."""
        q = np.asarray(q, dtype=float)
        frames = {0: np.eye(4)}
        for key, link in self.links.items():  # parents precede children in the file
            frames[key] = frames[link.parent] @ link.transform(q)
        return frames

    def tool_tip_transform(self, q: np.ndarray, frames: dict[int, np.ndarray] | None = None) -> np.ndarray:
        frames = frames if frames is not None else self.forward_kinematics(q)
        return frames[self.tool_tip.parent] @ self.tool_tip.transform(q)

    @cached_property
    def rotations_at_zero(self) -> dict[int, np.ndarray]:
        """R_i(q = 0): the frame in which params.json expresses r and I."""
        return {k: T[:3, :3] for k, T in self.forward_kinematics(np.zeros(N_JOINTS)).items()}

    @cached_property
    def motor_map(self) -> MotorCoordinateMap:
        """dVRK joint values <-> the model's coordinates (joints.py owns the map)."""
        return MotorCoordinateMap(self.dvrk_wrist_matrix)

    def dvrk_to_motor(self, dvrk_wrist: np.ndarray) -> np.ndarray:
        """(wrist pitch, wrist yaw, jaw) -> motor coordinates q5..q7 (last axis)."""
        full = np.zeros((*np.shape(dvrk_wrist)[:-1], N_JOINTS))
        full[..., WRIST_COLUMNS] = dvrk_wrist
        return self.motor_map.positions_to_model(full)[..., WRIST_COLUMNS]

    def motor_to_dvrk(self, motor: np.ndarray) -> np.ndarray:
        full = np.zeros((*np.shape(motor)[:-1], N_JOINTS))
        full[..., WRIST_COLUMNS] = motor
        return self.motor_map.positions_to_dvrk(full)[..., WRIST_COLUMNS]


def dh_transform(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """Modified DH (Craig): Rx(alpha) . Tx(a) . Rz(theta) . Tz(d)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_transforms(a: np.ndarray, alpha: np.ndarray, d: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """`dh_transform` of arrays of parameters, (N, 4, 4)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    T = np.zeros((len(theta), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 0, 3] = ct, -st, a
    T[:, 1, 0], T[:, 1, 1], T[:, 1, 2], T[:, 1, 3] = st * ca, ct * ca, -sa, -sa * d
    T[:, 2, 0], T[:, 2, 1], T[:, 2, 2], T[:, 2, 3] = st * sa, ct * sa, ca, ca * d
    T[:, 3, 3] = 1.0
    return T


class _ExpressionReader:
    """Turns {name = coefficient} tables into LinearExpr, naming the offending entry."""

    def __init__(self, path: Path, constants: dict[str, float]):
        self.path = path
        self.constants = constants
        self.model_angles: dict[str, LinearExpr] = {}

    def read(self, table: object, where: str) -> LinearExpr:
        if not isinstance(table, dict):
            raise DvrkDartError(f"{self.path}: {where} must be a table {{name = coefficient}}")
        expr = LinearExpr.constant(0.0)
        for name, coeff in table.items():
            if not isinstance(coeff, (int, float)) or not math.isfinite(coeff):
                raise DvrkDartError(f"{self.path}: {where}.{name} must be a finite number")
            expr = expr + self._term(name, where).scaled(float(coeff))
        return expr

    def _term(self, name: str, where: str) -> LinearExpr:
        if name == "pi":
            return LinearExpr.constant(math.pi)
        if name in self.constants:
            return LinearExpr.constant(self.constants[name])
        if name in JOINT_NAMES:
            coeffs = np.zeros(N_JOINTS)
            coeffs[JOINT_NAMES.index(name)] = 1.0
            return LinearExpr(coeffs, 0.0)
        if name in self.model_angles:
            return self.model_angles[name]
        raise DvrkDartError(f"{self.path}: {where} uses unknown name '{name}'")


def _require(table: dict, key: str, path: Path, where: str):
    if key not in table:
        raise DvrkDartError(f"{path}: {where} is missing '{key}'")
    return table[key]


def load_model(path: Path | str = DEFAULT_MODEL_FILE) -> PsmModel:
    """Read and check a PSM model description file."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: model file not found") from None
    except tomllib.TOMLDecodeError as exc:
        raise DvrkDartError(f"{path}: not valid TOML ({exc})") from None

    constants = {k: float(v) for k, v in _require(raw, "constants", path, "file").items()}
    reader = _ExpressionReader(path, constants)
    for name, table in raw.get("model_angles", {}).items():
        reader.model_angles[name] = reader.read(table, f"model_angles.{name}")

    links: dict[int, Link] = {}
    for entry in _require(raw, "links", path, "file"):
        key = int(_require(entry, "key", path, "a link"))
        where = f"links[key={key}]"
        parent = int(_require(entry, "parent", path, where))
        if parent != 0 and parent not in links:
            raise DvrkDartError(f"{path}: {where} has parent {parent} not defined before it")
        group = _require(entry, "group", path, where)
        if group not in GROUPS:
            raise DvrkDartError(f"{path}: {where} has group '{group}', expected one of {GROUPS}")
        link = Link(
            parent=parent,
            a=reader.read(entry.get("a", {}), f"{where}.a"),
            alpha=reader.read(entry.get("alpha", {}), f"{where}.alpha"),
            d=reader.read(entry.get("d", {}), f"{where}.d"),
            theta=reader.read(entry.get("theta", {}), f"{where}.theta"),
            key=key,
            name=_require(entry, "name", path, where),
            group=group,
            body=bool(entry.get("body", True)),
            inertia=bool(entry.get("inertia", False)),
            friction=bool(entry.get("friction", False)),
            motor_inertia=bool(entry.get("motor_inertia", False)),
            spring=bool(entry.get("spring", False)),
        )
        _ = link.joint_type  # raises on a link with two variables
        links[key] = link

    tip = _require(raw, "tool_tip", path, "file")
    tool_tip = DHFrame(
        parent=int(tip["parent"]),
        **{k: reader.read(tip.get(k, {}), f"tool_tip.{k}") for k in ("a", "alpha", "d", "theta")},
    )
    closures = tuple(
        LoopClosure(
            name=c["name"],
            link=int(c["link"]),
            other=int(c["other"]),
            point_in_link=np.array(
                [float(reader.read(c["point"].get(ax, {}), f"loop_closures.{c['name']}.point.{ax}").const) for ax in "xyz"]
            ),
        )
        for c in raw.get("loop_closures", [])
    )
    for c in closures:
        for k in (c.link, c.other):
            if k not in links:
                raise DvrkDartError(f"{path}: loop closure '{c.name}' names unknown link {k}")
    cw = _require(raw, "counterweight", path, "file")
    limits = _require(raw, "joint_limits", path, "file")
    wrist = _require(raw, "dvrk_wrist", path, "file")
    return PsmModel(
        name=raw.get("name", path.stem),
        source=path,
        constants=constants,
        gravity=np.array(raw.get("gravity_m_s2", [0.0, 0.0, -9.81]), dtype=float),
        default_parameters=raw.get("default_parameters", "params.json"),
        links=links,
        tool_tip=tool_tip,
        loop_closures=closures,
        counterweight_link=int(cw["link"]),
        counterweight_ratio=float(cw.get("ratio", 1.0)),
        joint_lower=np.array(limits["lower"], dtype=float),
        joint_upper=np.array(limits["upper"], dtype=float),
        dvrk_wrist_matrix=np.array(wrist["matrix"], dtype=float),
        dvrk_velocity_limits=np.array(raw["dvrk_velocity_limits"]["upper"], dtype=float) if "dvrk_velocity_limits" in raw else None,
        inertia_tolerance=float(raw.get("parameter_checks", {}).get("inertia_tolerance_kg_m2", 0.0)),
        max_link_mass_kg=float(raw.get("parameter_checks", {}).get("max_link_mass_kg", float("inf"))),
        max_com_distance_m=float(raw.get("parameter_checks", {}).get("max_com_distance_m", float("inf"))),
        model_angles=dict(reader.model_angles),
        session_offset_joints=_session_offset_joints(raw, path),
    )


def _session_offset_joints(raw: dict, path: Path) -> tuple[str, ...] | None:
    """[sessions] offset_joints: joint names (q1..q7) whose constant effort moves between sessions."""
    if "sessions" not in raw:
        return None
    names = tuple(raw["sessions"].get("offset_joints", ()))
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown:
        raise DvrkDartError(f"{path}: [sessions] offset_joints: unknown joint(s) {', '.join(map(str, unknown))} (known: {', '.join(JOINT_NAMES)})")
    return names

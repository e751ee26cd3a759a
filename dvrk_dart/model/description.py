"""An arm's model description (`models/psm/psm.toml`, `models/mtm/mtm.toml`) read into typed objects.

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
from dvrk_dart.model.dh import DHFrame, LinearExpr, Link
from dvrk_dart.model.joints import (
    JOINT_NAMES,
    N_JOINTS,
    MotorCoordinateMap,
)
from dvrk_dart.paths import MODELS_DIR

#: the arm a command models when --arm-model is not given
DEFAULT_MODEL_FILE = MODELS_DIR / "psm" / "psm.toml"



def resolve_arm_model(text: str) -> Path:
    """--arm-model: an arm of models/ by name (psm, mtm), a model folder
    (models/mtm/: its one description .toml) or a description file."""
    named = MODELS_DIR / text / f"{text}.toml"
    if named.is_file():
        return named
    path = Path(text)
    if path.is_dir():
        found = sorted(p for p in path.glob("*.toml") if p.name != "identification.toml")
        if len(found) != 1:
            raise DvrkDartError(f"--arm-model {text}: a model folder holds one description .toml (found {len(found)})")
        return found[0]
    if path.is_file():
        return path
    known = ", ".join(sorted(p.name for p in MODELS_DIR.iterdir() if (p / f"{p.name}.toml").is_file()))
    raise DvrkDartError(f"--arm-model {text}: no such arm ({known}), model folder or file")


@dataclass(frozen=True)
class UpstreamProcessing:
    """The identification's own filter and test window for this arm (io/signal.py)."""

    cutoff_parameter_hz: float
    first_period_samples: int


@dataclass(frozen=True)
class DvrkTopics:
    """The dVRK's topics of an arm ([dvrk_topics]): its default namespace, the
    joints of <ns>/measured_js and those of <ns>/jaw/measured_js (none on the MTM)."""

    namespace: str
    arm_joints: tuple[str, ...]
    jaw_joints: tuple[str, ...] = ()

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The dVRK's names of q1..q7's joints, in order."""
        return self.arm_joints + self.jaw_joints


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
    counterweight_link: int | None
    counterweight_ratio: float
    joint_lower: np.ndarray
    joint_upper: np.ndarray
    dvrk_coupling_matrix: np.ndarray
    dvrk_coupling_columns: tuple[int, ...]
    dvrk_velocity_limits: np.ndarray | None = None  # (7,) rad/s, m/s, dVRK joints ([dvrk_velocity_limits])
    inertia_tolerance: float = 0.0  # kg m^2, see [parameter_checks]
    max_link_mass_kg: float = float("inf")  # plausibility bounds of a parameter file
    max_com_distance_m: float = float("inf")
    #: link key -> a mass bound of the published identification: a mass sitting on it is reported ([parameter_checks])
    identification_mass_bounds_kg: dict[int, float] = field(default_factory=dict)
    model_angles: dict[str, LinearExpr] = field(default_factory=dict)
    session_offset_joints: tuple[str, ...] | None = None  # joints whose constant effort moves between sessions ([sessions])
    #: two reference recordings of one motion in two sessions ([sessions] repeat_pair: manifest names)
    session_repeat_pair: tuple[str, ...] = ()
    #: the controllers' and the counterweight PID's gains ([controllers]: name -> value)
    controller_gains: dict[str, object] = field(default_factory=dict)
    groups: tuple[str, ...] = ()
    processing: UpstreamProcessing | None = None  # [processing]: required of a model file
    dvrk_topics: DvrkTopics | None = None
    project_unphysical_bodies: bool = False  # DART gets the nearest physical body of a non-physical identified one
    #: what the diagnosis simulates before adding effects ([diagnosis] base): the identified
    #: inertia only ("inertial"), or every identified term ("identified": effects then correct it)
    diagnosis_base: str = "inertial"
    #: where `dvrk-dart force` estimates the external force ([force_point]): None when the card names none
    force_point: "ForcePoint | None" = None

    @property
    def folder(self) -> Path:
        """The arm's model folder (models/<arm>/)."""
        return self.source.parent

    @cached_property
    def prismatic_coordinates(self) -> tuple[str, ...]:
        """The coordinates a prismatic link moves (the PSM's q3; none on the MTM)."""
        moved = np.zeros(N_JOINTS, dtype=bool)
        for link in self.links.values():
            if link.joint_type == "prismatic":
                moved |= link.variable.coeffs != 0.0
        return tuple(name for name, m in zip(JOINT_NAMES, moved) if m)

    def position_unit(self, name: str) -> str:
        return "m" if name in self.prismatic_coordinates else "rad"

    def velocity_unit(self, name: str) -> str:
        return f"{self.position_unit(name)}/s"

    def effort_unit(self, name: str) -> str:
        return "N" if name in self.prismatic_coordinates else "N·m"

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

    def controller_gain(self, name: str):
        """A gain of the card's [controllers] (a one-line error naming the card where it has none)."""
        if name not in self.controller_gains:
            raise DvrkDartError(f"{self.source}: no [controllers] {name} (the paper's controllers and the counterweight PID need it)")
        return self.controller_gains[name]

    def cable_efforts(self, q: np.ndarray) -> np.ndarray:
        """The known cable torques (links with a `cable_polynomial`) at positions
        q (N, 7): what the measured efforts hold besides the identified model.
        The identification removed them from the measured efforts before fitting
        (the MTM's joint 4), so every comparison does too (io/signal.process)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.zeros_like(q)
        for link in self.links.values():
            if link.cable_polynomial:
                out += np.outer(np.polyval(link.cable_polynomial, q @ link.variable.coeffs), link.variable.coeffs)
        return out

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
        return MotorCoordinateMap(self.dvrk_coupling_matrix, list(self.dvrk_coupling_columns))


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


DIAGNOSIS_BASES = ("inertial", "identified")


@dataclass(frozen=True)
class ForcePoint:
    """The instrument point of a force estimate: the origin of `link`'s frame,
    positioned by `joints`; a direction whose lever arm (singular value of the
    positional Jacobian) is below `min_lever_m` is not determined."""

    link: int
    name: str
    joints: tuple[int, ...]
    min_lever_m: float


def _force_point(raw: dict, path: Path, links: dict) -> ForcePoint | None:
    table = raw.get("force_point")
    if table is None:
        return None
    name = str(_require(table, "link", path, "[force_point]"))
    keys = [k for k, link in links.items() if link.name == name]
    if not keys:
        raise DvrkDartError(f"{path}: [force_point] link '{name}' is not a link of the model")
    joints = tuple(JOINT_NAMES.index(j) for j in _require(table, "joints", path, "[force_point]"))
    return ForcePoint(keys[0], str(table.get("point", name)), joints, float(_require(table, "min_lever_m", path, "[force_point]")))


def _diagnosis_base(raw: dict, path: Path) -> str:
    base = raw.get("diagnosis", {}).get("base", "inertial")
    if base not in DIAGNOSIS_BASES:
        raise DvrkDartError(f"{path}: [diagnosis] base must be one of {', '.join(DIAGNOSIS_BASES)}, not {base!r}")
    return base


def _upstream_processing(raw: dict, path: Path) -> UpstreamProcessing:
    table = _require(raw, "processing", path, "file")
    try:
        return UpstreamProcessing(float(table["cutoff_parameter_hz"]), int(table["first_period_samples"]))
    except (KeyError, TypeError, ValueError):
        raise DvrkDartError(f"{path}: [processing] needs cutoff_parameter_hz (a number) and first_period_samples (an integer)") from None


def load_model(path: Path | str) -> PsmModel:
    """Read and check an arm's model description file."""
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

    groups = tuple(_require(raw, "groups", path, "file"))
    links: dict[int, Link] = {}
    for entry in _require(raw, "links", path, "file"):
        key = int(_require(entry, "key", path, "a link"))
        where = f"links[key={key}]"
        parent = int(_require(entry, "parent", path, where))
        if parent != 0 and parent not in links:
            raise DvrkDartError(f"{path}: {where} has parent {parent} not defined before it")
        group = _require(entry, "group", path, where)
        if group not in groups:
            raise DvrkDartError(f"{path}: {where} has group '{group}', expected one of {', '.join(groups)} (the file's groups)")
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
            spring_linkage={k: float(v) for k, v in entry["spring_linkage"].items()} if "spring_linkage" in entry else None,
            cable_polynomial=tuple(float(c) for c in entry["cable_polynomial"]) if "cable_polynomial" in entry else None,
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
    cw = raw.get("counterweight")
    if cw is not None and int(cw["link"]) not in links:
        raise DvrkDartError(f"{path}: [counterweight] names unknown link {cw['link']}")
    limits = _require(raw, "joint_limits", path, "file")
    coupling = _require(raw, "dvrk_coupling", path, "file")
    columns = tuple(int(c) for c in _require(coupling, "columns", path, "[dvrk_coupling]"))
    if any(not 0 <= c < N_JOINTS for c in columns):
        raise DvrkDartError(f"{path}: [dvrk_coupling] columns must be 0..{N_JOINTS - 1} (0 is q1)")
    checks = raw.get("parameter_checks", {})
    return PsmModel(
        name=raw.get("name", path.stem),
        source=path,
        constants=constants,
        gravity=np.array(raw.get("gravity_m_s2", [0.0, 0.0, -9.81]), dtype=float),
        default_parameters=raw.get("default_parameters", "params.json"),
        links=links,
        tool_tip=tool_tip,
        loop_closures=closures,
        counterweight_link=int(cw["link"]) if cw is not None else None,
        counterweight_ratio=float(cw.get("ratio", 1.0)) if cw is not None else 0.0,
        joint_lower=np.array(limits["lower"], dtype=float),
        joint_upper=np.array(limits["upper"], dtype=float),
        dvrk_coupling_matrix=np.array(_require(coupling, "matrix", path, "[dvrk_coupling]"), dtype=float),
        dvrk_coupling_columns=columns,
        dvrk_velocity_limits=np.array(raw["dvrk_velocity_limits"]["upper"], dtype=float) if "dvrk_velocity_limits" in raw else None,
        inertia_tolerance=float(checks.get("inertia_tolerance_kg_m2", 0.0)),
        max_link_mass_kg=float(checks.get("max_link_mass_kg", float("inf"))),
        max_com_distance_m=float(checks.get("max_com_distance_m", float("inf"))),
        identification_mass_bounds_kg={int(k): float(v) for k, v in checks.get("identification_mass_bounds_kg", {}).items()},
        model_angles=dict(reader.model_angles),
        session_offset_joints=_session_offset_joints(raw, path),
        session_repeat_pair=_session_repeat_pair(raw, path),
        controller_gains=dict(raw.get("controllers", {})),
        groups=groups,
        processing=_upstream_processing(raw, path),
        dvrk_topics=_dvrk_topics(raw, path),
        project_unphysical_bodies=bool(checks.get("project_unphysical_bodies", False)),
        diagnosis_base=_diagnosis_base(raw, path),
        force_point=_force_point(raw, path, links),
    )


def _dvrk_topics(raw: dict, path: Path) -> DvrkTopics:
    table = _require(raw, "dvrk_topics", path, "file")
    topics = DvrkTopics(str(_require(table, "namespace", path, "[dvrk_topics]")), tuple(_require(table, "arm_joints", path, "[dvrk_topics]")),
                        tuple(table.get("jaw_joints", ())))
    if len(topics.joint_names) != N_JOINTS:
        raise DvrkDartError(f"{path}: [dvrk_topics] names {len(topics.joint_names)} joints, the model has {N_JOINTS}")
    return topics


def _session_repeat_pair(raw: dict, path: Path) -> tuple[str, ...]:
    """[sessions] repeat_pair: two reference files (manifest names), or none."""
    pair = tuple(str(name) for name in raw.get("sessions", {}).get("repeat_pair", ()))
    if len(pair) not in (0, 2):
        raise DvrkDartError(f"{path}: [sessions] repeat_pair names {len(pair)} files, expected 2")
    return pair


def _session_offset_joints(raw: dict, path: Path) -> tuple[str, ...] | None:
    """[sessions] offset_joints: joint names (q1..q7) whose constant effort moves between sessions."""
    if "sessions" not in raw:
        return None
    names = tuple(raw["sessions"].get("offset_joints", ()))
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown:
        raise DvrkDartError(f"{path}: [sessions] offset_joints: unknown joint(s) {', '.join(map(str, unknown))} (known: {', '.join(JOINT_NAMES)})")
    return names

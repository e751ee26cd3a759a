"""An arm's model description (`models/psm/psm.toml`, `models/mtm/mtm.toml`) as typed objects.

Every link's joint variable (theta or d of its modified-DH transform) is a
linear function of the seven coordinates q1..q7 (model/model_file.py, the
single reader of the file, resolves its small linear expressions into
(coefficients, constant) pairs); `PsmModel` offers the forward kinematics of
the tree. The DART builder and the Pinocchio model are both built from it.
"""

from __future__ import annotations

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

#: the arm a command models when --arm-model is not given (a folder of models/)
DEFAULT_ARM = "psm"
DEFAULT_MODEL_FILE = MODELS_DIR / DEFAULT_ARM / f"{DEFAULT_ARM}.toml"



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
    #: the rate its filter's normalised cut-off was set at (2 pi fc / this rate), whatever a run's own
    filter_rate_hz: float


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
class SessionPayloadReading:
    """What the payload-shaped fit reads between two sessions of the arm without
    a weight ([sessions] payload_reading): J1's gravity effort at q = 0 (N·m) and
    its slope with q1 there (N·m/rad)."""

    q1_effort_at_q0: float
    q1_slope_at_q0: float


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
    session_constant_change: tuple[float, ...] | None = None  # how far each joint's constant moved between the repeat pair's sessions
    #: what the payload-shaped fit reads between the repeat pair's sessions ([sessions] payload_reading)
    session_payload_reading: SessionPayloadReading | None = None
    #: the controllers' and the counterweight PID's gains ([controllers]: name -> value)
    controller_gains: dict[str, object] = field(default_factory=dict)
    groups: tuple[str, ...] = ()
    joint_words: str = ""  # the coordinates in words (the card's joint_words)
    processing: UpstreamProcessing | None = None  # [processing]: required of a model file
    dvrk_topics: DvrkTopics | None = None
    project_unphysical_bodies: bool = False  # DART gets the nearest physical body of a non-physical identified one
    #: what the diagnosis simulates before adding effects ([diagnosis] base): the identified
    #: inertia only ("inertial"), or every identified term ("identified": effects then correct it)
    diagnosis_base: str = "inertial"
    #: the diagnosis's elastic candidates, (joint, kind) ([diagnosis] elastic), and its position-dependent friction's joints
    elastic_joints: tuple[tuple[str, str], ...] = ()
    position_friction_joints: tuple[str, ...] = ()
    #: the base frame at q = 0 in words ([diagnosis] frame_words), beside a payload's first moment; "" where the card has none
    frame_words: str = ""
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

    @cached_property
    def rotations_at_zero(self) -> dict[int, np.ndarray]:
        """R_i(q = 0): the frame in which params.json expresses r and I."""
        return {k: T[:3, :3] for k, T in self.forward_kinematics(np.zeros(N_JOINTS)).items()}

    @cached_property
    def motor_map(self) -> MotorCoordinateMap:
        """dVRK joint values <-> the model's coordinates (joints.py owns the map)."""
        return MotorCoordinateMap(self.dvrk_coupling_matrix, list(self.dvrk_coupling_columns))


@dataclass(frozen=True)
class ForcePoint:
    """The instrument point of a force estimate: the origin of `link`'s frame,
    positioned by `joints`; a direction whose lever arm (singular value of the
    positional Jacobian) is below `min_lever_m` is not determined."""

    link: int
    name: str
    joints: tuple[int, ...]
    min_lever_m: float

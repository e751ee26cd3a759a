"""Options of one simulation: step, counterweight variant and the physical
effects switched on in DART. Everything off by default, as in the paper: the
bodies carry the identified inertial parameters only."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np

#: the identified model's rigid-body terms, always simulated
from dvrk_dart.model.identified import INERTIAL_TERMS
from dvrk_dart.model.joints import N_JOINTS

COUNTERWEIGHT_VARIANTS = ("on", "off", "pid")
MODES = ("kinematic", "velocity", "torque")


@dataclass(frozen=True)
class Payload:
    """A point mass rigidly attached to a link (DART: a body welded to it)."""

    link: int  # key of the model link (models/psm/psm.toml)
    mass_kg: float
    position_m: tuple[float, float, float]  # in that link's frame


@dataclass(frozen=True)
class JointEffects:
    """Per-coordinate physical effects (7 values each, joint order of joints.py),
    added on top of the identified terms selected by the flags of SimConfig."""

    coulomb: tuple[float, ...] = (0.0,) * 7  # N·m or N, opposing the joint velocity
    viscous: tuple[float, ...] = (0.0,) * 7  # N·m s/rad or N s/m (DART joint damping)
    offset: tuple[float, ...] = (0.0,) * 7  # constant effort the actuator must supply
    stiffness: tuple[float, ...] = (0.0,) * 7  # N·m/rad (DART joint spring, rest at q = 0)
    armature: tuple[float, ...] = (0.0,) * 7  # kg m^2 (DART joint armature; >= 0)
    # velocity scale of a smooth Coulomb reversal (rad/s or m/s): 0 = sharp
    # (DART's Coulomb friction row); > 0 = coulomb * tanh(dq / scale), the
    # pre-sliding of a cable transmission, applied as a joint effort each step
    coulomb_reversal_velocity: tuple[float, ...] = (0.0,) * 7
    # pre-sliding distance of the Coulomb reversal (m or rad): > 0 = coulomb
    # times Dahl's state over the joint's position (model/friction.py), applied
    # as a joint effort each step; 0 = the reversal above
    coulomb_presliding: tuple[float, ...] = (0.0,) * 7
    # friction on a link variable that couples coordinates (the MTM's forearm,
    # qd3 = q3 - q2): (link key, Fc, Fv, pre-sliding distance) entries, applied
    # as joint efforts projected by the variable's coefficients each step
    link_friction: tuple[tuple[float, ...], ...] = ()
    # Coulomb friction piecewise linear along a coordinate, reversing over a
    # pre-sliding distance: (coordinate index, distance, knots..., Fc at the knots...)
    position_friction: tuple[tuple[float, ...], ...] = ()
    # an armature that takes the sign of the coordinate's velocity (kg or
    # kg m^2, either sign): effort value·sign(dq)·ddq, more or less inertia
    # while speeding up than while slowing down (J3's, diagnosis/beyond/insertion_terms.py)
    directional_armature: tuple[float, ...] = (0.0,) * 7
    # a link lighter or heavier than identified: (link key, error) entries, its
    # mass and inertia about its centre of mass times (1 + error), the centre of
    # mass where it is (every effort of the body scales with it)
    link_mass_scale: tuple[tuple[float, ...], ...] = ()
    # an effort on one coordinate set by another's angle: (target index,
    # source index, c_sin, c_cos) -> c_sin sin(q_source) + c_cos cos(q_source)
    angle_load: tuple[tuple[float, ...], ...] = ()
    # an effort on one coordinate, piecewise linear in a coordinate's position
    # and zero outside its knots (a load that changes along the range, not with
    # the direction of motion): (target index, source index, knots..., values...)
    position_load: tuple[tuple[float, ...], ...] = ()

    def plus(self, other: JointEffects) -> JointEffects:
        """Both sets of effects at once: per-coordinate values added, entries
        joined. A Coulomb reversal law (velocity scale, pre-sliding) is one per
        coordinate: where both carry a Coulomb level they must share it."""
        laws = ("coulomb_reversal_velocity", "coulomb_presliding")
        for name in laws:
            for mine, theirs, a, b in zip(getattr(self, name), getattr(other, name), self.coulomb, other.coulomb):
                if a and b and mine != theirs:
                    raise ValueError(f"JointEffects.plus: two Coulomb levels with different {name} ({mine} and {theirs}) on one coordinate")
        merged = {}
        for f in fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if f.name in laws:
                merged[f.name] = tuple(a if level else b for a, b, level in zip(mine, theirs, self.coulomb))
            elif f.default == ():  # entries (link and position frictions, angle and position loads)
                merged[f.name] = tuple(mine) + tuple(theirs)
            else:
                merged[f.name] = tuple(float(a + b) for a, b in zip(mine, theirs))
        return JointEffects(**merged)


@dataclass(frozen=True)
class SimConfig:
    dt_s: float = 1e-3
    counterweight: str = "on"  # on: ideal bilateral tendon; off: removed; pid: the paper's PID mirror
    # identified non-inertial terms as physics in DART (off, as in the paper)
    friction: bool = False  # Coulomb + viscous of the identified model
    offsets: bool = False  # constant friction offsets Fo
    spring: bool = False  # J4 torsion spring
    motor_inertia: bool = False  # armature (a negative identified Im is applied as a model-based effort)
    # further effects (diagnosis, synthetic injections)
    extra: JointEffects = field(default_factory=JointEffects)
    payloads: tuple[Payload, ...] = ()
    gravity_tilt_rad: tuple[float, float] = (0.0, 0.0)  # base mounting tilt about base x, then y
    counterweight_pid: tuple[float, float, float] | None = None  # Kp N/m, Ki N/(m s), Kd N s/m; None: the model card's
    closure_residual_limit_m: float = 1e-4  # beyond this the simulation is declared diverged

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict) -> "SimConfig":
        """The inverse of to_dict (JSON lists back to tuples and dataclasses); a
        value of the wrong type or length is a ValueError naming its key (a hand-written
        file's "friction": "false" switched friction on)."""
        if not isinstance(raw, dict):
            raise ValueError("sim_config: not an object")
        raw = dict(raw)
        unknown = set(raw) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"sim_config: unknown key {sorted(unknown)[0]!r}")
        for name in ("friction", "offsets", "spring", "motor_inertia"):
            if not isinstance(raw.get(name, False), bool):
                raise ValueError(f"sim_config.{name}: true or false, not {raw[name]!r}")
        if raw.get("counterweight", "on") not in COUNTERWEIGHT_VARIANTS:
            raise ValueError(f"sim_config.counterweight: one of {', '.join(COUNTERWEIGHT_VARIANTS)}, not {raw['counterweight']!r}")
        for name in ("dt_s", "closure_residual_limit_m"):
            if not _numbers(raw.get(name, 1.0), f"sim_config.{name}", None) > 0.0:
                raise ValueError(f"sim_config.{name}: above zero, not {raw[name]!r}")
        raw["extra"] = _joint_effects(raw.get("extra", {}))
        raw["payloads"] = tuple(_payload(p, i) for i, p in enumerate(_numbers_list(raw.get("payloads", []), "sim_config.payloads")))
        raw["gravity_tilt_rad"] = _numbers(raw.get("gravity_tilt_rad", cls.gravity_tilt_rad), "sim_config.gravity_tilt_rad", 2)
        pid = raw.get("counterweight_pid")
        raw["counterweight_pid"] = None if pid is None else _numbers(pid, "sim_config.counterweight_pid", 3)
        return cls(**raw)


def _numbers_list(value, key: str) -> list:
    if not isinstance(value, (list, tuple)):  # a JSON list, or to_dict's tuple
        raise ValueError(f"{key}: a list, not {value!r}")
    return value


def _numbers(value, key: str, length: int | None):
    """A number (length None) or a tuple of `length` numbers (any length: 0), checked."""
    values = value if length is not None else [value]
    if length is not None and (not isinstance(value, (list, tuple)) or (length and len(value) != length)):
        raise ValueError(f"{key}: a list of {length or 'some'} numbers, not {value!r}")
    if not all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and np.isfinite(v) for v in values):
        raise ValueError(f"{key}: not finite numbers ({value!r})")
    return tuple(float(v) for v in values) if length is not None else float(value)


def _joint_effects(raw) -> JointEffects:
    if not isinstance(raw, dict):
        raise ValueError(f"sim_config.extra: an object, not {raw!r}")
    kinds = {f.name: f.default for f in fields(JointEffects)}
    checked = {}
    for name, value in raw.items():
        if name not in kinds:
            raise ValueError(f"sim_config.extra: unknown key {name!r}")
        key = f"sim_config.extra.{name}"
        checked[name] = (tuple(check_entry(name, _numbers(entry, key, 0), key) for entry in _numbers_list(value, key)) if kinds[name] == ()
                         else _numbers(value, key, len(kinds[name])))
    return JointEffects(**checked)


#: JointEffects entries: (positions that are coordinate indices, positions that are link keys, their length; None:
#: two leading numbers and a piecewise-linear table: two or more knots, increasing, and as many values)
_ENTRY_LAYOUTS = {
    "link_friction": ((), (0,), 4),
    "position_friction": ((0,), (), None),
    "angle_load": ((0, 1), (), 4),
    "position_load": ((0, 1), (), None),
    "link_mass_scale": ((), (0,), 2),
}


def check_entry(name: str, entry: tuple[float, ...], key: str) -> tuple[float, ...]:
    """An entry of the JointEffects table `name`, its layout checked (`_ENTRY_LAYOUTS`); ValueError naming `key`."""
    coordinates, links, length = _ENTRY_LAYOUTS[name]
    if length is not None and len(entry) != length:
        raise ValueError(f"{key}: entries of {length} numbers, not {list(entry)}")
    if length is None:
        table = np.asarray(entry[2:], dtype=float)
        if len(table) < 4 or len(table) % 2 or not np.all(np.diff(table[:len(table) // 2]) > 0):
            raise ValueError(f"{key}: entries of two numbers, then two or more increasing knots and as many values, not {list(entry)}")
    for i in coordinates:
        if not (float(entry[i]).is_integer() and 0 <= entry[i] < N_JOINTS):
            raise ValueError(f"{key}: {list(entry)}: its number {i + 1} is a coordinate, 0..{N_JOINTS - 1} (0 is q1)")
    for i in links:
        if not (float(entry[i]).is_integer() and entry[i] >= 0):
            raise ValueError(f"{key}: {list(entry)}: its number {i + 1} is a link's key, a whole number")
    return entry


def _payload(raw, index: int) -> Payload:
    key = f"sim_config.payloads[{index}]"
    if not isinstance(raw, dict) or set(raw) != {"link", "mass_kg", "position_m"} or isinstance(raw["link"], bool) \
            or not isinstance(raw["link"], (int, np.integer)):
        raise ValueError(f"{key}: an object of link (an integer), mass_kg and position_m")
    mass = _numbers(raw["mass_kg"], f"{key}.mass_kg", None)
    if mass < 0.0:
        raise ValueError(f"{key}.mass_kg: a mass is not negative ({mass:g})")
    return Payload(int(raw["link"]), mass, _numbers(raw["position_m"], f"{key}.position_m", 3))


#: every identified term simulated as physics (the realistic arm, `--dynamics identified`)
IDENTIFIED_PHYSICS = SimConfig(friction=True, offsets=True, spring=True, motor_inertia=True)


def simulated_terms(config: SimConfig) -> tuple[str, ...]:
    """The identified-model terms a simulation with this config includes:
    what its efforts are compared with (sim vs model)."""
    flags = {"friction": config.friction, "offset": config.offsets, "spring": config.spring, "motor_inertia": config.motor_inertia}
    return INERTIAL_TERMS + tuple(term for term, on in flags.items() if on)


def position_load_table(entry: tuple[float, ...]) -> tuple[int, int, np.ndarray, np.ndarray]:
    """(target, source, knots, values) of a JointEffects.position_load entry."""
    target, source, table = int(entry[0]), int(entry[1]), np.asarray(entry[2:], dtype=float)
    half = len(table) // 2
    return target, source, table[:half], table[half:]


def position_load_effort(entry: tuple[float, ...], source_positions: np.ndarray) -> np.ndarray:
    """The entry's effort at these positions of its source coordinate: the table
    interpolated, zero outside the knots."""
    _, _, knots, values = position_load_table(entry)
    return np.interp(source_positions, knots, values, left=0.0, right=0.0)

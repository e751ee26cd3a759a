"""Options of one simulation: step, counterweight variant and the physical
effects switched on in DART. Everything off by default, as in the paper: the
bodies carry the identified inertial parameters only."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np

#: the identified model's rigid-body terms, always simulated
from dvrk_dart.model.identified import INERTIAL_TERMS

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
        """The inverse of to_dict (JSON lists back to tuples and dataclasses)."""
        raw = dict(raw)
        raw["extra"] = JointEffects(**{k: tuple(tuple(x) if isinstance(x, list) else x for x in v) for k, v in raw.get("extra", {}).items()})
        raw["payloads"] = tuple(Payload(p["link"], p["mass_kg"], tuple(p["position_m"])) for p in raw.get("payloads", []))
        raw["gravity_tilt_rad"] = tuple(raw.get("gravity_tilt_rad", cls.gravity_tilt_rad))
        pid = raw.get("counterweight_pid")
        raw["counterweight_pid"] = None if pid is None else tuple(pid)
        return cls(**raw)


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

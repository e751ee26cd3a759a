"""Where each identified non-inertial effect of a SimConfig acts in the DART
arm: on a DART joint where the mapping is exact, else as an explicit
model-based effort the simulator applies each step (`simulator.py`).

Identified non-inertial terms (SimConfig flags, JointEffects extras)
    - a spring through a linkage (the MTM's wrist pitch, nonlinear in its
      angle) is an explicit model-based effort like the terms below.
    - viscous friction, Coulomb friction and the J4 spring act on the DART
      joints whose own variable is the link's variable (yaw, pitch, carriage,
      tool roll, wrist pitch, jaws): the mapping is exact.  Coulomb friction is
      DART's joint friction (an LCP row bounded by Fc) in torque mode, where
      it sticks and slips; in velocity mode the motion is prescribed and the
      servo's efforts carry it (the simulator lifts the rows: on the
      near-massless jaws a row held a dof the servo had slide).  Viscous friction and
      the spring are NOT DART's joint damping/stiffness: DART applies those
      implicitly in its forward dynamics but its constraint impulses (the
      Coulomb rows) see the inertia without them, which on the near-massless
      tool dofs is off by orders of magnitude (measured: Coulomb + viscous on
      the tool roll gave a 0.5 N·m error, each alone was exact).  They are
      applied here the same implicit way (at the end-of-step velocity and
      position, acceleration solved with DART's closed-chain inertia plus
      dt·D + dt²·K), which is consistent with every constraint.  Against the
      model evaluated at the start-of-step state they differ by Fv·dt·ddq.
    - Coulomb friction that reverses over a pre-sliding distance (params.json
      "xs" > 0, model/friction.py) has no LCP row either: Fc times Dahl's
      state, which the simulator steps with each link's position.
    - a smooth Coulomb reversal (JointEffects.coulomb_reversal_velocity > 0:
      Fc tanh(dq / v_r), the pre-sliding of a cable transmission found by the
      diagnosis) has no LCP row: it is a joint effort computed each step from
      the simulated velocity, like the terms below.
    - friction of the motor-side pseudo links (14, 15, 16: no DART body),
      the offsets Fo and every JointEffects term on the motor coordinates q5..q7
      (not a DART joint variable) are explicit model-based efforts computed from
      the state at the start of each step and applied as joint forces mapped with
      A^-T (A: the actuated dofs as functions of q; W^T for the wrist).
    - motor inertia: DART 6.20 has no joint armature (no API), and the identified
      Im are partly negative.  Both are applied as the model-based effort
      -I_a·ddq, with ddq of the step solved implicitly from DART's closed-chain
      inertia (M_c + I_a) ddq = tau - b: exactly an armature (and the identified
      negative values too).
    - a directional armature (JointEffects.directional_armature: more or less
      inertia while speeding up than while slowing down, J3's) is the same
      armature with the sign of the step's velocity; an effort set by another
      coordinate's angle (JointEffects.angle_load) is an explicit effort.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.dh import Link
from dvrk_dart.model.identified import spring_torque
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters
from dvrk_dart.sim import kernels
from dvrk_dart.sim.builder import DartPsm
from dvrk_dart.sim.config import JointEffects, SimConfig, check_entry, position_load_table


@dataclass(frozen=True)
class PreslidingFriction:
    """Coulomb friction Fc on the rate of coeffs·q, reversing over a pre-sliding
    distance, and a viscous Fv on that rate (applied here where no DART joint
    carries it)."""

    coeffs: np.ndarray
    coulomb: float
    distance: float
    viscous: float = 0.0
    #: Fc piecewise linear in coeffs·q: at these positions, these values (empty: `coulomb` throughout)
    knots: tuple[float, ...] = ()
    coulomb_at_knots: tuple[float, ...] = ()


@dataclass(frozen=True)
class ExplicitEffects:
    """Per-coordinate explicit terms (q coordinates, 7 each), and the motor-side
    links whose friction acts on their variable's rate."""

    coulomb: np.ndarray
    viscous: np.ndarray
    stiffness: np.ndarray
    offset: np.ndarray
    armature: np.ndarray
    smooth_coulomb: np.ndarray  # Fc of the joints with a smooth reversal
    reversal_velocity: np.ndarray  # their velocity scale (1 where unused)
    friction_links: tuple[Link, ...]
    params: IdentifiedParameters
    #: springs acting through a linkage (the MTM's wrist pitch): nonlinear, explicit
    linkage_springs: tuple[Link, ...] = ()
    #: Coulomb frictions that reverse over a pre-sliding distance (Fc times their Dahl state)
    presliding: tuple[PreslidingFriction, ...] = ()
    #: per coordinate, the armature that takes the sign of its velocity (JointEffects.directional_armature)
    directional_armature: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    #: (target, source, c_sin, c_cos) efforts set by another coordinate's angle
    angle_loads: tuple[tuple[float, ...], ...] = ()
    #: efforts piecewise linear in a coordinate's position: (target, source, knots, values) of JointEffects.position_load
    position_loads: tuple[tuple[int, int, np.ndarray, np.ndarray], ...] = ()

    def armature_at(self, dq: np.ndarray) -> np.ndarray:
        """The armature of the step (the directional part takes the velocity's sign)."""
        return self.armature + self.directional_armature * np.sign(dq)

    @property
    def any_effort(self) -> bool:
        """Whether `effort` can be non-zero (the armature is applied apart)."""
        return bool(
            np.any(self.coulomb) or np.any(self.viscous) or np.any(self.stiffness) or np.any(self.offset)
            or np.any(self.smooth_coulomb) or self.friction_links or self.linkage_springs or self.presliding or self.angle_loads
            or self.position_loads
        )

    def effort(self, q: np.ndarray, dq: np.ndarray, presliding: np.ndarray) -> np.ndarray:
        """Model-based efforts the actuators must supply beyond DART's physics (q
        space); `presliding`: the Dahl state of each of `self.presliding`."""
        effort = kernels.explicit_effort(q, dq, presliding, *self.tables)
        for link in self.linkage_springs:
            x = float(q @ link.variable.coeffs)
            effort = effort + float(spring_torque(self.params[link.key].spring, x, link.spring_linkage)) * link.variable.coeffs
        return effort

    @cached_property
    def tables(self) -> tuple[np.ndarray, ...]:
        """The terms as the arrays of `kernels.explicit_effort` (its docstring has their layout)."""
        per_joint = np.array([self.offset, self.viscous, self.coulomb, self.stiffness, self.smooth_coulomb, self.reversal_velocity], dtype=float)
        links = [[*link.variable.coeffs, *self._sharp_friction(link)] for link in self.friction_links]
        presliding = [[*f.coeffs, f.coulomb, f.viscous] for f in self.presliding]
        presliding_tables = [(f.knots, f.coulomb_at_knots) for f in self.presliding]
        angle_loads = [list(entry) for entry in self.angle_loads]
        loads = [[target, source] for target, source, _, _ in self.position_loads]
        load_tables = [(knots, values) for _, _, knots, values in self.position_loads]
        return (per_joint, _rows(links, N_JOINTS + 2), _rows(presliding, N_JOINTS + 2), _tables(presliding_tables),
                _rows(angle_loads, 4), _rows(loads, 2), _tables(load_tables))

    def _sharp_friction(self, link: Link) -> tuple[float, float]:
        """(Coulomb, viscous) of a motor-side link's friction: a pre-sliding Coulomb is in `presliding`."""
        p = self.params[link.key]
        return (0.0 if p.presliding > 0.0 else p.coulomb), p.viscous

    @cached_property
    def presliding_coefficients(self) -> np.ndarray:
        """(n, 7): the position each pre-sliding friction's Dahl state follows, as coefficients of q."""
        return _rows([f.coeffs for f in self.presliding], N_JOINTS)

    @cached_property
    def presliding_distances(self) -> np.ndarray:
        return np.array([f.distance for f in self.presliding], dtype=float)


def _rows(rows: list, width: int) -> np.ndarray:
    """A (n, width) float array, (0, width) for none."""
    return np.array(rows, dtype=float).reshape(len(rows), width)


def _tables(tables: list[tuple]) -> np.ndarray:
    """Piecewise-linear tables (knots, values) as rows (count, knots..., values...), padded with zeros."""
    width = 1 + 2 * max((len(knots) for knots, _ in tables), default=0)
    out = np.zeros((len(tables), width))
    for row, (knots, values) in zip(out, tables):
        row[0] = len(knots)
        row[1:1 + 2 * len(knots)] = [*knots, *values]
    return out


@dataclass(frozen=True)
class EffectsPlacement:
    """The effects of one SimConfig, placed: per DART dof (implicit damping and
    stiffness applied by the simulator, Coulomb rows set on DART's joints) and
    the explicit rest."""

    damping: np.ndarray  # per dof, N·m s/rad or N s/m, applied implicitly
    stiffness: np.ndarray  # per dof, rest at 0, applied implicitly
    coulomb: np.ndarray  # per dof: DART's joint Coulomb friction (set by place_effects)
    explicit: ExplicitEffects


@dataclass
class _Placing:
    """What place_effects accumulates: per DART dof, then per coordinate q1..q7."""

    damping: np.ndarray
    stiffness_x: np.ndarray
    coulomb_x: np.ndarray
    coulomb_dofs: list[int] = field(default_factory=list)  # the dofs whose DART Coulomb row is set
    coulomb: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    viscous: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    armature: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    friction_links: list[Link] = field(default_factory=list)  # motor-side links: explicit, on their variable's rate
    presliding: list[PreslidingFriction] = field(default_factory=list)  # Coulomb over a pre-sliding distance: explicit, with its state
    linkage_springs: list[Link] = field(default_factory=list)  # nonlinear springs: explicit, at the start-of-step position

    def set_coulomb(self, dof: int, value: float) -> None:
        self.coulomb_x[dof] = value
        self.coulomb_dofs.append(dof)


def place_effects(model: PsmModel, params: IdentifiedParameters, config: SimConfig, psm: DartPsm) -> EffectsPlacement:
    """Put the selected physical effects on DART joints where the mapping is
    exact (Coulomb friction is set on `psm`'s skeleton here); return the rest
    as explicit per-coordinate terms."""
    n = psm.n_dofs
    acc = _Placing(np.zeros(n), np.zeros(n), np.zeros(n))
    _place_identified(acc, model, params, config, psm)
    extra = config.extra
    extra_arm = np.asarray(extra.armature, dtype=float)
    if np.any(extra_arm < 0.0):
        raise DvrkDartError("SimConfig.extra.armature must be >= 0 (a physical armature)")
    acc.armature += extra_arm
    acc.offset += np.asarray(extra.offset, dtype=float)
    reversal = np.asarray(extra.coulomb_reversal_velocity, dtype=float)
    if np.any(reversal < 0.0):
        raise DvrkDartError("SimConfig.extra.coulomb_reversal_velocity must be >= 0")
    smooth = reversal > 0.0
    distances = np.asarray(extra.coulomb_presliding, dtype=float)
    if np.any(distances < 0.0) or np.any(distances[smooth] > 0.0):
        raise DvrkDartError("SimConfig.extra.coulomb_presliding must be >= 0, and 0 where a tanh reversal is set")
    _place_extra_presliding(acc, model, extra, distances)
    _place_extra_joint_terms(acc, extra, psm, sharp=~smooth & (distances <= 0.0))
    for dof in dict.fromkeys(acc.coulomb_dofs):
        psm.skeleton.getDof(dof).setCoulombFriction(acc.coulomb_x[dof])
    explicit = ExplicitEffects(
        acc.coulomb, acc.viscous, acc.stiffness, acc.offset, acc.armature,
        np.where(smooth, np.asarray(extra.coulomb, dtype=float), 0.0), np.where(smooth, reversal, 1.0),
        tuple(acc.friction_links), params, tuple(acc.linkage_springs), tuple(acc.presliding),
        np.asarray(extra.directional_armature, dtype=float),
        tuple(tuple(float(v) for v in entry) for entry in extra.angle_load),
        tuple(_checked_position_loads(extra.position_load)),
    )
    return EffectsPlacement(acc.damping, acc.stiffness_x, acc.coulomb_x, explicit)


def _place_identified(acc: _Placing, model: PsmModel, params: IdentifiedParameters, config: SimConfig, psm: DartPsm) -> None:
    """The identified parameters' friction, offsets, springs and motor inertia, per link."""
    dof_of = {key: i for i, key in enumerate(psm.dof_links)}
    actuated = set(psm.actuated_dofs)
    for link in model.links.values():
        p = params[link.key]
        dof = dof_of.get(link.key)
        on_own_dof = dof is not None and dof in actuated
        if config.friction and link.friction and (p.coulomb or p.viscous):
            if p.presliding > 0.0 and p.coulomb:
                acc.presliding.append(PreslidingFriction(link.variable.coeffs, p.coulomb, p.presliding))
            if on_own_dof:
                # not DART's joint damping: see the module docstring (implicit, applied by the simulator)
                acc.damping[dof] = p.viscous
                if p.presliding <= 0.0:
                    acc.set_coulomb(dof, p.coulomb)
            else:
                acc.friction_links.append(link)
        if config.offsets and link.friction and p.offset:
            acc.offset += p.offset * link.variable.coeffs
        if config.spring and link.spring and p.spring and link.spring_linkage is not None:
            acc.linkage_springs.append(link)
        elif config.spring and link.spring and p.spring:
            if not on_own_dof:
                raise DvrkDartError(f"link {link.key}: a spring on a variable without its own joint is not supported")
            # not DART's joint spring: see the module docstring (implicit, rest at 0)
            acc.stiffness_x[dof] = p.spring
        if config.motor_inertia and link.motor_inertia and p.motor_inertia:
            j = int(np.flatnonzero(link.variable.coeffs)[0])
            acc.armature[j] += p.motor_inertia * link.variable.coeffs[j]


def _place_extra_presliding(acc: _Placing, model: PsmModel, extra: JointEffects, distances: np.ndarray) -> None:
    """The extras' Coulomb frictions over a pre-sliding distance (per coordinate,
    per link, piecewise linear in a position): explicit, each with its Dahl state."""
    for j in np.flatnonzero(distances > 0.0):
        acc.presliding.append(PreslidingFriction(np.eye(N_JOINTS)[j], float(extra.coulomb[j]), float(distances[j])))
    for key, fc, fv, distance in extra.link_friction:
        if int(key) not in model.links or not distance >= 0.0:
            raise DvrkDartError(f"SimConfig.extra.link_friction: link {key} of {model.source.name} with a pre-sliding distance >= 0 expected")
        acc.presliding.append(PreslidingFriction(model.links[int(key)].variable.coeffs, float(fc), float(distance), float(fv)))
    for entry in extra.position_friction:
        j, distance, values = int(entry[0]), float(entry[1]), entry[2:]
        half = len(values) // 2
        acc.presliding.append(PreslidingFriction(np.eye(N_JOINTS)[j], 0.0, distance, 0.0, tuple(values[:half]), tuple(values[half:])))


def _place_extra_joint_terms(acc: _Placing, extra: JointEffects, psm: DartPsm, sharp: np.ndarray) -> None:
    """The extras' viscous, sharp Coulomb (`sharp`: joints without a smooth or
    pre-sliding reversal, which have no LCP row) and stiffness: DART joint
    physics on q1..q4 (the actuated dof is the coordinate), explicit on the
    motor coordinates q5..q7."""
    for j in range(N_JOINTS):
        dof = psm.actuated_dofs[j]
        direct = np.count_nonzero(psm.A[j]) == 1 and psm.A[j, j] == 1.0
        sharp_coulomb = extra.coulomb[j] if sharp[j] else 0.0
        if direct:
            acc.damping[dof] = acc.damping[dof] + extra.viscous[j]
            acc.set_coulomb(dof, acc.coulomb_x[dof] + sharp_coulomb)
            acc.stiffness_x[dof] = acc.stiffness_x[dof] + extra.stiffness[j]
        else:
            acc.coulomb[j] += sharp_coulomb
            acc.viscous[j] += extra.viscous[j]
            acc.stiffness[j] += extra.stiffness[j]


def _checked_position_loads(entries) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """JointEffects.position_load entries as (target, source, knots, values), their layout checked (sim/config.py)."""
    out = []
    for entry in entries:
        try:
            check_entry("position_load", tuple(entry), "SimConfig.extra.position_load")
        except ValueError as exc:
            raise DvrkDartError(str(exc)) from None
        out.append(position_load_table(entry))
    return out

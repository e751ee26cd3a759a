"""The library of candidate effects, and the effects as simulator physics (SimConfig)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin

from dvrk_dart.diagnosis.effects.arm_effects import (
    CounterweightTransmission,
    GravityTilt,
    LinkMassScale,
    TimeShift,
    prismatic_bodies,
)
from dvrk_dart.diagnosis.effects.effect import Effect
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.first_moment import FirstMomentPayload
from dvrk_dart.diagnosis.effects.geometry import ENVELOPE_MARGIN_M, link_envelope
from dvrk_dart.diagnosis.effects.joint_effects import (
    AngleLoad,
    REVERSAL_VELOCITIES,
    JointArmature,
    JointFriction,
    JointOffset,
    JointStiffness,
    LinkFriction,
    PreslidingOfIdentifiedFriction,
    coupling_friction_links,
    presliding_distances,
)
from dvrk_dart.diagnosis.effects.position_friction import PositionFriction
from dvrk_dart.diagnosis.effects.payload import (
    PointPayload,
    equivalent_payload_links,
    mass_seen_by_gravity,
    payload_links,
    point_mass_parameters,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model import friction
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.body_regressor import tree_joint
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES, N_JOINTS, PITCH
from dvrk_dart.sim.config import SimConfig, position_load_effort, position_load_table, simulated_terms

#: the payload models of `candidate_effects`
PAYLOAD_MODELS = ("point", "first_moment")


def candidate_effects(
    arm: Arm, stribeck: bool = False, payload_margin_m: float = ENVELOPE_MARGIN_M, reversal_velocities: tuple[float, ...] = REVERSAL_VELOCITIES,
    payload_model: str = "point", base: SimConfig = SimConfig(),
) -> list[Effect]:
    """The library of candidate effects, in a fixed order; a `base` that
    simulates the identified friction adds its pre-sliding variants.

    payload_model: "point" (a point mass inside the link's envelope, simulated
    as a body) or "first_moment" (what the efforts determine, `first_moment`)."""
    if payload_model not in PAYLOAD_MODELS:
        raise DvrkDartError(f"payload model '{payload_model}': expected one of {', '.join(PAYLOAD_MODELS)}")
    effects: list[Effect] = []
    effects += [JointFriction(arm.model, j) for j in JOINT_NAMES]
    effects += [JointFriction(arm.model, j, reversal_velocity=v) for j in JOINT_NAMES for v in reversal_velocities]
    effects += [JointFriction(arm.model, j, presliding=d) for j in JOINT_NAMES for d in presliding_distances(arm.model, j)]
    effects += [PositionFriction(arm.model, j, d) for j in arm.model.position_friction_joints for d in presliding_distances(arm.model, j)]
    effects += [LinkFriction(arm.model, key, d) for key in coupling_friction_links(arm.model)
                for d in presliding_distances(arm.model, link=arm.model.links[key])]
    if base.friction:
        effects += [PreslidingOfIdentifiedFriction(arm.model, arm.params, link.key, d) for link in arm.model.links.values()
                    if link.friction and arm.params[link.key].coulomb > 0.0 and arm.params[link.key].presliding == 0.0
                    for d in presliding_distances(arm.model, link=link)]
    if stribeck:
        effects += [JointFriction(arm.model, j, stribeck=True) for j in JOINT_NAMES]
    effects += [JointOffset(arm.model, j) for j in JOINT_NAMES]
    effects += [JointStiffness(arm.model, j, kind) for j, kind in arm.model.elastic_joints]
    effects += [JointArmature(arm.model, j) for j in JOINT_NAMES]
    if JOINT_NAMES[INSERTION] in arm.model.prismatic_coordinates:  # a load on the insertion set by the pitch (the PSM's; the MTM has no insertion)
        effects.append(AngleLoad(arm.model, JOINT_NAMES[INSERTION], JOINT_NAMES[PITCH]))
    equivalents = equivalent_payload_links(arm)
    # where a mass on the link may sit: its skeleton and its identified centre of mass (the carriage's is 10 cm below its
    # frame, outside the skeleton's box: a change of the carriage's own mass was put on the pitch links)
    envelopes = {k: link_envelope(arm.model, k, payload_margin_m, [arm.params[k].com]) for k in payload_links(arm.model)}
    if payload_model == "point":
        effects += [PointPayload(arm.model, k, envelopes[k], equivalent_keys=equivalents[k]) for k in payload_links(arm.model)]
    else:
        effects += [FirstMomentPayload(arm.model, k, envelopes[k], equivalent_keys=equivalents[k],
                                       mass_seen=mass_seen_by_gravity(arm, k)) for k in payload_links(arm.model)]
    effects += [GravityTilt(arm), TimeShift()]
    if arm.model.counterweight_link is not None:  # an arm with a counterweight tendon (the PSM's)
        effects.append(CounterweightTransmission(arm))
    effects += [LinkMassScale(arm, key) for key in prismatic_bodies(arm)  # the counterweight's reaches J3 by the ideal tendon
                if key != arm.model.counterweight_link or base.counterweight == "on"]
    return effects


# ----------------------------------------------------------- to the simulator
def effects_to_sim_config(selected: list[tuple[Effect, np.ndarray]], base: SimConfig = SimConfig()) -> SimConfig:
    """SimConfig with the effects added as physics on top of `base`.

    Effects the simulation has no field for are skipped: `not_simulated` lists
    them (the caller adds their regressor effort)."""
    extra = base.extra
    fields = {
        name: np.array(getattr(extra, name), dtype=float)
        for name in ("coulomb", "viscous", "offset", "stiffness", "armature", "coulomb_reversal_velocity", "coulomb_presliding")
    }
    payloads = list(base.payloads)
    entries = {name: list(getattr(extra, name)) for name in ("link_friction", "position_friction", "angle_load", "link_mass_scale")}
    tilt = np.array(base.gravity_tilt_rad, dtype=float)
    for effect, p in selected:
        contribution = effect.sim_contribution(np.asarray(p, dtype=float))
        if contribution is None:
            continue
        for name in fields:
            fields[name] += getattr(contribution, name)
        payloads += list(contribution.payloads)
        for name, values in entries.items():
            values += list(getattr(contribution, name))
        tilt += contribution.gravity_tilt_rad
    new_extra = replace(extra, **{name: tuple(float(v) for v in values) for name, values in fields.items()},
                        **{name: tuple(values) for name, values in entries.items()})
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
    for j, distance in enumerate(x.coulomb_presliding):
        if distance > 0.0:
            reversal_law[:, j] = friction.reversal(features.q[:, j], features.dq[:, j], distance)
    total = total + np.asarray(x.coulomb) * reversal_law + np.asarray(x.viscous) * features.dq
    total = total + np.asarray(x.offset) + np.asarray(x.stiffness) * features.q + np.asarray(x.armature) * features.ddq
    for key, fc, fv, distance in x.link_friction:
        coeffs = arm.model.links[int(key)].variable.coeffs
        rate = features.dq @ coeffs
        total = total + np.outer(fc * friction.reversal(features.q @ coeffs, rate, distance) + fv * rate, coeffs)
    total = total + np.asarray(x.directional_armature) * np.sign(features.dq) * features.ddq
    for target, source, c_sin, c_cos in x.angle_load:
        total[:, int(target)] += c_sin * np.sin(features.q[:, int(source)]) + c_cos * np.cos(features.q[:, int(source)])
    for entry in x.position_load:
        target, source, _, _ = position_load_table(entry)
        total[:, target] += position_load_effort(entry, features.q[:, source])
    for entry in x.position_friction:
        j, distance, values = int(entry[0]), entry[1], entry[2:]
        half = len(values) // 2
        coulomb = np.interp(features.q[:, j], values[:half], values[half:])
        total[:, j] += coulomb * friction.reversal(features.q[:, j], features.dq[:, j], distance)
    for key, error in x.link_mass_scale:  # the body's efforts scale with it
        total = total + error * features.body_effort(int(key))
        if np.any(tilt != 0.0):
            total = total + _body_gravity_correction(arm, features, int(key), error * features.identified_body_parameters(int(key)), tilt)
    for payload in config.payloads:
        params = point_mass_parameters(payload.mass_kg, np.asarray(payload.position_m))
        total = total + features.body_regressor[:, :, features.body_columns(payload.link)] @ params
        if np.any(tilt != 0.0):  # the body regressor carries the nominal gravity
            total = total + _body_gravity_correction(arm, features, payload.link, params, tilt)
    return total


def _gravity_in_base(model: PsmModel, tilt: np.ndarray) -> np.ndarray:
    """Gravity in the base frame of a tilted base: the simulator's own definition."""
    from dvrk_dart.sim.builder import (
        gravity_in_base,  # imports dartpy: only when a tilt is simulated
    )

    return np.asarray(gravity_in_base(model, (float(tilt[0]), float(tilt[1]))), dtype=float)


def _body_gravity_correction(arm: Arm, features: TrajectoryFeatures, key: int, parameters: np.ndarray, tilt: np.ndarray) -> np.ndarray:
    """Gravity efforts of a body on link `key` (its 10 dynamic parameters) under tilted minus nominal gravity (N, 7)."""
    im = arm.identified
    model = pin.Model(im.pin_model)
    j = tree_joint(im, key)
    for i in range(1, model.njoints):
        model.inertias[i] = pin.Inertia.Zero()
    model.inertias[j] = pin.Inertia.FromDynamicParameters(np.asarray(parameters, dtype=float))
    data = model.createData()
    qt = im.tree_q(features.q)
    delta_g = _gravity_in_base(arm.model, tilt) - arm.model.gravity
    model.gravity = pin.Motion(np.r_[delta_g, np.zeros(3)])
    return np.array([im.G.T @ pin.computeGeneralizedGravity(model, data, qk) for qk in qt])

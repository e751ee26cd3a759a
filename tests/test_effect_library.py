"""The effect library's regressors and their mapping to simulator physics:
each effect's efforts by regressor equal what its SimConfig makes (evaluated
by formula, Pinocchio bodies for payloads), on a real measured state."""

from dataclasses import replace

import numpy as np
import pytest

from dvrk_dart.diagnosis.effects.arm_effects import EffortScale, GravityTilt, gravity_tilt_directions
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.joint_effects import AngleLoad, JointArmature, JointFriction, JointOffset, JointStiffness
from dvrk_dart.diagnosis.effects.position_friction import PositionFriction
from dvrk_dart.diagnosis.output.effect_words import size_words
from dvrk_dart.diagnosis.effects.library import candidate_effects, config_effort_by_formula, effects_to_sim_config
from dvrk_dart.diagnosis.effects.payload import PointPayload
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import process
from dvrk_dart.sim.config import JointEffects, SimConfig
from arms import PSM


@pytest.fixture(scope="module")
def segment():
    """A real measured state: the start of trajectory 'one'."""
    return process(load_run(resolve_run("one"), PSM)).head(200)


def test_payload_regressor_matches_pinocchio_body(arm, segment):
    """A point mass through the regressor equals the same mass as a Pinocchio body
    (config_effort_by_formula builds it independently from SimConfig)."""
    state = segment.head(200)
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz())
    payload = PointPayload(arm.model, 8)
    p = np.array([0.3, 0.02, -0.03, 0.25])
    by_regressor = ref + payload.effort(features, p)
    by_formula = config_effort_by_formula(arm, effects_to_sim_config([(payload, p)]), state.q, state.dq, state.ddq)
    assert np.max(np.abs(by_regressor - by_formula)) < 1e-10
    # and the body regressor reproduces the identified inertial efforts
    im = arm.identified
    pi = np.concatenate([im.pin_model.inertias[j].toDynamicParameters() for j in range(1, im.pin_model.njoints)])
    assert np.max(np.abs(features.body_regressor @ pi - ref)) < 1e-9


def test_tilt_regressor_is_the_derivative_of_the_simulators_gravity(arm, segment):
    """The linearised tilt regressor agrees with the exact tilted gravity of the
    simulator's convention to second order (error shrinks 100x for 10x smaller tilt)."""
    state = segment.head(100)
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz())
    tilt = GravityTilt(arm)
    errors = []
    for scale in (1.0, 0.1):
        angles = scale * np.array([0.02, -0.015])
        exact = config_effort_by_formula(arm, effects_to_sim_config([(tilt, angles)]), state.q, state.dq, state.ddq)
        errors.append(np.max(np.abs(exact - ref - tilt.effort(features, angles))))
    assert errors[1] < errors[0] / 50
    assert np.allclose(gravity_tilt_directions(np.array([0, 0, -9.81]))[:, 0], [0, -9.81, 0])


def test_envelopes_contain_the_dh_skeleton(arm):
    for effect in candidate_effects(arm):
        if isinstance(effect, PointPayload):
            env = effect.envelope
            assert all(env.contains(p) for p in env.skeleton_points)
            assert np.all(env.upper - env.lower > 0.05), effect.name
            # and the link's identified centre of mass: a change of the carriage's own mass (its centre 10 cm below its
            # frame, outside the skeleton's box) was put on the tool roll (0.172 kg for +0.15 kg on the carriage)
            assert env.contains(arm.params[effect.link_key].com), effect.name


def test_effects_to_sim_config_maps_each_field(arm):
    chosen = [
        (JointFriction(arm.model, "q2"), np.array([0.1, 0.2])),
        (JointOffset(arm.model, "q3"), np.array([-0.3])),
        (JointStiffness(arm.model, "q4", "torsion_spring"), np.array([0.002])),
        (JointArmature(arm.model, "q1"), np.array([0.01])),
        (GravityTilt(arm), np.array([0.01, -0.02])),
        (PointPayload(arm.model, 4), np.array([0.105, 0.2, 0.0, 0.01])),
    ]
    cfg = effects_to_sim_config(chosen)
    assert cfg.extra.coulomb[1] == 0.1 and cfg.extra.viscous[1] == 0.2
    assert cfg.extra.offset[2] == -0.3 and cfg.extra.stiffness[3] == 0.002 and cfg.extra.armature[0] == 0.01
    assert cfg.gravity_tilt_rad == (0.01, -0.02)
    assert cfg.payloads[0].link == 4 and cfg.payloads[0].mass_kg == 0.105


def test_the_pitch_angle_load_is_simulated_as_its_regressor_says(arm, segment):
    """A load on J3 set by q2 (the library's angle_load_q3_by_q2) maps to the
    simulator's explicit effort, on top of what the base already carries."""
    state = segment.head(200)
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz())
    load, p = AngleLoad(arm.model, "q3", "q2"), np.array([0.1, 0.2])
    base = SimConfig(extra=JointEffects(directional_armature=(0.0, 0.0, 0.05, 0.0, 0.0, 0.0, 0.0)))
    config = effects_to_sim_config([(load, p)], base)
    assert config.extra.directional_armature == base.extra.directional_armature
    added = config_effort_by_formula(arm, config, state.q, state.dq, state.ddq) - config_effort_by_formula(arm, base, state.q, state.dq, state.ddq)
    assert np.max(np.abs(added - load.effort(features, p))) < 1e-12
    assert np.max(np.abs(added[:, 2] - (0.1 * np.sin(state.q[:, 1]) + 0.2 * np.cos(state.q[:, 1])))) < 1e-12
    assert load.name in {e.name for e in candidate_effects(arm)}


def test_a_payload_on_the_yaw_link_has_its_inertia_in_j1(arm, segment):
    """J1 sees a payload through its own path (m, m c); the path's inertia about
    the yaw axis is tied to it as a point mass's: 0.2 kg on the yaw link gives
    J1 the point mass's whole effort (its only joint), the coefficients'
    Jacobian matches finite differences."""
    from dvrk_dart.diagnosis.effects.first_moment import FirstMomentPayload
    from dvrk_dart.diagnosis.effects.payload import point_mass_parameters

    state = segment.head(200)
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz())
    effect, mass, position = FirstMomentPayload(arm.model, 1), 0.2, np.array([0.10, 0.05, 0.0])
    p = np.r_[mass, mass * position, mass, mass * position]
    effort = effect.columns(features) @ effect.coefficients(p)
    body = features.body_regressor[:, :, features.body_columns(1)] @ point_mass_parameters(mass, position)
    inertia = mass * position @ position * np.abs(state.ddq[:, 0]).max()
    assert inertia > 1e-3  # what the path would miss without its second moment (N·m)
    np.testing.assert_allclose(effort[:, 0], body[:, 0], atol=1e-9)
    step = 1e-7 * np.eye(len(p))
    numeric = np.stack([(effect.coefficients(p + d) - effect.coefficients(p - d)) / 2e-7 for d in step], axis=1)
    np.testing.assert_allclose(effect.coefficients_jacobian(p), numeric, atol=1e-6)


def test_a_lighter_carriage_is_simulated_as_its_regressor_says(arm, segment):
    """A link's own mass scaled (the candidates: the bodies only prismatic coordinates move) is the DART body's
    inertia scaled: the velocity replay's efforts change by the error times the body's own efforts."""
    from dvrk_dart.diagnosis.effects.arm_effects import LinkMassScale, prismatic_bodies
    from dvrk_dart.io.arm import load_arm
    from dvrk_dart.model.description import resolve_arm_model
    from dvrk_dart.runs.replay import simulate_efforts

    assert [arm.model.links[k].name for k in prismatic_bodies(arm)] == ["insertion_carriage", "counterweight"]
    assert prismatic_bodies(load_arm(resolve_arm_model("mtm"))) == []  # no prismatic joint
    state = segment.head(200)
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, np.zeros_like(state.q), sample_rate_hz())
    effect = LinkMassScale(arm, 8)
    config = effects_to_sim_config([(effect, np.array([-0.3]))])
    assert config.extra.link_mass_scale == ((8.0, -0.3),)
    change = simulate_efforts(arm, config, state) - simulate_efforts(arm, SimConfig(), state)
    expected = -0.3 * effect.columns(features)[:, :, 0]
    assert np.abs(expected[:, 2]).max() > 0.5  # N on J3: the carriage's gravity and inertia
    np.testing.assert_allclose(change, expected, atol=2e-3)
    tilted = SimConfig(gravity_tilt_rad=(0.05, 0.03))  # the formula's stand-in for DART tilts the scaled body's gravity too
    config = replace(tilted, extra=config.extra)
    by_formula = config_effort_by_formula(arm, config, state.q, state.dq, state.ddq) - config_effort_by_formula(arm, tilted, state.q, state.dq, state.ddq)
    np.testing.assert_allclose(simulate_efforts(arm, config, state) - simulate_efforts(arm, tilted, state), by_formula, atol=2e-3)
    from dvrk_dart.errors import DvrkDartError

    for wrong, counterweight in [(((8.0, -1.0),), "on"), (((99.0, 0.1),), "on"), (((8.0,),), "on"), (((9.0, 0.1),), "off")]:
        with pytest.raises(DvrkDartError, match="link_mass_scale"):  # no mass left; not a link; no error; no counterweight
            simulate_efforts(arm, SimConfig(counterweight=counterweight, extra=JointEffects(link_mass_scale=wrong)), state)
    assert "mass_scale_counterweight" not in {e.name for e in candidate_effects(arm, base=SimConfig(counterweight="pid"))}


def test_a_friction_table_says_what_the_runs_do_not_reach():
    """A blind round's Fc = 0.1 + 0.5 q3 on "one" (q3 0.092..0.235 m): the knot at 0 m, whose hat no sample reaches, read
    coulomb_at_0 = 0.0 beside a true 0.1, and the answer quoted the largest knot alone ("Coulomb 0.209 N")."""
    effect = PositionFriction(PSM, "q3", 3e-5).within(0.0924, 0.235)
    entry = {"kind": "friction", "size": 0.2089, "units": {"coulomb_at_0": "N", "viscous": "N/(m/s)"},
             "parameters": effect.describe([0.0, 0.1338, 0.1847, 0.2089, 0.0038])}
    assert list(entry["parameters"]["not_determined"]) == ["coulomb_at_0"]
    assert entry["parameters"]["coulomb_within_runs"] == pytest.approx([0.1417, 0.2074], abs=1e-4)  # the truth: 0.146..0.218
    assert size_words(entry).startswith(", Coulomb 0.142 to 0.207 N along the runs' range")
    assert "not_determined" not in PositionFriction(PSM, "q3", 3e-5).describe([0.1] * 5)  # no training span given: nothing said


def test_an_effort_scale_reads_the_scale_of_the_measured_efforts(arm, segment):
    """Efforts measured times 1 + s: the effect on the exerted effort removes the gap exactly at the size s, in the
    words with its sign."""
    state = segment.head(100)
    simulated = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    measured = simulated * 1.08
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, simulated, sample_rate_hz(), exerted_effort=simulated)
    scale = EffortScale()
    column = scale.columns(features)[:, :, 0]
    share = np.sum(column * (measured - simulated)) / np.sum(column * column)
    assert np.max(np.abs(measured - simulated - scale.effort(features, np.array([share])))) < 1e-12
    assert scale.size(np.array([share])) == pytest.approx(0.08, rel=1e-9)
    assert size_words({"kind": "effort_scale", "size": -0.05, "units": {"scale_error": "1"}}) == ", 5.0% low"

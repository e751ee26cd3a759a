"""The gap diagnosis: blind recovery of injected effects,
the withheld 105 g payload, the regime tables and the diagnosis.json contract
(a payload from several runs against a baseline: test_payload_weights.py).

Synthetic runs: the identified inertial model at a real measured state (two
base periods of trajectory 'one'), plus the injected effect put in as
SimConfig physics (effects_to_sim_config, evaluated by formula), plus coloured
noise at the level of the real residual of the full identified model."""

import json

import numpy as np
import pytest

from dvrk_dart.diagnosis.effects.arm_effects import GravityTilt
from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.joint_effects import (
    JointArmature,
    JointFriction,
    JointOffset,
    JointStiffness,
)
from dvrk_dart.diagnosis.effects.library import (
    config_effort_by_formula,
    effects_to_sim_config,
)
from dvrk_dart.diagnosis.effects.payload import (
    PointPayload,
    equivalent_payload_links,
)
from dvrk_dart.diagnosis.output.answer import answer_paragraphs, answer_sentence
from dvrk_dart.diagnosis.output.effect_words import plain_name
from dvrk_dart.diagnosis.output.regimes import residual_regimes
from dvrk_dart.diagnosis.fit.diagnosis_runs import DiagnosisRun, prepare_run
from dvrk_dart.diagnosis.fit.identified_terms import identified_joint_term
from dvrk_dart.diagnosis.checks.synthetic import synthesize_measurement
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import process
from dvrk_dart.model.joints import JOINT_NAMES
from arms import PSM
from one_segment import FIRST_PERIOD_SAMPLES, noise_rms, segment  # noqa: F401 (fixtures)

#: the size of a blindly recovered effect must be within this relative error
SIZE_TOLERANCE = 0.20
#: the withheld payload's mass must be within this relative error (brief)
PAYLOAD_MASS_TOLERANCE = 0.30
#: hand measurement of the 105 g run (data README): a check, never an input
PAYLOAD_MASS_KG = 0.105
PAYLOAD_HORIZONTAL_M = 0.165
PAYLOAD_HEIGHT_M = 0.020
#: a recovered effect explains at least this share of the held-out residual of
#: one of its joints (noise is the rest: the tilt case is the weakest, ~0.25)
MIN_JOINT_FRACTION_EXPLAINED = 0.2
#: greedy steps allowed in the synthetic tests (the injected effect must come first)
SYNTHETIC_MAX_EFFECTS = 2
#: synthetic segment: two base periods of the excitation


#: diagnosis.json's top-level keys and those of each effect (docs/outputs.md)
DIAGNOSIS_KEYS = {
    "joints", "units", "joint_words", "measured", "measured_runs", "baseline_source", "nuisance_offsets", "nuisance_offset_joints", "session_floor",
    "repeat", "repeat_source", "gap_split", "baseline", "train_runs", "holdout_runs", "inputs", "processing", "residual_definition", "simulated_source",
    "gap_before", "gap_after", "gap_after_source", "explained_fraction", "effects", "selection", "payload", "payloads",
    "payload_candidates", "sim_config", "not_in_simulation", "where", "recorded_joints", "not_recorded_by", "unrecorded_joint_notes", "effort_convention_notes", "constants_beyond_session", "gravity_mismatch", "explanation", "dropped_effects", "payload_not_distinguished",
    "identified_terms", "payload_at_unused", "effort_scale_rival",
}
EFFECT_KEYS = {
    "rank", "name", "kind", "family", "joints", "parameters", "units", "size", "explained_fraction", "explained_fraction_per_joint",
    "selected", "role", "selection_step", "in_simulation", "fully_in_simulation",
}


def _recover(arm, segment, noise_rms, effect, p_true, seed):
    measured = synthesize_measurement(arm, segment, [(effect, np.asarray(p_true))], noise_rms, seed=seed)
    result = diagnose(measured, arm=arm, max_effects=SYNTHETIC_MAX_EFFECTS, figures=False, profile_payload_mass=False)
    return result, result["effects"][0]


# ------------------------------------------------------ blind recoveries
#: the identified arm is well balanced: gravity efforts are ~0.25 N·m RMS, so a
#: base tilt at its plausible limit (0.05 rad) changes them by ~0.01-0.02 N·m,
#: a quarter of the real residual. The tilt is recovered at 1/5 of that noise;
#: at the full level it is not observable (reported, see test below).
TILT_NOISE_SCALE = 0.2

SYNTHETIC_CASES = [
    # (effect factory, true parameters, index of the size parameter, noise scale)
    ("friction_q2", lambda arm: JointFriction(arm.model, "q2"), [0.15, 0.20], 0, 1.0),
    ("friction_q3_smooth0.03", lambda arm: JointFriction(arm.model, "q3", reversal_velocity=0.03), [0.4, 0.6], 0, 1.0),
    ("payload_on_insertion_carriage", lambda arm: PointPayload(arm.model, 8), [0.20, 0.02, -0.03, 0.30], 0, 1.0),
    # payloads elsewhere: a translating parallelogram link, the counterweight, the tool off its roll axis
    ("payload_on_pitch_front", lambda arm: PointPayload(arm.model, 4), [0.15, 0.30, 0.0, 0.02], 0, 1.0),
    ("payload_on_counterweight", lambda arm: PointPayload(arm.model, 9), [0.20, 0.02, 0.0, 0.03], 0, 1.0),
    ("payload_on_tool_roll", lambda arm: PointPayload(arm.model, 10), [0.10, 0.02, 0.0, -0.30], 0, 1.0),
    ("offset_q3", lambda arm: JointOffset(arm.model, "q3"), [-0.3], 0, 1.0),
    ("armature_q3", lambda arm: JointArmature(arm.model, "q3"), [0.5], 0, 1.0),
    ("cable_elasticity_q1", lambda arm: JointStiffness(arm.model, "q1", "cable_elasticity"), [0.3], 0, 1.0),
    ("torsion_spring_q4", lambda arm: JointStiffness(arm.model, "q4", "torsion_spring"), [0.01], 0, 1.0),
    ("offset_q1", lambda arm: JointOffset(arm.model, "q1"), [-0.15], 0, 1.0),
    ("armature_q1", lambda arm: JointArmature(arm.model, "q1"), [0.02], 0, 1.0),
    ("gravity_tilt", lambda arm: GravityTilt(arm), [0.030, -0.025], None, TILT_NOISE_SCALE),
]


@pytest.mark.parametrize("name,factory,p_true,size_index,noise_scale", SYNTHETIC_CASES, ids=[c[0] for c in SYNTHETIC_CASES])
def test_injected_effect_ranks_first_with_its_size(arm, segment, noise_rms, name, factory, p_true, size_index, noise_scale):
    effect = factory(arm)
    seed = [c[0] for c in SYNTHETIC_CASES].index(name)  # fixed noise per case
    result, top = _recover(arm, segment, noise_scale * noise_rms, effect, p_true, seed=seed)
    assert top["name"] == name, [e["name"] for e in result["effects"][:3]]
    assert top["selected"]
    values = [top["parameters"]["mass_kg"]] if top["kind"] in ("payload", "gravity_mismatch") else list(top["parameters"].values())
    if size_index is None:  # a tilt: both angles
        estimated, true = np.array(values[:2]), np.array(p_true)
        assert np.linalg.norm(estimated - true) < SIZE_TOLERANCE * np.linalg.norm(true)
    else:
        assert abs(values[size_index] - p_true[size_index]) < SIZE_TOLERANCE * abs(p_true[size_index])
    # the effect closes most of the gap of a joint it acts on, on held-out segments
    per_joint = top["explained_fraction_per_joint"]["cross_validated"]
    assert max(per_joint[JOINT_NAMES.index(j)] for j in top["joints"]) > MIN_JOINT_FRACTION_EXPLAINED


def test_payload_links_the_efforts_cannot_tell_apart(arm, segment):
    """The links turning with q2 about pivots that only translate along the yaw
    axis (pitch, pitch_top, pitch_bottom) are one family: on the measured
    trajectory the efforts of a point mass on pitch_top or pitch_bottom are
    exactly those of some body on the pitch link; a translating link's are not."""
    equivalents = equivalent_payload_links(arm)
    family = {arm.model.links[k].name for k in equivalents[arm.model.link_by_name("pitch").key]}
    assert family == {"pitch", "pitch_top", "pitch_bottom"}
    assert all(len(v) == 1 for k, v in equivalents.items() if arm.model.links[k].name not in family)
    state = segment.head(300)
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, np.zeros_like(state.q), sample_rate_hz())
    pitch = features.body_regressor[:, :, features.body_columns(arm.model.link_by_name("pitch").key)].reshape(-1, 10)

    def misfit_on_pitch(name: str) -> float:
        effort = PointPayload(arm.model, arm.model.link_by_name(name).key).effort(features, np.array([0.2, 0.03, -0.04, 0.02])).ravel()
        body, *_ = np.linalg.lstsq(pitch, effort, rcond=None)
        return float(np.max(np.abs(pitch @ body - effort)) / np.max(np.abs(effort)))

    assert misfit_on_pitch("pitch_top") < 1e-9 and misfit_on_pitch("pitch_bottom") < 1e-9
    assert misfit_on_pitch("pitch_front") > 1e-2 and misfit_on_pitch("insertion_carriage") > 1e-2


def test_payload_mass_interval_when_only_its_moment_is_seen(arm, segment, noise_rms):
    """A payload on a link turning about the fixed pitch shaft: gravity sees m c
    only, so the diagnosis finds its family and reports a mass interval that
    contains the truth, not a mass it cannot pin. Without a baseline run it is
    the arm's gravity against the parameters (a payload not told apart), in the keys too."""
    key = arm.model.link_by_name("pitch_bottom").key
    truth = PointPayload(arm.model, key, equivalent_keys=equivalent_payload_links(arm)[key])
    measured = synthesize_measurement(arm, segment, [(truth, np.array([0.15, 0.05, -0.20, 0.0]))], noise_rms, seed=3)
    result = diagnose(measured, arm=arm, max_effects=SYNTHETIC_MAX_EFFECTS, figures=False)
    assert result["payload"] is None and result["payloads"] == []
    payload = result["gravity_mismatch"]
    assert "an attached mass are not told apart" in payload["words"][0]
    assert not any(e["kind"] in ("payload", "payload_at_position") for e in result["effects"])  # the ranked effects' words too
    assert result["effects"][0]["kind"] == "gravity_mismatch" and "gravity mismatch" in plain_name(result["effects"][0])
    assert payload["link"] in {truth.link_name, *truth.equivalent_links}
    lo, hi = payload["mass_interval_kg"]
    assert lo <= 0.15 <= hi and not payload["mass_profile"]["identifiable"]


def test_tilt_at_real_noise_is_not_claimed(arm, segment, noise_rms):
    """At the real residual level a plausible tilt is below the noise: the
    diagnosis must not select a large spurious effect in its place."""
    measured = synthesize_measurement(arm, segment, [(GravityTilt(arm), np.array([0.03, -0.025]))], noise_rms, seed=11)
    result = diagnose(measured, arm=arm, max_effects=SYNTHETIC_MAX_EFFECTS, figures=False, profile_payload_mass=False)
    assert max(result["effects"][0]["explained_fraction_per_joint"]["cross_validated"]) < 0.15


def test_what_the_identified_model_has_is_said_to_be_its_own(arm, segment, noise_rms):
    """The identified model's own friction, offsets, spring and motor inertia in
    the measured efforts: what the inertia-only simulation misses is those
    terms, and the answer says so; an armature the model does not have is not."""
    from dvrk_dart.model.identified import NON_INERTIAL_TERMS

    own = arm.identified.predict(segment.q, segment.dq, segment.ddq, NON_INERTIAL_TERMS)
    measured = synthesize_measurement(arm, segment, [], noise_rms, seed=11, extra_effort=own)
    carried = diagnose(measured, arm=arm, max_effects=4, figures=False, profile_payload_mass=False)["identified_terms"]
    assert carried["share"] > 0.8 and carried["terms"] == list(NON_INERTIAL_TERMS), carried
    foreign = synthesize_measurement(arm, segment, [(JointArmature(arm.model, "q3"), np.array([0.5]))], noise_rms, seed=12)
    result = diagnose(foreign, arm=arm, max_effects=SYNTHETIC_MAX_EFFECTS, figures=False, profile_payload_mass=False)
    assert result["identified_terms"]["share"] < 0.2 and "beyond the identified model's terms" in answer_sentence(result), result["identified_terms"]


def test_what_is_beyond_the_identified_terms_is_put_on_the_effect_it_looks_like(arm, segment, noise_rms):
    """The identified model's own terms plus a q1 offset 0.2 N·m beyond its own: the selected effects rebuild
    the model's q1 friction and offset, and what they add to them on q1 is said to be the offset (a blind q1 offset
    change was told only as "mostly explained beyond it", the lead being J3's published friction)."""
    from dvrk_dart.model.identified import NON_INERTIAL_TERMS

    own = arm.identified.predict(segment.q, segment.dq, segment.ddq, NON_INERTIAL_TERMS)
    own[:, 0] += -0.2
    measured = synthesize_measurement(arm, segment, [], noise_rms, seed=13, extra_effort=own)
    result = diagnose(measured, arm=arm, max_effects=12, figures=False, profile_payload_mass=False)
    assert {"offset_q1", "friction_q1"} <= {name.split("_presliding")[0].split("_smooth")[0] for name in result["selection"]["selected"]}
    carried = result["identified_terms"]
    assert carried["beyond_carried_by"]["q1"] == "offset_q1" and carried["beyond_rms"]["q1"] == pytest.approx(0.2, rel=0.1), carried
    # every selected one-joint effect has the model's own values beside it, the lead too (a q1 friction at the published
    # values led an answer as if it were found)
    friction_q1 = next(name for name in result["selection"]["selected"] if name.startswith("friction_q1"))
    coulomb, _ = identified_joint_term(arm, 0, "friction")
    assert carried["identified_values"][friction_q1]["coulomb"] == pytest.approx(coulomb)
    story = answer_paragraphs(result)[-1]
    lead = min((name for name in result["selection"]["selected"] if f"({name}" in story), key=lambda name: story.index(f"({name}"))
    assert (lead in carried["identified_values"]) == ("the identified model's" in story.split(f"({lead}")[1].split(" with ")[0]), story


def test_with_a_baseline_the_model_errors_shared_with_it_are_said_to_be_the_identified_models(arm, segment, noise_rms):
    """A run of another motion fitted beside its baseline: the model errors the runs share with the baseline were
    the identified friction and offsets the inertia-only simulation leaves out, named "model errors" with no word."""
    from dvrk_dart.diagnosis.checks.synthetic import time_scaled
    from dvrk_dart.model.identified import NON_INERTIAL_TERMS

    def with_own_terms(state, seed):
        own = arm.identified.predict(state.q, state.dq, state.ddq, NON_INERTIAL_TERMS)
        return synthesize_measurement(arm, state, [], noise_rms, seed=seed, extra_effort=own)

    baseline, other = with_own_terms(segment, 21), with_own_terms(time_scaled(segment, 0.5), 22)
    result = diagnose(other, baseline, arm=arm, max_effects=4, figures=False, profile_payload_mass=False)
    carried = result["identified_terms"]
    assert carried["runs"] == "baseline" and carried["share"] > 0.8, carried
    assert "of the model errors' efforts" in answer_sentence(result)


def test_nothing_injected_selects_little(arm, segment, noise_rms):
    """On pure noise, no effect explains much held-out residual."""
    measured = synthesize_measurement(arm, segment, [], noise_rms, seed=7)
    result = diagnose(measured, arm=arm, max_effects=SYNTHETIC_MAX_EFFECTS, figures=False, profile_payload_mass=False)
    assert max(result["effects"][0]["explained_fraction_per_joint"]["cross_validated"]) < 0.15


# ------------------------------------------------- withheld real payload
@pytest.fixture(scope="module")
def payload_diagnosis(arm, tmp_path_factory):
    out = tmp_path_factory.mktemp("payload")
    # the point-mass model without nuisance offsets (the diagnosis before the
    # first-moment model): its limits are what the tests below document
    result = diagnose("one-105g", baseline="one-no-weight", arm=arm, out_dir=out, max_effects=1, figures=False,
                      payload_model="point", nuisance_offsets=False)
    return result, out


def test_withheld_payload_found_on_the_parallelogram(payload_diagnosis):
    result, out = payload_diagnosis
    payload = result["payload"]
    assert payload is not None and payload["group"] == "parallelogram"
    assert result["effects"][0]["kind"] == "payload"
    # gravity identifies the payload's moment about the pitch shaft: compare it
    # with the hand measurement's (0.105 kg x 0.165 m), within the mass tolerance
    moment = abs(payload["gravity_efforts_at_q0"][1]) / 9.81
    assert abs(moment - PAYLOAD_MASS_KG * PAYLOAD_HORIZONTAL_M) < PAYLOAD_MASS_TOLERANCE * PAYLOAD_MASS_KG * PAYLOAD_HORIZONTAL_M
    # the held-out gap closes on J2, the joint the payload loads most
    assert result["gap_after"]["train"][1] < 0.7 * result["gap_before"]["train"][1]
    on_disk = json.loads((out / "diagnosis.json").read_text())
    assert on_disk["payload"]["link"] == payload["link"]


def test_the_payload_is_the_finding_of_a_run_minus_baseline_diagnosis(arm):
    """The 105 g runs at full and half speed against the full-speed run without
    the weight: the half-speed run is another motion, fitted with the baseline,
    so the inertia-only simulation's own errors (friction, ...) explain more of
    the training residual than the payload; they are the runs' common model
    errors and rank after the payload, the one effect the runs have and their
    baseline has not."""
    result = diagnose(["one-105g", "one-105g-half"], baseline="one-no-weight", arm=arm, figures=False, profile_payload_mass=False)
    top, *others = result["effects"]
    assert top["kind"] in ("payload", "payload_at_position") and top["selected"] and top["role"] == "finding"
    common = [e for e in others if e["selected"] and e["role"] == "common_model_error"]
    assert common and all(e["kind"] not in ("payload", "payload_at_position") for e in common)
    # no --repeat: the payload's report says its intervals do not count a session change
    assert result["payloads"] and all(any(w.startswith("Without --repeat") for w in report["words"]) for report in result["payloads"])


@pytest.mark.xfail(strict=True, reason="the mass alone is not identifiable from this pair of runs (see the docstring's numbers)")
def test_withheld_payload_mass(payload_diagnosis):
    """Why the mass is not pinned (residual = 105 g run - no-weight run, stand-in
    simulation; point mass on a link turning with q2, position free):
    - gravity sees the first moment only: |m c| = 0.0157 kg m in the pitch plane
      (hand measurement 0.105 x 0.166 = 0.0174); m comes from m c c^T = h h^T / m,
      i.e. the estimate is linear in 1/m (truth 9.5 1/kg);
    - J2 alone: 1/m = 0.45 +- 6.9 1/kg (1 s block sandwich), so m > 0.085 kg
      (90 %) with no upper bound: the truth's inertial effort is 0.010 N m RMS
      on J2 (0.005 on J1) against 0.077 (0.062) N m of residual no payload explains;
    - J1 + J2: m = 0.048 kg, 90 % [0.035, 0.076], every base period alike, but
      driven by J1's unexplained residual: with a J1 offset nuisance (collinear
      with the along-shaft moment, the yaw axis being horizontal) m > 1.2 kg;
      with a J2 offset nuisance the first moment itself collapses to 0.006 kg m
      (an offset ~ the cos(q2) gravity over q2 in +-0.8 rad): the runs share a
      session, so offsets are not fitted;
    - the DH-skeleton envelope binds: along the fitted moment (36 degrees above
      the horizontal at q = 0) the pitch group's box reaches 0.112 m from the
      shaft, so m >= 0.14 kg (> +30 %); the hand-measured 16.5 cm lies outside it;
    - a translating link (pitch_front, intermediate: m identifiable from gravity)
      explains less held-out residual (0.105 / 0.094 vs 0.155); with the
      offsets of J1..J3 as nuisances it is a tie among links (0.205 / 0.205 /
      0.203 / 0.199 for pitch_front / intermediate / pitch_bottom / pitch) whose
      masses differ fourfold (0.077 / 0.061 / 0.021 / 0.039 kg), and a yaw-link
      payload beats them all (0.212): no link-and-mass claim survives;
    - profiled over the whole family of equivalent links (pitch, pitch_top,
      pitch_bottom: identical efforts), the cross-validated interval is still
      0.126-2 kg.
    +-30 % is therefore not reachable honestly from these runs."""
    result, _ = payload_diagnosis
    assert abs(result["payload"]["mass_kg"] - PAYLOAD_MASS_KG) < PAYLOAD_MASS_TOLERANCE * PAYLOAD_MASS_KG


def test_payload_mass_is_reported_as_an_envelope_bound(payload_diagnosis):
    """The data asks for a longer lever than the link's DH envelope allows: the
    estimate must say so (position on the envelope boundary, mass interval)."""
    result, _ = payload_diagnosis
    payload = result["payload"]
    assert payload["at_envelope_boundary"]
    lo, hi = payload["mass_interval_kg"]
    assert lo <= payload["mass_kg"] <= hi


def test_payload_impostor_yields_to_offsets(arm):
    """On trajectory 'one' alone a payload on the pitch link, pinned at its
    envelope boundary, mimics the J1 and J2 offsets (the identified J1 offset is
    -0.30 N m): the offsets, fewer parameters and not significantly worse, are
    selected instead of it."""
    result = diagnose("one", arm=arm, max_effects=3, figures=False, profile_payload_mass=False)
    selected = result["selection"]["selected"]
    assert {"offset_q1", "offset_q2"} <= set(selected)
    assert not any(name.startswith("payload") for name in selected)
    step = next(s for s in result["selection"]["steps"] if "offset_q1" in s["effects"])
    assert step["instead_of"] is not None and step["instead_of"].startswith("payload")
    j1 = next(e for e in result["effects"] if e["name"] == "offset_q1")
    assert j1["parameters"]["offset"] == pytest.approx(-0.30, abs=0.03)


def test_smooth_friction_goes_into_the_simulation_whole(arm, segment):
    """A smooth Coulomb reversal is simulator physics (tanh law, viscous as
    damping): the SimConfig carries all of it and its effort equals the regressor."""
    from dvrk_dart.diagnosis.effects.library import not_simulated

    state = segment.head(300)
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    features = TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz())
    effect, p = JointFriction(arm.model, "q3", reversal_velocity=0.03), np.array([0.4, 0.6])
    cfg = effects_to_sim_config([(effect, p)])
    assert cfg.extra.coulomb[2] == 0.4 and cfg.extra.viscous[2] == 0.6 and cfg.extra.coulomb_reversal_velocity[2] == 0.03
    assert not_simulated([(effect, p)]) == []
    total = config_effort_by_formula(arm, cfg, state.q, state.dq, state.ddq)
    assert np.max(np.abs(total - ref - effect.effort(features, p))) < 1e-10
    assert effect.family == JointFriction(arm.model, "q3").family


# ------------------------------------------------------ where + contract
def test_regime_table_finds_friction_by_velocity_sign(arm, segment):
    ref = arm.identified.predict(segment.q, segment.dq, segment.ddq, "inertial")
    coulomb = 0.2
    residual = np.zeros_like(ref)
    residual[:, 1] = coulomb * np.sign(segment.dq[:, 1])
    table = residual_regimes(segment, residual, PSM)
    j2 = table[(table.joint == "q2") & (table.regime == "velocity")].set_index("bin")
    assert j2.loc["positive", "mean"] == pytest.approx(coulomb)
    assert j2.loc["negative", "mean"] == pytest.approx(-coulomb)
    assert set(table.regime) == {"velocity", "acceleration", "insertion_depth_q3", "pitch_q2"}


def test_contract_and_outputs(arm, segment, noise_rms, tmp_path):
    """diagnose with a holdout run, a caller-supplied simulation and out_dir."""
    train_state, holdout_state = segment.head(FIRST_PERIOD_SAMPLES), process(load_run(resolve_run("two"), PSM)).head(FIRST_PERIOD_SAMPLES)
    offset = JointOffset(arm.model, "q3")

    def simulate(config, state):  # stand-in for the DART replay
        return config_effort_by_formula(arm, config, state.q, state.dq, state.ddq)

    train = synthesize_measurement(arm, train_state, [(offset, np.array([0.4]))], noise_rms, seed=3)
    holdout = synthesize_measurement(arm, holdout_state, [(offset, np.array([0.4]))], noise_rms, seed=4)
    result = diagnose(train, holdout=[holdout], simulate=simulate, out_dir=tmp_path, arm=arm, max_effects=1, profile_payload_mass=False)
    assert result["joints"] == list(JOINT_NAMES)
    for key in ("gap_before", "gap_after"):
        assert len(result[key]["train"]) == 7 and len(result[key]["holdout"]) == 7
    assert result["gap_after_source"] == "simulation"
    assert result["effects"][0]["name"] == "offset_q3" and result["effects"][0]["selected"]
    assert result["gap_after"]["holdout"][2] < 0.5 * result["gap_before"]["holdout"][2]
    assert result["sim_config"]["extra"]["offset"][2] == pytest.approx(0.4, rel=SIZE_TOLERANCE)
    on_disk = json.loads((tmp_path / "diagnosis.json").read_text())
    assert on_disk["effects"][0]["name"] == "offset_q3"
    # the layout of diagnosis.json (docs/outputs.md): a change of it is a decision, made here
    assert set(on_disk) == DIAGNOSIS_KEYS
    assert all(set(entry) == EFFECT_KEYS for entry in on_disk["effects"])
    assert (tmp_path / "where.csv").is_file()
    assert len(list((tmp_path / "figures").glob("*.png"))) == 15  # 7 joints before and after, and one period


def test_baseline_must_match_the_run(arm, segment):
    from dvrk_dart.errors import DvrkDartError

    run = prepare_run(segment, arm)
    with pytest.raises(DvrkDartError):
        DiagnosisRun("x", segment.head(100), run.simulated[:100], baseline=run)


def test_the_answer_sentence_says_what_how_far_and_what_is_left():
    friction = {"name": "friction_q3", "kind": "friction", "joints": ["q3"], "parameters": {"coulomb": 0.5, "reversal": "sign"},
                "units": {"coulomb": "N"}, "size": 0.5}
    split = [{"joint": j, "before": b, "after": a, "session_floor": f}
             for j, b, a, f in (("q1", 0.33, 0.065, 0.05), ("q2", 0.32, 0.106, 0.08), ("q3", 0.65, 0.18, 0.05))]
    result = {"gap_before": {"train": [0.3, 0.3, 0.6], "holdout": [0.33, 0.32, 0.65]},
              "gap_after": {"train": [0.06, 0.09, 0.12], "holdout": [0.065, 0.106, 0.18]}, "effects": [friction],
              "selection": {"selected": ["friction_q3", "offset_q1"]}, "payload": None, "session_floor": [0.05, 0.08, 0.05],
              "gap_split": {"runs": "holdout", "joints": split}, "units": ["N·m", "N·m", "N", "N·m", "N·m", "N·m", "N·m"]}
    sentence = answer_sentence(result)
    assert "friction of q3 (friction_q3, size 0.5 N) with 1 more effect (offset_q1)" in sentence
    assert "held-out" in sentence and "q3 0.650 -> 0.180 N" in sentence
    # a friction's viscous part is its size too (a blind viscous change of 0.2 N/(m/s) read "size 0 N")
    viscous = {**friction, "parameters": {"coulomb": 0.0, "viscous": 0.2, "reversal": "sign"},
               "units": {"coulomb": "N", "viscous": "N/(m/s)"}, "size": 0.0}
    assert "(friction_q3, Coulomb 0 N, viscous 0.2 N/(m/s))" in answer_sentence({**result, "effects": [viscous]})
    # q3: 1 - sqrt(0.18^2 - 0.05^2) / sqrt(0.65^2 - 0.05^2) of the gap above the floor removed (the words' measure)
    assert "q3 73% of that gap above the session floor" in sentence
    assert "over 1.5x the session floor on q3" in sentence and "q1" not in sentence.split("floor on")[1]
    for row, floor in zip(split, (0.06, 0.1, 0.15)):  # the floor of the gaps split (gap_split's rows) is what "left" is read against
        row["session_floor"] = floor
    assert "within 1.5x the session floor" in answer_sentence(result)


def test_a_mass_interval_holds_the_fit_between_grid_points():
    """2018 test1's gravity mismatch: 0.612 kg fitted, profile grid points 0.502
    (score under the best by more than its spread) and 0.632 (within it): the
    interval's end is where the score crosses, not the grid point (it read
    [0.632, 2.0], leaving out its own fit)."""
    from dvrk_dart.diagnosis.payload.payload_report import _interval_within

    masses = np.array([0.3987645279295233, 0.5020665656246561, 0.6321295367643321, 0.7958860011973393, 1.0020644346793832])
    scores = np.array([0.9387, 0.9584, 0.9664, 0.9665, 0.9666])
    lo, hi = _interval_within(masses, scores, 0.9666 - 0.0059)
    assert 0.502 < lo < 0.612 and hi == masses[-1]
    lo, hi = _interval_within(masses, np.array([0.5, 0.9, 1.0, 0.9, 0.5]), 0.95)  # both ends crossed, halfway in log mass
    assert lo == pytest.approx(np.sqrt(masses[1] * masses[2])) and hi == pytest.approx(np.sqrt(masses[2] * masses[3]))


def test_a_friction_along_a_joint_is_simulated_as_fitted_within_the_runs(arm, segment, noise_rms):
    """Its end knot beyond the runs (J1's at -1.6 rad, runs within -0.55..0.95)
    read 9.2 N·m, which the simulation extrapolated to a held-out run reaching
    past the training range. Within the runs' range, the simulated table is the
    fitted one; beyond it, Fc is held at its value at the range's end."""
    from dvrk_dart.diagnosis.effects.position_friction import PositionFriction

    effect = PositionFriction(arm.model, "q1", 0.01).within(-0.55, 0.95)
    p = np.array([9.2, 0.1, 0.2, 0.3, 0.05])  # Fc at -1.6, -0.533, 0.533, 1.6 rad, viscous
    knots, values = (np.asarray(x) for x in np.split(np.array(effect.sim_contribution(p).position_friction[0][2:]), 2))
    inside = np.linspace(-0.55, 0.95, 31)
    assert np.allclose(np.interp(inside, knots, values), np.interp(inside, effect.knots, p[:-1]))
    held = np.interp(-0.55, effect.knots, p[:-1])
    assert np.interp(-1.2, knots, values) == pytest.approx(held) and held < 1.0

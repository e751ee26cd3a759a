"""The identified model in Pinocchio: the published numbers and the physics."""

import json
import subprocess
import sys

import numpy as np

from dvrk_dart.model.identified import TERMS

PUBLISHED_RELATIVE_ERRORS = [0.0929, 0.1783, 0.1907, 0.1345, 0.2394, 0.2125, 0.2642]
#: the published values are rounded to 4 decimals
PUBLISHED_TOLERANCE = 0.0005
#: joints whose links carry mass in the identification (the tool is massless)
MASSIVE = slice(0, 3)


def test_cli_reproduces_published_relative_errors(arm):
    out = subprocess.run(
        [sys.executable, "-m", "dvrk_dart.cli", "model-errors", "--measured", "two", "--first-period", "--json", "--processing", "upstream"],
        capture_output=True, text=True, check=True,
    )
    result = json.loads(out.stdout)
    assert result["samples"] == 1111
    assert result["terms"] == "all"
    np.testing.assert_allclose(result["relative_error"], PUBLISHED_RELATIVE_ERRORS, atol=PUBLISHED_TOLERANCE)
    assert len(result["rms"]) == 7


def random_configurations(data_ranges, n, seed=0):
    lower, upper = data_ranges
    return np.random.default_rng(seed).uniform(lower, upper, size=(n, 7))


def test_mass_matrix_symmetric_positive_definite(arm, data_ranges):
    for q in random_configurations(data_ranges, 1000):
        M = arm.identified.mass_matrix(q)
        np.testing.assert_allclose(M, M.T, atol=1e-12)
        # the identified tool links are massless: rows 4..7 are exactly zero
        assert np.all(M[3:, :] == 0.0) and np.all(M[:, 3:] == 0.0)
        assert np.linalg.eigvalsh(M[MASSIVE, MASSIVE])[0] > 1e-4  # kg m^2 / kg: clearly positive


def test_dM_dt_minus_2C_is_skew_symmetric(arm, data_ranges):
    rng = np.random.default_rng(1)
    h = 1e-6
    for q in random_configurations(data_ranges, 20, seed=2):
        dq = rng.normal(size=7)
        dM = (arm.identified.mass_matrix(q + h * dq) - arm.identified.mass_matrix(q - h * dq)) / (2 * h)
        S = dM - 2 * arm.identified.coriolis_matrix(q, dq)
        assert np.max(np.abs(S + S.T)) < 1e-6 * max(1.0, np.max(np.abs(dM)))
        # and C(q, dq) dq is the Coriolis term of the model
        np.testing.assert_allclose(arm.identified.coriolis_matrix(q, dq) @ dq, arm.identified.coriolis(q, dq), atol=1e-10)


def test_gravity_is_gradient_of_potential_energy(arm, data_ranges):
    h = 1e-6
    for q in random_configurations(data_ranges, 20, seed=3):
        grad = np.array([
            (arm.identified.potential_energy(q + h * e) - arm.identified.potential_energy(q - h * e)) / (2 * h)
            for e in np.eye(7)
        ])
        np.testing.assert_allclose(arm.identified.gravity(q), grad, atol=1e-6)


def test_terms_sum_to_full_prediction(arm, processed_two):
    pr = processed_two.head(300)
    efforts = arm.identified.efforts(pr.q, pr.dq, pr.ddq)
    assert set(efforts.terms) == set(TERMS)
    total = sum(efforts.terms.values())
    np.testing.assert_allclose(total, arm.identified.predict(pr.q, pr.dq, pr.ddq), atol=1e-12, rtol=0)
    # and the rigid-body terms agree with the single-query M ddq + C dq + g
    for k in range(0, 300, 37):
        M, cdq, g = arm.identified.mcg(pr.q[k], pr.dq[k])
        inertial = M @ pr.ddq[k] + cdq + g
        np.testing.assert_allclose(efforts.total("inertial")[k], inertial, atol=1e-12)


def test_fast_query_equals_the_projection_in_any_call_order(arm, data_ranges):
    """The mimic-reduced model of mcg() against the full tree projected with G."""
    reduced = arm.identified._reduced
    assert reduced is not None
    rng = np.random.default_rng(4)
    for q in random_configurations(data_ranges, 50, seed=5):
        dq = rng.normal(size=7)
        fast = arm.identified.mcg(q, dq)
        arm.identified._reduced = None
        try:
            reference = arm.identified.mcg(q, dq)
        finally:
            arm.identified._reduced = reduced
        for a, b in zip(fast, reference):
            np.testing.assert_allclose(a, b, atol=1e-12)


def test_batch_on_the_small_model_equals_the_full_tree(arm, processed_two):
    pr = processed_two.head(400)
    fast = arm.identified.efforts(pr.q, pr.dq, pr.ddq, ("inertia", "coriolis", "gravity"))
    reduced = arm.identified._reduced
    arm.identified._reduced = None
    try:
        reference = arm.identified.efforts(pr.q, pr.dq, pr.ddq, ("inertia", "coriolis", "gravity"))
    finally:
        arm.identified._reduced = reduced
    for term in fast.terms:
        np.testing.assert_allclose(fast.terms[term], reference.terms[term], atol=1e-11)


def test_non_inertial_terms_follow_the_upstream_definitions(arm):
    q = np.array([0.1, 0.2, 0.1, 0.3, 0.2, -0.1, 0.4])
    dq = np.array([0.5, -0.4, 0.05, 0.7, -0.3, 0.2, 0.6])
    ddq = np.array([1.0, -2.0, 0.3, 0.5, 0.4, -0.6, 0.8])
    e = arm.identified.efforts(q[None], dq[None], ddq[None]).terms
    p = arm.params
    # spring of link 10: +K q4 on joint 4 only
    np.testing.assert_allclose(e["spring"][0], np.eye(7)[3] * p[10].spring * q[3], atol=1e-15)
    # motor inertia of link 11 acts on 1.0186 ddq5, added to joint 5 only
    expected = np.zeros(7)
    expected[3] = p[10].motor_inertia * ddq[3]
    expected[4] = p[11].motor_inertia * 1.0186 * ddq[4]
    expected[5] = p[14].motor_inertia * ddq[5]
    expected[6] = p[15].motor_inertia * ddq[6]
    np.testing.assert_allclose(e["motor_inertia"][0], expected, atol=1e-15)
    # friction of link 8 (insertion) acts on dq3
    f8 = p[8].coulomb * np.sign(dq[2]) + p[8].viscous * dq[2]
    f8_other_links = e["friction"][0][2] - f8
    assert abs(f8_other_links) < 1e-15


def test_a_value_the_model_card_does_not_use_is_said(arm, tmp_path):
    """A motor inertia on link 2 (the card gives the pitch no motor) was accepted and changed nothing, without a word."""
    from dvrk_dart.model.parameters import load_parameters

    raw = json.loads(arm.params.source.read_text())
    assert arm.params.unused_values(arm.model) == []  # the published file: zeros where the card has no term
    raw["2"]["Im"] = 0.05
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(raw))
    notes = load_parameters(path, arm.model).unused_values(arm.model)
    assert len(notes) == 1 and "link 2 (pitch): Im = 0.05 not used" in notes[0], notes

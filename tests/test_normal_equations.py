"""The diagnosis's per-block normal equations: a long recording's blocks
lengthen instead of multiplying (each holds 7 P^2 numbers), and blocking,
demeaning and run weighting leave the whole run's equations as they are."""

import numpy as np

from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.effects.joint_effects import JointFriction
from dvrk_dart.diagnosis.fit.design import MAX_BLOCKS_PER_RUN, Design, Grams
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from arms import PSM_ARM

RATE_HZ = 200.0


def _run(duration_s: float, seed: int = 0):
    design = Design([JointFriction(PSM_ARM.model, j) for j in JOINT_NAMES[:3]])
    n = int(duration_s * RATE_HZ)
    rng = np.random.default_rng(seed)
    zeros = np.zeros((n, N_JOINTS))
    features = TrajectoryFeatures(PSM_ARM, zeros, zeros, zeros, zeros, RATE_HZ)
    Phi = rng.normal(size=(n, N_JOINTS, design.n_columns)) + 0.3  # a mean, for the demeaning
    residual = rng.normal(size=(n, N_JOINTS)) + 0.1
    return design, features, Phi, residual


def _whole_run(Phi, residual, demean):
    mask = np.asarray(demean, dtype=float)
    X = Phi - mask[None, :, None] * Phi.mean(0)
    r = residual - mask * residual.mean(0)
    return np.einsum("njp,njq->jpq", X, X), np.einsum("njp,nj->jp", X, r), np.sum(r**2, axis=0)


def test_a_short_run_has_a_block_a_second():
    design, features, Phi, residual = _run(30.0)
    grams = Grams.of_run(design, features, residual, 5, None, Phi)
    assert len(grams.n) == 30 and set(grams.n) == {200}
    assert list(np.bincount(grams.fold)) == [6] * 5


def test_a_long_run_keeps_a_bounded_number_of_longer_blocks_and_the_same_equations():
    design, features, Phi, residual = _run(150.0)
    demean = np.array([True, False, True, False, False, False, False])
    grams = Grams.of_run(design, features, residual, 5, demean, Phi)
    assert len(grams.n) == MAX_BLOCKS_PER_RUN
    assert grams.n.sum() == len(residual) and grams.n.max() - grams.n.min() <= 1
    A, g, s = _whole_run(Phi, residual, demean)
    np.testing.assert_allclose(grams.A.sum(0), A, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(grams.g.sum(0), g, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(grams.s.sum(0), s, rtol=1e-10)


def test_runs_weighted_in_place_and_joined_keep_each_runs_blocks():
    design, features, Phi, residual = _run(12.0)
    first = Grams.of_run(design, features, residual, 3, None, Phi)
    second = Grams.of_run(design, features, 2.0 * residual, 3, None, Phi)
    weight = np.linspace(0.5, 2.0, N_JOINTS)
    expected_A = np.concatenate([first.A, second.A * weight[None, :, None, None]])
    second.scale_in_place(weight)
    joined = Grams.concat([first, second])
    np.testing.assert_array_equal(joined.A, expected_A)
    np.testing.assert_allclose(joined.s[12:], 4.0 * first.s * weight[None, :])
    assert Grams.concat([first]) is first

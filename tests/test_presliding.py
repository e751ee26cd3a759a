"""Coulomb friction over a pre-sliding distance (Dahl): the law, the model that
evaluates it, and DART's simulation of it agree."""

import json

import numpy as np
import pytest

from dvrk_dart.metrics import rms
from dvrk_dart.model.friction import reversal
from dvrk_dart.sim import kernels
from arms import PSM


def test_zero_distance_is_the_sign_law():
    rate = np.array([-2.0, -0.1, 0.0, 0.3, 1.0])
    assert np.array_equal(reversal(np.cumsum(rate), rate, 0.0), np.sign(rate))


def test_the_state_reverses_over_the_distance():
    """After a reversal the state goes from +1 to -1 as -1 + 2 exp(-d / x_s)."""
    xs = 1e-4
    back = np.linspace(0.0, -5 * xs, 501)
    position = np.r_[np.linspace(-1e-3, 0.0, 101)[:-1], back]
    z = reversal(position, np.gradient(position), xs)
    travelled = -back
    assert np.allclose(z[100:], -1.0 + 2.0 * np.exp(-travelled / xs), atol=1e-6)
    assert abs(z[99] - 1.0) < 1e-12  # fully sliding forward before


def test_the_stepped_state_is_the_sequence_law():
    """The simulator's per-step kernel (two frictions, on q1 and on q2 - q1) and the law over a trajectory."""
    rng = np.random.default_rng(0)
    q = np.zeros((400, 7))
    q[:, :2] = np.cumsum(rng.normal(scale=3e-5, size=(400, 2)), axis=0)
    coefficients = np.zeros((2, 7))
    coefficients[0, 0], coefficients[1, :2] = 1.0, (-1.0, 1.0)
    distances = np.array([1e-4, 3e-5])
    positions = q @ coefficients.T
    rates = np.gradient(positions, axis=0)
    position, state = positions[0].copy(), np.sign(rates[0])
    stepped = [state.copy()]
    for row in q[1:]:
        kernels.dahl_step(row, coefficients, position, state, distances)
        stepped.append(state.copy())
    for i, distance in enumerate(distances):
        assert np.allclose(np.array(stepped)[:, i], reversal(positions[:, i], rates[:, i], distance), atol=1e-14)


@pytest.fixture(scope="module")
def presliding_params(tmp_path_factory, params):
    """The published parameters with the insertion stage's and the yaw's friction reversing over a distance."""
    from dvrk_dart.io.reference_data import resolve

    raw = json.loads(resolve("params.json").read_text())
    raw["8"]["xs"] = 1e-4
    raw["1"]["xs"] = 0.003
    path = tmp_path_factory.mktemp("params") / "params.json"
    path.write_text(json.dumps(raw))
    return path


def test_dart_simulates_the_presliding_friction_as_the_model_says(presliding_params, tmp_path):
    """The replay of "two" with the identified dynamics: DART (the Dahl state
    stepped with the simulated positions) and Pinocchio (the state over the
    measured positions) agree far better than the friction's size (Fc 0.45 N)."""
    from dvrk_dart.cli import main

    out = tmp_path / "run"
    assert main(["replay", "--measured", "two", "--dynamics", "identified", "--params", str(presliding_params),
                 "--duration", "6", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    sim_vs_model = np.array(metrics["rms_sim_vs_model"][:3])
    assert np.all(sim_vs_model < [0.01, 0.01, 0.02]), sim_vs_model


def test_a_negative_distance_is_refused(presliding_params, model, tmp_path):
    from dvrk_dart.errors import DvrkDartError
    from dvrk_dart.model.parameters import load_parameters

    raw = json.loads(presliding_params.read_text())
    raw["8"]["xs"] = -1e-4
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(raw))
    with pytest.raises(DvrkDartError, match="xs"):
        load_parameters(path, model)


def test_friction_along_the_range_is_simulated_as_the_regressor_says(arm):
    """PositionFriction (Fc piecewise linear in q2, reversing over 0.01 rad): the
    regressor, the SimConfig's formula and DART's replay give the same effort."""
    from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
    from dvrk_dart.diagnosis.effects.position_friction import PositionFriction
    from dvrk_dart.diagnosis.effects.library import config_effort_by_formula, effects_to_sim_config
    from dvrk_dart.diagnosis.api import simulation_hook
    from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
    from dvrk_dart.io.signal import process
    from dvrk_dart.sim.config import SimConfig

    state = process(load_run(resolve_run("two"), PSM)).head(800)
    effect, p = PositionFriction(arm.model, "q2", 0.01), np.array([0.05, 0.30, 0.10, 0.20, 0.0])
    ref = arm.identified.predict(state.q, state.dq, state.ddq, "inertial")
    injected = effect.effort(TrajectoryFeatures(arm, state.q, state.dq, state.ddq, ref, sample_rate_hz()), p)
    config = effects_to_sim_config([(effect, p)])
    by_formula = config_effort_by_formula(arm, config, state.q, state.dq, state.ddq)
    assert np.max(np.abs(by_formula - ref - injected)) < 1e-10
    assert np.all(injected[:, [0, *range(2, 7)]] == 0.0) and rms(injected[:, 1]) > 0.05
    assert effect.size(p) == 0.30  # the largest level along the range, not the first knot's
    simulate = simulation_hook(arm, jobs=1)
    simulated = simulate(config, state) - simulate(SimConfig(), state)
    # DART's Dahl state runs on the simulated positions: the same to far below Fc (0.05-0.3 N·m)
    assert rms(simulated[:, 1] - injected[:, 1]) < 0.01, rms(simulated[:, 1] - injected[:, 1])

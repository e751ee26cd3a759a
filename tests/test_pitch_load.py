"""The loads the pitch angle sets on J1 and J2 (diagnosis/beyond/pitch_load.py):
fitted on trajectory "one" they carry to trajectory "two" and to "one" in
another session, at any reasonable setting, where the bodies' gravity does
not; in DART they add the table's effort to J1 and J2 and nothing elsewhere.
Here on the identified model's residual (the held-out validation judges them
on top of the diagnosis's effects: tests/test_validation.py)."""

import numpy as np
import pytest

from dvrk_dart.diagnosis.beyond import pitch_load
from dvrk_dart.diagnosis.beyond.pitch_load import fit_pitch_loads
from dvrk_dart.diagnosis.fit.diagnosis_runs import choose_processing, loaded_states
from dvrk_dart.identification.regressor import FrictionLaw, Regressor
from dvrk_dart.metrics import rms
from arms import PSM


@pytest.fixture(scope="module")
def states():
    names = ["one", "two", "one-no-weight"]
    return dict(zip(names, loaded_states(names, PSM, choose_processing(names, "periodic", PSM))))


@pytest.fixture(scope="module")
def residuals(arm, states):
    """Measured minus the identified model (every term), in each run's band."""
    return {k: s.tau - s.in_band(arm.identified.predict(s.q, s.dq, s.ddq, "all")) for k, s in states.items()}


def _left(fitted, states, residuals, run):
    return rms(residuals[run][:, :2] - fitted.predict(states[run])[:, :2])


def test_the_loads_fitted_on_one_carry_to_two(states, residuals):
    """Measured: J1 0.0458 -> 0.0405 N·m, J2 0.095 -> 0.082 on "two"."""
    fitted = fit_pitch_loads([states["one"]], [residuals["one"]])
    before = rms(residuals["two"][:, :2])
    assert np.all(before > [0.045, 0.09])
    assert np.all(_left(fitted, states, residuals, "two") < before - [0.004, 0.01])


@pytest.mark.parametrize("spacing_rad, ridge", [(0.15, 10.0), (0.15, 100.0), (0.3, 10.0), (0.3, 100.0)])
def test_the_result_is_not_a_tuned_setting(states, residuals, monkeypatch, spacing_rad, ridge):
    """Knots 0.15-0.3 rad apart, ridges of 10-100 samples: "two" left at
    0.0405-0.0417 (J1) and 0.082-0.084 N·m (J2)."""
    monkeypatch.setattr(pitch_load, "KNOT_SPACING_RAD", spacing_rad)
    monkeypatch.setattr(pitch_load, "RIDGE_SAMPLES", ridge)
    fitted = fit_pitch_loads([states["one"]], [residuals["one"]])
    assert np.all(_left(fitted, states, residuals, "two") <= [0.042, 0.085])


def test_the_loads_repeat_in_another_session(states, residuals):
    """The same motion recorded in another session (its constants moved: means
    removed): J1 0.037 -> 0.029, J2 0.071 -> 0.067 N·m."""
    fitted = fit_pitch_loads([states["one"]], [residuals["one"]])
    run = "one-no-weight"
    left = residuals[run][:, :2] - fitted.predict(states[run])[:, :2]
    before, after = rms(residuals[run][:, :2] - residuals[run][:, :2].mean(0)), rms(left - left.mean(0))
    assert after[0] < 0.85 * before[0] and after[1] < before[1] - 0.002, (after, before)


def test_the_bodies_gravity_does_not_make_the_shape(arm, states, residuals):
    """J1's and J2's gravity columns of the identified model (every body's mass
    and first moment) with a constant, fitted on "one", leave "two" where it
    was or worse (measured 0.0465 and 0.099 N·m), where the tables leave 0.0405 and 0.082."""
    regressor = Regressor(arm.model, FrictionLaw("sign"))
    fitted = fit_pitch_loads([states["one"]], [residuals["one"]])

    def gravity_columns(state, j):
        still = np.zeros_like(state.q)
        return np.column_stack([state.in_band(regressor(state.q, still, still)[:, j, :]), np.ones(len(state.q))])

    for j in (0, 1):
        coefficients, *_ = np.linalg.lstsq(gravity_columns(states["one"], j), residuals["one"][:, j], rcond=1e-9)
        by_gravity = rms(residuals["two"][:, j] - gravity_columns(states["two"], j) @ coefficients)
        assert by_gravity > rms(residuals["two"][:, j]) - 0.001 and by_gravity > _left(fitted, states, residuals, "two")[j] + 0.005


def test_the_loads_are_simulated_as_fitted(arm, states, residuals):
    """The tables as DART physics add to the replayed J1 and J2 efforts what
    the fit predicts (at the simulated pitch, which tracks the measured one)
    and nothing to J3; the SimConfig's formula agrees exactly."""
    from dataclasses import replace

    from dvrk_dart.diagnosis.api import simulation_hook
    from dvrk_dart.diagnosis.effects.library import config_effort_by_formula
    from dvrk_dart.diagnosis.beyond.pitch_load import simulation_effects
    from dvrk_dart.sim.config import IDENTIFIED_PHYSICS

    state = states["two"]
    fitted = fit_pitch_loads([states["one"]], [residuals["one"]])
    config = replace(IDENTIFIED_PHYSICS, extra=simulation_effects(fitted))
    simulate = simulation_hook(arm, jobs=1)
    added = state.in_band(simulate(config, state) - simulate(IDENTIFIED_PHYSICS, state))
    by_formula = state.in_band(config_effort_by_formula(arm, config, state.q, state.dq, state.ddq)
                               - config_effort_by_formula(arm, IDENTIFIED_PHYSICS, state.q, state.dq, state.ddq))
    expected = fitted.predict(state)
    assert np.all(rms(expected[:, :2]) > 0.01)  # the loads are exercised
    assert np.all(rms(by_formula[:, :2] - expected[:, :2]) < 1e-9) and np.all(rms(added[:, :2] - expected[:, :2]) < 2e-3)
    assert np.max(np.abs(added[:, 2])) < 1e-6

"""J3's repeatable gap (diagnosis/beyond/insertion_terms.py): three terms fitted on
trajectory "one" carry to trajectory "two" and to "one" in another session;
each term carries part of it, at any reasonable setting; a stroke table
coarser than the residual's bumps loses the gain."""

import numpy as np
import pytest

from dvrk_dart.diagnosis.beyond import insertion_terms
from dvrk_dart.diagnosis.beyond.insertion_terms import (
    TERMS,
    fit_insertion_terms,
    insertion_gap,
    insertion_residual,
)
from dvrk_dart.diagnosis.fit.diagnosis_runs import choose_processing, loaded_states
from dvrk_dart.metrics import rms
from arms import PSM

#: the issue's bar for J3 on held-out "two" (N); the identified model leaves 0.134
J3_TARGET_N = 0.090


@pytest.fixture(scope="module")
def states():
    names = ["one", "two", "one-no-weight"]
    return dict(zip(names, loaded_states(names, PSM, choose_processing(names, "periodic", PSM))))


def test_the_three_terms_fitted_on_one_carry_to_two(arm, states):
    """Measured: J3 on "two" 0.134 N (identified model), 0.117 after J3's own
    friction refitted on "one", 0.081 with the three terms."""
    own = insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], ()), states["two"])
    full = insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], TERMS), states["two"])
    assert rms(insertion_residual(arm, states["two"])) > 0.12
    assert full <= J3_TARGET_N and full < 0.75 * own, (full, own)


def test_each_term_carries_part_of_the_gap(arm, states):
    """Without any one of the terms, "two" is at least 0.008 N worse (measured
    0.0806 with all; 0.090 / 0.0945 / 0.095 without the pitch load, the effort
    in ddq3 sign(dq3), the stroke's Coulomb level)."""
    full = insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], TERMS), states["two"])
    for term in TERMS:
        without = insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], tuple(t for t in TERMS if t != term)), states["two"])
        assert without >= full + 0.008, (term, without, full)


def test_the_terms_repeat_in_another_session(arm, states):
    """Fitted on "one", the same motion recorded in another session is left
    at about half of its residual: the bumps along the stroke are the arm's."""
    fitted = fit_insertion_terms(arm, [states["one"]], TERMS)
    before = rms(insertion_residual(arm, states["one-no-weight"]))
    assert insertion_gap(arm, fitted, states["one-no-weight"]) < 0.55 * before


@pytest.mark.parametrize("spacing_m, ridge", [(0.0025, 10.0), (0.0025, 100.0), (0.01, 10.0), (0.01, 100.0), (0.02, 10.0), (0.02, 100.0)])
def test_the_result_is_not_a_tuned_setting(arm, states, monkeypatch, spacing_m, ridge):
    """Any knot spacing from 2.5 to 20 mm and ridge from 10 to 100 samples
    leaves "two" under the bar (measured 0.081-0.086 N)."""
    monkeypatch.setattr(insertion_terms, "STROKE_KNOT_SPACING_M", spacing_m)
    monkeypatch.setattr(insertion_terms, "STROKE_RIDGE_SAMPLES", ridge)
    assert insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], TERMS), states["two"]) <= J3_TARGET_N


def test_stroke_knots_coarser_than_the_bumps_lose_the_gain(arm, states, monkeypatch):
    """On 40 mm knots the stroke's table blurs the 5-10 mm bumps: "two" is
    left above the bar (measured 0.097 N against 0.081 on 5 mm knots)."""
    monkeypatch.setattr(insertion_terms, "STROKE_KNOT_SPACING_M", 0.04)
    assert insertion_gap(arm, fit_insertion_terms(arm, [states["one"]], TERMS), states["two"]) > J3_TARGET_N


def test_the_terms_are_simulated_as_fitted(arm, states):
    """The fitted terms as DART physics (directional armature, angle load,
    explicit Coulomb tables) add to the replayed J3 effort what the regression
    says, and nothing to the other joints (beyond the replay's numerical
    noise on the wrist's light bodies); the SimConfig's formula agrees."""
    from dataclasses import replace

    from dvrk_dart.diagnosis.api import simulation_hook
    from dvrk_dart.diagnosis.beyond.insertion_terms import simulation_effects
    from dvrk_dart.diagnosis.effects.library import config_effort_by_formula
    from dvrk_dart.sim.config import IDENTIFIED_PHYSICS

    state = states["two"]
    fitted = fit_insertion_terms(arm, [states["one"]], TERMS)
    config = replace(IDENTIFIED_PHYSICS, extra=simulation_effects(arm, fitted))
    simulate = simulation_hook(arm, jobs=1)
    added = state.in_band(simulate(config, state) - simulate(IDENTIFIED_PHYSICS, state))
    by_formula = state.in_band(config_effort_by_formula(arm, config, state.q, state.dq, state.ddq)
                               - config_effort_by_formula(arm, IDENTIFIED_PHYSICS, state.q, state.dq, state.ddq))
    expected = fitted.predict(state)
    # measured: DART 0.0024 N RMS from the regression (its Dahl states run on
    # the simulated positions), the formula 1e-16; J1, J2 1e-11 N·m, the light wrist 5e-4 N·m RMS
    assert rms(by_formula[:, 2] - expected) < 1e-9 and rms(added[:, 2] - expected) < 0.01
    assert np.max(np.abs(added[:, :2])) < 1e-6 and np.all(rms(added[:, 3:]) < 2e-3)


def test_a_diagnosis_reports_the_terms_where_they_apply(arm):
    """On the PSM's periodic held-out runs: J3 under the bar simulated, the
    words and the answer's clause; not on the MTM (no insertion), not with a
    baseline, not on the upstream processing, not without q3."""
    from pathlib import Path

    from dvrk_dart.diagnosis.beyond.insertion_terms import insertion_applies, insertion_check
    from dvrk_dart.diagnosis.output.clauses import insertion_clause
    from dvrk_dart.io.arm import load_arm

    periodic = {"processing": {"processing": "periodic", "harmonics": 30}, "session_floor": [0.011, 0.05, 0.028]}
    study = insertion_check(arm, ["one"], ["two"], periodic)
    # the share of J3's gap above the floor (0.028 N) removed, in RMS-equivalents: 0.134 -> 0.081 N is about 42 %
    above = [np.sqrt(g**2 - 0.028**2) for g in (study["gap_holdout_identified"], study["gap_holdout_simulated"])]
    assert study["gap_holdout_simulated"] <= J3_TARGET_N and study["repeatable_gap_removed_share"] == pytest.approx(1 - above[1] / above[0])
    assert "ddq3·sign(dq3)" in study["words"] and f"{study['gap_holdout_simulated']:.3g} N" in insertion_clause({"insertion_terms": study})
    assert insertion_applies(arm, periodic, ["one"], ["two"], None)
    mtm = load_arm(Path(__file__).parents[1] / "models" / "mtm" / "mtm.toml")
    assert not insertion_applies(mtm, periodic, ["mtm-one"], ["mtm-two"], None)
    assert not insertion_applies(arm, periodic, ["one"], ["two"], "one-no-weight")
    assert not insertion_applies(arm, {"processing": {"processing": "upstream"}}, ["one"], ["two"], None)
    # runs without q3 (a header CSV of q1 and q2: the study's terms have nothing to fit, its clause no figure)
    assert not insertion_applies(arm, {**periodic, "recorded_joints": ["q1", "q2"]}, ["one"], ["two"], None)
    assert not insertion_applies(arm, {**periodic, "recorded_joints": ["q1", "q3"]}, ["one"], ["two"], None)  # no pitch: no pitch loads


def test_friction_dissipates_the_viscous_correction_stops_at_zero(arm, states):
    """2018's test1 asked J3's viscous correction for -1.62 N/(m/s) against the identified +1.20: a net
    friction that feeds energy. A residual asking for twice the identified viscous off gets it to zero, no lower;
    one inside the bound is the plain least squares (the 2019 fit unchanged)."""
    from dvrk_dart.diagnosis.beyond.insertion_terms import identified_viscous

    state, fv = states["one"], identified_viscous(arm, 2)
    assert fv == pytest.approx(1.2035645)
    v = state.dq[:, 2]
    clipped = fit_insertion_terms(arm, [state], ("pitch_load",), residuals=[-2.0 * fv * v])
    assert clipped.named_coefficients()["viscous"] == pytest.approx(-fv, abs=1e-9)
    inside = fit_insertion_terms(arm, [state], ("pitch_load",), residuals=[-0.5 * fv * v])
    assert inside.named_coefficients()["viscous"] == pytest.approx(-0.5 * fv, rel=1e-6)


def test_the_answer_says_worse_where_j3s_terms_leave_more_than_j3s_own_friction():
    """2018: J3's terms took the held-out gap from 0.220 N (J3's friction alone) to 0.414 N: "add nothing" understated it."""
    from dvrk_dart.diagnosis.output.clauses import insertion_clause

    study = {"gap_holdout_identified": 0.192, "gap_holdout_own_friction": 0.220, "gap_holdout_terms": 0.414, "gap_holdout_simulated": 0.414}
    assert "make it worse there" in insertion_clause({"insertion_terms": study})
    level = {**study, "gap_holdout_terms": 0.220, "gap_holdout_simulated": 0.220}
    assert "add nothing to it there" in insertion_clause({"insertion_terms": level})

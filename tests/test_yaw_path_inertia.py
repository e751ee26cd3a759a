"""J1's payload figures span the models of the payload's path to J1 (dvrk_dart/diagnosis/payload/yaw_path_inertia.py)."""

import numpy as np
import pytest

from dvrk_dart.diagnosis.checks.payload_checks import hand_position_on_link
from dvrk_dart.diagnosis.checks.synthetic import synthesize_measurement
from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.diagnosis.fit.diagnosis_runs import prepare_run
from dvrk_dart.diagnosis.effects.payload import PointPayload, point_mass_parameters
from dvrk_dart.diagnosis.payload.payload_report import AT_POSITION_WITHOUT_REPEAT
from dvrk_dart.diagnosis.payload.yaw_path_inertia import BARE_PATH, RIGID_PATH, path_readings, span_both_path_models, span_readings
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import process
from arms import HAND_PITCH
from one_segment import noise_rms, segment  # noqa: F401 (fixtures)



def test_a_reading_outside_an_interval_widens_it_and_one_inside_does_not():
    report = {"gravity_efforts_at_q0": [-0.035, 0.2], "gravity_efforts_at_q0_interval": [[-0.037, -0.033], [0.1, 0.3]],
              "q1_gravity_slope_at_q0_nm_per_rad": -0.2, "q1_gravity_slope_at_q0_nm_per_rad_interval": [-0.5, 0.1]}
    grew = span_readings(report, {RIGID_PATH: {"gravity_efforts_at_q0": 0.030, "q1_gravity_slope_at_q0_nm_per_rad": 0.1}}, BARE_PATH)
    assert grew == ["gravity_efforts_at_q0"] and report["gravity_efforts_at_q0_interval"][0] == pytest.approx([-0.037, -0.005])
    assert report["gravity_efforts_at_q0_interval"][1] == [0.1, 0.3]  # J2's is not a path's
    assert report["q1_gravity_slope_at_q0_nm_per_rad_interval"] == [-0.5, 0.1]  # -0.1 lies inside
    assert not span_readings(report, {RIGID_PATH: {"gravity_efforts_at_q0": 0.001, "q1_gravity_slope_at_q0_nm_per_rad": 0.0}}, BARE_PATH)


def test_the_first_moment_j1_interval_holds_a_point_in_the_pitch_plane(arm, segment, noise_rms):
    """205 g at the hand position on the pitch link (in the pitch plane: no J1
    gravity at q = 0), upstream: the first moment's path has no inertia and read
    the payload's centripetal J1 mean as gravity, -0.009 N·m with the interval
    [-0.011, -0.006] (0 of 8 synthetic pairs held the truth); spanned by the
    point mass's own inertia, the interval holds zero (7 of 8). The hand
    position's fit held it too; without a --repeat pair it is now not determined."""
    key, position = hand_position_on_link(arm, HAND_PITCH)
    at_rest = TrajectoryFeatures(arm, *(np.zeros((1, 7)),) * 4, sample_rate_hz())
    truth = (at_rest.body_regressor[0][:, at_rest.body_columns(key)] @ point_mass_parameters(0.205, position))[0]
    baseline = prepare_run(synthesize_measurement(arm, segment, [], noise_rms, seed=11), arm, name="no_weight")
    weighted = prepare_run(synthesize_measurement(arm, segment, [(PointPayload(arm.model, key), np.r_[0.205, position])], noise_rms, seed=11),
                           arm, name="weighted")
    result = diagnose([weighted], baseline=baseline, arm=arm, figures=False, payload_at=(key, position), profile_payload_mass=False)
    # the hand position's figures need a --repeat pair: without one nothing measures a session's change of gravity's shape,
    # and no payload is told from that change
    payload = result["payload_not_distinguished"]
    assert abs(truth) < 1e-6
    low, high = payload["gravity_efforts_at_q0_interval"][0]
    assert low <= truth <= high, payload["gravity_efforts_at_q0_interval"][0]
    at = payload["payload_at"]
    assert at["gravity_efforts_at_q0_interval"][0] is None and at["not_determined"]["gravity_efforts_at_q0"] == AT_POSITION_WITHOUT_REPEAT
    assert payload["gravity_efforts_at_q0"][0] < -0.005  # the first moment's own reading is still the biased one


def test_the_real_pitch_weight_reads_j1_differently_with_a_rigid_path(arm):
    """The real 105 g on the pitch link (one-105g minus one-no-weight, measured
    efforts): a rigid path reads J1's gravity effort at q = 0 some 0.036 N·m
    above a path without inertia (-0.007 against -0.043 N·m), for fits of J1
    within 0.003 N·m RMS of each other: what the diagnoses' J1 intervals must span."""
    key = arm.model.link_by_name("pitch").key
    weighted, baseline = (process(load_run(resolve_run(name), arm.model)) for name in ("one-105g", "one-no-weight"))
    n = min(len(weighted.t), len(baseline.t))
    weighted = weighted.head(n)
    features = TrajectoryFeatures(arm, weighted.q, weighted.dq, weighted.ddq, np.zeros_like(weighted.q), weighted.rate_hz)
    gap = weighted.tau[:, 0] - baseline.tau[:n, 0]
    readings = path_readings(arm, key, [(gap, features, type("Run", (), {"state": weighted})(), False)])
    assert readings[BARE_PATH]["gravity_efforts_at_q0"] == pytest.approx(-0.043, abs=0.005)
    assert readings[RIGID_PATH]["gravity_efforts_at_q0"] - readings[BARE_PATH]["gravity_efforts_at_q0"] == pytest.approx(0.036, abs=0.01)


def test_a_j1_the_runs_did_not_record_gets_no_path_models():
    """q1 not recorded: its figures are nulled later (`without_unrecorded_joints`); the path models were
    read from the log's zeros and left a sentence on them before (review of the change)."""
    report = {"link_key": 2, "gravity_efforts_at_q0": [0.01, 0.2], "gravity_efforts_at_q0_interval": [[0.0, 0.02], [0.1, 0.3]], "words": []}
    problem = type("Problem", (), {"recorded": np.array([False] + [True] * 6)})()
    span_both_path_models(problem, {}, [report], None, periodic=False, payloads=[0])
    assert report["gravity_efforts_at_q0_interval"][0] == [0.0, 0.02] and report["words"] == [] and "yaw_path_models" not in report


def test_the_jackknife_interval_takes_students_t_with_the_folds_degrees_of_freedom():
    """Five folds: the half-width is t(0.95, 4) = 2.132 standard errors, not the normal law's 1.645
    (the hand position's J1 interval held the truth in 9 of 12 synthetic pairs with it, 11 of 12 now)."""
    from dvrk_dart.diagnosis.payload.intervals import central_interval, jackknife_error

    folds = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    se = np.sqrt(4 / 5 * np.sum((folds - 3.0) ** 2))
    low, high = central_interval(np.array(3.0), *jackknife_error(folds))
    assert (high - 3.0) / se == pytest.approx(2.132, abs=1e-3) and 3.0 - low == pytest.approx(high - 3.0)

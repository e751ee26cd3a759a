"""What the gap means at the instrument (model/force.py, `dvrk-dart force`)."""

import json

import numpy as np
import pytest

from dvrk_dart.model.force import estimate_force, point_positions, positional_jacobian
from dvrk_dart.cli import main
from dvrk_dart.io.reference_data import load_run, resolve_run
from arms import PSM, PSM_ARM  # noqa: F401

#: measured independently (the issue): the published model's periodic residual on
#: held-out "two" at the wrist centre, every sample: 1.10 N RMS, per axis 0.63 / 0.81 / 0.38 N
PUBLISHED_PHANTOM_N = 1.10


@pytest.fixture(scope="module")
def arm():
    return PSM_ARM


def test_the_jacobian_moves_the_point_as_the_joints_do(arm):
    """J dq against the point's displacement over a small step, on the run's own states."""
    run = load_run(resolve_run("two"), PSM)
    q, dq = run.q[::50], run.dq[::50]
    point = arm.model.force_point
    J = positional_jacobian(arm.model, q, point)
    h = 1e-4
    moved = (point_positions(arm.model, q + h * dq, point.link) - point_positions(arm.model, q, point.link)) / h
    predicted = np.einsum("nij,nj->ni", J, dq[:, list(point.joints)])
    assert np.max(np.abs(moved - predicted)) < 1e-3 * np.max(np.abs(predicted))


def test_a_force_is_recovered_from_the_efforts_it_causes(arm):
    """tau = J^T F at the run's states: the estimate gives F back where the levers allow, NaN where not."""
    run = load_run(resolve_run("two"), PSM)
    q = run.q[::20]
    J = positional_jacobian(arm.model, q, arm.model.force_point)
    force = np.random.default_rng(0).normal(0.0, 2.0, (len(q), 3))
    tau = np.zeros((len(q), 7))
    tau[:, :3] = np.einsum("nji,nj->ni", J, force)
    estimate = estimate_force(arm.model, q, tau)
    known = np.all(np.isfinite(estimate.force), axis=1)
    assert known.mean() > 0.9 and np.allclose(estimate.force[known], force[known], atol=1e-9)
    assert np.all(estimate.lever_m[~known] < arm.model.force_point.min_lever_m)


def test_the_published_models_phantom_force_on_two(tmp_path, capsys):
    """Free motion: the force the published model's residual implies, every sample, within 5 % of the
    independent figure; what the diagnosis's one configuration would imply is checked in make validate."""
    assert main(["force", "--measured", "two", "--out", str(tmp_path / "force")]) == 0
    summary = json.loads((tmp_path / "force" / "force.json").read_text())
    assert summary["processing"] == "periodic"
    assert abs(summary["rms_all_samples_n"] - PUBLISHED_PHANTOM_N) <= 0.05 * PUBLISHED_PHANTOM_N, summary["rms_all_samples_n"]
    assert np.allclose(summary["rms_per_axis_all_samples_n"], [0.63, 0.81, 0.38], atol=0.03)
    assert summary["rms_n"] < summary["rms_all_samples_n"] and 0.9 < summary["determined_fraction"] < 1.0
    for name in ("force.csv", "force.mcap", "force.rrd"):
        assert (tmp_path / "force" / name).stat().st_size > 0
    header = (tmp_path / "force" / "force.csv").read_text().splitlines()[0]
    assert header.startswith("t_s,fx_n,fy_n,fz_n")


def test_force_refuses_a_bad_dynamics_file_in_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["force", "--measured", "two", "--dynamics", str(bad), "--out", str(tmp_path / "f")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad.json" in err and not (tmp_path / "f").exists()


def test_a_diagnosis_against_a_baseline_is_no_arm_to_estimate_a_force_with(tmp_path, capsys):
    """A payload diagnosis (--baseline) simulates what the runs differ by, not the arm: its sim_config (the
    inertia alone, the payload not in it) made the phantom force 3.5 N where the identified model's is 1.1 N."""
    difference = tmp_path / "diagnosis.json"
    difference.write_text(json.dumps({"baseline": "one-no-weight", "sim_config": {}}))
    for command in ("force", "replay"):
        assert main([command, "--measured", "two", "--dynamics", str(difference), "--out", str(tmp_path / command)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "--baseline one-no-weight" in err and not (tmp_path / command).exists(), err


def test_a_contact_in_dart_is_estimated_from_the_simulated_efforts(arm):
    """The sim-to-sim check: the instrument pressing 1 cm into a 500 N/m surface while
    replaying "two"; the estimate from DART's efforts with the model it was built from."""
    from dvrk_dart.diagnosis.effects.library import config_effort_by_formula
    from dvrk_dart.io.signal import process
    from dvrk_dart.runs.contact import contact_check, simulate_contact, surface_under
    from dvrk_dart.sim.config import SimConfig

    state = process(load_run(resolve_run("two"), PSM), "upstream")
    run = simulate_contact(arm, state, surface_under(arm, state, 0.01), 8.0)
    check = contact_check(arm, run, config_effort_by_formula(arm, SimConfig(), run.q, run.dq, run.ddq))
    assert check["in_contact_fraction"] > 0.01 and np.abs(run.contact_force).max() > 1.0
    assert check["sim_to_sim_error_rms_n"] < 1e-3, check


def test_the_mtm_handle_force(tmp_path):
    """The MTM: the force at its handle in free motion, what a haptic loop would render."""
    assert main(["force", "--arm-model", "mtm", "--measured", "mtm-two", "--out", str(tmp_path / "mtm")]) == 0
    summary = json.loads((tmp_path / "mtm" / "force.json").read_text())
    assert summary["point_link"] == "wrist_platform" and 0.0 < summary["rms_n"] < 10.0


def test_force_with_an_excitation_is_periodic_says_so_and_records_the_file(tmp_path, capsys):
    """`--excitation` with `--processing upstream` ran and ignored the file; the file was not recorded."""
    from recordings import DATA_2018

    excitation = str(DATA_2018 / "psm1_fourier_test2_commanded.csv")
    assert main(["force", "--measured", "2018-test2", "--excitation", excitation, "--processing", "upstream",
                 "--out", str(tmp_path / "up")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--excitation" in err[0] and "upstream" in err[0] and not (tmp_path / "up").exists(), err
    assert main(["force", "--measured", "2018-test2", "--excitation", excitation, "--out", str(tmp_path / "f")]) == 0
    summary = json.loads((tmp_path / "f" / "force.json").read_text())
    assert summary["processing"] == "periodic" and summary["chosen_because"].startswith("--excitation")
    assert summary["inputs"]["excitation"]["path"] == excitation and len(summary["inputs"]["excitation"]["sha256"]) == 64

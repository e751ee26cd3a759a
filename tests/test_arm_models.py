"""Every arm in models/ (the Menagerie habit): it loads, builds in Pinocchio and
in DART, closes its loops, and its static efforts in DART equal g(q) from
Pinocchio; each reproduces its identification's published test errors."""

import json

import numpy as np
import pytest

from dvrk_dart.cli import main
from dvrk_dart.io.arm import load_arm
from dvrk_dart.paths import MODELS_DIR
from dvrk_dart.sim.config import SimConfig
from dvrk_dart.sim.simulator import PsmSimulator

ARMS = sorted(p.name for p in MODELS_DIR.iterdir() if (p / f"{p.name}.toml").is_file())
#: relative errors on "two", first period, of each arm's published parameters (its data README)
PUBLISHED = {
    "psm": ("two", [0.0929, 0.1783, 0.1907, 0.1345, 0.2394, 0.2125, 0.2642]),
    "mtm": ("mtm-two", [0.0769, 0.1485, 0.1695, 0.2232, 0.2800, 0.2342, 0.3395]),
}


@pytest.fixture(scope="module", params=ARMS)
def arm_of(request):
    return request.param, load_arm(MODELS_DIR / request.param / f"{request.param}.toml")


def test_every_arm_folder_is_complete():
    assert {"psm", "mtm"} <= set(ARMS)
    for name in ARMS:
        assert (MODELS_DIR / name / "README.md").is_file(), f"{name}: no model card"


def test_every_arm_closes_its_loops_and_holds_its_gravity_in_dart(arm_of):
    """Random poses: the closed chain in DART holds its loops to 1e-12 m, its
    frames are the model's, and the efforts that hold it still are Pinocchio's g(q)."""
    name, arm = arm_of
    model = arm.model
    sim = PsmSimulator(model, arm.params, SimConfig())
    rng = np.random.default_rng(2)
    for _ in range(10):
        q = rng.uniform(model.joint_lower, model.joint_upper)
        sim.set_kinematic(q)
        assert sim.closure_residual_m() < 1e-12, name
        frames = model.forward_kinematics(q)
        for key in sim.psm.bodies:
            np.testing.assert_allclose(sim.link_transform(key), frames[key], atol=1e-12)
        sim.reset(q)
        sim.step_velocity(np.zeros(len(q)), q)
        g = arm.identified.gravity(sim.q)
        np.testing.assert_allclose(sim.last_effort, g, atol=1e-3 * max(1.0, np.max(np.abs(g))))


@pytest.mark.parametrize("name", sorted(PUBLISHED))
def test_every_arm_reproduces_its_published_errors(name, capsys):
    run, published = PUBLISHED[name]
    capsys.readouterr()
    assert main(["model-errors", "--arm-model", name, "--measured", run, "--first-period", "--json", "--processing", "upstream"]) == 0
    errors = json.loads(capsys.readouterr().out)["relative_error"]
    np.testing.assert_allclose(errors, published, atol=1e-3)


def test_the_mtm_replays_two_in_dart(tmp_path, capsys):
    """The MTM's velocity replay of "two": the inertial arm (DART's physical
    inertias) within 0.01 N·m of the model on J1..J3, its parallelogram closed
    to 1e-9 m; the identified arm (friction, offsets, the linkage spring, motor
    inertia as physics) as close to the measured efforts as the model, within 0.01."""
    for dynamics in ("inertial", "identified"):
        out = tmp_path / dynamics
        assert main(["replay", "--arm-model", "mtm", "--measured", "mtm-two", "--dynamics", dynamics, "--out", str(out)]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["closure_residual_max_m"] < 1e-9
        # the report's rows of an MTM run carry the MTM's facts, whatever arm the report runs under
        from dvrk_dart.analysis.tables import _load_and_measure

        loaded, rows, error = _load_and_measure(str(out))
        assert error is None and loaded.counterweight == "none"
        assert set(rows[rows.joint == "q3"].unit) <= {"N·m", "rad", "1"}
        # its first period is the MTM's 2000 samples at 200 Hz (10 s), not the PSM's 1111
        first = rows[(rows.quantity == "samples") & (rows.regime == "first_period") & (rows.joint == "q1")].value
        assert len(first) == 1 and first.iloc[0] == np.sum(loaded.record.t < 10.0) > np.sum(loaded.record.t < 1111 / 200)
        if dynamics == "inertial":
            assert np.all(np.array(metrics["rms_sim_vs_model"][:3]) <= 0.01), metrics["rms_sim_vs_model"]
        else:
            gap = np.array(metrics["rms_sim_vs_measured"][:3]) - np.array(metrics["rms_model_vs_measured"][:3])
            assert np.all(np.abs(gap) <= 0.01), gap


def test_an_mtm_bag_reads_like_its_csv(tmp_path, capsys):
    """/MTML/measured_js (seven joints by the dVRK's names, no jaw topic) -> the
    run's model coordinates: the published errors of "two" come back from the bag."""
    from dvrk_dart.io.bag_writer import arm_joint_states, write_bag
    from dvrk_dart.io.reference_data import load_run, resolve_run

    from arms import MTM

    run = load_run(resolve_run("mtm-two"), MTM)
    states = arm_joint_states(MTM, None, 1.7e9 + run.t, run.q, run.dq, run.tau)
    bag = write_bag(tmp_path / "mtm_two", states)
    assert [s.topic for s in states] == ["/MTML/measured_js"] and len(states[0].names) == 7
    capsys.readouterr()
    assert main(["model-errors", "--arm-model", "mtm", "--measured", str(bag), "--first-period", "--json", "--processing", "upstream"]) == 0
    errors = json.loads(capsys.readouterr().out)["relative_error"]
    np.testing.assert_allclose(errors, PUBLISHED["mtm"][1], atol=1e-3)

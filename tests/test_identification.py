"""`dvrk-dart identify`: the regressor is the identified model's, the base
parameters are exact, the fit recovers known parameters, the result is
physically consistent and predicts the held-out run as well as the published
parameters, and bad input gives one line."""

import json

import numpy as np
import pytest

from dvrk_dart.cli import main
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.base import find_base_parameters
from dvrk_dart.identification.fit import DEFAULT_BOUNDS_FILE as DEFAULT_BOUNDS
from dvrk_dart.identification.fit import fit_weighted, load_bounds
from dvrk_dart.identification.identify import (
    IdentificationConfig,
    check_consistent_runs,
    identify,
)
from dvrk_dart.identification.outputs import (
    COVARIANCE_FORMAT,
    reference_theta,
    standard_covariance,
    write_outputs,
)
from dvrk_dart.identification.regressor import (
    FrictionLaw,
    Regressor,
    params_json,
    standard_vector,
)
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import process
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.model.parameters import load_parameters
from dvrk_dart.model.pseudo_inertia import pseudo_inertia
from arms import PSM, PSM_ARM  # noqa: F401

#: relative errors on "two", first period, of the published parameters (data README)
PUBLISHED = np.array([0.0929, 0.1783, 0.1907, 0.1345, 0.2394, 0.2125, 0.2642])


@pytest.fixture(scope="module")
def regressor(model):
    return Regressor(model)


@pytest.fixture(scope="module")
def result():
    """The upstream-processed identification (the published comparison)."""
    return identify(IdentificationConfig(runs=("one",), holdout=("two",), processing="upstream"))


def test_regressor_is_the_identified_model(regressor, identified, params, processed_two):
    """Y theta(published) = IdentifiedModel.predict, every term, to rounding."""
    run = processed_two.head(400)
    Y = regressor(run.q, run.dq, run.ddq)
    theta = standard_vector(params, regressor.layout)
    expected = identified.predict(run.q, run.dq, run.ddq, "all")
    assert np.max(np.abs(Y @ theta - expected)) < 1e-9 * max(1.0, np.max(np.abs(expected)))


def test_params_json_round_trip(regressor, model, params, tmp_path):
    theta = standard_vector(params, regressor.layout)
    path = tmp_path / "params.json"
    path.write_text(json.dumps(params_json(theta, regressor.layout, model)))
    back = standard_vector(load_parameters(path, model), regressor.layout)
    assert np.allclose(back, theta, rtol=1e-10, atol=1e-12)


def test_base_parameters_reproduce_the_regressor(regressor, model):
    base = find_base_parameters(regressor, seed=0)
    other = find_base_parameters(regressor, seed=1)
    assert len(base) == len(other) and 40 < len(base) < len(regressor.layout)
    rng = np.random.default_rng(7)
    q = rng.uniform(model.joint_lower, model.joint_upper, (50, N_JOINTS))
    dq, ddq = rng.normal(size=(50, N_JOINTS)), rng.normal(size=(50, N_JOINTS))
    Y = regressor(q, dq, ddq)
    theta = rng.normal(size=len(regressor.layout))
    full, reduced = Y @ theta, Y[:, :, base.independent] @ base.beta(theta)
    assert np.max(np.abs(full - reduced)) < 1e-9 * np.max(np.abs(full))
    # a mass on a link that only translates along the yaw-pitch chain is identifiable; link 4's
    # inertia about axes it never turns about is not
    names = regressor.layout.names
    assert base.identifiable[names.index("link8.m")]
    assert not base.identifiable[names.index("link4.Ixx")]


def test_fit_recovers_known_parameters(result, tmp_path):
    """Efforts synthesised from the identified parameters, plus noise of the
    measured size, are identified again: the base parameters within 4 standard
    errors and the consistent fit's predictions within the noise."""
    rng = np.random.default_rng(3)
    truth = result.theta
    run = result.train[0]
    noisy = run.Y @ truth + rng.normal(size=run.processed.tau.shape) * result.wls.sigma
    from dvrk_dart.identification.fit import fit_consistent, fit_weighted

    Yb = run.Y[:, :, result.base.independent]
    wls = fit_weighted(Yb, noisy, result.wls.joints, "synthetic")
    z = (wls.beta - result.base.beta(truth)) / wls.standard_errors
    assert np.max(np.abs(z)) < 4.0
    fit = fit_consistent(wls, result.base, result.regressor.layout, result.bounds, result.prior_theta)
    error = run.Y @ fit.theta - run.Y @ truth
    assert np.all(np.sqrt(np.mean(error**2, axis=0)) < 0.2 * result.wls.sigma)


def test_identification_is_physical_and_predicts_the_held_out_run(result):
    layout = result.regressor.layout
    for key in layout.inertial_links:
        from dvrk_dart.identification.regressor import body_of

        eig = np.linalg.eigvalsh(pseudo_inertia(*body_of(result.theta, layout, key)))
        assert eig[0] >= -1e-9, key
        lower, upper = result.bounds.mass_kg[key]
        assert lower <= result.theta[layout.body_slice(key)][0] <= upper
    friction = [i for i, n in enumerate(layout.names) if n.endswith((".Fc", ".Fv"))]
    assert np.all(result.theta[friction] >= 0.0)
    held_out = np.array(result.errors(result.holdout[0], first_period=True)["relative_error"])
    # at most 2 % above the published errors on every joint (the acceptance)
    assert np.all(held_out <= 1.02 * PUBLISHED), held_out / PUBLISHED
    train = np.array(result.errors(result.train[0])["relative_error"])
    assert np.all(train < held_out + 0.02)  # no overfitting beyond the day-to-day difference


def test_outputs_and_covariance(result, model, tmp_path):
    data = write_outputs(result, tmp_path)
    params = load_parameters(tmp_path / "params.json", model)
    assert np.allclose(standard_vector(params, result.regressor.layout), result.theta, rtol=1e-9, atol=1e-12)
    # the file as every --params reader sees it is physical (the published one: -1.9e-6 kg m^2)
    for key in result.regressor.layout.inertial_links:
        p = params[key]
        assert np.linalg.eigvalsh(pseudo_inertia(p.mass, p.com, p.inertia_com))[0] >= -1e-9, key
    cov = json.loads((tmp_path / "params_covariance.json").read_text())
    assert cov["format"] == COVARIANCE_FORMAT and cov["names"] == list(result.regressor.layout.names)
    C = np.array(cov["covariance"])
    assert C.shape == (len(cov["names"]),) * 2 and np.allclose(C, C.T)
    assert np.linalg.eigvalsh(C)[0] > -1e-12 * np.max(np.abs(C))
    # the covariance moves the efforts only as much as the base parameters' covariance says
    K = result.base.K
    assert np.allclose(K @ standard_covariance(result) @ K.T, result.wls.covariance, rtol=1e-6, atol=1e-18)
    assert data["n_base"] == len(result.base) and data["condition_number"] < 1e4
    assert set(data["identifiable"]) | set(data["set_by_constraints_and_prior"]) == set(cov["names"])
    assert "data:image/png;base64" in (tmp_path / "identification.html").read_text()


def _constant_pose_csv(path, rows=500):
    q = np.array([0.1, 0.2, 0.1, 0.0, 0.0, 0.0, 0.0])
    efforts = np.linspace(0.1, 0.7, 7) + 1e-3 * np.random.default_rng(0).standard_normal((rows, 7))  # a held arm's sensor noise
    values = np.hstack([np.tile(q, (rows, 1)), np.zeros((rows, 7)), efforts])
    np.savetxt(path, values, delimiter=",")
    return path


def test_unexciting_run_is_refused_in_one_line(tmp_path, capsys):
    run = _constant_pose_csv(tmp_path / "still.csv")
    out = tmp_path / "out"
    assert main(["identify", "--runs", str(run), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "condition number" in err
    assert not out.exists()


def test_too_short_a_run_is_refused_in_one_line(tmp_path, capsys):
    """402 rows of a real 3-joint run left 2 samples after the processing's
    trim: a LinAlgError traceback in the fit. Refused at loading now, and the
    fit itself refuses fewer equations than base parameters."""
    rows = np.loadtxt(resolve_run("2018-test1"), delimiter=",")[1000:1402]
    run = tmp_path / "short.csv"
    np.savetxt(run, rows, delimiter=",")
    out = tmp_path / "out"
    assert main(["identify", "--runs", str(run), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "short.csv" in err and "402 rows, at least 410 needed" in err
    assert not out.exists()
    Yb = np.random.default_rng(0).normal(size=(2, N_JOINTS, 26))
    with pytest.raises(DvrkDartError, match="6 equations .* more than its 26 base parameters"):
        fit_weighted(Yb, np.zeros((2, N_JOINTS)), np.array([0, 1, 2]), "--runs short.csv")


def test_a_short_run_without_holdout_says_its_reach_is_not_measured(tmp_path, capsys):
    """700 rows (3.5 s, not periodic) of a real 3-joint run: the fit runs, and
    says how much it rests on and that nothing measured how far it carries."""
    rows = np.loadtxt(resolve_run("2018-test1"), delimiter=",")[:700]
    run = tmp_path / "short700.csv"
    np.savetxt(run, rows, delimiter=",")
    assert main(["identify", "--runs", str(run), "--out", str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert "from 1 run(s), 1.5 s:" in printed and "note: no --holdout run" in printed


def test_inconsistent_runs_are_refused(tmp_path, capsys):
    bad = tmp_path / "twenty.csv"
    np.savetxt(bad, np.zeros((500, 20)), delimiter=",")
    assert main(["identify", "--runs", "one", str(bad), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "twenty.csv" in err and "20 columns" in err
    # runs of different rates go together: each is processed at its own
    from dvrk_dart.identification.identify import RunData

    a = process(load_run(resolve_run("two"), PSM))
    b = type(a)(a.t * 2.0, a.q, a.dq, a.ddq, a.tau)
    check_consistent_runs([RunData("a", tmp_path / "a.csv", a, None), RunData("b", tmp_path / "b.csv", b, None)])


def test_options_are_checked(model, tmp_path):
    with pytest.raises(DvrkDartError, match="--joints"):
        identify(IdentificationConfig(runs=("one",), joints=("q9",)))
    with pytest.raises(DvrkDartError, match="reversal"):
        FrictionLaw("tanh", None)
    bounds = tmp_path / "bounds.toml"
    bounds.write_text("[mass_bounds_kg]\n1 = [2.0, 1.0]\n")
    with pytest.raises(DvrkDartError, match="lower <= upper"):
        load_bounds(bounds, model)


def test_report_section_compares_with_the_published_parameters(tmp_path):
    """The validation report's section: per joint, the published parameters and
    ours on the held-out run, the numbers of identification.json."""
    from dvrk_dart.pipeline import _identification_section

    title, body = _identification_section(tmp_path)
    assert "published" in title
    for folder, processing in (("identification", "periodic"), ("identification-upstream", "upstream")):
        data = json.loads((tmp_path / folder / "identification.json").read_text())
        assert json.loads((tmp_path / folder / ".dvrk-dart").read_text())["kind"] == "identification"
        assert data["processing"]["processing"] == processing
        for j, value in enumerate(data["errors"]["holdout"]["two"]["first_period"]["relative_error"]):
            assert f'data-identification="relative_error_identified" data-run="two" data-joint="q{j + 1}" data-processing="{processing}" data-value="{value!r}"' in body
    published = data["reference"]["errors_first_period"]["two"]["relative_error"]
    assert np.allclose(published, PUBLISHED, atol=1e-4)  # the published file reproduces the published numbers


def test_bounds_file_is_honoured(tmp_path):
    """A site's bounds file: the pitch link's mass pinned to 2 kg is obeyed."""
    text = DEFAULT_BOUNDS.read_text().replace("2 = [0.1, 10.0]", "2 = [2.0, 2.0]")
    bounds = tmp_path / "bounds.toml"
    bounds.write_text(text)
    pinned = identify(IdentificationConfig(runs=("one",), bounds_file=str(bounds)))
    mass = pinned.theta[pinned.regressor.layout.body_slice(2)][0]
    assert abs(mass - 2.0) < 1e-6


def test_a_bounds_file_with_a_name_it_does_not_know_is_refused(tmp_path):
    """A misspelt [presliding] key left the revolute joints on the sign law; an upper bound over the card's
    plausible mass was refused only after the fit, by the reader of its params.json."""
    for old, new, words in (("revolute_rad =", "revolute_radd =", r"\[presliding\] revolute_radd: not one of prismatic_m, revolute_rad"),
                            ("[presliding]", "[pre-sliding]", r"\[pre-sliding\] is not a section of a bounds file"),
                            ("2 = [0.1, 10.0]", "2 = [0.1, 30.0]", r"mass_bounds_kg.2: upper 30 kg at or above the plausible 20 kg")):
        bounds = tmp_path / "bounds.toml"
        bounds.write_text(DEFAULT_BOUNDS.read_text().replace(old, new))
        with pytest.raises(DvrkDartError, match=words):
            load_bounds(bounds, PSM)


def test_model_errors_reads_the_identified_file(result, tmp_path, capsys):
    """The acceptance path: `model-errors --measured two --first-period --params
    DIR/params.json` gives the held-out numbers of identification.json."""
    data = write_outputs(result, tmp_path)
    capsys.readouterr()
    assert main(["model-errors", "--measured", "two", "--first-period", "--json", "--processing", "upstream", "--params", str(tmp_path / "params.json")]) == 0
    printed = json.loads(capsys.readouterr().out)
    expected = data["errors"]["holdout"]["two"]["first_period"]["relative_error"]
    assert np.allclose(printed["relative_error"], expected, rtol=1e-9)


# ------------------------------------------------------------ periodic processing
@pytest.fixture(scope="module")
def periodic_result():
    return identify(IdentificationConfig(runs=("one",), holdout=("two",), processing="periodic"))


def test_periodic_identification_is_physical_and_records_its_processing(periodic_result, tmp_path):
    """Every pseudo-inertia positive semidefinite; identification.json says
    which processing, period, harmonics and noise each run had."""
    result = periodic_result
    layout = result.regressor.layout
    from dvrk_dart.identification.regressor import body_of

    for key in layout.inertial_links:
        assert np.linalg.eigvalsh(pseudo_inertia(*body_of(result.theta, layout, key)))[0] >= -1e-9, key
    data = write_outputs(result, tmp_path)
    runs = data["processing"]["runs"]
    assert data["processing"]["processing"] == "periodic" and set(runs) == {"one", "two"}
    for summary in runs.values():
        assert abs(summary["period_s"] - 6.48) < 0.01 * 6.48 and summary["harmonics"] >= 6
        assert len(summary["noise_rms"]) == N_JOINTS


def test_periodic_identification_on_the_held_out_run(periodic_result):
    """Held-out "two", periodic on both sides: no joint of J1..J3 worse than the
    published parameters (the issue's acceptance). With the sign law J3 came out
    1-4 % worse: its friction reverses over about 0.1 mm (the pre-sliding law,
    chosen on "one"), which a model of the instantaneous velocity cannot follow."""
    result = periodic_result

    own = np.array(result.errors(result.holdout[0])["rms"][:3])
    run = result.holdout[0].processed
    published = PSM_ARM.identified.predict(run.q, run.dq, run.ddq)
    theirs = np.sqrt(np.mean((run.in_band(published) - run.tau) ** 2, axis=0))[:3]
    assert np.all(own <= theirs), (own, theirs)
    assert own[0] < 0.8 * theirs[0] and own[1] < 0.9 * theirs[1], (own, theirs)  # measured 0.55x, 0.81x
    # the same on the first period, against the published parameters' relative error (the upstream metric)
    relative = np.array(result.errors(result.holdout[0], first_period=True)["relative_error"][:3])
    theta_published = reference_theta(result)[0]
    reference = np.array(result.errors(result.holdout[0], first_period=True, theta=theta_published, sign_law=True)["relative_error"][:3])
    assert np.all(relative <= reference), (relative, reference)


def test_the_presliding_distances_are_chosen_on_the_training_run(periodic_result):
    """Every friction link has a distance from the bounds file's candidates (0:
    sign), chosen by the training residual; the insertion stage's about 0.1 mm."""
    choice = periodic_result.presliding_choice
    law = periodic_result.regressor.friction_law
    assert set(choice) == {str(k) for k in periodic_result.regressor.layout.friction_links}
    for key, entry in choice.items():
        assert entry["distance"] == law.distance(int(key))
        assert min(entry["score_by_distance"].values()) == entry["score_by_distance"][f"{entry['distance']:g}"]
    assert 3e-5 <= law.distance(8) <= 3e-4


def _simulated_periodic_run(path, truth_Y_theta, positions, t, noise_std, rng):
    """A measured run (CSV) of the given efforts plus white noise of known std per joint."""
    from dvrk_dart.io.reference_data import MeasuredRun

    import pandas as pd

    from dvrk_dart.io.reference_data import CSV_COLUMNS

    values = np.hstack([positions[0], positions[1], truth_Y_theta + rng.normal(size=truth_Y_theta.shape) * noise_std])
    data = pd.DataFrame(values, columns=CSV_COLUMNS)
    data.insert(0, "t", t)
    return MeasuredRun(path, data, PSM)


def test_periodic_standard_errors_match_the_scatter_over_noise_draws(periodic_result, tmp_path):
    """Simulated periodic runs (the identified parameters on the analytic motion
    of "one", white effort noise of the measured size): over 20 noise draws the
    base parameters scatter as the stated standard errors say, within a factor
    1.5. The efforts are made with the friction in its periodic steady state
    (the motion run from one period before): a state started at the first sample
    has a transient that does not repeat, which the noise estimate would count."""
    from dvrk_dart.identification.identify import RunData, _weighted_fit

    result = periodic_result
    clean = result.train[0].processed
    positions, step = clean.periodic.positions, clean.t[1] - clean.t[0]
    before = int(round(clean.periodic.period.period_s / step))
    t = np.r_[clean.t[0] - step * np.arange(before, 0, -1), clean.t]
    efforts = (result.regressor(positions(t), positions(t, 1), positions(t, 2)) @ result.theta)[before:]
    noise_std = np.array(clean.periodic.effort_noise.per_sample_rms)
    rng = np.random.default_rng(11)
    betas, stated = [], []
    for draw in range(20):
        measured = _simulated_periodic_run(tmp_path / f"draw{draw}.csv", efforts, (clean.q, clean.dq), clean.t, noise_std, rng)
        run = process(measured, "periodic", harmonics=clean.periodic.harmonics)
        data = RunData("draw", measured.path, run, run.in_band(result.regressor(run.q, run.dq, run.ddq)))
        wls = _weighted_fit([data], result.base, result.wls.joints, "draw")
        betas.append(wls.beta)
        stated.append(wls.standard_errors)
    scatter = np.std(betas, axis=0, ddof=1)
    ratio = scatter / np.mean(stated, axis=0)
    # 20 draws: a standard deviation is known to ~16 %; the median over the 49 parameters to a few %
    assert 1 / 1.5 < np.median(ratio) < 1.5, np.median(ratio)
    assert np.mean((ratio > 1 / 1.5) & (ratio < 1.5)) > 0.9, np.sort(ratio)


def test_the_reference_data_facts_of_the_runs_are_said(tmp_path):
    """Training runs the manifest says carry different weights, or come from different repositories, get a warning; a
    held-out run with another weight than the training's too (beside a file the manifest does not list); runs of one
    weight and one repository, and a file it does not list, none."""
    from types import SimpleNamespace

    from dvrk_dart.identification.identify import IdentificationResult

    def warnings(train, holdout=()):
        def runs(names):
            return [SimpleNamespace(name=name, path=resolve_run(name)) for name in names]
        return IdentificationResult.recording_warnings(SimpleNamespace(train=runs(train), holdout=runs(holdout)))

    mixed = warnings(["one", "one-105g"], ["two"])
    assert len(mixed) == 1 and "one-105g 0.105 kg" in mixed[0] and "one no weight" in mixed[0]
    held = warnings(["one-105g", "one-105g-half"], ["two", "one-105g-insertion"])
    assert len(held) == 1 and held[0].startswith("two carries no weight, the training runs 0.105 kg")
    datasets = warnings(["one", "2018-test1"])
    assert len(datasets) == 1 and "different repositories" in datasets[0] and "radiang/dvrk_parameter_identification" in datasets[0]
    copy = tmp_path / "mine.csv"  # not the manifest's content: no facts
    copy.write_text(resolve_run("one-105g").read_text() + "\n")
    assert warnings(["one", "one-no-weight"], ["two"]) == [] and warnings(["one", str(copy)], ["two"]) == []
    assert warnings(["one-105g", str(copy)], ["two"])[0].startswith("two carries no weight, the training runs 0.105 kg")

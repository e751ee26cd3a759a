"""Monte Carlo over parameter uncertainty: consistent samples, the band, the
measured run in it."""

import json

import numpy as np
import pandas as pd
import pytest

from dvrk_dart.cli import main
from dvrk_dart.identification.sampling import project_body, sample_parameters
from dvrk_dart.model.pseudo_inertia import pseudo_inertia_of_dynamic_parameters
from dvrk_dart.runs.uncertainty import band_statistics

#: the band must hold the nominal model's efforts almost everywhere: at 5-95 %
#: over a handful of samples a few percent of the samples may sit on its edge
NOMINAL_INSIDE_MIN = 0.9


def test_projection_gives_a_consistent_body_and_keeps_consistent_ones():
    consistent = np.array([0.5, 0.01, 0.0, 0.02, 0.003, 0.0, 0.003, 0.0, 0.0, 0.001])
    assert np.array_equal(project_body(consistent)[0], consistent)
    broken = consistent.copy()
    broken[9] = 0.02  # Izz above Ixx + Iyy: a triangle inequality broken
    fixed, moved = project_body(broken)
    assert moved and np.linalg.eigvalsh(pseudo_inertia_of_dynamic_parameters(fixed))[0] >= -1e-12


def test_samples_are_physically_consistent(arm):
    drawn = sample_parameters(arm, 16, seed=1, relative_std=0.05)
    assert len(drawn.samples) == 16 and "relative std 0.05" in drawn.source
    for sample in drawn.samples[:4]:
        for key, link in sample.items():
            assert link["Fc"] >= 0.0 and link["Fv"] >= 0.0
    masses = np.array([[s[k]["m"] for k in sorted(s, key=int)] for s in drawn.samples])
    nominal = np.array([drawn.nominal[k]["m"] for k in sorted(drawn.nominal, key=int)])
    spread = masses.std(axis=0)[nominal > 0] / nominal[nominal > 0]
    assert np.all((spread > 0.01) & (spread < 0.1))  # about the asked 5 %


def test_band_statistics_count_inside_and_measure_outside():
    low, high = np.zeros((4, 1)), np.ones((4, 1))
    inside, gap = band_statistics(low, high, np.array([[0.5], [1.0], [2.0], [-1.0]]))
    assert inside[0] == 0.5 and np.isclose(gap[0], np.sqrt((1.0 + 1.0) / 4))


def test_uncertainty_cli_writes_the_band_and_the_fractions(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["uncertainty", "--measured", "two", "--samples", "6", "--duration", "1", "--relative-std", "0.05", "--out", str(out)]) == 0
    summary = json.loads((out / "uncertainty.json").read_text())
    assert summary["samples_replayed"] == 6 and "relative std 0.05" in summary["parameters"]
    assert all(0.0 <= f <= 1.0 for f in summary["measured_inside_band_fraction"])
    assert min(summary["nominal_model_inside_band_fraction"][:3]) >= NOMINAL_INSIDE_MIN
    assert len(list((out / "params").glob("sample_*.json"))) == 6 and (out / "band.csv").is_file()
    assert {p.name for p in (out / "figures").iterdir()} == {"band_q1.png", "band_q2.png", "band_q3.png"}
    assert "inside" in capsys.readouterr().out


def test_a_three_joint_run_has_no_band_figure_on_the_joints_it_did_not_record(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["uncertainty", "--measured", "2018-test1", "--samples", "2", "--duration", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "uncertainty.json").read_text())
    assert summary["recorded_joints"] == ["q1", "q2", "q3"]
    for key in ("measured_inside_band_fraction", "rms_measured_outside_band", "rms_nominal_sim_vs_measured",
                "nominal_model_inside_band_fraction", "band_width_rms"):
        assert summary[key][3:] == [None] * 4 and all(v is not None for v in summary[key][:3]), key
    assert capsys.readouterr().out.count("not measured") == 4
    band = pd.read_csv(out / "band.csv")  # its measured columns read 0.0 on q4..q7
    assert band[[f"q{j}_measured" for j in range(4, 8)]].isna().all().all() and band["q3_measured"].notna().all()


@pytest.mark.parametrize("argv, message", [
    (["--params-cov", "missing.json"], "--params-cov: missing.json: file not found"),
    (["--relative-std", "2"], "--relative-std: 2: must be in (0, 1)"),
    (["--samples", "0"], "--samples: 0: at least 2"),
    (["--samples", "1"], "--samples: 1: at least 2"),
])
def test_uncertainty_bad_input_is_one_line(tmp_path, capsys, argv, message):
    code = main(["uncertainty", "--measured", "two", "--out", str(tmp_path / "mc"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0]
    assert not (tmp_path / "mc").exists()


def _sha(name):
    from dvrk_dart.io.reference_data import resolve_run, sha256_of

    return sha256_of(resolve_run(name))


def _band_folder(tmp_path, inside, measured="two"):
    folder = tmp_path / "band"
    folder.mkdir()
    (folder / "uncertainty.json").write_text(json.dumps({
        "config": {"measured": measured}, "parameters": "relative std 0.05", "measured_inside_band_fraction": inside,
        "rms_measured_outside_band": [0.0] * 7, "measured_file": {"sha256": _sha(measured), "replayed_s": 28.0}}))
    return folder


def _diagnosis_result(runs=("two",)):  # a run is known by its content
    effect = {"selected": True, "explained_fraction": {}}
    return {"inputs": {name: {"sha256": _sha(name)} for name in runs}, "train_runs": list(runs), "holdout_runs": [], "effects": [
        {**effect, "name": "friction q2", "joints": ["q2"]},
        {**effect, "name": "offset q3", "joints": ["q3"]},
        {**effect, "name": "payload", "joints": ["q1", "q2", "q3"], "selected": False}]}


def test_an_effect_is_unmodelled_only_where_the_run_leaves_the_parameter_band(tmp_path):
    from dvrk_dart.diagnosis.payload.parameter_band import BAND_COVERAGE, apply_band, load_band

    inside = [0.99, 0.98, BAND_COVERAGE - 0.01, 0.5, 0.95, 0.95, 0.95]
    result = apply_band(_diagnosis_result(), load_band(_band_folder(tmp_path, inside)))
    band = result["parameter_band"]
    assert band["joints_outside_band"] == ["q3", "q4"]
    assert band["unmodelled_effects"] == ["offset q3"] and band["within_parameter_uncertainty"] == ["friction q2"]
    assert result["effects"][2]["beyond_parameter_uncertainty"]  # not selected, still marked


def test_a_band_with_a_fraction_that_is_not_a_number_is_refused(tmp_path):
    """NaN compares false: a band summary edited to NaN read "outside on no joint, unmodelled effects: none"."""
    from dvrk_dart.diagnosis.payload.parameter_band import load_band
    from dvrk_dart.errors import DvrkDartError

    folder = _band_folder(tmp_path, [1.0] * 6 + [None])
    (folder / "uncertainty.json").write_text((folder / "uncertainty.json").read_text().replace("1.0, null", "NaN, null"))
    with pytest.raises(DvrkDartError, match="measured_inside_band_fraction holds a value that is not finite"):
        load_band(folder)


def test_a_band_of_another_run_is_refused(tmp_path):
    from dvrk_dart.diagnosis.payload.parameter_band import apply_band, load_band
    from dvrk_dart.errors import DvrkDartError

    band = load_band(_band_folder(tmp_path, [1.0] * 7))
    with pytest.raises(DvrkDartError, match="none of the diagnosed runs"):
        apply_band(_diagnosis_result(runs=("one",)), band)
    # a band of another recording that happens to have the same file name: refused by content
    other = tmp_path / "other"
    other.mkdir()
    renamed = _band_folder(other, [1.0] * 7, measured="one")
    data = json.loads((renamed / "uncertainty.json").read_text())
    data["config"]["measured"] = "two"
    (renamed / "uncertainty.json").write_text(json.dumps(data))
    with pytest.raises(DvrkDartError, match="none of the diagnosed runs"):
        apply_band(_diagnosis_result(runs=("two",)), load_band(renamed))
    with pytest.raises(DvrkDartError, match="not an output folder of `dvrk-dart uncertainty`"):
        load_band(tmp_path)
    # a summary missing a key is refused when loaded, before any diagnosis
    del data["rms_measured_outside_band"]
    (renamed / "uncertainty.json").write_text(json.dumps(data))
    with pytest.raises(DvrkDartError, match="rms_measured_outside_band"):
        load_band(renamed)

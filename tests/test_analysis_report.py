"""The analysis tables and the generated report, from a small runs folder:
real short simulations plus synthetic runs with known answers."""

from __future__ import annotations

import json
import math
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from report_runs import (
    SYNTHETIC_EFFORT_OFFSET,
    SYNTHETIC_ERROR_AFTER_1S_M,
    real_short_runs,
    synthetic_torque_record,
    synthetic_velocity_record,
    write_run,
)

from dvrk_dart.analysis import tables as an
from dvrk_dart.analysis.checks import MAX_MEANINGFUL_RATIO, STATUS_MISSING
from dvrk_dart.analysis.report import RATIO_DIGITS, SHOWN_DIGITS, build_report
from dvrk_dart.errors import DvrkDartError


@pytest.fixture(scope="module")
def runs_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("runs")
    real_short_runs(folder)
    write_run(synthetic_torque_record(), folder)
    write_run(synthetic_velocity_record(), folder)
    return folder


@pytest.fixture(scope="module")
def analysis(runs_dir) -> an.Analysis:
    return an.analyze(runs_dir, jobs=2)


@pytest.fixture(scope="module")
def small_runs_dir(tmp_path_factory) -> Path:
    """Synthetic runs only: for the tests that build several reports."""
    folder = tmp_path_factory.mktemp("small_runs")
    write_run(synthetic_torque_record(), folder)
    return folder


@pytest.fixture(scope="module")
def report(runs_dir, tmp_path_factory) -> Path:
    return build_report(runs_dir, tmp_path_factory.mktemp("out") / "report")


# ---------------------------------------------------------------- HTML reading


class ReportParser(HTMLParser):
    """Table cells (attributes, text, whether inside <code>) and referenced files."""

    def __init__(self):
        super().__init__()
        self.cells: list[dict] = []
        self.references: list[str] = []
        self._cell: dict | None = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in ("td", "th"):
            self._cell = {"tag": tag, "attrs": attrs, "text": "", "code": False}
        elif tag == "code" and self._cell is not None:
            self._cell["code"] = True
        for key in ("src", "href"):
            if tag in ("img", "a", "link", "script") and attrs.get(key):
                self.references.append(attrs[key])

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._cell["text"] = self._cell["text"].strip()
            self.cells.append(self._cell)
            self._cell = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell["text"] += data


def parse(report: Path) -> ReportParser:
    parser = ReportParser()
    parser.feed(report.read_text())
    return parser


SPECIAL_TEXT = {"—": math.nan, "∞": math.inf, "-∞": -math.inf}


def shown(text: str) -> float:
    """The number a cell shows."""
    return SPECIAL_TEXT[text] if text in SPECIAL_TEXT else float(text)


def looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


# ---------------------------------------------------------------- the analysis


def test_synthetic_velocity_run_known_errors(tmp_path):
    write_run(synthetic_velocity_record(), tmp_path)
    result = an.analyze(tmp_path, jobs=1)
    m = result.metrics
    rms = m[(m.quantity == "rms_sim_vs_model") & (m.regime == "all")]
    assert len(rms) == 7
    np.testing.assert_allclose(rms.value, SYNTHETIC_EFFORT_OFFSET, rtol=1e-12)
    # the NaN rows of the run are left out, not propagated
    samples = m[(m.quantity == "samples") & (m.regime == "all")]
    assert set(samples.value) == {len(synthetic_velocity_record()) - 3}
    # q1 is at rest for the first half: exactly those samples form its near-zero regime
    near_zero = m[(m.quantity == "samples") & (m.regime == an.REGIME_NEAR_ZERO_VELOCITY)]
    assert near_zero.set_index("joint").value.to_dict() == {"q1": len(synthetic_velocity_record()) // 2 - 3}
    assert set(m.unit[m.quantity == "rms_sim_vs_model"]) == {"N·m", "N"}
    assert (m.source[m.quantity == "rms_sim_vs_model"] == an.RUN_LOG).all()
    assert not m.value[m.quantity.str.startswith("rel_")].isin([np.inf]).any()


def test_simulated_terms_follow_the_logged_config(tmp_path):
    """With friction simulated, sim - model must use the model including friction."""
    write_run(synthetic_velocity_record(friction=True), tmp_path)
    m = an.analyze(tmp_path, jobs=1).metrics
    rms = m[(m.quantity == "rms_sim_vs_model") & (m.regime == "all")]
    np.testing.assert_allclose(rms.value, SYNTHETIC_EFFORT_OFFSET, rtol=1e-12)
    assert an.simulated_terms_of({"sim": {"friction": True}}) == ("inertia", "coriolis", "gravity", "friction")


def test_torque_tracking_after_transient_matches_log_and_check(analysis):
    result = analysis
    assert result.value("rectilinear_torque_cw-on", "tracking_rms_position_after_1s", "x") == pytest.approx(SYNTHETIC_ERROR_AFTER_1S_M, rel=1e-9)
    row = result.checks[(result.checks.check == "torque-tracking-after-transient") & (result.checks.run == "rectilinear_torque_cw-on")].iloc[0]
    assert row.status == an.STATUS_PASS and row.value == pytest.approx(SYNTHETIC_ERROR_AFTER_1S_M, rel=1e-9)


def test_real_runs_verdicts_and_metrics_json_agree(analysis):
    result = analysis
    assert not result.failures
    checks = result.checks.set_index(["check", "run"]).status
    assert checks[("kinematic-tracking-position", "rectilinear_kinematic_cw-on")] == an.STATUS_PASS
    assert checks[("velocity-sim-vs-model-with-counterweight", "rectilinear_velocity_cw-on")] == an.STATUS_PASS
    assert checks[("velocity-no-counterweight-shows-on-J3", "rectilinear_velocity_cw-off")] == an.STATUS_PASS
    # runs of the check list absent from the folder are reported, not skipped
    assert checks[("kinematic-tracking-position", "spiral_kinematic_cw-on")] == STATUS_MISSING
    assert set(checks.loc["loop-closure"].index) == set(result.runs)
    # the kinematic run has no efforts (NaN in the log): no effort rows, tracking rows present
    kin = result.metrics[result.metrics.run == "rectilinear_kinematic_cw-on"]
    assert not kin.quantity.str.contains("sim_vs").any() and "tracking_rms_position" in set(kin.quantity)
    # the log and the runner's metrics.json agree on the numbers they share
    for name in ("rectilinear_velocity_cw-on", "rectilinear_velocity_cw-off"):
        logged = result.runs[name].metrics["rms_sim_vs_model"]
        ours = [result.value(name, "rms_sim_vs_model", j) for j in ("q1", "q2", "q3", "q4", "q5", "q6", "q7")]
        np.testing.assert_allclose(ours, logged, rtol=1e-9, atol=1e-300)
    replay = result.runs["replay-two_velocity_cw-on"]
    at_measured = result.metrics[(result.metrics.run == replay.name) & (result.metrics.quantity == "rms_model_full_vs_measured_at_measured_state")]
    assert list(at_measured.value) == replay.metrics["rms_model_vs_measured"] and set(at_measured.source) == {an.METRICS_FILE}
    assert (result.metrics[(result.metrics.run == replay.name)].regime == an.REGIME_FIRST_PERIOD).any()


def test_analysis_from_a_copied_folder_is_identical(runs_dir, analysis, tmp_path):
    copy = tmp_path / "elsewhere"
    shutil.copytree(runs_dir, copy)
    a, b = analysis, an.analyze(copy, jobs=2)
    pd.testing.assert_frame_equal(a.metrics, b.metrics)
    pd.testing.assert_frame_equal(a.checks, b.checks)


def test_bad_data_files_fail_with_one_line(tmp_path):
    bad = tmp_path / "checks.toml"
    bad.write_text('[[checks]]\nid = "x"\n')
    with pytest.raises(DvrkDartError, match="lacks"):
        an.load_checks(bad)
    with pytest.raises(DvrkDartError, match="not a folder"):
        an.discover_runs(tmp_path / "absent")


def test_published_numbers_are_data_with_sources():
    published = an.load_published()
    ids = {p["id"]: p for p in published["published"]}
    assert ids["paper-rectilinear-sim-vs-model-wCW"]["values"] == [0.65, 0.1, 0.048]
    assert ids["wang2019-relative-error-two"]["values"][0] == 0.0929
    for entry in published["published"]:
        assert entry["where"] and entry["source"] in published["sources"] and entry["compare"]


# ---------------------------------------------------------------- the report


def test_report_numbers_equal_the_analysis_tables(report):
    folder = report.parent
    metrics = pd.read_parquet(folder / "analysis" / "metrics.parquet")
    pd.testing.assert_frame_equal(metrics, pd.read_csv(folder / "analysis" / "metrics.csv", keep_default_na=True), check_dtype=False)
    by_key = metrics.set_index(["run", "quantity", "joint", "regime"]).value
    checks = pd.read_csv(folder / "analysis" / "checks.csv").set_index(["check", "run"])
    comparison = pd.read_csv(folder / "analysis" / "comparison.csv")
    summary = json.loads((folder / "analysis" / "summary.json").read_text())
    runs = {r["run"]: r for r in summary["runs"]}

    cells = parse(report).cells
    numeric = [c for c in cells if "data-value" in c["attrs"]]
    assert len(numeric) > 100
    for cell in numeric:
        a, value = cell["attrs"], float(cell["attrs"]["data-value"])
        # what is shown is the exact value rounded (4 significant digits, 3 for ratios)
        digits = RATIO_DIGITS if a.get("data-field") == "ratio_published_over_ours" else SHOWN_DIGITS
        text = shown(cell["text"])
        assert same(text, value) or math.isclose(text, value, rel_tol=0.5 * 10 ** (1 - digits)), cell
        if "data-check" in a:
            assert same(value, checks.loc[(a["data-check"], a["data-run"]), "value"]), cell
        elif "data-published" in a:
            rows = comparison[(comparison.published == a["data-published"]) & (comparison.component == a["data-component"])]
            if a["data-field"] == "published_value":  # shown once for all the runs it is compared with
                assert len(rows) and all(same(value, v) for v in rows.published_value), cell
                continue
            rows = rows[(rows.run == a["data-run"]) & (rows.quantity == a["data-quantity"]) & (rows.regime == a["data-regime"])]
            assert len(rows) == 1 and same(value, float(rows[a["data-field"]].iloc[0])), cell
            if a["data-field"] == "our_value" and not math.isnan(value):
                assert value == by_key[(a["data-run"], a["data-quantity"], a["data-joint"], a["data-regime"])], cell
        elif "data-quantity" in a:
            assert value == by_key[(a["data-run"], a["data-quantity"], a["data-joint"], a["data-regime"])], cell
        else:
            assert a["data-field"] in ("samples", "duration_s", "dt_s"), cell
            if a["data-field"] == "samples":
                assert value == runs[a["data-run"]]["samples"]
    # no number in a table without its exact value and identity
    for cell in cells:
        if cell["tag"] == "td" and not cell["code"] and looks_numeric(cell["text"]):
            assert "data-value" in cell["attrs"], cell
    # every verdict on a run of the folder and every published number is in the report (the checks of runs not in
    # the folder are named in one line, not listed as missing: the analysis's checks.csv keeps them)
    present = {r["run"] for r in summary["runs"]} | set(summary["unreadable_runs"] or {})
    assert any(key[1] in present for key in checks.index)
    assert {(c["attrs"]["data-check"], c["attrs"]["data-run"]) for c in numeric if "data-check" in c["attrs"]} == {
        key for key in checks.index if key[1] in present}
    assert {(c["attrs"]["data-published"], c["attrs"]["data-component"]) for c in numeric if c["attrs"].get("data-field") == "published_value"} == set(
        zip(comparison.published, comparison.component)
    )
    assert sum(c["attrs"].get("data-field") == "our_value" for c in numeric) == len(comparison)
    # every whole-run error of the analysis is shown
    shown_keys = {(c["attrs"]["data-run"], c["attrs"]["data-quantity"], c["attrs"]["data-joint"], c["attrs"]["data-regime"]) for c in numeric if "data-quantity" in c["attrs"] and "data-published" not in c["attrs"]}
    for quantity in ("rms_sim_vs_model", "rms_sim_vs_measured", "tracking_rms_position", "closure_residual_max"):
        rows = metrics[(metrics.quantity == quantity) & (metrics.regime == "all")]
        assert len(rows) and set(zip(rows.run, rows.quantity, rows.joint, rows.regime)) <= shown_keys


def test_report_references_existing_files_and_has_the_figures(report):
    folder = report.parent
    references = [r for r in parse(report).references if not r.startswith("#")]
    assert references
    for reference in references:
        assert "://" not in reference, f"the report must be self-contained: {reference}"
        assert (folder / reference).is_file(), reference
    figures = sorted(p.name for p in (folder / "figures").glob("*.png"))
    for expected in (
        "fig2_rectilinear_kinematic_tracking.png",
        "fig4_rectilinear_velocity_efforts.png",
        "fig6_replay-two_efforts.png",
        "fig7_rectilinear_torque_control.png",
        "residual_replay-two_velocity_cw-on.png",
    ):
        assert expected in figures
    html = report.read_text()
    assert "Verdicts" in html and "Comparison with the published numbers" in html and "Provenance" in html
    assert not list(folder.parent.glob(".report.*")), "no temporary build folder left behind"


def test_extra_sections_and_atomic_rebuild(small_runs_dir, report, tmp_path):
    runs_dir = small_runs_dir
    out = tmp_path / "report"
    image = report.parent / "figures" / "fig2_rectilinear_kinematic_tracking.png"
    diagnosis_figure = _copy(image, tmp_path / "diag.png")
    section = ("Diagnosis", "<p id='diag'>found it</p><img src='figures/extra/diag.png' alt='d'>", [diagnosis_figure])
    others = [{"check": "held-out q3 closer than the identified model", "passed": False, "value": "0.4208 vs 0.1912 N"},
              {"check": "payload found", "passed": True, "value": "pitch"},
              {"check": "mass from the data alone within 20% (reported as not determined)", "passed": True, "value": "not determined: m·c only",
               "not_determined": True}]
    index = build_report(runs_dir, out, extra_sections=[section], campaign_verdicts=others)
    text = index.read_text()
    assert "<p id='diag'>found it</p>" in text and (out / "figures" / "extra" / "diag.png").is_file()
    # the verdicts' first lines count validate's other checks too, and name the failed ones
    assert "2 of 3</strong> other checks of the campaign passed (1 of them on a figure the diagnosis reports as not determined" in text
    assert "0.4208 vs 0.1912 N" in text.split("Thresholds")[0]
    assert json.loads((out / "analysis" / "summary.json").read_text())["other_checks"]["failed"] == [
        "held-out q3 closer than the identified model: 0.4208 vs 0.1912 N"]
    # a folder of some runs: the checks of runs not in it are counted apart, not listed as missing; validate's are missing
    verdicts = text.split('id="verdicts"')[1].split("Thresholds")[0]
    assert "Not checked here:" in verdicts and "missing" not in verdicts
    whole = build_report(runs_dir, tmp_path / "campaign", every_check_run=True).read_text().split('id="verdicts"')[1].split("Thresholds")[0]
    assert "Not checked here:" not in whole and "missing" in whole
    before = text
    # a failing build leaves the previous report untouched
    with pytest.raises(DvrkDartError):
        build_report(runs_dir, out, extra_sections=tmp_path / "no-such-folder")
    assert index.read_text() == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".report.")]
    # a folder of extra figures
    extra = tmp_path / "extra"
    extra.mkdir()
    _copy(image, extra / "gap_per_joint.png")
    (extra / "notes.html").write_text("<p>notes of the diagnosis</p>")
    text = build_report(runs_dir, out, extra_sections=extra).read_text()
    assert "figures/extra/gap_per_joint.png" in text and "<p>notes of the diagnosis</p>" in text and "found it" not in text  # not escaped
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DvrkDartError, match="holds no .html section nor image"):
        build_report(runs_dir, out, extra_sections=empty)


def _copy(source: Path, target: Path) -> Path:
    shutil.copyfile(source, target)
    return target


def test_no_ratio_in_the_report_compares_with_round_off(report):
    """Ratios above MAX_MEANINGFUL_RATIO compare a physical error with round-off: none is shown."""
    comparison = pd.read_csv(report.parent / "analysis" / "comparison.csv")
    assert (comparison.ratio_published_over_ours.dropna() <= MAX_MEANINGFUL_RATIO).all()
    ratios = [float(c["attrs"]["data-value"]) for c in parse(report).cells if c["attrs"].get("data-field") == "ratio_published_over_ours"]
    assert ratios and max(r for r in ratios if math.isfinite(r)) <= MAX_MEANINGFUL_RATIO
    # the paper's Sect. IV-A tracking ran with its dynamic engine disabled: our kinematic run is its like, at round-off
    tracking = comparison[comparison.published == "paper-rectilinear-position"]
    kinematic = tracking[tracking.run == "rectilinear_kinematic_cw-on"]
    assert set(tracking[tracking.goal == "smaller"].run) == {"rectilinear_kinematic_cw-on", "rectilinear_velocity_cw-on"}
    assert kinematic.ratio_published_over_ours.isna().all() and kinematic.note.str.startswith("at round-off; like the paper's").all()
    # each compared run counted on its own, its values at round-off said
    assert "rectilinear_kinematic_cw-on: better on 3 of 3 (3 at round-off)" in report.read_text()
    # reproducing the published model errors is an equality goal: the difference is shown, not a ratio
    reproduction = comparison[(comparison.published == "wang2019-relative-error-two") & (comparison.goal == "equal")]
    assert len(reproduction) == 7 and reproduction.ratio_published_over_ours.isna().all() and reproduction.reproduced_to.notna().all()


def test_report_shows_the_realistic_arm_per_joint(report):
    text = report.read_text()
    assert 'id="realistic-arm"' in text
    cells = [c for c in parse(report).cells if c["attrs"].get("data-quantity") == "rms_sim_vs_measured"]
    assert {"replay-two_velocity_cw-on", "replay-two_velocity_cw-on_identified"} <= {c["attrs"]["data-run"] for c in cells}

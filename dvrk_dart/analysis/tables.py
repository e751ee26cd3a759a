"""The analysis stage: a folder of run logs -> tidy tables of errors, the
validation verdicts (pipelines/checks.toml) and the comparison with the
published numbers (pipelines/published.toml).

It works from the logs alone (`<runs_dir>/<run>/run.mcap`, read with
`log_mcap.read_mcap`, plus each folder's config.json and metrics.json), so a
runs folder copied to another machine gives the same tables.

The metrics table is long ("tidy"): one row per (run, joint or axis, quantity,
motion regime), with the columns of `METRICS_COLUMNS`. Effort comparisons use
the identified model as logged, i.e. evaluated at the *simulated* state; the one
exception is `rms_model_full_vs_measured_at_measured_state`, taken from the
run's metrics.json (the replay computes it on the measured, processed signals).
The `source` column says which file each number comes from.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.analysis.checks import (
    CHECKS_FILE,
    PUBLISHED_FILE,
    STATUS_PASS,
    compare_with_published,
    evaluate_checks,
    load_checks,
    load_published,
    other_checks,
)
from dvrk_dart.analysis.run_folders import METRICS_FILE, RUN_LOG, LoadedRun, discover_runs, load_run_folder
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import atomic_path, write_json_atomic, write_text_atomic
from dvrk_dart.model.description import PsmModel
from dvrk_dart.metrics import REGIME_ALL, TORQUE_TRANSIENT_S, relative_error, rms
from dvrk_dart.model.identified import INERTIAL_TERMS, TERMS
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.runs.executors import quiet_worker

METRICS_COLUMNS = ["run", "scenario", "mode", "counterweight", "joint", "quantity", "regime", "value", "unit", "source"]

# ---------------------------------------------------------------- motion regimes
# Regimes are defined per joint on the *simulated* state of the run (which follows
# the measured one in a replay), so every comparison of a run uses the same samples.

REGIME_NEAR_ZERO_VELOCITY = "near_zero_velocity"
REGIME_HIGH_ACCELERATION = "high_acceleration"
REGIME_FIRST_PERIOD = "first_period"
#: |dq| below which a joint counts as (nearly) at rest: where Coulomb friction
#: switches sign and stiction dominates, i.e. where a rigid-body simulation is
#: expected to differ most from the real arm. About 0.6 deg/s, and 1 mm/s for q3.
NEAR_ZERO_VELOCITY = {"rad": 0.01, "m": 0.001}  # rad/s, m/s by joint position unit
#: |ddq| at or above this percentile of the joint's own |ddq| in the run counts as
#: high acceleration (inertia-dominated samples, where mass errors show)
HIGH_ACCELERATION_PERCENTILE = 90.0
#: fewer samples than this in a regime: no RMS is reported (not meaningful)
MIN_REGIME_SAMPLES = 20


def first_period_s(model: PsmModel) -> float:
    """Upstream's test window of the arm's runs (s): its first period at the reference rate."""
    from dvrk_dart.io.reference_data import sample_rate_hz

    return model.processing.first_period_samples / sample_rate_hz()


REGIME_DESCRIPTIONS = {
    REGIME_ALL: "every logged sample",
    REGIME_NEAR_ZERO_VELOCITY: "samples where the joint's simulated |dq| < {rad} rad/s ({m} m/s for q3)".format(**NEAR_ZERO_VELOCITY),
    REGIME_HIGH_ACCELERATION: f"samples where the joint's simulated |ddq| is at or above its {HIGH_ACCELERATION_PERCENTILE:g}th percentile in the run",
    REGIME_FIRST_PERIOD: "replays only: upstream's test window, the arm's [processing] first_period_samples (the PSM's 1111 at 200 Hz, "
                         "1 / 0.18 Hz: the base frequency its identification assumed, not a run's own period, which the periodic processing fits)",
}

# ---------------------------------------------------------------- quantities

CARTESIAN_POSITION_AXES = ("x", "y", "z")
CARTESIAN_ORIENTATION_AXES = ("rx", "ry", "rz")
ALL_COMPONENTS = "all"  # the `joint` value of run-wide scalars

#: effort comparisons: name -> (actual, reference, description); values and regimes per joint
EFFORT_COMPARISONS = {
    "sim_vs_model": ("sim", "model_sim_terms", "simulated efforts vs the identified model restricted to the terms the simulation includes (its config's flags), model at the simulated state"),
    "sim_vs_measured": ("sim", "measured", "simulated efforts vs the measured efforts of the replayed run"),
    "model_full_vs_measured": ("model_full", "measured", "the full identified model (all terms) at the simulated state vs the measured efforts"),
    "model_inertial_vs_measured": ("model_inertial", "measured", "the inertial terms of the identified model (M ddq + C dq + g) at the simulated state vs the measured efforts"),
}

QUANTITY_DESCRIPTIONS = {
    **{f"rms_{name}": f"RMS of the difference: {text}" for name, (_, _, text) in EFFORT_COMPARISONS.items()},
    **{f"rel_{name}": f"relative error ||actual - reference|| / ||reference||: {text}" for name, (_, _, text) in EFFORT_COMPARISONS.items()},
    "rms_model_full_vs_measured_at_measured_state": "RMS of the full identified model at the *measured* (processed) state minus the measured efforts, over the replayed window (from metrics.json)",
    "rms_q_sim_vs_measured": "RMS of simulated minus measured joint positions (replays)",
    "tracking_rms_position": "RMS of the tool-tip position error (reference - actual) per base axis",
    "tracking_rms_orientation": "RMS of the tool orientation error (rotation vector of reference vs actual) per base axis",
    "tracking_rms_position_after_1s": "torque mode: RMS of the tool-tip position error after the initial transient (t >= 1 s)",
    "rms_sim_vs_measured_excess": "RMS(simulated - measured) minus the full identified model's RMS(model - measured) at the measured states: "
    "below 0 when the simulation is closer to the real arm than the identified model",
    "closure_residual_max": "maximum loop-closure residual over the run (parallelograms, counterweight)",
    "samples": "number of samples the joint's values in that regime are computed on",
}


@dataclass
class Analysis:
    runs_dir: Path
    runs: dict[str, LoadedRun]
    metrics: pd.DataFrame
    checks: pd.DataFrame
    comparison: pd.DataFrame
    failures: dict[str, str] = field(default_factory=dict)  # unreadable run folders -> error
    left_out: dict[str, str] = field(default_factory=dict)  # folders holding a run another folder holds -> why

    def value(self, run: str, quantity: str, joint: str, regime: str = REGIME_ALL) -> float:
        rows = self.metrics[
            (self.metrics.run == run) & (self.metrics.quantity == quantity) & (self.metrics.joint == joint) & (self.metrics.regime == regime)
        ]
        return float(rows.value.iloc[0]) if len(rows) else math.nan


def _load_and_measure(run_dir: str) -> tuple[LoadedRun | None, pd.DataFrame | None, str | None]:
    """Worker: one run folder -> (loaded run, its metric rows) or an error message."""
    try:
        loaded = load_run_folder(run_dir)
        return loaded, run_metrics(loaded), None
    except Exception as exc:  # one unreadable log must not hide the others
        return None, None, f"{type(exc).__name__}: {exc}".splitlines()[0]


# ---------------------------------------------------------------- per-run metrics


def simulated_terms_of(config: dict) -> tuple[str, ...]:
    """The model terms the simulation includes, from the run's logged config["sim"] flags."""
    from dvrk_dart.sim.config import SimConfig, simulated_terms

    sim = config.get("sim") or {}
    flags = {k: bool(sim.get(k, False)) for k in ("friction", "offsets", "spring", "motor_inertia")}
    return simulated_terms(SimConfig(**flags))


def _regime_masks(record, joint: int, finite: np.ndarray, replay: bool, model: PsmModel) -> dict[str, np.ndarray]:
    """Sample masks of each regime for one joint (already restricted to finite rows)."""
    masks = {REGIME_ALL: finite}
    dq = np.abs(record.dq[:, joint])
    ddq = np.abs(record.ddq[:, joint])
    limit = NEAR_ZERO_VELOCITY[model.position_unit(JOINT_NAMES[joint])]
    masks[REGIME_NEAR_ZERO_VELOCITY] = finite & (dq < limit)
    usable = finite & np.isfinite(ddq)
    if usable.any():
        masks[REGIME_HIGH_ACCELERATION] = usable & (ddq >= np.percentile(ddq[usable], HIGH_ACCELERATION_PERCENTILE))
    if replay:
        masks[REGIME_FIRST_PERIOD] = finite & (record.t < first_period_s(model))
    return masks


def _effort_sources(record, config: dict) -> dict[str, np.ndarray]:
    sources: dict[str, np.ndarray] = {}
    if record.effort_sim is not None and np.isfinite(record.effort_sim).any():
        sources["sim"] = record.effort_sim
    if record.effort_measured is not None:
        sources["measured"] = record.effort_measured
    if record.effort_model:
        present = tuple(t for t in TERMS if t in record.effort_model)
        sources["model_full"] = record.model_total(present)
        sources["model_inertial"] = record.model_total(tuple(t for t in INERTIAL_TERMS if t in record.effort_model))
        sources["model_sim_terms"] = record.model_total(tuple(t for t in simulated_terms_of(config) if t in record.effort_model))
    return sources


def run_metrics(loaded: LoadedRun) -> pd.DataFrame:
    """The long table of one run (columns METRICS_COLUMNS); a replay has no row
    on a joint its measured run did not record (held, it is not measured)."""
    rows = _in_band(loaded, _effort_rows(loaded))
    rows += _position_rows(loaded, rows)
    rows += _tracking_rows(loaded)
    unrecorded = set(JOINT_NAMES) - set(loaded.metrics.get("measured_joints") or JOINT_NAMES)
    rows = [row for row in rows if row[0] not in unrecorded]
    residual = loaded.record.closure_residual_m
    if residual is not None and np.isfinite(residual).any():
        rows.append(_row(ALL_COMPONENTS, "closure_residual_max", REGIME_ALL, np.nanmax(residual), "m"))
    table = pd.DataFrame(rows, columns=["joint", "quantity", "regime", "value", "unit", "source"])
    for column, value in (("counterweight", loaded.counterweight), ("mode", loaded.mode), ("scenario", loaded.scenario), ("run", loaded.name)):
        table.insert(0, column, value)
    return table[METRICS_COLUMNS]


def _row(joint: str, quantity: str, regime: str, value: float, unit: str, source: str = RUN_LOG) -> tuple:
    return (joint, quantity, regime, float(value), unit, source)


def _effort_rows(loaded: LoadedRun) -> list[tuple]:
    """RMS and relative error of every effort comparison the run has, per joint and regime, and the sample counts."""
    record, model = loaded.record, loaded.model
    rows: list[tuple] = []
    replay = record.effort_measured is not None
    sources = _effort_sources(record, loaded.config)
    if _periodic_replay(loaded):  # measured in the harmonics' band, the log's efforts not: _in_band
        sources.pop("measured", None)
    counted: set[tuple[str, str]] = set()  # (joint, regime) whose sample count is in the table
    for name, (actual_key, reference_key, _) in EFFORT_COMPARISONS.items():
        if actual_key not in sources or reference_key not in sources:
            continue
        actual, reference = sources[actual_key], sources[reference_key]
        for j, joint in enumerate(JOINT_NAMES):
            finite = np.isfinite(actual[:, j]) & np.isfinite(reference[:, j])
            for regime, mask in _regime_masks(record, j, finite, replay, loaded.model).items():
                n = int(mask.sum())
                if n < MIN_REGIME_SAMPLES:
                    continue
                a, b = actual[mask, j], reference[mask, j]
                rows.append(_row(joint, f"rms_{name}", regime, rms(a - b), model.effort_unit(joint)))
                if np.any(b != 0.0):  # a relative error to an all-zero reference (the massless tool) is undefined
                    rows.append(_row(joint, f"rel_{name}", regime, relative_error(a, b), "1"))
                if (joint, regime) not in counted:  # from the first comparison: the simulated samples
                    counted.add((joint, regime))
                    rows.append(_row(joint, "samples", regime, n, "1"))
    return rows


def _in_band(loaded: LoadedRun, rows: list[tuple]) -> list[tuple]:
    """A periodic replay's measured efforts are in the excitation's band: the
    log's raw simulated and model efforts are not compared with them (_effort_rows
    leaves them out); its whole-run RMS(simulated - measured) is metrics.json's,
    in the same band at the measured samples (the figure the replay printed)."""
    if not _periodic_replay(loaded):
        return rows
    unit = loaded.model.effort_unit
    return rows + [_row(joint, "rms_sim_vs_measured", REGIME_ALL, value, unit(joint), METRICS_FILE)
                   for joint, value in zip(JOINT_NAMES, loaded.metrics.get("rms_sim_vs_measured") or []) if value is not None]


def _periodic_replay(loaded: LoadedRun) -> bool:
    return bool(loaded.metrics.get("in_band_note"))


def _position_rows(loaded: LoadedRun, effort_rows: list[tuple]) -> list[tuple]:
    """A replay's position error, and the simulation's effort error beyond the model's at the measured state."""
    record, model = loaded.record, loaded.model
    rows: list[tuple] = []
    if record.q_measured is not None:
        for j, joint in enumerate(JOINT_NAMES):  # per joint: a joint the run did not log has no measured positions
            finite = np.isfinite(record.q[:, j]) & np.isfinite(record.q_measured[:, j])
            if finite.sum() >= MIN_REGIME_SAMPLES:
                rows.append(_row(joint, "rms_q_sim_vs_measured", REGIME_ALL, rms(record.q[finite, j] - record.q_measured[finite, j]),
                                 model.position_unit(joint)))
    at_measured = loaded.metrics.get("rms_model_vs_measured")
    if at_measured is not None:
        sim_vs_measured = {row[0]: row[3] for row in effort_rows if row[1] == "rms_sim_vs_measured" and row[2] == REGIME_ALL}
        for joint, value in zip(JOINT_NAMES, at_measured):
            if value is None:  # not recorded
                continue
            rows.append(_row(joint, "rms_model_full_vs_measured_at_measured_state", REGIME_ALL, value, model.effort_unit(joint), METRICS_FILE))
            if joint in sim_vs_measured:
                rows.append(_row(joint, "rms_sim_vs_measured_excess", REGIME_ALL, sim_vs_measured[joint] - value, model.effort_unit(joint)))
    return rows


def _tracking_rows(loaded: LoadedRun) -> list[tuple]:
    """The instrument's Cartesian tracking error (and, in torque mode, after its first second)."""
    if loaded.tracking is None:
        return []
    position, orientation = loaded.tracking
    finite = np.all(np.isfinite(position), axis=1) & np.all(np.isfinite(orientation), axis=1)
    rows = [_row(axis, "tracking_rms_position", REGIME_ALL, value, "m") for axis, value in zip(CARTESIAN_POSITION_AXES, rms(position[finite]))]
    rows += [_row(axis, "tracking_rms_orientation", REGIME_ALL, value, "rad")
             for axis, value in zip(CARTESIAN_ORIENTATION_AXES, rms(orientation[finite]))]
    after = finite & (loaded.record.t >= TORQUE_TRANSIENT_S)
    if loaded.mode == "torque" and after.any():
        rows += [_row(axis, "tracking_rms_position_after_1s", REGIME_ALL, value, "m")
                 for axis, value in zip(CARTESIAN_POSITION_AXES, rms(position[after]))]
    return rows


# ---------------------------------------------------------------- the whole folder


def default_jobs() -> int:
    return os.cpu_count() or 1


def _kept_of_two(kept: Path, other: Path, run: str) -> tuple[Path, Path]:
    """Of two folders holding the same run, (the one reported, the one left
    out): the folder named after its run, as the campaign names it, wins over
    one a user named (`dvrk-dart run --out runs/mine`); two such are refused."""
    for named, unnamed in ((kept, other), (other, kept)):
        if named.name == run and unnamed.name != run:
            return named, unnamed
    raise DvrkDartError(f"--runs: {kept} and {other} hold the same run {run}: keep one of them")


def analyze(
    runs_dir: str | os.PathLike,
    jobs: int | None = None,
    checks_file: str | os.PathLike = CHECKS_FILE,
    published_file: str | os.PathLike = PUBLISHED_FILE,
) -> Analysis:
    """Read every run of `runs_dir` (in `jobs` processes) and compute all the tables."""
    folders = discover_runs(runs_dir)
    checks, published = load_checks(checks_file), load_published(published_file)  # fail early on bad data files
    jobs = jobs or default_jobs()
    if jobs > 1 and len(folders) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(folders)), initializer=quiet_worker) as pool:
            results = list(pool.map(_load_and_measure, map(str, folders)))
    else:
        results = [_load_and_measure(str(f)) for f in folders]
    runs, tables, failures, folder_of, left_out = {}, {}, {}, {}, {}
    for folder, (loaded, table, error) in zip(folders, results):
        if error is not None:
            failures[folder.name] = error
            continue
        if loaded.name in runs:
            kept, other = _kept_of_two(folder_of[loaded.name], folder, loaded.name)
            left_out[other.name] = f"holds the run {loaded.name}, as {kept} does: left out"
            if kept is folder_of[loaded.name]:
                continue
        runs[loaded.name], tables[loaded.name], folder_of[loaded.name] = loaded, table, folder
    metrics = pd.concat(tables.values(), ignore_index=True) if tables else pd.DataFrame(columns=METRICS_COLUMNS)
    metrics["value"] = metrics["value"].astype(float)
    return Analysis(
        runs_dir=Path(runs_dir),
        runs=runs,
        metrics=metrics,
        checks=evaluate_checks(metrics, checks),
        comparison=compare_with_published(metrics, published),
        failures=failures,
        left_out=left_out,
    )


def run_summary(loaded: LoadedRun) -> dict:
    m = loaded.metrics
    return {
        "run": loaded.name,
        "scenario": loaded.scenario,
        "mode": loaded.mode,
        "counterweight": loaded.counterweight,
        "samples": len(loaded.record),
        "duration_s": loaded.config.get("duration_s", m.get("duration_s")),
        "error": m.get("error"),
        "checksums_sha256": loaded.checksums,
        "inputs_sha256": loaded.config.get("inputs_sha256"),
        "git_revision": loaded.versions.get("git_revision"),
    }


def _finite_or_none(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def summary(analysis: Analysis, campaign_verdicts: list[dict] | None = None) -> dict:
    """summary.json: the runs, the verdicts (the check runs', and validate's
    others: `campaign_verdicts`) and the comparison, JSON-clean (NaN -> null)."""
    checks = analysis.checks
    return {
        "runs_dir": str(analysis.runs_dir),
        "runs": [run_summary(r) for r in analysis.runs.values()],
        "unreadable_runs": analysis.failures,
        "checks_passed": int((checks.status == STATUS_PASS).sum()),
        "checks_total": len(checks),
        "other_checks": other_checks(campaign_verdicts),
        "checks": [{k: (_finite_or_none(v) if isinstance(v, float) else v) for k, v in row.items()} for row in checks.to_dict("records")],
        "comparison": [{k: (_finite_or_none(v) if isinstance(v, float) else v) for k, v in row.items()} for row in analysis.comparison.to_dict("records")],
        "regimes": REGIME_DESCRIPTIONS,
        "quantities": QUANTITY_DESCRIPTIONS,
    }


def write_analysis(analysis: Analysis, out_dir: str | os.PathLike, campaign_verdicts: list[dict] | None = None) -> dict[str, Path]:
    """metrics.parquet/.csv, checks.csv, comparison.csv and summary.json in `out_dir` (atomically)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {
        "metrics_parquet": out_dir / "metrics.parquet",
        "metrics_csv": out_dir / "metrics.csv",
        "checks_csv": out_dir / "checks.csv",
        "comparison_csv": out_dir / "comparison.csv",
        "summary_json": out_dir / "summary.json",
    }
    with atomic_path(files["metrics_parquet"]) as tmp:
        analysis.metrics.to_parquet(tmp, index=False)
    # repr-exact floats: the CSV reads back to the same numbers as the parquet
    write_text_atomic(files["metrics_csv"], analysis.metrics.to_csv(index=False, float_format=None))
    write_text_atomic(files["checks_csv"], analysis.checks.to_csv(index=False))
    write_text_atomic(files["comparison_csv"], analysis.comparison.to_csv(index=False))
    write_json_atomic(files["summary_json"], summary(analysis, campaign_verdicts))
    return files

"""Run folders read back: each holds run.mcap (`io.mcap_read`), config.json and
metrics.json; the analysis (`tables.py`) works from these alone."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.reference_data import sha256_of
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel
from dvrk_dart.model.model_file import load_model
from dvrk_dart.paths import MODELS_DIR

RUN_LOG = "run.mcap"
CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.json"
#: files of a run folder whose checksums the report lists (provenance)
CHECKSUMMED_FILES = (RUN_LOG, CONFIG_FILE, METRICS_FILE)


def run_model_file(config: dict) -> Path:
    """The arm model a run was made with (its config.json `model_file`, a file
    of models/); a folder that names none predates other arms: the PSM."""
    name = Path(str(config.get("model_file") or "")).name
    candidate = MODELS_DIR / Path(name).stem / name if name else None
    return candidate if candidate is not None and candidate.is_file() else DEFAULT_MODEL_FILE


@dataclass
class LoadedRun:
    """One run folder, read back: the record and what the report needs besides."""

    name: str
    path: Path
    record: object  # RunRecord (body positions dropped: the analysis does not use them)
    config: dict  # config.json
    metrics: dict  # metrics.json
    versions: dict  # the MCAP "versions" metadata record
    checksums: dict  # file name -> sha256
    scenario: str
    mode: str
    counterweight: str
    model: PsmModel  # the run's arm: its units, first period, whether it has a counterweight
    dynamics: str = "inertial"  # the simulated arm (runs.config.RunConfig.dynamics label)
    #: per-sample (position m, orientation rad) tracking errors of a Cartesian task,
    #: computed once (RunRecord.tracking_errors) for the tables and the figures
    tracking: tuple[np.ndarray, np.ndarray] | None = None


def discover_runs(runs_dir: str | os.PathLike) -> list[Path]:
    """The run folders of `runs_dir` (those holding a run.mcap, and those the
    tool may not look into: they are reported unreadable), sorted by name."""
    runs_dir = Path(runs_dir)
    if not runs_dir.is_dir():
        raise DvrkDartError(f"--runs: {runs_dir} is not a folder")
    closed = [p for p in runs_dir.iterdir() if p.is_dir() and not os.access(p, os.R_OK | os.X_OK)]
    return sorted([p.parent for p in runs_dir.glob(f"*/{RUN_LOG}")] + closed)


def read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return {}


def mcap_versions(path: Path) -> dict:
    """The "versions" metadata record (read_mcap does not return it)."""
    from mcap.reader import make_reader

    from dvrk_dart.io.mcap_log import METADATA_VERSIONS

    with open(path, "rb") as stream:
        for record in make_reader(stream).iter_metadata():
            if record.name == METADATA_VERSIONS:
                return dict(record.metadata)
    return {}


def run_identity(name: str, config: dict, model: PsmModel) -> tuple[str, str, str]:
    """(scenario, mode, counterweight) from the config, else from the run name."""
    parts = name.rsplit("_", 2)
    scenario = config.get("scenario")
    scenario = scenario.get("name") if isinstance(scenario, dict) else scenario
    scenario = scenario or (parts[0] if len(parts) == 3 else name)
    mode = config.get("mode") or (parts[1] if len(parts) == 3 else "")
    counterweight = config.get("counterweight") or (parts[2].removeprefix("cw-") if len(parts) == 3 else "")
    if model.counterweight_link is None:
        counterweight = "none"  # an arm without a counterweight (the MTM): no variant to name
    return str(scenario), str(mode), str(counterweight)


def load_run_folder(run_dir: str | os.PathLike) -> LoadedRun:
    from dvrk_dart.io.mcap_log import TOPIC_BODIES
    from dvrk_dart.io.mcap_read import read_mcap

    run_dir = Path(run_dir)
    record = read_mcap(run_dir / RUN_LOG, without=(TOPIC_BODIES,))  # the largest topic, unused here: not decoded
    config = read_json(run_dir / CONFIG_FILE) or record.config
    metrics = read_json(run_dir / METRICS_FILE) or record.metrics
    model = load_model(run_model_file(config))
    scenario, mode, counterweight = run_identity(record.name or run_dir.name, config, model)
    tracking = None
    if record.tool_pose is not None and record.tool_pose_ref is not None:
        tracking = record.tracking_errors()
    return LoadedRun(
        name=record.name or run_dir.name,
        path=run_dir,
        record=record,
        config=config,
        metrics=metrics,
        versions=mcap_versions(run_dir / RUN_LOG),
        checksums={f: sha256_of(run_dir / f) for f in CHECKSUMMED_FILES if (run_dir / f).is_file()},
        scenario=scenario,
        mode=mode,
        counterweight=counterweight,
        model=model,
        dynamics=str(config.get("dynamics", "inertial")),
        tracking=tracking,
    )

"""The batch pipeline: `pipelines/campaign.toml` -> one output folder per run,
run in parallel worker processes, skipping runs whose inputs and code did not
change, continuing past failures and listing them at the end.

A run folder holds: config.json (resolved config, versions, git revision,
input checksum), metrics.json, run.mcap, run.rrd. Every file is written
atomically, and inputs.sha256 last: a folder without it is not complete.
"""

from __future__ import annotations

import hashlib
import json
import time
import tomllib
from pathlib import Path

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic, write_text_atomic
from dvrk_dart.io.outputs import building_folder
from dvrk_dart.io.reference_data import sha256_of
from dvrk_dart.paths import MODELS_DIR, PACKAGE_DIR, PIPELINES_DIR
from dvrk_dart.runs.config import RunConfig, run_name
from dvrk_dart.runs.executors import error_text, run_tasks
from dvrk_dart.runs.scenarios import load_scenario

CAMPAIGN_FILE = PIPELINES_DIR / "campaign.toml"
INPUTS_FILE = "inputs.sha256"


#: a campaign `dynamics` entry "@FOLDER" means the diagnosis.json that the
#: validation's diagnosis stage writes in OUT/diagnosis/FOLDER: such runs wait for it
DIAGNOSIS_PREFIX = "@"


def load_campaign(path: Path = CAMPAIGN_FILE, diagnosis_dir: Path | None = None, default_dynamics: str | None = None) -> list[RunConfig]:
    """The campaign's runs; entries without `dynamics` simulate `default_dynamics`
    (when given, else their scenario's);
    "@FOLDER" dynamics resolve under diagnosis_dir (left out when it is None)."""
    try:
        raw = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: campaign file not found") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise DvrkDartError(f"{path}: not valid TOML ({exc})") from None
    configs = []
    for entry in raw.get("runs", []):
        unknown = set(entry) - {"scenario", "measured", "arm_model", "mode", "counterweights", "duration_s", "dynamics", "processing"}
        if unknown:
            raise DvrkDartError(f"{path}: unknown key(s) {', '.join(sorted(unknown))} in a [[runs]] entry")
        scenario = load_scenario(entry["scenario"])
        for dynamics in entry.get("dynamics", [default_dynamics or scenario.dynamics]):
            if dynamics.startswith(DIAGNOSIS_PREFIX):
                if diagnosis_dir is None:
                    continue
                dynamics = str(diagnosis_dir / dynamics[len(DIAGNOSIS_PREFIX):] / "diagnosis.json")
            for cw in entry.get("counterweights", ["on"]):
                configs.append(RunConfig(scenario.name, entry["mode"], cw, dynamics, duration_s=entry.get("duration_s"), measured=entry.get("measured"),
                                         processing=entry.get("processing", "upstream"), arm_model=entry.get("arm_model")))
    return configs


def needs_diagnosis(config: RunConfig) -> bool:
    return config.dynamics.endswith(".json")


def config_name(config: RunConfig) -> str:
    from dvrk_dart.runs.runner import scenario_of

    return run_name(scenario_of(config).name, config.mode, *config.name_parts)


def code_fingerprint() -> str:
    """Checksum of the code and model data a run depends on."""
    digest = hashlib.sha256()
    roots = [PACKAGE_DIR, MODELS_DIR]
    for root in roots:
        for path in sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
            digest.update(str(path.relative_to(root.parent)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()


def inputs_fingerprint(config: RunConfig, code: str) -> str:
    from dvrk_dart.model.model_file import load_model
    from dvrk_dart.runs.runner import arm_model_file, inputs_used, scenario_of

    scenario, model_file = scenario_of(config), arm_model_file(config)
    parts = [code, sha256_of(model_file), json.dumps(scenario.to_dict(), sort_keys=True), json.dumps(config.to_dict(), sort_keys=True)]
    parts += [f"{k}={json.dumps(v, sort_keys=True)}" for k, v in sorted(inputs_used(config, scenario, load_model(model_file)).items())]
    if config.params_file:
        parts.append(sha256_of(Path(config.params_file)))
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def write_run_folder(record, out_dir: Path, model, fingerprint: str | None = None) -> None:
    """config.json, metrics.json, run.mcap, run.rrd (drawn with `model`, the
    run's own arm description), inputs.sha256 last; the folder replaces a
    previous one as a whole or not at all. A run that diverged before its
    first logged sample has no logs, only its config and metrics."""
    from dvrk_dart.io.mcap_log import write_mcap
    from dvrk_dart.io.provenance import software_versions
    from dvrk_dart.io.rerun_log import write_rrd

    with building_folder(out_dir, "run") as folder:
        write_json_atomic(folder / "config.json", {"run": record.name, **record.config, "versions": software_versions(), "inputs_sha256": fingerprint})
        write_json_atomic(folder / "metrics.json", record.metrics)
        if len(record):
            write_mcap(record, folder / "run.mcap", model)
            write_rrd(record, folder / "run.rrd", model)
        if fingerprint and "error" not in record.metrics:  # a failed run is run again next time
            write_text_atomic(folder / INPUTS_FILE, fingerprint + "\n")


def _execute(task: tuple[RunConfig, str | None, str]):
    """Worker: run one config. With a folder (local workers share the driver's
    file system) it writes the run there and returns its metrics; without, it
    returns the record for the driver to write (Ray)."""
    from dvrk_dart.runs.runner import arm_of_run, run

    config, runs_dir, fingerprint = task
    arm = arm_of_run(config)
    record = run(config, arm)
    if runs_dir is None:
        return record
    write_run_folder(record, Path(runs_dir) / record.name, arm.model, fingerprint)
    return record.metrics


def run_campaign(specs: list[RunConfig], runs_dir: Path, jobs: int = 2, force: bool = False,
                 executor: str = "local", ray_address: str | None = None) -> dict:
    """Run every spec not already up to date, on the executor; returns a summary
    with the failures by run name (a failed run does not stop the others)."""
    from dvrk_dart.runs.runner import arm_of_run

    start = time.perf_counter()
    code = code_fingerprint()
    tasks, skipped = [], []
    names = {spec: config_name(spec) for spec in specs}
    worker_writes = executor == "local"
    for spec in specs:
        fingerprint = inputs_fingerprint(spec, code)
        marker = runs_dir / names[spec] / INPUTS_FILE
        if not force and marker.is_file() and marker.read_text().strip() == fingerprint:
            skipped.append(names[spec])
        else:
            tasks.append((spec, str(runs_dir) if worker_writes else None, fingerprint))
    failures: dict[str, str] = {}
    done: list[str] = []
    for (spec, _, fingerprint), result, error in run_tasks(_execute, tasks, executor, jobs, ray_address):
        name = names[spec]
        if error is None and not worker_writes:  # the driver writes what the Ray worker returned
            try:
                write_run_folder(result, runs_dir / name, arm_of_run(spec).model, fingerprint)
            except Exception as exc:
                error = error_text(exc)
        if error is None:
            metrics = result if worker_writes else result.metrics
            error = metrics.get("error")
        if error is None:
            done.append(name)
        else:
            failures[name] = error
    summary = {
        "runs": [names[s] for s in specs],
        "ran": sorted(done),
        "skipped_up_to_date": sorted(skipped),
        "failures": failures,
        "wall_time_s": time.perf_counter() - start,
        "jobs": jobs,
        "executor": executor,
    }
    return summary

"""The diagnosis as the CLI and the withheld-data checks call it: diagnose()
with the DART replay as the simulation, written with its page and replay logs.
The checks (`validation`, `payload_checks`, `out_of_library`), the page
(`page`) and the printing (`printout`) import this module, never the reverse."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.fit.batch import BatchSimulate
from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.diagnosis.beyond.insertion_terms import insertion_applies, insertion_check
from dvrk_dart.diagnosis.beyond.one_configuration import ONE_CONFIGURATION_FILE, one_configuration_check
from dvrk_dart.diagnosis.output.page import diagnosis_page
from dvrk_dart.diagnosis.payload.parameter_band import apply_band, band_run, load_band
from dvrk_dart.diagnosis.beyond.refit import check_refit_inputs, refit_check
from dvrk_dart.diagnosis.fit.result import gaps
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic, write_text_atomic
from dvrk_dart.io.provenance import software_versions
from dvrk_dart.io.reference_data import load_run, resolve_run, run_label, sha256_of
from dvrk_dart.io.signal import process
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS, SimConfig

IMAGE_SUFFIXES = (".png", ".svg")


def simulation_hook(arm: Arm, executor: str = "local", jobs: int = 2, ray_address: str | None = None):
    """The diagnosis's `simulate(config, processed) -> efforts`: the DART
    replay, its independent replays run side by side on the executor."""
    return BatchSimulate(arm, executor, jobs, ray_address)


def sim_config_of(result: dict) -> SimConfig:
    """The SimConfig of the selected effects (diagnose() reports it as a dict)."""
    raw = result.get("sim_config")
    return SimConfig.from_dict(raw) if raw else SimConfig()


def base_sim_config(arm: Arm) -> SimConfig:
    """What the diagnosis simulates before any effect (the model card's [diagnosis] base)."""
    if arm.model.diagnosis_base == "identified":
        return IDENTIFIED_PHYSICS
    return SimConfig()


def log_replays(arm: Arm, measured: str, config_after: SimConfig, out_dir: Path, topics: BagTopics = BagTopics()) -> None:
    """MCAP and Rerun logs of the replay before (the diagnosis's base: the
    identified inertia, or the identified arm) and after (with the selected
    effects as physics)."""
    from dvrk_dart.runs.campaign import write_run_folder
    from dvrk_dart.runs.replay import replay_processed
    from dvrk_dart.runs.runner import rcm_position

    processed = process(load_run(resolve_run(measured), arm.model, topics))
    for label, config in (("before", base_sim_config(arm)), ("after", config_after)):
        record = replay_processed(processed, measured, "velocity", config, None, 5, arm.model, arm.params)
        record.name = f"diagnosis-{run_label(measured)}_{label}"
        record.config = {"scenario": {"name": record.name, "kind": "replay", "measured": str(measured)}, "mode": "velocity",
                         "counterweight": config.counterweight, "sim": config.to_dict()}
        record.markers.setdefault("rcm", rcm_position(arm))
        write_run_folder(record, out_dir / f"replay_{label}", arm.model)


def images_of(folder: Path) -> list[Path]:
    """The diagnosis figures (not those of the replay logs)."""
    return sorted(p for p in folder.rglob("*") if p.suffix in IMAGE_SUFFIXES and not any(part.startswith("replay_") for part in p.parts))


def run_diagnosis(arm: Arm, measured, out_dir: Path, baseline=None, train=(), holdout=(), logs: bool = True, repeat=None, payload_at=None,
                  parameter_band=None, executor: str = "local", jobs: int = 2, ray_address: str | None = None,
                  processing: str | None = "upstream", refit: bool = False, topics: BagTopics = BagTopics()) -> dict:
    """diagnose() with the DART replay, plus diagnosis.html and the replay logs
    (of the first measured run). parameter_band: a `dvrk-dart uncertainty`
    folder of one of the runs: effects are unmodelled only outside its band;
    refit: the identified parameters refitted on the training runs and judged
    on the held-out ones (`refit`)."""
    start = time.perf_counter()
    training = [*(measured if isinstance(measured, (list, tuple)) else [measured]), *train]
    if refit:
        check_refit_inputs(training, holdout, baseline)
    band = load_band(parameter_band) if parameter_band is not None else None  # a bad folder fails before any work
    if band is not None:
        _band_span(band, band_run(band, _runs_sha256([*training, baseline, *holdout, repeat])), arm, topics)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = diagnose(measured, baseline=baseline, train=list(train) or None, holdout=list(holdout) or None,
                      simulate=simulation_hook(arm, executor, jobs, ray_address), out_dir=out_dir, arm=arm, repeat=repeat, payload_at=payload_at,
                      processing=processing, base_config=base_sim_config(arm), topics=topics)
    if band is not None:
        apply_band(result, band)
    if refit:
        result["refit"] = refit_check(arm, training, holdout, result, out_dir, executor, jobs, ray_address, topics)
    if insertion_applies(arm, result, training, holdout, baseline):
        for key, check in (("insertion_terms", insertion_check), ("one_configuration", one_configuration_check)):
            try:
                result[key] = check(arm, training, holdout, result, executor, jobs, ray_address, topics)
            except DvrkDartError as exc:  # its replay failed or drifted: dropped with the reason, the diagnosis stands
                result[key] = None
                result["dropped_effects"].append({"effect": key, "reason": str(exc)})
    result["diagnosis_base"] = arm.model.diagnosis_base
    if holdout:
        result["identified_model_gap_holdout"] = identified_model_gap(arm, holdout, result["processing"], topics)
    measured = measured[0] if isinstance(measured, (list, tuple)) else measured
    result["params"] = {"path": str(arm.params.source), "sha256": sha256_of(arm.params.source)}
    result["versions"] = software_versions()
    _write_one_configuration(result, out_dir)
    result["wall_time_s"] = time.perf_counter() - start
    write_json_atomic(out_dir / "diagnosis.json", result)
    write_text_atomic(out_dir / "diagnosis.html", diagnosis_page(result, [str(p.relative_to(out_dir)) for p in images_of(out_dir)], page_title(result)))
    if logs:
        log_replays(arm, measured, sim_config_of(result), out_dir, topics)
    return result


def identified_model_gap(arm: Arm, holdout, processing: dict, topics: BagTopics = BagTopics()) -> list[float | None]:
    """The identified model on the held-out runs, in the diagnosis's band,
    pooled over their samples as the simulation's gaps are (result.gaps): what
    the diagnosis is measured against."""
    residuals, recorded = [], []
    for name in holdout:
        state = process(load_run(resolve_run(name), arm.model, topics), processing["processing"], processing.get("harmonics"))
        residuals.append(state.tau - state.in_band(arm.identified.predict(state.q, state.dq, state.ddq, "all")))
        recorded.append(state.measured)
    return gaps(residuals, np.all(recorded, axis=0))


def page_title(result: dict) -> str:
    """What the page scored: the held-out runs when there are, else the training runs."""
    trained = ", ".join(result.get("train_runs") or [result.get("measured", "")])
    if result.get("holdout_runs"):
        return f"diagnosis: fitted on {trained}, scored on held-out {', '.join(result['holdout_runs'])}"
    baseline = f" against the baseline {result['baseline']}" if result.get("baseline") else ""
    return f"diagnosis of {trained}{baseline}"


def _write_one_configuration(result: dict, out_dir: Path) -> None:
    """The one configuration with what its held-out gaps belong to: the runs,
    their processing (replay them with the same) and the arm's parameters."""
    combined = result.get("one_configuration")
    if combined:
        write_json_atomic(out_dir / ONE_CONFIGURATION_FILE, {
            "sim_config": combined["sim_config"], "joints": result["joints"], "units": result["units"],
            "gap_holdout": combined["gap_holdout"], "train_runs": result.get("train_runs"), "holdout_runs": result.get("holdout_runs"),
            "processing": {k: result["processing"].get(k) for k in ("processing", "harmonics")}, "params": result["params"],
            "method": combined["method"], "diagnosis": "diagnosis.json (one_configuration: its inputs, versions and figures)"})


def _band_span(band: dict, run: str, arm: Arm, topics: BagTopics) -> None:
    """The run's own duration beside the band's (a band replayed over the first
    seconds of a run judges those seconds: said with the verdicts)."""
    measured = load_run(resolve_run(run), arm.model, topics)
    band["run_duration_s"] = float(measured.t[-1] - measured.t[0])


def _runs_sha256(specs) -> dict[str, str]:
    """name -> content sha256 of the runs given by name or path ((run, baseline) pairs opened)."""
    flat = [part for spec in specs for part in (spec if isinstance(spec, tuple) else (spec,))]
    return {str(s): sha256_of(resolve_run(s)) for s in flat if isinstance(s, (str, Path))}

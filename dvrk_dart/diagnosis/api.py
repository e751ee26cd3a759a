"""The diagnosis as the CLI and the withheld-data checks call it: diagnose()
with the DART replay as the simulation, written with its page and replay logs.
The checks (`validation`, `payload_checks`, `out_of_library`), the page
(`page`) and the printing (`printout`) import this module, never the reverse."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.fit.session_floor import AT_FLOOR_RATIO, repeatable_share
from dvrk_dart.diagnosis.fit.batch import BatchSimulate
from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.diagnosis.beyond.insertion_terms import insertion_applies, insertion_check
from dvrk_dart.diagnosis.beyond.one_configuration import ONE_CONFIGURATION_FILE, one_configuration_check
from dvrk_dart.diagnosis.output.beyond_identified import beyond_identified
from dvrk_dart.diagnosis.output.page import diagnosis_page
from dvrk_dart.diagnosis.payload.parameter_band import apply_band, band_run, load_band
from dvrk_dart.diagnosis.beyond.refit import REFIT_FOLDER, check_refit_inputs, refit_check
from dvrk_dart.diagnosis.fit.result import gaps
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.outputs import FOLDER_ENTRIES
from dvrk_dart.io.atomic import write_json_atomic, write_text_atomic
from dvrk_dart.io.provenance import arm_model_record, file_record, software_versions
from dvrk_dart.io.reference_data import input_record, load_run, resolve_run, run_label, sha256_of
from dvrk_dart.io.signal import process
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS, SimConfig

IMAGE_SUFFIXES = (".png", ".svg")


@dataclass(frozen=True)
class DiagnosisConfig:
    """One diagnosis with the DART replay (`dvrk-dart diagnose`, every
    withheld-data check): the runs by role (each a reference run's name or a
    file), what else to study, where it runs and how the runs are read.

    measured: the run(s) whose gap is diagnosed (several: one set of effects
        for all, each against the baseline); baseline: the same trajectory
        without the effect under study; train: further training runs;
        holdout: runs only scored; repeat: the same motion in another session
        (the session floor); payload_at: 'LINK:x,y,z' or (link key, position),
        a hand-measured payload position; parameter_band: a `dvrk-dart
        uncertainty` folder; refit: refit the identified parameters on the
        training runs and judge them on the held-out ones; processing:
        upstream, periodic, or None (periodic where every run is periodic);
        logs: the replays before and after as MCAP and Rerun logs; figures:
        the residual's figures (diagnosis.html's, the report's); effort_scale:
        a scale of every measured effort among the candidates."""

    measured: tuple[str, ...]
    baseline: str | None = None
    train: tuple[str, ...] = ()
    holdout: tuple[str, ...] = ()
    repeat: str | None = None
    payload_at: object = None
    parameter_band: str | None = None
    refit: bool = False
    processing: str | None = None  # as the command's: periodic where every run is a periodic excitation
    executor: str = "local"
    jobs: int = 2
    ray_address: str | None = None
    logs: bool = True
    figures: bool = True
    topics: BagTopics = BagTopics()
    effort_scale: bool = False

    def __post_init__(self) -> None:
        for name in ("measured", "train", "holdout"):  # a single run given as its name
            value = getattr(self, name)
            object.__setattr__(self, name, (str(value),) if isinstance(value, (str, Path)) else tuple(str(v) for v in value))
        if not self.measured:
            raise DvrkDartError("--measured: at least one run to diagnose")

    @property
    def measured_spec(self):
        """What diagnose() takes: one run, or the list of them."""
        return self.measured[0] if len(self.measured) == 1 else list(self.measured)


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


def log_replays(arm: Arm, measured: str, config_after: SimConfig, out_dir: Path, processing: dict,
                topics: BagTopics = BagTopics()) -> None:
    """MCAP and Rerun logs of the replay before (the diagnosis's base: the
    identified inertia, or the identified arm) and after (with the selected
    effects as physics), the run read in the diagnosis's `processing` (its
    name and harmonics) so their figures are the diagnosis's."""
    from dvrk_dart.runs.campaign import write_run_folder
    from dvrk_dart.runs.replay import replay_processed
    from dvrk_dart.runs.runner import rcm_position

    processed = process(load_run(resolve_run(measured), arm.model, topics), processing["processing"], processing.get("harmonics"))
    for label, config in (("before", base_sim_config(arm)), ("after", config_after)):
        record = replay_processed(processed, measured, "velocity", config, None, 5, arm.model, arm.params)
        record.name = f"diagnosis-{run_label(measured)}_{label}"
        dynamics = arm.model.diagnosis_base + (" + the selected effects" if label == "after" else "")
        record.config = {"scenario": {"name": record.name, "kind": "replay", "measured": str(measured)}, "mode": "velocity",
                         "counterweight": config.counterweight, "dynamics": dynamics, "duration_s": record.metrics["duration_s"],
                         "processing": processing, "sim": config.to_dict(), "model_file": arm.model.source.name,
                         "arm_model": arm_model_record(arm.model), "params_file": str(arm.params.source),
                         "params_sha256": sha256_of(arm.params.source), "inputs": {str(measured): input_record(resolve_run(measured), arm.model, topics)}}
        record.metrics |= {"dynamics": dynamics, "samples": len(record)}
        record.markers.setdefault("rcm", rcm_position(arm))
        write_run_folder(record, out_dir / f"replay_{label}", arm.model)


def images_of(folder: Path) -> list[Path]:
    """The diagnosis figures (not those of the replay logs)."""
    return sorted(p for p in folder.rglob("*") if p.suffix in IMAGE_SUFFIXES and not any(part.startswith("replay_") for part in p.parts))


def files_written(config: DiagnosisConfig) -> list[str]:
    """The files of fixed names a diagnosis with `config` writes (relative to its folder)."""
    names = ["diagnosis.json", "diagnosis.html", "where.csv", ONE_CONFIGURATION_FILE]
    return names + ([f"{REFIT_FOLDER}/{name}" for name in FOLDER_ENTRIES] if config.refit else [])


def run_diagnosis(arm: Arm, config: DiagnosisConfig, out_dir: Path) -> dict:
    """diagnose() on `arm` with the DART replay, what is studied on top of its
    effects (`config`), diagnosis.json and diagnosis.html (written once), and
    the replay logs of the first measured run."""
    start = time.perf_counter()
    c = config
    training, holdout = [*c.measured, *c.train], list(c.holdout)
    if c.refit:
        check_refit_inputs(training, holdout, c.baseline)
    band = load_band(c.parameter_band) if c.parameter_band is not None else None  # a bad folder fails before any work
    if band is not None:
        _band_span(band, band_run(band, _runs_sha256([*training, c.baseline, *holdout, c.repeat])), arm, c.topics)
    out_dir.mkdir(parents=True, exist_ok=True)
    found = diagnose(c.measured_spec, baseline=c.baseline, train=list(c.train) or None, holdout=holdout or None,
                     simulate=simulation_hook(arm, c.executor, c.jobs, c.ray_address), out_dir=out_dir, arm=arm, repeat=c.repeat,
                     payload_at=c.payload_at, processing=c.processing, base_config=base_sim_config(arm), topics=c.topics, write_json=False,
                     figures=c.figures, effort_scale=c.effort_scale)
    if band is not None:
        found = apply_band(found, band)
    studies = (arm, training, holdout, found, c.executor, c.jobs, c.ray_address, c.topics)
    beyond = _beyond_the_effects(studies, c.refit, insertion_applies(arm, found, training, holdout, c.baseline), out_dir)
    if holdout and c.baseline is None:  # held-out runs minus a baseline have no identified model's gap to compare with
        beyond["identified_model_gap_holdout"] = identified_model_gap(arm, holdout, found["processing"], c.topics)
        if not any(isinstance(run, (tuple, list)) for run in training):  # runs of their own, as gap_after's
            beyond["identified_model_gap_train"] = identified_model_gap(arm, training, found["processing"], c.topics)
    # the diagnosis and what was studied on top of it: built once here, written once
    result = {**found, **beyond, "diagnosis_base": arm.model.diagnosis_base, "arm_model": arm_model_record(arm.model),
              "params": file_record(arm.params.source), "versions": software_versions()}
    result = {**result, **(_repeatable_shares(result) if holdout else {})}
    result = {**result, "beyond_identified_model": beyond_identified(result), "wall_time_s": time.perf_counter() - start}
    result["explanation"] = {**result["explanation"], "of": _explanation_subject(result)}
    _write_one_configuration(result, out_dir)
    write_json_atomic(out_dir / "diagnosis.json", result)
    write_text_atomic(out_dir / "diagnosis.html", diagnosis_page(result, [str(p.relative_to(out_dir)) for p in images_of(out_dir)], page_title(result)))
    if c.logs:
        log_replays(arm, c.measured[0], sim_config_of(result), out_dir, result["processing"], c.topics)
    return result


def _explanation_subject(result: dict) -> str:
    """What `explanation`'s words are of (a script read "mostly explained" of a run whose J3 the diagnosis's
    simulation leaves at 2.2x the identified model's gap: that is `beyond_identified_model`'s)."""
    if result["diagnosis_base"] != "inertial":
        return "the gap to the simulation of the identified arm"
    beyond = " (`beyond_identified_model`: against the identified model itself)" if result.get("beyond_identified_model") else ""
    return f"the gap to the simulation of the identified inertia alone: the identified model's own terms count as explained{beyond}"


def _beyond_the_effects(studies: tuple, refit: bool, insertion: bool, out_dir: Path) -> dict:
    """What is studied on top of the selected effects (`studies`: arm, training
    and held-out runs, the diagnosis, executor, jobs, Ray address, topics): the
    refit (when asked), J3's terms and the one configuration (where they
    apply); a study whose replay fails or drifts is dropped with the reason."""
    arm, training, holdout, found, executor, jobs, ray_address, topics = studies
    beyond, dropped = {}, list(found["dropped_effects"])
    if refit:
        beyond["refit"] = refit_check(arm, training, holdout, found, out_dir, executor, jobs, ray_address, topics)
    if insertion:
        for key, check in (("insertion_terms", insertion_check), ("one_configuration", one_configuration_check)):
            try:
                beyond[key] = check(*studies)
            except DvrkDartError as exc:  # the diagnosis stands
                beyond[key] = None
                dropped.append({"effect": key, "reason": str(exc)})
    return {**beyond, "dropped_effects": dropped}


def _repeatable_shares(result: dict) -> dict:
    """With held-out runs and a session floor: per joint, the share of the
    identified model's repeatable gap (above the floor) the selected effects
    explain, and the one configuration's likewise (None on a joint the runs did not record)."""
    floor, after, combined = result.get("session_floor"), result["gap_after"]["holdout"], result.get("one_configuration")
    if floor is None or after is None:
        return {}

    def share(gap) -> list[float | None]:
        values = repeatable_share(*(np.asarray(x, dtype=float) for x in (result["identified_model_gap_holdout"], gap, floor)))
        return [None if np.isnan(v) else float(v) for v in values]

    shares = {"repeatable_gap_explained_share": share(after),
              "repeatable_gap_share_null_when": f"the identified model's held-out gap is within {AT_FLOOR_RATIO:g}x the session floor (no "
                                                "repeatable gap shown: a session's change alone can leave it), or the joint was not recorded"}
    if combined:
        shares["one_configuration"] = {**combined, "repeatable_gap_explained_share": share(combined["gap_holdout"])}
    return shares


def identified_model_gap(arm: Arm, runs, processing: dict, topics: BagTopics = BagTopics()) -> list[float | None]:
    """The identified model on `runs` (the held-out ones: what the diagnosis is measured against), in the
    diagnosis's band, pooled over their samples as the simulation's gaps are (result.gaps)."""
    residuals, recorded = [], []
    for name in runs:
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
            "processing": {k: result["processing"].get(k) for k in ("processing", "harmonics")}, "arm_model": result["arm_model"],
            "params": result["params"],
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

"""`dvrk-dart force`: the force at the instrument that a run's measured efforts
imply under a model (model/force.py), written as CSV, MCAP and Rerun logs
with a summary: in free motion, the model's phantom force."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.model.force import estimate_force, force_point_of, point_positions
from dvrk_dart.diagnosis.effects.library import config_effort_by_formula
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.excitation_design import read_design
from dvrk_dart.io.force_log import force_table, write_force_logs
from dvrk_dart.io.provenance import arm_model_record, file_record, software_versions
from dvrk_dart.io.reference_data import input_record, load_run, resolve_run, run_label
from dvrk_dart.io.signal import ProcessedRun, chosen_because, not_periodic_reason, process, process_all
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import PsmModel
from dvrk_dart.runs.config import DYNAMICS_CHOICES, RunConfig, diagnosis_sim_config, recorded_processing, sim_config_for
from dvrk_dart.sim.config import SimConfig


@dataclass(frozen=True)
class ForceConfig:
    measured: str
    dynamics: str = "identified"  # inertial | identified | a diagnosis.json / one_configuration.json
    processing: str | None = None  # None: the file's recorded one, else periodic where the run is periodic
    excitation: str | None = None
    #: how the run is read where it is a bag (--arm, --topic, --jaw-topic) or a CSV (--rate)
    topics: BagTopics = BagTopics()


def processed_run(config: ForceConfig, model: PsmModel) -> tuple[ProcessedRun, str]:
    """The run of `model`'s arm through the processing the options, the
    --dynamics file or the default choose, and why."""
    run = load_run(resolve_run(config.measured), model, config.topics)
    design = read_design(config.excitation) if config.excitation else None
    recorded = recorded_processing(config.dynamics)
    if recorded is not None and config.processing is None and design is None:
        try:
            return process(run, *recorded), f"the one {config.dynamics} was fitted on"
        except DvrkDartError as exc:  # the option the message names was not given: the file chose it
            raise DvrkDartError(f"{not_periodic_reason(exc)} (the processing --dynamics {config.dynamics} records; "
                                "--processing chooses another)") from None
    [state], note = process_all([run], config.processing, design)  # refuses --excitation with upstream
    return state, chosen_because(config.processing, config.excitation, None, note)


def model_efforts(arm: Arm, config: ForceConfig, state: ProcessedRun) -> np.ndarray:
    """The model's efforts at the run's samples, in the band of its measured efforts."""
    return state.in_band(config_effort_by_formula(arm, model_config(config.dynamics, arm), state.q, state.dq, state.ddq))


def model_config(dynamics: str, arm: Arm) -> SimConfig:
    """The physics of --dynamics on `arm`, evaluated by formula here (not simulated: a
    diagnosis's explicit terms need not be a physical DART damping)."""
    if dynamics in DYNAMICS_CHOICES:
        return sim_config_for(RunConfig("replay", "velocity", dynamics=dynamics))
    return diagnosis_sim_config(Path(dynamics), physical=False, model=arm.model, params_path=arm.params.source)


def instrument_force(arm: Arm, config: ForceConfig, out_dir: Path | None) -> dict:
    """Estimate, summarise and (with `out_dir`) write the logs and force.json."""
    state, why = processed_run(config, arm.model)
    missing = [f"q{j + 1}" for j in force_point_of(arm.model).joints if not state.measured[j]]
    if missing:
        raise DvrkDartError(f"--measured {config.measured}: {', '.join(missing)} not recorded: the force at the "
                            f"{force_point_of(arm.model).name} needs every joint that positions it")
    gap = state.tau - model_efforts(arm, config, state)
    estimate = estimate_force(arm.model, state.q, gap)
    point = force_point_of(arm.model)
    every_sample = estimate_force_all(arm, state.q, gap)
    summary = {
        "measured": run_label(config.measured), "dynamics": config.dynamics, "processing": state.processing, "chosen_because": why,
        **{k: v for k, v in state.summary().items() if k == "rate_note"},
        "point": point.name, "point_link": arm.model.links[point.link].name, "min_lever_m": point.min_lever_m,
        **estimate.summary(), "rms_all_samples_n": every_sample["rms_n"], "p95_all_samples_n": every_sample["p95_n"],
        "rms_per_axis_all_samples_n": every_sample["rms_per_axis_n"],
        "definition": "F = J^-T (tau_measured - tau_model) over the point's joints, base frame; a direction whose lever "
                      "(singular value of J) is under min_lever_m is not determined (NaN in force.csv); the figures are "
                      "over the determined samples, *_all_samples_* over every sample",
        "inputs": {run_label(config.measured): input_record(resolve_run(config.measured), arm.model, config.topics),
                   **({"excitation": file_record(Path(config.excitation))} if config.excitation else {}),
                   **({"dynamics": file_record(Path(config.dynamics))} if config.dynamics.endswith(".json") else {})},
        "arm_model": arm_model_record(arm.model), "params": file_record(arm.params.source), "versions": software_versions(),
    }
    if out_dir is not None:
        table = force_table(state.t, point_positions(arm.model, state.q, point.link), estimate.force, estimate.determined, estimate.lever_m)
        write_force_logs(out_dir, table, summary["measured"])
        write_json_atomic(out_dir / "force.json", summary)
    return summary


def one_period_forces(arm: Arm, config: ForceConfig) -> tuple[np.ndarray, np.ndarray]:
    """(t in the period, F) over the first period of a periodic run (NaN where not determined)."""
    state, _ = processed_run(config, arm.model)
    if state.periodic is None:
        raise DvrkDartError(f"{config.measured}: one period needs the periodic processing")
    n = state.first_period_samples()
    estimate = estimate_force(arm.model, state.q[:n], (state.tau - model_efforts(arm, config, state))[:n])
    return state.t[:n] - state.t[0], estimate.force


def estimate_force_all(arm: Arm, q: np.ndarray, gap: np.ndarray) -> dict:
    """The same estimate with every direction kept (the figure to compare with published phantom forces)."""
    from dataclasses import replace

    point = force_point_of(arm.model)
    model = replace(arm.model, force_point=replace(point, min_lever_m=0.0))
    return estimate_force(model, q, gap).summary()


def print_force_summary(s: dict) -> None:
    """What `dvrk-dart force` prints: the figures of force.json with their units."""
    print(f"force at the {s['point']} of {s['measured']} (model: --dynamics {s['dynamics']}{' (the default)' if s['dynamics'] == 'identified' else ''}, parameters {s['params']['path']}), "
          f"{s['processing']} processing ({s['chosen_because']})")
    if s.get("rate_note"):
        print(f"  note: {s['rate_note']}")
    if s["rms_n"] is None:
        print(f"  not determined on any sample: the lever arm stays under {s['min_lever_m']} m")
        return
    axes = " / ".join(f"{v:.3f}" for v in s["rms_per_axis_n"])
    print(f"  |F| RMS {s['rms_n']:.3f} N, 95th percentile {s['p95_n']:.3f} N, per axis x / y / z {axes} N "
          f"(over the {s['determined_fraction']:.0%} of samples with every lever >= {s['min_lever_m']} m)")
    print(f"  every sample, along the determined directions only: |F| RMS {s['determined_part_rms_n']:.3f} N")
    # its RMS is the few samples nearest a zero lever: 2018 test1 read 149 N at 200 Hz, 46 N resampled at 100 Hz
    print(f"  every sample, the short levers included (there J^-T divides by a lever near zero): 95th percentile "
          f"{s['p95_all_samples_n']:.3f} N; |F| RMS {s['rms_all_samples_n']:.3f} N, set by the samples nearest a zero lever "
          "(a published figure's way: not comparable between samplings of one motion)")

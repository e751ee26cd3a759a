"""The commands that simulate: `run` (a scenario) and `replay` (a measured run),
with their run configuration and printout (the parser is cli_parser.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.command_args import arm_model_file, reading_options
from dvrk_dart.model.joints import JOINT_NAMES


def _run_config(args: argparse.Namespace, scenario: str, mode: str, measured: str | None = None):
    from dvrk_dart.runs.config import RunConfig
    from dvrk_dart.runs.scenarios import load_scenario

    spec = load_scenario(scenario)
    _check_arm_of_scenario(args, spec)
    if mode == "kinematic":  # poses imposed: no dynamics for these options to change
        if args.dynamics is not None:  # an unknown value is named as such first
            from dvrk_dart.runs.config import sim_config_for

            sim_config_for(RunConfig("replay", "velocity", dynamics=args.dynamics))
        for option, value in (("--counterweight", args.counterweight), ("--dynamics", args.dynamics)):
            if value is not None:
                raise DvrkDartError(f"{option} {value}: a kinematic run imposes the poses and simulates no dynamics; "
                                    "use --mode velocity or torque")
    dynamics = args.dynamics or spec.dynamics
    counterweight = args.counterweight or ("on" if "on" in spec.counterweights else spec.counterweights[0])  # as --mode: the scenario's
    return RunConfig(scenario, mode, counterweight, dynamics, args.dt, args.duration, args.params, measured,
                     getattr(args, "processing", "upstream"), getattr(args, "harmonics", None), args.arm_model, reading_options(args))


def _check_arm_of_scenario(args: argparse.Namespace, spec) -> None:
    """A scenario written for one arm (its `arm_model`) is not run on another."""
    from dvrk_dart.model.description import resolve_arm_model

    asked = getattr(args, "arm_model", None)
    if asked and spec.arm_model and resolve_arm_model(asked) != resolve_arm_model(spec.arm_model):
        raise DvrkDartError(f"--arm-model {asked}: the scenario {spec.name} is the {spec.arm_model} arm's; leave --arm-model out")


def _print_effort_table(metrics: dict, dynamics: str | None, model) -> None:
    """The replay's RMS figures as a labelled table, a row per joint with its unit."""
    terms = metrics.get("model_terms_compared")
    columns = [("rms_sim_vs_model", "sim vs model"),
               ("rms_sim_vs_measured", "sim vs measured"), ("rms_model_vs_measured", "model (all terms) vs measured")]
    columns = [(key, label) for key, label in columns if metrics.get(key) is not None]
    if not columns:
        return
    hint = " (--dynamics identified would simulate every identified term)" if dynamics in (None, "inertial") else ""
    print(f"  RMS per joint, simulated arm: {dynamics or 'the scenario default'}{hint}"
          + (f"; model terms compared: {', '.join(terms)}" if terms else ""))
    print(f"  {'joint':>6}  " + "  ".join(f"{label:>22}" for _, label in columns))
    recorded = metrics.get("measured_joints") or list(JOINT_NAMES)
    for j, name in enumerate(JOINT_NAMES[:len(metrics[columns[0][0]])]):
        if name not in recorded:
            print(f"  {name:>6}  not measured (the run did not record its effort)")
            continue
        print(f"  {name:>6}  " + "  ".join(f"{metrics[key][j]:18.5f} {model.effort_unit(name):<3}" for key, _ in columns))


def _run_and_write(config, out: Path | None) -> int:
    from dvrk_dart.runs.campaign import code_fingerprint, inputs_fingerprint, write_run_folder
    from dvrk_dart.runs.runner import arm_of_run, run

    out_dir = _output_folder(config, out)
    arm = arm_of_run(config)
    record = run(config, arm)
    metrics = record.metrics
    if "error" in metrics:  # a run that stopped is no result: nothing written (validate's campaign keeps its logs, marked)
        raise DvrkDartError(f"{record.name}: {metrics['error']}; nothing written to {out_dir}")
    write_run_folder(record, out_dir, arm.model, inputs_fingerprint(config, code_fingerprint()))
    measured = metrics.get("measured_samples")
    logged = metrics.get("samples") or 0
    of_measured = (f" (of the measured run's {measured}: the simulation ends at the last)" if measured == logged + 1
                   else f" logged, at the measured run's {measured} samples compared" if measured else "")
    print(f"{record.name}: {logged} samples{of_measured}, {metrics.get('wall_time_s', 0):.1f} s wall -> {out_dir}")
    for note in [metrics.get("rate_note"), *metrics.get("effort_convention_notes", []), *metrics.get("unrecorded_joint_notes", []),
                 *metrics.get("tracking_notes", [])]:
        if note:
            print(f"note: {note}")
    _print_effort_table(metrics, config.dynamics, arm.model)
    for key, unit in (("tracking_rms_position", "m"), ("tracking_rms_orientation", "rad")):
        if metrics.get(key) is not None:
            print(f"  {key}: {float(np.max(metrics[key])):.3g} {unit}")
    return 0


def _output_folder(config, out: Path | None) -> Path:
    """--out, else out/runs/<the run's name>, checked (no work done yet)."""
    from dvrk_dart.io.outputs import check_output_folder
    from dvrk_dart.runs.campaign import config_name

    out_dir = check_output_folder(out or Path("out") / "runs" / config_name(config), "run")
    if out is None:
        _check_default_folder_input(out_dir, config)
    return out_dir


def _check_default_folder_input(out_dir: Path, config) -> None:
    """A default run folder is named after the measured file's name: one that holds the run of another file of
    that name (another folder's x.csv) is not replaced silently."""
    import json

    from dvrk_dart.io.reference_data import resolve_run

    if config.measured is None or not (out_dir / "config.json").is_file():
        return
    try:
        before = [Path(entry["path"]) for entry in json.loads((out_dir / "config.json").read_text())["inputs"].values()]
    except (ValueError, KeyError, TypeError, AttributeError):
        return  # not a replay's record: replaced as any run folder the tool made
    now = resolve_run(config.measured).resolve()
    if before and all(path.resolve() != now for path in before):
        raise DvrkDartError(f"{out_dir} holds the replay of {before[0]}, another file than {now}: give --out")


def cmd_run(args: argparse.Namespace) -> int:
    """One scenario variant -> its output folder."""
    from dvrk_dart.runs.scenarios import load_scenario

    spec = load_scenario(args.scenario)
    config = _run_config(args, args.scenario, args.mode or spec.modes[0])
    if spec.kind == "replay":  # every command says how it read a measured run
        print(f"processing: {config.processing} (a scenario file's replay; dvrk-dart replay chooses it from the run, or takes --processing)")
    return _run_and_write(config, Path(args.out))


def cmd_replay(args: argparse.Namespace) -> int:
    """Replay of a measured run (the paper's Sect. IV-B excitation test)."""
    recorded, said = _replay_processing(args)
    config = _run_config(args, "replay", args.mode, measured=args.measured)
    _output_folder(config, Path(args.out) if args.out else None)
    print(said)  # once the options are known good: an error is the only line
    try:
        return _run_and_write(config, Path(args.out) if args.out else None)
    except DvrkDartError as exc:
        if recorded and "--processing periodic" in str(exc):  # the user did not ask for it: say where it came from
            raise DvrkDartError(f"{exc}; --dynamics {args.dynamics} records the periodic processing: give --processing upstream") from None
        raise


def _replay_processing(args: argparse.Namespace) -> tuple[bool, str]:
    """Set a replay's processing (and harmonic cutoff) when --processing is not
    given: the one a --dynamics diagnosis file was fitted on, so that the replay
    finds its figures; upstream otherwise. (True when it came from the file, the line saying it.)"""
    from dvrk_dart.runs.config import recorded_processing

    args.harmonics = None
    if args.processing == "periodic" and args.duration is not None:
        raise DvrkDartError("--duration with --processing periodic: a part of a run has no periodic projection of its own; "
                            "replay the whole run, or give --processing upstream")
    if args.processing is not None:
        return False, f"processing: {args.processing} (--processing {args.processing})"
    recorded = recorded_processing(args.dynamics)
    if args.duration is not None:
        args.processing = "upstream"
        return False, "processing: upstream (--duration replays a part of the run, which has no projection of its own)"
    if recorded is None:  # the default of every command: periodic where the run is a periodic excitation
        from dvrk_dart.io.reference_data import load_run, resolve_run
        from dvrk_dart.io.signal import process_all
        from dvrk_dart.model.model_file import load_model

        [processed], note = process_all([load_run(resolve_run(args.measured), load_model(arm_model_file(args)), reading_options(args))], None)
        args.processing = processed.processing
        return False, f"processing: {args.processing} ({note or 'the default: the run is a periodic excitation'})"
    args.processing, args.harmonics = recorded
    cutoff = "" if args.harmonics is None else f", {args.harmonics} harmonics"
    return True, f"processing: {args.processing}{cutoff} (the one {args.dynamics} was fitted on)"

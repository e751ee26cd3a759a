"""The `dvrk-dart` command line. Every user-facing error is one line on stderr
and exit code 2 (no traceback)."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from pathlib import Path

from dvrk_dart import cli_config, cli_parser
from dvrk_dart.errors import DvrkDartError, interrupted, raise_if_interrupted
from dvrk_dart.command_args import arm_model_file, command_arm, reading_options
from dvrk_dart.model.joints import JOINT_NAMES
# commands kept beside their own kind; the parser finds every cmd_* here
from dvrk_dart.model_commands import cmd_force, cmd_model_check, cmd_model_errors, cmd_session_floor  # noqa: F401
from dvrk_dart.run_commands import cmd_replay, cmd_run  # noqa: F401
from dvrk_dart.bag_commands import cmd_excitation, cmd_export, cmd_import  # noqa: F401


#: the options that name measured runs (any of them may be a bag)
RUN_OPTIONS = ("measured", "repeat", "runs", "holdout", "baseline", "train", "bag")


#: the options that name files or folders a command reads (argparse dest: option)
INPUT_OPTIONS = {"measured": "--measured", "runs": "--runs", "repeat": "--repeat", "holdout": "--holdout", "train": "--train",
                 "baseline": "--baseline", "prior": "--prior", "params": "--params", "params_cov": "--params-cov",
                 "parameter_band": "--parameter-band", "bounds": "--bounds", "dynamics": "--dynamics", "bag": "--bag",
                 "arm_model": "--arm-model", "extra": "--extra"}
OUTPUT_OPTIONS = {"out": "--out", "report": "--report"}


def _values(args: argparse.Namespace, dest: str) -> list:
    """An option's values as a list (one value, several, or none)."""
    values = getattr(args, dest, None)
    return list(values) if isinstance(values, (list, tuple)) else [values]


def _check_outputs_apart_from_inputs(args: argparse.Namespace) -> None:
    """No output (replaced whole) holds an input, and none is written into an
    input's folder (a bag, a run folder): refused before any work, even with --force."""
    from dvrk_dart.io.bags import is_bag
    from dvrk_dart.io.outputs import check_not_inside

    empty = [option for dest, option in OUTPUT_OPTIONS.items() if getattr(args, dest, None) == ""]
    if empty:
        raise DvrkDartError(f"{empty[0]}: an empty name")
    outputs = [(getattr(args, dest), option) for dest, option in OUTPUT_OPTIONS.items() if getattr(args, dest, None)]
    for dest, option in INPUT_OPTIONS.items():
        option = "the input bag" if dest == "bag" and getattr(args, "command", None) == "import" else option  # a positional there
        for value in _values(args, dest):
            if not isinstance(value, (str, os.PathLike)) or not Path(value).exists():
                continue  # a reference run's name, a dynamics keyword, or absent
            folder = Path(value).resolve()
            if folder.is_file() and is_bag(folder.parent):  # a bag given by its .mcap/.db3: the bag is the folder
                folder = folder.parent
            for out, out_option in outputs:
                check_not_inside(value, out, option, out_option)
                if folder.is_dir() and folder in Path(out).resolve().parents:
                    raise DvrkDartError(f"{out_option}: {out} is inside {option} {value}: an output is not written into an input")


def _check_arm_of_reference_runs(args: argparse.Namespace) -> None:
    """A reference run of another arm than --arm-model (mtm-one without --arm-model mtm) is named, not read as this arm's."""
    from dvrk_dart.io.reference_data import RUNS, reference_run_arm
    from dvrk_dart.model.description import DEFAULT_ARM, resolve_arm_model

    if not hasattr(args, "arm_model"):
        return
    asked = resolve_arm_model(args.arm_model or DEFAULT_ARM)
    for dest in RUN_OPTIONS:
        for value in _values(args, dest):
            if isinstance(value, str) and value in RUNS and not _same_arm(resolve_arm_model(reference_run_arm(value)), asked):
                arm = reference_run_arm(value)
                raise DvrkDartError(f"--{dest}: {value} is a recording of the {arm.upper()}: add --arm-model {arm}")


def _same_arm(card: Path, asked: Path) -> bool:
    """The card itself, or a copy of it (models/psm/ copied and edited, the same name): a file that is not a
    valid card is said here, in its own words."""
    from dvrk_dart.model.model_file import load_model

    return card == asked or load_model(asked).name == load_model(card).name


def _check_bag_options(args: argparse.Namespace) -> None:
    """--arm, --topic and --jaw-topic select data in a bag: with no bag among the inputs they would do nothing."""
    from dvrk_dart.io.bags import is_bag
    from dvrk_dart.io.reference_data import RUNS

    given = [f"--{name.replace('_', '-')}" for name in ("arm", "topic", "jaw_topic") if getattr(args, name, None) is not None]
    inputs = []
    for name in RUN_OPTIONS:
        value = getattr(args, name, None)
        inputs += value if isinstance(value, list) else [value] if value else []
    if given and not any(str(v) not in RUNS and is_bag(str(v)) for v in inputs):
        raise DvrkDartError(f"{given[0]}: selects the topics of a ROS bag, and no input of this command is one")


def cmd_validate(args: argparse.Namespace) -> int:
    """The main job: the campaign, its report and the sim-to-real diagnosis."""
    from dvrk_dart.io.outputs import (
        check_not_inside,
        check_output_folder,
        check_shared_folder,
    )
    from dvrk_dart.pipeline import VALIDATION_KIND, validate

    check_shared_folder(args.out, VALIDATION_KIND)
    if args.dynamics is not None:
        from dvrk_dart.model.description import DEFAULT_MODEL_FILE
        from dvrk_dart.model.model_file import load_model
        from dvrk_dart.runs.config import RunConfig, sim_config_for

        # a bad --dynamics fails now, not after the campaign (its runs are the PSM's)
        sim_config_for(RunConfig("replay", "velocity", dynamics=args.dynamics), load_model(DEFAULT_MODEL_FILE))
    check_output_folder(args.report, "report", "--report")
    check_not_inside(args.out, args.report, "--out", "--report")
    if Path(args.out).resolve() in Path(args.report).resolve().parents:  # validate rewrites its --out's folders whole
        raise DvrkDartError(f"--report: {args.report} is inside --out {args.out}, whose folders validate replaces: give it a folder of its own")

    return validate(Path(args.out), Path(args.report), jobs=args.jobs, force=args.force, dynamics=args.dynamics,
                    executor=args.executor, ray_address=args.ray_address)


def cmd_report(args: argparse.Namespace) -> int:
    from dvrk_dart.analysis.report import build_report, unreadable_runs

    index = build_report(Path(args.runs), Path(args.out), extra_sections=Path(args.extra) if args.extra else None, jobs=args.jobs,
                         allow_unreadable=args.allow_unreadable)
    for name, error in unreadable_runs(Path(args.out)).items():
        print(f"dvrk-dart: left out of the report, unreadable run {name}: {error}", file=sys.stderr)
    print(f"report: {index}")
    return 0


def cmd_diagnose(args: argparse.Namespace) -> int:
    """The diagnosis folder is built beside --out and replaces it whole at the end."""
    from dvrk_dart.diagnosis.api import DiagnosisConfig, files_written, run_diagnosis
    from dvrk_dart.diagnosis.output.printout import print_diagnosis
    from dvrk_dart.io.outputs import building_folder, check_output_folder

    config = DiagnosisConfig(args.measured, args.baseline, args.train, args.holdout, args.repeat, args.payload_at, args.parameter_band,
                             args.refit, args.processing, args.executor, args.jobs, args.ray_address, topics=reading_options(args),
                             effort_scale=args.effort_scale)
    check_output_folder(args.out, "diagnosis", writes=files_written(config))
    with building_folder(args.out, "diagnosis") as folder:
        print_diagnosis(run_diagnosis(command_arm(args), config, folder))
    print(f"written {Path(args.out) / 'diagnosis.json'}")
    return 0


def cmd_identify(args: argparse.Namespace) -> int:
    """Identify the dynamic parameters from measured runs: params.json and its reports."""
    from dvrk_dart.identification.identify import IdentificationConfig
    from dvrk_dart.identification.outputs import identify_into_folder
    from dvrk_dart.identification.regressor import FrictionLaw

    config = IdentificationConfig(
        runs=tuple(args.runs), holdout=tuple(args.holdout), joints=tuple(args.joints),
        friction_law=FrictionLaw(args.friction_law, args.reversal_velocity), bounds_file=args.bounds,
        prior=args.prior, seed=args.seed, processing=args.processing, excitation=args.excitation,
        model_file=str(arm_model_file(args)), topics=reading_options(args),
    )
    result, data = identify_into_folder(config, args.out)
    processing = data["processing"]
    print(f"processing: {processing['processing']} ({processing['chosen_because']})")
    for name, run in processing["runs"].items():
        if run.get("rate_note"):
            print(f"note: {name}: {run['rate_note']}")
    for line in data["left_out"]:
        print(f"note: {line}")
    extent = data["data"]
    periods = f", {extent['whole_periods']} whole periods" if extent["whole_periods"] is not None else ""
    print(f"identified {data['n_base']} base parameters ({data['n_standard']} standard) from {extent['runs']} run(s), "
          f"{extent['seconds']:.1f} s{periods}: condition number {data['condition_number']:.3g}; fitted in {result.timings_s['total_s']:.1f} s -> {args.out}")
    _print_identification_errors(data)
    for line in data["warnings"]:
        print(f"warning: {line}")
    departure = data["consistent_departure"]
    print(f"the physical fit (params.json) lies up to {departure['max_standard_errors']:.3g} standard errors from the weighted least "
          f"squares ({departure['base_parameter']}; {departure['over_3_standard_errors']} of {departure['of']} base parameters over 3): "
          "the standard errors leave out model error and the constraints")
    if not data["errors"].get("holdout"):
        few = " (one short run may not determine the arm)" if extent["runs"] == 1 else ""
        print(f"note: no --holdout run: how well these parameters carry to another motion is not measured{few}")
    print(f"friction law: {data['config']['friction_law']}")
    if args.friction_law == "tanh":
        print("note: errors above use the tanh law; params.json readers apply sign(v)")
    worst = min(min(v) for v in data["pseudo_inertia_eigenvalues_kg_m2"].values())
    # the solver meets a bound to its tolerance (5.000000000005 kg on [5, 5])
    outside = [k for k, m in data["masses_kg"].items() if not m["lower"] - 1e-6 * m["upper"] <= m["value"] <= m["upper"] * (1 + 1e-6)]
    print(f"smallest pseudo-inertia eigenvalue {worst:.3g} kg m^2; masses outside their bounds: {outside or 'none'}; "
          f"params: {Path(args.out) / 'params.json'}")
    return 0


def _print_identification_errors(data: dict) -> None:
    """identify's table: each run's RMS per joint, training and held out, and the reference parameters' on the held-out runs."""
    from dvrk_dart.io.reference_data import distinct_labels

    print(f"{'run':<22} " + " ".join(f"{j:>7}" for j in JOINT_NAMES) + f"   (RMS, N·m, N for a prismatic joint; fitted: {' '.join(data['fitted_joints'])})")
    reference = data.get("reference") or {}
    labels = distinct_labels([*(name for runs in data["errors"].values() for name in runs), *(reference.get("errors_first_period") or {})])
    whole_samples = {name: spans["whole_run"]["samples"] for runs in data["errors"].values() for name, spans in runs.items()}

    def span_label(name: str, span: str, samples: int) -> str:  # a run shorter than a period: its first "period" is the run
        short = span == "first_period" and samples >= whole_samples.get(name, samples + 1)
        return f"{labels[name]} {'whole (< 1 period)' if short else span.replace('_run', '')}"

    for kind, runs in data["errors"].items():
        for name, spans in runs.items():
            for span, e in spans.items():
                label = span_label(name, span, e["samples"])
                fitted = [v if j in data["fitted_joints"] else None for j, v in zip(JOINT_NAMES, e["rms"])]  # no figure on a joint not fitted
                print(f"{label:<22} " + " ".join("      -" if v is None else f"{v:7.4f}" for v in fitted) + f"   {kind}")
    for name in reference.get("errors_first_period") or {}:
        for span in ("whole_run", "first_period"):
            e = reference[f"errors_{span}"][name]
            print(f"{span_label(name, span, e['samples']):<22} " + " ".join("      -" if v is None else f"{v:7.4f}" for v in e["rms"])
                  + f"   holdout, the reference parameters ({Path(reference['params_file']).name}: the arm's published ones)")


def cmd_uncertainty(args: argparse.Namespace) -> int:
    """Monte Carlo over the parameters' uncertainty: the effort band and the measured run in it."""
    from dvrk_dart.runs.uncertainty import UncertaintyConfig, run_uncertainty

    config = UncertaintyConfig(args.measured, args.samples, args.seed, None if args.params_cov else args.relative_std,
                               args.params_cov, args.duration, executor=args.executor, jobs=args.jobs, processing=args.processing,
                               arm_model=str(arm_model_file(args)), topics=reading_options(args))
    summary = run_uncertainty(config, args.out, args.ray_address)
    print(f"parameters: {summary['parameters']}; {summary['samples_replayed']} replays in {summary['wall_time_s']:.3g} s (wall) -> {args.out}")
    print(f"processing: {summary['processing']['processing']} ({summary['processing']['chosen_because']})")
    print(f"{'joint':>6} {'inside':>7} {'outside rms':>16} {'model inside':>13}")
    for j, name in enumerate(JOINT_NAMES):
        inside, outside = summary["measured_inside_band_fraction"][j], summary["rms_measured_outside_band"][j]
        if inside is None:
            print(f"{name:>6}  not measured (the run did not record its effort)")
            continue
        print(f"{name:>6} {inside:7.3f} {outside:11.4f} {summary['effort_units'][j]:<4} {summary['nominal_model_inside_band_fraction'][j]:13.3f}")
    for name, error in summary["failed_samples"].items():
        print(f"dvrk-dart: sample {name} failed: {error}", file=sys.stderr)
    return 0


class Terminated(BaseException):
    """SIGTERM, raised like Ctrl-C so that partial outputs are cleaned up."""


def _terminate(signum, frame) -> None:
    raise Terminated()



def _interrupt(signum, frame) -> None:
    """Ctrl-C as usual, remembered (`errors.interrupted`): an interrupt that
    lands in an extension module surfaces as another error (an ImportError, a
    SystemError from a compiled kernel) or is swallowed in a callback."""
    interrupted.set()
    raise KeyboardInterrupt


def build_parser() -> argparse.ArgumentParser:
    return cli_parser.build_parser(sys.modules[__name__])


def _repeated_option(argv: list[str]) -> str | None:
    """The first option given twice (argparse would keep the last one silently)."""
    seen = set()
    for token in argv:
        if token == "--":
            break
        name = token.split("=", 1)[0]
        if name.startswith("--") and name in seen:
            return name
        seen.add(name)
    return None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    args = _parse(argv)
    if isinstance(args, int):  # --help, or a usage error already said in one line
        return args
    interrupted.clear()  # (main may run several times in one process: the tests)
    with _signals_handled():
        return _run(args)


def _parse(argv: list[str]) -> argparse.Namespace | int:
    """The command's options (a --config file's among them), or the exit code of a usage error."""
    repeated = _repeated_option(argv)
    if repeated:
        print(f"dvrk-dart: {repeated}: given twice (an option takes its values once: {repeated} A B where it takes several)",
              file=sys.stderr)
        return 2
    parser = build_parser()
    try:
        return parser.parse_args(cli_config.expand_config(argv, parser))
    except SystemExit as exc:  # --help, or a usage error already printed in one line
        return int(exc.code or 0)
    except DvrkDartError as exc:  # --config FILE.toml
        print(f"dvrk-dart: {exc}", file=sys.stderr)
        return 2


@contextlib.contextmanager
def _signals_handled():
    """SIGTERM and SIGINT end the command with its partial outputs removed (in the main thread)."""
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    # (an ignored SIGINT, as under nohup, stays ignored)
    previous_interrupt = signal.signal(signal.SIGINT, _interrupt) if main_thread and signal.getsignal(signal.SIGINT) is not signal.SIG_IGN else None
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        if previous_interrupt is not None:
            signal.signal(signal.SIGINT, previous_interrupt)


def _check(args: argparse.Namespace) -> None:
    """What argparse cannot check alone: the Ray address, combinations, outputs apart from inputs, the runs' arm, bag options."""
    if getattr(args, "executor", None) == "ray":
        from dvrk_dart.runs.executors import check_ray_address

        check_ray_address(args.ray_address)
    cli_parser.check_combinations(args)
    _check_outputs_apart_from_inputs(args)
    _check_arm_of_reference_runs(args)
    if hasattr(args, "jaw_topic"):  # a command that reads measured runs, which may be bags
        _check_bag_options(args)


def _stopped(how: str, written_before: int) -> str:
    """The line of a command stopped by a signal: what it removed, and the folders it had completed."""
    from dvrk_dart.io.outputs import FOLDERS_WRITTEN

    complete = FOLDERS_WRITTEN[written_before:]
    kept = f"; {', '.join(map(str, complete))} written before it, complete" if complete else ""
    return f"dvrk-dart: {how} (partial outputs removed{kept})"


def _run(args: argparse.Namespace) -> int:
    """The command, its failures as one line and an exit code."""
    from dvrk_dart.io.outputs import FOLDERS_WRITTEN

    written_before = len(FOLDERS_WRITTEN)
    try:
        _check(args)
        code = args.func(args)
        raise_if_interrupted()  # a Ctrl-C swallowed on the way: the outputs were not committed after it
        return code
    except DvrkDartError as exc:
        print(f"dvrk-dart: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(_stopped("interrupted", written_before), file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of stdout left (| head): nothing more to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # a file the system refuses (permissions, a full disk): its name and why, in one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"dvrk-dart: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Terminated:
        print(_stopped("terminated", written_before), file=sys.stderr)
        return 143
    except RuntimeError as exc:  # pathlib's "Symlink loop from '...'": a path given, not a fault of the tool
        if not str(exc).startswith("Symlink loop"):
            raise
        print(f"dvrk-dart: {exc}: a symbolic link that leads back to itself", file=sys.stderr)
        return 2
    except Exception:  # an interrupt that surfaced as another error (ImportError, SystemError) is an interrupt
        if not interrupted.is_set():
            raise
        print(_stopped("interrupted", written_before), file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

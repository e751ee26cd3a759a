"""The commands that turn runs into files for a real dVRK and back: `import`
(a ROS bag -> the measured-run CSV), `export` (a simulated run -> a ROS 2 bag),
`excitation` (a trajectory to play, CSV + bag). The parser is cli_parser.py."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dvrk_dart.command_args import arm_model_file, command_arm, reading_options
from dvrk_dart.errors import DvrkDartError


def cmd_import(args: argparse.Namespace) -> int:
    """A ROS bag -> the 21-column measured-run CSV (model coordinates, 200 Hz)."""
    from dvrk_dart.io.atomic import atomic_path
    from dvrk_dart.io.bags import is_bag
    from dvrk_dart.io.outputs import MARKER, check_writable_folder, enclosing_output
    from dvrk_dart.io.reference_data import load_run, sample_rate_hz
    from dvrk_dart.model.model_file import load_model

    topics = reading_options(args)
    if topics.rate != sample_rate_hz():
        raise DvrkDartError(f"--rate: the 21-column CSV has no time column and is read at {sample_rate_hz():g} Hz; import at that rate")
    if not is_bag(args.bag):
        raise DvrkDartError(f"{args.bag}: not a ROS bag (a rosbag2 folder with metadata.yaml, an .mcap/.db3 file or a ROS 1 .bag)")
    out, bag = Path(args.out), Path(args.bag)
    if out.resolve() == bag.resolve() or bag.resolve() in out.resolve().parents:
        raise DvrkDartError(f"--out: {out} is the input bag {bag} or inside it: refusing to write over the input, even with --force")
    if out.is_symlink():
        raise DvrkDartError(f"--out: {out} is a symbolic link: give the file itself, or a new name")
    owner = enclosing_output(out) or next((p for p in out.absolute().resolve().parents if (p / MARKER).is_file()), None)
    if owner is not None:
        raise DvrkDartError(f"--out: {out} is inside {owner}, a folder dvrk-dart wrote, which holds only what its command wrote: "
                            "write the CSV elsewhere")
    if out.is_dir() or str(args.out).endswith(("/", "\\")):  # Path drops a trailing slash: bags/new/ named a file 'new'
        raise DvrkDartError(f"--out: {args.out} is a folder, not the CSV file to write")
    if out.suffix.lower() != ".csv":  # a measured run's CSV under another name (imp.json) read as something else later
        raise DvrkDartError(f"--out: {out} is not a .csv name: import writes a measured-run CSV")
    if out.exists() and not out.is_file():
        raise DvrkDartError(f"--out: {out} is not a regular file (a device, a pipe): refusing to replace it")
    if out.exists() and not args.force:
        raise DvrkDartError(f"--out: {out} exists (--force replaces it)")
    check_writable_folder(out.absolute().parent)
    run = load_run(args.bag, load_model(arm_model_file(args)), topics)  # the checks of every reader
    values = np.hstack([run.q, run.dq, run.tau])
    with atomic_path(out) as tmp:
        np.savetxt(tmp, values, delimiter=",", fmt="%.17g")
    print(f"{args.bag}: {len(run)} samples ({run.t[-1]:.2f} s at {topics.rate:g} Hz) -> {out}")
    return 0


def _model_of_run(run_dir: Path) -> Path:
    """The arm model a run folder was simulated with (its config.json's model_file), else the PSM's."""
    from dvrk_dart.model.description import DEFAULT_ARM, resolve_arm_model

    try:
        name = Path(json.loads((run_dir / "config.json").read_text())["model_file"]).stem
    except (OSError, ValueError, KeyError, TypeError):
        return resolve_arm_model(DEFAULT_ARM)
    try:
        return resolve_arm_model(name)
    except DvrkDartError:
        raise DvrkDartError(f"{run_dir}: simulated with the arm model {name}, which is not in models/") from None


def cmd_export(args: argparse.Namespace) -> int:
    """A simulated run -> a ROS 2 bag with the topics and types a real PSM publishes."""
    from dvrk_dart.io.bag_writer import export_run
    from dvrk_dart.io.bags import check_arm_namespace
    from dvrk_dart.io.outputs import check_writable_folder
    from dvrk_dart.model.model_file import load_model

    run_dir, bag = Path(args.run_dir), Path(args.bag)
    if run_dir.resolve() in bag.absolute().resolve().parents:
        raise DvrkDartError(f"--bag: {bag} is inside the run folder {run_dir}: a run folder holds only what the run wrote")
    check_writable_folder(bag.absolute().parent, "--bag")
    if bag.suffix == ".bag" and args.storage != "ros1":
        raise DvrkDartError(f"--bag: {bag} is a ROS 1 bag's name and --storage {args.storage} writes a rosbag2 folder: "
                            "add --storage ros1, or name the folder without .bag")
    model = load_model(_model_of_run(run_dir))  # an MTM run gets the MTM's topics and joint names
    check_arm_namespace(args.arm, model.dvrk_topics)
    out = export_run(run_dir, bag, model, args.arm, args.storage)
    print(f"{args.run_dir} -> {out}")
    return 0


def cmd_excitation(args: argparse.Namespace) -> int:
    """An excitation to play on a real dVRK: CSV + ROS 2 bag of servo_jp commands."""
    from dvrk_dart.io.bags import check_arm_namespace
    from dvrk_dart.io.outputs import building_folder, check_output_folder
    from dvrk_dart.io.reference_data import sample_rate_hz
    from dvrk_dart.runs.excitation import build_excitation, write_excitation

    check_output_folder(args.out, "excitation")
    arm = command_arm(args)
    check_arm_namespace(args.arm, arm.model.dvrk_topics)
    excitation = build_excitation(args.name, args.rate if args.rate is not None else sample_rate_hz(), arm)
    with building_folder(args.out, "excitation") as folder:
        summary = write_excitation(excitation, folder, arm.model, args.arm)
    print(f"excitation {args.name}: {summary['samples']} samples, {summary['duration_s']:.2f} s -> {args.out}/{summary['csv']}, {args.out}/{summary['bag']}")
    print(f"  the bag plays it from rest, speeding up over its first {summary['lead_s']:g} s and slowing to rest over its last")
    print("  start pose (move there first, e.g. with move_jp): " + ", ".join(f"{k} {v:.4f}" for k, v in summary["start_pose"].items()))
    return 0

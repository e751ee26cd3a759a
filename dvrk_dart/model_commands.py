"""The commands that compare the identified model with a measured run:
`model-errors`, `force`, `session-floor`, `model-check` (the parser is cli_parser.py)."""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.command_args import command_arm, reading_options
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.signal import CUT_SAMPLES
from dvrk_dart.io.period import spanning_columns
from dvrk_dart.model.joints import JOINT_NAMES


@dataclass(frozen=True)
class ModelErrorsConfig:
    """`model-errors`: the identified model against one measured run."""

    measured: str
    processing: str | None = None
    excitation: str | None = None
    terms: str = "all"
    first_period: bool = False
    topics: BagTopics = BagTopics()
    harmonics: int | None = None  # the periodic band imposed (--harmonics), else read from the run


def model_errors(arm: Arm, config: ModelErrorsConfig) -> dict:
    """Per-joint relative and RMS error of the identified model on the run (`null` where a joint is not recorded)."""
    from dvrk_dart.io.excitation_design import read_design
    from dvrk_dart.io.provenance import file_record
    from dvrk_dart.io.reference_data import load_run, resolve_run
    from dvrk_dart.io.signal import chosen_because, process_all
    from dvrk_dart.metrics import per_measured_joint, relative_error, rms
    from dvrk_dart.model.identified import TERMS, parse_terms, terms_label
    from dvrk_dart.identification.effort_convention import effort_convention_notes
    from dvrk_dart.identification.unrecorded_joints import unrecorded_joint_notes

    terms = parse_terms(config.terms)
    design = read_design(config.excitation) if config.excitation else None
    [processed], note = process_all([load_run(resolve_run(config.measured), arm.model, config.topics)], config.processing, design,
                                    config.harmonics)
    why = chosen_because(config.processing, config.excitation, config.harmonics, note)
    with np.errstate(over="ignore", invalid="ignore"):
        predicted = processed.in_band(arm.identified.predict(processed.q, processed.dq, processed.ddq, terms))
        sane = np.all(np.isfinite(predicted)) and np.all(np.isfinite(rms(predicted - processed.tau)))
    if not sane:
        raise DvrkDartError(f"--params {arm.params.source}: the model's efforts on {config.measured} are not finite "
                            "(a parameter far out of any physical range)")
    measured = processed.tau
    if config.first_period:
        n = processed.first_period_samples()
        if len(measured) < n:
            raise DvrkDartError(f"--first-period: {config.measured} has {len(measured)} processed samples, fewer than one period ({n})")
        predicted, measured = predicted[:n], measured[:n]
    return {
        "relative_error": per_measured_joint(relative_error(predicted, measured), processed.measured),
        "rms": per_measured_joint(rms(predicted - measured), processed.measured),
        "samples": len(measured),
        "scored_on": _scored_on(processed, config.first_period),
        "unrecorded_joint_notes": unrecorded_joint_notes(arm.identified, processed, rms(predicted - measured)),
        # against every term only: a model of some terms (--terms gravity) misses the others' efforts by any gain
        "effort_convention_notes": effort_convention_notes(predicted, measured, processed.measured) if set(terms) == set(TERMS) else [],
        "coordinates_note": _coordinates_note(arm, processed, terms, relative_error(predicted, measured), config.first_period),
        "params": file_record(arm.params.source),
        "terms": terms_label(config.terms),
        **processed.summary(),
        "chosen_because": why,
    }


#: a file's coupled joints fit the model this many times better read as the dVRK's values: it is said
COORDINATES_FACTOR = 2.0


def _coordinates_note(arm: Arm, processed, terms, relative: np.ndarray, first_period: bool) -> str | None:
    """Columns without names are the model's coordinates (upstream's logs); a log of the dVRK's own values (the
    dVRK's Python API's 7-joint logs) read so misses the coupled wrist by 2-9x, silently. Where reading its coupled
    columns as the dVRK's values fits the model COORDINATES_FACTOR times better, say so."""
    from dvrk_dart.metrics import relative_error

    motor_map = arm.model.motor_map
    coupled = np.arange(len(relative))[motor_map.columns]
    if not len(coupled) or not processed.measured[coupled].all() or not spanning_columns(processed.q[:, coupled]).all():
        return None  # a wrist that does not move tells no coordinates apart
    q, dq, ddq = (motor_map.positions_to_model(x) for x in (processed.q, processed.dq, processed.ddq))
    with np.errstate(over="ignore", invalid="ignore"):
        predicted, tau = processed.in_band(arm.identified.predict(q, dq, ddq, terms)), motor_map.efforts_to_model(processed.tau)
    n = processed.first_period_samples() if first_period else len(tau)
    alternative = relative_error(predicted[:n], tau[:n])[coupled]
    if not np.mean(alternative) * COORDINATES_FACTOR < np.mean(relative[coupled]):
        return None
    joints = ", ".join(f"q{j + 1}" for j in coupled)
    return (f"{joints}: read as the dVRK's joint values (through the coupling), the relative errors would be "
            f"{' / '.join(f'{v:.3f}' for v in alternative)} instead of {' / '.join(f'{v:.3f}' for v in relative[coupled])}: "
            "is this log in the dVRK's coordinates? give it a header with the dVRK's names (position.<joint>, ...)")


def _band_notes(asked: int | None, result: dict) -> list[str]:
    """What an imposed band (--harmonics) became: capped at the layer's highest, or below the motion's own harmonics."""
    if not asked:
        return []
    notes = [f"--harmonics {asked}: the periodic layer fits at most {result['harmonics']}"] if result["harmonics"] < asked else []
    if result["harmonics"] < (result.get("design_harmonics") or 0):
        notes.append(f"--harmonics {asked} is below the excitation's {result['design_harmonics']} harmonics: part of the motion "
                     "and of its efforts is cut off")
    return notes


def _scored_on(processed, first_period: bool) -> str:
    """What a model-errors figure is over: the whole run, the fitted period, or
    upstream's window (the model card's, set for the identification's own runs)."""
    if not first_period:
        if processed.periodic is None:  # upstream's zero-phase filter settles over its first and last rows
            return f"the whole run but its first and last {CUT_SAMPLES} rows, as upstream left them out"
        start, stop = processed.periodic.kept
        return f"rows {start + 1}-{stop}: the whole run after its start transient" if start > 0 else "the whole run"
    n = processed.first_period_samples()
    seconds = f"{n * float(processed.t[1] - processed.t[0]):.4g} s"
    if processed.periodic is not None:
        return f"the first period, {seconds}"
    return f"the model card's first base period, {seconds}: upstream's window, not this run's own period, which --processing periodic reads"


def cmd_model_errors(args: argparse.Namespace) -> int:
    """Per-joint relative and RMS error of the identified model on a measured run."""
    from dvrk_dart.io.atomic import json_text

    arm = command_arm(args)
    config = ModelErrorsConfig(args.measured, args.processing, args.excitation, args.terms, args.first_period, reading_options(args),
                               args.harmonics)
    result = model_errors(arm, config)
    why = result["chosen_because"]
    if args.json:
        print(json_text(result), end="")
    else:
        periodic = result["processing"] == "periodic"
        print(f"identified model ({result['terms']}, parameters {result['params']['path']}) vs {args.measured}: "
              f"{result['samples']} samples ({result['scored_on']}), {result['processing']} processing ({why})")
        if periodic:
            print(f"period {result['period_s']:.4f} s (+- {result['period_standard_error_s']:.1e}), "
                  f"projection fitted on the run's {result['whole_periods']} whole periods, "
                  f"{result['harmonics']} harmonics ({'--harmonics' if args.harmonics else 'the smallest cutoff of the moving joints'}; "
                  f"the trajectory's own {result['design_harmonics']}, read from {result['design_from']})")
        if result.get("rate_note"):
            print(f"note: {result['rate_note']}")
        for note in _band_notes(args.harmonics, result):
            print(f"note: {note}")
        for note in [*result["effort_convention_notes"], *result["unrecorded_joint_notes"],
                     *([result["coordinates_note"]] if result["coordinates_note"] else [])]:
            print(f"note: {note}")
        print("relative = ||model - measured|| / ||measured|| per joint; rms = RMS of model - measured")
        print(f"{'joint':>6} {'relative':>9} {'rms':>10}" + (f" {'own cutoff':>10}  (its efforts' own harmonics; the band used is above)" if periodic else ""))
        for j, (name, rel, r) in enumerate(zip(JOINT_NAMES, result["relative_error"], result["rms"])):
            if r is None:
                print(f"{name:>6} {'-':>9} {'-':>10}  not measured (the run did not record its effort)")
                continue
            cutoff = f" {result['joint_cutoffs'][j]:10d}" if periodic else ""
            why = "" if math.isfinite(rel) else "  (relative error not determined: the measured efforts are zero)"
            print(f"{name:>6} {rel:9.4f} {r:10.4f} {arm.model.effort_unit(name)}{cutoff}{why}")
    return 0


def cmd_force(args: argparse.Namespace) -> int:
    """The force at the instrument point (the arm's model card) the measured efforts imply."""
    from dvrk_dart.instrument_force import ForceConfig, instrument_force, print_force_summary
    from dvrk_dart.io.outputs import building_folder, check_output_folder

    check_output_folder(args.out, "force")
    config = ForceConfig(args.measured, args.dynamics, args.processing, args.excitation, reading_options(args))
    with building_folder(args.out, "force") as folder:
        summary = instrument_force(command_arm(args), config, folder)
    print_force_summary(summary)
    print(f"written {Path(args.out) / 'force.csv'}, force.json, force.mcap, force.rrd")
    return 0


@dataclass(frozen=True)
class SessionFloorConfig:
    """`session-floor`: two recordings of one trajectory in two sessions."""

    measured: str
    repeat: str
    processing: str | None = None  # every command's default: periodic where both runs are periodic excitations
    topics: BagTopics = BagTopics()


def session_floor(arm: Arm, config: SessionFloorConfig) -> dict:
    """The floor of the identified model's residual: what changes between the two sessions, per joint."""
    from dvrk_dart.analysis.residual_floor import check_repeat, floor_table, processed_pair

    a, b = processed_pair((config.measured, config.repeat), config.processing, arm.model, config.topics)
    try:
        check_repeat(a, b)
        table = floor_table(arm, a, b)
    except DvrkDartError as exc:
        raise DvrkDartError(f"--repeat {config.repeat}: {exc}") from None
    return {"measured": config.measured, "repeat": config.repeat, **table,
            "runs": {config.measured: a.summary(), config.repeat: b.summary()}, "note": _weights_note(config)}


def _weights_note(config: SessionFloorConfig) -> str | None:
    """Where the reference data say the two recordings carry different weights (one-105g against one, read as "a session
    effect beyond the noise" on every joint), that their difference holds the weight's efforts, not only a session's."""
    from dvrk_dart.io.reference_data import attached_mass_kg, resolve_run

    masses = [attached_mass_kg(resolve_run(name)) for name in (config.measured, config.repeat)]
    if None in masses or masses[0] == masses[1]:
        return None
    return (f"{config.measured} carries {masses[0]:g} kg on the arm and {config.repeat} {masses[1]:g} kg (the reference data's "
            "facts): their difference holds the weight's efforts, not a session's alone")


def cmd_session_floor(args: argparse.Namespace) -> int:
    """The floor of the identified model's residual: two recordings of one trajectory."""
    arm = command_arm(args)
    table = session_floor(arm, SessionFloorConfig(args.measured, args.repeat, args.processing, reading_options(args)))
    if args.json:
        print(json.dumps(table))
        return 0
    processing = table["runs"][args.measured]["processing"]
    why = f"--processing {args.processing}" if args.processing else ("the default: both runs are periodic excitations" if processing == "periodic"
                                                                     else "the default where a run is not a periodic excitation")
    print(f"identified model's residual, {args.measured} vs {args.repeat} ({processing} processing, {why})")
    if table["note"]:
        print(f"note: {table['note']}")
    print(f"{'joint':>6} {'unit':>4} {'rms diff':>9} {'demeaned':>9} {'noise':>9} {'one sess.':>9}  verdict")
    def cell(value) -> str:
        return f"{'-':>9}" if value is None else f"{value:9.4f}"

    noise = table["noise_predicted_rms"] or [None] * len(JOINT_NAMES)
    verdicts = table["verdict"] or [table["noise_reason"]] * len(JOINT_NAMES)
    for j, name in enumerate(JOINT_NAMES):
        if table["rms_difference"][j] is None:
            print(f"{name:>6} {'':>4} {'-':>9} {'-':>9} {'-':>9} {'-':>9}  not measured (a run did not record its effort)")
            continue
        print(f"{name:>6} {arm.model.effort_unit(name):>4} {cell(table['rms_difference'][j])} {cell(table['rms_difference_demeaned'][j])} "
              f"{cell(noise[j])} {cell(table['one_session'][j])}  {verdicts[j]}")
    print("one sess.: one session's deviation, rms diff / sqrt(2) (the difference carries two sessions'): the floor diagnose --repeat "
          "uses; on the joints whose constant it fits per run (a nuisance offset: the model card's [sessions] joints, and those "
          "the pair shows moved) it uses the demeaned column / sqrt(2) instead")
    return 0


def cmd_model_check(args: argparse.Namespace) -> int:
    """Print the model card facts: parameter oddities and basic model checks."""
    arm = command_arm(args)
    print(f"model: {arm.model.name} ({arm.model.source})")
    print(f"parameters: {arm.params.source}")
    for note in arm.params.oddities(arm.model):
        print(f"  oddity: {note}")
    q = np.zeros(len(JOINT_NAMES))
    print("g(0) =", np.array2string(arm.identified.gravity(q), precision=4))
    return 0

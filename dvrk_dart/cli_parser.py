"""The `dvrk-dart` command line's options: every command's parser, the checks
of option values, and the one-line usage errors (the commands are in cli.py)."""

from __future__ import annotations

import argparse
import os
import sys

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.paths import PIPELINES_DIR
from dvrk_dart.option_types import (
    MAX_SAMPLES,
    RATE_HZ,
    SECONDS,
    arm_namespace,
    existing_file,
    int_in,
    measured_run,
    non_empty,
    number_in,
    positive_int,
    seed,
)
from dvrk_dart.io.reference_data import RUNS, reference_run_arm
from dvrk_dart.io.signal import PROCESSINGS
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.runs.config import MAX_STEP_S, MIN_STEP_S
from dvrk_dart.sim.config import COUNTERWEIGHT_VARIANTS, MODES

#: the PSM's reference runs by their short names, as the help lists them
PSM_RUN_NAMES = "|".join(name for name in RUNS if reference_run_arm(name) == "psm") + " (with --arm-model mtm: " + "|".join(
    name for name in RUNS if reference_run_arm(name) == "mtm") + ")"


def _add_arm_model_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--arm-model", default=None, type=non_empty, help="the arm: psm, mtm (models/), a model folder or a description file (default psm)")


def _add_arm_options(p: argparse.ArgumentParser) -> None:
    _add_arm_model_option(p)
    p.add_argument("--params", help="identified parameters file (default: the arm's upstream params.json, resolved at run time)")


def _add_bag_options(p: argparse.ArgumentParser) -> None:
    """Where a measured run that is a ROS bag keeps the PSM's joint states."""
    g = p.add_argument_group("reading measured runs: ROS bags (rosbag2 folder, .mcap, .db3, ROS 1 .bag) and CSVs")
    g.add_argument("--arm", default=None, type=arm_namespace,
                   help="the arm's namespace (default: the arm model's, PSM1: /PSM1/measured_js, /PSM1/jaw/measured_js; MTML: /MTML/measured_js)")
    g.add_argument("--topic", type=non_empty, help="the arm's sensor_msgs/JointState topic (default /ARM/measured_js)")
    g.add_argument("--jaw-topic", type=non_empty, help="the jaw's sensor_msgs/JointState topic (default /ARM/jaw/measured_js)")
    g.add_argument("--rate", type=RATE_HZ, default=None,
                   help="rows per second of a CSV without a time column, or the grid a bag's messages are resampled on (Hz, default 200)")


def _add_processing_option(p: argparse.ArgumentParser, default: str | None, said: str | None = None, excitation: bool = False) -> None:
    said = said or default or "periodic where every run is a periodic excitation, else upstream (said in the output)"
    p.add_argument("--processing", default=default, choices=PROCESSINGS,
                   help=f"upstream: filtered and differentiated as the identification did; periodic: projected on the "
                        f"excitation's harmonics, analytic derivatives, measured noise (default: {said})")
    if not excitation:
        return
    p.add_argument("--excitation", default=None, type=existing_file, metavar="FILE",
                   help="the commanded excitation (a *_commanded.csv of q, dq, ddq rows, or `dvrk-dart excitation`'s CSV): "
                        "the periodic processing takes its period and harmonics from it instead of reading them from the run")


def _executor_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--executor", default="local", choices=("local", "ray"), help="where the runs execute: local processes or Ray")
    p.add_argument("--ray-address", default=None, help="an existing Ray cluster (default: start a local Ray instance with --jobs CPUs)")


DESCRIPTION = ("dvrk-dart: a DART simulation of the dVRK PSM (and MTM) with its identified dynamics, compared with the efforts "
               "measured on a real arm. model-errors: the identified model against a recording; replay: the simulator against it; "
               "identify: your arm's own parameters; diagnose: which unmodelled effect makes the simulation differ, and how much "
               "of the gap it removes; validate: the whole campaign and its report. Reference runs by name: "
               + ", ".join(RUNS) + "; or any CSV or ROS bag.")


class DefaultsShown(argparse.HelpFormatter):
    """Every option's help says its default where it has a value and the help does not already say it."""

    def _get_help_string(self, action):
        text = action.help or ""
        shown = action.default not in (None, False, [], argparse.SUPPRESS) and "default" not in text and action.option_strings
        return f"{text} (default: %(default)s)" if shown else text


class OneLineParser(argparse.ArgumentParser):
    """Usage errors as every other error: one line naming the option, exit 2.
    No abbreviated options: `--dur 3 --duration 4` would give one option twice."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        kwargs.setdefault("formatter_class", DefaultsShown)
        super().__init__(*args, **kwargs)

    def parse_args(self, args=None, namespace=None):
        """An option the command does not have is its command's error (`see dvrk-dart diagnose --help`)."""
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            commands = next((a.choices for a in self._actions if isinstance(a, argparse._SubParsersAction)), {})
            commands.get(getattr(parsed, "command", None), self).error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed

    def parse_known_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)  # to name a mistyped option (`error`)
        return super().parse_known_args(args, namespace)

    def error(self, message: str):
        """A missing required option is often a mistyped one: named first."""
        unknown = [a.split("=")[0] for a in getattr(self, "_given", []) if a.startswith("--") and a.split("=")[0] not in self._option_string_actions]
        if unknown and message.startswith("the following arguments are required"):
            message = f"unrecognized arguments: {' '.join(unknown)} ({message})"
        print(f"dvrk-dart: {self.prog.removeprefix('dvrk-dart').strip() + ': ' if self.prog != 'dvrk-dart' else ''}"
              f"{message} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser(commands) -> argparse.ArgumentParser:
    """The parser of every command; `commands` holds the cmd_* functions (dvrk_dart.cli)."""
    parser = OneLineParser(prog="dvrk-dart", description=DESCRIPTION)
    sub = parser.add_subparsers(dest="command", required=True)
    for add_command in COMMANDS:
        add_command(sub, commands)
    return parser


def _add_sim_options(p: argparse.ArgumentParser, duration_help: str = "simulate only the first seconds") -> None:
    """The simulation's options of `run` and `replay`."""
    p.add_argument("--counterweight", default=None, choices=COUNTERWEIGHT_VARIANTS,
                   help="ideal tendon (on, the default unless the scenario runs without it: then its first), removed, or the paper's "
                        "PID mirror (velocity and torque modes)")
    p.add_argument("--dt", type=number_in(MIN_STEP_S, MAX_STEP_S, "s"), default=1e-3, help="simulation step (s)")
    p.add_argument("--duration", type=SECONDS, default=None, help=duration_help)
    p.add_argument("--dynamics", default=None, metavar="inertial|identified|DIAGNOSIS.json",
                   help="the simulated arm: identified inertia only (the paper's), every identified term as physics, "
                        "or the simulation a diagnosis selected (default: the scenario's, else inertial)")
    _add_arm_options(p)


def _model_errors_command(sub, commands) -> None:
    p = sub.add_parser("model-errors", help="errors of the identified model on a measured run")
    p.add_argument("--measured", type=measured_run, required=True, help=f"measured run: path (CSV or ROS bag), or {PSM_RUN_NAMES}")
    p.add_argument("--first-period", action="store_true", help="only the first base period (upstream: the arm model card's, as the identification used it; periodic: the fitted period)")
    _add_processing_option(p, None, excitation=True)
    p.add_argument("--harmonics", type=positive_int, default=None, metavar="N",
                   help="periodic processing on N harmonics of the base period, not the band read from the run "
                        "(to compare with figures quoted at a fixed band; the default reads each joint's cutoff)")
    p.add_argument("--terms", default="all", help="all | inertial | comma list of inertia,coriolis,gravity,friction,offset,spring,motor_inertia")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    _add_arm_options(p)
    _add_bag_options(p)
    p.set_defaults(func=commands.cmd_model_errors)


def _force_command(sub, commands) -> None:
    p = sub.add_parser("force", help="the force at the instrument the measured efforts imply (in free motion: the model's phantom force)")
    p.add_argument("--measured", type=measured_run, required=True, help=f"measured run: path (CSV or ROS bag), or {PSM_RUN_NAMES}")
    p.add_argument("--dynamics", default="identified", metavar="inertial|identified|DIAGNOSIS.json",
                   help="the model the efforts are compared with: the identified inertia, every identified term (default), "
                        "or what a diagnosis selected (its diagnosis.json or one_configuration.json)")
    p.add_argument("--out", required=True, help="output folder: force.csv, force.json, force.mcap, force.rrd")
    _add_processing_option(p, None, "the one a --dynamics file records, else periodic where the run is a periodic excitation, else upstream",
                           excitation=True)
    _add_arm_options(p)
    _add_bag_options(p)
    p.set_defaults(func=commands.cmd_force)


def _session_floor_command(sub, commands) -> None:
    p = sub.add_parser("session-floor", help="the floor of the identified model's residual from two recordings of one trajectory")
    p.add_argument("--measured", type=measured_run, required=True, help=f"a measured run: path (CSV or ROS bag), or {PSM_RUN_NAMES}")
    p.add_argument("--repeat", type=measured_run, required=True, help="the same trajectory recorded in another session")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    _add_processing_option(p, None)
    _add_arm_options(p)
    _add_bag_options(p)
    p.set_defaults(func=commands.cmd_session_floor)


def _identify_command(sub, commands) -> None:
    p = sub.add_parser("identify", help="identify the dynamic parameters of an arm from measured runs")
    p.add_argument("--runs", type=measured_run, nargs="+", required=True, help=f"training runs: paths, or {PSM_RUN_NAMES}")
    p.add_argument("--holdout", type=measured_run, nargs="+", default=[], help="held-out runs, scored only")
    p.add_argument("--out", required=True, help="output folder (params.json, params_covariance.json, identification.json/.html)")
    p.add_argument("--joints", nargs="+", default=list(JOINT_NAMES), help="joints whose efforts are fitted (default: all)")
    p.add_argument("--friction-law", default="presliding", choices=("presliding", "sign", "tanh"),
                   help="Coulomb reversal: presliding (default: over a distance per joint chosen on the training runs, written to "
                        "params.json as xs), sign (upstream), or tanh(v / --reversal-velocity) (params.json readers apply sign)")
    p.add_argument("--reversal-velocity", type=number_in(0.0, 1e3, open_low=True), default=None, help="velocity scale of the tanh law (rad/s or m/s)")
    p.add_argument("--bounds", default=None, help="bounds and prior file (default: the arm's, models/<arm>/identification.toml)")
    p.add_argument("--prior", default="none",
                   help="prior of the parameters the data leave free: 'none' (about zero: minimum norm, the default), "
                        "'default' (the model's default params.json) or a params file")
    p.add_argument("--seed", type=seed, default=0, help="seed of the random states of the base-parameter test")
    _add_processing_option(p, None, excitation=True)
    _add_bag_options(p)
    _add_arm_model_option(p)
    _add_config_option(p)
    p.set_defaults(func=commands.cmd_identify)


def _import_command(sub, commands) -> None:
    p = sub.add_parser("import", help="a ROS bag of a dVRK arm -> a measured-run CSV")
    p.add_argument("bag", help="rosbag2 folder, .mcap or .db3 file, or ROS 1 .bag")
    p.add_argument("--out", required=True, help="the CSV to write (21 columns, model coordinates, 200 Hz)")
    p.add_argument("--force", action="store_true", help="replace --out if it exists")
    _add_arm_model_option(p)
    _add_bag_options(p)
    p.set_defaults(func=commands.cmd_import)


def _export_command(sub, commands) -> None:
    p = sub.add_parser("export", help="a simulated run -> a ROS 2 bag (MCAP) like a real PSM's recording")
    p.add_argument("run_dir", help="a run folder (run.mcap)")
    p.add_argument("--bag", required=True, help="the bag to write (a rosbag2 folder; a .bag file with --storage ros1)")
    p.add_argument("--arm", default=None, type=arm_namespace, help="the arm's namespace of the topics (default: the arm model's, PSM1)")
    p.add_argument("--storage", default="mcap", choices=("mcap", "sqlite3", "ros1"), help="rosbag2 storage, or a ROS 1 bag")
    p.set_defaults(func=commands.cmd_export)


def _excitation_command(sub, commands) -> None:
    p = sub.add_parser("excitation", help="a trajectory to play on a dVRK: CSV + ROS 2 bag of servo_jp")
    p.add_argument("name", help="one | two (the identification's excitations) or a Cartesian scenario (rectilinear, spiral, ...)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--arm", default=None, type=arm_namespace, help="the arm's namespace of the servo_jp topics (default: the arm model's, PSM1)")
    p.add_argument("--rate", type=RATE_HZ, default=None, help="command rate (Hz, default 200; at least 50: servo_jp jumps to each setpoint)")
    p.set_defaults(func=commands.cmd_excitation)


def _model_check_command(sub, commands) -> None:
    p = sub.add_parser("model-check", help="parameter oddities and model facts")
    _add_arm_options(p)
    p.set_defaults(func=commands.cmd_model_check)


def _run_command(sub, commands) -> None:
    p = sub.add_parser("run", help="run one scenario variant")
    named = ", ".join(sorted(path.stem for path in (PIPELINES_DIR / "scenarios").glob("*.toml")))
    p.add_argument("scenario", help=f"a scenario of pipelines/scenarios/ ({named}) or a .toml file")
    p.add_argument("--mode", choices=MODES, help="default: the scenario's first mode")
    p.add_argument("--out", required=True, help="output folder of the run")
    _add_sim_options(p)
    p.set_defaults(func=commands.cmd_run)


def _replay_command(sub, commands) -> None:
    p = sub.add_parser("replay", help="replay a measured run in the simulator")
    p.add_argument("--measured", type=measured_run, required=True, help=f"measured run: path (CSV or ROS bag), or {PSM_RUN_NAMES}")
    _add_bag_options(p)
    p.add_argument("--mode", default="velocity", choices=MODES,
                   help="velocity: the simulator follows the recorded motion and its efforts are read (the paper's replay); "
                        "torque: computed torque from the arm's own model; kinematic: poses imposed, no dynamics")
    p.add_argument("--out", help="output folder (default out/runs/<run name>)")
    _add_processing_option(p, None, "the one a --dynamics diagnosis file records, else periodic where the run is a periodic "
                                    "excitation, else upstream (said in the output)")
    _add_sim_options(p, "replay only the first seconds (read upstream: a part of a run has no periodic projection of its own)")
    _add_config_option(p)
    p.set_defaults(func=commands.cmd_replay)


def _validate_command(sub, commands) -> None:
    p = sub.add_parser("validate", help="the whole validation campaign, report and diagnosis")
    p.add_argument("--out", default="out", help="output folder (runs in OUT/runs)")
    p.add_argument("--report", default="report", help="report folder")
    p.add_argument("--jobs", type=positive_int, default=2, help="parallel worker processes")
    p.add_argument("--force", action="store_true", help="re-run runs that are up to date")
    p.add_argument("--dynamics", default=None, metavar="inertial|identified|DIAGNOSIS.json",
                   help="the simulated arm of the campaign's runs that do not name one (default: their scenario's)")
    _executor_options(p)
    p.set_defaults(func=commands.cmd_validate)


def _uncertainty_command(sub, commands) -> None:
    p = sub.add_parser("uncertainty", help="Monte Carlo over parameter uncertainty: effort bands of a replay")
    p.add_argument("--measured", type=measured_run, required=True, help=f"measured run: path (CSV or ROS bag), or {PSM_RUN_NAMES}")
    p.add_argument("--samples", type=int_in(2, MAX_SAMPLES, "each is a replay; a band settles within hundreds"), default=64, help="parameter sets drawn (at least 2: a band)")
    p.add_argument("--out", required=True, help="output folder")
    source = p.add_mutually_exclusive_group()
    source.add_argument("--params-cov", help="params_covariance.json written by dvrk-dart identify")
    source.add_argument("--relative-std", type=number_in(0.0, 1.0, open_low=True, open_high=True), default=0.05,
                        help="fallback: relative std of every parameter (default 0.05)")
    p.add_argument("--duration", type=SECONDS, default=None, help="replay only the first seconds")
    p.add_argument("--seed", type=seed, default=0, help="seed of the parameter draws")
    p.add_argument("--jobs", type=positive_int, default=2, help="parallel workers")
    _executor_options(p)
    _add_processing_option(p, None)
    _add_bag_options(p)
    _add_arm_model_option(p)
    _add_config_option(p)
    p.set_defaults(func=commands.cmd_uncertainty)


def _report_command(sub, commands) -> None:
    p = sub.add_parser("report", help="build the validation report from a folder of runs")
    p.add_argument("--runs", required=True, help="folder of run folders (<run>/run.mcap)")
    p.add_argument("--out", required=True, help="report folder")
    p.add_argument("--extra", help="folder of extra sections (*.html fragments and images)")
    p.add_argument("--jobs", type=positive_int, default=None, help="parallel workers (default: the machine's cores)")
    p.add_argument("--allow-unreadable", action="store_true", help="report without the run folders that cannot be read (listed in the report); without it they refuse the report")
    p.set_defaults(func=commands.cmd_report)


def _diagnose_command(sub, commands) -> None:
    p = sub.add_parser("diagnose", help="diagnose the sim-to-real gap of a measured run")
    p.add_argument("--measured", type=measured_run, required=True, nargs="+",
                   help=f"measured run(s): path, or {PSM_RUN_NAMES}; several: one set of effects for all")
    p.add_argument("--baseline", type=measured_run, help="a run of the same arm without the withheld effect (isolates a payload): the same "
                   "trajectory (subtracted sample by sample) or another (fitted beside the runs: it must lack the effect, which is not checked)")
    p.add_argument("--train", type=measured_run, nargs="+", default=[], help="further training runs, fitted beside the measured run (which always trains)")
    p.add_argument("--holdout", type=measured_run, nargs="+", default=[], help="held-out runs scored with the effects fitted on training")
    p.add_argument("--repeat", type=measured_run, help="the same trajectory recorded in another session: the session-to-session floor and each joint's gap split")
    p.add_argument("--payload-at", help="LINK:x,y,z, a hand-measured payload position (link frame, m): the payload's mass with its interval")
    p.add_argument("--parameter-band", help="a `dvrk-dart uncertainty` folder of one of the runs: effects are reported as unmodelled "
                                            "only on joints whose measured efforts leave the parameters' band")
    p.add_argument("--refit", action="store_true", help="also refit the identified parameters on the training runs (OUT/refit/) and "
                                                          "replay the held-out runs with them: is a held-out gap the published fit's bias?")
    p.add_argument("--effort-scale", action="store_true", help="also weigh a scale of every measured effort (the controller's torque "
                   "constants or effort scale off, e.g. after a configuration change); not by default: between real sessions it takes "
                   "what the sessions change")
    p.add_argument("--jobs", type=positive_int, default=2, help="re-simulations run side by side")
    _executor_options(p)
    _add_processing_option(p, None)
    p.add_argument("--out", required=True, help="output folder: diagnosis.json, diagnosis.html, figures, the replays before and after")
    _add_arm_options(p)
    _add_bag_options(p)
    _add_config_option(p)
    p.set_defaults(func=commands.cmd_diagnose)


#: every command's parser, in the order `--help` lists them
COMMANDS = (
    _model_errors_command,
    _force_command,
    _session_floor_command,
    _identify_command,
    _import_command,
    _export_command,
    _excitation_command,
    _model_check_command,
    _run_command,
    _replay_command,
    _validate_command,
    _uncertainty_command,
    _report_command,
    _diagnose_command,
)


#: the commands that take many options, and so `--config FILE.toml` (option = value, e.g. baseline = "one-no-weight")
CONFIG_COMMANDS = ("diagnose", "identify", "uncertainty", "replay")


#: local worker processes per core: more only wait on each other (and each holds a simulator)
MAX_JOBS_PER_CORE = 4
MAX_LOCAL_JOBS = MAX_JOBS_PER_CORE * (os.cpu_count() or 1)

#: options that mean something only beside another (each value on its own is
#: checked by its argparse type): (option's dest, whether it may be given, why not)
COMBINATION_RULES = (
    ("ray_address", lambda a: a.executor == "ray", "--ray-address: only with --executor ray"),
    ("jobs", lambda a: getattr(a, "executor", "local") == "ray" or a.jobs <= MAX_LOCAL_JOBS,
     f"--jobs: more than {MAX_LOCAL_JOBS} workers on {os.cpu_count()} cores would only wait on each other (a Ray cluster: --executor ray)"),
    ("payload_at", lambda a: a.baseline is not None,
     "--payload-at: only with --baseline (the payload is what the runs have and their baseline has not)"),
    ("reversal_velocity", lambda a: a.friction_law == "tanh", "--reversal-velocity: only with --friction-law tanh"),
)


def check_combinations(args: argparse.Namespace) -> None:
    """The first option given where another makes it meaningless: one line."""
    for dest, allowed, why in COMBINATION_RULES:
        if getattr(args, dest, None) is not None and not allowed(args):
            raise DvrkDartError(why)


def _add_config_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="FILE.toml", help="the options as a TOML table (option = value; the command line's own "
                                                         "options win); a relative path in it is relative to the file")

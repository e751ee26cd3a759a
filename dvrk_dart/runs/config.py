"""One run's configuration: a frozen dataclass built by the command line and by
the campaign alike, resolved into the simulator's options, and written as the
run's config.json (with what the resolution found: files, checksums).

`dynamics` chooses how realistic the simulated arm is:
- "inertial": the identified rigid-body parameters only (the CoppeliaSim
  paper's arm; the default for the paper's checks);
- "identified": every identified term as DART physics: Coulomb and viscous
  friction, offsets, the J4 spring and the motor inertias;
- a diagnosis.json path: the simulation that diagnosis selected (the arm it
  was fitted on plus its effects as physics, as recorded in its `sim_config`).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.signal import PROCESSINGS
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.runs.scenarios import DYNAMICS_CHOICES, MAX_DURATION_S  # noqa: F401  (the CLI's bound too)
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS, SimConfig

#: the simulation step bounds a user may ask for (s): above 10 ms the closed
#: chain's constraint stabilisation no longer holds the loops
MAX_STEP_S = 0.01
#: the smallest simulation step: 100 kHz, ten times any servo rate of the arm (a 1 ns step
#: would hold 10^9 states per simulated second, more than the machine's memory)
MIN_STEP_S = 1e-5
#: the simulation step of every run that does not choose one (1 kHz, the dVRK servo rate)
DEFAULT_STEP_S = 1e-3
#: the fewest simulated steps a run compares anything over
MIN_STEPS = 10
#: the most simulation steps of one run (the hour at 1 kHz above)
MAX_STEPS = 3.6e6


@dataclass(frozen=True)
class RunConfig:
    scenario: str  # scenario name (pipelines/scenarios/) or .toml path
    mode: str
    counterweight: str = "on"
    dynamics: str = "inertial"  # inertial | identified | path of a diagnosis.json
    dt_s: float = DEFAULT_STEP_S
    duration_s: float | None = None  # None: the scenario's (or the whole measured run)
    params_file: str | None = None  # None: the upstream params.json, resolved at run time
    measured: str | None = None  # overrides a replay scenario's measured run
    #: a replay's processing of the measured run (io/signal.py): its reference
    #: for the servo and the band its efforts are compared in
    processing: str = "upstream"
    #: the periodic processing's harmonic cutoff (None: the run's own), as a
    #: diagnosis that compared several runs on their smallest one recorded it
    harmonics: int | None = None
    #: the arm (an arm of models/ by name, a model folder or file); None: the scenario's, else the PSM
    arm_model: str | None = None
    #: how the measured run is read where it is a bag (--arm, --topic, --jaw-topic) or a CSV (--rate)
    topics: BagTopics = BagTopics()

    def __post_init__(self) -> None:
        if self.processing not in PROCESSINGS:
            raise DvrkDartError(f"--processing: '{self.processing}' is not upstream or periodic")
        if not (MIN_STEP_S <= self.dt_s <= MAX_STEP_S):
            raise DvrkDartError(f"--dt: {self.dt_s} s is outside [{MIN_STEP_S:g}, {MAX_STEP_S:g}] s")
        if self.duration_s is not None and not (0.0 < self.duration_s <= MAX_DURATION_S):
            raise DvrkDartError(f"--duration: {self.duration_s} s is outside (0, {MAX_DURATION_S:g}] s")
        if self.duration_s is not None:
            self.check_steps(self.duration_s, "--duration")
        if self.dynamics not in DYNAMICS_CHOICES and not Path(self.dynamics).suffix == ".json":
            raise DvrkDartError(f"--dynamics: '{self.dynamics}' is not one of {', '.join(DYNAMICS_CHOICES)} nor a diagnosis.json")

    def check_steps(self, duration_s: float, whose: str) -> None:
        """A run of `duration_s` (`whose`: the option or scenario that set it) holds MIN_STEPS to MAX_STEPS steps."""
        if duration_s < MIN_STEPS * self.dt_s:
            raise DvrkDartError(f"{whose}: {duration_s:g} s is fewer than {MIN_STEPS} steps of {self.dt_s:g} s: nothing to compare")
        if duration_s / self.dt_s > MAX_STEPS:
            raise DvrkDartError(f"--dt: {self.dt_s:g} s over {duration_s:g} s ({whose}) is {duration_s / self.dt_s:.3g} steps, "
                                f"more than {MAX_STEPS:.3g}: a longer step or a shorter --duration")

    @property
    def dynamics_label(self) -> str:
        """Short name of the dynamics for run names: inertial, identified,
        diagnosed-<folder> (its diagnosis.json), diagnosed-<folder>-<stem> (another file of it)."""
        if self.dynamics in DYNAMICS_CHOICES:
            return self.dynamics
        path = Path(self.dynamics).resolve()
        return f"diagnosed-{path.parent.name}" + ("" if path.stem == "diagnosis" else f"-{path.stem}")

    @property
    def params_label(self) -> str | None:
        """Short name of a --params file for run names: params-<folder> (its params.json), params-<stem> (another name)."""
        if self.params_file is None:
            return None
        path = Path(self.params_file).resolve()
        return f"params-{path.parent.name if path.stem == 'params' else path.stem}"

    @property
    def name_parts(self) -> tuple:
        """What tells this run's name from another's beyond its scenario and mode (run_name's last arguments)."""
        return self.counterweight, self.dynamics_label, self.processing, self.params_label, self.duration_label, self.step_label

    @property
    def duration_label(self) -> str | None:
        """first-<s>s for a --duration: a part of a run is not the whole run (the report would hold two of one name)."""
        return None if self.duration_s is None else f"first-{self.duration_s:g}s"

    @property
    def step_label(self) -> str | None:
        """dt-<ms>ms for a step other than the default: runs of two steps are two runs (the report refused them as one)."""
        return None if self.dt_s == DEFAULT_STEP_S else f"dt-{self.dt_s * 1e3:g}ms"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict) -> "RunConfig":
        names = {f.name for f in fields(cls)}
        kept = {k: v for k, v in raw.items() if k in names}
        if isinstance(kept.get("topics"), dict):
            kept["topics"] = BagTopics(**kept["topics"])
        return cls(**kept)


def run_name(scenario: str, mode: str, counterweight: str, dynamics_label: str = "inertial", processing: str = "upstream",
             params_label: str | None = None, duration_label: str | None = None, step_label: str | None = None) -> str:
    """The run folder's name; the paper's arm (inertial, the published parameters) and processing (upstream) keep the historical name."""
    parts = [f"{scenario}_{mode}_cw-{counterweight}"]
    parts += [label for label, usual in ((dynamics_label, "inertial"), (params_label, None), (processing, "upstream"),
                                          (duration_label, None), (step_label, None)) if label != usual]
    return "_".join(parts)


def sim_config_for(config: RunConfig, model: PsmModel | None = None, params_path: Path | None = None) -> SimConfig:
    """The simulator's options of a run of `model`'s arm with the parameters of `params_path` (None: not
    checked): step, counterweight and dynamics."""
    if config.dynamics == "inertial":
        sim = SimConfig()
    elif config.dynamics == "identified":
        sim = IDENTIFIED_PHYSICS
    else:
        sim = diagnosis_sim_config(Path(config.dynamics), model=model, params_path=params_path)
    return replace(sim, dt_s=config.dt_s, counterweight=config.counterweight)


def diagnosis_sim_config(path: Path, physical: bool = True, model: PsmModel | None = None, params_path: Path | None = None) -> SimConfig:
    """The SimConfig a diagnosis selected (its diagnosis.json `sim_config`, or a one_configuration.json's);
    `physical`: checked as DART physics (a replay), not only evaluated by formula. A diagnosis with --baseline
    is refused: it fitted what the runs differ by from their baseline, and its sim_config is not the arm (a
    payload diagnosis's made the force at the instrument three times the plain model's)."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DvrkDartError(f"--dynamics: {path}: diagnosis file not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError, OSError) as exc:
        raise DvrkDartError(f"--dynamics: {path}: not a diagnosis.json ({type(exc).__name__})") from None
    if not isinstance(raw, dict) or not isinstance(raw.get("sim_config"), dict):
        raise DvrkDartError(f"--dynamics: {path}: no 'sim_config' object (not written by dvrk-dart diagnose?)")
    if raw.get("baseline"):
        raise DvrkDartError(f"--dynamics: {path}: a diagnosis with --baseline {raw['baseline']}: it simulates what the runs differ by "
                            "from their baseline, not the arm; use a diagnosis without --baseline (or its one_configuration.json)")
    try:
        config = SimConfig.from_dict(raw["sim_config"])
    except (TypeError, ValueError, KeyError) as exc:
        raise DvrkDartError(f"--dynamics: {path}: malformed sim_config ({exc})") from None
    if model is not None:
        _check_arm(raw, path, model)
        _check_links(config, path, model)
    if params_path is not None:
        _say_other_parameters(raw, path, params_path)
    if physical:
        _check_physical(config, path)
    return config


def _check_arm(raw: dict, path: Path, model: PsmModel) -> None:
    """A diagnosis of another arm is refused: its effects name that arm's joints and links. Its `arm_model`
    says which (a file written before it existed: its efforts' units)."""
    recorded = raw.get("arm_model", {}).get("name") if isinstance(raw.get("arm_model"), dict) else None
    units = raw.get("units")
    if recorded is not None and recorded != model.name:
        raise DvrkDartError(f"--dynamics: {path}: a diagnosis of the arm {recorded!r}, not of {model.source.name}'s: give its --arm-model")
    if recorded is None and units is not None and units != [model.effort_unit(j) for j in JOINT_NAMES]:
        raise DvrkDartError(f"--dynamics: {path}: a diagnosis of another arm (efforts in {', '.join(map(str, units))}) than {model.source.name}'s: "
                            "give its --arm-model")


def _check_links(config: SimConfig, path: Path, model: PsmModel) -> None:
    """The links a diagnosis's effects name are the arm's (a friction on link 99 ended in a KeyError)."""
    extra = config.extra
    for name, entries in (("link_friction", extra.link_friction), ("link_mass_scale", extra.link_mass_scale)):
        unknown = sorted({int(entry[0]) for entry in entries} - set(model.links))
        if unknown:
            raise DvrkDartError(f"--dynamics: {path}: sim_config.extra.{name} names link {unknown[0]}, not a link of {model.source.name}")


def _say_other_parameters(raw: dict, path: Path, params_path: Path) -> None:
    """A note where the diagnosis was fitted on other identified parameters than the run's: its effects are
    corrections to those (a replay with them does not find the diagnosis's figures)."""
    from dvrk_dart.io.csv_run import say_once
    from dvrk_dart.io.provenance import sha256_of

    recorded = raw.get("params", {}).get("sha256") if isinstance(raw.get("params"), dict) else None
    if recorded is not None and recorded != sha256_of(params_path):
        say_once([f"--dynamics {path}: fitted on other identified parameters ({Path(str(raw['params'].get('path', '?'))).name}, "
                  f"sha256 {str(recorded)[:12]}...) than {params_path}: its effects are corrections to those"])


def recorded_processing(dynamics: str | None) -> tuple[str, int | None] | None:
    """(processing, harmonic cutoff) a diagnosis file's effects were fitted on
    (its `processing`), so that a replay with them finds the diagnosis's
    figures; None for a keyword, a file without it, or one that cannot be read
    (the replay's own reading of the file says why)."""
    if dynamics in (None, *DYNAMICS_CHOICES):
        return None
    try:
        recorded = json.loads(Path(dynamics).read_text(encoding="utf-8")).get("processing", {})
        name, harmonics = recorded.get("processing"), recorded.get("harmonics")
    except (OSError, UnicodeDecodeError, ValueError, AttributeError):
        return None
    if name not in PROCESSINGS:
        return None
    cutoff = harmonics if name == "periodic" and isinstance(harmonics, int) and harmonics > 0 else None
    return name, cutoff


#: JointEffects fields that dissipate or store energy the physical way only when >= 0
NON_NEGATIVE_EFFECTS = ("coulomb", "viscous", "armature", "coulomb_reversal_velocity", "coulomb_presliding")


def _check_physical(config: SimConfig, path: Path) -> None:
    """A diagnosis's effects as the diagnosis can write them: finite numbers,
    friction, armature and payload masses not negative (a file edited by hand
    would otherwise run, and report NaN or energy from nowhere)."""
    extra = config.extra
    for name in extra.__dataclass_fields__:
        values = np.asarray([x for v in getattr(extra, name) for x in (v if isinstance(v, tuple) else (v,))], dtype=float)
        if not np.all(np.isfinite(values)):
            raise DvrkDartError(f"--dynamics: {path}: sim_config.extra.{name} holds a value that is not finite")
        if name in NON_NEGATIVE_EFFECTS and np.any(values < 0.0):
            raise DvrkDartError(f"--dynamics: {path}: sim_config.extra.{name} holds a negative value (not physical)")
    for payload in config.payloads:
        if not (np.isfinite(payload.mass_kg) and payload.mass_kg >= 0.0 and np.all(np.isfinite(payload.position_m))):
            raise DvrkDartError(f"--dynamics: {path}: a payload of sim_config is not a finite, non-negative mass at a finite position")

"""`dvrk-dart identify`: measured runs in, physically consistent parameters out.

Steps: load and process every run (`io/signal.py`: upstream's filters, or the
periodic layer, where each run is read as its harmonic series); build the regressor from the identified model's
Pinocchio tree; find the base parameters; weighted least squares; the convex
program; predictions and errors on the training and held-out runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.base import BaseParameters, acting_on_none_of, find_base_parameters
from dvrk_dart.identification.fit import (
    Bounds,
    ConsistentFit,
    WeightedFit,
    fit_consistent,
    fit_weighted,
    fit_weighted_periodic,
    load_bounds,
)
from dvrk_dart.identification.presliding import choose_distances, with_link_column
from dvrk_dart.identification.regressor import FrictionLaw, Regressor, standard_vector
from dvrk_dart.io.reference_data import distinct_inputs, load_run, resolve, resolve_run
from dvrk_dart.io.signal import ProcessedRun, process_all
from dvrk_dart.metrics import per_measured_joint, relative_error, rms
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel
from dvrk_dart.model.model_file import load_model
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.model.identified import IdentifiedModel
from dvrk_dart.model.parameters import load_parameters
from dvrk_dart.identification.unrecorded_joints import unrecorded_joint_notes

#: a held-out RMS this many times the training RMS on a fitted joint: the fit does not carry (too little data, or runs that differ)
HOLDOUT_OVERFIT_RATIO = 2.0

#: --prior values besides a file
PRIOR_DEFAULT, PRIOR_NONE = "default", "none"


@dataclass(frozen=True)
class IdentificationConfig:
    runs: tuple[str, ...]
    holdout: tuple[str, ...] = ()
    joints: tuple[str, ...] = JOINT_NAMES
    #: presliding without distances: each friction link's distance chosen on the training runs (presliding.py)
    friction_law: FrictionLaw = FrictionLaw("presliding")
    bounds_file: str | None = None
    prior: str = PRIOR_NONE
    seed: int = 0
    solver: str = "CLARABEL"
    model_file: str = str(DEFAULT_MODEL_FILE)  # the arm (--arm-model)
    #: how the runs are read where they are bags (--arm, --topic, --jaw-topic) or CSVs (--rate)
    topics: BagTopics = BagTopics()
    #: upstream | periodic | None: periodic where every run is periodic, else upstream (noted)
    processing: str | None = None
    #: the commanded excitation (--excitation): the periodic layer's design
    excitation: str | None = None


@dataclass
class RunData:
    name: str
    path: Path
    processed: ProcessedRun
    Y: np.ndarray  # (N, 7, n_standard), in the run's band (periodic: projected on its harmonics)
    #: Y under the sign law, where pre-sliding columns replaced some of Y's (parameters without xs: the published)
    Y_sign: np.ndarray | None = None


@dataclass
class IdentificationResult:
    config: IdentificationConfig
    model: PsmModel
    regressor: Regressor
    bounds: Bounds
    base: BaseParameters
    wls: WeightedFit
    consistent: ConsistentFit
    prior_theta: np.ndarray
    prior_source: str
    train: list[RunData]
    holdout: list[RunData]
    processing_note: str | None = None
    timings_s: dict[str, float] = field(default_factory=dict)
    #: link key -> the chosen pre-sliding distance and the training score of every candidate
    presliding_choice: dict = field(default_factory=dict)
    #: one line per joint of --joints the runs do not let the fit use
    left_out: list[str] = field(default_factory=list)
    #: standard parameters acting on no fitted joint: params.json holds the reference's value (NaN elsewhere)
    reference_theta: np.ndarray | None = None

    @property
    def theta(self) -> np.ndarray:
        return self.consistent.theta

    def predicted(self, run: RunData, theta: np.ndarray | None = None, sign_law: bool = False) -> np.ndarray:
        Y = run.Y_sign if sign_law and run.Y_sign is not None else run.Y
        return Y @ (self.theta if theta is None else theta)

    def errors(self, run: RunData, first_period: bool = False, theta: np.ndarray | None = None, sign_law: bool = False) -> dict:
        """Errors of the identified parameters (or `theta`: with `sign_law`, parameters of the sign law's model)."""
        n = run.processed.first_period_samples() if first_period else len(run.processed)
        predicted, measured = self.predicted(run, theta, sign_law)[:n], run.processed.tau[:n]
        recorded = run.processed.measured
        return {
            "samples": int(len(measured)),
            "relative_error": per_measured_joint(relative_error(predicted, measured), recorded),
            "rms": per_measured_joint(rms(predicted - measured), recorded),
        }

    @cached_property
    def reference_model(self) -> IdentifiedModel:
        """The arm's published parameters' model (its model card's), what the warnings compare the runs with."""
        return IdentifiedModel(self.model, load_parameters(resolve(self.model.default_parameters), self.model))

    def data_extent(self) -> dict:
        """What the fit rests on: runs, seconds and (periodic) whole periods."""
        periods = [run.processed.periodic.period.whole_periods for run in self.train if run.processed.periodic is not None]
        return {"runs": len(self.train), "seconds": float(sum(run.processed.t[-1] - run.processed.t[0] for run in self.train)),
                "whole_periods": int(sum(periods)) if len(periods) == len(self.train) else None}

    def unrecorded_joint_warnings(self) -> list[str]:
        """A joint the training runs did not record, held at zero by the fit,
        that moves a fitted joint's efforts (the reference parameters' model)
        by more than its training figure: the fit absorbs that error."""
        reference = self.reference_model
        fitted = np.isin(np.arange(len(JOINT_NAMES)), self.wls.joints)
        notes = []
        for run in self.train:
            figures = np.where(fitted, [np.inf if v is None else v for v in self.errors(run)["rms"]], np.inf)
            notes += [f"{run.name}: {note}" for note in unrecorded_joint_notes(reference, run.processed, figures)]
        return notes

    def effort_convention_warnings(self) -> list[str]:
        """Training runs whose measured efforts run opposite to the reference parameters' model, or are a multiple
        of them: a log's sign or unit (effort_convention.py), which the fit would take for the arm's (masses 1000
        times too large, or no physical set at all)."""
        from dvrk_dart.identification.effort_convention import effort_convention_notes

        notes = []
        for run in self.train:
            state = run.processed
            model = state.in_band(self.reference_model.predict(state.q, state.dq, state.ddq))
            notes += [f"{run.name}: {note}" for note in effort_convention_notes(model, state.tau, state.measured)]
        return notes

    def params_file_warnings(self) -> list[str]:
        """A fit of some joints without a prior: the inertia only the others'
        efforts would determine comes out about zero, and params.json's
        efforts on those joints rest on it (q2 alone: q3 off by 10 N on a
        7-joint run; 0.56 N with --prior default, 0.12 published)."""
        others = [name for j, name in enumerate(JOINT_NAMES) if j not in self.wls.joints]
        if not others or self.config.prior != PRIOR_NONE:
            return []
        return [f"params.json is fitted on {', '.join(JOINT_NAMES[j] for j in self.wls.joints)} only: its efforts on "
                f"{', '.join(others)} rest on the inertia these runs leave free, about zero with --prior none (the default); "
                "--prior default keeps the published values there"]

    def recording_warnings(self) -> list[str]:
        """What the reference data's manifest says of the runs: training runs with different weights on the arm, or
        from different repositories (other sessions, perhaps another arm), get one parameter set that describes none
        of their states; a held-out run with another weight than the training's holds that weight's efforts in its
        error. A file the manifest does not list has no facts: nothing is said of it."""
        from dvrk_dart.io.reference_data import recording_facts

        def weight(mass: float) -> str:
            return f"{mass:g} kg" if mass else "no weight"

        facts = {run.name: recording_facts(run.path) for run in self.train + self.holdout}
        trained = {run.name: facts[run.name] for run in self.train if facts[run.name] is not None}
        masses, sources = {m for m, _ in trained.values()}, {r for _, r in trained.values()}
        notes = []
        if len(masses) > 1:
            notes.append("the training runs carry different weights on the arm (" + ", ".join(
                f"{name} {weight(m)}" for name, (m, _) in trained.items()) + "; the reference data's facts): one parameter set "
                "fitted to several states of the arm describes none of them; identify the runs of one state together")
        elif masses:
            notes += [f"{run.name} carries {weight(facts[run.name][0])}, the training runs {weight(next(iter(masses)))} (the "
                      "reference data's facts): its held-out error holds the weight's efforts, not the fit's alone"
                      for run in self.holdout if facts[run.name] is not None and facts[run.name][0] not in masses]
        if len(sources) > 1:
            notes.append("the training runs come from different repositories (" + ", ".join(
                f"{name} {r}" for name, (_, r) in trained.items()) + "): other sessions, perhaps another arm; one parameter "
                "set fitted to them describes none of them alone")
        return notes

    def overfit_warnings(self) -> list[str]:
        """A fitted joint whose held-out RMS is far above its training RMS: too little data for the parameters."""
        def pooled(runs):
            return rms([self.errors(run)["rms"] for run in runs])

        if not self.holdout:
            return []
        train, held = pooled(self.train), pooled(self.holdout)
        pooling = "" if len(self.train) == len(self.holdout) == 1 else " (each pooled over its runs: the root of their mean square)"
        return [f"{JOINT_NAMES[j]}: held-out RMS {held[j]:.3g} is {held[j] / train[j]:.1f}x the training RMS {train[j]:.3g}{pooling}: "
                "the fit does not carry to the held-out runs: too few runs or periods to determine the arm, or runs that "
                "differ (another session, another state of the arm); more training runs tell the two apart"
                for j in self.wls.joints if held[j] > HOLDOUT_OVERFIT_RATIO * train[j]]


def _joint_indices(names: tuple[str, ...]) -> np.ndarray:
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown or not names:
        raise DvrkDartError(f"--joints: unknown joints {unknown} (known: {', '.join(JOINT_NAMES)})")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise DvrkDartError(f"--joints: {', '.join(repeated)} given twice")
    return np.array(sorted({JOINT_NAMES.index(n) for n in names}))


def excited_joints(runs: list[RunData], asked: np.ndarray) -> tuple[np.ndarray, dict[int, float], list[str]]:
    """(the joints fitted, the joints held still at their positions, one line
    per joint left out): a joint is fitted where every training run recorded
    it and some run moves it; a joint no run moves is held in the base
    parameters' test (its own parameters are not determined)."""
    from dvrk_dart.io.period import moving_joints

    recorded = np.all([run.processed.measured for run in runs], axis=0)
    moving = np.any([moving_joints(run.processed.q, run.processed.measured) for run in runs], axis=0)
    held = {int(j): float(np.mean([run.processed.q[:, j].mean() for run in runs])) for j in np.flatnonzero(~moving)}
    fitted = np.array([j for j in asked if recorded[j] and moving[j]], dtype=int)
    notes = [f"{JOINT_NAMES[j]} left out: not recorded in every training run" for j in asked if not recorded[j]]
    notes += [f"{JOINT_NAMES[j]} left out: no training run moves it (held at {held[j]:.4g}; its own inertia, friction "
              "and offset are not determined)" for j in asked if recorded[j] and not moving[j]]
    if not len(fitted):
        raise DvrkDartError("--runs: no joint (of --joints, where given) is recorded in every training run and moved by one: nothing to fit")
    return fitted, held, notes


def _load_runs(names: tuple[str, ...], regressor: Regressor, config: IdentificationConfig) -> tuple[list[RunData], str | None]:
    """Every run through one processing (and the note of io/signal.process_all). The --excitation is the
    training runs' design: a held-out run, of another trajectory as a rule, is read on its own period."""
    from dvrk_dart.io.excitation_design import read_design

    paths = [resolve_run(name) for name in names]
    measured = [load_run(path, regressor.model, config.topics) for path in paths]
    design = read_design(config.excitation) if config.excitation else None
    if design is None:
        processed, note = process_all(measured, config.processing)
    else:
        trained = len(config.runs)
        processed, note = process_all(measured[:trained], config.processing, design)
        processed += process_all(measured[trained:], "periodic")[0]
    runs = [RunData(str(name), path, p, p.in_band(regressor(p.q, p.dq, p.ddq))) for name, path, p in zip(names, paths, processed)]
    return runs, note


def _weighted_fit(train: list[RunData], base: BaseParameters, joints: np.ndarray, what: str) -> WeightedFit:
    """Upstream: on the samples, weights from a first fit's residual; periodic:
    on the harmonic coefficients, weights from the measured noise."""
    if train[0].processed.periodic is None:
        Yb = np.concatenate([run.Y[:, :, base.independent] for run in train])
        return fit_weighted(Yb, np.concatenate([run.processed.tau for run in train]), joints, what)
    rows_Y, rows_tau, rows_variance = [], [], []
    for run in train:
        periodic = run.processed.periodic
        Yb = run.Y[:, :, base.independent]
        rows_Y.append(periodic.projector.series(Yb.reshape(len(Yb), -1)).coefficients.reshape(-1, *Yb.shape[1:]))
        rows_tau.append(periodic.efforts.coefficients)
        rows_variance.append(periodic.effort_noise.coefficient_variance())
    return fit_weighted_periodic(np.concatenate(rows_Y), np.concatenate(rows_tau), np.concatenate(rows_variance), joints, what)


def check_consistent_runs(runs: list[RunData]) -> None:
    """Every run with the same columns: one line naming the odd one (runs of
    different rates go together: each is processed at its own)."""
    first = runs[0]
    for run in runs[1:]:
        if run.processed.tau.shape[1] != first.processed.tau.shape[1]:
            raise DvrkDartError(f"{run.path}: {run.processed.tau.shape[1]} joints, {first.path} has {first.processed.tau.shape[1]}")


def _prior(config: IdentificationConfig, model: PsmModel, regressor: Regressor) -> tuple[np.ndarray, str]:
    layout = regressor.layout
    if config.prior == PRIOR_NONE:
        return np.zeros(len(layout)), "none (zero: minimum norm)"
    explicit = None if config.prior == PRIOR_DEFAULT else config.prior
    try:
        path = resolve(model.default_parameters, explicit=explicit)
        return standard_vector(load_parameters(path, model), layout), str(path)
    except DvrkDartError as exc:
        if explicit is None:
            raise
        raise DvrkDartError(f"--prior {explicit}: {exc}") from None


def identify(config: IdentificationConfig) -> IdentificationResult:
    timings: dict[str, float] = {}
    start = time.perf_counter()
    if not config.runs:
        raise DvrkDartError("--runs: at least one training run is needed")
    model = load_model(config.model_file)
    distinct_inputs([("--runs", r) for r in config.runs] + [("--holdout", r) for r in config.holdout], model, config.topics)
    joints = _joint_indices(config.joints)
    bounds = load_bounds(config.bounds_file, model)
    regressor = Regressor(model, config.friction_law)
    prior, prior_source = _prior(config, model, regressor)
    loaded, note = _load_runs(config.runs + config.holdout, regressor, config)
    train, holdout = loaded[: len(config.runs)], loaded[len(config.runs):]
    check_consistent_runs(train + holdout)
    timings["load_and_regressor_s"] = time.perf_counter() - start
    joints, held, left_out = excited_joints(train, joints)
    base = find_base_parameters(regressor, seed=config.seed, joints=joints, held=held)
    what = "--runs " + " ".join(config.runs)
    choice = {}
    if regressor.friction_law.kind == "presliding" and not regressor.friction_law.presliding:
        train, regressor.friction_law, choice = choose_distances(
            train, regressor, base, joints, bounds.presliding, lambda runs: _weighted_fit(runs, base, joints, what))
        holdout = [_with_law(run, regressor) for run in holdout]
    wls = _weighted_fit(train, base, joints, what)
    timings["base_and_wls_s"] = time.perf_counter() - start - timings["load_and_regressor_s"]
    t0 = time.perf_counter()
    consistent = fit_consistent(wls, base, regressor.layout, bounds, prior, solver=config.solver)
    consistent, reference_note, reference_theta = _reference_where_no_fitted_joint(consistent, regressor, joints, config, model)
    left_out += reference_note
    timings["convex_program_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - start
    return IdentificationResult(config, model, regressor, bounds, base, wls, consistent, prior, prior_source, train, holdout, note, timings,
                                choice, left_out, reference_theta)


def _reference_where_no_fitted_joint(consistent: ConsistentFit, regressor: Regressor, joints: np.ndarray,
                                     config: IdentificationConfig, model: PsmModel) -> tuple[ConsistentFit, list[str], np.ndarray | None]:
    """The parameters acting on no fitted joint (a left-out joint's own
    friction, offset, motor inertia) take the reference's values: --prior's
    file, else the arm's published parameters. Fitted with no prior they came
    out about zero, and params.json gave a wrist without friction."""
    alone = acting_on_none_of(regressor, joints, seed=config.seed)
    if not len(alone):
        return consistent, [], None
    reference, source = _prior(config if config.prior != PRIOR_NONE else replace(config, prior=PRIOR_DEFAULT), model, regressor)
    theta = consistent.theta.copy()
    theta[alone] = reference[alone]
    by_link: dict[str, list[str]] = {}
    for i in alone:
        link, name = regressor.layout.names[i].split(".", 1)
        by_link.setdefault(link, []).append(name)
    said = "; ".join(f"{link} ({model.links[int(link.removeprefix('link'))].name}) {' '.join(names)}" for link, names in by_link.items())
    held = np.full(len(theta), np.nan)
    held[alone] = reference[alone]
    return replace(consistent, theta=theta), [f"{len(alone)} parameters act on no fitted joint ({said}): "
                                              f"not determined by these runs, params.json holds {source}'s values "
                                              "(Fc Coulomb, Fv viscous, Fo offset, Im motor inertia, K spring)"], held


def _with_law(run: RunData, regressor: Regressor) -> RunData:
    """`run` with the Coulomb columns of the regressor's pre-sliding links."""
    for key, _ in regressor.friction_law.presliding:
        run = with_link_column(run, regressor, key, regressor.friction_law)
    return run

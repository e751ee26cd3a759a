"""`dvrk-dart identify`: measured runs in, physically consistent parameters out.

Steps: load and process every run with the project's one upstream-compatible
processing (`io/signal.py`); build the regressor from the identified model's
Pinocchio tree; find the base parameters; weighted least squares; the convex
program; predictions and errors on the training and held-out runs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.base import BaseParameters, find_base_parameters
from dvrk_dart.identification.fit import (
    Bounds,
    ConsistentFit,
    WeightedFit,
    fit_consistent,
    fit_weighted,
    load_bounds,
)
from dvrk_dart.identification.regressor import FrictionLaw, Regressor, standard_vector
from dvrk_dart.io.reference_data import load_run, resolve, resolve_run
from dvrk_dart.io.signal import FIRST_PERIOD_SAMPLES, ProcessedRun, process
from dvrk_dart.metrics import relative_error, rms
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel, load_model
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.model.parameters import load_parameters

#: --prior values besides a file
PRIOR_DEFAULT, PRIOR_NONE = "default", "none"


@dataclass(frozen=True)
class IdentificationConfig:
    runs: tuple[str, ...]
    holdout: tuple[str, ...] = ()
    joints: tuple[str, ...] = JOINT_NAMES
    friction_law: FrictionLaw = FrictionLaw()
    bounds_file: str | None = None
    prior: str = PRIOR_NONE
    seed: int = 0
    solver: str = "CLARABEL"
    model_file: str = str(DEFAULT_MODEL_FILE)


@dataclass
class RunData:
    name: str
    path: Path
    processed: ProcessedRun
    Y: np.ndarray  # (N, 7, n_standard)


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
    timings_s: dict[str, float] = field(default_factory=dict)

    @property
    def theta(self) -> np.ndarray:
        return self.consistent.theta

    def predicted(self, run: RunData, theta: np.ndarray | None = None) -> np.ndarray:
        return run.Y @ (self.theta if theta is None else theta)

    def errors(self, run: RunData, first_period: bool = False, theta: np.ndarray | None = None) -> dict:
        n = FIRST_PERIOD_SAMPLES if first_period else len(run.processed)
        predicted, measured = self.predicted(run, theta)[:n], run.processed.tau[:n]
        return {
            "samples": int(len(measured)),
            "relative_error": relative_error(predicted, measured).tolist(),
            "rms": rms(predicted - measured).tolist(),
        }


def _joint_indices(names: tuple[str, ...]) -> np.ndarray:
    unknown = [n for n in names if n not in JOINT_NAMES]
    if unknown or not names:
        raise DvrkDartError(f"--joints: unknown joints {unknown} (known: {', '.join(JOINT_NAMES)})")
    return np.array(sorted({JOINT_NAMES.index(n) for n in names}))


def _load_runs(names: tuple[str, ...], regressor: Regressor) -> list[RunData]:
    out = []
    for name in names:
        path = resolve_run(name)
        measured = load_run(path)
        processed = process(measured)
        out.append(RunData(str(name), path, processed, regressor(processed.q, processed.dq, processed.ddq)))
    return out


def check_consistent_runs(runs: list[RunData]) -> None:
    """Every run with the same columns and sampling rate: one line naming the odd one."""
    first = runs[0]
    step = float(np.median(np.diff(first.processed.t)))
    for run in runs[1:]:
        if run.processed.tau.shape[1] != first.processed.tau.shape[1]:
            raise DvrkDartError(f"{run.path}: {run.processed.tau.shape[1]} joints, {first.path} has {first.processed.tau.shape[1]}")
        other = float(np.median(np.diff(run.processed.t)))
        if abs(other - step) > 1e-9 * step:
            raise DvrkDartError(f"{run.path}: sampled at {1 / other:g} Hz, {first.path} at {1 / step:g} Hz: resample to one rate")


def _prior(config: IdentificationConfig, model: PsmModel, regressor: Regressor) -> tuple[np.ndarray, str]:
    layout = regressor.layout
    if config.prior == PRIOR_NONE:
        return np.zeros(len(layout)), "none (zero: minimum norm)"
    explicit = None if config.prior == PRIOR_DEFAULT else config.prior
    path = resolve(model.default_parameters, explicit=explicit)
    return standard_vector(load_parameters(path, model), layout), str(path)


def identify(config: IdentificationConfig) -> IdentificationResult:
    timings: dict[str, float] = {}
    start = time.perf_counter()
    if not config.runs:
        raise DvrkDartError("--runs: at least one training run is needed")
    model = load_model(config.model_file)
    joints = _joint_indices(config.joints)
    bounds = load_bounds(config.bounds_file, model)
    regressor = Regressor(model, config.friction_law)
    prior, prior_source = _prior(config, model, regressor)
    train = _load_runs(config.runs, regressor)
    holdout = _load_runs(config.holdout, regressor)
    check_consistent_runs(train + holdout)
    timings["load_and_regressor_s"] = time.perf_counter() - start
    base = find_base_parameters(regressor, seed=config.seed, joints=joints)
    Yb = np.concatenate([run.Y[:, :, base.independent] for run in train])
    tau = np.concatenate([run.processed.tau for run in train])
    what = "--runs " + " ".join(config.runs)
    wls = fit_weighted(Yb, tau, joints, what)
    timings["base_and_wls_s"] = time.perf_counter() - start - timings["load_and_regressor_s"]
    t0 = time.perf_counter()
    consistent = fit_consistent(wls, base, regressor.layout, bounds, prior, solver=config.solver)
    timings["convex_program_s"] = time.perf_counter() - t0
    timings["total_s"] = time.perf_counter() - start
    return IdentificationResult(config, model, regressor, bounds, base, wls, consistent, prior, prior_source, train, holdout, timings)

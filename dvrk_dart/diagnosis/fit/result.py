"""The later stages of a diagnosis: the selection of effects, the
re-simulation with them, and the frozen result (`Diagnosis.to_json()` is the
contract of diagnosis.json, docs/outputs.md)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from dvrk_dart.diagnosis.fit.design import BLOCK_DURATION_S, MAX_BLOCKS_PER_RUN, WITHHELD_KINDS, Fit, per_joint_fraction, sse, weighted_fraction
from dvrk_dart.diagnosis.effects.library import effects_to_sim_config, not_simulated, unsimulated_effort
from dvrk_dart.diagnosis.fit.families import choose_within_families
from dvrk_dart.diagnosis.fit.problem import Problem
from dvrk_dart.diagnosis.fit.diagnosis_runs import DiagnosisRun, RunRole, Simulate
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.measured_run import EFFORT_RESOLUTION
from dvrk_dart.diagnosis.fit.selection import (
    BOOTSTRAP_RESAMPLES,
    GAIN_FAILURE_QUANTILE,
    MIN_HELDOUT_GAIN,
    CvResult,
    Selector,
)
from dvrk_dart.metrics import rms, per_measured_joint
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.sim.config import SimConfig


# ------------------------------------------------------------------ selection
@dataclass
class Selection:
    """The greedy selection's outcome: the chosen effects, their joint fit, every candidate's own score."""

    selector: Selector
    selected: list[int]
    final: Fit
    steps: list
    individual: dict[int, CvResult]
    cross_validated: CvResult

    def method(self) -> str:
        return (f"greedy forward selection on {len(self.selector.folds)}-fold contiguous time-segment cross-validation of the training "
                f"runs, weighted least squares (joint weight 1/RMS before; runs minus their baseline refitted with 1/RMS after), bounded to "
                f"physical ranges; stop when the held-out gain < "
                f"{MIN_HELDOUT_GAIN} or not positive with probability {1 - GAIN_FAILURE_QUANTILE:.2f} (block bootstrap, "
                f"{BLOCK_DURATION_S} s blocks, at most {MAX_BLOCKS_PER_RUN} a run, {BOOTSTRAP_RESAMPLES} resamples); a payload's link among its equivalent links "
                f"(identical efforts) by the penalised training cost")


def select(problem: Problem, max_effects: int) -> Selection:
    selector = Selector(problem.design, problem.train_grams, problem.joint_weights, problem.folds)
    selected, steps, individual, selected_cv = selector.greedy(max_effects)
    if selected and all(run.role is RunRole.DIFFERENCE for run in problem.train_runs):
        # runs minus their baseline: what the selection leaves is their noise and the session's change, and the final
        # fit weighs each joint by it (feasible generalised least squares); of a run alone, what is left is model error
        selector = selector.fitting_by(_residual_weights(problem, selector.fit_all(selected)))
    selected, final, selected_cv = choose_within_families(selector, selected, selected_cv)
    return Selection(selector, selected, final, steps, individual, selected_cv)


def _residual_weights(problem: Problem, fit: Fit) -> np.ndarray:
    """1 / the training runs' residual energy per sample on each joint after `fit` (floored as the weights before).
    A tool payload's off-axis first moment took q3's noise, which the gap's weights let pull what q2 pins: q2 was
    left at 1.9x the true physics' gap on another noise draw of the 2018 design (docs/diagnosis-method.md)."""
    grams = problem.train_grams
    after = sse(fit.beta, grams.A, grams.g, grams.s).sum(0) / max(grams.n.sum(), 1)
    return np.where(problem.joint_weights > 0, 1.0 / np.maximum(after, EFFORT_RESOLUTION**2), 0.0)


def without_last_effect(selection: Selection) -> Selection:
    """The selection less its last effect, refitted (its re-simulation failed)."""
    chosen = selection.selected[:-1]
    selector = selection.selector
    return Selection(selector, chosen, selector.fit_all(chosen), selection.steps, selection.individual, selector.cross_validate(chosen))


def train_fraction(problem: Problem, beta: np.ndarray) -> float:
    A, g, s = problem.train_totals
    return weighted_fraction(sse(beta, A, g, s), s, problem.joint_weights)


def holdout_fraction(problem: Problem, beta: np.ndarray) -> float | None:
    if not problem.holdout_grams:
        return None
    errors = np.sum([sse(beta, A, g, s) for A, g, s in problem.holdout_totals], axis=0)
    return weighted_fraction(errors, np.sum([s for _, _, s in problem.holdout_totals], axis=0), problem.joint_weights)


def effect_entries(problem: Problem, selection: Selection) -> list[dict]:
    """Every candidate, fitted alone on all training data, for its parameters
    and scores; with a baseline the finding (what the runs have and their
    baseline has not) ranks before the errors common to both."""
    s, effects = selection, problem.effects
    rank_order = s.selected + sorted((i for i in s.individual if i not in s.selected), key=lambda i: -s.individual[i].fraction)
    if problem.has_baseline:
        rank_order = sorted(rank_order, key=lambda i: i not in s.selected or not problem.design.is_withheld(effects[i]))
    return [_entry(problem, selection, rank, i) for rank, i in enumerate(rank_order, start=1)]


#: a payload-shaped effect without a baseline: the arm's mass distribution
#: against the parameters; only a baseline run without the weight isolates a payload
GRAVITY_MISMATCH_KIND = "gravity_mismatch"


def _entry(problem: Problem, s: Selection, rank: int, i: int) -> dict:
    e = problem.effects[i]
    alone = s.selector.fit_all([i])
    p = s.final.params[i] if i in s.selected else alone.params[i]
    cv = s.individual[i]
    hold = holdout_fraction(problem, alone.beta)
    return {
        "rank": rank,
        "name": e.name,
        "kind": e.kind if problem.has_baseline or e.kind not in WITHHELD_KINDS else GRAVITY_MISMATCH_KIND,
        "family": e.family,
        "joints": [name for name in e.joints if problem.recorded[JOINT_NAMES.index(name)]],  # no say on a joint not recorded
        "parameters": e.describe(p),
        "units": e.units(),
        "size": e.size(p),
        "explained_fraction": {
            "train": train_fraction(problem, alone.beta),
            "holdout": hold if hold is not None else cv.fraction,
            "holdout_source": "runs" if hold is not None else "time_segments",
            "cross_validated": cv.fraction,
            "cross_validated_interval": s.selector.interval(cv.after),
        },
        "explained_fraction_per_joint": {"cross_validated": per_measured_joint(per_joint_fraction(cv.after, problem.train_grams.s),
                                                                               problem.recorded)},
        "selected": i in s.selected,
        "role": "finding" if not problem.has_baseline or problem.design.is_withheld(e) else "common_model_error",
        "selection_step": s.selected.index(i) + 1 if i in s.selected else None,
        "in_simulation": e.sim_contribution(np.asarray(p)) is not None,
        "fully_in_simulation": e.fully_simulated(np.asarray(p)),
    }


# ------------------------------------------------------------ re-simulation
@dataclass
class Resimulation:
    """The selected effects as physics, and what they leave on every run."""

    sim_config: SimConfig
    not_in_simulation: list
    train_after: list[np.ndarray]
    holdout_after: list[np.ndarray]
    source: str


def resimulate(problem: Problem, selection: Selection, simulate: Simulate | None, base_config: SimConfig) -> Resimulation:
    """Each run replayed with the selected effects (a baseline run, and the
    baseline under a run of the same motion, with the effects all runs share:
    no withheld payload); without a simulation, the effects' regressors."""
    chosen = [(problem.effects[i], selection.final.params[i]) for i in selection.selected]
    full = (effects_to_sim_config(chosen, base_config), not_simulated(chosen))
    shared_effects = [(e, p) for e, p in chosen if not problem.design.is_withheld(e)]
    shared = (effects_to_sim_config(shared_effects, base_config), not_simulated(shared_effects))

    def simulated_after(run: DiagnosisRun, with_withheld: bool = True) -> np.ndarray:
        config, extra = full if with_withheld else shared
        simulated = np.asarray(simulate(config, run.state), dtype=float) + unsimulated_effort(extra, problem.features_of(run))
        return np.where(run.state.measured, run.state.tau - run.state.in_band(simulated), 0.0)  # nothing to explain where not recorded

    def after_residual(run: DiagnosisRun, columns: np.ndarray) -> np.ndarray:
        if simulate is None:
            after = run.residual - columns @ selection.final.beta
        elif run.role is RunRole.DIFFERENCE:
            after = simulated_after(run) - simulated_after(run.baseline, with_withheld=False)
        else:
            after = simulated_after(run, with_withheld=run.role is not RunRole.BASELINE)
        return after - problem.demean_of(run) * after.mean(axis=0) if problem.nuisance else after

    if hasattr(simulate, "prefetch"):  # the replays after the effects, side by side
        simulate.prefetch([pair for r in problem.train_runs + problem.holdout_runs for pair in _after_replays(r, full[0], shared[0])])
    train_after = [after_residual(r, c) for r, c in zip(problem.train_runs, problem.train_columns)]
    holdout_after = [after_residual(r, c) for r, c in zip(problem.holdout_runs, problem.holdout_columns)]
    source = "regressor" if simulate is None else ("simulation" if not full[1] else "simulation+regressor")
    return Resimulation(full[0], [e.name for e, _ in full[1]], train_after, holdout_after, source)


def _after_replays(run: DiagnosisRun, sim_config: SimConfig, shared_config: SimConfig) -> list[tuple[SimConfig, object]]:
    """The (config, state) replays a run's residual after asks for."""
    if run.role is RunRole.DIFFERENCE:
        return [(sim_config, run.state), (shared_config, run.baseline.state)]
    return [(shared_config if run.role is RunRole.BASELINE else sim_config, run.state)]


def gaps(residuals: list[np.ndarray], recorded: np.ndarray | None = None) -> list[float | None] | None:
    """RMS per joint over the runs' residuals (None for a joint the runs did
    not record: no figure on it), or None without runs."""
    if not residuals:
        return None
    values = rms(np.vstack(residuals))
    return values.tolist() if recorded is None else per_measured_joint(values, recorded)


def noise_gaps(runs: list[DiagnosisRun], recorded: np.ndarray, arm: Arm) -> list[float | None] | None:
    """Per joint, the noise the periodic projection leaves on the runs' gaps (`DiagnosisRun.noise_energy`), as `gaps`
    pools them: what a gap cannot go under without a session floor; None upstream or without runs."""
    energies = [run.noise_energy(arm) for run in runs]
    if not runs or any(energy is None for energy in energies):
        return None
    samples = sum(len(run) for run in runs)
    return per_measured_joint(np.sqrt(sum(len(run) * e for run, e in zip(runs, energies)) / samples), recorded)


# ------------------------------------------------------------------- result
@dataclass(frozen=True)
class Diagnosis:
    """The diagnosis's outcome, field for field the keys of diagnosis.json."""

    joints: list
    units: list
    joint_words: str
    measured: str
    measured_runs: list
    baseline_source: dict
    nuisance_offsets: dict | None
    nuisance_offset_joints: dict | None
    session_floor: list | None
    repeat: str | None
    #: where the --repeat came from: the option, the model card's repeat pair, or none and why
    repeat_source: str | None
    gap_split: dict
    baseline: str | None
    train_runs: list
    holdout_runs: list
    inputs: dict
    processing: dict
    residual_definition: str
    simulated_source: str
    gap_before: dict
    gap_after: dict
    gap_after_source: str
    explained_fraction: dict
    effects: list
    selection: dict
    payload: dict | None
    payloads: list
    payload_candidates: list
    sim_config: dict
    not_in_simulation: list
    #: the joints every run recorded (the others carry no figure, weight or effect)
    recorded_joints: list
    #: a joint some runs recorded and others not -> the runs that did not
    not_recorded_by: dict
    #: a joint a run of its own did not record, held at 0, moving the model's efforts on recorded joints more than their gaps
    unrecorded_joint_notes: list
    #: a training run whose measured efforts run opposite to the simulated ones, or are a multiple of them (a log's sign or unit)
    effort_convention_notes: list
    #: without a baseline, a payload-shaped fit is this arm's gravity (mass distribution) against the parameters, not a payload
    gravity_mismatch: dict | None
    #: with a baseline, a payload-shaped fit whose intervals all hold zero: no payload is named
    payload_not_distinguished: dict | None
    #: a --payload-at given where no payload-shaped effect is selected: why it reads nothing (else null)
    payload_at_unused: str | None
    #: selected effects whose re-simulation failed or drifted: dropped, with the reason
    dropped_effects: list
    #: how much of the gap the selected effects remove, in the one rule's words (diagnosis/output/wording.py)
    explanation: dict
    #: how much of the selected effects' efforts the identified model's non-inertial terms carry (fit/identified_terms.py)
    identified_terms: dict | None = None

    def to_json(self) -> dict:
        """The diagnosis.json document (a fresh dict: the caller may add to it)."""
        return asdict(self)

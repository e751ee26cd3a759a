"""The first stage of a diagnosis: the problem it solves.

The runs by role (`runs.RunRole`), the candidate effects as one design, the
per-joint and per-run weights, the joints that carry a nuisance constant,
and the runs' Gram blocks the selection works on."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Sequence

import numpy as np

from dvrk_dart.diagnosis.fit.design import Design, Grams
from dvrk_dart.diagnosis.effects.arm_effects import EffortScale, LinkMassScale
from dvrk_dart.diagnosis.effects.effect import Effect
from dvrk_dart.diagnosis.effects.first_moment import FirstMomentPayload, PayloadAtPosition, check_mass_determinable, parse_payload_at
from dvrk_dart.diagnosis.effects.payload import PointPayload, equivalent_payload_links
from dvrk_dart.diagnosis.effects.joint_effects import JointOffset
from dvrk_dart.diagnosis.effects.position_friction import PositionFriction
from dvrk_dart.diagnosis.effects.library import candidate_effects
from dvrk_dart.diagnosis.fit.diagnosis_runs import (
    DiagnosisRun,
    RunProcessing,
    RunRole,
    Simulate,
    choose_processing,
    flat_specs,
    with_baseline_motion,
    loaded_states,
    prepare_run,
)
from dvrk_dart.diagnosis.fit.session_floor import check_repeat_motion, session_offset_joints
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.effort_convention import effort_convention_notes
from dvrk_dart.identification.unrecorded_joints import unrecorded_joint_notes
from dvrk_dart.io.reference_data import distinct_inputs, distinct_labels
from dvrk_dart.metrics import rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.io.measured_run import EFFORT_RESOLUTION
from dvrk_dart.io.period import spanning_columns
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.sim.config import SimConfig

#: the roles whose runs take a nuisance constant on every joint (Problem.demean_of)
CONSTANT_ON_EVERY_JOINT = (RunRole.OTHER_MOTION, RunRole.BASELINE)


@dataclass
class Problem:
    """Runs by role, effects, design and weights: what the selection fits."""

    arm: Arm
    effects: list[Effect]
    design: Design
    processing: RunProcessing
    inputs: dict
    train_runs: list[DiagnosisRun]
    holdout_runs: list[DiagnosisRun]
    baseline_run: DiagnosisRun | None
    repeat_run: DiagnosisRun | None
    n_measured: int
    #: the index in `effects` of the payload at a given position (--payload-at)
    at_index: int | None
    #: a constant per run fitted as a nuisance, on `offset_joints` for a run minus its baseline
    nuisance: bool
    offset_joints: np.ndarray | None
    offset_joints_source: str | None
    folds: int
    #: where the --repeat came from (the option, the model card's repeat pair, or none and why)
    repeat_source: str | None = None
    train_columns: list[np.ndarray] = field(default_factory=list, repr=False)
    holdout_columns: list[np.ndarray] = field(default_factory=list, repr=False)
    train_grams: Grams | None = field(default=None, repr=False)
    holdout_grams: list[Grams] = field(default_factory=list, repr=False)
    #: per-joint weights, 1 / (training residual RMS)^2
    joint_weights: np.ndarray | None = None

    @property
    def recorded(self) -> np.ndarray:
        """(7,) bool: the joints every run recorded (the others have no weight and no figure)."""
        return recorded_joints([*self.train_runs, *self.holdout_runs, self.baseline_run, self.repeat_run])

    @property
    def not_recorded_by(self) -> dict[str, list[str]]:
        """A joint some runs recorded and others not -> the runs that did not (each held where its log holds it in
        its simulation): the diagnosis has no figure, weight or effect on it, and says why."""
        runs = [r for r in (*self.train_runs, *self.holdout_runs, self.baseline_run, self.repeat_run) if r is not None]
        return {name: list(dict.fromkeys(r.name for r in runs if not r.state.measured[j])) for j, name in enumerate(JOINT_NAMES)
                if not self.recorded[j] and any(r.state.measured[j] for r in runs)}

    def unrecorded_joint_notes(self) -> list[str]:
        """Per training run of its own: a joint it did not record, held at 0 in its simulation, that moves the
        model's efforts on a recorded joint by more than that joint's gap: the effects found there may stand
        for it (a baseline of the same motion holds it alike, and the difference cancels it)."""
        return [f"{run.name}: {note}" for run in self.train_runs if run.role is RunRole.RAW
                for note in unrecorded_joint_notes(self.arm.identified, run.state, rms(self.before_residual(run)))]

    def effort_convention_notes(self) -> list[str]:
        """Per training, baseline and repeat run: measured efforts opposite to the simulated ones, or a multiple of them
        (a log's sign or unit, which no effect of the library is: a flipped log was read as a cable's elasticity)."""
        runs = {run.name: run for run in (*self.train_runs, self.baseline_run, self.repeat_run) if run is not None}
        return [f"{name}: {note}" for name, run in runs.items()
                for note in effort_convention_notes(run.simulated, run.state.tau, run.state.measured, "simulation")]

    @cached_property
    def train_totals(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The training Gram blocks summed over the folds (A, g, s): every candidate's training fraction reads them."""
        grams = self.train_grams
        return grams.A.sum(0), grams.g.sum(0), grams.s.sum(0)

    @cached_property
    def holdout_totals(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Each held-out run's Gram blocks summed (A, g, s): every candidate's held-out fraction reads them."""
        return [(h.A.sum(0), h.g.sum(0), h.s.sum(0)) for h in self.holdout_grams]

    @property
    def has_baseline(self) -> bool:
        return self.baseline_run is not None

    @property
    def reference_run(self) -> DiagnosisRun:
        """The run the session floor is read against: the baseline, else the first training run."""
        return self.baseline_run or self.train_runs[0]

    def features_of(self, run: DiagnosisRun):
        return run.features(self.arm)

    def columns_of(self, run: DiagnosisRun) -> np.ndarray:
        """The effects' columns in the band of the run's efforts. A run of
        another motion than its baseline has no J1 reference: its raw J1 gap is
        dominated by motion-dependent errors (0.36 N·m RMS on the half-speed
        105 g run, the weight's J1 effort 0.1), which a payload's free J1 path
        would absorb; J1's payload is read from the runs minus their baseline."""
        yaw_path_from_differences = any(r.role is RunRole.DIFFERENCE for r in self.train_runs)
        baseline_features = self.features_of(run.baseline) if run.role is RunRole.DIFFERENCE else None
        return run.state.in_band(self.design.run_columns(run.role, self.features_of(run), baseline_features,
                                                         yaw_path=not (yaw_path_from_differences and run.role is RunRole.OTHER_MOTION)))

    def demean_of(self, run: DiagnosisRun) -> np.ndarray | None:
        """The joints with a nuisance constant: a run minus its baseline (same
        motion), like a run of its own, changes its constant with the session
        only (a constant the same in every session is an effect: J1's left-out
        offset); a run fitted beside a baseline of another motion, and that
        baseline, keep one on every joint (the mean of each motion's
        dependent errors, e.g. friction's asymmetry, is its own)."""
        if not self.nuisance:
            return None
        return np.ones(N_JOINTS, dtype=bool) if run.role in CONSTANT_ON_EVERY_JOINT else self.offset_joints

    def before_residual(self, run: DiagnosisRun) -> np.ndarray:
        """The run's gap before any effect, its nuisance constants taken out as
        the fit and the gap after take them out: a session's constant is no
        effect's to explain (q2's counted as explained with a baseline)."""
        demean = self.demean_of(run)
        return run.residual if demean is None else run.residual - demean * run.residual.mean(axis=0)

    def grams_of(self, run: DiagnosisRun, columns: np.ndarray, folds: int) -> Grams:
        grams = Grams.of_run(self.design, self.features_of(run), run.residual, folds, self.demean_of(run), columns)
        noise = direction_noise(run, self.arm)
        return grams if noise is None else replace(grams, noise=np.tile(noise, (len(grams.s), 1)))


def direction_noise(run: DiagnosisRun, arm: Arm) -> np.ndarray | None:
    """(7,) periodic processing: the noise energy of the run's residual along one
    direction of its band (N sigma^2 / (2H+1) per joint, `DiagnosisRun.noise_energy`); None upstream."""
    energy = run.noise_energy(arm)
    return None if energy is None else len(run) * energy / (2 * run.state.periodic.harmonics + 1)


def _joint_weights(residual: np.ndarray) -> np.ndarray:
    sigma = np.maximum(rms(residual), EFFORT_RESOLUTION)  # a joint whose residual is below it must not dominate the fit
    return 1.0 / sigma**2


def _run_weights(parts: list[Grams]) -> list[np.ndarray]:
    """Per run and joint, weights that give every training run the pooled
    residual level: runs are heteroscedastic (a run minus its baseline has a
    tenth of a raw run's residual) and each must count, not only the largest."""
    if len(parts) < 2:
        return [np.ones(N_JOINTS) for _ in parts]
    energy = [p.s.sum(0) / max(p.n.sum(), 1) for p in parts]
    pooled = np.sum([p.s.sum(0) for p in parts], axis=0) / max(sum(p.n.sum() for p in parts), 1)
    return [np.where(e > 0, pooled / np.maximum(e, 1e-300), 1.0) for e in energy]


def roles(measured_list, baseline, train, holdout, repeat) -> list[tuple[str, str]]:
    """(option, run) of every run given by name or path (a run given as data has no file)."""
    pairs = [("--measured", m) for m in measured_list] + [("--baseline", baseline), ("--repeat", repeat)]
    for option, specs in (("--train", train or []), ("--holdout", holdout or [])):
        # a (run, baseline) pair: its baseline may serve several runs
        pairs += [(option, spec[0] if isinstance(spec, tuple) else spec) for spec in specs]
    measured = {str(m) for m in measured_list}
    return [(option, s) for option, s in pairs if isinstance(s, (str, Path))
            and not (option == "--train" and str(s) in measured)]  # --train may repeat the measured run (it always trains)


def _effects(arm: Arm, effects, payload_model: str, base_config: SimConfig, payload_at, effort_scale: bool) -> tuple[list[Effect], int | None]:
    """The candidate effects, and a payload at a given position appended (its index)."""
    if effects is None:  # a scale of the measured efforts is a candidate only when asked: on the real session pairs it takes
        # what sessions change (docs/diagnosis-method.md); else it is weighed against the selection only (`scale_rival`)
        effects = candidate_effects(arm, payload_model=payload_model, base=base_config) + [EffortScale(candidate=effort_scale)]
    else:
        effects = list(effects) + ([EffortScale()] if effort_scale and not any(isinstance(e, EffortScale) for e in effects) else [])
    if payload_at is None:
        return effects, None
    key, position = parse_payload_at(payload_at, arm.model) if isinstance(payload_at, str) else payload_at
    check_mass_determinable(arm, key, position, str(payload_at))
    return effects + [PayloadAtPosition(arm.model, key, position)], len(effects)


def _one_body_on_these_runs(arm: Arm, effects: list[Effect], runs: list) -> list[Effect]:
    """The payload candidates with the links these runs do not move apart from theirs as equivalent links (the
    joints between held in every run: a 3-joint log's wrist moves the tool with the insertion carriage), as the
    parallelogram's links are for any motion: the efforts cannot tell them apart. They become one family: at
    most one of them is selected, the member by its penalised cost (families.choose_within_families)."""
    q = np.vstack([r.state.q for r in runs if r is not None])
    held = {j: float(q[0, j]) for j in np.flatnonzero(~spanning_columns(q))}
    if not held:
        return effects
    equivalents = equivalent_payload_links(arm, held, recorded_joints(runs))
    relabelled = []
    for effect in effects:
        if isinstance(effect, (PointPayload, FirstMomentPayload)):
            effect = copy.copy(effect)
            effect.equivalent_links = tuple(arm.model.links[k].name for k in equivalents[effect.link_key] if k != effect.link_key)
        relabelled.append(effect)
    return relabelled


def recorded_joints(runs: list) -> np.ndarray:
    """(7,) bool: the joints every run recorded (None: a role without a run)."""
    return np.all([r.state.measured for r in runs if r is not None], axis=0)


def _on_training_range(effect: Effect, runs: list) -> Effect:
    """A friction that changes along a joint's range, simulated as fitted within the range the training runs cover."""
    if not isinstance(effect, PositionFriction):
        return effect
    q = np.concatenate([r.state.q[:, effect.joint_index] for r in runs])
    return effect.within(float(q.min()), float(q.max())) if q.max() > q.min() else effect


def _without_kind(effects: list[Effect], at_index: int | None, kind: str) -> tuple[list[Effect], int | None]:
    """The candidates but those of one kind (a link's own mass, where only what the runs changed is sought)."""
    kept = [e for i, e in enumerate(effects) if i == at_index or e.kind != kind]
    return kept, (None if at_index is None else kept.index(effects[at_index]))


def _without_nuisance_constants(effects: list[Effect], at_index: int | None, offset_joints: np.ndarray,
                                runs: list) -> tuple[list[Effect], int | None]:
    """The candidates without a constant offset on a joint where every training
    run has its own nuisance constant: nothing is left to fit it (it read
    -8.9e11 N·m, with no share, in diagnosis.json)."""
    constant_per_run = offset_joints | np.all([r.role in CONSTANT_ON_EVERY_JOINT for r in runs])
    kept = [e for i, e in enumerate(effects) if i == at_index or not (isinstance(e, JointOffset) and constant_per_run[e.joint_index])]
    return kept, (None if at_index is None else kept.index(effects[at_index]))


def _on_recorded_joints(effects: list[Effect], at_index: int | None, runs: list) -> tuple[list[Effect], int | None]:
    """The candidates that act on a joint every run recorded (one acting only on joints
    a run did not record has nothing to fit), and the index of the payload at a given position."""
    names = {name for name, on in zip(JOINT_NAMES, recorded_joints(runs)) if on}
    if not names:
        each = "; ".join(f"{r.name}: {', '.join(n for n, on in zip(JOINT_NAMES, r.state.measured) if on)}" for r in runs if r is not None)
        raise DvrkDartError(f"--measured: no joint is recorded in every run ({each}): nothing to compare them on")
    at_effect = None if at_index is None else effects[at_index]
    kept = [e for e in effects if names.intersection(e.joints)]
    if at_effect is None:
        return kept, None
    if at_effect not in kept:
        raise DvrkDartError(f"--payload-at: a payload there acts on {', '.join(at_effect.joints)}, which the runs did not record")
    return kept, next(i for i, e in enumerate(kept) if e is at_effect)


def _held_out(run: DiagnosisRun, baseline: DiagnosisRun | None) -> DiagnosisRun:
    """A held-out run as the training runs are read: minus the baseline where there is one, which needs its motion
    (a run of another motion scored raw against effects fitted as a change read "378x worse than the identified model")."""
    if baseline is not None and run.role is RunRole.OTHER_MOTION:
        raise DvrkDartError(f"--holdout {run.name}: with --baseline a held-out run is scored minus the baseline, which needs the "
                            f"baseline's motion ({baseline.name}); {run.name} is another motion"
                            f"{f' ({run.alignment})' if run.alignment else ''}: diagnose it with a baseline of its own, or leave it out")
    return run


def build_problem(arm: Arm, measured_list: list, baseline, train: Sequence | None, holdout: Sequence | None, repeat, *,
                  simulate: Simulate | None, base_config: SimConfig, effects, payload_model: str, payload_at,
                  nuisance: bool, processing: str | None, folds: int, topics: BagTopics = BagTopics(),
                  repeat_source: str | None = None, effort_scale: bool = False) -> Problem:
    """The runs prepared by role (simulated, aligned on their baseline), the
    design of the candidate effects and the Gram blocks of every run."""
    effects, at_index = _effects(arm, effects, payload_model, base_config, payload_at, effort_scale)
    all_specs = [baseline, *measured_list, *(train or []), *(holdout or []), repeat]
    inputs = distinct_inputs(roles(measured_list, baseline, train, holdout, repeat), arm.model, topics)
    # every command's default (None): periodic where every run is a periodic excitation, else upstream
    run_processing = choose_processing([baseline, *measured_list, *(train or []), repeat], processing, arm.model, topics, holdout or ())
    if processing is None:
        run_processing = with_baseline_motion(run_processing, baseline, measured_list, arm.model)

    labels = distinct_labels(s for s in flat_specs(all_specs) if isinstance(s, (str, Path)))  # a/run.csv and b/run.csv: a/run, b/run

    def as_run(spec, baseline=None, rate_hz=None):
        if isinstance(spec, tuple):  # (run, its own baseline)
            spec, baseline = spec
            baseline = as_run(baseline) if isinstance(baseline, (str, Path)) else baseline
        return prepare_run(spec, arm, simulate, base_config, baseline=baseline, name=labels.get(str(spec)), processing=run_processing,
                           rate_hz=rate_hz)

    # a baseline and a repeat are subtracted from, or compared with, the runs sample by sample: on their rate
    rate = next(iter(loaded_states(measured_list[:1], arm.model, run_processing)), None)
    rate = rate.rate_hz if rate is not None else None
    check_repeat_motion(baseline if baseline is not None else measured_list[0], repeat, arm.model, run_processing, rate, baseline is not None)
    if hasattr(simulate, "prefetch"):  # the replays before the effects, side by side
        simulate.prefetch([(base_config, state) for state in loaded_states(all_specs[:-1], arm.model, run_processing)])
    baseline_run = as_run(baseline, rate_hz=rate) if baseline is not None else None
    train_runs = [as_run(m, baseline_run) for m in measured_list]
    train_runs += [as_run(s) for s in (train or []) if not (isinstance(s, (str, Path)) and str(s) in map(str, measured_list))]
    holdout_runs = [_held_out(as_run(s, baseline_run), baseline_run) for s in (holdout or [])]
    if baseline_run is not None and any(r.role is RunRole.OTHER_MOTION for r in train_runs):  # the baseline is fitted with them
        train_runs.append(DiagnosisRun(baseline_run.name, baseline_run.state, baseline_run.simulated, role=RunRole.BASELINE))
    repeat_run = as_run(repeat, baseline_run, rate) if repeat is not None else None
    offset_joints, offset_source = (session_offset_joints(arm.model, repeat_run, baseline_run or train_runs[0]) if nuisance
                                    else (None, None))
    # a baseline of the runs' own motion only: whatever differs may be any effect; runs of
    # other motions fitted with the baseline need the shared errors apart from the change
    every_effect_a_change = baseline_run is not None and not any(r.role is RunRole.OTHER_MOTION for r in train_runs)
    if every_effect_a_change:
        effects, at_index = _without_kind(effects, at_index, LinkMassScale.kind)
    elif baseline_run is not None and any(isinstance(e, EffortScale) and e.candidate for e in effects):
        other = next(r.name for r in train_runs if r.role is RunRole.OTHER_MOTION)
        raise DvrkDartError(f"--effort-scale: with --baseline only runs of the baseline's motion (a change of scale is read against "
                            f"the baseline's measured efforts); {other} is another motion: diagnose it with a baseline of its own")
    elif baseline_run is not None:  # nor weighed: its column would be the baseline's gap
        effects, at_index = _without_kind(effects, at_index, EffortScale.kind)
    effects = [_on_training_range(e, train_runs) for e in effects]
    effects, at_index = _on_recorded_joints(effects, at_index, [*train_runs, *holdout_runs, baseline_run, repeat_run])
    effects = _one_body_on_these_runs(arm, effects, [*train_runs, *holdout_runs, baseline_run, repeat_run])
    if nuisance:
        effects, at_index = _without_nuisance_constants(effects, at_index, offset_joints, train_runs)
    problem = Problem(arm, effects, Design(effects, every_effect_a_change), run_processing, inputs, train_runs, holdout_runs, baseline_run, repeat_run,
                      len(measured_list), at_index, nuisance, offset_joints, offset_source, folds, repeat_source)
    _add_grams(problem)
    return problem


def _add_grams(problem: Problem) -> None:
    """Columns and Gram blocks of every run; the training runs weighted to one residual level."""
    problem.train_columns = [problem.columns_of(r) for r in problem.train_runs]
    problem.holdout_columns = [problem.columns_of(r) for r in problem.holdout_runs]
    parts = [problem.grams_of(r, Phi, problem.folds) for r, Phi in zip(problem.train_runs, problem.train_columns)]
    problem.holdout_grams = [problem.grams_of(r, Phi, 1) for r, Phi in zip(problem.holdout_runs, problem.holdout_columns)]
    # without the nuisance constants, as the fit: a session's constant on q2 lowered q2's weight and changed the selection
    problem.joint_weights = _joint_weights(np.vstack([problem.before_residual(r) for r in problem.train_runs])) * problem.recorded
    for part, weight in zip(parts, _run_weights(parts)):
        part.scale_in_place(weight)
    problem.train_grams = Grams.concat(parts)

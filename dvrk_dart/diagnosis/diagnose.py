"""diagnose(): the sim-to-real gap diagnosis of measured runs (see `selection` for the method), and its outputs."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from dvrk_dart.diagnosis.design import (
    BLOCK_DURATION_S,
    WITHHELD_KINDS,
    Design,
    Grams,
    per_joint_fraction,
    sse,
    weighted_fraction,
)
from dvrk_dart.diagnosis.effect import Effect
from dvrk_dart.diagnosis.features import TrajectoryFeatures
from dvrk_dart.diagnosis.first_moment import (
    FirstMomentPayload,
    PayloadAtPosition,
    check_mass_determinable,
    parse_payload_at,
)
from dvrk_dart.diagnosis.identifiable import first_moment_report
from dvrk_dart.diagnosis.library import (
    candidate_effects,
    effects_to_sim_config,
    not_simulated,
    unsimulated_effort,
)
from dvrk_dart.diagnosis.payload import PointPayload
from dvrk_dart.diagnosis.payload_report import (
    choose_within_families,
    describe_payload,
    mass_profile,
)
from dvrk_dart.diagnosis.page import PERIOD_FIGURE
from dvrk_dart.diagnosis.periodic_payload_report import periodic_payload_report
from dvrk_dart.diagnosis.regimes import plot_period, plot_residuals, residual_regimes
from dvrk_dart.diagnosis.runs import (
    DiagnosisRun,
    RunProcessing,
    RunRole,
    Simulate,
    choose_processing,
    loaded_states,
    prepare_run,
)
from dvrk_dart.diagnosis.selection import (
    BOOTSTRAP_RESAMPLES,
    CV_FOLDS,
    GAIN_FAILURE_QUANTILE,
    MIN_HELDOUT_GAIN,
    Selector,
)
from dvrk_dart.diagnosis.session_floor import (
    gap_split,
    session_floor,
    session_offset_joints,
)
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.reference_data import distinct_inputs
from dvrk_dart.metrics import rms
from dvrk_dart.model.arm import Arm, load_arm
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS, effort_unit
from dvrk_dart.sim.config import SimConfig

#: safety bound of the greedy selection
MAX_SELECTED_EFFECTS = 25
#: joint weights are 1 / max(residual RMS, this): a joint whose residual is
#: below the effort resolution (N·m or N) must not dominate the fit
EFFORT_WEIGHT_FLOOR = 1e-3


def _gaps(residuals: list[np.ndarray]) -> list[float] | None:
    if not residuals:
        return None
    return rms(np.vstack(residuals)).tolist()


def _weights(residual: np.ndarray) -> np.ndarray:
    sigma = np.maximum(rms(residual), EFFORT_WEIGHT_FLOOR)
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



def diagnose(
    measured,
    baseline=None,
    train: Sequence | None = None,
    holdout: Sequence | None = None,
    simulate: Simulate | None = None,
    out_dir: Path | str | None = None,
    *,
    arm: Arm | None = None,
    base_config: SimConfig = SimConfig(),
    effects: Sequence[Effect] | None = None,
    max_effects: int = MAX_SELECTED_EFFECTS,
    folds: int = CV_FOLDS,
    figures: bool = True,
    profile_payload_mass: bool = True,
    repeat=None,
    payload_at: str | tuple[int, np.ndarray] | None = None,
    nuisance_offsets: bool | None = None,
    payload_model: str | None = None,
    processing: str | None = "upstream",
) -> dict:
    """Diagnose the gap of `measured` (a run name such as 'two', a path, a
    ProcessedRun or a DiagnosisRun carrying its simulated efforts), or of
    several runs at once (a list: one set of physical effects for all, each
    with the same baseline).

    baseline: the same trajectory without the effect under study (its gap is
        subtracted sample by sample from a run of the same motion; a run of
        another motion, e.g. another speed, is fitted together with the
        baseline run, which then carries the shared effects only);
    repeat: the same motion recorded in another session: the session-to-
        session floor per joint and each joint's gap split (`session_floor`);
    payload_at: 'LINK:x,y,z' or (link key, position in its frame): a selected
        payload's mass at that (hand-measured) position, with its interval;
    nuisance_offsets: a constant per run fitted as a nuisance term and
        reported (default: with a baseline or several runs), on the joints
        whose constant effort moves between sessions: measured on `repeat`
        when given, else the model card's ([sessions]); a constant the same in
        every session is an effect (`JointOffset`);
    payload_model: "first_moment" (default with a baseline: the identifiable
        quantity) or "point" (`library.candidate_effects`);
    processing: "upstream", "periodic" (every run on the excitation's
        harmonics, one cutoff for all; simulated efforts and effect columns
        projected likewise), or None: periodic where every run is periodic;
    train: further runs to fit on (each a run spec or a (run, baseline) pair);
        `measured` is always a training run;
    holdout: runs never used for fitting nor selection, only scored;
    simulate: simulate(config, run) -> efforts, the DART replay; without it the
        identified model at the measured state stands in for the simulation and
        the gap after is computed with the effects' regressors;
    out_dir: where diagnosis.json, the regime tables and the figures go.
    Returns the diagnosis dict (the contract of diagnosis.json)."""
    arm = arm or load_arm()
    measured_list = list(measured) if isinstance(measured, (list, tuple)) else [measured]
    several = baseline is not None or len(measured_list) > 1
    nuisance = several if nuisance_offsets is None else bool(nuisance_offsets)
    payload_model = payload_model or ("first_moment" if baseline is not None else "point")
    effects = list(effects) if effects is not None else candidate_effects(arm, payload_model=payload_model, base=base_config)
    at_index = None
    if payload_at is not None:
        key, position = parse_payload_at(payload_at, arm.model) if isinstance(payload_at, str) else payload_at
        check_mass_determinable(arm, key, position, str(payload_at))
        effects.append(PayloadAtPosition(arm.model, key, position))
        at_index = len(effects) - 1

    all_specs = [baseline, *measured_list, *(train or []), *(holdout or []), repeat]
    inputs = distinct_inputs(_roles(measured_list, baseline, train, holdout, repeat))
    if processing is None and baseline is not None:
        run_processing = RunProcessing(why="upstream: a payload diagnosis (with a baseline) keeps the upstream processing, "
                                           "on which its payload checks were made")
    else:
        run_processing = choose_processing(all_specs, processing)

    def as_run(spec, baseline=None):
        if isinstance(spec, tuple):
            spec, baseline = spec
        return prepare_run(spec, arm, simulate, base_config, baseline=baseline, processing=run_processing)

    if hasattr(simulate, "prefetch"):  # the replays before the effects, side by side
        simulate.prefetch([(base_config, state) for state in loaded_states(all_specs[:-1], run_processing)])
    baseline_run = as_run(baseline) if baseline is not None else None
    train_runs = [as_run(m, baseline_run) for m in measured_list]
    train_runs += [as_run(s) for s in (train or []) if not (isinstance(s, (str, Path)) and str(s) in map(str, measured_list))]
    holdout_runs = [as_run(s) for s in (holdout or [])]
    if baseline_run is not None and any(r.role is RunRole.OTHER_MOTION for r in train_runs):  # the baseline is fitted with them
        train_runs.append(DiagnosisRun(baseline_run.name, baseline_run.state, baseline_run.simulated, role=RunRole.BASELINE))

    design = Design(effects)

    def features_of(run: DiagnosisRun) -> TrajectoryFeatures:
        return run.features(arm)

    # A run of another motion than its baseline has no J1 reference: its raw J1
    # gap is dominated by motion-dependent errors (0.36 N·m RMS on the half-speed
    # 105 g run, the weight's J1 effort 0.1), which a payload's free J1 path
    # would absorb; J1's payload is read from the runs minus their baseline.
    yaw_path_from_differences = any(r.role is RunRole.DIFFERENCE for r in train_runs)

    def columns_of(run: DiagnosisRun) -> np.ndarray:
        """The effects' columns in the band of the run's efforts."""
        baseline_features = features_of(run.baseline) if run.role is RunRole.DIFFERENCE else None
        return run.state.in_band(design.run_columns(run.role, features_of(run), baseline_features,
                                                    yaw_path=not (yaw_path_from_differences and run.role is RunRole.OTHER_MOTION)))

    repeat_run = as_run(repeat, baseline_run) if repeat is not None else None
    reference_run = baseline_run or train_runs[0]
    offset_joints, offset_joints_source = session_offset_joints(arm.model, repeat_run, reference_run) if nuisance else (None, None)

    train_features = [features_of(r) for r in train_runs]
    holdout_features = [features_of(r) for r in holdout_runs]
    train_columns = [columns_of(r) for r in train_runs]
    holdout_columns = [columns_of(r) for r in holdout_runs]

    def demean_of(run: DiagnosisRun) -> np.ndarray | None:
        """The joints with a nuisance constant: a run minus its baseline (same
        motion) changes its constant with the session only; a run of another
        motion keeps one on every joint (the mean of its motion-dependent
        errors, e.g. friction's asymmetry, is its own)."""
        if not nuisance:
            return None
        return offset_joints if run.role is RunRole.DIFFERENCE else np.ones(N_JOINTS, dtype=bool)

    train_parts = [Grams.of_run(design, f, r.residual, folds, demean_of(r), Phi) for f, r, Phi in zip(train_features, train_runs, train_columns)]
    holdout_grams = [Grams.of_run(design, f, r.residual, 1, demean_of(r), Phi) for f, r, Phi in zip(holdout_features, holdout_runs, holdout_columns)]
    train_residuals = [r.residual for r in train_runs]
    w2 = _weights(np.vstack(train_residuals))
    run_weights = _run_weights(train_parts)
    train_grams = Grams.concat([part.scaled(weight) for part, weight in zip(train_parts, run_weights)])

    selector = Selector(design, train_grams, w2, folds)
    selected, steps, individual, selected_cv = selector.greedy(max_effects)
    selected, final, selected_cv = choose_within_families(selector, selected, selected_cv)

    def train_fraction(beta):
        return weighted_fraction(sse(beta, train_grams.A.sum(0), train_grams.g.sum(0), train_grams.s.sum(0)), train_grams.s.sum(0), w2)

    def holdout_sse(beta):
        return [sse(beta, h.A.sum(0), h.g.sum(0), h.s.sum(0)) for h in holdout_grams]

    def holdout_fraction(beta):
        if not holdout_grams:
            return None
        return weighted_fraction(np.sum(holdout_sse(beta), axis=0), np.sum([h.s.sum(0) for h in holdout_grams], axis=0), w2)

    # every candidate alone, fitted on all training data, for its parameters and scores
    entries = []
    rank_order = selected + sorted((i for i in individual if i not in selected), key=lambda i: -individual[i].fraction)
    if baseline is not None:  # the finding is what the runs have and their baseline has not; the rest are errors common to both
        rank_order = sorted(rank_order, key=lambda i: i not in selected or effects[i].kind not in WITHHELD_KINDS)
    for rank, i in enumerate(rank_order, start=1):
        e = effects[i]
        alone = selector.fit_all([i])
        p = final.params[i] if i in selected else alone.params[i]
        cv = individual[i]
        hold = holdout_fraction(alone.beta)
        entry = {
            "rank": rank,
            "name": e.name,
            "kind": e.kind,
            "family": e.family,
            "joints": list(e.joints),
            "parameters": e.describe(p),
            "units": e.units(),
            "size": e.size(p),
            "explained_fraction": {
                "train": train_fraction(alone.beta),
                "holdout": hold if hold is not None else cv.fraction,
                "holdout_source": "runs" if hold is not None else "time_segments",
                "cross_validated": cv.fraction,
                "cross_validated_interval": selector.interval(cv.after),
            },
            "explained_fraction_per_joint": {"cross_validated": per_joint_fraction(cv.after, train_grams.s)},
            "selected": i in selected,
            "role": "finding" if baseline is None or e.kind in WITHHELD_KINDS else "common_model_error",
            "selection_step": selected.index(i) + 1 if i in selected else None,
            "in_simulation": e.sim_contribution(np.asarray(p)) is not None,
            "fully_in_simulation": e.fully_simulated(np.asarray(p)),
        }
        entries.append(entry)

    chosen = [(effects[i], final.params[i]) for i in selected]
    sim_config = effects_to_sim_config(chosen, base_config)
    extra_by_regressor = not_simulated(chosen)

    shared = [(e, p) for e, p in chosen if e.kind not in WITHHELD_KINDS]
    shared_config, shared_extra = effects_to_sim_config(shared, base_config), not_simulated(shared)

    def simulated_after(run: DiagnosisRun, with_withheld: bool = True) -> np.ndarray:
        """(tau - the simulation with the effects) of a run, as its role asks."""
        config, extra = (sim_config, extra_by_regressor) if with_withheld else (shared_config, shared_extra)
        simulated = np.asarray(simulate(config, run.state), dtype=float) + unsimulated_effort(extra, features_of(run))
        return run.state.tau - run.state.in_band(simulated)

    def after_residual(run: DiagnosisRun, columns: np.ndarray) -> np.ndarray:
        if simulate is None:
            after = run.residual - columns @ final.beta
        elif run.role is RunRole.DIFFERENCE:
            after = simulated_after(run) - simulated_after(run.baseline, with_withheld=False)
        else:
            after = simulated_after(run, with_withheld=run.role is not RunRole.BASELINE)
        return after - demean_of(run) * after.mean(axis=0) if nuisance else after

    if hasattr(simulate, "prefetch"):  # the replays after the effects, side by side
        simulate.prefetch([pair for r in train_runs + holdout_runs for pair in _after_replays(r, sim_config, shared_config)])
    train_after = [after_residual(r, c) for r, c in zip(train_runs, train_columns)]
    holdout_after = [after_residual(r, c) for r, c in zip(holdout_runs, holdout_columns)]
    nuisance_report = None
    if nuisance:  # the run's own constants: its share of the mean of what the effects leave
        nuisance_report = {r.name: dict(zip(JOINT_NAMES, (demean_of(r) * (r.residual.mean(0) - (c @ final.beta).mean(0))).tolist()))
                           for r, c in zip(train_runs + holdout_runs, train_columns + holdout_columns)}
    del train_columns, holdout_columns
    floor, session_fit = None, None
    if repeat_run is not None:  # two runs without the effect under study, of two sessions
        floor = session_floor(reference_run, repeat_run)
        if repeat_run.role is RunRole.DIFFERENCE:  # what the effects read from a session change alone
            session = Grams.of_run(design, features_of(repeat_run), repeat_run.residual, 1, demean_of(repeat_run), columns_of(repeat_run))
            A, g = np.einsum("bjpq,j->pq", session.A, w2), np.einsum("bjp,j->p", session.g, w2)

            def session_fit(chosen: list[int]) -> dict[int, np.ndarray]:
                return selector.fitter.fit(chosen, A, g, None, float((session.s @ w2).sum())).params
    split_source = (holdout_runs, holdout_after) if holdout_runs else (train_runs, train_after)
    split = gap_split(np.asarray(_gaps([r.residual for r in split_source[0]])), np.asarray(_gaps(split_source[1])), floor)
    if simulate is None:
        source = "regressor"
    else:
        source = "simulation" if not extra_by_regressor else "simulation+regressor"

    payloads = [
        (effects[i], final.params[i], arm, mass_profile(selector, selected, i) if profile_payload_mass else None)
        for i in selected
        if isinstance(effects[i], PointPayload)
    ]
    if run_processing.name == "periodic" and baseline is not None:  # on the harmonics of the runs minus their baseline
        first_moments = [periodic_payload_report(arm, [e for e in effects if isinstance(e, FirstMomentPayload)], train_runs, repeat_run,
                                                 features_of, offset_joints if offset_joints is not None else np.zeros(N_JOINTS, bool),
                                                 effects[at_index] if at_index is not None else None)]
    else:
        first_moments = [first_moment_report(arm, selector, selected, i, final.params, selected_cv.fold_params, at_index, session_fit)
                         for i in selected if isinstance(effects[i], FirstMomentPayload)]
        for report in first_moments:
            report["words"].append(_j1_constant_sentence(offset_joints, offset_joints_source))
    payload_candidates = sorted(
        (
            {
                "cross_validated_fraction": individual[i].fraction,
                **describe_payload(effects[i], selector.fit_all([i]).params[i], arm),
            }
            for i in range(len(effects))
            if isinstance(effects[i], PointPayload)
        ),
        key=lambda c: -c["cross_validated_fraction"],
    ) + sorted(
        ({"cross_validated_fraction": individual[i].fraction, **effects[i].describe(selector.fit_all([i]).params[i])}
         for i in individual if isinstance(effects[i], FirstMomentPayload)),
        key=lambda c: -c["cross_validated_fraction"],
    )
    result = {
        "joints": list(JOINT_NAMES),
        "units": [effort_unit(j) for j in JOINT_NAMES],
        "measured": train_runs[0].name,
        "measured_runs": [r.name for r in train_runs[: len(measured_list)]],
        "baseline_source": {r.name: r.baseline_source for r in train_runs if r.baseline_source is not None},
        "nuisance_offsets": nuisance_report,
        "nuisance_offset_joints": None if offset_joints is None else {
            "joints": [j for j, on in zip(JOINT_NAMES, offset_joints) if on], "source": offset_joints_source},
        "session_floor": floor.tolist() if floor is not None else None,
        "repeat": repeat_run.name if repeat_run is not None else None,
        "gap_split": {"runs": "holdout" if holdout_runs else "train", "joints": split},
        "baseline": train_runs[0].baseline.name if train_runs[0].baseline is not None else None,
        "train_runs": [r.name for r in train_runs],
        "holdout_runs": [r.name for r in holdout_runs],
        "inputs": inputs,
        "processing": {**run_processing.summary(), "runs": {r.name: r.state.summary() for r in train_runs + holdout_runs}},
        "residual_definition": "measured - simulated" + (" - (baseline measured - baseline simulated)" if baseline is not None else "")
        + (" - a constant per run on the joints whose constant moves between sessions (nuisance)" if nuisance else ""),
        "simulated_source": "simulation" if simulate is not None else "identified model at the measured state (stand-in for the DART replay)",
        "gap_before": {"train": _gaps(train_residuals), "holdout": _gaps([r.residual for r in holdout_runs])},
        "gap_after": {"train": _gaps(train_after), "holdout": _gaps(holdout_after)},
        "gap_after_source": source,
        "explained_fraction": {
            "train": train_fraction(final.beta),
            "holdout": holdout_fraction(final.beta),
            "cross_validated": selected_cv.fraction,
            "cross_validated_interval": selector.interval(selected_cv.after),
        },
        "effects": entries,
        "selection": {
            "method": (
                f"greedy forward selection on {len(selector.folds)}-fold contiguous time-segment cross-validation of the training runs, "
                f"weighted least squares (joint weight 1/RMS before), bounded to physical ranges; stop when the held-out gain < "
                f"{MIN_HELDOUT_GAIN} or not positive with probability {1 - GAIN_FAILURE_QUANTILE:.2f} (block bootstrap, "
                f"{BLOCK_DURATION_S} s blocks, {BOOTSTRAP_RESAMPLES} resamples); a payload's link among its equivalent links "
                f"(identical efforts) by the penalised training cost"
            ),
            "steps": steps,
            "selected": [effects[i].name for i in selected],
        },
        "payload": first_moments[0] if first_moments else (describe_payload(*payloads[0]) if payloads else None),
        "payloads": first_moments + [describe_payload(*pl) for pl in payloads],
        "payload_candidates": payload_candidates,
        "sim_config": sim_config.to_dict(),
        "not_in_simulation": [e.name for e, _ in extra_by_regressor],
    }
    if out_dir is not None:
        period = (split_source[0][0], split_source[1][0], floor)  # the run the answer speaks of
        _write_outputs(Path(out_dir), result, train_runs[0], train_after[0], figures, period)
    return result


def _roles(measured_list, baseline, train, holdout, repeat) -> list[tuple[str, str]]:
    """(option, run) of every run given by name or path (a run given as data has no file)."""
    roles = [("--measured", m) for m in measured_list] + [("--baseline", baseline), ("--repeat", repeat)]
    for option, specs in (("--train", train or []), ("--holdout", holdout or [])):
        # a (run, baseline) pair: its baseline may serve several runs
        roles += [(option, spec[0] if isinstance(spec, tuple) else spec) for spec in specs]
    measured = {str(m) for m in measured_list}
    return [(option, s) for option, s in roles if isinstance(s, (str, Path))
            and not (option == "--train" and str(s) in measured)]  # --train may repeat the measured run (it always trains)


def _j1_constant_sentence(offset_joints: np.ndarray | None, source: str | None) -> str:
    """What determines the payload's J1 effort at q = 0: the constant change of
    J1's effort, unless each run's offset takes it."""
    if offset_joints is not None and offset_joints[0]:
        return (f"J1's value at q = 0 is barely determined: sessions move J1's constant ({source}), so each run's offset takes it, "
                "and over the runs' yaw range cos q1 hardly differs from one.")
    return (f"J1's value at q = 0 is read from the constant change of J1's effort, which sessions do not move ({source}; runs get no "
            "J1 offset); it includes the mean of the payload's own centripetal efforts, which the first moment does not model "
            "(proportional to the mass, like the gravity effort).")


def _after_replays(run: DiagnosisRun, sim_config: SimConfig, shared_config: SimConfig) -> list[tuple[SimConfig, object]]:
    """The (config, state) replays `simulated_after` asks for a run: a baseline
    run gets only the effects all runs share (no withheld payload)."""
    if run.role is RunRole.DIFFERENCE:
        return [(sim_config, run.state), (shared_config, run.baseline.state)]
    return [(shared_config if run.role is RunRole.BASELINE else sim_config, run.state)]


def _write_outputs(out_dir: Path, result: dict, run: DiagnosisRun, after: np.ndarray, figures: bool, period: tuple) -> None:
    from dvrk_dart.io.atomic import write_text_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    before_table = residual_regimes(run.state, run.residual).assign(stage="before")
    after_table = residual_regimes(run.state, after).assign(stage="after")
    table = pd.concat([before_table, after_table], ignore_index=True)
    write_text_atomic(out_dir / "where.csv", table.to_csv(index=False))
    result["where"] = {"table": "where.csv", "run": run.name, "figures": []}
    if figures:
        paths = plot_residuals(run.state, run.residual, out_dir / "figures", "residual_before")
        paths += plot_residuals(run.state, after, out_dir / "figures", "residual_after")
        period_run, period_after, floor = period
        paths.append(plot_period(period_run.state, period_run.residual, period_after, floor, out_dir / "figures" / f"{PERIOD_FIGURE}.png"))
        result["where"]["figures"] = [str(p.relative_to(out_dir)) for p in paths]
    write_json_atomic(out_dir / "diagnosis.json", result)

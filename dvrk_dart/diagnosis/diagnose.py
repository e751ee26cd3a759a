"""diagnose(): the sim-to-real gap diagnosis of measured runs, in stages a
reader can follow: the problem (`problem`: runs by role, design, weights,
nuisance mask), the selection of effects (`selection`, `result.select`), the
re-simulation with them (`result.resimulate`), the payload reports, and the
frozen result (`result.Diagnosis`, whose `to_json()` is diagnosis.json)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from dvrk_dart.diagnosis.fit.design import Grams
from dvrk_dart.diagnosis.effects.effect import Effect
from dvrk_dart.diagnosis.effects.first_moment import FirstMomentPayload
from dvrk_dart.diagnosis.payload.identifiable import first_moment_report, with_point_ties
from dvrk_dart.diagnosis.output.page import PERIOD_FIGURE
from dvrk_dart.diagnosis.effects.payload import PointPayload
from dvrk_dart.diagnosis.payload.payload_report import (
    describe_payload,
    effort_not_determined,
    flag_payload_at_link,
    PAYLOAD_AT_UNUSED,
    not_a_payload_because,
    mass_profile,
    without_unrecorded_joints,
)
from dvrk_dart.diagnosis.payload.periodic_payload_report import periodic_payload_report
from dvrk_dart.diagnosis.payload.yaw_path_inertia import span_both_path_models
from dvrk_dart.diagnosis.fit.identified_terms import identified_terms_share
from dvrk_dart.diagnosis.fit.problem import Problem, build_problem
from dvrk_dart.diagnosis.fit.scale_rival import effort_scale_rival
from dvrk_dart.diagnosis.output.regimes import plot_period, plot_residuals, residual_regimes
from dvrk_dart.diagnosis.fit.result import (
    Diagnosis,
    Resimulation,
    Selection,
    effect_entries,
    gaps,
    holdout_fraction,
    noise_gaps,
    resimulate,
    select,
    train_fraction,
    without_last_effect,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.diagnosis.fit.diagnosis_runs import DiagnosisRun, RunRole, Simulate
from dvrk_dart.diagnosis.fit.selection import CV_FOLDS
from dvrk_dart.diagnosis.fit.session_floor import card_repeat, constants_beyond_session, gap_split, session_floor
from dvrk_dart.diagnosis.output.gravity_mismatch import gravity_mismatch_of, offsets_left_out
from dvrk_dart.diagnosis.output.wording import explanation
from dvrk_dart.io.atomic import write_json_atomic, write_text_atomic
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.metrics import per_measured_joint
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.sim.config import SimConfig

#: safety bound of the greedy selection
MAX_SELECTED_EFFECTS = 25


def diagnose(
    measured,
    baseline=None,
    train: Sequence | None = None,
    holdout: Sequence | None = None,
    simulate: Simulate | None = None,
    out_dir: Path | str | None = None,
    *,
    arm: Arm,
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
    topics: BagTopics = BagTopics(),
    write_json: bool = True,
    effort_scale: bool = False,
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
        whose constant effort moves between sessions: those `repeat` shows
        moved, and the model card's ([sessions]) unless it rules their move
        out (`session_floor.session_offset_joints`); a constant the same in
        every session is an effect (`JointOffset`);
    payload_model: "first_moment" (default with a baseline: the identifiable
        quantity) or "point" (`library.candidate_effects`);
    processing: "upstream", "periodic" (every run on the excitation's
        harmonics, one cutoff for all; simulated efforts and effect columns
        projected likewise; with a baseline, the payload is read on the
        harmonics of the runs minus their baseline: `periodic_payload`), or
        None: periodic where every run is periodic;
    train: further runs to fit on (each a run spec or a (run, baseline) pair);
        `measured` is always a training run;
    holdout: runs never used for fitting nor selection, only scored;
    simulate: simulate(config, run) -> efforts, the DART replay; without it the
        identified model at the measured state stands in for the simulation and
        the gap after is computed with the effects' regressors;
    out_dir: where diagnosis.json, the regime tables and the figures go
        (write_json False: not diagnosis.json, which the caller writes with what it adds: api.run_diagnosis);
    arm: the arm the runs were recorded on (its model and identified parameters);
    topics: how runs that are bags are read (--arm, --topic, --jaw-topic) and CSVs' --rate;
    effort_scale: a scale of every measured effort among the candidates (else weighed against the selection: `scale_rival`).
    Returns the diagnosis dict (the contract of diagnosis.json)."""
    measured_list = list(measured) if isinstance(measured, (list, tuple)) else [measured]
    several = baseline is not None or len(measured_list) > 1
    repeat_source = "--repeat" if repeat is not None else "none: no --repeat and no --baseline"
    if repeat is None and baseline is not None:
        repeat, repeat_source = card_repeat(arm.model, baseline, [*measured_list, *(train or []), *(holdout or [])])
    problem = build_problem(arm, measured_list, baseline, train, holdout, repeat, simulate=simulate, base_config=base_config,
                            effects=effects, payload_model=payload_model or ("first_moment" if baseline is not None else "point"),
                            payload_at=payload_at, nuisance=several if nuisance_offsets is None else bool(nuisance_offsets),
                            processing=processing, folds=folds, topics=topics, repeat_source=repeat_source, effort_scale=effort_scale)
    selection, after, dropped = _resimulated(problem, select(problem, max_effects), simulate, base_config)
    entries = effect_entries(problem, selection)
    nuisance_joints = problem.offset_joints if problem.nuisance else None  # the floor without the constants the fit takes out
    floor = session_floor(problem.reference_run, problem.repeat_run, nuisance_joints) if problem.repeat_run is not None else None
    split_source = (problem.holdout_runs, after.holdout_after) if problem.holdout_runs else (problem.train_runs, after.train_after)
    split_floor, split = _gap_split(problem, split_source, floor)
    first_moments, points = _payload_reports(problem, selection, profile_payload_mass)
    _finish_payload_reports(problem, first_moments, points)
    carried = identified_terms_share(problem, selection, base_config)
    result = _diagnosis(problem, selection, after, entries, (floor, split_floor), split, first_moments, points, simulate is not None, dropped,
                        carried).to_json()
    result["effort_scale_rival"] = effort_scale_rival(problem, selection)
    # runs minus their baseline, else runs of their own (against the identified offsets the simulation leaves out)
    differences = [r for r in problem.train_runs if r.role is RunRole.DIFFERENCE]
    own = [r for r in problem.train_runs if r.role is RunRole.RAW] if not problem.has_baseline else []
    result["constants_beyond_session"] = constants_beyond_session(result["nuisance_offsets"], differences or own, problem.repeat_run,
                                                                  problem.reference_run, problem.arm.model, result["units"],
                                                                  offsets_left_out(problem.arm, carried, problem.recorded))
    if out_dir is None:
        return result
    # the run the answer speaks of; before and after both without the nuisance constants the fit takes out
    period = (split_source[0][0], problem.before_residual(split_source[0][0]), split_source[1][0], split_floor)
    where_run = problem.train_runs[0]
    result = {**result, "where": _write_outputs(Path(out_dir), where_run, problem.before_residual(where_run), after.train_after[0], figures,
                                                period, arm.model, problem.recorded)}
    if write_json:
        write_json_atomic(Path(out_dir) / "diagnosis.json", result)
    return result


def _gap_split(problem: Problem, split_source: tuple, floor: np.ndarray | None) -> tuple[np.ndarray | None, list[dict]]:
    """The floor of the gaps the answer speaks of, and each recorded joint's gap split against it. A run minus its
    baseline carries two sessions' deviations: its floor is sqrt(2) times one session's (a point mass exactly injected
    read "over 1.5x the session floor: an unmodelled effect remains" at 1.8x one session's)."""
    runs, after = split_source
    split_floor = None if floor is None else floor * (math.sqrt(2.0) if all(r.role is RunRole.DIFFERENCE for r in runs) else 1.0)
    split = gap_split(np.asarray(gaps([problem.before_residual(r) for r in runs])), np.asarray(gaps(after)), split_floor, problem.arm.model)
    return split_floor, [row for row, recorded in zip(split, problem.recorded) if recorded]  # no row for a joint not recorded


def _finish_payload_reports(problem: Problem, first_moments: list[dict], points: list[dict]) -> None:
    """No figure on a joint the runs did not record; a hand position on a link the efforts do not choose flagged;
    where the session change was read without --repeat, said."""
    for report in [*first_moments, *points]:
        without_unrecorded_joints(report, problem.recorded)
    if problem.at_index is not None:
        at = problem.effects[problem.at_index]
        same = next((e.equivalent_links for e in problem.effects if isinstance(e, FirstMomentPayload) and e.link_key == at.link_key), ())
        for report in first_moments:
            flag_payload_at_link(report, at.link_name, same)
    for report in first_moments:
        if problem.repeat_run is not None and problem.repeat_source != "--repeat":
            report["words"].append(f"Without --repeat, the session change is read on {problem.repeat_run.name}, from {problem.repeat_source}.")


def _resimulated(problem: Problem, selection: Selection, simulate: Simulate | None, base_config: SimConfig):
    """The selection re-simulated: a selected effect whose re-simulation fails or
    drifts is dropped with the reason (the last first) and the diagnosis goes on.
    Returns (selection kept, its re-simulation, [{effect, reason}])."""
    dropped = []
    while True:
        try:
            return selection, resimulate(problem, selection, simulate, base_config), dropped
        except DvrkDartError as exc:
            if not selection.selected:
                raise
            dropped.append({"effect": problem.effects[selection.selected[-1]].name, "reason": str(exc)})
            selection = without_last_effect(selection)


# ------------------------------------------------------------------- payloads
def _session_fit(problem: Problem, selection: Selection):
    """fit(chosen effects, reverse) on the --repeat pair (two sessions without the
    weight; `reverse`: the first session minus the second): what the effects
    read from a session change alone; None without it."""
    repeat = problem.repeat_run
    if repeat is None or repeat.role is not RunRole.DIFFERENCE:
        return None
    session = Grams.of_run(problem.design, problem.features_of(repeat), repeat.residual, 1, problem.demean_of(repeat),
                           problem.columns_of(repeat))
    w2 = problem.joint_weights
    A, g = np.einsum("bjpq,j->pq", session.A, w2), np.einsum("bjp,j->p", session.g, w2)

    def fit(chosen: list[int], reverse: bool = False) -> dict[int, np.ndarray]:
        return selection.selector.fitter.fit(chosen, A, -g if reverse else g, None, float((session.s @ w2).sum())).params

    return fit


def _payload_reports(problem: Problem, s: Selection, profile_payload_mass: bool) -> tuple[list[dict], list[dict]]:
    """The selected first-moment payloads' reports (on the harmonics of the runs
    minus their baseline with periodic processing) and the point payloads'."""
    effects = problem.effects
    points = [with_point_ties(describe_payload(effects[i], s.final.params[i], problem.arm, mass_profile(s.selector, s.selected, i)
                                               if profile_payload_mass else None), s.selector, s.selected, i)
              for i in s.selected if isinstance(effects[i], PointPayload)]
    selected_moments = [i for i in s.selected if isinstance(effects[i], FirstMomentPayload)]
    at = effects[problem.at_index] if problem.at_index is not None else None
    at_key = at.link_key if at is not None else None
    if problem.processing.name == "periodic" and problem.has_baseline:
        offsets = problem.offset_joints if problem.offset_joints is not None else np.zeros(N_JOINTS, bool)
        candidates = [e for e in effects if isinstance(e, FirstMomentPayload)]
        reports = [periodic_payload_report(problem.arm, candidates, problem.train_runs, problem.repeat_run, problem.features_of, offsets, at,
                                           effects[i]) for i in selected_moments[:1]]
        span_both_path_models(problem, s.final.params, reports, at_key, periodic=True)
        return reports, points
    session_fit = _session_fit(problem, s)
    # J1's constant is read from a run minus its baseline of the same motion; without one, from runs of another motion
    other_motion = not any(r.role is RunRole.DIFFERENCE for r in problem.train_runs)
    offsets = problem.offset_joints if problem.offset_joints is not None else np.zeros(N_JOINTS, bool)
    undetermined = {**{int(j): OFFSET_TAKES_CONSTANT for j in np.flatnonzero(offsets[:3])}, **({0: J1_OTHER_MOTION} if other_motion else {})}
    reports = [first_moment_report(problem.arm, s.selector, s.selected, i, s.final.params, s.cross_validated.fold_params, problem.at_index,
                                   session_fit, undetermined) for i in selected_moments]
    for report in reports:
        if not other_motion:
            report["words"].append(_j1_constant_sentence(problem.offset_joints, problem.offset_joints_source))
        elif report.get("payload_at"):
            effort_not_determined(report["payload_at"], 0, J1_OTHER_MOTION)
    span_both_path_models(problem, s.final.params, reports, at_key, periodic=False, payloads=selected_moments)
    return reports, points


def _payload_candidates(problem: Problem, s: Selection) -> list[dict]:
    """Every payload candidate fitted alone, by cross-validated fraction."""
    effects = problem.effects
    points = ({"cross_validated_fraction": s.individual[i].fraction, **describe_payload(effects[i], s.selector.fit_all([i]).params[i], problem.arm)}
              for i in range(len(effects)) if isinstance(effects[i], PointPayload))
    moments = ({"cross_validated_fraction": s.individual[i].fraction, **effects[i].describe(s.selector.fit_all([i]).params[i])}
               for i in s.individual if isinstance(effects[i], FirstMomentPayload))
    def by_fraction(candidate: dict) -> float:
        return -candidate["cross_validated_fraction"]

    candidates = sorted(points, key=by_fraction) + sorted(moments, key=by_fraction)
    for candidate in candidates:
        without_unrecorded_joints(candidate, problem.recorded)
    return candidates


#: why J1's payload effort at q = 0 is not determined when a run of another motion is fitted with the baseline
J1_OTHER_MOTION = ("no run has the baseline's motion, and a run of another motion moves J1's constant effort by its own friction "
                   "and centripetal means, which cannot be told from the payload's J1 effort at q = 0")


#: why the first moment's gravity effort at q = 0 is not determined on a joint whose constant each run's offset takes
OFFSET_TAKES_CONSTANT = ("each run's offset takes the joint's constant effort (sessions move it), so the payload's effort there at q = 0 "
                         "rests on how the effort bends over the runs' range, which the fit's prior on the first moment decides as much "
                         "as the data; --payload-at ties it to the position's geometry")


def _j1_constant_sentence(offset_joints: np.ndarray | None, source: str | None) -> str:
    """What determines the payload's J1 effort at q = 0: the constant change of
    J1's effort, unless each run's offset takes it."""
    if offset_joints is not None and offset_joints[0]:
        return (f"J1's value at q = 0 is not determined: sessions move J1's constant ({source}), so each run's offset takes it, "
                "and over the runs' yaw range cos q1 hardly differs from one.")
    return (f"J1's value at q = 0 is read from the constant change of J1's effort, which sessions do not move ({source}; runs get no "
            "J1 offset); it includes the mean of the payload's own centripetal efforts, which the first moment does not model "
            "(proportional to the mass, like the gravity effort).")


# --------------------------------------------------------------------- result
def _nuisance_report(problem: Problem, s: Selection) -> dict | None:
    """Each run's own constants: its share of the mean of what the effects leave."""
    if not problem.nuisance:
        return None
    runs = problem.train_runs + problem.holdout_runs
    columns = problem.train_columns + problem.holdout_columns
    recorded = [j for j, on in zip(JOINT_NAMES, problem.recorded) if on]  # no offset on a joint the runs did not record
    return {r.name: {j: v for j, v in zip(JOINT_NAMES, (problem.demean_of(r) * (r.residual.mean(0) - (c @ s.final.beta).mean(0))).tolist())
                     if j in recorded} for r, c in zip(runs, columns)}


def _payload_findings(problem: Problem, fits: list[dict], carried: dict | None) -> tuple[list[dict], dict | None, dict | None]:
    """(the payloads named, the gravity mismatch, the payload-shaped fit that is no payload): a payload-shaped fit names a
    payload only where a baseline run without it isolates it, and not where it is what sessions change (a session change
    read as a payload: `not_a_payload_because`, with the model card's repeat pair's reading where no --repeat was given)."""
    if not fits:
        return [], None, None
    if not problem.has_baseline:
        return [], gravity_mismatch_of(fits[0], problem.arm.model, offsets_left_out(problem.arm, carried, problem.recorded)), None
    sessions_read = problem.arm.model.session_payload_reading if problem.repeat_run is None else None
    why = not_a_payload_because(fits[0], sessions_read)
    if why is None:
        return fits, None, None
    return [], None, {**fits[0], "meaning": f"the payload-shaped fit is not a payload: {why}", "why": why}


def _diagnosis(problem: Problem, s: Selection, after: Resimulation, entries: list[dict], floors, split, first_moments: list[dict],
               points: list[dict], simulated: bool, dropped: list[dict], carried: dict | None) -> Diagnosis:
    train_runs, holdout_runs = problem.train_runs, problem.holdout_runs
    offsets, recorded = problem.offset_joints, problem.recorded
    floor, split_floor = floors  # one session's deviation; the floor of the gaps split (runs minus a baseline: two sessions')
    payload_fits, mismatch, not_distinguished = _payload_findings(problem, first_moments + points, carried)
    gap_before = {split: gaps([problem.before_residual(r) for r in runs], recorded) for split, runs in (("train", train_runs), ("holdout", holdout_runs))}
    gap_after = {"train": gaps(after.train_after, recorded), "holdout": gaps(after.holdout_after, recorded)}
    return Diagnosis(
        joints=list(JOINT_NAMES),
        units=[problem.arm.model.effort_unit(j) for j in JOINT_NAMES],
        joint_words=problem.arm.model.joint_words,
        measured=train_runs[0].name,
        measured_runs=[r.name for r in train_runs[: problem.n_measured]],
        baseline_source={r.name: r.baseline_source for r in train_runs if r.baseline_source is not None},
        nuisance_offsets=_nuisance_report(problem, s),
        nuisance_offset_joints=None if offsets is None else {
            "joints": [j for j, on, seen in zip(JOINT_NAMES, offsets, recorded) if on and seen], "source": problem.offset_joints_source},
        session_floor=per_measured_joint(floor, recorded) if floor is not None else None,  # none on a joint not recorded
        repeat=problem.repeat_run.name if problem.repeat_run is not None else None,
        repeat_source=problem.repeat_source,
        gap_split={"runs": "holdout" if holdout_runs else "train", "joints": split},  # each row's session_floor: its gap's
        baseline=train_runs[0].baseline.name if train_runs[0].baseline is not None else None,
        train_runs=[r.name for r in train_runs],
        holdout_runs=[r.name for r in holdout_runs],
        inputs=problem.inputs,
        processing={**problem.processing.summary(), "runs": {r.name: r.state.summary() for r in train_runs + holdout_runs}},
        residual_definition="measured - simulated" + (" - (baseline measured - baseline simulated)" if problem.has_baseline else "")
        + (" - a constant per run on the joints whose constant moves between sessions (nuisance)" if problem.nuisance else ""),
        simulated_source="simulation" if simulated else "identified model at the measured state (stand-in for the DART replay)",
        gap_before=gap_before,
        gap_after=gap_after,
        gap_after_source=after.source,
        explained_fraction={
            "train": train_fraction(problem, s.final.beta),
            "holdout": holdout_fraction(problem, s.final.beta),
            "cross_validated": s.cross_validated.fraction,
            "cross_validated_interval": s.selector.interval(s.cross_validated.after),
        },
        effects=entries,
        selection={"method": s.method(), "steps": s.steps, "selected": [problem.effects[i].name for i in s.selected]},
        payload=payload_fits[0] if payload_fits else None, payloads=payload_fits,
        payload_candidates=_payload_candidates(problem, s),
        sim_config=after.sim_config.to_dict(),
        not_in_simulation=after.not_in_simulation,
        recorded_joints=[j for j, on in zip(JOINT_NAMES, recorded) if on],
        not_recorded_by=problem.not_recorded_by, unrecorded_joint_notes=problem.unrecorded_joint_notes(),
        effort_convention_notes=problem.effort_convention_notes(),
        gravity_mismatch=mismatch,
        payload_not_distinguished=not_distinguished,
        payload_at_unused=(PAYLOAD_AT_UNUSED if problem.at_index is not None and problem.has_baseline and not (payload_fits or not_distinguished)
                           else None),
        dropped_effects=dropped,
        explanation=explanation(gap_before, gap_after, list(JOINT_NAMES), [e for e in entries if e.get("selected")],
                                per_measured_joint(split_floor, recorded) if split_floor is not None else None,
                                noise_gaps(holdout_runs or train_runs, recorded, problem.arm)),
        identified_terms=carried,
    )


def _write_outputs(out_dir: Path, run: DiagnosisRun, before: np.ndarray, after: np.ndarray, figures: bool, period: tuple,
                   model: PsmModel, recorded: np.ndarray) -> dict:
    """where.csv and the figures of the residual (`before`, `after`: the run's gap before and after the effects);
    returns diagnosis.json's `where`."""
    out_dir.mkdir(parents=True, exist_ok=True)
    before_table = residual_regimes(run.state, before, model).assign(stage="before")
    after_table = residual_regimes(run.state, after, model).assign(stage="after")
    table = pd.concat([before_table, after_table], ignore_index=True)
    write_text_atomic(out_dir / "where.csv", table.to_csv(index=False))
    where = {"table": "where.csv", "run": run.name, "figures": []}
    if figures:
        paths = plot_residuals(run.state, before, out_dir / "figures", model, "residual_before", run.name)
        paths += plot_residuals(run.state, after, out_dir / "figures", model, "residual_after", run.name)
        period_run, period_before, period_after, floor = period
        paths.append(plot_period(period_run.state, period_before, period_after, floor, out_dir / "figures" / f"{PERIOD_FIGURE}.png", model,
                                 period_run.name, recorded))
        where["figures"] = [str(p.relative_to(out_dir)) for p in paths]
    return where

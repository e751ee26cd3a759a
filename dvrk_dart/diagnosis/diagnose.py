"""diagnose(): the sim-to-real gap diagnosis of measured runs (see `selection` for the method), and its outputs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from dvrk_dart.diagnosis.design import (
    BLOCK_DURATION_S,
    Design,
    Grams,
    per_joint_fraction,
    sse,
    weighted_fraction,
)
from dvrk_dart.diagnosis.effect import Effect
from dvrk_dart.diagnosis.features import TrajectoryFeatures
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
from dvrk_dart.diagnosis.regimes import plot_residuals, residual_regimes
from dvrk_dart.diagnosis.runs import DiagnosisRun, Simulate, prepare_run, run_features
from dvrk_dart.diagnosis.selection import (
    BOOTSTRAP_RESAMPLES,
    CV_FOLDS,
    GAIN_FAILURE_QUANTILE,
    MIN_HELDOUT_GAIN,
    Selector,
)
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.metrics import rms
from dvrk_dart.model.arm import Arm, load_arm
from dvrk_dart.model.joints import JOINT_NAMES, effort_unit
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
) -> dict:
    """Diagnose the gap of `measured` (a run name such as 'two', a path, a
    ProcessedRun or a DiagnosisRun carrying its simulated efforts).

    baseline: the same trajectory without the effect under study (its residual
        is subtracted, sample by sample);
    train: further runs to fit on (each a run spec or a (run, baseline) pair);
        `measured` is always a training run;
    holdout: runs never used for fitting nor selection, only scored;
    simulate: simulate(config, run) -> efforts, the DART replay; without it the
        identified model at the measured state stands in for the simulation and
        the gap after is computed with the effects' regressors;
    out_dir: where diagnosis.json, the regime tables and the figures go.
    Returns the diagnosis dict (the contract of diagnosis.json)."""
    arm = arm or load_arm()
    effects = list(effects) if effects is not None else candidate_effects(arm)

    def as_run(spec):
        if isinstance(spec, tuple):
            return prepare_run(spec[0], arm, simulate, base_config, baseline=spec[1])
        return prepare_run(spec, arm, simulate, base_config)

    train_runs = [prepare_run(measured, arm, simulate, base_config, baseline=baseline)]
    train_runs += [as_run(s) for s in (train or []) if not (isinstance(s, (str, Path)) and str(s) == str(measured))]
    holdout_runs = [as_run(s) for s in (holdout or [])]

    design = Design(effects)
    train_features = [run_features(arm, r) for r in train_runs]
    holdout_features = [run_features(arm, r) for r in holdout_runs]
    train_grams = Grams.concat([Grams.of_run(design, f, r.residual, folds) for f, r in zip(train_features, train_runs)])
    holdout_grams = [Grams.of_run(design, f, r.residual, 1) for f, r in zip(holdout_features, holdout_runs)]
    train_residuals = [r.residual for r in train_runs]
    w2 = _weights(np.vstack(train_residuals))

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
    rank_order = selected + sorted((i for i in range(len(effects)) if i not in selected), key=lambda i: -individual[i].fraction)
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
            "selection_step": selected.index(i) + 1 if i in selected else None,
            "in_simulation": e.sim_contribution(np.asarray(p)) is not None,
            "fully_in_simulation": e.fully_simulated(np.asarray(p)),
        }
        entries.append(entry)

    chosen = [(effects[i], final.params[i]) for i in selected]
    sim_config = effects_to_sim_config(chosen, base_config)
    extra_by_regressor = not_simulated(chosen)

    def after_residual(run: DiagnosisRun, features: TrajectoryFeatures) -> np.ndarray:
        if simulate is None:
            explained = sum((e.effort(features, p) for e, p in chosen), np.zeros_like(run.residual))
            return run.residual - explained
        sim_after = np.asarray(simulate(sim_config, run.state), dtype=float)
        sim_after = sim_after + unsimulated_effort(extra_by_regressor, features)
        after = run.state.tau - sim_after
        return after if run.baseline is None else after - run.baseline.gap

    train_after = [after_residual(r, f) for r, f in zip(train_runs, train_features)]
    holdout_after = [after_residual(r, f) for r, f in zip(holdout_runs, holdout_features)]
    if simulate is None:
        source = "regressor"
    else:
        source = "simulation" if not extra_by_regressor else "simulation+regressor"

    payloads = [
        (effects[i], final.params[i], arm, mass_profile(selector, selected, i) if profile_payload_mass else None)
        for i in selected
        if isinstance(effects[i], PointPayload)
    ]
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
    )
    result = {
        "joints": list(JOINT_NAMES),
        "units": [effort_unit(j) for j in JOINT_NAMES],
        "measured": train_runs[0].name,
        "baseline": train_runs[0].baseline.name if train_runs[0].baseline is not None else None,
        "train_runs": [r.name for r in train_runs],
        "holdout_runs": [r.name for r in holdout_runs],
        "residual_definition": "measured - simulated" + (" - (baseline measured - baseline simulated)" if baseline is not None else ""),
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
        "payload": describe_payload(*payloads[0]) if payloads else None,
        "payloads": [describe_payload(*pl) for pl in payloads],
        "payload_candidates": payload_candidates,
        "sim_config": sim_config.to_dict(),
        "not_in_simulation": [e.name for e, _ in extra_by_regressor],
    }
    if out_dir is not None:
        _write_outputs(Path(out_dir), result, train_runs[0], train_after[0], figures)
    return result


def _write_outputs(out_dir: Path, result: dict, run: DiagnosisRun, after: np.ndarray, figures: bool) -> None:
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
        result["where"]["figures"] = [str(p.relative_to(out_dir)) for p in paths]
    write_json_atomic(out_dir / "diagnosis.json", result)


# ----------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m dvrk_dart.diagnosis.diagnose", description=__doc__.splitlines()[0])
    parser.add_argument("--measured", required=True, help="run name ('one', 'two', 'one-105g' ...) or CSV path")
    parser.add_argument("--baseline", help="same trajectory without the effect under study")
    parser.add_argument("--train", nargs="*", default=[], help="further training runs")
    parser.add_argument("--holdout", nargs="*", default=[], help="held-out runs (scored only)")
    parser.add_argument("--out", required=True, help="output folder (diagnosis.json, where.csv, figures/)")
    parser.add_argument("--no-figures", action="store_true")
    args = parser.parse_args(argv)
    try:
        result = diagnose(args.measured, args.baseline, args.train, args.holdout, out_dir=args.out, figures=not args.no_figures)
    except DvrkDartError as exc:
        print(f"dvrk-dart: {exc}", file=sys.stderr)
        return exc.exit_code
    print(f"selected: {', '.join(result['selection']['selected']) or 'none'}")
    for key in ("gap_before", "gap_after"):
        for split, values in result[key].items():
            if values is not None:
                print(f"{key:>10} {split:>7}: " + " ".join(f"{v:.4f}" for v in values))
    if result["payload"]:
        p = result["payload"]
        print(f"payload: {p['mass_kg']:.4f} kg on {p['link']} ({p['group']}) at {np.round(p['position_m'], 4).tolist()} m (link frame)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

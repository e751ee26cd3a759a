"""The identified parameters refitted on the training runs: is a held-out gap
the bias of the published fit?

The published parameters were identified on accelerations differentiated from
noisy positions (upstream's filters). Noise in a regressor biases a least-
squares fit (errors in variables), most on the parameters that the noisy
columns carry. `--refit` runs this project's identification
(`dvrk_dart.identification`: the same regressor, physical-consistency
constraints, the arm's parameters as prior) on the diagnosis's training runs
with its processing, then replays each held-out run in DART with every
identified term as physics, once with the arm's parameters and once with the
refit. Per joint: both held-out gaps, and the share of the repeatable gap
(above the session floor, with `--repeat`) that the refit removes.

On "one" -> "two" (periodic), replayed: J1 0.047 -> 0.025 N·m, so J1's
repeatable gap is mostly the published fit's bias; J2 0.095 -> 0.077; J3
hardly moves (0.136 -> 0.131): what J3 misses is not in the identified
model's structure (docs/diagnosis.md lists what was tested)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.fit.batch import replayed_residuals
from dvrk_dart.diagnosis.fit.session_floor import AT_FLOOR_RATIO, repeatable_share
from dvrk_dart.diagnosis.fit.result import gaps
from dvrk_dart.diagnosis.fit.diagnosis_runs import loaded_states, processing_of
from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.identify import IdentificationConfig, identify
from dvrk_dart.identification.outputs import PARAMS_FILE, write_outputs
from dvrk_dart.io.provenance import file_record, sha256_of
from dvrk_dart.io.reference_data import resolve_run
from dvrk_dart.io.arm import Arm, load_arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS

#: the refit's identification outputs, inside the diagnosis's folder
REFIT_FOLDER = "refit"


def check_refit_inputs(train, holdout, baseline) -> None:
    """What a refit needs, checked before any work."""
    if not holdout:
        raise DvrkDartError("--refit: needs --holdout runs (a refit is judged on runs it was not fitted on)")
    if baseline is not None:
        raise DvrkDartError("--refit: not with --baseline (a refit identifies the whole arm from raw runs)")
    if any(not isinstance(spec, (str, Path)) for spec in train):
        raise DvrkDartError("--refit: training runs must be files or reference names")


def _held_out_gaps(arms: list[Arm], states: list, executor: str, jobs: int, ray_address: str | None) -> list[list[float]]:
    """Per arm, the RMS gap (measured - replayed, in band) over the held-out
    runs, every identified term simulated (the refit moves friction, offsets
    and springs as much as the bodies)."""
    tasks = [(arm, IDENTIFIED_PHYSICS, state) for arm in arms for state in states]
    residuals = replayed_residuals(tasks, executor, jobs, ray_address, "--refit: held-out replays")
    n = len(states)
    return [gaps(residuals[k * n:(k + 1) * n]) for k in range(len(arms))]


def refit_check(arm: Arm, train, holdout, result: dict, out_dir: Path, executor: str = "local", jobs: int = 2,
                ray_address: str | None = None, topics: BagTopics = BagTopics()) -> dict:
    """The refit's identification (written to OUT/refit/) and its held-out
    gaps beside the arm's; `result` is the diagnosis (its processing and floor)."""
    processing = result["processing"]
    config = IdentificationConfig(runs=tuple(str(resolve_run(s)) for s in train), processing=processing["processing"],
                                  prior=str(arm.params.source), model_file=str(arm.model.source), topics=topics)
    identified = identify(config)
    folder = Path(out_dir) / REFIT_FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    write_outputs(identified, folder)
    refit_arm = load_arm(arm.model.source, folder / PARAMS_FILE)
    states = loaded_states(list(holdout), arm.model, processing_of(result, topics))
    published, refit = _held_out_gaps([arm, refit_arm], states, executor, jobs, ray_address)
    floor = result.get("session_floor")
    share = None if floor is None else repeatable_share(published, refit, floor).tolist()
    return {
        "params": {"path": f"{REFIT_FOLDER}/{PARAMS_FILE}", "sha256": sha256_of(folder / PARAMS_FILE)},
        "prior": file_record(arm.params.source),
        "training_runs": [str(s) for s in train], "holdout_runs": list(result.get("holdout_runs") or []),
        "processing": processing["processing"],
        "simulated_source": "DART replay of each held-out run, every identified term as physics",
        "gap_holdout_arm_params": published, "gap_holdout_refit": refit,
        "repeatable_gap_removed_share": share,
        "repeatable_gap_removed_share_null_when": f"the published parameters' held-out gap is within {AT_FLOOR_RATIO:g}x the session floor "
                                                  "(no repeatable gap shown), or no --repeat measured the floor",
        "words": refit_sentence(published, refit, share),
    }


def refit_sentence(published: list[float], refit: list[float], share: list[float] | None) -> str:
    """J1..J3 of the held-out gap before and after the refit, in words."""
    parts = []
    for j, name in enumerate(JOINT_NAMES[:3]):
        removed = "" if share is None or not np.isfinite(share[j]) else f" ({share[j]:.0%} of the repeatable gap)"
        parts.append(f"{name} {published[j]:.3f} -> {refit[j]:.3f}{removed}")
    return ("The identified parameters refitted on the training runs (same identification, the arm's parameters as prior), "
            "replayed on the held-out runs: " + "; ".join(parts) + ".")

"""A synthetic other arm: the diagnosis trained on one trajectory, scored on another.

The blind suite injects one effect at a time; an arm of another lab (or another
year) differs from the published parameters in several ways at once. Here the
arm is the identified model simulated in DART with every identified term, plus a
set of differences of the library's classes together (friction, offsets, a mass
on the parallelogram: `pipelines/withheld.toml` [other_arm]), recorded along two
real excitations' motions with their measured noise. The diagnosis is fitted on
the first and scored on the second, as `diagnose --measured A --holdout B`: its
one DART configuration must be closer than the identified model there, by the
margin issue 39 asks of the real held-out runs (`holdout_ratio`, on J1..J3).

`python -m dvrk_dart.diagnosis.checks.other_arm OUT SEED...` diagnoses random
other arms (`random_other_arm`) on both datasets' motions: how the fixed case of
`make validate` stands among them (docs/diagnosis-method.md).
"""

from __future__ import annotations

import json
import sys
import zlib
from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.api import DiagnosisConfig, run_diagnosis
from dvrk_dart.diagnosis.checks.blind_suite import case_physics, measured_noise, write_run
from dvrk_dart.diagnosis.fit.batch import BatchSimulate
from dvrk_dart.diagnosis.fit.diagnosis_runs import simulated_efforts
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.csv_run import notes_kept
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import process_periodic
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.sim.config import IDENTIFIED_PHYSICS


def other_arm_runs(arm: Arm, spec: dict, folder: Path) -> dict[str, str]:
    """The other arm's recordings along the spec's training and held-out motions (CSV paths by role)."""
    simulate = BatchSimulate(arm, "local", 1)
    physics = case_physics(spec, IDENTIFIED_PHYSICS)
    folder.mkdir(parents=True, exist_ok=True)
    files = {}
    for role in ("train", "holdout"):
        real = process_periodic(load_run(resolve_run(spec[role]), arm.model))
        noise = measured_noise({"session_pair": spec["session_pair"]}, real, np.zeros(len(JOINT_NAMES), bool), arm.model)  # one session
        rng = np.random.default_rng(zlib.crc32(f"{spec['name']}-{role}".encode()))
        files[role] = str(write_run(folder / f"{role}.csv", real, simulated_efforts(arm, real, simulate, physics), noise, rng))
    return files


def validate_other_arm(arm: Arm, spec: dict, out_dir: Path) -> tuple[dict, list[dict]]:
    """The diagnosis of the synthetic other arm (default processing) and its verdicts on J1..J3."""
    with notes_kept([]) as notes:  # on the check's own runs: in other_arm.json, not in make validate's log
        files = other_arm_runs(arm, spec, out_dir / "runs")
        result = run_diagnosis(arm, DiagnosisConfig((files["train"],), holdout=(files["holdout"],), processing=None, logs=False,
                                                    figures=False, jobs=1), out_dir / "diagnosis")
    bar = result["identified_model_gap_holdout"][:3]
    combined = (result.get("one_configuration") or {}).get("gap_holdout") or [None] * 3
    summary = {"physics": {k: spec[k] for k in ("physics", "payloads") if k in spec}, "motions": [spec["train"], spec["holdout"]],
               "processing": result["processing"].get("processing"), "identified_model_gap_holdout": bar,
               "one_configuration_gap_holdout": combined[:3], "effects": [e["name"] for e in result["effects"] if e.get("selected")],
               "notes": notes, "generator": "DART with every identified term and the differences as physics + the measured noise"}
    write_json_atomic(out_dir / "other_arm.json", summary)
    ratio = spec["holdout_ratio"]
    verdicts = [{"check": f"synthetic other arm ({spec['label']}), fitted on {spec['train']}'s motion, held out on {spec['holdout']}'s: "
                          f"one DART configuration within {ratio:g}x the identified model on {joint}",
                 "passed": combined[i] is not None and combined[i] <= ratio * bar[i],
                 "value": "no configuration" if combined[i] is None else f"{combined[i]:.4f} vs {bar[i]:.4f} {arm.model.effort_unit(joint)}"}
                for i, joint in enumerate(JOINT_NAMES[:3])]
    return summary, verdicts


#: the datasets' training and held-out motions
MOTIONS = {"2018 motions": ("2018-test1", "2018-test2"), "2019 motions": ("one", "two")}


def random_other_arm(seed: int, label: str) -> dict:
    """An [other_arm] spec with differences drawn at plausible sizes: friction and offsets on J1..J3 (N·m, N), a
    0.05-0.3 kg mass on a parallelogram link (pitch, intermediate or pitch_top) within 5 cm of its frame."""
    rng = np.random.default_rng(seed)

    def per_joint(arm_size: float, insertion_size: float, signed: bool) -> dict:
        sizes = rng.uniform(0.25, 1.0, 3) * [arm_size, arm_size, insertion_size] * (rng.choice([-1, 1], 3) if signed else 1)
        return dict(zip(JOINT_NAMES[:3], sizes.tolist()))

    payload = {"link": int(rng.choice([2, 5, 7])), "mass_kg": float(rng.uniform(0.05, 0.3)), "position_m": rng.uniform(-0.05, 0.05, 3).tolist()}
    train, holdout = MOTIONS[label]
    return {"name": f"other_arm_{seed}", "label": label, "train": train, "holdout": holdout, "session_pair": ["one", "one-no-weight"],
            "holdout_ratio": 0.85, "physics": {"coulomb": per_joint(0.06, 0.3, False), "viscous": per_joint(0.1, 0.5, False),
                                               "offset": per_joint(0.03, 0.2, True)}, "payloads": [payload]}


def main(argv: list[str]) -> None:
    from dvrk_dart.io.arm import load_arm
    from dvrk_dart.model.description import DEFAULT_MODEL_FILE

    arm, out = load_arm(DEFAULT_MODEL_FILE), Path(argv[0])
    for seed in map(int, argv[1:]):
        for label in MOTIONS:
            summary, _ = validate_other_arm(arm, random_other_arm(seed, label), out / f"{seed}-{label.split()[0]}")
            ratios = np.divide(summary["one_configuration_gap_holdout"], summary["identified_model_gap_holdout"])
            print(json.dumps({"seed": seed, "motions": label, "ratio_j1_j3": np.round(ratios, 2).tolist()}), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])

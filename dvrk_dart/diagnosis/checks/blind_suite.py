"""The blind effect suite: every effect class of the library injected alone, as
DART physics (never by the regressors the diagnosis fits), into two periods of
a real excitation, with the measured noise and a session change of the
constant efforts added, then diagnosed without knowing it: without and with a
baseline (the same motion without the effect, another session), in both
processings. Each case must rank the injected class on its joint first and
leave that joint's gap within `gap_tolerance` times what the true physics
leaves there (the noise through the processing); a class with no candidate
in the library ("none") must not be claimed: "not explained", or an
equivalent effect as close (`pipelines/withheld.toml` [blind_suite]).

Classes the simulation has no physics for (the counterweight tendon's
transmission error, a Stribeck drop) are not in the suite: a run made with
their regressor would test the regressor against itself. An effort scale and
a time shift are the sensor's: DART's efforts read times 1 + s
(`measured_scale`), or late (`measured_delay_s`, whole samples of the
periodic motion, rolled).
"""

from __future__ import annotations

import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from dvrk_dart.diagnosis.fit.batch import BatchSimulate
from dvrk_dart.diagnosis.output.wording import NOT_DETERMINED
from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.diagnosis.fit.diagnosis_runs import RunProcessing, Simulate, loaded_states, simulated_efforts
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.csv_run import notes_kept
from dvrk_dart.io.reference_data import load_run, resolve_run, sample_rate_hz
from dvrk_dart.io.signal import ProcessedRun, process_periodic
from dvrk_dart.metrics import rms
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.sim.config import JointEffects, Payload, SimConfig

#: JointEffects fields given per joint name in a case (the others are entries)
PER_JOINT_FIELDS = ("coulomb", "viscous", "offset", "stiffness", "armature", "coulomb_presliding", "coulomb_reversal_velocity")


def case_physics(case: dict, base: SimConfig) -> SimConfig:
    """The case's effect as simulation physics on top of `base`: per-joint
    JointEffects fields ({"coulomb": {"q2": 0.15}}), entry fields
    (position_friction, angle_load: lists) and point payloads."""
    fields = {}
    for name, value in case.get("physics", {}).items():
        if name in PER_JOINT_FIELDS:
            per_joint = np.zeros(N_JOINTS)
            for joint, v in value.items():
                per_joint[JOINT_NAMES.index(joint)] = float(v)
            fields[name] = tuple(per_joint.tolist())
        else:
            fields[name] = tuple(tuple(float(x) for x in entry) for entry in value)
    payloads = tuple(Payload(int(p["link"]), float(p["mass_kg"]), tuple(p["position_m"])) for p in case.get("payloads", []))
    return replace(base, extra=base.extra.plus(JointEffects(**fields)), payloads=base.payloads + payloads)


def delay_samples(case: dict, rate_hz: float) -> int:
    """The case's sensor delay (`measured_delay_s`) in whole samples."""
    return int(round(float(case.get("measured_delay_s", 0.0)) * rate_hz))


def sensor_reading(case: dict, efforts: np.ndarray, rate_hz: float) -> np.ndarray:
    """DART's efforts as the case's sensor reads them: times 1 + its `measured_scale`, `measured_delay_s` late (rolled:
    the first samples read the motion's end, about a period later; `true_physics_gap` leaves them out)."""
    return np.roll(efforts * (1.0 + float(case.get("measured_scale", 0.0))), delay_samples(case, rate_hz), axis=0)


def suite_motion(spec: dict, real: ProcessedRun) -> ProcessedRun:
    """`periods` whole periods of the spec's real run (processed periodic), its
    positions as the periodic layer's series (exactly periodic: both processings apply)."""
    return real.head(int(round(spec["periods"] * real.periodic.period.period_s * real.rate_hz)) + 2)


def measured_noise(spec: dict, real: ProcessedRun, joints_with_session_offsets: np.ndarray, model: PsmModel) -> dict[str, np.ndarray]:
    """The real runs' noise: per sample on the efforts and the positions (the
    periodic layer's, on the suite's run), and the constant efforts that moved
    between two sessions of it (`session_pair`) on the joints sessions move."""
    summary = real.periodic.summary()
    first, second = (load_run(resolve_run(name), model).tau for name in spec["session_pair"])
    span = min(len(first), len(second))
    return {"effort": np.nan_to_num(np.array(summary["noise_per_sample_rms"], dtype=float)),
            "position": np.nan_to_num(np.array(summary["position_noise_per_sample_rms"], dtype=float)),
            "session_offsets": np.where(joints_with_session_offsets, first[:span].mean(axis=0) - second[:span].mean(axis=0), 0.0)}


def write_run(path: Path, state: ProcessedRun, efforts: np.ndarray, noise: dict, rng: np.random.Generator) -> Path:
    """The run as a measured CSV: the 21 columns where the suite's real run records every joint at the default
    rate, else a header naming the joints it records and a time column (a 3-joint design's wrist, simulated
    without noise, is no measured joint; a run logged at 100 Hz read at 200 Hz is refused)."""
    q = state.q + rng.standard_normal(state.q.shape) * noise["position"]
    columns = np.hstack([q, state.dq, efforts + rng.standard_normal(efforts.shape) * noise["effort"]])
    if state.measured.all() and abs(state.rate_hz - sample_rate_hz()) <= 1e-6 * state.rate_hz:
        np.savetxt(path, columns, delimiter=",")
        return path
    kept = np.r_[True, np.tile(state.measured, 3)]
    names = np.array(["t", *(f"{kind}{j + 1}" for kind in ("q", "dq", "tau") for j in range(N_JOINTS))])
    np.savetxt(path, np.column_stack([state.t - state.t[0], columns])[:, kept], delimiter=",", header=",".join(names[kept]), comments="")
    return path


def case_runs(arm: Arm, motion: ProcessedRun, simulate: Simulate, case: dict, noise: dict, folder: Path, seed: int) -> dict:
    """The case's measured run (effect, noise) and its baseline (no effect,
    other noise, the other session's constant efforts), as CSV files, and the
    case's physics; with `repeat` in the case, a --repeat run too: the
    baseline's motion again in the measured run's session (no effect, its own noise)."""
    base = SimConfig()
    rng = np.random.default_rng(seed)
    config = case_physics(case, base)
    clean = sensor_reading(case, simulated_efforts(arm, motion, simulate, config), motion.rate_hz)
    effect_free = simulated_efforts(arm, motion, simulate, base)
    folder.mkdir(parents=True, exist_ok=True)
    runs = {"measured": write_run(folder / f"{case['name']}.csv", motion, clean, noise, rng), "config": config, "case": case,
            "baseline": write_run(folder / f"{case['name']}_baseline.csv", motion, effect_free + noise["session_offsets"], noise, rng)}
    if case.get("repeat"):
        runs["repeat"] = write_run(folder / f"{case['name']}_repeat.csv", motion, effect_free, noise, rng)
    return runs


def true_physics_gap(arm: Arm, runs: dict, simulate: Simulate, processing: RunProcessing, with_baseline: bool,
                     session_joints: np.ndarray, known: dict | None = None) -> np.ndarray:
    """(7,) what the diagnosis's residual keeps when the injected effect is
    known exactly: the processed run against its simulation with the case's
    physics (minus, with a baseline, the baseline against the effect-free
    simulation, each joint that sessions move demeaned as the diagnosis does):
    the noise of efforts and positions through the processing, the floor.
    `known`: the residuals already simulated, by run and band (a run's is the
    same with and without a baseline when the band is)."""
    known = {} if known is None else known

    def gap(role: str, config: SimConfig, case: dict) -> np.ndarray:
        key = (str(runs[role]), processing.name, processing.harmonics)
        if key not in known:
            state = loaded_states([str(runs[role])], arm.model, processing)[0]
            known[key] = state.tau - sensor_reading(case, simulated_efforts(arm, state, simulate, config), state.rate_hz)
        return known[key]

    residual = gap("measured", runs["config"], runs["case"])
    if with_baseline:
        difference = residual - gap("baseline", SimConfig(), {})
        residual = difference - session_joints * difference.mean(axis=0)
    rate_hz = loaded_states([str(runs["measured"])], arm.model, processing)[0].rate_hz
    return rms(residual[delay_samples(runs["case"], rate_hz):])


def judge_case(case: dict, result: dict, floor: np.ndarray, tolerance: float) -> dict:
    """The top finding against the injected class and joint, the gap it leaves against the noise."""
    top = result["effects"][0] if result.get("effects") else {"name": None, "family": "", "parameters": {}}
    joint = JOINT_NAMES.index(case["joint"])
    gap = result["gap_after"]["train"][joint]
    gap_ok = gap is not None and gap <= tolerance * floor[joint]
    expected = case["expect"]
    if expected == "none":  # no class of the library: no false claim (not explained, or an equivalent to within the noise)
        named = result["explanation"]["words"] in ("not explained", NOT_DETERMINED) or bool(gap_ok)
    elif expected.startswith("payload:"):  # a payload on a link group, or on one the answer names as not told apart
        # from it: equivalent on these runs (a held wrist moves the tool with the insertion carriage) or tied
        found = top["parameters"]
        reports = [*(result.get("payloads") or ()), result.get("gravity_mismatch") or {}]
        fit = next((r for r in reports if r.get("link") == found.get("link")), {})  # the top effect's own report
        groups = {found.get("group"), *(found.get("equivalent_link_groups") or ()), *(fit.get("tied_groups") or ())}
        named = (top.get("kind") in ("payload", "payload_at_position", "gravity_mismatch") and expected.split(":", 1)[1] in groups
                 and not result.get("payload_not_distinguished"))
    else:
        named = top["family"] == expected
    size_error = None
    if named and "size" in case and isinstance(top["parameters"].get(case["size_parameter"]), (int, float)):
        size_error = abs(top["parameters"][case["size_parameter"]] / case["size"] - 1.0)
    return {"top_effect": top["name"], "named": bool(named), "joint": case["joint"], "gap_after": gap, "size_error": size_error,
            "floor": float(floor[joint]), "gap_within_noise": bool(gap_ok)}


def run_case(arm: Arm, spec: dict, case: dict, runs: dict, simulate: Simulate, processing: str, with_baseline: bool,
             known: dict | None = None) -> dict:
    """One diagnosis of the suite, judged (`known`: `true_physics_gap`'s)."""
    repeat = str(runs["repeat"]) if with_baseline and "repeat" in runs else None
    result = diagnose(str(runs["measured"]), baseline=str(runs["baseline"]) if with_baseline else None, simulate=simulate, arm=arm,
                      figures=False, profile_payload_mass=False, processing=processing, repeat=repeat,
                      effort_scale=bool(case.get("effort_scale")))
    used = RunProcessing(processing, result["processing"].get("harmonics"))
    nuisance = (result.get("nuisance_offset_joints") or {}).get("joints", arm.model.session_offset_joints or ())  # as the diagnosis demeaned
    floor = true_physics_gap(arm, runs, simulate, used, with_baseline, np.isin(JOINT_NAMES, nuisance), known)
    verdict = judge_case(case, result, floor, spec["gap_tolerance"])
    return {"case": case["name"], "processing": processing, "baseline": with_baseline, **verdict,
            "words": (result.get("explanation") or {}).get("words")}


def validate_blind_suite(arm: Arm, spec: dict, out_dir: Path, simulate: Simulate | None = None) -> tuple[dict, list[dict]]:
    """Every case of `spec` in every processing of `spec["processings"]`,
    without and with a baseline (the case's or `spec["baselines"]`, default both;
    `spec["subset"]`: the case names to run only; `spec["seed_offset"]`: another noise draw)."""
    simulate = simulate or BatchSimulate(arm, "local", 1)
    real = process_periodic(load_run(resolve_run(spec["run"]), arm.model))
    motion = suite_motion(spec, real)
    noise = measured_noise(spec, real, np.isin(JOINT_NAMES, arm.model.session_offset_joints or ()), arm.model)
    cases = [c for c in spec["cases"] if c["name"] in spec.get("subset", [c["name"] for c in spec["cases"]])]
    outcomes = []
    with notes_kept([]) as notes:  # on the suite's own runs: in blind_suite.json, not in make validate's log
        for case in cases:
            seed = zlib.crc32(case["name"].encode()) + spec.get("seed_offset", 0)  # a case's runs whatever runs beside it
            runs = case_runs(arm, motion, simulate, case, noise, out_dir / "runs", seed)
            known: dict = {}
            outcomes += [run_case(arm, spec, case, runs, simulate, processing, with_baseline, known)
                         for processing in spec["processings"] for with_baseline in case.get("baselines", spec.get("baselines", (False, True)))]
    summary = {"cases": outcomes, "notes": notes, **{k: v.tolist() for k, v in noise.items()},
               "generator": "DART replay with the effect as physics + the measured noise; the baseline in another session"}
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out_dir / "blind_suite.json", summary)
    return summary, suite_verdicts(spec, outcomes)


def suite_verdicts(spec: dict, outcomes: list[dict]) -> list[dict]:
    """A verdict per diagnosis (the class first, the gap closed), and the size for the upstream runs without a baseline."""
    design = f" on the {spec['label']}" if spec.get("label") else ""
    verdicts = [{"check": f"blind {o['case']}{design} ({o['processing']}, {'with' if o['baseline'] else 'without'} a baseline): "
                          f"the injected class on {o['joint']} first, its gap within {spec['gap_tolerance']:g}x the noise",
                 "passed": o["named"] and o["gap_within_noise"],
                 "value": f"top = {o['top_effect']}; {o['joint']} {o['gap_after']:.4g} vs {o['floor']:.4g} with the true physics"}
                for o in outcomes]
    verdicts += [{"check": f"blind {o['case']}{design} ({o['processing']}, without a baseline): its size within {spec['size_tolerance']:.0%}",
                  "passed": o["size_error"] is not None and o["size_error"] <= spec["size_tolerance"],
                  "value": "not named" if o["size_error"] is None else f"size error {o['size_error']:.1%}"}
                 for o in outcomes if not o["baseline"] and o["processing"] == "upstream" and "size" in _case(spec, o["case"])]
    return verdicts


def _case(spec: dict, name: str) -> dict:
    return next(c for c in spec["cases"] if c["name"] == name)

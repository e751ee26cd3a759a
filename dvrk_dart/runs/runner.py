"""One run: a RunConfig -> the simulation (Cartesian task or replay), the
identified model at the simulated states, and the metrics -> a RunRecord.

The identified model is evaluated at the simulated (q, dq, ddq) of each step,
where ddq is the acceleration the step produced: a "simulated" column is
always read from DART, never from the model.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError, SimulationDiverged
from dvrk_dart.io.provenance import arm_model_record, file_record
from dvrk_dart.io.reference_data import resolve_run, run_label, sha256_of
from dvrk_dart.metrics import TORQUE_TRANSIENT_S, rms
from dvrk_dart.io.arm import Arm, load_arm
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel, resolve_arm_model
from dvrk_dart.model.identified import TERMS
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.runs.config import RunConfig, run_name, sim_config_for
from dvrk_dart.io.record import RunRecord
from dvrk_dart.runs.scenarios import Scenario, load_scenario
from dvrk_dart.sim.config import SimConfig, simulated_terms


def add_model_efforts(arm: Arm, record: RunRecord) -> None:
    """The identified model, term by term, at the simulated states (dynamic modes)."""
    valid = np.all(np.isfinite(record.ddq), axis=1)
    if not valid.any():
        return
    efforts = arm.identified.efforts(record.q, record.dq, np.where(valid[:, None], record.ddq, 0.0), TERMS)
    record.effort_model = {k: np.where(valid[:, None], v, np.nan) for k, v in efforts.terms.items()}


#: the tool tip of a kinematic or velocity run follows its path to ~1e-11 m;
#: farther off than this the path has left what the arm can reach (m)
MAX_PATH_DEVIATION_M = 1e-3


def cartesian_metrics(record: RunRecord, mode: str, config: SimConfig) -> dict:
    if not len(record):
        return {}
    position, orientation = record.tracking_errors()
    metrics = {
        "tracking_rms_position": rms(position).tolist(),
        "tracking_rms_orientation": rms(orientation).tolist(),
    }
    distance = np.linalg.norm(position, axis=1)
    if mode != "torque" and np.nanmax(distance, initial=0.0) > MAX_PATH_DEVIATION_M:
        k = int(np.nanargmax(distance))
        metrics["error"] = (f"the tool tip is {distance[k]:.3g} m off the path at t = {record.t[k]:.3f} s: "
                            "the path leaves what the arm can reach (its workspace or joint limits)")
    if mode == "torque":
        after = record.t >= TORQUE_TRANSIENT_S
        metrics["tracking_rms_position_after_1s"] = rms(position[after]).tolist() if after.any() else None
        norm = np.linalg.norm(position, axis=1)
        metrics["position_error_max_first_s_m"] = float(norm[~after].max()) if (~after).any() else None
    if mode != "kinematic" and record.effort_model:
        metrics["model_terms_compared"] = list(simulated_terms(config))
        model = record.model_total(simulated_terms(config))
        ok = np.all(np.isfinite(record.effort_sim), axis=1) & np.all(np.isfinite(model), axis=1)
        metrics["rms_sim_vs_model"] = rms(record.effort_sim[ok] - model[ok]).tolist() if ok.any() else None
    return metrics


def scenario_of(config: RunConfig) -> Scenario:
    """The run's scenario, with a replay's measured run overridden when asked."""
    scenario = load_scenario(config.scenario)
    if config.measured is not None:
        if scenario.kind != "replay":
            raise DvrkDartError(f"--measured: scenario '{scenario.name}' is not a replay")
        scenario = Scenario(f"replay-{run_label(config.measured)}", "replay", scenario.modes, scenario.counterweights,
                            scenario.duration_s, measured=config.measured, dynamics=scenario.dynamics, arm_model=scenario.arm_model)
    return scenario


def arm_model_file(config: RunConfig) -> Path:
    """The run's arm: its scenario's (`arm_model`), else the config's, else the PSM."""
    arm_model = scenario_of(config).arm_model or config.arm_model
    return resolve_arm_model(arm_model) if arm_model else DEFAULT_MODEL_FILE


def arm_of_run(config: RunConfig) -> Arm:
    """The run's arm (`arm_model_file`) with the parameters config.params_file names."""
    return load_arm(arm_model_file(config), config.params_file)


def _check_scenario_options(scenario: Scenario, mode: str, counterweight: str, arm: Arm) -> None:
    """One line for a mode or counterweight the scenario (or the arm) does not have."""
    if mode not in scenario.modes:
        raise DvrkDartError(f"--mode: scenario '{scenario.name}' runs in {', '.join(scenario.modes)}, not '{mode}'")
    if counterweight not in scenario.counterweights:
        raise DvrkDartError(
            f"--counterweight: scenario '{scenario.name}' runs with {', '.join(scenario.counterweights)}, not '{counterweight}'"
        )
    if arm.model.counterweight_link is None and counterweight != "on":
        raise DvrkDartError(f"--counterweight {counterweight}: the {arm.model.folder.name} arm has no counterweight (only 'on': the arm as it is)")


def run(config: RunConfig, arm: Arm | None = None) -> RunRecord:
    """Run one configuration; the record carries its resolved config and metrics.
    `arm` (model + parameters), when given, must be `arm_of_run(config)`."""
    arm = arm or arm_of_run(config)
    scenario = scenario_of(config)
    mode, counterweight = config.mode, config.counterweight
    _check_scenario_options(scenario, mode, counterweight, arm)
    sim_config = sim_config_for(config, arm.model, arm.params.source)
    duration = config.duration_s or scenario.duration_s
    if scenario.kind != "replay" and duration > scenario.duration_s:  # the path would go on past its end
        raise DvrkDartError(f"--duration {duration:g}: the scenario {scenario.name} lasts {scenario.duration_s:g} s")
    if scenario.kind != "replay" and config.duration_s is None:
        config.check_steps(duration, f"scenario {scenario.name}'s duration_s")
    start = time.perf_counter()
    if scenario.kind == "replay":
        from dvrk_dart.runs.replay import replay

        try:
            record = replay(scenario.measured, arm.model, mode=mode, config=sim_config, duration_s=duration, params=arm.params,
                            processing=config.processing, harmonics=config.harmonics, topics=config.topics)
        except SimulationDiverged as exc:  # keep what was logged up to the divergence
            record = exc.record
    else:
        from dvrk_dart.runs.cartesian import run_cartesian

        record = run_cartesian(arm, scenario, mode, sim_config, duration)
        if mode != "kinematic":
            add_model_efforts(arm, record)
        record.metrics = {**cartesian_metrics(record, mode, sim_config), **record.metrics}  # a divergence is the first error
    record.name = run_name(scenario.name, mode, *config.name_parts)
    record.config = {
        "run_config": config.to_dict(),
        "scenario": scenario.to_dict(),
        "mode": mode,
        "counterweight": counterweight,
        "dynamics": config.dynamics_label,
        "duration_s": record.metrics["duration_s"],  # simulated: the steps taken (to a divergence) times the step
        "sim": sim_config.to_dict(),
        "model_file": str(arm.model.source.name),
        "arm_model": arm_model_record(arm.model),
        "params_file": str(arm.params.source),
        "params_sha256": sha256_of(arm.params.source),
        "inputs": inputs_used(config, scenario, arm.model),
    }
    record.markers.setdefault("rcm", rcm_position(arm))
    record.metrics.update(
        {
            "scenario": scenario.name,
            "mode": mode,
            "counterweight": counterweight,
            "dynamics": config.dynamics_label,
            "dt_s": sim_config.dt_s,
            "duration_s": record.config["duration_s"],
            "samples": len(record),
            "wall_time_s": time.perf_counter() - start,
        }
    )
    if record.closure_residual_m is not None and len(record):
        record.metrics["closure_residual_max_m"] = float(np.max(record.closure_residual_m))
    return record


def inputs_used(config: RunConfig, scenario: Scenario, model: PsmModel) -> dict[str, dict]:
    """The input files the run really used (measured run, diagnosis): path,
    sha256 and the options that selected data from them (a bag's topics, a
    CSV's rate)."""
    from dvrk_dart.io.reference_data import input_record

    inputs = {}
    if scenario.measured:
        inputs[str(scenario.measured)] = input_record(resolve_run(scenario.measured), model, config.topics)
    if config.dynamics.endswith(".json"):
        inputs[config.dynamics] = file_record(Path(config.dynamics))
    return inputs


def rcm_position(arm: Arm) -> np.ndarray:
    """The remote centre of motion: where the tool axis crosses itself for any pitch."""
    frames_a = arm.model.forward_kinematics(np.zeros(N_JOINTS))
    frames_b = arm.model.forward_kinematics(np.r_[0.0, 0.3, np.zeros(N_JOINTS - 2)])
    (pa, za), (pb, zb) = ((f[8][:3, 3], f[8][:3, 2]) for f in (frames_a, frames_b))
    # closest points of the two tool axes
    A = np.column_stack([za, -zb])
    s, _ = np.linalg.lstsq(A, pb - pa, rcond=None)[0]
    return pa + s * za

"""One DART configuration for every joint: the diagnosis's selected effects,
with the terms found beyond them fitted on top (J3's stroke friction, effort
in ddq3·sign(dq3) and pitch load, `insertion_terms`; the loads that the pitch
angle sets on J1 and J2, `pitch_load`), replayed on the held-out runs.

The terms are fitted on the training runs' residual replayed with the
selected effects, so they add what the effects leave. The terms act on
different coordinates and the replay follows the measured motion, so each
joint's held-out gap is its own effects' and terms'. The configuration is
written beside diagnosis.json (`ONE_CONFIGURATION_FILE`), which `--dynamics`
runs. Like the terms, it is a finding to confirm on withheld runs: they were
screened with the held-out score in view.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from dvrk_dart.diagnosis.beyond import insertion_terms
from dvrk_dart.diagnosis.beyond import pitch_load
from dvrk_dart.diagnosis.fit.batch import replayed_residuals
from dvrk_dart.diagnosis.fit.result import gaps
from dvrk_dart.diagnosis.fit.diagnosis_runs import loaded_states, processing_of
from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.io.arm import Arm
from dvrk_dart.io.bags import BagTopics
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES, N_JOINTS
from dvrk_dart.sim.config import JointEffects, SimConfig

#: the one configuration, as `--dynamics` reads it:
#: `dvrk-dart replay --measured two --processing periodic --dynamics OUT/one_configuration.json`
ONE_CONFIGURATION_FILE = "one_configuration.json"
METHOD = ("the diagnosis's selected effects, with J3's terms and the pitch-angle loads on J1 and J2 fitted on top of them "
          "(on the training runs replayed with the effects), one DART configuration replayed on the held-out runs")


def one_configuration(arm: Arm, effects: SimConfig, train: list[ProcessedRun], holdout: list[ProcessedRun], executor: str = "local",
                      jobs: int = 2, ray_address: str | None = None, session_joints: np.ndarray | None = None) -> dict:
    """The selected effects (`effects`) plus the terms fitted on what they leave
    on the training runs; the held-out runs replayed with all of them.
    session_joints: (7,) bool, the joints on which the diagnosis took each
    run's constant out as a session's: the configuration carries the training
    runs' mean constant there, a new session's best guess (without it, q4 of
    one and two scored on one-no-weight was 0.0058 N·m, the identified model 0.0017)."""
    trained = replayed_residuals([(arm, effects, s) for s in train], executor, jobs, ray_address, "one configuration: training replays")
    session_joints = np.zeros(N_JOINTS, bool) if session_joints is None else np.asarray(session_joints, bool)
    constants = np.where(session_joints, np.mean([r.mean(axis=0) for r in trained], axis=0), 0.0)
    trained = [r - constants for r in trained]  # a constant effort adds to the replayed efforts sample by sample
    terms = insertion_terms.fit_insertion_terms(arm, train, insertion_terms.TERMS, [r[:, INSERTION] for r in trained])
    loads = pitch_load.fit_pitch_loads(train, trained)
    extra = (effects.extra.plus(JointEffects(offset=tuple(map(float, constants)))).plus(insertion_terms.simulation_effects(arm, terms))
             .plus(pitch_load.simulation_effects(loads)))
    config = replace(effects, extra=extra)
    held = replayed_residuals([(arm, config, s) for s in holdout], executor, jobs, ray_address, "one configuration: held-out replays")
    gap = gaps(held, np.all([s.measured for s in holdout], axis=0))
    return {"gap_holdout": gap, "insertion_terms": terms.named_coefficients(), "pitch_loads": loads.to_dict(),
            "session_constants": {name: float(c) for name, c, on in zip(JOINT_NAMES, constants, session_joints) if on},
            "sim_config": config.to_dict(), "method": METHOD, "words": one_configuration_sentence(gap, arm.model)}


def one_configuration_check(arm: Arm, train, holdout, result: dict, executor: str = "local", jobs: int = 2,
                            ray_address: str | None = None, topics: BagTopics = BagTopics()) -> dict | None:
    """`one_configuration` on the diagnosis's runs and processing (None when it selected no effect)."""
    if not result.get("sim_config"):
        return None
    processing = processing_of(result, topics)
    train, holdout = loaded_states(list(train), arm.model, processing), loaded_states(list(holdout), arm.model, processing)
    session_joints = np.isin(JOINT_NAMES, (result.get("nuisance_offset_joints") or {}).get("joints") or [])  # runs of their own (no baseline)
    return one_configuration(arm, SimConfig.from_dict(result["sim_config"]), train, holdout, executor, jobs, ray_address, session_joints)


def one_configuration_sentence(gap: list[float], model: PsmModel) -> str:
    return ("The selected effects with J3's terms and the loads the pitch angle sets on J1 and J2, in one DART configuration, leave "
            + ", ".join(f"{name} {gap[j]:.3g} {model.effort_unit(name)}" for j, name in enumerate(JOINT_NAMES[:3]) if gap[j] is not None)
            + " on the held-out runs.")

"""The report's section on how realistic the simulated arm is: the replay of
the held-out trajectory "two" with the paper's arm (identified inertia only),
with every identified term as DART physics, and with the effects a diagnosis
fitted on trajectory "one", each against the measured efforts, per joint."""

from __future__ import annotations

import math

from dvrk_dart.io.html import num_cell, render, table, text_cell
from dvrk_dart.analysis.tables import (
    REGIME_DESCRIPTIONS,
    REGIME_HIGH_ACCELERATION,
    REGIME_NEAR_ZERO_VELOCITY,
    Analysis,
)
from dvrk_dart.metrics import REGIME_ALL
from dvrk_dart.model.joints import JOINT_NAMES

SCENARIO, MODE, COUNTERWEIGHT = "replay-two", "velocity", "on"
#: the order the arms are shown in: from the paper's to the most realistic
DYNAMICS_ORDER = ("inertial", "identified")
SHOWN_JOINTS = JOINT_NAMES[:3]
#: where the servo's sign(target velocity) and the model's sign(dq) Coulomb reversals differ
REGIMES_SHOWN = (REGIME_ALL, REGIME_NEAR_ZERO_VELOCITY, REGIME_HIGH_ACCELERATION)


def _processing(run) -> str:
    """The processing a replay read its measured run with (config.json's run_config)."""
    return (run.config.get("run_config") or {}).get("processing") or "upstream"


def _rank(dynamics: str) -> tuple[int, str]:
    return (DYNAMICS_ORDER.index(dynamics), dynamics) if dynamics in DYNAMICS_ORDER else (len(DYNAMICS_ORDER), dynamics)


def realistic_arm_section(analysis: Analysis) -> str:
    runs = sorted(
        (r for r in analysis.runs.values() if (r.scenario, r.mode, r.counterweight) == (SCENARIO, MODE, COUNTERWEIGHT)),
        key=lambda r: _rank(r.dynamics),
    )
    if len(runs) < 2:
        return ""
    header = ["simulated arm (--dynamics)", *[f"{j} ({runs[0].model.effort_unit(j)})" for j in SHOWN_JOINTS]]

    def cell(run: str, quantity: str, joint: str, regime: str) -> str:
        value = analysis.value(run, quantity, joint, regime)
        if math.isnan(value):  # too few samples in that regime
            return text_cell("—")
        return num_cell(value, run=run, quantity=quantity, joint=joint, regime=regime)

    def row(label: str, run: str, quantity: str, regime: str = REGIME_ALL) -> list:
        return [text_cell(label), *(cell(run, quantity, j, regime) for j in SHOWN_JOINTS)]

    measured = [row(f"{r.dynamics}, {_processing(r)} processing: RMS(simulated - measured)", r.name, "rms_sim_vs_measured") for r in runs]
    # the model in each processing's band: a periodic replay sits beside the model's periodic figure, not the upstream one
    first_of = {_processing(r): r for r in reversed(runs)}
    measured += [row(f"the full identified model, {processing} processing: RMS(model - measured) at the measured states", r.name,
                     "rms_model_full_vs_measured_at_measured_state") for processing, r in sorted(first_of.items(), reverse=True)]
    identified = next((r for r in runs if r.dynamics == "identified"), None)
    regimes = [] if identified is None else [
        row(f"{regime}: {REGIME_DESCRIPTIONS.get(regime, regime)}", identified.name, "rms_sim_vs_model", regime) for regime in REGIMES_SHOWN]
    return render("sections/realistic_arm.html", measured_table=table(header, measured), identified=identified.name if identified else None,
                  regimes_table=table(["regime", *header[1:]], regimes))

"""The report's section on the periodic processing: both processings side by
side, the session floor, and each joint's gap split into floor and repeatable part.

- the identified model vs the measured efforts of "two", and the realistic
  replay of "two" (every identified term simulated) vs the same, once with
  upstream's filters and once on the excitation's harmonics;
- the floor: two recordings of trajectory one in two sessions
  (`residual_floor`), what their noise predicts, and per session s = RMS of
  the difference / sqrt(2);
- the model's periodic gap on "two" split in squares into s and the
  repeatable part sqrt(gap^2 - s^2), the part a fixed effect could explain;
- a figure of the two sessions' residuals over one period (J1..J3), their
  mean (the repeatable residual) with the floor as a band.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from dvrk_dart.io.html import num_cell, render, table, text_cell
from dvrk_dart.analysis.residual_floor import aligned_residuals, floor_table, processed_pair, residual
from dvrk_dart.io.atomic import write_json_atomic
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import process
from dvrk_dart.metrics import rms
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import JOINT_NAMES

SHOWN_JOINTS = JOINT_NAMES[:3]
#: the runs of the section: the held-out run, and two sessions of trajectory one
HELD_OUT, SESSIONS = "two", ("one", "one-no-weight")
#: the realistic replay of "two", by processing (pipelines/campaign.toml)
REPLAY_RUNS = {"upstream": "replay-two_velocity_cw-on_identified", "periodic": "replay-two_velocity_cw-on_identified_periodic"}


def periodic_figures(arm: Arm, out_dir: Path) -> dict:
    """The section's numbers (also written to OUT/periodic.json) and its figure."""
    held_out = {p: process(load_run(resolve_run(HELD_OUT), arm.model), p) for p in ("upstream", "periodic")}
    model = {p: rms(residual(arm, state)).tolist() for p, state in held_out.items()}
    a, b = processed_pair(SESSIONS, "periodic", arm.model)
    floor = floor_table(arm, a, b)
    per_session = np.asarray(floor["rms_difference"]) / math.sqrt(2.0)
    gap = np.asarray(model["periodic"])
    figures = {
        "model_vs_measured_two": model,
        "session_floor": floor,
        "session_floor_per_session": per_session.tolist(),
        "gap_two_periodic": gap.tolist(),
        "repeatable_two_periodic": np.sqrt(np.maximum(gap**2 - per_session**2, 0.0)).tolist(),
        "period_s": a.periodic.period.period_s,
        "harmonics": a.periodic.harmonics,
        "harmonics_held_out": held_out["periodic"].periodic.harmonics,  # its own band (a diagnosis's is its training runs')
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    _plot_one_period(arm, a, b, per_session, out_dir / "repeatable_residual_one_period.png")
    write_json_atomic(out_dir / "periodic.json", figures)
    return figures


def _plot_one_period(arm: Arm, a, b, per_session: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    phase, ra, rb = aligned_residuals(arm, a, b)
    t = phase * a.periodic.period.period_s
    mean = 0.5 * (ra + rb)
    fig, axes = plt.subplots(len(SHOWN_JOINTS), 1, figsize=(9, 7), sharex=True)
    for ax, name in zip(axes, SHOWN_JOINTS):
        j = JOINT_NAMES.index(name)
        ax.fill_between(t, mean[:, j] - per_session[j], mean[:, j] + per_session[j], color="0.85", label="repeatable +- session floor")
        ax.plot(t, ra[:, j], lw=0.6, color="#2c6fbb", label=SESSIONS[0])
        ax.plot(t, rb[:, j], lw=0.6, color="#c0392b", label=SESSIONS[1])
        ax.plot(t, mean[:, j], lw=1.4, color="k", label="repeatable (mean of the sessions)")
        ax.axhline(0.0, color="0.5", lw=0.5)
        ax.set_ylabel(f"{name} ({arm.model.effort_unit(name)})")
    axes[0].legend(ncol=2, fontsize=7, loc="upper right")
    axes[-1].set_xlabel("t within one period (s)")
    fig.suptitle("Model residual over one period of trajectory one: two sessions (periodic processing)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _replay_gaps(runs_dir: Path) -> dict:
    gaps = {}
    for processing, name in REPLAY_RUNS.items():
        path = runs_dir / name / "metrics.json"
        gaps[processing] = json.loads(path.read_text())["rms_sim_vs_measured"] if path.is_file() else None
    return gaps


def periodic_section(arm: Arm, out_dir: Path, runs_dir: Path) -> tuple[str, str, list[Path]]:
    figures = periodic_figures(arm, out_dir)
    replay = _replay_gaps(runs_dir)
    floor = figures["session_floor"]

    def row(label: str, values, key: str, **attrs) -> list:
        return [text_cell(label), *(num_cell(None if values is None else values[JOINT_NAMES.index(j)], periodic=key, joint=j, **attrs)
                                    for j in SHOWN_JOINTS)]

    rows = [
        row("identified model vs measured, upstream processing", figures["model_vs_measured_two"]["upstream"], "model_vs_measured", processing="upstream"),
        row(f"identified model vs measured, periodic processing (the run's own {figures['harmonics_held_out']} harmonics)",
            figures["model_vs_measured_two"]["periodic"], "model_vs_measured", processing="periodic"),
        row("realistic replay (identified arm) vs measured, upstream", replay["upstream"], "replay_vs_measured", processing="upstream"),
        row("realistic replay (identified arm) vs measured, periodic", replay["periodic"], "replay_vs_measured", processing="periodic"),
        row("session floor: RMS difference of the two sessions' residuals", floor["rms_difference"], "rms_difference"),
        row("... after each run's mean", floor["rms_difference_demeaned"], "rms_difference_demeaned"),
        row("... what the runs' measured noise predicts", floor["noise_predicted_rms"], "noise_predicted_rms"),
        row("floor of one session (RMS difference / sqrt 2)", figures["session_floor_per_session"], "floor_per_session"),
        row("model's gap on two (periodic) = floor + repeatable, in squares: repeatable part", figures["repeatable_two_periodic"], "repeatable"),
    ]
    figure = out_dir / "repeatable_residual_one_period.png"
    body = render("sections/periodic.html", period_s=figures["period_s"], harmonics=figures["harmonics"], held_out=HELD_OUT, sessions=SESSIONS,
                  rms_table=table(["RMS", *[f"{j} ({arm.model.effort_unit(j)})" for j in SHOWN_JOINTS]], rows),
                  verdicts=[(j, floor["verdict"][JOINT_NAMES.index(j)]) for j in SHOWN_JOINTS], figure=figure.name)
    return "Periodic excitation: both processings, the session floor, the repeatable gap", body, [figure]

"""The report's figures, mirroring the seed paper's Figs. 2-8, plus the residual
(measured - simulated) per joint. matplotlib, Agg backend, PNG files.

One colour per source everywhere: simulated = red, identified model = blue,
measured = green (as in the paper), reference = black dashed, commanded
efforts = purple. Counterweight variants are told apart by the panel (velocity
mode) or by the line style (torque mode).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display on the machines that build the report
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from dvrk_dart.analysis.run_folders import LoadedRun  # noqa: E402
from dvrk_dart.analysis.tables import simulated_terms_of  # noqa: E402
from dvrk_dart.model.identified import TERMS  # noqa: E402
from dvrk_dart.model.joints import JOINT_NAMES  # noqa: E402
from dvrk_dart.runs.executors import quiet_worker  # noqa: E402

COLORS = {"sim": "tab:red", "model": "tab:blue", "measured": "tab:green", "reference": "black", "command": "tab:purple"}
REFERENCE_STYLE = "--"
#: torque-mode figures overlay the counterweight variants
VARIANT_STYLES = {"on": "-", "pid": ":", "off": "-."}
VARIANT_LABELS = {"off": "without counterweight (cw-off, paper nCW)", "on": "ideal tendon (cw-on)", "pid": "PID mirror (cw-pid, paper wCW)"}
#: the joints driven in the paper's dynamic tests (the identified tool links are massless)
ARM_JOINTS = (0, 1, 2)
DPI = 100
LINE_WIDTH = 1.0
#: smallest y-span of a pose panel (m or rad): a constant reference then reads as
#: a flat line instead of autoscaled floating-point noise
MIN_POSE_SPAN = 1e-3


@dataclass(frozen=True)
class FigureFile:
    file: str  # path relative to the report folder
    title: str
    caption: str
    runs: tuple[str, ...]


def _joint_label(run: LoadedRun, j: int) -> str:
    return f"{JOINT_NAMES[j]} ({run.model.effort_unit(JOINT_NAMES[j])})"


def _save(fig, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def _at_least_span(ax, span: float) -> None:
    low, high = ax.get_ylim()
    if high - low < span:
        middle = 0.5 * (low + high)
        ax.set_ylim(middle - span / 2, middle + span / 2)


#: effort panels are scaled to this percentile range of their curves: the first
#: step's velocity jump (an acceleration spike of one or two samples) would
#: otherwise flatten everything else; such samples are drawn, just off-scale
ROBUST_PERCENTILES = (0.1, 99.9)
ROBUST_MARGIN = 0.1  # fraction of the range added on each side


def _robust_ylim(ax, curves: list[np.ndarray]) -> None:
    values = np.concatenate([c[np.isfinite(c)] for c in curves]) if curves else np.array([])
    if values.size == 0:
        return
    low, high = np.percentile(values, ROBUST_PERCENTILES)
    margin = ROBUST_MARGIN * max(high - low, 1e-12)
    full_low, full_high = values.min(), values.max()
    if full_low < low - margin or full_high > high + margin:  # only when a spike would dominate
        ax.set_ylim(low - margin, high + margin)


def _euler_xyz(quaternions: np.ndarray) -> np.ndarray:
    """Fixed-axis roll, pitch, yaw (rad), unwrapped in time for continuous curves."""
    return np.unwrap(Rotation.from_quat(quaternions).as_euler("xyz"), axis=0)


def tracking_figure(run: LoadedRun, path: Path) -> None:
    """Figs. 2-3: reference vs actual tool position and orientation, and the errors."""
    record = run.record
    position_error, orientation_error = run.tracking
    angles, angles_ref = _euler_xyz(record.tool_pose[:, 3:]), _euler_xyz(record.tool_pose_ref[:, 3:])
    fig, axes = plt.subplots(3, 4, figsize=(16, 8), sharex=True, layout="constrained")
    for i, axis in enumerate("xyz"):
        ax = axes[i, 0]
        ax.plot(record.t, record.tool_pose_ref[:, i], REFERENCE_STYLE, color=COLORS["reference"], lw=LINE_WIDTH, label="reference")
        ax.plot(record.t, record.tool_pose[:, i], color=COLORS["sim"], lw=LINE_WIDTH, label="simulated")
        ax.set_ylabel(f"{axis} (m)")
        _at_least_span(ax, MIN_POSE_SPAN)
        axes[i, 1].plot(record.t, position_error[:, i], color=COLORS["sim"], lw=LINE_WIDTH)
        axes[i, 1].set_ylabel(f"error {axis} (m)")
        ax = axes[i, 2]
        name = ("roll", "pitch", "yaw")[i]
        ax.plot(record.t, angles_ref[:, i], REFERENCE_STYLE, color=COLORS["reference"], lw=LINE_WIDTH, label="reference")
        ax.plot(record.t, angles[:, i], color=COLORS["sim"], lw=LINE_WIDTH, label="simulated")
        ax.set_ylabel(f"{name} about {axis} (rad)")
        _at_least_span(ax, MIN_POSE_SPAN)
        axes[i, 3].plot(record.t, orientation_error[:, i], color=COLORS["sim"], lw=LINE_WIDTH)
        axes[i, 3].set_ylabel(f"error r{axis} (rad)")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].set_title("(a) position")
    axes[0, 1].set_title("position error, reference - actual")
    axes[0, 2].set_title("(b) orientation (fixed-axis x-y-z angles)")
    axes[0, 3].set_title("orientation error (rotation vector)")
    axes[0, 0].legend(loc="best")
    axes[0, 2].legend(loc="best")
    fig.suptitle(f"{run.name}: tool-tip tracking")
    _save(fig, path)


def _model_efforts(run: LoadedRun) -> tuple[np.ndarray, np.ndarray]:
    """(model restricted to the simulated terms, full model) at the simulated state."""
    record = run.record
    simulated = tuple(t for t in simulated_terms_of(run.config) if t in record.effort_model)
    return record.model_total(simulated), record.model_total(tuple(t for t in TERMS if t in record.effort_model))


def efforts_figure(runs: list[LoadedRun], path: Path, with_measured: bool) -> None:
    """Figs. 4-6: model vs simulated (vs measured) efforts, one column per counterweight variant."""
    fig, axes = plt.subplots(len(ARM_JOINTS), len(runs), figsize=(6 * len(runs), 8), sharex=True, squeeze=False, layout="constrained")
    for c, run in enumerate(runs):
        record = run.record
        model, full = _model_efforts(run)
        for r, j in enumerate(ARM_JOINTS):
            ax = axes[r, c]
            curves = [model[:, j], record.effort_sim[:, j]]
            if with_measured and record.effort_measured is not None:
                ax.plot(record.t, record.effort_measured[:, j], color=COLORS["measured"], lw=LINE_WIDTH, label="measured")
                ax.plot(record.t, full[:, j], REFERENCE_STYLE, color=COLORS["model"], lw=0.7, alpha=0.7, label="model, all identified terms")
                curves += [record.effort_measured[:, j], full[:, j]]
            ax.plot(record.t, model[:, j], color=COLORS["model"], lw=LINE_WIDTH, label="model (simulated terms)")
            ax.plot(record.t, record.effort_sim[:, j], color=COLORS["sim"], lw=LINE_WIDTH, alpha=0.8, label="simulated")
            ax.set_ylabel(_joint_label(run, j))
            _robust_ylim(ax, curves)
        axes[0, c].set_title(f"({'abc'[c]}) {VARIANT_LABELS.get(run.counterweight, run.counterweight)}")
        axes[-1, c].set_xlabel("time (s)")
    axes[0, 0].legend(loc="best", fontsize="small")
    fig.suptitle(f"{runs[0].scenario}, {runs[0].mode} mode: efforts at the actuated joints")
    _save(fig, path)


def torque_figure(runs: list[LoadedRun], path: Path) -> None:
    """Figs. 7-8: commanded efforts (Eq. 6-7) and Cartesian position error under torque control."""
    fig, axes = plt.subplots(3, 2, figsize=(14, 8), sharex=True, layout="constrained")
    for run in runs:
        record = run.record
        style = VARIANT_STYLES.get(run.counterweight, "-")
        label = VARIANT_LABELS.get(run.counterweight, run.counterweight)
        position_error, _ = run.tracking
        for r, j in enumerate(ARM_JOINTS):
            if record.effort_command is not None:
                axes[r, 0].plot(record.t, record.effort_command[:, j], style, color=COLORS["command"], lw=LINE_WIDTH, label=f"commanded, {label}")
            axes[r, 0].set_ylabel(f"u{j + 1} ({run.model.effort_unit(JOINT_NAMES[j])})")
            axes[r, 1].plot(record.t, position_error[:, r], style, color=COLORS["sim"], lw=LINE_WIDTH, label=f"error, {label}")
            axes[r, 1].set_ylabel(f"error {'xyz'[r]} (m)")
    axes[0, 0].set_title("(a) commanded efforts")
    axes[0, 1].set_title("(b) Cartesian position error, reference - actual")
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    axes[0, 0].legend(loc="best", fontsize="small")
    axes[0, 1].legend(loc="best", fontsize="small")
    fig.suptitle(f"{runs[0].scenario}, torque mode (feedback linearisation)")
    _save(fig, path)


def residual_figure(run: LoadedRun, path: Path) -> None:
    """Measured - simulated per joint the run recorded (a joint it did not has no residual), next to
    measured - full model (the model's own floor)."""
    record = run.record
    _, full = _model_efforts(run)
    recorded = [j for j, name in enumerate(JOINT_NAMES) if name in run.metrics.get("measured_joints", JOINT_NAMES)]
    fig, axes = plt.subplots(len(recorded), 1, figsize=(12, 2 * len(recorded)), sharex=True, layout="constrained", squeeze=False)
    for j, ax in zip(recorded, axes[:, 0]):
        residual_sim = record.effort_measured[:, j] - record.effort_sim[:, j]
        residual_model = record.effort_measured[:, j] - full[:, j]
        ax.plot(record.t, residual_sim, color=COLORS["sim"], lw=LINE_WIDTH, label="measured - simulated")
        ax.plot(record.t, residual_model, color=COLORS["model"], lw=LINE_WIDTH, alpha=0.8, label="measured - model (all terms)")
        _robust_ylim(ax, [residual_sim, residual_model])
        ax.axhline(0.0, color="grey", lw=0.5)
        ax.set_ylabel(f"residual {_joint_label(run, j)}")
    axes[0, 0].legend(loc="best", fontsize="small")
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(f"{run.name}: residual efforts")
    _save(fig, path)


# ---------------------------------------------------------------- which figures, from which runs

FIGURES_DIR = "figures"
VELOCITY_VARIANT_ORDER = ("off", "on", "pid")  # the paper's (a) nCW, then (b) wCW
TORQUE_VARIANT_ORDER = ("on", "pid")


def _has_efforts(run: LoadedRun) -> bool:
    return run.record.effort_sim is not None and np.isfinite(run.record.effort_sim).any() and bool(run.record.effort_model)


@dataclass(frozen=True)
class _Plan:
    figure: FigureFile
    draw: Callable[[], None]


#: the plans of the figures being drawn, read by the forked workers (a lambda
#: cannot be sent to a process; a fork inherits it)
_PLANS: list[_Plan] = []


def _draw(index: int) -> int:
    _PLANS[index].draw()
    return index


def build_figures(runs: dict[str, LoadedRun], out_dir: Path, jobs: int = 1) -> list[FigureFile]:
    """Write every figure whose runs are present (in `jobs` forked processes where
    the platform forks); returns them in report order."""
    global _PLANS
    plans = plan_figures(runs, out_dir)
    if jobs > 1 and len(plans) > 1 and "fork" in multiprocessing.get_all_start_methods():
        _PLANS = plans
        try:
            with ProcessPoolExecutor(max_workers=min(jobs, len(plans)), mp_context=multiprocessing.get_context("fork"), initializer=quiet_worker) as pool:
                list(pool.map(_draw, range(len(plans))))
        finally:
            _PLANS = []
    else:
        for plan in plans:
            plan.draw()
    return [plan.figure for plan in plans]


def plan_figures(runs: dict[str, LoadedRun], out_dir: Path) -> list[_Plan]:
    """The figures the runs allow, in report order, each with how to draw it."""
    plans: list[_Plan] = []

    def add(file: str, title: str, caption: str, used: list[LoadedRun], draw) -> None:
        plans.append(_Plan(FigureFile(file, title, caption, tuple(r.name for r in used)), lambda: draw(out_dir / file)))

    for number, scenario in ((2, "rectilinear"), (3, "spiral")):
        run = runs.get(f"{scenario}_kinematic_cw-on")
        if run is not None and run.tracking is not None:
            add(
                f"{FIGURES_DIR}/fig{number}_{scenario}_kinematic_tracking.png",
                f"Kinematic tracking, {scenario} (paper Fig. {number})",
                "Reference (black, dashed) and actual (red) tool-tip position and orientation, with the errors.",
                [run],
                lambda p, run=run: tracking_figure(run, p),
            )
    for number, scenario in ((4, "rectilinear"), (5, "spiral")):
        variants = [runs[n] for cw in VELOCITY_VARIANT_ORDER if (n := f"{scenario}_velocity_cw-{cw}") in runs and _has_efforts(runs[n])]
        if variants:
            add(
                f"{FIGURES_DIR}/fig{number}_{scenario}_velocity_efforts.png",
                f"Simulated vs model efforts, {scenario}, velocity mode (paper Fig. {number})",
                "Identified model restricted to the simulated terms (blue) and simulated efforts (red), J1..J3, per counterweight variant. "
                "Vertical scale: 0.1-99.9th percentiles of the curves (the start's one-sample acceleration spike runs off-scale).",
                variants,
                lambda p, v=variants: efforts_figure(v, p, with_measured=False),
            )
    variants = [runs[n] for cw in VELOCITY_VARIANT_ORDER if (n := f"replay-two_velocity_cw-{cw}") in runs and _has_efforts(runs[n])]
    if variants:
        add(
            f"{FIGURES_DIR}/fig6_replay-two_efforts.png",
            "Model vs simulated vs measured efforts on the excitation replay (paper Fig. 6)",
            "Measured (green), model restricted to the simulated terms (blue), full identified model (blue dashed) and simulated (red) efforts, J1..J3. "
            "Vertical scale: 0.1-99.9th percentiles of the curves.",
            variants,
            lambda p, v=variants: efforts_figure(v, p, with_measured=True),
        )
    for number, scenario in ((7, "rectilinear"), (8, "spiral")):
        variants = [runs[n] for cw in TORQUE_VARIANT_ORDER if (n := f"{scenario}_torque_cw-{cw}") in runs and runs[n].tracking is not None]
        if variants:
            add(
                f"{FIGURES_DIR}/fig{number}_{scenario}_torque_control.png",
                f"Torque control, {scenario} (paper Fig. {number})",
                "Commanded efforts (purple) and Cartesian position error (red); solid: ideal tendon (cw-on), dotted: PID mirror (cw-pid).",
                variants,
                lambda p, v=variants: torque_figure(v, p),
            )
    for name in sorted(runs):
        run = runs[name]
        if run.mode == "velocity" and run.counterweight == "on" and run.record.effort_measured is not None and _has_efforts(run):
            add(
                f"{FIGURES_DIR}/residual_{name}.png",
                f"Residual efforts, {name}",
                "Measured minus simulated efforts (red) per joint, next to measured minus the full identified model (blue): what the simulation misses beyond the model's own error.",
                [run],
                lambda p, run=run: residual_figure(run, p),
            )
    return plans

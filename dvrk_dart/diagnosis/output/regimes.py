"""Where the gap is: residual statistics per motion regime, and residual figures."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.metrics import rms

#: |dq| below this fraction of the run's largest |dq| counts as "near zero"
NEAR_ZERO_VELOCITY_FRACTION = 0.05
#: quantile bins of the acceleration and pose regimes (terciles)
REGIME_QUANTILES = (1 / 3, 2 / 3)
#: samples plotted per figure at most (thinned evenly): scatter plots of 6000
#: points say no more than 3000 and take twice as long
MAX_PLOTTED_SAMPLES = 3000


def residual_regimes(state: ProcessedRun, residual: np.ndarray, model: PsmModel) -> pd.DataFrame:
    """Residual statistics per joint and motion regime (tidy: one row per
    joint, regime and bin): velocity sign / near zero, acceleration level,
    insertion depth q3 and pitch angle q2."""
    rows = []
    q3, q2 = state.q[:, JOINT_NAMES.index("q3")], state.q[:, JOINT_NAMES.index("q2")]

    def tercile_bins(values: np.ndarray, labels: tuple[str, str, str]) -> list[tuple[str, np.ndarray, float, float]]:
        edges = np.quantile(values, REGIME_QUANTILES)
        masks = [values <= edges[0], (values > edges[0]) & (values <= edges[1]), values > edges[1]]
        bounds = [(values.min(), edges[0]), (edges[0], edges[1]), (edges[1], values.max())]
        return [(lab, m, lo, hi) for lab, m, (lo, hi) in zip(labels, masks, bounds)]

    pose_bins = {
        "insertion_depth_q3": tercile_bins(q3, ("shallow", "middle", "deep")),
        "pitch_q2": tercile_bins(q2, ("low", "middle", "high")),
    }
    for j, joint in enumerate(JOINT_NAMES):
        if not state.measured[j]:
            continue
        v, a, r = state.dq[:, j], state.ddq[:, j], residual[:, j]
        near = NEAR_ZERO_VELOCITY_FRACTION * np.max(np.abs(v))
        regimes = {
            "velocity": [
                ("negative", v < -near, -np.inf, -near),
                ("near_zero", np.abs(v) <= near, -near, near),
                ("positive", v > near, near, np.inf),
            ],
            "acceleration": tercile_bins(np.abs(a), ("low", "medium", "high")),
            **pose_bins,
        }
        for regime, bins in regimes.items():
            for label, mask, lo, hi in bins:
                x = r[mask]
                rows.append(
                    {
                        "joint": joint,
                        "unit": model.effort_unit(joint),
                        "regime": regime,
                        "bin": label,
                        "bin_lower": float(lo),
                        "bin_upper": float(hi),
                        "samples": int(mask.sum()),
                        "mean": float(x.mean()) if len(x) else math.nan,
                        "std": float(x.std()) if len(x) else math.nan,
                        "rms": float(rms(x)) if len(x) else math.nan,
                    }
                )
    return pd.DataFrame(rows)


def plot_residuals(state: ProcessedRun, residual: np.ndarray, folder: Path | str, model: PsmModel, label: str = "residual",
                   run: str = "") -> list[Path]:
    """One figure per joint: the residual against q, dq and ddq of that joint (`run`: its name, in the title)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dvrk_dart.io.atomic import atomic_path

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    keep = np.linspace(0, len(state) - 1, min(len(state), MAX_PLOTTED_SAMPLES)).astype(int)
    paths = []
    for j, joint in enumerate(JOINT_NAMES):
        if not state.measured[j]:  # a joint the run did not record has no figure
            continue
        fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharey=True)
        pu = model.position_unit(joint)
        for ax, x, xlabel in zip(axes, (state.q, state.dq, state.ddq), (f"{joint} ({pu})", f"d{joint} ({pu}/s)", f"dd{joint} ({pu}/s²)")):
            ax.scatter(x[keep, j], residual[keep, j], s=2, alpha=0.4, c=state.dq[keep, j] > 0, cmap="coolwarm")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_xlabel(xlabel)
        axes[0].set_ylabel(f"{label} ({model.effort_unit(joint)})")
        fig.suptitle(f"{label} of {joint}{f' on {run}' if run else ''} (colour: velocity sign)")
        fig.tight_layout()
        target = folder / f"{label}_{joint}.png"
        with atomic_path(target) as tmp:
            fig.savefig(tmp, format="png", dpi=90)
        plt.close(fig)
        paths.append(target)
    return paths


#: the joints of the figure over one period (the arm's main joints)
PERIOD_FIGURE_JOINTS = 3


def plot_period(state: ProcessedRun, before: np.ndarray, after: np.ndarray, floor, path: Path, model: PsmModel, run: str = "",
                recorded=None) -> Path:
    """The residual before and after the effects over the run's first period,
    one panel per main joint the diagnosis's runs all recorded (`recorded`, default the run's),
    ± the session floor as a band (when measured)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dvrk_dart.io.atomic import atomic_path

    n = min(len(state), state.first_period_samples())
    t = state.t[:n] - state.t[0]
    shown = [j for j in range(PERIOD_FIGURE_JOINTS) if state.measured[j] and (recorded is None or recorded[j])] or [0]
    fig, axes = plt.subplots(len(shown), 1, figsize=(11, 2.4 * len(shown)), sharex=True, squeeze=False)
    axes = axes[:, 0]
    for j, ax in zip(shown, axes):
        if floor is not None:
            ax.axhspan(-floor[j], floor[j], color="0.85", label="± session floor")
        ax.plot(t, before[:n, j], color="tab:red", lw=0.8, alpha=0.6, label="before")
        ax.plot(t, after[:n, j], color="tab:blue", lw=1.0, label="after")
        ax.set_ylabel(f"{JOINT_NAMES[j]} ({model.effort_unit(JOINT_NAMES[j])})")
    axes[0].legend(loc="upper right", ncol=3, fontsize=8)
    axes[-1].set_xlabel("time in the period (s)")
    fig.suptitle(f"residual (measured - simulated) over one period{f' of {run}' if run else ''}")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
    return path

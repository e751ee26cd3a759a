"""A measured run, the project's one type for it (io/ leaf): named columns
t, q1..q7, dq1..dq7, tau1..tau7 at a uniform rate, and the checks of its
content that every reader (CSV, ROS bag) applies: joint ranges, the rate
against the velocity column, glitched rows."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.period import moving_joints, spanning_columns
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.model_file import load_model
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS, column_names
from dvrk_dart.paths import MODELS_DIR, PROJECT_DIR

MANIFEST_FILE = PROJECT_DIR / "reference_data" / "manifest.toml"

CSV_COLUMNS = column_names("q") + column_names("dq") + column_names("tau")


@cache
def manifest() -> dict:
    return tomllib.loads(MANIFEST_FILE.read_text())


def sample_rate_hz() -> float:
    """The default rate of a measured run's rows (the reference data's, 200 Hz)."""
    return float(manifest()["sample_rate_hz"])


#: a CSV's velocity column must match the finite differences of its positions
#: at its rate to this fraction (the half-speed run read at 200 Hz: 1.0 off)
RATE_TOLERANCE = 0.1


#: where a rate comes from when a CSV's t column gives it (io.reference_data.rate_of)
TIME_COLUMN_SOURCE = "its time column"


#: rows repeating the row before, beyond this share, say why a rate seems to fit (the MTM's logs repeat 13-15 %)
REPEATED_ROWS_SHARE = 0.4


def check_rate(q: np.ndarray, dq: np.ndarray, rate_hz: float, where: str, source: str) -> None:
    """The velocity column against finite differences of the positions at the
    rate: a mismatch names the rate that fits. Each joint's least-squares
    scale is biased low by its velocity column's noise (a noisy wrist joint:
    7 % low), so the clock is the median of the upper half of the joints'
    scales: the cleanest joints, and still no single odd column."""
    differences = np.gradient(q, 1.0 / rate_hz, axis=0)
    moving = (np.sum(differences**2, axis=0) > 0) & (np.sum(dq**2, axis=0) > 0)
    if not moving.any():
        return  # a still arm says nothing of its rate
    by_joint = np.full(q.shape[1], np.nan)
    by_joint[moving] = np.sum(differences * dq, axis=0)[moving] / np.sum(dq**2, axis=0)[moving]
    if np.any(np.abs(by_joint[moving] - 1.0) <= RATE_TOLERANCE):
        return  # a rate scales every joint alike: where one agrees, the others' columns are off (check_velocity_columns)
    scales = np.sort(by_joint[moving])
    scale = float(np.median(scales[len(scales) // 2:]))
    if not scale > 0:
        raise DvrkDartError(f"{where}: the velocity column runs against the positions' finite differences (rows in reverse order, "
                            "or the velocities' sign flipped)")
    if abs(scale - 1.0) > RATE_TOLERANCE:
        fits = rate_hz / scale
        fix = (f"correct the time column, or remove it and give --rate {fits:.4g}" if source == TIME_COLUMN_SOURCE
               else f"--rate {fits:.4g}; or a time column t in s, where runs of other rates are in the command")
        unit = next((f"; a time column in {name}? give it in seconds" for name, factor in (("ms", 1e3), ("µs", 1e6), ("ns", 1e9))
                     if source == TIME_COLUMN_SOURCE and abs(fits / (rate_hz * factor) - 1.0) < RATE_TOLERANCE), "")
        fix += unit
        repeated = float(np.mean(np.all(q[1:] == q[:-1], axis=1)))
        if repeated > REPEATED_ROWS_SHARE:  # the finite differences halve: a rate would "fit" a log written twice per sample
            fix = f"{repeated:.0%} of the rows repeat the one before: each sample written twice? remove the repeats, not the rate; or {fix}"
        raise DvrkDartError(f"{where}: at {rate_hz:g} Hz ({source}) the positions' finite differences are {scale:.3g} times the velocity "
                            f"column; the rate that fits is {fits:.4g} Hz ({fix})")


#: a moving joint's velocity column against its positions' finite differences:
#: a correlation below -this is a flipped sign (refused: noise does not make
#: it); below +this, or a scale outside this factor of 1, earns a note (the
#: reference runs' noisiest, the MTM's wrist: 0.80 and 0.73; a velocity as
#: noisy as its signal, or a slow drift, reads lower and is still a log)
VELOCITY_CORRELATION_MIN = 0.5
VELOCITY_SCALE_FACTOR = 2.0


def check_velocity_columns(q: np.ndarray, dq: np.ndarray, rate_hz: float, where: str) -> list[str]:
    """Each moving joint's velocity column against its own positions' finite
    differences (check_rate reads the clock from the cleanest joints: one
    broken column passed it and skewed every upstream figure of its joint):
    a zero or sign-flipped column is refused, one that hardly follows its
    positions gets a note (returned). A held joint (servo error, encoder
    counts: io/period.moving_joints) is not checked: its velocity is noise."""
    differences = np.gradient(q, 1.0 / rate_hz, axis=0)
    notes = []
    for j in np.flatnonzero(moving_joints(q) & spanning_columns(q)):
        name, position = CSV_COLUMNS[N_JOINTS + j], CSV_COLUMNS[j]
        if not np.any(dq[:, j]):
            raise DvrkDartError(f"{where}: {name} is zero while {position} moves: the velocity column was not recorded")
        correlation = float(np.corrcoef(differences[:, j], dq[:, j])[0, 1])
        scale = float(differences[:, j] @ dq[:, j] / (dq[:, j] @ dq[:, j]))
        figures = f"correlation {correlation:.2f}, scale {scale:.3g}"
        if correlation < -VELOCITY_CORRELATION_MIN:
            raise DvrkDartError(f"{where}: {name} runs against the finite differences of {position} ({figures}): its sign flipped?")
        if correlation < VELOCITY_CORRELATION_MIN or not 1 / VELOCITY_SCALE_FACTOR <= scale <= VELOCITY_SCALE_FACTOR:
            notes.append(f"{where}: {name} hardly follows the finite differences of {position} at {rate_hz:g} Hz ({figures}): "
                         "a noisy, lagged or misplaced velocity column weighs on the upstream processing's figures of "
                         f"{position} (the periodic processing derives velocities from the positions)")
    return notes


#: a row stands out as a glitch when its disagreement is this many times the
#: 99th percentile of the column's (the reference runs' largest: 3.7 times)
GLITCH_RATIO = 30.0
#: the effort resolution (N·m or N): a gap, a constant or a residual below it is nothing to explain (the
#: diagnosis's joint weights' floor and words), nor a glitch (a noise-free simulated effort's Coulomb step of
#: 0.005 N·m stood out of a 99th percentile of 0)
EFFORT_RESOLUTION = 1e-3


def _outlier_row(x: np.ndarray, floor: float = np.finfo(float).tiny) -> tuple[int, int] | None:
    """(row, column) of the largest value of |x| if it exceeds GLITCH_RATIO times its column's 99th percentile (at least `floor`)."""
    scale = np.maximum(np.percentile(x, 99, axis=0), floor)
    rows = np.argmax(x, axis=0)  # each column's worst row, then the column that stands out most
    with np.errstate(over="ignore"):
        ratio = x[rows, np.arange(x.shape[1])] / scale
    column = int(np.argmax(ratio))
    return (int(rows[column]), column) if ratio[column] > GLITCH_RATIO else None


def check_glitches(values: np.ndarray, rate_hz: float, where: str, velocities: bool = True) -> None:
    """One bad row (a glitched value, rows out of order) refused with its row
    number: a velocity that disagrees with the positions' finite differences
    (`velocities`), or an effort that stands out of its neighbours, far more
    than anywhere else."""
    q, dq, tau = values[:, :N_JOINTS], values[:, N_JOINTS : 2 * N_JOINTS], values[:, 2 * N_JOINTS :]
    velocity = _outlier_row(np.abs(dq - np.gradient(q, 1.0 / rate_hz, axis=0))) if velocities else None
    if velocity is not None:
        row, j = velocity
        raise DvrkDartError(f"{where}: row {row + 1}: the velocity column {CSV_COLUMNS[N_JOINTS + j]} ({dq[row, j]:.6g}) and the finite "
                            f"differences of {CSV_COLUMNS[j]} disagree {GLITCH_RATIO:g} times more than on 99 % of the rows "
                            "(a glitched value, or rows out of order)")
    effort = _outlier_row(np.abs(tau[1:-1] - 0.5 * (tau[:-2] + tau[2:])), EFFORT_RESOLUTION)
    if effort is not None:
        row, j = effort
        raise DvrkDartError(f"{where}: row {row + 2}, column {CSV_COLUMNS[2 * N_JOINTS + j]}: {tau[row + 1, j]:.6g} stands out of its "
                            f"neighbouring rows {GLITCH_RATIO:g} times more than on 99 % of the rows (a glitched value)")


@dataclass(frozen=True)
class MeasuredRun:
    """A measured run: named, typed columns t, q1..q7, dq1..dq7, tau1..tau7.
    `measured`: the joints the run recorded; the others' columns hold zeros
    (the arm held at zero) and carry no figure, fit or cutoff."""

    path: Path
    data: pd.DataFrame
    model: PsmModel  # the arm it was recorded on: its coordinates, units and processing facts
    measured: tuple[str, ...] = JOINT_NAMES

    @property
    def measured_mask(self) -> np.ndarray:
        """(7,) bool: which of q1..q7 the run recorded."""
        return np.array([name in self.measured for name in JOINT_NAMES])

    @property
    def name(self) -> str:
        return self.path.stem

    @property
    def t(self) -> np.ndarray:
        return self.data["t"].to_numpy()

    @property
    def rate_hz(self) -> float:
        """Rows per second (checked against the velocity column when loaded)."""
        return float(1.0 / (self.data["t"].iat[1] - self.data["t"].iat[0]))

    @property
    def q(self) -> np.ndarray:
        return self.data[column_names("q")].to_numpy()

    @property
    def dq(self) -> np.ndarray:
        return self.data[column_names("dq")].to_numpy()

    @property
    def tau(self) -> np.ndarray:
        return self.data[column_names("tau")].to_numpy()

    def __len__(self) -> int:
        return len(self.data)


def check_joint_ranges(q: np.ndarray, where: str | Path, model: PsmModel) -> None:
    """Positions within the model's joint ranges (the simulator's own limits)."""
    outside = (q < model.joint_lower) | (q > model.joint_upper)
    if outside.any():
        row, j = np.argwhere(outside)[0]
        raise DvrkDartError(
            f"{where}: row {row + 1}, column {CSV_COLUMNS[j]}: {float(q[row, j])!r} outside the joint range "
            f"[{float(model.joint_lower[j])!r}, {float(model.joint_upper[j])!r}]" + _other_arm_fitting(q, model)
        )


def _other_arm_fitting(q: np.ndarray, model: PsmModel) -> str:
    """' (... --arm-model X)' when every row lies in the joint ranges of another arm model."""
    for folder in sorted(p for p in MODELS_DIR.iterdir() if (p / f"{p.name}.toml").is_file()):
        model_file = folder / f"{folder.name}.toml"
        if model_file.resolve() == model.source.resolve():
            continue
        other = load_model(model_file)
        if np.all((q >= other.joint_lower) & (q <= other.joint_upper)):
            return f" (every row fits the {folder.name} arm model's ranges: --arm-model {folder.name})"
    return ""

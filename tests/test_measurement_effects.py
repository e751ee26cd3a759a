"""Effects of the measurement on real runs: the real "one"'s efforts logged 10 ms late against "one" itself.

The time shift's column is the rate of what the arm exerts: against a baseline of the same motion, the baseline's
measured effort, with the friction reversals the simulation lacks. On the simulated effort's rate the upstream
diagnosis read 0.0030 s with five more effects (a DART run delayed cannot show it: its rate is the simulation's)."""

import numpy as np
import pytest

from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.io.reference_data import resolve_run
from arms import PSM_ARM

DELAY_SAMPLES = 2  # 10 ms at the run's 200 Hz


def test_a_real_runs_delay_is_read_against_its_baseline(tmp_path):
    rows = np.loadtxt(resolve_run("one"), delimiter=",")
    late = rows.copy()
    late[DELAY_SAMPLES:, 14:21] = rows[:-DELAY_SAMPLES, 14:21]  # efforts: q1..q7, dq1..dq7, tau1..tau7
    # positions with their own noise: two recordings of one motion never agree sample for sample
    late[:, :7] += np.random.default_rng(3).standard_normal((len(rows), 7)) * 2e-5
    paths = {name: tmp_path / f"{name}.csv" for name in ("late", "baseline")}
    np.savetxt(paths["late"], late[DELAY_SAMPLES:], delimiter=",")
    np.savetxt(paths["baseline"], rows[DELAY_SAMPLES:], delimiter=",")
    result = diagnose(str(paths["late"]), baseline=str(paths["baseline"]), arm=PSM_ARM, figures=False, processing="upstream")
    first = result["effects"][0]
    assert first["name"] == "time_shift" and first["parameters"]["delay_s"] == pytest.approx(0.010, rel=0.1), first
    assert [e["name"] for e in result["effects"] if e["selected"]] == ["time_shift"]

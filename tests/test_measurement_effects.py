"""Effects of the measurement on real runs: a real run's efforts logged 10 ms late against the run itself, on
both PSM datasets ("one": 21 columns; 2018 test1: joints 1..3, 9 columns).

The time shift's column is the rate of what the arm exerts: against a baseline of the same motion, the baseline's
measured effort, with the friction reversals the simulation lacks. On the simulated effort's rate the upstream
diagnosis read 0.0030 s with five more effects on "one" and 0.0019 s with three on 2018 test1 (a DART run delayed
cannot show it: its rate is the simulation's)."""

import numpy as np
import pytest

from dvrk_dart.diagnosis.diagnose import diagnose
from dvrk_dart.io.reference_data import resolve_run
from arms import PSM_ARM

DELAY_SAMPLES = 2  # 10 ms at the runs' 200 Hz


@pytest.mark.parametrize("run, joints", [("one", 7), ("2018-test1", 3)])
def test_a_real_runs_delay_is_read_against_its_baseline(run, joints, tmp_path):
    rows = np.loadtxt(resolve_run(run), delimiter=",")  # q, dq, tau of `joints` joints each
    late = rows.copy()
    late[DELAY_SAMPLES:, 2 * joints:] = rows[:-DELAY_SAMPLES, 2 * joints:]
    # positions with their own noise: two recordings of one motion never agree sample for sample
    late[:, :joints] += np.random.default_rng(3).standard_normal((len(rows), joints)) * 2e-5
    paths = {name: tmp_path / f"{name}.csv" for name in ("late", "baseline")}
    np.savetxt(paths["late"], late[DELAY_SAMPLES:], delimiter=",")
    np.savetxt(paths["baseline"], rows[DELAY_SAMPLES:], delimiter=",")
    result = diagnose(str(paths["late"]), baseline=str(paths["baseline"]), arm=PSM_ARM, figures=False, processing="upstream")
    first = result["effects"][0]
    assert first["name"] == "time_shift" and first["parameters"]["delay_s"] == pytest.approx(0.010, rel=0.1), first
    assert [e["name"] for e in result["effects"] if e["selected"]] == ["time_shift"]

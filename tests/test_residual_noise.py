"""The noise a periodic residual carries: the efforts' own, and the positions' through the arm's model (the
simulation is driven by the projected positions, whose noise the accelerations raise by (k w)^2 at harmonic k)."""

import numpy as np
import pandas as pd
import pytest

from dvrk_dart.diagnosis.fit.diagnosis_runs import DiagnosisRun
from dvrk_dart.io.measured_run import CSV_COLUMNS, MeasuredRun
from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import process_periodic
from dvrk_dart.metrics import rms


def test_a_periodic_residual_s_noise_is_the_efforts_and_the_positions(arm):
    """The model's efforts along "one"'s periodic series, the efforts' and the positions' noise added at the levels
    measured on "one": the residual against the model is that noise alone, and its RMS on J1..J3 is what
    `noise_energy` says (to 20 %); the efforts' noise alone (the accounting before) is under 80 % of it on J1 and J2."""
    real = process_periodic(load_run(resolve_run("one"), arm.model))
    levels = real.periodic.summary()
    rng = np.random.default_rng(1)
    q = real.q + rng.standard_normal(real.q.shape) * np.nan_to_num(np.array(levels["position_noise_per_sample_rms"], dtype=float))
    tau = arm.identified.predict(real.q, real.dq, real.ddq)
    tau += rng.standard_normal(tau.shape) * np.nan_to_num(np.array(levels["noise_per_sample_rms"], dtype=float))
    data = pd.DataFrame(np.hstack([q, real.dq, tau]), columns=CSV_COLUMNS)
    data.insert(0, "t", real.t - real.t[0])
    state = process_periodic(MeasuredRun(arm.model.source, data, arm.model))
    run = DiagnosisRun("synthetic", state, state.in_band(arm.identified.predict(state.q, state.dq, state.ddq)))

    measured = rms(run.residual)[:3]
    assert np.sqrt(run.noise_energy(arm))[:3] == pytest.approx(measured, rel=0.2)
    efforts_alone = np.nan_to_num(state.periodic.effort_noise.projected_rms)[:3]
    assert np.all(efforts_alone[:2] < 0.8 * measured[:2])

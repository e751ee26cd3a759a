"""The diagnosis tests' real state: the first two upstream periods of trajectory
"one", and the noise the identified model's residual leaves on it (imported as
fixtures by the modules that use them)."""

import pytest

from dvrk_dart.io.reference_data import load_run, resolve_run
from dvrk_dart.io.signal import process
from dvrk_dart.metrics import rms
from arms import PSM

FIRST_PERIOD_SAMPLES = PSM.processing.first_period_samples
SEGMENT_SAMPLES = 2 * FIRST_PERIOD_SAMPLES


@pytest.fixture(scope="module")
def segment():
    return process(load_run(resolve_run("one"), PSM)).head(SEGMENT_SAMPLES)


@pytest.fixture(scope="module")
def noise_rms(arm, segment):
    """RMS per joint of the real residual left by the full identified model."""
    return rms(segment.tau - arm.identified.predict(segment.q, segment.dq, segment.ddq, "all"))

"""Shared fixtures: the arm (model, parameters, Pinocchio model) and the
reference runs, loaded once per test session."""

import numpy as np
import pytest

from dvrk_dart.io.reference_data import RUNS, load_run, resolve_run
from dvrk_dart.io.signal import process
from arms import PSM, PSM_ARM  # noqa: F401


@pytest.fixture(scope="session")
def arm():
    return PSM_ARM


@pytest.fixture(scope="session")
def model(arm):
    return arm.model


@pytest.fixture(scope="session")
def params(arm):
    return arm.params


@pytest.fixture(scope="session")
def identified(arm):
    return arm.identified


@pytest.fixture(scope="session")
def processed_two():
    return process(load_run(resolve_run("two"), PSM))


@pytest.fixture(scope="session")
def data_ranges():
    """(lower, upper) of the joint positions seen in all the measured runs."""
    qs = np.vstack([load_run(resolve_run(name), PSM).q for name, file in RUNS.items() if not file.startswith("mtm/")])
    return qs.min(axis=0), qs.max(axis=0)


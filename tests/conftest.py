"""Shared fixtures: the arm (model, parameters, Pinocchio model) and the
reference runs, loaded once per test session."""

import numpy as np
import pytest

from dvrk_dart.io.reference_data import RUNS, load_run, resolve_run
from dvrk_dart.io.signal import process
from arms import PSM, PSM_ARM  # noqa: F401


#: the modules that keep a worker longest (measured totals 26-90 s each): collected
#: first, so that `make test`'s workers (xdist, a module each) start them
#: first and do not end waiting on one of them
LONGEST_FIRST = ("test_validation.py", "test_validation_payload.py", "test_diagnosis.py", "test_payload_weights.py", "test_blind_suite.py", "test_periodic_payload.py",
                 "test_identification.py", "test_diagnose_combinations.py", "test_pipeline.py", "test_periodic_designs.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest in their order


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


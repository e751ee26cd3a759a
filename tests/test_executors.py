"""Batches on the local process pool and on Ray give the same runs; a failed
task is reported by name and the others land."""

import json

import pytest

from dvrk_dart.runs.campaign import config_name, run_campaign
from dvrk_dart.runs.config import RunConfig
from dvrk_dart.runs.executors import run_tasks
from arms import PSM, PSM_ARM  # noqa: F401

#: fields that measure the machine, not the run
TIMING_FIELDS = {"wall_time_s", "realtime_factor"}
CAMPAIGN = [
    RunConfig("rectilinear", "kinematic", duration_s=0.2),
    RunConfig("rectilinear", "velocity", duration_s=0.2),
    RunConfig("spiral", "torque", duration_s=0.2),
    RunConfig("replay", "velocity", "off", measured="two", duration_s=0.5),
]


def _metrics(folder, config):
    metrics = json.loads((folder / config_name(config) / "metrics.json").read_text())
    return {k: v for k, v in metrics.items() if k not in TIMING_FIELDS}


@pytest.fixture(scope="module", autouse=True)
def ray_cluster():
    """One local Ray cluster for the module's tests (the executor starts its own only where none runs, and
    then stops it: its start is what a Ray test would otherwise spend most of its time on)."""
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def test_a_campaign_on_ray_gives_the_local_executors_metrics(tmp_path):
    local = run_campaign(CAMPAIGN, tmp_path / "local", jobs=2, executor="local")
    ray = run_campaign(CAMPAIGN, tmp_path / "ray", jobs=2, executor="ray")
    assert not local["failures"] and not ray["failures"]
    assert sorted(ray["ran"]) == sorted(local["ran"]) == sorted(config_name(c) for c in CAMPAIGN)
    for config in CAMPAIGN:
        assert _metrics(tmp_path / "ray", config) == _metrics(tmp_path / "local", config)
        assert {p.name for p in (tmp_path / "ray" / config_name(config)).iterdir()} >= {"run.mcap", "run.rrd", "config.json", "inputs.sha256"}


@pytest.mark.parametrize("executor", ["local", "ray"])
def test_a_failed_task_is_reported_and_the_others_land(executor):
    # a library function, importable by every worker (a test module is not on Ray's path)
    results = {task: (result, error) for task, result, error in run_tasks(json.loads, ["10", "{", "30"], executor, jobs=2)}
    assert results["10"] == (10, None) and results["30"] == (30, None)
    assert results["{"][0] is None and results["{"][1].startswith("JSONDecodeError: Expecting property name")


def test_a_failed_campaign_run_is_named_and_the_others_land_on_ray(tmp_path):
    good, bad = CAMPAIGN[0], RunConfig("replay", "velocity", measured="two", duration_s=100.0)  # longer than the measured run
    summary = run_campaign([good, bad], tmp_path, jobs=2, executor="ray")
    assert summary["ran"] == [config_name(good)] and list(summary["failures"]) == [config_name(bad)]
    assert "--duration: 100 s outside" in summary["failures"][config_name(bad)]


def test_the_diagnosis_replays_in_a_batch_give_the_replays_one_by_one():
    import numpy as np

    from dvrk_dart.diagnosis.fit.batch import BatchSimulate
    from dvrk_dart.io.reference_data import load_run, resolve_run
    from dvrk_dart.io.signal import process
    from dvrk_dart.runs.replay import simulate_efforts
    from dvrk_dart.sim.config import SimConfig

    arm = PSM_ARM
    state = process(load_run(resolve_run("two"), PSM)).head(500)  # 2.5 s
    configs = [SimConfig(), SimConfig(friction=True, offsets=True)]
    batch = BatchSimulate(arm, "local", jobs=2)
    batch.prefetch([(c, state) for c in configs])
    assert len(batch._done) == 2
    for config in configs:
        assert np.array_equal(batch(config, state), simulate_efforts(arm, config, state))
    assert not np.allclose(batch(configs[0], state), batch(configs[1], state))  # the two configs really differ


def test_an_unreachable_ray_address_fails_in_seconds(tmp_path, capsys):
    """Nothing listens on port 1: one line, exit 2, before any work (ray.init would retry for minutes)."""
    import time

    from dvrk_dart.cli import main

    start = time.perf_counter()
    for argv in (["uncertainty", "--measured", "two", "--samples", "2", "--out", str(tmp_path / "u")],
                 ["validate", "--out", str(tmp_path / "v"), "--report", str(tmp_path / "r")]):
        assert main([*argv, "--executor", "ray", "--ray-address", "127.0.0.1:1"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--ray-address" in err[0] and "no Ray head" in err[0]
    assert time.perf_counter() - start < 30.0
    assert not any(tmp_path.iterdir())


def test_replayed_residuals_come_back_in_the_tasks_order():
    """A long replay given first finishes after a short one: the residuals
    still line up with their tasks (the refit's published and refitted arms
    are told apart by position)."""
    from dvrk_dart.diagnosis.fit.batch import replayed_residuals
    from dvrk_dart.io.reference_data import load_run, resolve_run
    from dvrk_dart.io.signal import process
    from dvrk_dart.sim.config import SimConfig

    arm, state = PSM_ARM, process(load_run(resolve_run("two"), PSM))
    lengths = [3000, 100]  # 15 s, then 0.5 s
    residuals = replayed_residuals([(arm, SimConfig(), state.head(n)) for n in lengths], "local", jobs=2)
    assert [len(r) for r in residuals] == lengths


def _build_slowly(folder):
    """A task that builds an output folder for a minute (a worker's run folder)."""
    import time

    from dvrk_dart.io.outputs import building_folder

    with building_folder(folder, "run") as building:
        (building / "half.txt").write_text("half")
        time.sleep(60)


def test_workers_ended_mid_task_remove_the_folders_they_were_building(tmp_path):
    """A validate stopped by SIGTERM said "partial outputs removed" and left its workers' .building folders."""
    import time
    from concurrent.futures import ProcessPoolExecutor

    from dvrk_dart.runs.executors import _in_worker, _stop, quiet_worker

    pool = ProcessPoolExecutor(max_workers=2, initializer=quiet_worker)
    for name in ("a", "b"):
        pool.submit(_in_worker, _build_slowly, tmp_path / name)
    deadline = time.monotonic() + 30
    while len(list(tmp_path.glob(".*.building-*"))) < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(list(tmp_path.glob(".*.building-*"))) == 2
    started = time.monotonic()
    _stop(pool, finished=False)
    assert not list(tmp_path.iterdir()) and time.monotonic() - started < 10

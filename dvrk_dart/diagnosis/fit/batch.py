"""The diagnosis's re-simulations as a batch on an executor (`--executor
local|ray`): the replays before the effects (one per run) and after them are
independent, so `prefetch` runs each group at once and the diagnosis's
`simulate(config, state)` calls then read the results."""

from __future__ import annotations

import hashlib

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.signal import ProcessedRun
from dvrk_dart.io.arm import Arm
from dvrk_dart.runs.executors import run_tasks
from dvrk_dart.sim.config import SimConfig


def replay_task(task: tuple[Arm, SimConfig, ProcessedRun]):
    """One DART velocity replay: (arm, config, state) -> efforts (a task an executor can ship)."""
    from dvrk_dart.runs.replay import simulate_efforts

    return simulate_efforts(*task)


def replayed_residuals(tasks: list, executor: str = "local", jobs: int = 2, ray_address: str | None = None, what: str = "replays") -> list[np.ndarray]:
    """measured - replayed (in the run's band) of each (arm, config, state) task, in the tasks' order."""
    position = {id(task): k for k, task in enumerate(tasks)}  # the executor yields them as they finish
    residuals = [None] * len(tasks)
    for task, efforts, error in run_tasks(replay_task, tasks, executor, jobs, ray_address, desc=what, unit="replay"):
        if error is not None:
            raise DvrkDartError(f"{what}: a replay failed ({error})")
        state = task[2]
        residuals[position[id(task)]] = state.tau - state.in_band(np.asarray(efforts, dtype=float))
    return residuals


def motion_key(state: ProcessedRun) -> str:
    """What a velocity replay reads of a run (its times, positions and
    velocities), as a digest: two loads of one file replay alike."""
    digest = hashlib.blake2b(digest_size=16)
    for array in (state.t, state.q, state.dq):
        digest.update(np.ascontiguousarray(array, dtype=float).tobytes())
    return digest.hexdigest()


class BatchSimulate:
    """simulate(config, state) -> efforts: the DART velocity replay, served
    from the replays already run (`prefetch`'s batches, earlier calls) of the
    same motion and config, else run here. One instance serves several
    diagnoses of the same runs (the blind suite's, with and without a
    baseline) without replaying a run twice."""

    def __init__(self, arm: Arm, executor: str = "local", jobs: int = 2, ray_address: str | None = None):
        self.arm, self.executor, self.jobs, self.ray_address = arm, executor, jobs, ray_address
        self._done: dict[tuple[SimConfig, str], np.ndarray] = {}

    def prefetch(self, pairs: list[tuple[SimConfig, ProcessedRun]]) -> None:
        todo = {(config, motion_key(state)): state for config, state in pairs}
        todo = {key: state for key, state in todo.items() if key not in self._done}
        if len(todo) < 2:  # nothing to run side by side
            return
        tasks = [(self.arm, config, state) for (config, _), state in todo.items()]
        for (_, config, state), efforts, error in run_tasks(replay_task, tasks, self.executor, self.jobs, self.ray_address,
                                                              desc="diagnosis replays", unit="replay"):
            if error is not None:
                raise DvrkDartError(f"diagnosis: a re-simulation failed ({error})")
            self._done[(config, motion_key(state))] = _read_only(efforts)

    def __call__(self, config: SimConfig, state: ProcessedRun):
        from dvrk_dart.runs.replay import simulate_efforts

        key = (config, motion_key(state))
        if key not in self._done:
            self._done[key] = _read_only(simulate_efforts(self.arm, config, state))
        return self._done[key]


def _read_only(efforts) -> np.ndarray:
    """A replay's efforts as served to every caller: not to be changed in place."""
    array = np.array(efforts, dtype=float)
    array.flags.writeable = False
    return array

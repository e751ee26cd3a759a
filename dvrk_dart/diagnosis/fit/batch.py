"""The diagnosis's re-simulations as a batch on an executor (`--executor
local|ray`): the replays before the effects (one per run) and after them are
independent, so `prefetch` runs each group at once and the diagnosis's
`simulate(config, state)` calls then read the results."""

from __future__ import annotations

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


class BatchSimulate:
    """simulate(config, state) -> efforts: the DART velocity replay, served
    from the batches `prefetch` ran, else run here."""

    def __init__(self, arm: Arm, executor: str = "local", jobs: int = 2, ray_address: str | None = None):
        self.arm, self.executor, self.jobs, self.ray_address = arm, executor, jobs, ray_address
        self._done: dict[tuple[SimConfig, int], tuple[ProcessedRun, object]] = {}  # the state is kept: its id stays its own

    def prefetch(self, pairs: list[tuple[SimConfig, ProcessedRun]]) -> None:
        todo = {(config, id(state)): state for config, state in pairs if (config, id(state)) not in self._done}
        if len(todo) < 2:  # nothing to run side by side
            return
        tasks = [(self.arm, config, state) for (config, _), state in todo.items()]
        for (_, config, state), efforts, error in run_tasks(replay_task, tasks, self.executor, self.jobs, self.ray_address,
                                                              desc="diagnosis replays", unit="replay"):
            if error is not None:
                raise DvrkDartError(f"diagnosis: a re-simulation failed ({error})")
            self._done[(config, id(state))] = (state, efforts)

    def __call__(self, config: SimConfig, state: ProcessedRun):
        from dvrk_dart.runs.replay import simulate_efforts

        done = self._done.get((config, id(state)))
        return done[1] if done is not None else simulate_efforts(self.arm, config, state)

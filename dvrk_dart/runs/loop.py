"""The one simulation loop of every run (Cartesian tasks and replays).

Each step: the driver may impose the state (kinematic mode); the state at the
step's start is logged (every `log_every` steps): that is where the identified
model is evaluated; the driver advances the simulation and returns the step's
acceleration and effort read from DART (None when the mode has no dynamics).
A divergence stops the loop and keeps everything logged before it.

A logged state is DART's dof positions and the coordinates; the frames, the
loop-closure gaps and the passive joints' errors of all logged states are read
from them at the end, at once (`readout_at`: DART's tree kinematics, batched),
which costs a fraction of querying DART's frames at every logged step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation

from dvrk_dart.errors import SimulationDiverged
from dvrk_dart.model.joints import N_JOINTS


class Driver(Protocol):
    def impose(self, k: int, sim) -> None:
        """Before logging step k: impose the state (kinematic mode) or nothing."""

    def advance(self, k: int, sim) -> tuple[np.ndarray, np.ndarray] | None:
        """Step k: advance the simulation; (ddq, effort) of the step, or None."""


@dataclass
class LoopLog:
    """What the loop logged, one row per logged step (start-of-step state)."""

    steps: list[int] = field(default_factory=list)
    q: list = field(default_factory=list)
    dq: list = field(default_factory=list)
    x: list = field(default_factory=list)  # DART's dof positions
    ddq: list = field(default_factory=list)
    effort: list = field(default_factory=list)
    body_names: list[str] = field(default_factory=list)
    readout: dict[str, np.ndarray] = field(default_factory=dict)  # `readout_at` of the logged states
    steps_done: int = 0
    error: SimulationDiverged | None = None

    def __len__(self) -> int:
        return len(self.steps)

    def array(self, name: str) -> np.ndarray:
        return np.asarray(getattr(self, name), dtype=float).reshape(len(self), N_JOINTS)

    @property
    def closure(self) -> np.ndarray:
        return self.readout["closure"]

    @property
    def passive(self) -> np.ndarray:
        return self.readout["passive"]

    @property
    def counterweight(self) -> np.ndarray:
        return self.readout["counterweight"]

    def figures(self, dt: float, wall_s: float) -> dict:
        """What every run records of its loop: steps, simulated time (the steps taken, to a divergence, times the
        step), simulated s per wall s of the loop, the largest passive-joint and counterweight errors."""
        return {"steps": self.steps_done, "duration_s": self.steps_done * dt,
                "realtime_factor": self.steps_done * dt / wall_s if wall_s > 0 else None,
                "passive_joint_error_max_rad": float(np.max(self.passive, initial=0.0)),
                "counterweight_error_max_m": float(np.nanmax(np.abs(self.counterweight), initial=0.0)) if len(self) else 0.0}

    def tool_pose(self) -> np.ndarray:
        """(N, 7) position (m) + quaternion (x, y, z, w), one batched conversion."""
        poses = self.readout["tool"]
        if not len(poses):
            return np.zeros((0, 7))
        return np.column_stack([poses[:, :3, 3], Rotation.from_matrix(poses[:, :3, :3]).as_quat()])

    def body_positions(self) -> dict[str, np.ndarray]:
        if not len(self):
            return {}
        origins = self.readout["bodies"]  # (N, B, 3)
        return {name: origins[:, i].copy() for i, name in enumerate(self.body_names)}


def simulate(sim, driver: Driver, steps: int, log_every: int = 1) -> LoopLog:
    log = LoopLog(body_names=list(sim.body_names))
    nan = np.full(N_JOINTS, np.nan)
    try:
        for k in range(steps):
            driver.impose(k, sim)
            logging = k % log_every == 0
            if logging:
                log.steps.append(k)
                log.q.append(sim.q)
                log.dq.append(sim.dq)
                log.x.append(sim.dof_positions())
            result = driver.advance(k, sim)
            log.steps_done = k + 1
            if logging:
                ddq, effort = result if result is not None else (nan, nan)
                log.ddq.append(np.array(ddq, dtype=float))
                log.effort.append(np.array(effort, dtype=float))
    except SimulationDiverged as exc:
        log.error = exc
        if len(log.ddq) < len(log.steps):  # the diverged step's start state has no result
            for name in ("steps", "q", "dq", "x"):
                getattr(log, name).pop()
    n_dofs = sim.skeleton.getNumDofs()
    log.readout = sim.readout_at(np.reshape(log.x, (len(log), n_dofs)), log.array("q"))
    return log

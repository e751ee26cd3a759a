"""The one simulation loop of every run (Cartesian tasks and replays).

Each step: the driver may impose the state (kinematic mode); the state at the
step's start is logged (every `log_every` steps): that is where the identified
model is evaluated; the driver advances the simulation and returns the step's
acceleration and effort read from DART (None when the mode has no dynamics).
A divergence stops the loop and keeps everything logged before it.
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
    ddq: list = field(default_factory=list)
    effort: list = field(default_factory=list)
    tool: list = field(default_factory=list)  # 4x4 poses, converted once at the end
    closure: list = field(default_factory=list)
    passive: list = field(default_factory=list)
    counterweight: list = field(default_factory=list)
    bodies: list = field(default_factory=list)  # (B, 3) link frame origins per row
    body_names: list[str] = field(default_factory=list)
    steps_done: int = 0
    error: SimulationDiverged | None = None

    def __len__(self) -> int:
        return len(self.steps)

    def array(self, name: str) -> np.ndarray:
        return np.asarray(getattr(self, name), dtype=float).reshape(len(self), N_JOINTS)

    def tool_pose(self) -> np.ndarray:
        """(N, 7) position (m) + quaternion (x, y, z, w), one batched conversion."""
        if not self.tool:
            return np.zeros((0, 7))
        poses = np.asarray(self.tool)
        return np.column_stack([poses[:, :3, 3], Rotation.from_matrix(poses[:, :3, :3]).as_quat()])

    def body_positions(self) -> dict[str, np.ndarray]:
        if not self.bodies:
            return {}
        origins = np.asarray(self.bodies)  # (N, B, 3)
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
                log.tool.append(sim.tool_tip_pose())
                log.closure.append(sim.closure_residual_m())
                log.passive.append(max((abs(e) for n, e in sim.passive_joint_errors().items() if n != "counterweight"), default=0.0))
                cw = sim.counterweight_error_m()
                log.counterweight.append(np.nan if cw is None else cw)
                log.bodies.append(sim.body_origins())
            result = driver.advance(k, sim)
            log.steps_done = k + 1
            if logging:
                ddq, effort = result if result is not None else (nan, nan)
                log.ddq.append(np.array(ddq, dtype=float))
                log.effort.append(np.array(effort, dtype=float))
    except SimulationDiverged as exc:
        log.error = exc
        if len(log.ddq) < len(log.steps):  # the diverged step's start state has no result
            for name in ("steps", "q", "dq", "tool", "closure", "passive", "counterweight", "bodies"):
                getattr(log, name).pop()
    return log

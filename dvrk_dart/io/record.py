"""What one simulated run produces, in memory: the contract between the
simulator loop (runner), the loggers (MCAP, Rerun), the analysis and the report.

All arrays are SI. Efforts carry the sign of the dVRK's measured effort: the
generalized force the actuator applies (N·m, N for q3). Joint order: joints.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation


def pose_vector(T: np.ndarray) -> np.ndarray:
    """4x4 -> position (m) + quaternion (x, y, z, w)."""
    return np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_quat()]


@dataclass
class RunRecord:
    name: str  # unique run name, e.g. "replay-two_velocity_cw-on"
    config: dict  # the resolved config that produced the run (JSON-serialisable)
    t: np.ndarray  # (N,) s, simulation time of each logged sample
    q: np.ndarray  # (N, 7) simulated joint positions (rad, m)
    dq: np.ndarray  # (N, 7) simulated joint velocities
    ddq: np.ndarray  # (N, 7) simulated joint accelerations (the step's (dq+ - dq)/dt)
    effort_sim: np.ndarray  # (N, 7) efforts read from the simulation
    effort_model: dict[str, np.ndarray] = field(default_factory=dict)  # term -> (N, 7) identified model at (q, dq, ddq)
    q_measured: np.ndarray | None = None  # (N, 7) measured run resampled to t, when replaying
    dq_measured: np.ndarray | None = None
    effort_measured: np.ndarray | None = None  # (N, 7) measured efforts (processed like upstream)
    effort_command: np.ndarray | None = None  # (N, 7) torque-mode commands (Eq. 6-7)
    tool_pose: np.ndarray | None = None  # (N, 7) tool-tip position (m) + quaternion (x, y, z, w), base frame
    tool_pose_ref: np.ndarray | None = None  # (N, 7) reference pose of a Cartesian task
    closure_residual_m: np.ndarray | None = None  # (N,) max loop-closure residual of the step
    body_positions: dict[str, np.ndarray] = field(default_factory=dict)  # link name -> (N, 3) frame origin, base frame
    markers: dict[str, np.ndarray] = field(default_factory=dict)  # fixed points, e.g. "rcm" -> (3,)
    metrics: dict = field(default_factory=dict)  # scalar and per-joint results (metrics.json)

    def __len__(self) -> int:
        return len(self.t)

    def model_total(self, terms: tuple[str, ...] | None = None) -> np.ndarray:
        """Sum of the stored model terms (all of them by default)."""
        names = terms if terms is not None else tuple(self.effort_model)
        out = np.zeros_like(self.q)
        for name in names:
            out = out + self.effort_model[name]
        return out

    def tracking_errors(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-sample position (m) and orientation (rad, rotation vector of
        R_ref R^T) errors, reference - actual, of a Cartesian task."""
        position = self.tool_pose_ref[:, :3] - self.tool_pose[:, :3]
        orientation = (Rotation.from_quat(self.tool_pose_ref[:, 3:]) * Rotation.from_quat(self.tool_pose[:, 3:]).inv()).as_rotvec()
        return position, orientation

"""Per-sample quantities of one trajectory that the effect regressors are built from."""

from __future__ import annotations

from functools import cached_property

import numpy as np
import pinocchio as pin

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.body_regressor import body_columns, body_regressor, tree_joint
from dvrk_dart.model.joints import N_JOINTS

#: (m, m cx, m cy, m cz): the first four of them, what gravity sees
FIRST_MOMENT_COLUMNS = 4


class TrajectoryFeatures:
    """Per-sample quantities of one trajectory that the regressors are built from.

    `reference_effort` is the simulated effort at the measured samples;
    `exerted_effort` what the arm exerts as well as the runs tell it, what a
    scale of the measurement multiplies (`EffortScale`) and a time shift
    delays (`TimeShift`): the reference effort unless given."""

    def __init__(self, arm: Arm, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, reference_effort: np.ndarray, sample_rate_hz: float,
                 exerted_effort: np.ndarray | None = None):
        self.arm = arm
        self.q, self.dq, self.ddq = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, dq, ddq))
        self.reference_effort = np.asarray(reference_effort, dtype=float)
        self.exerted_effort = self.reference_effort if exerted_effort is None else np.asarray(exerted_effort, dtype=float)
        for name, effort in (("reference", self.reference_effort), ("exerted", self.exerted_effort)):
            if effort.shape != self.q.shape:
                raise DvrkDartError(f"{name} efforts {effort.shape} do not match the states {self.q.shape}")
        self.sample_rate_hz = float(sample_rate_hz)

    def __len__(self) -> int:
        return len(self.q)

    def body_columns(self, key: int) -> slice:
        """Columns of `body_regressor` belonging to a moving link's body."""
        return body_columns(self.arm.identified, key)

    def first_moment_columns(self, key: int) -> np.ndarray:
        """(N, 7, 4) efforts per unit (m, m c) of a link's body."""
        return self.body_regressor[:, :, self.body_columns(key)][:, :, :FIRST_MOMENT_COLUMNS]

    @cached_property
    def body_regressor(self) -> np.ndarray:
        """(N, 7, 10 n_joints): efforts per unit dynamic parameter of every tree body,
        projected onto the 7 coordinates (tau = G^T tau_tree)."""
        return body_regressor(self.arm.identified, self.q, self.dq, self.ddq)

    @cached_property
    def unit_gravity_efforts(self) -> np.ndarray:
        """(N, 7, 3): gravity efforts of the identified bodies for a unit gravity
        vector along base x, y, z (efforts are linear in the gravity vector)."""
        im = self.arm.identified
        model = pin.Model(im.pin_model)
        data = model.createData()
        qt = im.tree_q(self.q)
        out = np.empty((len(qt), N_JOINTS, 3))
        for axis in range(3):
            model.gravity = pin.Motion(np.r_[np.eye(3)[axis], np.zeros(3)])
            for k in range(len(qt)):
                out[k, :, axis] = im.G.T @ pin.computeGeneralizedGravity(model, data, qt[k])
        return out

    @cached_property
    def exerted_rate(self) -> np.ndarray:
        """d/dt of the exerted effort (N, 7), per second."""
        if len(self) < 2:
            return np.zeros_like(self.exerted_effort)
        return np.gradient(self.exerted_effort, 1.0 / self.sample_rate_hz, axis=0)

    def identified_body_parameters(self, key: int) -> np.ndarray:
        """The 10 dynamic parameters of one link's body in the identified model."""
        return self.arm.identified.pin_model.inertias[tree_joint(self.arm.identified, key)].toDynamicParameters()

    def body_effort(self, key: int) -> np.ndarray:
        """(N, 7) efforts due to one link's body alone (its identified inertia)."""
        return self.body_regressor[:, :, self.body_columns(key)] @ self.identified_body_parameters(key)

    @cached_property
    def counterweight_effort(self) -> np.ndarray:
        """(N, 7) efforts due to the counterweight body alone (identified inertia)."""
        return self.body_effort(self.arm.model.counterweight_link)

"""The one place that knows the joint order and units of the PSM coordinates.

Coordinates are those of the identification model (Wang et al. 2019): q1 yaw,
q2 pitch, q3 insertion, q4 tool roll, and q5..q7 the three wrist/jaw *motor*
coordinates (see models/psm/README.md).
"""

import numpy as np

JOINT_NAMES = ("q1", "q2", "q3", "q4", "q5", "q6", "q7")
N_JOINTS = len(JOINT_NAMES)
PRISMATIC_JOINTS = ("q3",)
#: index of the insertion joint (the only prismatic one)
INSERTION = JOINT_NAMES.index("q3")


def position_unit(name: str) -> str:
    return "m" if name in PRISMATIC_JOINTS else "rad"


def effort_unit(name: str) -> str:
    return "N" if name in PRISMATIC_JOINTS else "N·m"


def column_names(prefix: str) -> list[str]:
    """['tau1', ..., 'tau7'] for prefix 'tau'."""
    return [f"{prefix}{i + 1}" for i in range(N_JOINTS)]


# --- the dVRK's own joints and the motor-coordinate map ---------------------

#: the joint names a dVRK PSM publishes on measured_js (dVRK 2.x), in the order
#: of q1..q6 here; the jaw is published on its own topic (jaw/measured_js)
DVRK_ARM_JOINT_NAMES = ("outer_yaw", "outer_pitch", "outer_insertion", "outer_roll", "outer_wrist_pitch", "outer_wrist_yaw")
DVRK_JAW_JOINT_NAME = "jaw"
#: the dVRK's joint order of the 7 values (arm joints, then the jaw)
DVRK_JOINT_NAMES = (*DVRK_ARM_JOINT_NAMES, DVRK_JAW_JOINT_NAME)
#: columns of q1..q7 that are motor coordinates: the dVRK's wrist pitch, wrist
#: yaw and jaw mapped through inv(M) (the identification's coordinates)
WRIST_COLUMNS = slice(4, 7)


class MotorCoordinateMap:
    """The map between the dVRK's joint values and the identification model's
    coordinates (data README: dvrk = M . motor for positions and velocities of
    the wrist pitch, wrist yaw and jaw; efforts map the other way, motor = M^T .
    dvrk, so that power tau . dq is the same in both). q1..q4 are the same in
    both. Arrays have the joints on their last axis (7 values); M comes from the
    model description (models/psm/psm.toml, [dvrk_wrist])."""

    def __init__(self, matrix) -> None:
        self.matrix = np.array(matrix, dtype=float)
        if self.matrix.shape != (3, 3):
            raise ValueError(f"the wrist map is 3x3, not {self.matrix.shape}")
        self._inverse = np.linalg.inv(self.matrix)

    @staticmethod
    def _mapped(values, matrix):
        out = np.array(values, dtype=float, copy=True)
        out[..., WRIST_COLUMNS] = out[..., WRIST_COLUMNS] @ matrix.T
        return out

    def positions_to_model(self, dvrk):
        """dVRK positions (or velocities, accelerations) -> model q1..q7."""
        return self._mapped(dvrk, self._inverse)

    def positions_to_dvrk(self, model):
        return self._mapped(model, self.matrix)

    def efforts_to_model(self, dvrk):
        """dVRK efforts -> model efforts (through M^T)."""
        return self._mapped(dvrk, self.matrix.T)

    def efforts_to_dvrk(self, model):
        return self._mapped(model, self._inverse.T)

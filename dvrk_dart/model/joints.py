"""The one place that knows the joint order and units of the PSM coordinates.

Coordinates are those of the identification model (Wang et al. 2019): q1 yaw,
q2 pitch, q3 insertion, q4 tool roll, and q5..q7 the three wrist/jaw *motor*
coordinates (see models/psm/README.md).
"""

import numpy as np

JOINT_NAMES = ("q1", "q2", "q3", "q4", "q5", "q6", "q7")
N_JOINTS = len(JOINT_NAMES)
INSERTION = JOINT_NAMES.index("q3")
#: the coordinate that pitches the arm (both arms' q2): the reference of a hand-measured payload position
PITCH = JOINT_NAMES.index("q2")
#: the coordinate that turns the arm about its first axis (both arms' q1)
YAW = JOINT_NAMES.index("q1")


def column_names(prefix: str) -> list[str]:
    """['tau1', ..., 'tau7'] for prefix 'tau'."""
    return [f"{prefix}{i + 1}" for i in range(N_JOINTS)]


# --- the map between the dVRK's joints and the model's coordinates -----------
# (the dVRK's joint names of each arm are data: its model card's [dvrk_topics])

#: columns of q1..q7 that are motor coordinates: the dVRK's wrist pitch, wrist
#: yaw and jaw mapped through inv(M) (the identification's coordinates)
WRIST_COLUMNS = slice(4, 7)


class MotorCoordinateMap:
    """The map between the dVRK's joint values and the identification model's
    coordinates (data READMEs: dvrk = M . q for positions and velocities of the
    coupled columns; efforts map the other way, q-efforts = M^T . dvrk, so that
    power tau . dq is the same in both). The other columns are the same in
    both. Arrays have the joints on their last axis (7 values); M and its
    columns come from the model description ([dvrk_coupling]: the PSM's wrist
    pitch, wrist yaw and jaw, columns 5..7; the MTM's joints 2..4)."""

    def __init__(self, matrix, columns=WRIST_COLUMNS) -> None:
        self.matrix = np.array(matrix, dtype=float)
        self.columns = columns if isinstance(columns, slice) else np.asarray(columns, dtype=int)
        width = len(range(N_JOINTS)[self.columns]) if isinstance(self.columns, slice) else len(self.columns)
        if self.matrix.shape != (width, width):
            raise ValueError(f"the coupling of {width} columns is {width}x{width}, not {self.matrix.shape}")
        self._inverse = np.linalg.inv(self.matrix)

    def _identity(self) -> tuple:
        columns = tuple(range(N_JOINTS)[self.columns]) if isinstance(self.columns, slice) else tuple(self.columns.tolist())
        return self.matrix.tobytes(), columns

    def __eq__(self, other) -> bool:  # a value: two arms' maps read a file alike when their numbers agree
        return isinstance(other, MotorCoordinateMap) and self._identity() == other._identity()

    def __hash__(self) -> int:
        return hash(self._identity())

    def _mapped(self, values, matrix):
        out = np.array(values, dtype=float, copy=True)
        out[..., self.columns] = out[..., self.columns] @ matrix.T
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

    def determined_by(self, recorded):
        """(7,) bool: the model coordinates a log of the dVRK's `recorded`
        joints ((7,) bool) gives: the coupled ones only all together (each
        mixes the dVRK's coupled columns, and its model effort the others'
        motion: a PSM log without the jaw gives q1..q4; q5 alone, with q6 and
        q7 held, moved its modelled effort's RMS error on "one" from 0.006 to 0.011)."""
        determined = np.array(recorded, dtype=bool)
        determined[self.columns] = determined[self.columns].all()
        return determined

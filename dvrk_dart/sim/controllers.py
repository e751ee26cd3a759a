"""The paper's controllers, on the identified model (Pinocchio):

- Eq. 5, kinematic control of the full tool-tip pose:
  dq_d = J(q)^-1 (Kp e + dr_d), e = (p_d - p, e_o), with the orientation error
  e_o = log(R_d R^T) as a rotation vector in base axes. The 6 task coordinates
  are driven through the six dVRK joints q1..q4, wrist pitch and wrist yaw; the
  jaw opening is held. J is the tool-tip Jacobian in those coordinates.
- Eq. 6-7, Cartesian feedback linearisation on J1..J3 (position task):
  u = M J_L^-1 (a - dJ_L dq) + C dq + g,  a = ddr_d + Kp e_p + Kd de_p.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dvrk_dart.io.arm import Arm
from dvrk_dart.model.joints import N_JOINTS

#: joints of the position task under torque control (J1..J3)
ARM_JOINTS = slice(0, 3)


def orientation_error(R_desired: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rotation vector of R_d R^T (base axes): zero when the orientations agree."""
    return pin.log3(R_desired @ R.T)


@dataclass
class KinematicController:
    """Eq. 5 in the dVRK joint coordinates (q1..q4, wrist pitch, wrist yaw)."""

    arm: Arm
    gain: float | None = None  # 1/s; None: the arm's model card ([controllers] kinematic_gain)

    def __post_init__(self):
        if self.gain is None:
            self.gain = float(self.arm.model.controller_gain("kinematic_gain"))
        # dq_motor = T dtheta, theta = (q1..q4, wrist pitch, wrist yaw, jaw)
        # (the map as a matrix: its images of the unit vectors, as columns)
        self._dvrk_to_motor = self.arm.model.motor_map.positions_to_model(np.eye(N_JOINTS)).T

    def joint_velocity(self, q: np.ndarray, pose_desired: np.ndarray, twist_desired: np.ndarray) -> np.ndarray:
        pose, J = self.arm.identified.tool_tip_pose_and_jacobian(q)
        error = np.concatenate((pose_desired[:3, 3] - pose[:3, 3], orientation_error(pose_desired[:3, :3], pose[:3, :3])))
        J_dvrk = J @ self._dvrk_to_motor
        dtheta = np.zeros(N_JOINTS)
        dtheta[:6] = np.linalg.solve(J_dvrk[:, :6], self.gain * error + twist_desired)  # jaw held: dtheta[6] = 0
        return self._dvrk_to_motor @ dtheta


@dataclass
class CartesianTorqueController:
    """Eq. 6-7: feedback linearisation of the tool-tip position on J1..J3."""

    arm: Arm
    kp: float | None = None  # 1/s^2; None: the arm's model card ([controllers] torque_kp)
    kd: float | None = None  # 1/s; None: [controllers] torque_kd

    def __post_init__(self):
        self.kp = float(self.arm.model.controller_gain("torque_kp")) if self.kp is None else self.kp
        self.kd = float(self.arm.model.controller_gain("torque_kd")) if self.kd is None else self.kd

    def efforts(self, q, dq, p_desired, v_desired, a_desired) -> tuple[np.ndarray, np.ndarray]:
        """(u for J1..J3, position error p_d - p)."""
        identified = self.arm.identified
        M, c, g = identified.mcg(q, dq)
        pose, J = identified.tool_tip_pose_and_jacobian(q)
        J_L, p, v = J[:3, ARM_JOINTS], pose[:3, 3], J[:3] @ dq
        e_p = p_desired - p
        a = a_desired + self.kp * e_p + self.kd * (v_desired - v)
        bias = identified.tool_tip_bias_acceleration(q, dq)[:3]
        ddq_arm = np.linalg.solve(J_L, a - bias)
        u = M[ARM_JOINTS, ARM_JOINTS] @ ddq_arm + c[ARM_JOINTS] + g[ARM_JOINTS]
        return u, e_p

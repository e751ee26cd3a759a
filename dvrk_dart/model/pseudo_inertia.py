"""Physical consistency of a rigid body's inertial parameters: the 4x4
pseudo-inertia matrix of Wensing, Kim and Slotine (2017),

    J = [[Sigma, h], [h^T, m]],   Sigma = integral of r r^T dm,  h = m c,

is positive semi-definite exactly when the mass is non-negative and the
inertia about the centre of mass satisfies the triangle inequalities. One
place computes it for the identification, the parameter sampling and checks.
"""

from __future__ import annotations

import numpy as np


def pseudo_inertia(mass_kg: float, com_m: np.ndarray, inertia_com: np.ndarray) -> np.ndarray:
    """J (4x4, kg and kg m, kg m^2) of a body from its mass, centre of mass and
    inertia tensor about the centre of mass, all in the same frame."""
    com = np.asarray(com_m, dtype=float)
    sigma_com = 0.5 * np.trace(inertia_com) * np.eye(3) - inertia_com
    J = np.empty((4, 4))
    J[:3, :3] = sigma_com + mass_kg * np.outer(com, com)
    J[:3, 3] = J[3, :3] = mass_kg * com
    J[3, 3] = mass_kg
    return J


def _dynamic_parameter_basis() -> np.ndarray:
    """B (10, 4, 4) with J = sum_i p_i B_i for Pinocchio's dynamic parameters
    p = (m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz), inertia about the
    frame origin: Sigma = tr(I)/2 1 - I, h = m c. J is linear in p, so the
    basis also builds the LMI of a convex program from a vector variable."""
    B = np.zeros((10, 4, 4))
    B[0, 3, 3] = 1.0
    for i in range(3):
        B[1 + i, i, 3] = B[1 + i, 3, i] = 1.0
    diagonal = {4: 0, 6: 1, 9: 2}  # Ixx, Iyy, Izz
    for index, axis in diagonal.items():
        B[index, :3, :3] = 0.5 * np.eye(3)
        B[index, axis, axis] -= 1.0
    for index, (a, b) in {5: (0, 1), 7: (0, 2), 8: (1, 2)}.items():  # Ixy, Ixz, Iyz
        B[index, a, b] = B[index, b, a] = -1.0
    return B


#: J = sum_i p_i PSEUDO_INERTIA_BASIS[i] (see _dynamic_parameter_basis)
PSEUDO_INERTIA_BASIS = _dynamic_parameter_basis()


def pseudo_inertia_of_dynamic_parameters(parameters: np.ndarray) -> np.ndarray:
    """J (4x4) of Pinocchio's 10 dynamic parameters of a body."""
    return np.tensordot(np.asarray(parameters, dtype=float), PSEUDO_INERTIA_BASIS, axes=1)

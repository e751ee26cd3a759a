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


def from_pseudo_inertia(J: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, centre of mass, inertia about the centre of mass) of a pseudo-inertia
    matrix; the centre of mass is undefined (zeros) for a massless body."""
    mass = float(J[3, 3])
    com = J[:3, 3] / mass if mass > 0.0 else np.zeros(3)
    sigma_com = J[:3, :3] - mass * np.outer(com, com)
    inertia_com = np.trace(sigma_com) * np.eye(3) - sigma_com
    return mass, com, inertia_com


def smallest_eigenvalue(mass_kg: float, com_m: np.ndarray, inertia_com: np.ndarray) -> float:
    """The pseudo-inertia's smallest eigenvalue: >= 0 for a physical body."""
    return float(np.linalg.eigvalsh(pseudo_inertia(mass_kg, com_m, inertia_com))[0])

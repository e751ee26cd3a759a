"""The modified-DH frames of an arm's model description: each frame's
parameters are linear expressions of the seven coordinates q1..q7
(`LinearExpr`), a `Link` is a frame with its body's flags, and `dh_transform`
is Craig's modified-DH transform (model/model_file.py reads them)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.joints import N_JOINTS


@dataclass(frozen=True)
class LinearExpr:
    """value = coeffs . q + const, with q the seven joint coordinates."""

    coeffs: np.ndarray
    const: float

    @staticmethod
    def constant(value: float) -> "LinearExpr":
        return LinearExpr(np.zeros(N_JOINTS), float(value))

    def __call__(self, q: np.ndarray) -> np.ndarray | float:
        """Evaluate at one configuration (7,) or a batch (N, 7)."""
        return np.asarray(q) @ self.coeffs + self.const

    @property
    def depends_on_q(self) -> bool:
        return bool(np.any(self.coeffs != 0.0))

    def __add__(self, other: "LinearExpr") -> "LinearExpr":
        return LinearExpr(self.coeffs + other.coeffs, self.const + other.const)

    def scaled(self, k: float) -> "LinearExpr":
        return LinearExpr(self.coeffs * k, self.const * k)


@dataclass(frozen=True)
class DHFrame:
    """A modified-DH frame: T(parent -> this) = Rx(alpha) Tx(a) Rz(theta) Tz(d)."""

    parent: int
    a: LinearExpr
    alpha: LinearExpr
    d: LinearExpr
    theta: LinearExpr

    @cached_property  # read at every simulation step (sim/effects.py): the frame does not change
    def joint_type(self) -> str:
        if self.theta.depends_on_q and self.d.depends_on_q:
            raise DvrkDartError("a link cannot have both theta and d depend on q")
        if self.theta.depends_on_q:
            return "revolute"
        if self.d.depends_on_q:
            return "prismatic"
        return "fixed"

    @cached_property
    def variable(self) -> LinearExpr | None:
        """The link's own joint variable (theta or d), None for a fixed frame."""
        return {"revolute": self.theta, "prismatic": self.d, "fixed": None}[self.joint_type]

    def transform(self, q: np.ndarray) -> np.ndarray:
        return dh_transform(float(self.a(q)), float(self.alpha(q)), float(self.d(q)), float(self.theta(q)))

    def transforms(self, q: np.ndarray) -> np.ndarray:
        """(N, 4, 4) transforms at a batch of configurations (N, 7)."""
        return dh_transforms(self.a(q), self.alpha(q), self.d(q), self.theta(q))


@dataclass(frozen=True)
class Link(DHFrame):
    key: int = 0
    name: str = ""
    group: str = ""
    body: bool = True
    inertia: bool = False
    friction: bool = False
    motor_inertia: bool = False
    spring: bool = False
    #: a spring acting through a linkage (the MTM's wrist pitch): its geometry, else a linear K q spring
    spring_linkage: dict[str, float] | None = None
    #: a known cable torque, a polynomial of the link's variable (highest power first), N·m
    cable_polynomial: tuple[float, ...] | None = None


def dh_transform(a: float, alpha: float, d: float, theta: float) -> np.ndarray:
    """Modified DH (Craig): Rx(alpha) . Tx(a) . Rz(theta) . Tz(d)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def dh_transforms(a: np.ndarray, alpha: np.ndarray, d: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """`dh_transform` of arrays of parameters, (N, 4, 4)."""
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    T = np.zeros((len(theta), 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 0, 3] = ct, -st, a
    T[:, 1, 0], T[:, 1, 1], T[:, 1, 2], T[:, 1, 3] = st * ca, ct * ca, -sa, -sa * d
    T[:, 2, 0], T[:, 2, 1], T[:, 2, 2], T[:, 2, 3] = st * sa, ct * sa, ca, ca * d
    T[:, 3, 3] = 1.0
    return T

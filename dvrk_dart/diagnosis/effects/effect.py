"""Candidate physical effects of the sim-to-real gap, each a small physical model.

An effect adds a joint effort that the simulation (the identified inertial
parameters only, as in the CoppeliaSim paper) does not produce. Each one has
- physical parameters p with physical bounds (Coulomb >= 0, a payload's mass
  > 0 and its position inside the link, a small tilt ...),
- a regressor: effort = Y(q, dq, ddq) . beta(p), Y of shape (N*7, n_columns),
  with beta = p for the linear effects; for a payload beta is the point mass's
  10 dynamic parameters (m, m c, inertia about the link frame origin), linear in
  (m, m c) except for the small second moment m (|c|^2 I - c c^T),
- a mapping to the simulation as physics: the SimConfig fields it sets
  (JointEffects, Payload, gravity_tilt_rad); None for an effect the simulation
  has no field for (a measurement time shift, a counterweight transmission loss).

The per-sample quantities the regressors need (Pinocchio's body regressor of
every moving link, the efforts of unit gravity ...) are computed once per
trajectory by `TrajectoryFeatures`.

Sign conventions (those of the measured efforts and of SimConfig): an effort is
what the actuator supplies. Coulomb friction Fc sign(dq), viscous Fv dq, a
spring K q (rest at q = 0), an armature Ia ddq, an offset o are all *added* to
the efforts the actuator must supply."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np

from dvrk_dart.diagnosis.effects.features import TrajectoryFeatures
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.sim.config import Payload


@dataclass(frozen=True)
class Parameter:
    name: str
    unit: str
    lower: float = -math.inf
    upper: float = math.inf


@dataclass
class SimContribution:
    """SimConfig fields an effect sets (added to those of other effects)."""

    coulomb: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    viscous: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    stiffness: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    armature: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    coulomb_reversal_velocity: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    coulomb_presliding: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    link_friction: tuple[tuple[float, ...], ...] = ()
    position_friction: tuple[tuple[float, ...], ...] = ()
    angle_load: tuple[tuple[float, ...], ...] = ()
    link_mass_scale: tuple[tuple[float, ...], ...] = ()
    payloads: tuple[Payload, ...] = ()
    gravity_tilt_rad: np.ndarray = field(default_factory=lambda: np.zeros(2))


class Effect(ABC):
    """A candidate physical effect: parameters, regressor and simulation mapping."""

    name: str
    kind: str
    joints: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    linear = True  # effort linear in the parameters (beta = p)
    #: beta(p) = d beta/dp (p) @ p (degree one): fitted with the Jacobian frozen
    #: at a warm start, the fit is exact along the warm start's direction
    homogeneous = False

    @property
    def n_parameters(self) -> int:
        return len(self.parameters)

    @property
    def n_columns(self) -> int:
        return self.n_parameters

    @property
    def n_seen_parameters(self) -> int:
        """Parameters the efforts can tell apart (the selection's parsimony counts these)."""
        return self.n_parameters

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @abstractmethod
    def columns(self, features: TrajectoryFeatures) -> np.ndarray:
        """(N, 7, n_columns): effort per unit regression coefficient."""

    def regressor(self, features: TrajectoryFeatures) -> np.ndarray:
        """Y of effort = Y beta, (N*7, n_columns), rows sample-major (sample k, joint j)."""
        return self.columns(features).reshape(-1, self.n_columns)

    def coefficients(self, p: np.ndarray) -> np.ndarray:
        """Regression coefficients beta(p)."""
        return np.asarray(p, dtype=float)

    def coefficients_jacobian(self, p: np.ndarray) -> np.ndarray:
        return np.eye(self.n_parameters)

    def effort(self, features: TrajectoryFeatures, p: np.ndarray) -> np.ndarray:
        """(N, 7) effort of the effect with parameters p."""
        return self.columns(features) @ self.coefficients(p)

    def initial_guesses(self, linear_solution: np.ndarray) -> list[np.ndarray]:
        """Starting points of a nonlinear fit (only nonlinear effects need them)."""
        return [np.clip(linear_solution, self.lower, self.upper)]

    @abstractmethod
    def sim_contribution(self, p: np.ndarray) -> SimContribution | None:
        """The SimConfig fields of this effect, None if the simulation has no field for it."""

    @property
    def family(self) -> str:
        """Effects of one family are alternative models of the same physics
        (e.g. the friction of one joint with a sharp or a smooth reversal): at
        most one of a family is selected."""
        return self.name

    @property
    def selection_group(self) -> str:
        """At most one effect of a group is selected: its family by default."""
        return self.family

    def fully_simulated(self, p: np.ndarray) -> bool:
        """Whether the simulation produces all of this effect's effort."""
        return self.sim_contribution(np.asarray(p, dtype=float)) is not None

    def unsimulated_effort(self, features: TrajectoryFeatures, p: np.ndarray) -> np.ndarray | None:
        """(N, 7) part of the effort the simulation does not produce from
        `sim_contribution` (added to the simulated efforts as a model-based
        effort), None when the simulation produces all of it."""
        if self.sim_contribution(np.asarray(p, dtype=float)) is None:
            return self.effort(features, p)
        return None

    def describe(self, p: np.ndarray) -> dict:
        return {par.name: float(v) for par, v in zip(self.parameters, p)}

    def units(self) -> dict:
        return {par.name: par.unit for par in self.parameters}

    def size(self, p: np.ndarray) -> float:
        """One number for "how big": the first parameter (overridden where needed)."""
        return float(p[0])

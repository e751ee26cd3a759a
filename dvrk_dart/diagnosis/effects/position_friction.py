"""A joint's Coulomb friction that changes along its range (a table on knots)."""

from __future__ import annotations

import copy

import numpy as np

from dvrk_dart.diagnosis.effects.effect import Effect, Parameter, SimContribution
from dvrk_dart.model import friction
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS

#: knots of a position-dependent friction over the joint's range (the hat functions' count)
POSITION_FRICTION_KNOTS = 4
#: a knot whose hat weighs at most this on the training runs is reported not determined: its value is mostly the prior
#: (J1's end knot at -1.6 rad on runs over -0.55..0.95: 0.016; a knot the runs do not reach: 0)
DETERMINED_KNOT_WEIGHT = 0.1


class PositionFriction(Effect):
    """Coulomb friction that changes along the joint's range (a guide or a
    cable tighter at one end), reversing over a pre-sliding distance:
    sum_k Fc_k phi_k(q) z + Fv dq, phi_k the hat functions on knots spread
    over the model's joint range (piecewise-linear Fc(q), constant beyond the
    end knots; simulated constant beyond the training runs' range, `within`).
    Simulation: the simulator's explicit friction with Fc interpolated in q
    (SimConfig.extra.position_friction)."""

    kind = "friction"

    def __init__(self, model, joint: str, presliding: float):
        self.joint_index = JOINT_NAMES.index(joint)
        self.joints = (joint,)
        self.presliding = float(presliding)
        self.knots = np.linspace(model.joint_lower[self.joint_index], model.joint_upper[self.joint_index], POSITION_FRICTION_KNOTS)
        self.name = f"position_friction_{joint}_presliding{self.presliding:g}"
        self.position_unit = model.position_unit(joint)
        eu = model.effort_unit(joint)
        self.parameters = (*(Parameter(f"coulomb_at_{x:.3g}", eu, 0.0) for x in self.knots),
                           Parameter("viscous", f"{eu}/({model.velocity_unit(joint)})", 0.0))

    @property
    def family(self) -> str:
        return f"friction_{self.joints[0]}"

    #: the training runs' range of the joint (None: the knots' own): the
    #: simulation holds Fc constant beyond it, where no run determined it
    span: tuple[float, float] | None = None

    def within(self, low: float, high: float) -> PositionFriction:
        """The same effect (same knots, same fit) simulated with Fc held beyond
        [low, high], the training runs' range: J1's end knot at -1.6 rad, on runs
        within -0.55..0.95 rad, read 9.2 N·m, which the simulation extrapolated
        to any run reaching past -0.55 rad. (Knots over that range instead, a
        finer table, took 2018's J1 on test2 from 0.081 to 0.100 N·m.)"""
        other = copy.copy(self)
        other.span = (float(low), float(high))
        return other

    def _simulated_table(self, p) -> tuple[np.ndarray, np.ndarray]:
        """(knots, Fc at them) as simulated: the fitted table, held beyond the training range."""
        if self.span is None:
            return self.knots, np.asarray(p[:-1], dtype=float)
        low, high = self.span
        knots = np.unique(np.r_[low, self.knots[(self.knots > low) & (self.knots < high)], high])
        return knots, np.interp(knots, self.knots, np.asarray(p[:-1], dtype=float))

    def columns(self, features):
        q, v = features.q[:, self.joint_index], features.dq[:, self.joint_index]
        z = friction.reversal(q, v, self.presliding)
        hats = np.column_stack([np.interp(q, self.knots, np.eye(len(self.knots))[k]) for k in range(len(self.knots))])
        out = np.zeros((len(features), N_JOINTS, len(self.knots) + 1))
        out[:, self.joint_index, :] = np.column_stack([hats * z[:, None], v])
        return out

    def sim_contribution(self, p):
        c = SimContribution()
        knots, values = self._simulated_table(p)
        c.position_friction = ((float(self.joint_index), self.presliding, *map(float, knots), *map(float, values)),)
        c.viscous[self.joint_index] = p[-1]
        return c

    def describe(self, p):
        out = super().describe(p)
        out["reversal"] = f"Dahl over {self.presliding:g} {self.position_unit}, Fc piecewise linear in {self.joints[0]}" + (
            "" if self.span is None else f", simulated held beyond the training runs' {self.span[0]:.3g}..{self.span[1]:.3g} {self.position_unit}")
        if self.span is not None:
            levels = self._simulated_table(p)[1]
            out["coulomb_within_runs"] = [float(levels.min()), float(levels.max())]
            weak = {f"coulomb_at_{x:.3g}": f"its weight is at most {w:.2g} on the training runs (they span {self.span[0]:.3g}.."
                    f"{self.span[1]:.3g} {self.position_unit}): the fit's prior more than the data"
                    for x, w in zip(self.knots, self._largest_weights()) if w < DETERMINED_KNOT_WEIGHT}
            if weak:
                out["not_determined"] = weak
        return out

    def units(self) -> dict:
        return {**super().units(), "coulomb_within_runs": self.parameters[0].unit}

    def _largest_weights(self) -> np.ndarray:
        """Each knot's largest hat weight over the training span (the knots are evenly spaced; a knot the span does not
        reach has its weight at the span's nearest end)."""
        spacing = self.knots[1] - self.knots[0]
        nearest = np.clip(self.knots, *self.span)
        return np.clip(1.0 - np.abs(self.knots - nearest) / spacing, 0.0, 1.0)

    def size(self, p) -> float:
        """The largest Coulomb level along the range (the first knot's may be nil where the largest is not)."""
        levels = np.asarray(p[:-1], dtype=float)
        return float(levels[np.argmax(np.abs(levels))])

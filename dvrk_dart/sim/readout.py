"""What is read from the simulated closed chain besides the efforts: frames
(link transforms, tool tip, body origins), the loop-closure residuals, the
passive joints' and the counterweight's errors against the model's relations,
and the divergence checks of each step.

`ClosedChainReadout` is a mixin of `PsmSimulator` (simulator.py): it reads the
DART arm (`self.psm`, `self.skeleton`), the model, the simulator's current
state (`_positions`, `_coordinates`) and `self.step_index`. A DART world
transform costs more to query than a step's arithmetic, and the loop, the
divergence check and the logs ask for the same frames of one state: they are
fetched once per state (`_frame`), the cache being dropped whenever the state
changes (`_state_changed`).
"""

from __future__ import annotations

import math

import numpy as np

from dvrk_dart.errors import DvrkDartError, SimulationDiverged
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES

#: the loop-closure residual is checked for divergence every this many steps
#: (10 ms at 1 ms); NaN and joint ranges are checked every step
CLOSURE_CHECK_EVERY_STEPS = 10


class ClosedChainReadout:
    """Frames, closure residuals, relation errors and divergence checks."""

    # ------------------------------------------------------------ state
    def _state_changed(self) -> None:
        """DART's state changed (step, reset, imposed pose): forget what was read."""
        self._frames: dict[int, np.ndarray] = {}
        self._closures: dict[str, float] | None = None

    def _frame(self, key: int) -> np.ndarray:
        """Base-frame transform of a link frame at the current state (shared: do not modify)."""
        T = self._frames.get(key)
        if T is None:
            if key in self.psm.bodies:
                # getTransform() is the world transform (DART's Frame::getTransform with respect to
                # the world returns getWorldTransform()); dartpy answers it in half the time
                T = self.psm.bodies[key].getTransform().matrix()
            elif key in self.psm.fixed_frames:
                parent, offset = self.psm.fixed_frames[key]
                T = (self._frame(parent) if parent else np.eye(4)) @ offset
            else:
                raise DvrkDartError(f"link {key} has no frame in this simulation")
            self._frames[key] = T
        return T

    # ---------------------------------------------------------- checks
    def closure_residuals_m(self) -> dict[str, float]:
        if self._closures is None:
            out = {}
            for c in self.psm.closures:
                Ta = self._frame(c.link)
                Tb = self._frame(c.other)
                pa = Ta[:3, :3] @ c.point_in_link + Ta[:3, 3]
                pb = Tb[:3, :3] @ c.point_in_other + Tb[:3, 3]
                gap = pa - pb
                out[c.name] = math.sqrt(gap.dot(gap))  # what np.linalg.norm computes, without its overhead
            self._closures = out
        return dict(self._closures)

    def closure_residual_m(self) -> float:
        """Largest loop-closure gap (m) over the loops."""
        self.closure_residuals_m()
        return max(self._closures.values(), default=0.0)

    def passive_joint_errors(self) -> dict[str, float]:
        """Passive dof (and coupled counterweight) minus the model's linear relation (rad, m)."""
        x = self._positions()
        q = self._coordinates()
        expected = self.psm.G @ q
        dofs = self._passive_and_counterweight
        if self.psm.counterweight_dof is not None:
            expected[self.psm.counterweight_dof] = q[INSERTION] * self.model.counterweight_ratio
        return {name: float(x[d] - expected[d]) for name, d in zip(self._passive_names, dofs)}

    def counterweight_error_m(self) -> float | None:
        """Counterweight position minus ratio·q3 (the transmission's exactness)."""
        cw = self.psm.counterweight_dof
        if cw is None:
            return None
        return float(self._positions()[cw]) - self.model.counterweight_ratio * float(self._coordinates()[INSERTION])

    def _check(self, x: np.ndarray, v: np.ndarray, q: np.ndarray) -> None:
        """Divergence checks at the state (x, v) after a step (q: its coordinates):
        NaN and joint range every step, loop closure every
        CLOSURE_CHECK_EVERY_STEPS steps (its frame queries cost more than a step)."""
        lower, upper = self.model.joint_lower, self.model.joint_upper
        finite = math.isfinite(np.add.reduce(x) + np.add.reduce(v))  # ufuncs direct: this runs every step
        in_range = finite and bool(np.logical_and.reduce(np.abs(q - self._range_mid) <= self._range_half))
        check_loops = self.step_index % CLOSURE_CHECK_EVERY_STEPS == 0
        if in_range and not check_loops:
            return
        where = f"step {self.step_index} (t = {self.time_s:.3f} s)"
        if not finite:
            bad = int(np.flatnonzero(~(np.isfinite(x) & np.isfinite(v)))[0])
            raise SimulationDiverged(f"{where}: joint {self.skeleton.getDof(bad).getName()} is not finite")
        outside = np.flatnonzero((q < lower) | (q > upper))
        if outside.size:
            j = int(outside[0])
            # repr: the shortest text that is the exact value, so the violation shows
            raise SimulationDiverged(f"{where}: joint {JOINT_NAMES[j]} at {float(q[j])!r} outside its range [{float(lower[j])!r}, {float(upper[j])!r}]")
        residuals = self.closure_residuals_m()
        name, worst = max(residuals.items(), key=lambda kv: kv[1], default=("", 0.0))
        if worst > self.config.closure_residual_limit_m:
            raise SimulationDiverged(f"{where}: loop {name} open by {worst:.3g} m (limit {self.config.closure_residual_limit_m:g} m)")

    # ------------------------------------------------------------ frames
    def link_transform(self, key: int) -> np.ndarray:
        """4x4 base-frame transform of a link frame (DART bodies and fixed frames)."""
        return self._frame(key).copy()

    def tool_tip_pose(self) -> np.ndarray:
        tip = self.model.tool_tip
        return self._frame(tip.parent) @ tip.transform(self._coordinates())

    def body_positions(self) -> dict[str, np.ndarray]:
        """Link name -> frame origin (base frame, m) of every simulated link frame."""
        return dict(zip(self.body_names, self.body_origins()))

    def body_origins(self) -> np.ndarray:
        """(B, 3) frame origins (base frame, m), in the order of `body_names`."""
        frame = self._frame
        return np.array([frame(k)[:3, 3] for k in self._body_keys])

    def _setup_readout(self) -> None:
        """Names and orders fixed by the built arm (called once by the simulator)."""
        self._body_keys = sorted(list(self.psm.fixed_frames) + list(self.psm.bodies))
        self.body_names = [self.model.links[k].name for k in self._body_keys]
        dofs = list(self.psm.passive_dofs)
        if self.psm.counterweight_dof is not None:
            dofs.append(self.psm.counterweight_dof)
        self._passive_and_counterweight = dofs
        self._passive_names = [self.model.links[self.psm.dof_links[d]].name for d in dofs]
        self._state_changed()

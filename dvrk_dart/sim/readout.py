"""What is read from the simulated closed chain besides the efforts: frames
(link transforms, tool tip, body origins), the loop-closure residuals, the
passive joints' and the counterweight's errors against the model's relations,
and the divergence checks of each step.

`ClosedChainReadout` is a mixin of `PsmSimulator` (simulator.py): it reads the
DART arm (`self.psm`, `self.skeleton`), the model, `self.q` and
`self.step_index`.
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

    # ---------------------------------------------------------- checks
    def closure_residuals_m(self) -> dict[str, float]:
        out = {}
        for c in self.psm.closures:
            Ta = self.psm.bodies[c.link].getWorldTransform().matrix()
            Tb = self.psm.bodies[c.other].getWorldTransform().matrix()
            pa = Ta[:3, :3] @ c.point_in_link + Ta[:3, 3]
            pb = Tb[:3, :3] @ c.point_in_other + Tb[:3, 3]
            out[c.name] = float(np.linalg.norm(pa - pb))
        return out

    def closure_residual_m(self) -> float:
        """Largest loop-closure gap (m) over the loops."""
        return max(self.closure_residuals_m().values(), default=0.0)

    def passive_joint_errors(self) -> dict[str, float]:
        """Passive dof (and coupled counterweight) minus the model's linear relation (rad, m)."""
        x = self.skeleton.getPositions()
        expected = self.psm.G @ self.q
        dofs = list(self.psm.passive_dofs)
        if self.psm.counterweight_dof is not None:
            dofs.append(self.psm.counterweight_dof)
            expected[self.psm.counterweight_dof] = self.q[INSERTION] * self.model.counterweight_ratio
        return {self.model.links[self.psm.dof_links[d]].name: float(x[d] - expected[d]) for d in dofs}

    def counterweight_error_m(self) -> float | None:
        """Counterweight position minus ratio·q3 (the transmission's exactness)."""
        cw = self.counterweight_position_m
        return None if cw is None else cw - self.model.counterweight_ratio * float(self.q[INSERTION])

    def _check(self, x: np.ndarray, v: np.ndarray) -> None:
        """Divergence checks: NaN and joint range every step, loop closure every
        CLOSURE_CHECK_EVERY_STEPS steps (its frame queries cost more than a step)."""
        q = self._A_inv @ x[self._act]
        lower, upper = self.model.joint_lower, self.model.joint_upper
        finite = math.isfinite(x.sum() + v.sum())
        in_range = finite and bool((np.abs(q - self._range_mid) <= self._range_half).all())
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
        if key in self.psm.bodies:
            return self.psm.bodies[key].getWorldTransform().matrix()
        if key in self.psm.fixed_frames:
            parent, offset = self.psm.fixed_frames[key]
            return (self.link_transform(parent) if parent else np.eye(4)) @ offset
        raise DvrkDartError(f"link {key} has no frame in this simulation")

    def tool_tip_pose(self) -> np.ndarray:
        tip = self.model.tool_tip
        return self.link_transform(tip.parent) @ tip.transform(self.q)

    def body_positions(self) -> dict[str, np.ndarray]:
        """Link name -> frame origin (base frame, m) of every simulated link frame."""
        keys = list(self.psm.fixed_frames) + list(self.psm.bodies)
        return {self.model.links[k].name: self.link_transform(k)[:3, 3].copy() for k in sorted(keys)}

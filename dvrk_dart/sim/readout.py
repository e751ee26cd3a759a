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

#: how far past a joint limit (m or rad) a coordinate may sit before the run counts as
#: diverged: a joint held at its limit (an unrecorded q3 held at 0) sits there to 1e-13
RANGE_TOLERANCE = 1e-6

#: the loop-closure residual is checked for divergence every this many steps
#: (50 ms at 1 ms: a diverging closed chain opens by far more than the limit
#: within that); NaN and joint ranges are checked every step, and the logs
#: hold the residual of every logged state
CLOSURE_CHECK_EVERY_STEPS = 50


def raise_if_out_of_range(q: np.ndarray, lower: np.ndarray, upper: np.ndarray, where: str, why: str = "") -> None:
    """SimulationDiverged naming the first coordinate of q beyond its range (by more than RANGE_TOLERANCE)."""
    outside = np.flatnonzero((q < lower - RANGE_TOLERANCE) | (q > upper + RANGE_TOLERANCE))
    if outside.size:
        j = int(outside[0])
        # repr: the shortest text that is the exact value, so the violation shows
        raise SimulationDiverged(f"{where}: joint {JOINT_NAMES[j]} at {float(q[j])!r} outside its range "
                                 f"[{float(lower[j])!r}, {float(upper[j])!r}]{why}")


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

    def _check(self, x: np.ndarray, v: np.ndarray, q: np.ndarray, in_range: bool | None = None) -> None:
        """Divergence checks at the state (x, v) after a step (q: its coordinates):
        NaN and range of the coordinates every step; NaN of every dof and the
        loop closure every CLOSURE_CHECK_EVERY_STEPS steps (the frame queries cost
        more than a step)."""
        lower, upper = self.model.joint_lower, self.model.joint_upper
        if in_range is None:  # (the servo's kernel tells it) False when a coordinate is NaN or out of its range
            in_range = np.maximum.reduce(np.abs(q - self._range_mid) - self._range_half) <= 0.0
        if in_range and self.step_index % CLOSURE_CHECK_EVERY_STEPS:
            return
        finite = math.isfinite(np.add.reduce(x) + np.add.reduce(v))  # the passive dofs too
        where = f"step {self.step_index} (t = {self.time_s:.3f} s)"
        if not finite:
            bad = int(np.flatnonzero(~(np.isfinite(x) & np.isfinite(v)))[0])
            raise SimulationDiverged(f"{where}: joint {self.skeleton.getDof(bad).getName()} is not finite")
        raise_if_out_of_range(q, lower, upper, where)
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

    # ------------------------------------------------- batched readout
    def frames_at(self, X: np.ndarray) -> dict[int, np.ndarray]:
        """Base-frame transforms (N, 4, 4) of every link frame at logged dof
        positions X (N, n_dofs): DART's tree kinematics (each joint's placement in
        its parent as DART holds it, then its rotation or translation about z),
        evaluated for a whole run at once; equal to DART's own frames at those
        states to round-off (tests/test_simulator.py)."""
        X = np.asarray(X, dtype=float)
        frames: dict[int, np.ndarray] = {0: np.broadcast_to(np.eye(4), (len(X), 4, 4))}
        for key, parent, placement, revolute, dof in self._tree:
            motion = np.tile(np.eye(4), (len(X), 1, 1))
            if revolute:
                c, s = np.cos(X[:, dof]), np.sin(X[:, dof])
                motion[:, 0, 0], motion[:, 0, 1], motion[:, 1, 0], motion[:, 1, 1] = c, -s, s, c
            else:
                motion[:, 2, 3] = X[:, dof]
            frames[key] = frames[parent] @ placement @ motion
        for key, (parent, offset) in self.psm.fixed_frames.items():
            frames[key] = frames[parent] @ offset
        del frames[0]
        return frames

    def readout_at(self, X: np.ndarray, q: np.ndarray) -> dict[str, np.ndarray]:
        """What the logs keep of each logged state, for a whole run: the largest
        loop-closure gap (m), the largest passive-joint error (rad), the
        counterweight's error (m, NaN without it), the link frame origins
        (N, B, 3) and the tool tip poses (N, 4, 4)."""
        X, q = np.asarray(X, dtype=float), np.asarray(q, dtype=float)
        frames = self.frames_at(X)
        gaps = [np.zeros(len(X))]
        for c in self.psm.closures:
            Ta, Tb = frames[c.link], frames[c.other]
            pa = Ta[:, :3, :3] @ c.point_in_link + Ta[:, :3, 3]
            pb = Tb[:, :3, :3] @ c.point_in_other + Tb[:, :3, 3]
            gaps.append(np.linalg.norm(pa - pb, axis=1))
        passive = np.abs(X[:, self._passive_only] - q @ self._G_passive.T)
        cw = self.psm.counterweight_dof
        tip = self.model.tool_tip
        return {
            "closure": np.max(gaps, axis=0),
            "passive": passive.max(axis=1, initial=0.0),
            "counterweight": np.full(len(X), np.nan) if cw is None else X[:, cw] - self.model.counterweight_ratio * q[:, INSERTION],
            "bodies": np.stack([frames[k][:, :3, 3] for k in self._body_keys], axis=1),
            "tool": frames[tip.parent] @ tip.transforms(q),
        }

    def _setup_readout(self) -> None:
        """Names and orders fixed by the built arm (called once by the simulator)."""
        self._body_keys = sorted(list(self.psm.fixed_frames) + list(self.psm.bodies))
        self.body_names = [self.model.links[k].name for k in self._body_keys]
        dofs = list(self.psm.passive_dofs)
        if self.psm.counterweight_dof is not None:
            dofs.append(self.psm.counterweight_dof)
        self._passive_and_counterweight = dofs
        self._passive_only = np.asarray(self.psm.passive_dofs, dtype=int)
        self._G_passive = self.psm.G[self._passive_only]
        key_of = {body.getName(): key for key, body in self.psm.bodies.items()}
        self._tree = []  # bodies in creation order: a parent comes before its children
        for key, body in self.psm.bodies.items():
            joint, parent = body.getParentJoint(), body.getParentBodyNode()
            if not np.allclose(joint.getTransformFromChildBodyNode().matrix(), np.eye(4)):
                raise DvrkDartError(f"{joint.getName()}: a child-side joint offset is not supported by the batched readout")
            placement = joint.getTransformFromParentBodyNode().matrix()
            parent_key = 0 if parent is None else key_of[parent.getName()]
            self._tree.append((key, parent_key, placement, joint.getType() == "RevoluteJoint", joint.getIndexInSkeleton(0)))
        self._passive_names = [self.model.links[self.psm.dof_links[d]].name for d in dofs]
        self._state_changed()

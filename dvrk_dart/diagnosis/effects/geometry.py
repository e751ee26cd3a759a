"""Where a payload may sit on a link (its envelope) and which coordinates move a link."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.dh import dh_transform
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS

#: margin around a link's DH skeleton (joint origins, closure points) inside
#: which a payload may sit: bar width plus a clamp, m
ENVELOPE_MARGIN_M = 0.05


@dataclass(frozen=True)
class LinkEnvelope:
    """Axis-aligned box in a link's own frame where a payload may sit (m)."""

    link: int
    lower: np.ndarray
    upper: np.ndarray
    skeleton_points: np.ndarray  # (k, 3) the DH points the box was built from

    def contains(self, point: np.ndarray, tolerance_m: float = 1e-9) -> bool:
        p = np.asarray(point)
        return bool(np.all(p >= self.lower - tolerance_m) and np.all(p <= self.upper + tolerance_m))

    def on_boundary(self, point: np.ndarray, tolerance_m: float = 1e-4) -> bool:
        p = np.asarray(point)
        return bool(np.any(np.abs(p - self.lower) < tolerance_m) or np.any(np.abs(p - self.upper) < tolerance_m))


def _variable_range(expr, model: PsmModel) -> tuple[float, float]:
    """Range of a linear expression of q over the joint limits."""
    lo = expr.const + np.sum(np.minimum(expr.coeffs * model.joint_lower, expr.coeffs * model.joint_upper))
    hi = expr.const + np.sum(np.maximum(expr.coeffs * model.joint_lower, expr.coeffs * model.joint_upper))
    return float(lo), float(hi)


def _child_origins(model: PsmModel, key: int, T_key_to_link: np.ndarray, points: list) -> None:
    """Origins of the children of `key`, in the frame of the envelope's link, at
    the ends of their joint ranges; fixed children are part of the same body."""
    zero = np.zeros(N_JOINTS)
    for child in model.children(key):
        a, alpha = float(child.a(zero)), float(child.alpha(zero))
        if child.joint_type == "prismatic":
            d_values = _variable_range(child.d, model)
            thetas = (float(child.theta(zero)),)
        else:  # a revolute child's origin does not depend on its angle
            d_values = (float(child.d(zero)),)
            thetas = (float(child.theta(zero)),)
        for d in d_values:
            for theta in thetas:
                T = T_key_to_link @ dh_transform(a, alpha, d, theta)
                points.append(T[:3, 3])
                if child.joint_type == "fixed":
                    _child_origins(model, child.key, T, points)


def link_envelope(model: PsmModel, key: int, margin_m: float = ENVELOPE_MARGIN_M, body_points=()) -> LinkEnvelope:
    """Bounding box of a link's DH skeleton and `body_points` (link frame, m:
    the identified centre of mass, where the link's own body is), widened by `margin_m`.

    The skeleton: the link's own joint origin, the origins of its children
    (prismatic children at both ends of their travel, fixed children with their
    own children), the loop-closure points on the link, and, for a revolute link
    whose axis passes through its parent's origin (the tool shaft), that origin."""
    link = model.links[key]
    points: list[np.ndarray] = [np.zeros(3)]
    _child_origins(model, key, np.eye(4), points)
    frames = model.forward_kinematics(np.zeros(N_JOINTS))
    for closure in model.loop_closures:
        if closure.link == key:
            points.append(closure.point_in_link)
        elif closure.other == key:
            p_base = frames[closure.link] @ np.r_[closure.point_in_link, 1.0]
            points.append((np.linalg.inv(frames[key]) @ p_base)[:3])
    zero = np.zeros(N_JOINTS)
    if link.joint_type == "revolute" and abs(float(link.a(zero))) < 1e-12:
        points.append(np.array([0.0, 0.0, -float(link.d(zero))]))
    pts = np.array(points + [np.asarray(p, dtype=float) for p in body_points])
    return LinkEnvelope(key, pts.min(axis=0) - margin_m, pts.max(axis=0) + margin_m, pts)


def joints_moving_link(model: PsmModel, key: int) -> tuple[str, ...]:
    """The coordinates that move a link (its own and its ancestors' variables)."""
    coeffs = np.zeros(N_JOINTS)
    k = key
    while k != 0:
        link = model.links[k]
        if link.variable is not None:
            coeffs = coeffs + np.abs(link.variable.coeffs)
        k = link.parent
    return tuple(JOINT_NAMES[j] for j in np.flatnonzero(coeffs))


def arm_reach_m(model: PsmModel, key: int) -> float:
    """How far from a link's origin any part of the arm reaches (m): the corners
    of every link's envelope at q = 0, in the base frame. A user's payload
    position farther than that is not on the arm (millimetres given as metres)."""
    frames = model.forward_kinematics(np.zeros(N_JOINTS))
    origin = frames[key][:3, 3]
    reach = 0.0
    for link in model.links.values():
        if link.key not in frames or not link.body:
            continue
        envelope = link_envelope(model, link.key)
        corners = np.array([[x, y, z, 1.0] for x in (envelope.lower[0], envelope.upper[0])
                            for y in (envelope.lower[1], envelope.upper[1]) for z in (envelope.lower[2], envelope.upper[2])])
        reach = max(reach, float(np.max(np.linalg.norm((corners @ frames[link.key].T)[:, :3] - origin, axis=1))))
    return reach

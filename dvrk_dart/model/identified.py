"""The identified dynamic model (Wang et al. 2019) evaluated with Pinocchio.

The identification model is a tree of links whose joint variables are linear
functions of the seven coordinates q: theta_tree = G q + c. Pinocchio holds the
tree (one joint per moving link, in the link's DH frame), and the coupled
coordinates are handled by projection:
    tau = G^T tau_tree(G q + c, G dq, G ddq),   M = G^T M_tree G.
Non-inertial terms follow the upstream package exactly (see
../shared/docs/psm-identified-model.md): friction of a link acts on the rate of
its own joint variable and is projected by its chain rule; the J4 spring gives
+K q4; a motor inertia Im adds Im times its variable's acceleration to the one
coordinate that variable depends on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model import friction
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.dh import DHFrame, Link, dh_transform
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters
from dvrk_dart.model.reduced_dynamics import ReducedDynamics

#: the rigid-body terms of the identified model (what the inertial arm simulates)
INERTIAL_TERMS = ("inertia", "coriolis", "gravity")

NON_INERTIAL_TERMS = ("friction", "offset", "spring", "motor_inertia")
TERMS = INERTIAL_TERMS + NON_INERTIAL_TERMS
TERM_GROUPS = {
    "all": TERMS,
    "inertial": INERTIAL_TERMS,
}
TOOL_TIP_FRAME = "tool_tip"


def parse_terms(spec: str) -> tuple[str, ...]:
    """'all', 'inertial', 'inertial,friction', 'gravity' ... -> term names."""
    names: list[str] = []
    for part in (p.strip() for p in spec.split(",")):
        expanded = TERM_GROUPS.get(part, (part,))
        for name in expanded:
            if name not in TERMS:
                raise DvrkDartError(f"--terms: unknown term '{part}' (known: {', '.join(list(TERM_GROUPS) + list(TERMS))})")
            if name not in names:
                names.append(name)
    return tuple(names)


def terms_label(spec: str) -> str:
    """--terms in its own words: a group's name where the terms are one ('all,inertial' is all), else the parts given."""
    names = parse_terms(spec)
    parts = dict.fromkeys(p.strip() for p in spec.split(","))
    return next((group for group, members in TERM_GROUPS.items() if set(members) == set(names)), ",".join(parts))


def spring_torque(stiffness: float, x: np.ndarray, linkage: dict[str, float] | None) -> np.ndarray:
    """A spring's effort on its variable x: +K x (the PSM's J4, rest at x = 0),
    or through a linkage (the MTM's wrist pitch, upstream main_mtm.ipynb): a
    spring of rest length l_r between a crank of radius r_s and a point h_s
    away, at angle pi + q_o - x: effort -K r_f (l - l_r), r_f its lever arm."""
    if linkage is None:
        return stiffness * x
    r_s, h_s, rest = linkage["r_s"], linkage["h_s"], linkage["l_r"]
    angle = np.pi + np.radians(linkage["q_o_deg"]) - x
    length = np.sqrt(r_s**2 + h_s**2 - 2.0 * r_s * h_s * np.cos(angle))
    lever = r_s * h_s * np.sin(angle) / length
    return -stiffness * lever * (length - rest)


def body_inertia(mass: float, com: np.ndarray, inertia_com: np.ndarray) -> pin.Inertia:
    """Pinocchio's inertia of a body as identified, physical or not: the
    identified model is evaluated as published (the MTM's parameters have
    inertias with negative eigenvalues, which pin.Inertia's constructor refuses)."""
    inertia = pin.Inertia.Zero()
    inertia.mass, inertia.lever, inertia.inertia = float(mass), np.asarray(com, float).copy(), np.asarray(inertia_com, float).copy()
    return inertia


def _se3(T: np.ndarray) -> pin.SE3:
    return pin.SE3(T[:3, :3].copy(), T[:3, 3].copy())


def _placement(link: DHFrame) -> np.ndarray:
    """Constant part of a link's DH transform; the joint supplies the variable."""
    zero = np.zeros(N_JOINTS)
    a, alpha = float(link.a(zero)), float(link.alpha(zero))
    if link.joint_type == "revolute":  # Rz(theta) Tz(d) = Tz(d) Rz(theta): d is constant
        return dh_transform(a, alpha, float(link.d(zero)), 0.0)
    if link.joint_type == "prismatic":  # Rz(theta) Tz(d): the joint's Tz comes last
        return dh_transform(a, alpha, 0.0, float(link.theta(zero)))
    return link.transform(zero)


def _depth_first(model: PsmModel) -> list[DHFrame]:
    """Body links and the tool-tip frame, parents first, each subtree contiguous."""
    order: list[DHFrame] = []

    def visit(key: int) -> None:
        for child in model.children(key):
            if child.body:
                order.append(child)
                visit(child.key)
        if key == model.tool_tip.parent:
            order.append(model.tool_tip)

    visit(0)
    return order


@dataclass
class ModelEfforts:
    """Efforts of the identified model, term by term, each (N, 7)."""

    terms: dict[str, np.ndarray]

    def total(self, names: tuple[str, ...] | str = "all") -> np.ndarray:
        names = parse_terms(names) if isinstance(names, str) else names
        out = np.zeros_like(next(iter(self.terms.values())))
        for name in names:
            out = out + self.terms[name]
        return out


class IdentifiedModel:
    """M(q), C(q, dq) dq, g(q), friction, spring and motor-inertia terms."""

    def __init__(self, model: PsmModel, params: IdentifiedParameters):
        self.model = model
        self.params = params
        self.pin_model, self.tree_links = self._build_tree()
        self.data = self.pin_model.createData()
        self.G = np.array([link.variable.coeffs for link in self.tree_links])  # (n_tree, 7)
        self.c = np.array([link.variable.const for link in self.tree_links])
        self._GT = np.ascontiguousarray(self.G.T)
        self._reduced = ReducedDynamics.build(self.pin_model, self.G, self.c)
        self.tip_frame_id = self.pin_model.getFrameId(TOOL_TIP_FRAME)
        self._friction_links = [l for l in model.links.values() if l.friction]
        self._motor_links = [l for l in model.links.values() if l.motor_inertia]
        self._spring_links = [l for l in model.links.values() if l.spring]
        for link in self._motor_links:
            if np.count_nonzero(link.variable.coeffs) != 1:
                raise DvrkDartError(f"link {link.key}: motor inertia on a variable of several coordinates is not defined")

    # ---------------------------------------------------------------- building
    def _build_tree(self) -> tuple[pin.Model, list[Link]]:
        pm = pin.Model()
        pm.name = "psm_identified"
        pm.gravity = pin.Motion(np.r_[self.model.gravity, np.zeros(3)])
        # For each link key: (pinocchio joint id, transform from that joint frame to the link frame)
        anchor: dict[int, tuple[int, np.ndarray]] = {0: (0, np.eye(4))}
        tree_links: list[DHFrame] = []
        # Pinocchio's CRBA needs every subtree to be contiguous: add joints depth first.
        for link in _depth_first(self.model):
            parent_joint, parent_offset = anchor[link.parent]
            placement = parent_offset @ _placement(link)
            if link is self.model.tool_tip:
                if link.joint_type == "fixed":  # a frame on its parent (the MTM's gripper)
                    pm.addFrame(pin.Frame(TOOL_TIP_FRAME, parent_joint, _se3(placement), pin.FrameType.OP_FRAME))
                    continue
                # the PSM's tool tip turns with the wrist yaw (its own theta): a massless joint
                jid = pm.addJoint(parent_joint, pin.JointModelRZ(), _se3(placement), TOOL_TIP_FRAME)
                pm.addJointFrame(jid, -1)
                tree_links.append(link)
                continue
            p = self.params[link.key]
            if link.joint_type == "fixed":
                if p.mass > 0.0:
                    raise DvrkDartError(f"link {link.key}: a fixed link with mass is not supported")
                anchor[link.key] = (parent_joint, placement)
                continue
            joint = pin.JointModelRZ() if link.joint_type == "revolute" else pin.JointModelPZ()
            jid = pm.addJoint(parent_joint, joint, _se3(placement), f"link{link.key}_{link.name}")
            pm.appendBodyToJoint(jid, body_inertia(p.mass, p.com, p.inertia_com), pin.SE3.Identity())
            pm.addJointFrame(jid, -1)
            anchor[link.key] = (jid, np.eye(4))
            tree_links.append(link)
        return pm, tree_links

    # ------------------------------------------------------------ coordinates
    def tree_q(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q) @ self.G.T + self.c

    def tree_v(self, dq: np.ndarray) -> np.ndarray:
        return np.asarray(dq) @ self.G.T

    # -------------------------------------------------------- single queries
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Rigid-body M(q) (7x7), without motor inertia."""
        Mt = pin.crba(self.pin_model, self.data, self.tree_q(q))  # pin >= 3: the full symmetric matrix
        return self.G.T @ Mt @ self.G

    def gravity(self, q: np.ndarray) -> np.ndarray:
        return self.G.T @ pin.computeGeneralizedGravity(self.pin_model, self.data, self.tree_q(q))

    def coriolis(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """C(q, dq) dq."""
        qt, vt = self.tree_q(q), self.tree_v(dq)
        return self.G.T @ (pin.rnea(self.pin_model, self.data, qt, vt, np.zeros_like(vt)) - pin.computeGeneralizedGravity(self.pin_model, self.data, qt))

    def coriolis_matrix(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """C(q, dq) with dM/dt - 2C skew-symmetric (Pinocchio's factorisation)."""
        Ct = pin.computeCoriolisMatrix(self.pin_model, self.data, self.tree_q(q), self.tree_v(dq))
        return self.G.T @ Ct @ self.G

    def mcg(self, q: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """M, C dq and g in one query (what a torque controller needs)."""
        if self._reduced is not None:
            return self._reduced.mcg(q, dq)
        G = self.G
        pin.computeAllTerms(self.pin_model, self.data, G @ q + self.c, G @ dq)
        X = self._GT @ np.column_stack((self.data.M @ G, self.data.nle, self.data.g))
        n = G.shape[1]
        return X[:, :n], X[:, n] - X[:, n + 1], X[:, n + 1]

    def motor_inertia_matrix(self) -> np.ndarray:
        """Diagonal 7x7 of the identified motor inertias (the armature)."""
        diag = np.zeros(N_JOINTS)
        for link in self._motor_links:
            j = int(np.flatnonzero(link.variable.coeffs)[0])
            diag[j] += self.params[link.key].motor_inertia * link.variable.coeffs[j]
        return np.diag(diag)

    def potential_energy(self, q: np.ndarray) -> float:
        return float(pin.computePotentialEnergy(self.pin_model, self.data, self.tree_q(q)))

    # ---------------------------------------------------------- kinematics
    def tool_tip_pose(self, q: np.ndarray) -> np.ndarray:
        """4x4 base-frame pose of the tool tip."""
        pin.framesForwardKinematics(self.pin_model, self.data, self.tree_q(q))
        return self.data.oMf[self.tip_frame_id].homogeneous.copy()

    def tool_tip_pose_and_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The tool tip's pose and Jacobian from one kinematics pass (a controller's step asks for both)."""
        pin.computeJointJacobians(self.pin_model, self.data, self.tree_q(q))
        pin.updateFramePlacements(self.pin_model, self.data)
        J_tree = pin.getFrameJacobian(self.pin_model, self.data, self.tip_frame_id, pin.LOCAL_WORLD_ALIGNED)
        return self.data.oMf[self.tip_frame_id].homogeneous.copy(), J_tree @ self.G

    def tool_tip_bias_acceleration(self, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """dJ/dt dq (linear; angular) of the tool tip: its acceleration at ddq = 0."""
        pin.forwardKinematics(self.pin_model, self.data, self.tree_q(q), self.tree_v(dq), np.zeros(self.pin_model.nv))
        pin.updateFramePlacements(self.pin_model, self.data)
        acc = pin.getFrameClassicalAcceleration(self.pin_model, self.data, self.tip_frame_id, pin.LOCAL_WORLD_ALIGNED)
        return np.r_[acc.linear, acc.angular]

    # ------------------------------------------------------------ batch terms
    def efforts(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, terms: tuple[str, ...] = TERMS) -> ModelEfforts:
        """Every requested term over a trajectory (N, 7) arrays -> ModelEfforts."""
        q, dq, ddq = (np.atleast_2d(np.asarray(x, dtype=float)) for x in (q, dq, ddq))
        out: dict[str, np.ndarray] = {}
        if any(t in INERTIAL_TERMS for t in terms):
            out.update(self._rigid_body_terms(q, dq, ddq, terms))
        if "friction" in terms or "offset" in terms:
            fric, offs = np.zeros_like(q), np.zeros_like(q)
            for link in self._friction_links:
                p = self.params[link.key]
                coeffs = link.variable.coeffs
                rate = dq @ coeffs
                reversing = friction.reversal(q @ coeffs, rate, p.presliding)
                fric += np.outer(p.coulomb * reversing + p.viscous * rate, coeffs)
                offs += np.outer(np.full(len(q), p.offset), coeffs)
            if "friction" in terms:
                out["friction"] = fric
            if "offset" in terms:
                out["offset"] = offs
        if "spring" in terms:
            spring = np.zeros_like(q)
            for link in self._spring_links:
                var = link.variable
                stiffness = self.params[link.key].spring
                torque = spring_torque(stiffness, q @ var.coeffs, link.spring_linkage)
                spring += np.outer(torque, var.coeffs)
            out["spring"] = spring
        if "motor_inertia" in terms:
            out["motor_inertia"] = ddq @ self.motor_inertia_matrix().T
        return ModelEfforts({t: out[t] for t in terms})

    def _rigid_body_terms(self, q, dq, ddq, terms) -> dict[str, np.ndarray]:
        """Gravity, Coriolis and inertia terms, sample by sample in Pinocchio, on
        the small mimic model when there is one (same numbers, fewer joints)."""
        if self._reduced is not None:
            grav, nle, total = self._reduced.batch(q, dq, ddq)
            result = {"gravity": grav, "coriolis": nle - grav, "inertia": total - nle}
            return {t: result[t] for t in INERTIAL_TERMS if t in terms}
        qt, vt, at = self.tree_q(q), self.tree_v(dq), self.tree_v(ddq)
        zeros = np.zeros(self.pin_model.nv)
        grav, nle, total = np.empty_like(qt), np.empty_like(qt), np.empty_like(qt)
        model, data = self.pin_model, self.data
        for k in range(len(qt)):
            grav[k] = pin.computeGeneralizedGravity(model, data, qt[k])
            nle[k] = pin.rnea(model, data, qt[k], vt[k], zeros)
            total[k] = pin.rnea(model, data, qt[k], vt[k], at[k])
        G = self.G
        result = {"gravity": grav @ G, "coriolis": (nle - grav) @ G, "inertia": (total - nle) @ G}
        return {t: result[t] for t in INERTIAL_TERMS if t in terms}

    def predict(self, q, dq, ddq, terms: tuple[str, ...] | str = "all") -> np.ndarray:
        terms = parse_terms(terms) if isinstance(terms, str) else terms
        return self.efforts(q, dq, ddq, terms).total(terms)

    def friction_partners(self, joint: int) -> dict[int, list[str]]:
        """The other joints that share an identified friction with `joint` (a link moved by several
        coordinates: the PSM's jaw blades), each with those links' names."""
        partners: dict[int, list[str]] = {}
        for link in self._friction_links:
            coeffs = link.variable.coeffs
            if coeffs[joint] != 0.0:
                for k in np.flatnonzero(coeffs):
                    if k != joint:
                        partners.setdefault(int(k), []).append(link.name)
        return partners

    def held_joint_change(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, joint: int) -> np.ndarray:
        """Per joint, the largest change of the rigid-body efforts (inertia,
        Coriolis, gravity) at the states (q, dq, ddq) when `joint` goes from
        where `q` holds it to either end of its range: what holding a joint a
        log did not record may cost the efforts of the others."""
        held = self.predict(q, dq, ddq, INERTIAL_TERMS)
        change = np.zeros(q.shape[1])
        for end in (self.model.joint_lower[joint], self.model.joint_upper[joint]):
            moved = np.array(q, dtype=float)
            moved[:, joint] = end
            change = np.maximum(change, np.max(np.abs(self.predict(moved, dq, ddq, INERTIAL_TERMS) - held), axis=0))
        return change

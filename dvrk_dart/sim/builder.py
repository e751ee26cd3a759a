"""Builds the DART world of the PSM from the model description (`PsmModel`)
and the identified parameters, as the real closed-chain mechanism.

Bodies and frames
    Every link with a rigid body gets a DART BodyNode whose frame IS the link's
    modified-DH frame: the joint's parent-side transform is the constant part of
    the DH transform (everything at q = 0, including the constant theta or d
    offsets) and the joint turns or slides about the local z axis. So a DART
    dof position is the link's joint variable minus its constant: x = G q, with
    G the coefficient rows of the model's linear relations.  A massless fixed
    frame (link 3, pitch_back) gets no body: it is folded into its children's
    joint transforms and kept as a fixed offset for `link_transform`.

Inertial parameters (the paper's Eq. 3-4 reduced to link frames)
    The paper places the identified parameters, given in the base frame at
    q = 0, into the simulator's body frames with r_body = R^T r and
    I_body = R^T I R.  `parameters.py` already applies that rotation with
    R = R_i(0), the link frame at q = 0; since the DART body frame is the link
    frame, `com` and `inertia_com` go in directly: DART's `Inertia(m, com,
    I)` takes the centre of mass in the body frame and the inertia about the
    centre of mass with body-frame axes.

Closed chains
    Joints: J1 yaw and J2 pitch revolute, J3 prismatic, the tool joints revolute
    on the physical wrist angles (qm5..qm7); every other parallelogram link is a
    passive revolute.  The two parallelogram loops are closed by DART loop
    constraints (`[[loop_closures]]` of psm.toml), created after the skeleton is
    put in a configuration where each loop is closed.  The counterweight slides
    on the pitch link on its own prismatic joint; how it is tied to J3 depends on
    the variant (see `simulator.py`).

Numerical choices (documented here because they are the only numbers in code)
    - links the identification leaves without mass (the tool) get
      NEGLIGIBLE_MASS_KG and NEGLIGIBLE_INERTIA_KG_M2: DART needs an invertible
      joint-space inertia; the effect on the 7 efforts is tested below 1e-5.
    - inertias about the centre of mass that break the triangle inequality by a
      few 1e-6 kg m^2 (an identification artefact) are projected onto the
      nearest physically consistent tensor (`physical_inertia`); the change of
      the 7 efforts is tested.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import dartpy as dart
import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.dh import Link
from dvrk_dart.model.joints import N_JOINTS
from dvrk_dart.model.parameters import IdentifiedParameters, inertia_violation
from dvrk_dart.sim.config import SimConfig

#: mass given to links the identification leaves massless (tool links): 0.1 g.
#: Their gravity moment at 0.6 m from the pitch axis is < 1e-6 N·m per link.
NEGLIGIBLE_MASS_KG = 1e-7
#: principal inertia about the centre of mass of such links (kg m^2); it is the
#: whole joint-space inertia of the wrist dofs, so it must stay > 0.
NEGLIGIBLE_INERTIA_KG_M2 = 1e-10
#: a payload is a point mass; DART needs a rotational inertia > 0
PAYLOAD_INERTIA_KG_M2 = 1e-9
#: margin added when an inertia tensor is made physically consistent (kg m^2):
#: the triangle inequality then holds strictly, far below identification accuracy
INERTIA_MARGIN_KG_M2 = 1e-9

#: DART constraint solver settings (see `configure_solver`)
#: error reduction: fraction of a loop's position error removed per step; a
#: closed loop never opens by more than round-off, so ERP only cleans drift.
LOOP_ERROR_REDUCTION = 0.2
#: constraint force mixing: a tiny diagonal regularisation needed because each
#: planar loop closed with a ball constraint is rank-deficient by one row.
LOOP_FORCE_MIXING = 1e-9
#: error allowance (m): DART ignores position errors below this; 0 = none.
LOOP_ERROR_ALLOWANCE_M = 0.0


@dataclass
class LoopClosureConstraint:
    """A DART loop constraint between two bodies with the closure point in each body frame."""

    name: str
    link: int
    other: int
    point_in_link: np.ndarray  # m, frame of `link`
    point_in_other: np.ndarray  # m, frame of `other`
    constraint: object  # dart.constraint.BallJointConstraint


@dataclass
class DartPsm:
    """The built world and the map between the 7 coordinates and DART's dofs."""

    world: dart.simulation.World
    skeleton: dart.dynamics.Skeleton
    bodies: dict[int, dart.dynamics.BodyNode]  # link key -> body (links with a joint)
    joints: dict[int, dart.dynamics.Joint]
    fixed_frames: dict[int, tuple[int, np.ndarray]]  # link key -> (body link key or 0, fixed transform)
    dof_links: tuple[int, ...]  # link key of each DART dof, in skeleton dof order
    G: np.ndarray  # (n_dofs, 7) x = G q for every dof tied to q by the mechanism
    actuated_dofs: np.ndarray  # (7,) dof index of each actuated joint (coordinate order)
    A: np.ndarray  # (7, 7) actuated dof positions = A q (identity for q1..q4, W for the wrist)
    passive_dofs: np.ndarray  # dofs that follow the linear relations through the closures
    counterweight_dof: int | None  # None when the counterweight is removed
    closures: list[LoopClosureConstraint] = field(default_factory=list)
    payload_bodies: list[dart.dynamics.BodyNode] = field(default_factory=list)

    @property
    def n_dofs(self) -> int:
        return self.skeleton.getNumDofs()


def gravity_in_base(model: PsmModel, tilt_rad: tuple[float, float]) -> np.ndarray:
    """Gravity in the base frame of a base mounted with a tilt about base x, then y.

    The base frame is R = Rx(tilt_x) Ry(tilt_y) in the world; gravity stays
    fixed in the world, so in base coordinates it is R^T g."""
    ax, ay = tilt_rad
    cx, sx, cy, sy = math.cos(ax), math.sin(ax), math.cos(ay), math.sin(ay)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return (rx @ ry).T @ model.gravity


def physical_inertia(inertia: np.ndarray, margin: float = INERTIA_MARGIN_KG_M2) -> np.ndarray:
    """The nearest tensor (same principal axes) that is positive definite and
    satisfies the triangle inequalities; the tensor itself when it already does.

    Raising the smallest principal moment is the smallest change that restores
    a + b >= c; it is what DART needs for a body that can be a tree leaf."""
    if inertia_violation(inertia) == 0.0 and np.linalg.eigvalsh(inertia)[0] > 0.0:
        return inertia
    values, vectors = np.linalg.eigh(inertia)  # ascending: a <= b <= c
    a, b, c = values
    c = max(c, margin)  # every moment negative (the MTM's published link 7): the smallest body there is
    b = max(b, margin)
    a = max(a, c - b + margin, margin)
    return vectors @ np.diag([a, b, c]) @ vectors.T


def body_inertia(link: Link, params: IdentifiedParameters, scale: float = 1.0) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, com in the link frame, inertia about the com in link axes) used in DART; `scale` multiplies
    the mass and the inertia (`JointEffects.link_mass_scale`: a link lighter or heavier than identified)."""
    p = params[link.key]
    if p.mass <= 0.0:
        return NEGLIGIBLE_MASS_KG, np.zeros(3), NEGLIGIBLE_INERTIA_KG_M2 * np.eye(3)
    return scale * p.mass, p.com.copy(), scale * physical_inertia(p.inertia_com)


def _mass_scales(config: SimConfig, model: PsmModel) -> dict[int, float]:
    """Per link key, the factor of `JointEffects.link_mass_scale` (its entries' errors added)."""
    scales: dict[int, float] = {}
    for entry in config.extra.link_mass_scale:
        if len(entry) != 2 or int(entry[0]) not in model.links:
            raise DvrkDartError(f"sim_config.extra.link_mass_scale: {list(entry)} is not [a link of the model, an error]")
        if int(entry[0]) == model.counterweight_link and config.counterweight == "off":
            raise DvrkDartError("sim_config.extra.link_mass_scale: the counterweight's mass scaled with the counterweight off")
        key, error = entry
        scales[int(key)] = scales.get(int(key), 1.0) + float(error)
    if any(scale <= 0.0 for scale in scales.values()):
        raise DvrkDartError(f"sim_config.extra.link_mass_scale: a link's mass scaled to zero or below ({scales})")
    return scales


def _isometry(T: np.ndarray) -> dart.math.Isometry3:
    return dart.math.Isometry3(T[:3, :3].copy(), T[:3, 3].copy())


def _select_actuated(model: PsmModel, moving: list[Link]) -> list[Link]:
    """One actuated joint per coordinate: walking the links in file order, a link
    is actuated when its coefficient row adds a new direction (so J2 before the
    parallelogram links that repeat q2, J3's carriage before the counterweight)."""
    chosen: list[Link] = []
    for link in moving:
        if link.group == "counterweight":
            continue
        rows = np.array([l.variable.coeffs for l in chosen + [link]])
        if np.linalg.matrix_rank(rows) == len(chosen) + 1:
            chosen.append(link)
    if len(chosen) != N_JOINTS:
        raise DvrkDartError(f"{model.source}: found {len(chosen)} independent actuated joints, expected {N_JOINTS}")
    # order them by coordinate: the actuated-dof matrix becomes block triangular
    rows = np.array([l.variable.coeffs for l in chosen])
    order = np.argsort([int(np.flatnonzero(r)[-1]) for r in rows], kind="stable")
    return [chosen[i] for i in order]


def configure_solver(world: dart.simulation.World) -> None:
    """Constraint solver settings for accurate closed chains.

    - Dantzig boxed LCP (a pivoting, exact solver) as primary (DART's default): the loop and
      transmission rows are bilateral, so the LCP is a linear solve and Dantzig
      returns it to round-off; PGS (iterative) stays DART's fallback.
    - ERP / CFM / allowance: see the module constants.  DART keeps them as
      class-wide values of `DynamicJointConstraint` (all ball/revolute loop
      constraints of the process share them)."""
    solver = world.getConstraintSolver()
    # dartpy 6.20 cannot construct a Dantzig solver, but it is the world's default
    primary = solver.getBoxedLcpSolver().getType()
    if primary != "DantzigBoxedLcpSolver":
        raise DvrkDartError(f"DART's boxed LCP solver is {primary}, the simulator relies on Dantzig")
    dart.constraint.DynamicJointConstraint.setErrorReductionParameter(LOOP_ERROR_REDUCTION)
    dart.constraint.DynamicJointConstraint.setConstraintForceMixing(LOOP_FORCE_MIXING)
    dart.constraint.DynamicJointConstraint.setErrorAllowance(LOOP_ERROR_ALLOWANCE_M)


def build(model: PsmModel, params: IdentifiedParameters, config: SimConfig) -> DartPsm:
    """The DART world of the PSM in the closed-chain configuration q = 0."""
    if config.counterweight not in ("on", "off", "pid"):
        raise DvrkDartError(f"counterweight must be on, off or pid, not '{config.counterweight}'")
    world = dart.simulation.World()
    world.setTimeStep(config.dt_s)
    world.setGravity(gravity_in_base(model, config.gravity_tilt_rad))
    configure_solver(world)
    skel = dart.dynamics.Skeleton("psm")
    bodies, joints, fixed_frames, moving = _tree(skel, model, params, config)
    payload_bodies = _add_payloads(skel, bodies, config.payloads)

    world.addSkeleton(skel)
    dof_links = tuple(_link_of_dof(skel, joints))
    actuated = _select_actuated(model, moving)
    index = {key: i for i, key in enumerate(dof_links)}
    cw_dof = index.get(model.counterweight_link)
    G = np.array([model.links[key].variable.coeffs for key in dof_links])
    if cw_dof is not None:
        # the counterweight joint is a free dof of the tree: the tendon that ties it
        # to q3 is a force computed by the simulator (ideal constraint or PID)
        G[cw_dof] = 0.0
    actuated_dofs = np.array([index[l.key] for l in actuated])
    passive = np.array([i for i, key in enumerate(dof_links) if i not in set(actuated_dofs) and key != model.counterweight_link])
    psm = DartPsm(
        world=world,
        skeleton=skel,
        bodies=bodies,
        joints=joints,
        fixed_frames=fixed_frames,
        dof_links=dof_links,
        G=G,
        actuated_dofs=actuated_dofs,
        A=G[actuated_dofs],
        passive_dofs=passive,
        counterweight_dof=cw_dof,
        payload_bodies=payload_bodies,
    )
    # Close the loops in a configuration where they are closed (the linear relations at q = 0).
    skel.setPositions(G @ np.zeros(N_JOINTS))
    skel.setVelocities(np.zeros(skel.getNumDofs()))
    for closure in model.loop_closures:
        psm.closures.append(_close_loop(psm, closure))
    return psm


def _tree(skel, model: PsmModel, params: IdentifiedParameters, config: SimConfig):
    """The links' bodies and one-dof joints on `skel`, placed at q = 0 (a fixed
    link rides on its parent's body). Returns (bodies, joints, fixed frames:
    key -> (body key, offset), the moving links)."""
    bodies: dict[int, dart.dynamics.BodyNode] = {}
    joints: dict[int, dart.dynamics.Joint] = {}
    fixed_frames: dict[int, tuple[int, np.ndarray]] = {}
    # where a link frame sits: (key of the DART body it rides on, 0 = base; offset)
    anchor: dict[int, tuple[int, np.ndarray]] = {0: (0, np.eye(4))}
    mass_scales = _mass_scales(config, model)
    zero = np.zeros(N_JOINTS)
    moving: list[Link] = []
    for link in model.links.values():
        if not link.body:
            continue
        if link.key == model.counterweight_link and config.counterweight == "off":
            continue
        parent_body, parent_offset = anchor[link.parent]
        placement = parent_offset @ link.transform(zero)
        if link.joint_type == "fixed":
            if params[link.key].mass > 0.0:
                raise DvrkDartError(f"link {link.key} ({link.name}): a fixed link with mass is not supported")
            anchor[link.key] = (parent_body, placement)
            fixed_frames[link.key] = (parent_body, placement)
            continue
        joint, body = _joint_and_body(skel, bodies.get(parent_body), link, placement)
        mass, com, inertia = body_inertia(link, params, mass_scales.get(link.key, 1.0))
        body.setInertia(dart.dynamics.Inertia(mass, com, inertia))
        bodies[link.key] = body
        joints[link.key] = joint
        anchor[link.key] = (link.key, np.eye(4))
        moving.append(link)
    return bodies, joints, fixed_frames, moving


def _joint_and_body(skel, parent_node, link: Link, placement: np.ndarray):
    """A force-actuated revolute or prismatic joint about z of `placement`, and its body."""
    if link.joint_type == "revolute":
        props = dart.dynamics.RevoluteJointProperties()
    else:
        props = dart.dynamics.PrismaticJointProperties()
    props.mName = f"joint{link.key}_{link.name}"
    props.mAxis = np.array([0.0, 0.0, 1.0])
    props.mT_ParentBodyToJoint = _isometry(placement)
    props.mT_ChildBodyToJoint = dart.math.Isometry3.Identity()
    create = skel.createRevoluteJointAndBodyNodePair if link.joint_type == "revolute" else skel.createPrismaticJointAndBodyNodePair
    joint, body = create(parent_node, props) if parent_node is not None else create(None, props)
    body.setName(f"link{link.key}_{link.name}")
    joint.setActuatorType(dart.dynamics.ActuatorType.FORCE)
    return joint, body


def _add_payloads(skel, bodies: dict, payloads) -> list:
    """Each payload a point-like body welded to its link's body."""
    payload_bodies = []
    for i, payload in enumerate(payloads):
        if payload.link not in bodies:
            raise DvrkDartError(f"payload {i}: link {payload.link} has no body in this simulation")
        joint, body = skel.createWeldJointAndBodyNodePair(bodies[payload.link])
        T = np.eye(4)
        T[:3, 3] = payload.position_m
        joint.setTransformFromParentBodyNode(_isometry(T))
        body.setName(f"payload{i}_on_link{payload.link}")
        body.setInertia(dart.dynamics.Inertia(payload.mass_kg, np.zeros(3), PAYLOAD_INERTIA_KG_M2 * np.eye(3)))
        payload_bodies.append(body)
    return payload_bodies


def _link_of_dof(skel, joints: dict[int, dart.dynamics.Joint]) -> list[int]:
    """Link key of each skeleton dof (every joint here has one dof)."""
    by_index = {j.getIndexInSkeleton(0): key for key, j in joints.items()}
    return [by_index[i] for i in range(skel.getNumDofs())]


def _close_loop(psm: DartPsm, closure) -> LoopClosureConstraint:
    """A ball-joint loop constraint at the closure point.

    Ball rather than revolute: every joint axis of a parallelogram is parallel,
    so the relative motion of the two bodies is planar and a point constraint
    already fixes the loop; a revolute constraint would add three more rows
    that the tree already satisfies identically (more rank deficiency for the
    LCP, no extra information)."""
    body = psm.bodies[closure.link]
    other = psm.bodies[closure.other]
    T_link = body.getWorldTransform().matrix()
    T_other = other.getWorldTransform().matrix()
    point_world = T_link[:3, :3] @ closure.point_in_link + T_link[:3, 3]
    point_in_other = T_other[:3, :3].T @ (point_world - T_other[:3, 3])
    constraint = dart.constraint.BallJointConstraint(body, other, point_world)
    psm.world.getConstraintSolver().addConstraint(constraint)
    return LoopClosureConstraint(closure.name, closure.link, closure.other, closure.point_in_link.copy(), point_in_other, constraint)

"""Identified dynamic parameters (params.json of Wang et al. 2019) in link frames.

params.json gives, per link, the mass `m`, the centre of mass `r` (from the
link frame origin) and the inertia `I` about the centre of mass, both with the
axes of the base frame at q = 0, i.e. rotated by that link's R_i(0). The loader
converts them back to the link (DH) frame, which is the frame of the DART body
and of the Pinocchio joint:  r_link = R_i(0)^T r,  I_link = R_i(0)^T I R_i(0)
(the paper's Eq. 3-4 with the world frame replaced by the link frame).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.description import PsmModel


@dataclass(frozen=True)
class LinkParameters:
    key: int
    mass: float  # kg
    com: np.ndarray  # m, link frame
    inertia_com: np.ndarray  # kg m^2, about the com, link-frame axes
    coulomb: float  # Fc, N·m or N
    viscous: float  # Fv
    offset: float  # Fo
    motor_inertia: float  # Im, kg m^2 (may be negative: see oddities)
    spring: float  # K, N·m/rad
    #: xs, m or rad: the distance over which Coulomb friction reverses (model/friction.py); 0: at once (sign)
    presliding: float = 0.0


@dataclass(frozen=True)
class IdentifiedParameters:
    source: Path
    links: dict[int, LinkParameters]

    def __getitem__(self, key: int) -> LinkParameters:
        return self.links[key]

    def unused_values(self, model: PsmModel) -> list[str]:
        """Non-zero values of terms the model card does not give a link (an Im where it has no motor): no
        simulation or model uses them, which a user who edited them must be told."""
        notes = []
        for key, p in self.links.items():
            link = model.links[key]
            given = {"Fc": (link.friction, p.coulomb), "Fv": (link.friction, p.viscous), "Fo": (link.friction, p.offset),
                     "Im": (link.motor_inertia, p.motor_inertia), "K": (link.spring, p.spring)}
            unused = [f"{name} = {float(np.max(np.abs(value))):.3g}" for name, (has, value) in given.items() if not has and np.any(value)]
            if unused:
                notes.append(f"{self.source.name}: link {key} ({link.name}): {', '.join(unused)} not used: the model card "
                             f"({model.source.name}) gives this link no such term")
        return notes

    def oddities(self, model: PsmModel) -> list[str]:
        """Physically feasible but implausible values, reported, never hidden."""
        notes = self.unused_values(model)
        for key, bound in model.identification_mass_bounds_kg.items():
            if key in self.links and abs(self.links[key].mass - bound) < 1e-3 * bound:
                notes.append(f"link {key} ({model.links[key].name}): mass {self.links[key].mass:.4f} kg sits at the identification bound {bound} kg")
        for key, p in self.links.items():
            principal = np.linalg.eigvalsh(p.inertia_com)
            excitable = _excitable_inertia(model, key, p.inertia_com)
            if principal[-1] > UNEXCITABLE_RATIO * max(excitable, 1e-12) and principal[-1] > 1e-3:
                notes.append(
                    f"link {key} ({model.links[key].name}): inertia of {principal[-1]:.3g} kg m^2 about axes it never "
                    f"rotates about (it rotates only where the inertia is {excitable:.2g} kg m^2): unidentifiable, "
                    "no effect on the 7 joint efforts"
                )
            violation = inertia_violation(p.inertia_com)
            if violation > 0.0:
                notes.append(
                    f"link {key} ({model.links[key].name}): inertia about the centre of mass is not quite physical "
                    f"(violation {violation:.2g} kg m^2, within the accepted {model.inertia_tolerance:.0e})"
                )
            if p.motor_inertia < 0.0:
                notes.append(
                    f"link {key} ({model.links[key].name if key in model.links else key}): negative motor inertia "
                    f"Im = {p.motor_inertia:.3g} kg m^2 (not a physical armature: applied as a model-based effort)"
                )
        return notes


#: a principal inertia this many times larger than any the link's motion can
#: excite is reported as unidentifiable
UNEXCITABLE_RATIO = 100.0


def _excitable_inertia(model: PsmModel, key: int, inertia_link: np.ndarray) -> float:
    """Largest inertia (kg m^2) about any direction the link can rotate about.

    The link's angular velocity is sum_j z_j (c_j . dq) over its revolute
    ancestors j (itself included): its directions span range(W), W = sum z_j c_j^T.
    """
    frames = model.forward_kinematics(np.zeros(len(model.joint_lower)))
    R_link = frames[key][:3, :3]
    W = np.zeros((3, len(model.joint_lower)))
    k = key
    while k != 0:
        link = model.links[k]
        if link.joint_type == "revolute":
            W += np.outer(R_link.T @ frames[k][:3, 2], link.theta.coeffs)
        k = link.parent
    U, sv, _ = np.linalg.svd(W)
    basis = U[:, sv > 1e-9 * max(sv.max(), 1e-300)]
    if basis.shape[1] == 0:
        return 0.0
    return float(np.linalg.eigvalsh(basis.T @ inertia_link @ basis)[-1])


def _vector(entry: dict, name: str, size: int, where: str) -> np.ndarray:
    value = entry.get(name)
    if name not in entry:
        raise DvrkDartError(f"{where}: '{name}' is missing")
    if not isinstance(value, list) or len(value) != size:
        raise DvrkDartError(f"{where}: '{name}' must be a list of {size} numbers")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise DvrkDartError(f"{where}: '{name}' must hold numbers") from None
    if not np.all(np.isfinite(arr)):
        raise DvrkDartError(f"{where}: '{name}' is not finite")
    return arr


def _scalar(entry: dict, name: str, where: str) -> float:
    if name not in entry:
        raise DvrkDartError(f"{where}: '{name}' is missing")
    value = entry[name]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise DvrkDartError(f"{where}: '{name}' must be a finite number")
    return float(value)


def inertia_matrix(vec6: np.ndarray) -> np.ndarray:
    """[Ixx, Ixy, Ixz, Iyy, Iyz, Izz] -> symmetric 3x3."""
    xx, xy, xz, yy, yz, zz = vec6
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def inertia_violation(inertia: np.ndarray) -> float:
    """How far (kg m^2) a tensor is from physical: the worst of its smallest
    eigenvalue and of the triangle inequalities a + b >= c; 0 when physical."""
    a, b, c = np.linalg.eigvalsh(inertia)
    return max(0.0, -a, c - a - b)


def check_inertia(inertia: np.ndarray, where: str, tolerance: float) -> None:
    """Symmetric, positive semi-definite and satisfying the triangle inequalities."""
    if not np.allclose(inertia, inertia.T, atol=1e-12):
        raise DvrkDartError(f"{where}: inertia tensor is not symmetric")
    violation = inertia_violation(inertia)
    if violation > tolerance:
        raise DvrkDartError(
            f"{where}: inertia tensor is not physically consistent (eigenvalues {np.linalg.eigvalsh(inertia)}, "
            f"violation {violation:.3g} kg m^2 > tolerance {tolerance:.3g})"
        )


#: a friction coefficient this far below zero is the identification's solver
#: round-off (its fit bounds friction at >= 0), not a negative friction
FRICTION_ROUND_OFF = 1e-9


def _friction(entry: dict, name: str, where: str) -> float:
    """A Coulomb or viscous coefficient: friction dissipates, so it is >= 0."""
    value = _scalar(entry, name, where)
    if value < -FRICTION_ROUND_OFF:
        raise DvrkDartError(f"{where}: {name} {value!r}: a friction dissipates energy, its coefficient is >= 0")
    return value


def _presliding(entry: dict, where: str) -> float:
    """The optional pre-sliding distance "xs" (absent in the upstream files: the sign law)."""
    if "xs" not in entry:
        return 0.0
    value = _scalar(entry, "xs", where)
    if value < 0.0:
        raise DvrkDartError(f"{where}: xs {value!r}: a pre-sliding distance is >= 0")
    return value


#: what a link of params.json holds: mass, first moment's point, inertia, Coulomb, viscous, offset, motor inertia,
#: spring, pre-sliding distance
LINK_ENTRIES = ("m", "r", "I", "Fc", "Fv", "Fo", "Im", "K", "xs")


def load_parameters(path: Path | str, model: PsmModel) -> IdentifiedParameters:
    """Read params.json, check it, and convert every link to its own frame."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text(encoding="utf-8-sig"))  # a BOM, as some editors save, is not content
    except FileNotFoundError:
        raise DvrkDartError(f"{path}: parameter file not found") from None
    except IsADirectoryError:
        raise DvrkDartError(f"{path}: is a folder, not a parameter file") from None
    except UnicodeDecodeError:
        raise DvrkDartError(f"{path}: not UTF-8 text") from None
    except json.JSONDecodeError as exc:
        raise DvrkDartError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(raw, dict):
        raise DvrkDartError(f"{path}: expected an object keyed by link number")
    links = {}
    for key in model.links:
        where = f"{path}: link {key} ({model.links[key].name})"
        entry = raw.get(str(key))
        if not isinstance(entry, dict):
            raise DvrkDartError(f"{where}: missing")
        if unknown := sorted(set(entry) - set(LINK_ENTRIES)):  # a misspelt "Fc" would leave the friction at 0
            raise DvrkDartError(f"{where}: unknown {', '.join(map(repr, unknown))} (a link holds {', '.join(LINK_ENTRIES)})")
        mass = _scalar(entry, "m", where)
        if mass < 0.0:
            raise DvrkDartError(f"{where}: negative mass {mass}")
        if mass > model.max_link_mass_kg:
            raise DvrkDartError(f"{where}: mass {mass!r} kg above the plausible {model.max_link_mass_kg:g} kg (model card)")
        com_distance = float(np.linalg.norm(_vector(entry, "r", 3, where)))
        if com_distance > model.max_com_distance_m:
            raise DvrkDartError(f"{where}: centre of mass {com_distance!r} m from the link frame, above the plausible {model.max_com_distance_m:g} m (model card)")
        R0 = model.rotations_at_zero[key]
        inertia_base = inertia_matrix(_vector(entry, "I", 6, where))
        check_inertia(inertia_base, where, model.inertia_tolerance)
        links[key] = LinkParameters(
            key=key,
            mass=mass,
            com=R0.T @ _vector(entry, "r", 3, where),
            inertia_com=R0.T @ inertia_base @ R0,
            coulomb=_friction(entry, "Fc", where),
            viscous=_friction(entry, "Fv", where),
            offset=_scalar(entry, "Fo", where),
            motor_inertia=_scalar(entry, "Im", where),
            spring=_scalar(entry, "K", where),
            presliding=_presliding(entry, where),
        )
    unknown = sorted(set(raw) - {str(k) for k in model.links})
    if unknown:
        raise DvrkDartError(f"{path}: links {', '.join(unknown)} are not in the model {model.source.name}")
    return IdentifiedParameters(source=path, links=links)

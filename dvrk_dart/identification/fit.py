"""The two fits of the identification.

1. Weighted least squares on the base parameters (`fit_weighted`): a first
   unweighted fit gives each joint's noise sigma_j (residual variance over the
   degrees of freedom of that joint's rows); the weighted fit divides every
   joint's rows by sigma_j. Its covariance is (A^T A)^-1 of the weighted rows,
   each joint's information divided by the integrated autocorrelation time of
   its residual (the filtered residual is coloured: ~10-50 samples are one
   independent observation), so the standard errors are not overconfident.
   With periodic processing (`fit_weighted_periodic`) the fit is made on the
   harmonic coefficients of the efforts and of the regressor's columns, each
   row weighted by its measured noise variance (io/periodic.py: the lines
   between the harmonics); the regressor is noise-free up to the positions'
   own small noise (no differentiated accelerations in it), and the
   covariance is (A^T W A)^-1 as it stands: the coefficients' noises are
   independent, and the model's own error is not counted in it.
2. The physically consistent estimate (`fit_consistent`): the same weighted
   least squares over the standard parameters, as a convex program (cvxpy,
   Clarabel), subject to
   - each link's pseudo-inertia matrix positive semidefinite (Wensing, Kim
     and Slotine 2017; implies a non-negative mass and the triangle
     inequalities), with a margin PSD_MARGIN_KG_M2 so that the written file
     passes the check after rounding,
   - masses within the bounds of the bounds file,
   - Coulomb and viscous coefficients >= 0,
   plus a Gaussian prior (one standard deviation per parameter class, from
   the bounds file) about a prior parameter set. The data constrain only the
   base parameters: the prior and the constraints set the rest.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from dataclasses import dataclass
from pathlib import Path

import cvxpy as cp
import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.metrics import integrated_autocorrelation_time, rms  # noqa: F401 (integrated_autocorrelation_time: here since the fits use it)
from dvrk_dart.identification.base import ZERO_COLUMN_TOLERANCE, BaseParameters
from dvrk_dart.identification.regressor import PARAMETER_CLASSES, ParameterLayout
from dvrk_dart.identification.presliding import PreslidingCandidates
from dvrk_dart.model.description import DEFAULT_MODEL_FILE, PsmModel
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.model.pseudo_inertia import PSEUDO_INERTIA_BASIS

#: the bounds and prior file of an arm: beside its description, in models/<arm>/
BOUNDS_FILE_NAME = "identification.toml"
DEFAULT_BOUNDS_FILE = DEFAULT_MODEL_FILE.parent / BOUNDS_FILE_NAME
#: a base regressor (unit-norm columns) worse conditioned than this does not
#: excite the base parameters: the fit would be noise. The reference run
#: "one" is at ~1e3; a constant pose is singular (infinite).
MAX_CONDITION_NUMBER = 1e6
#: margin of the pseudo-inertia LMI (kg m^2): far below any link's second
#: moments (>= 1e-5), far above the solver's accuracy
PSD_MARGIN_KG_M2 = 1e-8
#: margin kept inside the mass bounds (kg), above the solver's accuracy
MASS_MARGIN_KG = 1e-7
#: sigma_j of a perfectly fitted joint (synthetic data) relative to its effort RMS
SIGMA_FLOOR = 1e-9
#: the conic solvers the fit is known to meet the model card's tolerances with (SCS, first order, left link 1's
#: inertia 0.03 kg m^2 outside the physical set on "one", even at eps 1e-9: it was an option, no longer)
SOLVERS = ("CLARABEL",)


@dataclass(frozen=True)
class Bounds:
    source: Path
    mass_kg: dict[int, tuple[float, float]]
    prior_std: dict[str, float]
    presliding: PreslidingCandidates = PreslidingCandidates()

    def scales(self, layout: ParameterLayout) -> np.ndarray:
        return np.array([self.prior_std[c] for c in layout.classes])


def load_bounds(path: Path | str | None, model: PsmModel) -> Bounds:
    """The identification bounds file (`path`: the user's --bounds; None: the arm's own, its model folder's)."""
    given = "--bounds: " if path is not None else f"the arm's identification file ({model.source.name}'s folder): "
    path = Path(path) if path is not None else model.folder / BOUNDS_FILE_NAME
    if path.is_dir():
        raise DvrkDartError(f"{given}{path} is a folder, not a bounds file")
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DvrkDartError(f"{given}{path}: bounds file not found") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise DvrkDartError(f"{path}: not a valid TOML file ({exc})") from None
    masses: dict[int, tuple[float, float]] = {}
    for key_text, pair in raw.get("mass_bounds_kg", {}).items():
        where = f"{path}: mass_bounds_kg.{key_text}"
        if not key_text.isdigit() or int(key_text) not in model.links or not model.links[int(key_text)].inertia:
            raise DvrkDartError(f"{where}: not a link with inertial parameters in {model.source.name}")
        if not (isinstance(pair, list) and len(pair) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair)):
            raise DvrkDartError(f"{where}: expected [lower, upper] in kg")
        lower, upper = float(pair[0]), float(pair[1])
        if not (math.isfinite(lower) and math.isfinite(upper) and 0.0 <= lower <= upper):
            raise DvrkDartError(f"{where}: need 0 <= lower <= upper, finite (got {pair})")
        if upper >= model.max_link_mass_kg:  # the fit could land on a mass every reader of params.json refuses
            raise DvrkDartError(f"{where}: upper {upper:g} kg at or above the plausible {model.max_link_mass_kg:g} kg of "
                                f"{model.source.name} ([parameter_checks] max_link_mass_kg)")
        masses[int(key_text)] = (lower, upper)
    _check_names(raw, {"mass_bounds_kg": None, "prior_std": set(PARAMETER_CLASSES.values()), "presliding": {"revolute_rad", "prismatic_m"}},
                 path)
    missing = [link.key for link in model.links.values() if link.inertia and link.key not in masses]
    if missing:
        raise DvrkDartError(f"{path}: mass_bounds_kg has no bounds for links {missing}")
    std = raw.get("prior_std", {})
    for cls in sorted(set(PARAMETER_CLASSES.values())):
        value = std.get(cls)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0.0):
            raise DvrkDartError(f"{path}: prior_std.{cls} must be a positive number")
    return Bounds(path, masses, {k: float(v) for k, v in std.items()}, _presliding_candidates(raw.get("presliding", {}), path))


def _check_names(raw: dict, known: dict[str, set | None], path: Path) -> None:
    """The file's sections and keys (None: any key) are the known ones: a misspelt name would be left out silently."""
    for section, table in raw.items():
        if section not in known or not isinstance(table, dict):
            raise DvrkDartError(f"{path}: [{section}] is not a section of a bounds file (known: {', '.join(known)})")
        unknown = sorted(set(table) - known[section]) if known[section] is not None else []
        if unknown:
            raise DvrkDartError(f"{path}: [{section}] {unknown[0]}: not one of {', '.join(sorted(known[section]))}")


def _presliding_candidates(raw: dict, path: Path) -> PreslidingCandidates:
    """[presliding]: candidate distances per kind of joint (positive, finite)."""
    lists = {}
    for name in ("revolute_rad", "prismatic_m"):
        values = raw.get(name, [])
        if not (isinstance(values, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                 and math.isfinite(v) and v > 0.0 for v in values)):
            raise DvrkDartError(f"{path}: presliding.{name} must be a list of positive distances")
        lists[name] = tuple(float(v) for v in values)
    return PreslidingCandidates(**lists)


def condition_number(A: np.ndarray) -> float:
    """Of the columns scaled to unit norm (independent of the parameters' units);
    infinite when a column is never excited."""
    norms = np.linalg.norm(A, axis=0)
    if not np.all(norms > ZERO_COLUMN_TOLERANCE * norms.max()):
        return math.inf
    return float(np.linalg.cond(A / norms))


def _checked_condition_number(A: np.ndarray, what: str, rows: str) -> float:
    """The condition number of the stacked regressor A (equations x base
    parameters), refusing in one line a fit with no more equations than
    parameters (a run too short) or one the motion does not excite."""
    n_rows, n_base = A.shape
    if n_rows <= n_base:
        raise DvrkDartError(f"{what}: {n_rows} equations ({rows} x fitted joints) after processing, the fit needs more "
                            f"than its {n_base} base parameters: use longer runs")
    cond = condition_number(A)
    if not cond < MAX_CONDITION_NUMBER:
        raise DvrkDartError(
            f"{what}: the motion does not excite the base parameters (regressor condition number {cond:.3g}, "
            f"at most {MAX_CONDITION_NUMBER:.0e} is usable): use an excitation trajectory"
        )
    return cond


@dataclass(frozen=True)
class WeightedFit:
    joints: np.ndarray  # indices of the fitted joints
    beta_unweighted: np.ndarray
    sigma: np.ndarray  # (7,) per-joint noise (nan for joints not fitted)
    autocorrelation_samples: np.ndarray  # (7,)
    beta: np.ndarray
    covariance: np.ndarray  # of beta
    condition_number: float
    R: np.ndarray  # weighted base regressor = Q R (for the convex program)
    y: np.ndarray  # Q^T weighted efforts

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


def fit_weighted(Yb: np.ndarray, tau: np.ndarray, joints: np.ndarray, what: str) -> WeightedFit:
    """Yb (N, 7, n_base), tau (N, 7): OLS, per-joint noise, WLS and its covariance."""
    joints = np.asarray(joints)
    A = Yb[:, joints, :]
    n_samples, n_base = len(Yb), Yb.shape[2]
    cond = _checked_condition_number(A.reshape(-1, n_base), what, "samples")
    beta0 = np.linalg.lstsq(A.reshape(-1, n_base), tau[:, joints].reshape(-1), rcond=None)[0]
    residual = tau[:, joints] - A @ beta0
    sigma = np.full(len(JOINT_NAMES), np.nan)
    tau_int = np.full(len(JOINT_NAMES), np.nan)
    weights = np.empty(len(joints))
    for i, j in enumerate(joints):
        dof = max(n_samples - int(np.count_nonzero(np.abs(A[:, i, :]).sum(axis=0))), 1)
        floor = SIGMA_FLOOR * max(float(rms(tau[:, j])), 1e-300)
        sigma[j] = max(float(np.sqrt(np.sum(residual[:, i] ** 2) / dof)), floor)
        tau_int[j] = integrated_autocorrelation_time(residual[:, i])
        weights[i] = 1.0 / sigma[j]
    Aw = (A * weights[None, :, None]).reshape(-1, n_base)
    bw = (tau[:, joints] * weights[None, :]).reshape(-1)
    Q, R = np.linalg.qr(Aw)
    y = Q.T @ bw
    beta = np.linalg.solve(R, y)
    information = sum((A[:, i, :].T @ A[:, i, :]) / (sigma[j] ** 2 * tau_int[j]) for i, j in enumerate(joints))
    covariance = np.linalg.inv(information)
    return WeightedFit(joints, beta0, sigma, tau_int, beta, 0.5 * (covariance + covariance.T), cond, R, y)


def fit_weighted_periodic(coefficients_Y: np.ndarray, coefficients_tau: np.ndarray, variance: np.ndarray,
                          joints: np.ndarray, what: str) -> WeightedFit:
    """Rows are harmonic coefficients: coefficients_Y (R, 7, n_base), coefficients_tau
    (R, 7), variance (R, 7) their measured noise variance. WLS with weights 1/variance."""
    joints = np.asarray(joints)
    A, b = coefficients_Y[:, joints, :], coefficients_tau[:, joints]
    n_base = A.shape[2]
    cond = _checked_condition_number(A.reshape(-1, n_base), what, "harmonic coefficients")
    beta0 = np.linalg.lstsq(A.reshape(-1, n_base), b.reshape(-1), rcond=None)[0]
    weights = 1.0 / np.sqrt(np.maximum(variance[:, joints], np.finfo(float).tiny))
    Aw = (A * weights[:, :, None]).reshape(-1, n_base)
    Q, R = np.linalg.qr(Aw)
    y = Q.T @ (b * weights).reshape(-1)
    beta = np.linalg.solve(R, y)
    R_inverse = np.linalg.inv(R)
    covariance = R_inverse @ R_inverse.T
    sigma = np.full(len(JOINT_NAMES), np.nan)
    sigma[joints] = np.sqrt(variance[:, joints].mean(axis=0))
    uncorrelated = np.full(len(JOINT_NAMES), np.nan)  # the harmonics' residuals are independent: 1 sample each, fitted joints only
    uncorrelated[joints] = 1.0
    return WeightedFit(joints, beta0, sigma, uncorrelated, beta, covariance, cond, R, y)


@dataclass(frozen=True)
class ConsistentFit:
    theta: np.ndarray
    solver: str
    status: str
    objective_data: float  # weighted squared residual (data term)
    objective_prior: float
    active: list[str]  # constraints that hold with equality


def fit_consistent(
    wls: WeightedFit, base: BaseParameters, layout: ParameterLayout, bounds: Bounds, prior: np.ndarray, solver: str = "CLARABEL"
) -> ConsistentFit:
    """argmin ||R K theta - y||^2 + ||(theta - prior) / s||^2 subject to physical consistency."""
    if solver not in SOLVERS:
        raise DvrkDartError(f"solver: unknown solver '{solver}' (known: {', '.join(SOLVERS)})")
    scale = bounds.scales(layout)
    x = cp.Variable(len(layout))
    theta = cp.multiply(scale, x)
    data_term = cp.sum_squares(wls.R @ (base.K @ theta) - wls.y)
    prior_term = cp.sum_squares(x - prior / scale)
    constraints = []
    mass_constraints = {}
    for key in layout.inertial_links:
        block = layout.body_slice(key)
        p = theta[block]
        J = sum(p[i] * PSEUDO_INERTIA_BASIS[i] for i in range(PSEUDO_INERTIA_BASIS.shape[0]))
        constraints.append(J >> PSD_MARGIN_KG_M2 * np.eye(4))
        lower, upper = bounds.mass_kg[key]
        lo = min(lower + MASS_MARGIN_KG, upper)
        hi = max(upper - MASS_MARGIN_KG, lo)
        mass_constraints[key] = (lo, hi)
        constraints += [p[0] >= lo, p[0] <= hi]
    friction = [i for i, n in enumerate(layout.names) if n.endswith((".Fc", ".Fv"))]
    constraints.append(theta[friction] >= 0.0)
    problem = cp.Problem(cp.Minimize(data_term + prior_term), constraints)
    try:
        with warnings.catch_warnings():  # an inaccurate solve is said by its status (identification.json, the error)
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=solver)
    except cp.error.SolverError as exc:
        raise DvrkDartError(f"identification: the convex program failed ({solver}: {exc})") from None
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or x.value is None:
        raise DvrkDartError(f"identification: the convex program ended '{problem.status}' ({solver}): the bounds may be infeasible")
    value = scale * np.asarray(x.value)
    active = []
    for key, (lo, hi) in mass_constraints.items():
        m = value[layout.body_slice(key)][0]
        if abs(m - lo) < 1e-5 * max(1.0, lo):
            active.append(f"link{key}.m at its lower bound {bounds.mass_kg[key][0]:g} kg")
        elif abs(m - hi) < 1e-5 * max(1.0, hi):
            active.append(f"link{key}.m at its upper bound {bounds.mass_kg[key][1]:g} kg")
    for key in layout.inertial_links:
        eig = np.linalg.eigvalsh(np.tensordot(value[layout.body_slice(key)], PSEUDO_INERTIA_BASIS, axes=1))[0]
        if eig < 10 * PSD_MARGIN_KG_M2:
            active.append(f"link{key} pseudo-inertia on the physical boundary (smallest eigenvalue {eig:.2g} kg m^2)")
    for i in friction:
        if value[i] < 1e-6:
            active.append(f"{layout.names[i]} at 0")
    return ConsistentFit(
        theta=value,
        solver=solver,
        status=str(problem.status),
        objective_data=float(data_term.value),
        objective_prior=float(prior_term.value),
        active=active,
    )

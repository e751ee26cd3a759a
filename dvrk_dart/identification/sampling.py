"""Physically consistent parameter sets drawn around a nominal one, for the
Monte Carlo over parameter uncertainty (`dvrk-dart uncertainty`).

Samples live in the standard-parameter vector of the identification
(regressor.parameter_layout: per body Pinocchio's m, m c, inertia about the
frame origin; then friction, motor inertia, spring), drawn either from the
covariance `dvrk-dart identify` writes (params_covariance.json) or, as a
stated fallback, with an independent relative standard deviation on every
physical quantity (see `perturbed`). A sample whose body breaks the pseudo-inertia condition
(Wensing et al. 2017) is projected onto it (eigenvalues clipped at zero, the
nearest consistent body in the Frobenius norm of J), and negative Coulomb
or viscous coefficients are clipped at zero; the output counts both.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.identification.regressor import (
    FrictionLaw,
    parameter_layout,
    params_json,
    standard_vector,
)
from dvrk_dart.io.arm import Arm
from dvrk_dart.model.parameters import IdentifiedParameters
from dvrk_dart.model.pseudo_inertia import (
    PSEUDO_INERTIA_BASIS,
    pseudo_inertia_of_dynamic_parameters,
)

COVARIANCE_FORMAT = "dvrk-dart-params-covariance/1"
#: friction coefficients that are dissipative by definition
NON_NEGATIVE = ("Fc", "Fv")
#: J's basis flattened: p = lstsq(B, vec J) recovers the 10 dynamic parameters
_BASIS_MATRIX = PSEUDO_INERTIA_BASIS.reshape(10, 16).T


@dataclass(frozen=True)
class ParameterSamples:
    nominal: dict  # params.json of the nominal set
    samples: list[dict]  # params.json of each sample
    source: str  # how they were drawn, in words
    projected_bodies: int  # body samples moved onto the pseudo-inertia condition
    clipped_friction: int  # friction coefficients clipped at zero


def project_body(p: np.ndarray) -> tuple[np.ndarray, bool]:
    """The nearest physically consistent body (PSD pseudo-inertia) of 10 dynamic parameters."""
    J = pseudo_inertia_of_dynamic_parameters(p)
    w, V = np.linalg.eigh(J)
    if w[0] >= 0.0:
        return p, False
    J = (V * np.clip(w, 0.0, None)) @ V.T
    return np.linalg.lstsq(_BASIS_MATRIX, J.reshape(16), rcond=None)[0], True


#: a covariance is symmetric and positive semidefinite to rounding: this fraction of its largest entry
COVARIANCE_TOLERANCE = 1e-9


def _covariance(path: Path, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, dict[int, float]]:
    if path.is_dir():
        raise DvrkDartError(f"--params-cov: {path} is a folder, not a params_covariance.json")
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
        if raw.get("format") != COVARIANCE_FORMAT:
            raise DvrkDartError(f"--params-cov: {path}: format is {raw.get('format')!r}, expected {COVARIANCE_FORMAT!r}")
        file_names, nominal, covariance = raw["names"], np.asarray(raw["nominal"], float), np.asarray(raw["covariance"], float)
        presliding = {int(k): float(v) for k, v in raw.get("presliding", {}).items()}
    except FileNotFoundError:
        raise DvrkDartError(f"--params-cov: {path}: file not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError, AttributeError) as exc:
        raise DvrkDartError(f"--params-cov: {path}: not a parameter covariance file ({type(exc).__name__})") from None
    if tuple(file_names) != names or nominal.shape != (len(names),) or covariance.shape != (len(names), len(names)):
        raise DvrkDartError(f"--params-cov: {path}: its parameters are not this model's {len(names)} standard parameters")
    if not (np.all(np.isfinite(nominal)) and np.all(np.isfinite(covariance))):
        raise DvrkDartError(f"--params-cov: {path}: not finite")
    scale = max(float(np.max(np.abs(covariance))), np.finfo(float).tiny)
    if np.max(np.abs(covariance - covariance.T)) > COVARIANCE_TOLERANCE * scale:
        raise DvrkDartError(f"--params-cov: {path}: the covariance is not symmetric")
    smallest = float(np.linalg.eigvalsh(covariance)[0])
    if smallest < -COVARIANCE_TOLERANCE * scale:
        raise DvrkDartError(f"--params-cov: {path}: the covariance is not positive semidefinite (eigenvalue {smallest:.3g})")
    return nominal, covariance, presliding


def perturbed(params: IdentifiedParameters, relative_std: float, rng: np.random.Generator) -> IdentifiedParameters:
    """Every physical quantity scaled by (1 + relative_std z). The rotational
    inertia is scaled through the principal values of its second moment
    Sigma = tr(I)/2 - I (the mass distribution's spread along each principal
    axis, >= 0 for a real body): the sample stays a real body, and a large
    inertia about an axis a link never turns about (links 4, 5) does not leak
    onto the axes it does turn about."""
    def scaled(x):
        return np.asarray(x) * (1.0 + relative_std * rng.standard_normal(np.shape(x)))

    links = {}
    for key, p in params.links.items():
        spread, axes = np.linalg.eigh(0.5 * np.trace(p.inertia_com) * np.eye(3) - p.inertia_com)
        # a large relative std can draw a negative spread or mass: a real body has none
        sigma = (axes * np.clip(scaled(spread), 0.0, None)) @ axes.T
        links[key] = replace(
            p, mass=max(float(scaled(p.mass)), 0.0), com=scaled(p.com), inertia_com=np.trace(sigma) * np.eye(3) - sigma,
            coulomb=float(scaled(p.coulomb)), viscous=float(scaled(p.viscous)), offset=float(scaled(p.offset)),
            motor_inertia=float(scaled(p.motor_inertia)), spring=float(scaled(p.spring)),
        )
    return IdentifiedParameters(source=params.source, links=links)


def sample_parameters(arm: Arm, samples: int, seed: int, relative_std: float | None = None,
                      covariance_file: str | Path | None = None) -> ParameterSamples:
    if samples < 1:
        raise DvrkDartError(f"--samples: {samples} must be at least 1")
    layout = parameter_layout(arm.model)
    rng = np.random.default_rng(seed)
    if covariance_file is not None:
        nominal, covariance, presliding = _covariance(Path(covariance_file), layout.names)
        law = FrictionLaw.of_distances(presliding)
        # a square root robust to the rank deficiency of a base-parameter covariance
        w, V = np.linalg.eigh(0.5 * (covariance + covariance.T))
        root = V * np.sqrt(np.clip(w, 0.0, None))
        draws = nominal + rng.standard_normal((samples, len(nominal))) @ root.T
        source = f"covariance of {covariance_file} (dvrk-dart identify), nominal from the same file"
    else:
        if relative_std is None or not (0.0 < relative_std < 1.0):
            raise DvrkDartError(f"--relative-std: {relative_std} must be in (0, 1)")
        nominal = standard_vector(arm.params, layout)
        law = FrictionLaw.of_distances({k: p.presliding for k, p in arm.params.links.items()})
        draws = np.stack([standard_vector(perturbed(arm.params, relative_std, rng), layout) for _ in range(samples)])
        source = (f"independent relative std {relative_std:g} on every mass, centre-of-mass coordinate, principal inertia and "
                  f"friction, motor-inertia and spring coefficient of {arm.params.source.name} (no covariance given)")
    projected = clipped = 0
    for theta in draws:
        for key in layout.inertial_links:
            part = layout.body_slice(key)
            theta[part], moved = project_body(theta[part])
            projected += moved
            if theta[part][0] <= 0.0:  # no mass left: a body of nothing (J = 0), not an inertia without mass
                theta[part] = 0.0
        for key in layout.friction_links:
            for name in NON_NEGATIVE:
                i = layout.index(f"link{key}.{name}")
                clipped += bool(theta[i] < 0.0)
                theta[i] = max(theta[i], 0.0)
    return ParameterSamples(
        nominal=params_json(nominal, layout, arm.model, law),
        samples=[params_json(theta, layout, arm.model, law) for theta in draws],
        source=source,
        projected_bodies=projected,
        clipped_friction=clipped,
    )

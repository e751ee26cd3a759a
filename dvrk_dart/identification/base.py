"""Base parameters: the combinations of standard parameters that the joint
efforts depend on, found numerically rather than by hand.

The regressor is evaluated at random states (positions uniform within the
model's joint ranges, rates and accelerations uniform within +-RANDOM_RATE and
+-RANDOM_ACCELERATION, drawn with `seed`), its columns are normalised, and a
QR decomposition with column pivoting ranks them: a column whose |R_ii| is
below RANK_TOLERANCE times the largest one is a combination of the columns
before it. This is the structure of the model, independent of any measured
motion (whether a run excites the base parameters is the fit's condition
number). The result:

    Y theta = Y[:, independent] beta,   beta = K theta   (K: n_base x n_standard)

A standard parameter is identifiable on its own when its unit vector lies in
the row space of K; the others enter only through combinations and are set by
the constraints and the prior of the convex program.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from dvrk_dart.identification.regressor import BODY_PARAMETER_NAMES, Regressor
from dvrk_dart.model.joints import N_JOINTS

#: |R_ii| / max |R_ii| below which a (unit-norm) column is dependent: the
#: structural dependencies sit at ~1e-15, the weakest base column at ~1e-3
RANK_TOLERANCE = 1e-8
#: random states of the structural rank test: enough rows (x 7 efforts) to
#: exceed the ~115 standard parameters many times over
RANDOM_SAMPLES = 400
#: rad/s or m/s, rad/s^2 or m/s^2: covers the measured excitation (RMS ~1 rad/s)
RANDOM_RATE = 2.0
RANDOM_ACCELERATION = 10.0
#: a row of K or a projection residual below this is numerically zero
ZERO_TOLERANCE = 1e-9
#: a column whose norm is below this fraction of the largest is rounding
#: (e.g. ~1e-32 for the inertia of a link about an axis it never turns
#: about): it is a zero column, not a direction to normalise
ZERO_COLUMN_TOLERANCE = 1e-12


@dataclass(frozen=True)
class BaseParameters:
    independent: np.ndarray  # indices of the standard parameters kept as base columns
    K: np.ndarray  # (n_base, n_standard): beta = K theta
    names: tuple[str, ...]  # a readable name of each base parameter
    identifiable: np.ndarray  # (n_standard,) bool: identifiable on its own
    tolerance: float

    def __len__(self) -> int:
        return len(self.independent)

    def beta(self, theta: np.ndarray) -> np.ndarray:
        return self.K @ theta


def _combination_name(row: np.ndarray, standard_names: tuple[str, ...]) -> str:
    terms = []
    for i in np.flatnonzero(np.abs(row) > ZERO_TOLERANCE):
        coeff = row[i]
        if abs(coeff - 1.0) < 1e-9:
            terms.append(f"+ {standard_names[i]}")
        else:
            terms.append(f"{'+' if coeff >= 0 else '-'} {abs(coeff):.6g} {standard_names[i]}")
    text = " ".join(terms)
    return text[2:] if text.startswith("+ ") else text


def random_states(model, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, dq, ddq) at random over the joints' ranges: where structural properties of the regressor are read."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(model.joint_lower, model.joint_upper, (RANDOM_SAMPLES, N_JOINTS))
    dq = rng.uniform(-RANDOM_RATE, RANDOM_RATE, (RANDOM_SAMPLES, N_JOINTS))
    ddq = rng.uniform(-RANDOM_ACCELERATION, RANDOM_ACCELERATION, (RANDOM_SAMPLES, N_JOINTS))
    return q, dq, ddq


def find_base_parameters(regressor: Regressor, seed: int = 0, joints: np.ndarray | None = None,
                         held: dict[int, float] | None = None) -> BaseParameters:
    """Structural base parameters of the rows `joints` (default: all seven).
    `held`: joints the runs hold still, at their positions: the random states
    hold them there too, so that the parameters only their motion would
    determine (a held wrist's own inertia, friction) leave the base, and the
    links beyond them count as one body with the link that carries them."""
    q, dq, ddq = random_states(regressor.model, seed)
    for j, position in (held or {}).items():
        q[:, j], dq[:, j], ddq[:, j] = position, 0.0, 0.0
    rows = np.arange(N_JOINTS) if joints is None else np.asarray(joints)
    W = regressor(q, dq, ddq)[:, rows, :].reshape(-1, len(regressor.layout))
    norms = np.linalg.norm(W, axis=0)
    used = norms > ZERO_COLUMN_TOLERANCE * norms.max()
    _, R, pivots = scipy.linalg.qr(W[:, used] / norms[used], mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > RANK_TOLERANCE * diag[0]))
    used_index = np.flatnonzero(used)
    independent = np.sort(used_index[pivots[:rank]])
    dependent = np.setdiff1d(np.arange(W.shape[1]), independent)
    # beta = theta_ind + X theta_dep with W_ind X = W_dep (exact: W_dep is in the span)
    X = np.linalg.lstsq(W[:, independent], W[:, dependent], rcond=None)[0]
    X[np.abs(X) < ZERO_TOLERANCE] = 0.0
    K = np.zeros((rank, W.shape[1]))
    K[:, independent] = np.eye(rank)
    K[:, dependent] = X
    basis = np.linalg.qr(K.T)[0]  # orthonormal basis of the row space of K
    residual = np.linalg.norm(np.eye(W.shape[1]) - basis @ basis.T, axis=0)
    names = tuple(_combination_name(row, regressor.layout.names) for row in K)
    return BaseParameters(independent, K, names, residual < 1e-6, RANK_TOLERANCE)


def acting_on_none_of(regressor: Regressor, joints: np.ndarray, seed: int = 0) -> np.ndarray:
    """The joint-level parameters (friction, offset, motor inertia, spring:
    not a body's inertia, whose parts are bound together by its physical
    consistency) whose efforts fall on none of `joints` at any state (random
    states over the ranges) but on another joint: a left-out joint's own. No
    run of `joints` determines them, and none of their figures depends on them."""
    Y = regressor(*random_states(regressor.model, seed))
    on_joints = np.linalg.norm(Y[:, np.asarray(joints), :].reshape(-1, Y.shape[2]), axis=0)
    anywhere = np.linalg.norm(Y.reshape(-1, Y.shape[2]), axis=0)
    tolerance = ZERO_COLUMN_TOLERANCE * anywhere.max()
    joint_level = np.array([name.split(".", 1)[1] not in BODY_PARAMETER_NAMES for name in regressor.layout.names])
    return np.flatnonzero((on_joints <= tolerance) & (anywhere > tolerance) & joint_level)

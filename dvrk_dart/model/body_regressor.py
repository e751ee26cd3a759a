"""Efforts per unit dynamic parameter of the identified tree's bodies: Pinocchio's
joint-torque regressor of the tree that evaluates the identified model
(`IdentifiedModel.pin_model`), projected onto the seven coordinates with G^T as
its efforts are. The identification's regressor and the diagnosis's payload
columns are both read from here."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.identified import IdentifiedModel
from dvrk_dart.model.joints import N_JOINTS

#: Pinocchio's order of a body's 10 dynamic parameters (mass, first moment m c,
#: inertia about the joint frame origin)
BODY_PARAMETER_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
BODY_PARAMETERS = len(BODY_PARAMETER_NAMES)


def body_regressor(model: IdentifiedModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, columns=slice(None)) -> np.ndarray:
    """(N, 7, 10 n_tree_joints): the efforts on q1..q7 per unit dynamic parameter of every tree body
    (`columns`: only these of them, as `body_columns` gives them)."""
    pm, data = model.pin_model, model.pin_model.createData()
    qt, vt, at = (f(np.atleast_2d(np.asarray(x, dtype=float))) for f, x in ((model.tree_q, q), (model.tree_v, dq), (model.tree_v, ddq)))
    width = len(np.arange(BODY_PARAMETERS * (pm.njoints - 1))[columns])
    out = np.empty((len(qt), N_JOINTS, width))
    GT = model.G.T
    for k in range(len(qt)):
        out[k] = GT @ pin.computeJointTorqueRegressor(pm, data, qt[k], vt[k], at[k])[:, columns]
    return out


def tree_joint(model: IdentifiedModel, key: int) -> int:
    """The Pinocchio joint of link `key`'s body in the identified model's tree."""
    name = f"link{key}_{model.model.links[key].name}" if key in model.model.links else ""
    if not name or not model.pin_model.existJointName(name):
        raise DvrkDartError(f"{model.model.source}: link {key} has no joint of its own in the identified model's tree")
    return model.pin_model.getJointId(name)


def body_columns(model: IdentifiedModel, key: int) -> slice:
    """The columns of `body_regressor` of link `key`'s body (Pinocchio's: 10 per joint, joint 1 first)."""
    joint = tree_joint(model, key)
    return slice(BODY_PARAMETERS * (joint - 1), BODY_PARAMETERS * joint)

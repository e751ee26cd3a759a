"""The values of a model card, checked once it is read (model_file.py): the
shapes and signs every command relies on, each refused in one line naming the
file and the entry, before any command computes with them."""

from __future__ import annotations

import math
import re

import numpy as np

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import INSERTION, JOINT_NAMES, N_JOINTS

#: an arm's ROS namespace (PSM1, MTML): one name, a letter first
ARM_NAMESPACE = r"[A-Za-z][A-Za-z0-9_]*"
#: a coupling this close to singular turns a log's values into noise
MAX_COUPLING_CONDITION = 1e8


def check_model_values(model: PsmModel, counterweight: dict | None) -> None:
    """One-line refusal of a card's value that no command could use (`counterweight`: its [counterweight] table)."""
    where = model.source
    _vector(where, "gravity_m_s2", model.gravity, 3)
    _vector(where, "[joint_limits] lower", model.joint_lower, N_JOINTS)
    _vector(where, "[joint_limits] upper", model.joint_upper, N_JOINTS)
    if not np.all(model.joint_lower < model.joint_upper):
        raise DvrkDartError(f"{where}: [joint_limits] each lower must be below its upper (q1..q7)")
    if model.dvrk_velocity_limits is not None:
        _vector(where, "[dvrk_velocity_limits] upper", model.dvrk_velocity_limits, N_JOINTS, positive=True)
    _coupling(model)
    _processing(model)
    if model.tool_tip.parent not in model.links:
        raise DvrkDartError(f"{where}: [tool_tip] parent {model.tool_tip.parent} is not a link of the model")
    if model.force_point is not None and not model.force_point.min_lever_m > 0:
        raise DvrkDartError(f"{where}: [force_point] min_lever_m must be a positive length (m)")
    if not re.fullmatch(ARM_NAMESPACE, model.dvrk_topics.namespace):
        raise DvrkDartError(f"{where}: [dvrk_topics] namespace {model.dvrk_topics.namespace!r} is not a ROS name such as PSM1 (letters, digits, _)")
    _counterweight(model, counterweight)
    _controllers(where, model.controller_gains)


def _vector(where, entry: str, values: np.ndarray, size: int, positive: bool = False) -> None:
    if values.shape != (size,) or not np.all(np.isfinite(values)) or (positive and not np.all(values > 0)):
        raise DvrkDartError(f"{where}: {entry} must be {size} finite{' positive' if positive else ''} numbers")


def _coupling(model: PsmModel) -> None:
    width = len(model.dvrk_coupling_columns)
    matrix = model.dvrk_coupling_matrix
    if matrix.shape != (width, width) or not np.all(np.isfinite(matrix)):
        raise DvrkDartError(f"{model.source}: [dvrk_coupling] matrix must be {width}x{width} finite numbers (one row per column), "
                            f"not {'x'.join(map(str, matrix.shape))}")
    if width and np.linalg.cond(matrix) > MAX_COUPLING_CONDITION:
        raise DvrkDartError(f"{model.source}: [dvrk_coupling] matrix is singular: the dVRK's values could not be put in the model's coordinates")


def _processing(model: PsmModel) -> None:
    # the filter's normalised cut-off, 2 pi fc / filter_rate_hz, must be in (0, 1)
    rate = model.processing.filter_rate_hz
    if not (math.isfinite(rate) and rate > 0):
        raise DvrkDartError(f"{model.source}: [processing] filter_rate_hz must be a positive rate, not {rate:g}")
    highest = rate / (2 * math.pi)
    if not 0 < model.processing.cutoff_parameter_hz < highest:
        raise DvrkDartError(f"{model.source}: [processing] cutoff_parameter_hz must be in (0, {highest:.1f}) "
                            f"(the filter's 2 pi fc / {rate:g} below 1)")
    if model.processing.first_period_samples < 1:
        raise DvrkDartError(f"{model.source}: [processing] first_period_samples must be a positive number of samples")


def _counterweight(model: PsmModel, table: dict | None) -> None:
    if table is None:
        return
    leader = table.get("leader", JOINT_NAMES[INSERTION])
    if leader != JOINT_NAMES[INSERTION]:  # the transmission is built on the insertion (sim/, diagnosis/effects/)
        raise DvrkDartError(f"{model.source}: [counterweight] leader {leader!r}: the counterweight follows the insertion, {JOINT_NAMES[INSERTION]}")
    if not (math.isfinite(model.counterweight_ratio) and model.counterweight_ratio != 0):
        raise DvrkDartError(f"{model.source}: [counterweight] ratio must be a finite non-zero number")


def _controllers(where, gains: dict) -> None:
    for name, value in gains.items():
        if name == "counterweight_pid":
            ok = isinstance(value, list) and len(value) == 3 and all(_number(v) and v >= 0 for v in value) and value[0] > 0
            if not ok:
                raise DvrkDartError(f"{where}: [controllers] counterweight_pid must be [Kp, Ki, Kd], non-negative numbers, Kp above zero")
        elif not (_number(value) and (value > 0 or (name.endswith("_kd") and value == 0))):
            raise DvrkDartError(f"{where}: [controllers] {name} must be a positive number")


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)

"""A simulated run as an MCAP file: viewable in Foxglove, and the only input the
analysis stage needs (it runs elsewhere, from the logs alone).

`write_mcap` stores every array of a `RunRecord` as JSON messages, one message per
sample and channel, stamped with the sample's simulation time (ns); config,
metrics, markers and software versions go into MCAP metadata records.
`mcap_read.read_mcap` rebuilds the RunRecord. JSON floats are written in their shortest
round-trip form (Arrow's, like `repr`; -0.0 keeps its sign), so the arrays come
back bit-identical; non-finite values are written as `null` (valid JSON for
Foxglove) and read back as NaN. Messages are built column-wise with Arrow and
written in bulk (`mcap_bulk.py`: the file mcap's Writer would write), so a
long run costs no Python call per message.

Channels (all JSON, schema encoding jsonschema; `timestamp` = {sec, nsec}):

- `/joint_states/sim`      foxglove.JointStates: {timestamp, t_s, joints: [{name,
  position, velocity, acceleration, effort}]} from q, dq, ddq, effort_sim. `t_s` is
  the exact float64 sample time (the stamp is rounded to 1 ns).
- `/joint_states/measured` foxglove.JointStates with whichever of position (q_measured),
  velocity (dq_measured), effort (effort_measured) the record has.
- `/efforts/model/<term>`, `/efforts/model/total`, `/efforts/command`
  dvrk_dart.JointEfforts: {timestamp, name: [q1..q7], effort: [7 floats]}
  (sensor_msgs/JointState-like: plot `/efforts/model/total.effort[2]` in Foxglove).
- `/tool_pose/actual`, `/tool_pose/reference` foxglove.PoseInFrame: {timestamp,
  frame_id: "base", pose: {position: {x, y, z}, orientation: {x, y, z, w}}}.
- `/closure_residual`      dvrk_dart.ClosureResidual: {timestamp, residual_m}.
- `/bodies`                dvrk_dart.BodyPositions: {timestamp, frame_id: "base",
  bodies: [{name, position: {x, y, z}}]} (link frame origins, for the 3D replay).

Metadata records (values are JSON strings): "run" (name, joint names and units,
format), "config" and "metrics" (one entry per top-level key), "markers" (name ->
[x, y, z]), "versions" (python, libraries, dvrk_dart, git revision).
Units: SI; efforts in N·m, N for the prismatic q3 (see joints.py; each joint
channel also carries its units in the channel metadata).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from mcap.well_known import MessageEncoding, SchemaEncoding

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import atomic_path as atomic_output
from dvrk_dart.io.atomic import strict_json
from dvrk_dart.io.mcap_bulk import BulkChannel, write_bulk
from dvrk_dart.io.provenance import software_versions
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES, N_JOINTS
from dvrk_dart.io.record import RunRecord

FORMAT = "dvrk_dart.run/1"

TOPIC_SIM = "/joint_states/sim"
TOPIC_MEASURED = "/joint_states/measured"
TOPIC_MODEL_PREFIX = "/efforts/model/"
MODEL_TOTAL = "total"  # reserved: /efforts/model/total is derived, not a term
TOPIC_MODEL_TOTAL = TOPIC_MODEL_PREFIX + MODEL_TOTAL
TOPIC_COMMAND = "/efforts/command"
TOPIC_TOOL_POSE = "/tool_pose/actual"
TOPIC_TOOL_POSE_REF = "/tool_pose/reference"
TOPIC_CLOSURE_RESIDUAL = "/closure_residual"
TOPIC_BODIES = "/bodies"

METADATA_RUN = "run"
METADATA_CONFIG = "config"
METADATA_METRICS = "metrics"
METADATA_MARKERS = "markers"
METADATA_VERSIONS = "versions"

FRAME_ID = "base"

_NUMBER = {"type": ["number", "null"]}
_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
    "required": ["sec", "nsec"],
}
_XYZ = {"type": "object", "properties": {k: _NUMBER for k in "xyz"}}
SCHEMAS: dict[str, dict] = {
    "foxglove.JointStates": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "t_s": {"type": "number", "description": "exact sample time, s"},
            "joints": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "name": {"type": "string"},
                        "position": _NUMBER,
                        "velocity": _NUMBER,
                        "acceleration": _NUMBER,
                        "effort": _NUMBER,
                    },
                    "required": ["name"],
                },
            },
        },
    },
    "dvrk_dart.JointEfforts": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "name": {"type": "array", "items": {"type": "string"}},
            "effort": {"type": "array", "items": _NUMBER, "description": "N·m (N for q3)"},
        },
    },
    "foxglove.PoseInFrame": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": {
                "type": "object",
                "properties": {
                    "position": _XYZ,
                    "orientation": {"type": "object", "properties": {k: _NUMBER for k in "xyzw"}},
                },
            },
        },
    },
    "dvrk_dart.ClosureResidual": {
        "type": "object",
        "properties": {"timestamp": _TIME, "residual_m": _NUMBER},
    },
    "dvrk_dart.BodyPositions": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "bodies": {
                "type": "array",
                "items": {"type": "object", "properties": {"name": {"type": "string"}, "position": _XYZ}},
            },
        },
    },
}

_dumps = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode
_JOINT_NAMES = list(JOINT_NAMES)


def _joint_channel_metadata(model: PsmModel) -> dict[str, str]:
    """The joints' names and units of the run's arm, on every joint channel."""
    return {
        "joint_names": json.dumps(_JOINT_NAMES),
        "position_units": json.dumps([model.position_unit(n) for n in JOINT_NAMES]),
        "effort_units": json.dumps([model.effort_unit(n) for n in JOINT_NAMES]),
    }


# ---------------------------------------------------------------- writing

_SLOT = "\x00slot\x00"  # placeholder for a per-sample number in a message skeleton


def _json_numbers(values: np.ndarray) -> pa.Array:
    """JSON text of each value (an Arrow string array): the shortest text that
    reads back as the same float64, null if not finite."""
    values = np.asarray(values)
    if values.dtype.kind in "iu":
        return pc.cast(pa.array(values.astype(np.int64)), pa.string())
    values = values.astype(float, copy=False)
    text = pc.cast(pa.array(values), pa.string())
    finite = np.isfinite(values)
    if not finite.all():  # NaN/Infinity are not JSON; Foxglove would reject the message
        text = pc.if_else(pa.array(finite), text, "null")
    negative_zero = (values == 0.0) & np.signbit(values)
    if negative_zero.any():  # Arrow writes "-0", which JSON readers take for the integer 0
        text = pc.if_else(pa.array(negative_zero), "-0.0", text)
    return text


class _Messages:
    """Messages of one channel: a skeleton laid out once, numbers filled per sample.

    `slot(column)` stands for a per-sample number in the skeleton (an (N,) column);
    `encode(skeleton)` dumps the skeleton once and joins its pieces with the
    columns' texts element-wise (Arrow), all samples at once. Slots are filled in
    the order they were created, which is the order json.dumps writes them,
    because both follow the order in which the skeleton is written.
    """

    def __init__(self, ns: np.ndarray):
        self.columns: list[pa.Array] = []
        sec, nsec = np.divmod(ns, 1_000_000_000)
        self.timestamp = {"sec": self.slot(sec), "nsec": self.slot(nsec)}

    def slot(self, column: np.ndarray) -> str:
        self.columns.append(_json_numbers(column))
        return _SLOT

    def encode(self, skeleton: dict) -> pa.Array:
        pieces = _dumps(skeleton).split(_dumps(_SLOT))
        if len(pieces) != len(self.columns) + 1:
            raise AssertionError("message skeleton and its columns differ")
        parts = [pieces[0]]
        for column, piece in zip(self.columns, pieces[1:]):
            parts += [column, piece]
        return pc.binary_join_element_wise(*parts, "")


def _joint_states(ns: np.ndarray, fields: dict[str, np.ndarray], t_s: np.ndarray | None = None) -> pa.Array:
    """foxglove.JointStates; `fields` maps a JointState field (position, ...) to (N, 7)."""
    m = _Messages(ns)
    head = {"timestamp": m.timestamp} | ({} if t_s is None else {"t_s": m.slot(t_s)})
    joints = [{"name": name} | {k: m.slot(v[:, j]) for k, v in fields.items()} for j, name in enumerate(JOINT_NAMES)]
    return m.encode(head | {"joints": joints})


def _efforts(ns: np.ndarray, effort: np.ndarray) -> pa.Array:
    m = _Messages(ns)
    return m.encode({"timestamp": m.timestamp, "name": _JOINT_NAMES, "effort": [m.slot(e) for e in effort.T]})


def _poses(ns: np.ndarray, pose: np.ndarray) -> pa.Array:
    m = _Messages(ns)
    position = {k: m.slot(pose[:, i]) for i, k in enumerate("xyz")}
    orientation = {k: m.slot(pose[:, 3 + i]) for i, k in enumerate("xyzw")}
    return m.encode({"timestamp": m.timestamp, "frame_id": FRAME_ID, "pose": {"position": position, "orientation": orientation}})


def _residuals(ns: np.ndarray, residual: np.ndarray) -> pa.Array:
    m = _Messages(ns)
    return m.encode({"timestamp": m.timestamp, "residual_m": m.slot(residual)})


def _bodies(ns: np.ndarray, bodies: dict[str, np.ndarray]) -> pa.Array:
    m = _Messages(ns)
    items = [{"name": name, "position": {k: m.slot(p[:, i]) for i, k in enumerate("xyz")}} for name, p in bodies.items()]
    return m.encode({"timestamp": m.timestamp, "frame_id": FRAME_ID, "bodies": items})


def _to_json(value: object) -> object:
    """json.dumps default: numpy arrays and scalars as plain lists and numbers."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"not JSON-serialisable: {type(value).__name__}")


def _json_strings(mapping: dict) -> dict[str, str]:
    return {str(k): json.dumps(strict_json(v), default=_to_json, allow_nan=False) for k, v in mapping.items()}


def _checked(name: str, array: np.ndarray | None, n: int, width: int | None) -> np.ndarray | None:
    if array is None:
        return None
    array = np.asarray(array, dtype=float)
    shape = (n,) if width is None else (n, width)
    if array.shape != shape:
        raise DvrkDartError(f"RunRecord.{name}: shape {array.shape}, expected {shape}")
    return array


def _channels(record: RunRecord, ns: np.ndarray, model: PsmModel) -> list[tuple[str, str, dict[str, str], pa.Array]]:
    """(topic, schema name, channel metadata, messages) for what the record holds."""
    n = len(record)
    jm = _joint_channel_metadata(model)
    sim = {
        "position": _checked("q", record.q, n, N_JOINTS),
        "velocity": _checked("dq", record.dq, n, N_JOINTS),
        "acceleration": _checked("ddq", record.ddq, n, N_JOINTS),
        "effort": _checked("effort_sim", record.effort_sim, n, N_JOINTS),
    }
    channels = [(TOPIC_SIM, "foxglove.JointStates", jm, _joint_states(ns, sim, np.asarray(record.t, dtype=float)))]

    measured = {
        "position": _checked("q_measured", record.q_measured, n, N_JOINTS),
        "velocity": _checked("dq_measured", record.dq_measured, n, N_JOINTS),
        "effort": _checked("effort_measured", record.effort_measured, n, N_JOINTS),
    }
    measured = {k: v for k, v in measured.items() if v is not None}
    if measured:
        channels.append((TOPIC_MEASURED, "foxglove.JointStates", jm, _joint_states(ns, measured)))

    for term, effort in record.effort_model.items():
        if term == MODEL_TOTAL or not term or "/" in term:
            raise DvrkDartError(f"RunRecord.effort_model: invalid term name '{term}'")
        effort = _checked(f"effort_model[{term!r}]", effort, n, N_JOINTS)
        channels.append((TOPIC_MODEL_PREFIX + term, "dvrk_dart.JointEfforts", jm, _efforts(ns, effort)))
    if record.effort_model:
        channels.append((TOPIC_MODEL_TOTAL, "dvrk_dart.JointEfforts", jm, _efforts(ns, record.model_total())))

    command = _checked("effort_command", record.effort_command, n, N_JOINTS)
    if command is not None:
        channels.append((TOPIC_COMMAND, "dvrk_dart.JointEfforts", jm, _efforts(ns, command)))

    pose_meta = {"units": "m, quaternion (x, y, z, w)"}
    for topic, name, pose in ((TOPIC_TOOL_POSE, "tool_pose", record.tool_pose), (TOPIC_TOOL_POSE_REF, "tool_pose_ref", record.tool_pose_ref)):
        pose = _checked(name, pose, n, 7)
        if pose is not None:
            channels.append((topic, "foxglove.PoseInFrame", pose_meta, _poses(ns, pose)))

    residual = _checked("closure_residual_m", record.closure_residual_m, n, None)
    if residual is not None:
        channels.append((TOPIC_CLOSURE_RESIDUAL, "dvrk_dart.ClosureResidual", {"units": "m"}, _residuals(ns, residual)))

    if record.body_positions:
        bodies = {name: _checked(f"body_positions[{name!r}]", p, n, 3) for name, p in record.body_positions.items()}
        channels.append((TOPIC_BODIES, "dvrk_dart.BodyPositions", {"units": "m"}, _bodies(ns, bodies)))
    return channels


def _stamps_ns(t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or len(t) == 0 or not np.isfinite(t).all() or (t < 0).any():
        raise DvrkDartError("RunRecord.t: expected a non-empty 1-D array of finite, non-negative times (s)")
    return np.round(t * 1e9).astype(np.int64)


def write_mcap(record: RunRecord, path: str | os.PathLike, model: PsmModel) -> None:
    """Write `record` of `model`'s arm to `path` (atomically: a failed write leaves no file there).

    Messages are interleaved in time order (sample by sample) so chunks cover
    short time ranges and Foxglove plays the file back without seeking.
    """
    ns = _stamps_ns(record.t)
    channels = [BulkChannel(topic, schema, metadata, messages) for topic, schema, metadata, messages in _channels(record, ns, model)]
    versions = software_versions()
    schemas = {name: (SchemaEncoding.JSONSchema, json.dumps(schema).encode()) for name, schema in SCHEMAS.items()}
    metadata = [
        (METADATA_RUN, {"name": record.name, "format": FORMAT, "joint_names": json.dumps(_JOINT_NAMES), "frame_id": FRAME_ID}),
        (METADATA_CONFIG, _json_strings(record.config)),
        (METADATA_METRICS, _json_strings(record.metrics)),
        (METADATA_MARKERS, _json_strings(record.markers)),
        (METADATA_VERSIONS, {k: v if isinstance(v, str) else json.dumps(v) for k, v in versions.items()}),  # MCAP metadata: strings
    ]
    with atomic_output(path) as tmp, open(tmp, "wb") as stream:
        write_bulk(stream, schemas, channels, MessageEncoding.JSON, ns, metadata, library=f"dvrk_dart {versions['dvrk_dart']}")

"""A run log back: `read_mcap` rebuilds the RunRecord that `mcap_log.write_mcap`
wrote (the channels and metadata records are described there)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.mcap_bulk import read_bulk
from dvrk_dart.io.mcap_log import (
    FORMAT,
    METADATA_CONFIG,
    METADATA_MARKERS,
    METADATA_METRICS,
    METADATA_RUN,
    MODEL_TOTAL,
    TOPIC_BODIES,
    TOPIC_CLOSURE_RESIDUAL,
    TOPIC_COMMAND,
    TOPIC_MEASURED,
    TOPIC_MODEL_PREFIX,
    TOPIC_SIM,
    TOPIC_TOOL_POSE,
    TOPIC_TOOL_POSE_REF,
)
from dvrk_dart.io.record import RunRecord
from dvrk_dart.model.joints import JOINT_NAMES


def _json_values(strings: dict[str, str]) -> dict:
    return {k: json.loads(v) for k, v in strings.items()}


def _pose_row(message: dict) -> list:
    p, o = message["pose"]["position"], message["pose"]["orientation"]
    return [p["x"], p["y"], p["z"], o["x"], o["y"], o["z"], o["w"]]


def _array(values: list) -> np.ndarray:
    """JSON lists back to float64; null (a non-finite value) becomes NaN."""
    return np.array(values, dtype=float)


def read_mcap(path: str | os.PathLike, without: tuple[str, ...] = ()) -> RunRecord:
    """Rebuild the RunRecord that `write_mcap` wrote (config/metrics come back as JSON types).
    `without`: topics not decoded (e.g. TOPIC_BODIES, the largest: no body_positions)."""
    path = Path(path)
    metadata, messages = _decoded(path, without)
    run = _checked_run(path, metadata, messages)

    def joint_field(topic: str, key: str) -> np.ndarray | None:
        items = messages.get(topic)
        if not items or key not in items[0]["joints"][0]:
            return None
        return _array([[joint[key] for joint in m["joints"]] for m in items])

    def efforts(topic: str) -> np.ndarray | None:
        items = messages.get(topic)
        return None if items is None else _array([m["effort"] for m in items])

    def poses(topic: str) -> np.ndarray | None:
        items = messages.get(topic)
        return None if items is None else _array([_pose_row(m) for m in items])

    terms = [topic[len(TOPIC_MODEL_PREFIX):] for topic in messages if topic.startswith(TOPIC_MODEL_PREFIX)]
    residual = messages.get(TOPIC_CLOSURE_RESIDUAL)
    return RunRecord(
        name=run["name"],
        config=_json_values(metadata.get(METADATA_CONFIG, {})),
        t=_array([m["t_s"] for m in messages[TOPIC_SIM]]),
        q=joint_field(TOPIC_SIM, "position"),
        dq=joint_field(TOPIC_SIM, "velocity"),
        ddq=joint_field(TOPIC_SIM, "acceleration"),
        effort_sim=joint_field(TOPIC_SIM, "effort"),
        effort_model={term: efforts(TOPIC_MODEL_PREFIX + term) for term in terms if term != MODEL_TOTAL},
        q_measured=joint_field(TOPIC_MEASURED, "position"),
        dq_measured=joint_field(TOPIC_MEASURED, "velocity"),
        effort_measured=joint_field(TOPIC_MEASURED, "effort"),
        effort_command=efforts(TOPIC_COMMAND),
        tool_pose=poses(TOPIC_TOOL_POSE),
        tool_pose_ref=poses(TOPIC_TOOL_POSE_REF),
        closure_residual_m=None if residual is None else _array([m["residual_m"] for m in residual]),
        body_positions=_body_positions(messages),
        markers={k: np.asarray(v, dtype=float) for k, v in _json_values(metadata.get(METADATA_MARKERS, {})).items()},
        metrics=_json_values(metadata.get(METADATA_METRICS, {})),
    )


def _decoded(path: Path, without: tuple[str, ...]) -> tuple[dict, dict[str, list[dict]]]:
    """The file's metadata records and its messages, decoded per topic."""
    with open(path, "rb") as stream:
        metadata = {m.name: dict(m.metadata) for m in make_reader(stream).iter_metadata()}
        # file order, not log-time order: keeps equal stamps in the order they were written
        raw = read_bulk(stream, without)
    # one JSON array per topic: a run's ~50 000 messages decoded in one call each
    return metadata, {topic: json.loads(b"[" + b",".join(items) + b"]") for topic, items in raw.items()}


def _checked_run(path: Path, metadata: dict, messages: dict[str, list[dict]]) -> dict:
    """The run's metadata record, once the file is known to be a whole dvrk_dart run log."""
    run = metadata.get(METADATA_RUN)
    if run is None or run.get("format") != FORMAT or TOPIC_SIM not in messages:
        raise DvrkDartError(f"{path}: not a dvrk_dart run log (no '{METADATA_RUN}' metadata or no {TOPIC_SIM})")
    if json.loads(run["joint_names"]) != list(JOINT_NAMES):
        raise DvrkDartError(f"{path}: joint names {run['joint_names']} differ from {list(JOINT_NAMES)}")
    n = len(messages[TOPIC_SIM])
    for topic, items in messages.items():
        if len(items) != n:
            raise DvrkDartError(f"{path}: {topic} has {len(items)} messages, {TOPIC_SIM} has {n}")
    return run


def _body_positions(messages: dict[str, list[dict]]) -> dict[str, np.ndarray]:
    if TOPIC_BODIES not in messages:
        return {}
    items = messages[TOPIC_BODIES]
    names = [b["name"] for b in items[0]["bodies"]]
    xyz = _array([[[b["position"]["x"], b["position"]["y"], b["position"]["z"]] for b in m["bodies"]] for m in items])
    return {name: xyz[:, k, :].copy() for k, name in enumerate(names)}

"""A simulated run as a Rerun recording (.rrd), for a person to look at.

The MCAP log (log_mcap.py) is the record the analysis reads back; this file is
the picture: the arm moving in 3D, the tool paths, and per-joint plots of the
efforts (sim red, model blue, measured green, command orange, as in the paper's
figures) and of the errors between them. Arrays go in as whole columns
(`send_columns`), so a 10 000-sample run takes no per-sample Python loop. The
recording opens on a blueprint: 3D view on the left, one effort plot per joint
on the right (more plots in the other tabs).

Entity paths (timeline "sim_time", a duration in s):
  world/arm/links/<group> link segments (one entity per model group, or "chain")
  world/arm/bodies, world/arm/counterweight_body   body frame origins
  world/markers/<name>    fixed points from record.markers (rcm, ...)
  world/tool/...          actual and reference paths, moving tool points, tool frame
  efforts/<joint>/<src>   src in sim, model, measured, command
  model_terms/<joint>/<term>
  errors/<kind>/<joint>   effort_sim_minus_model (the model's terms the simulation
                          holds: metrics' model_terms_compared), effort_sim_minus_measured,
                          position_sim_minus_measured; errors/tool_position_m
  closure/residual_m
  run/config, run/metrics text documents
"""

from __future__ import annotations

import json
import os
import uuid

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from dvrk_dart.errors import DvrkDartError
from dvrk_dart.io.atomic import atomic_path as atomic_output
from dvrk_dart.model.description import PsmModel
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.io.record import RunRecord

APPLICATION_ID = "dvrk_dart"
TIMELINE = "sim_time"

#: one colour per source, the same in every plot (paper figures: sim red, model blue, measured green)
COLORS: dict[str, tuple[int, int, int]] = {
    "sim": (220, 40, 40),
    "model": (40, 90, 220),
    "measured": (30, 160, 60),
    "command": (240, 150, 0),
    "reference": (40, 90, 220),
    "error": (120, 60, 160),
    "closure": (90, 90, 90),
}
#: link groups of models/psm/psm.toml, drawn in distinct colours; the counterweight stands out
GROUP_COLORS: dict[str, tuple[int, int, int]] = {
    "yaw": (150, 150, 150),
    "parallelogram": (90, 140, 200),
    "insertion": (200, 200, 200),
    "counterweight": (230, 120, 0),
    "tool": (60, 60, 60),
}
COUNTERWEIGHT_COLOR = GROUP_COLORS["counterweight"]
MARKER_COLORS: dict[str, tuple[int, int, int]] = {"rcm": (250, 210, 0)}
DEFAULT_MARKER_COLOR = (200, 0, 200)
TERM_COLORS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75)]

ARM_UPDATE_HZ = 100.0  # the 3D arm is a picture: 100 Hz is smooth and keeps the file small


def _series(rec: rr.RecordingStream, entity: str, times: rr.TimeColumn, values: np.ndarray, name: str, color) -> None:
    """One named, coloured scalar series, sent as a whole column."""
    rec.log(entity, rr.SeriesLines(colors=[color], names=[name]), static=True, strict=True)
    rec.send_columns(entity, indexes=[times], columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=float)), strict=True)


def _log_joint_series(rec: rr.RecordingStream, record: RunRecord, times: rr.TimeColumn, model: PsmModel) -> None:
    model_total = record.model_total() if record.effort_model else None
    # the error against the model is against the terms the simulation holds, as metrics.json's rms_sim_vs_model
    compared = record.metrics.get("model_terms_compared")
    model_compared = record.model_total(tuple(compared)) if record.effort_model and compared is not None else model_total
    for j, joint in enumerate(JOINT_NAMES):
        tau, pos = model.effort_unit(joint), model.position_unit(joint)
        sources = {"sim": record.effort_sim, "model": model_total, "measured": record.effort_measured, "command": record.effort_command}
        for source, effort in sources.items():
            if effort is not None and np.isfinite(effort[:, j]).any():  # a joint the measured run did not record: no series
                _series(rec, f"efforts/{joint}/{source}", times, effort[:, j], f"{source} ({tau})", COLORS[source])
        for k, (term, effort) in enumerate(record.effort_model.items()):
            _series(rec, f"model_terms/{joint}/{term}", times, effort[:, j], f"{term} ({tau})", TERM_COLORS[k % len(TERM_COLORS)])
        errors = {
            "effort_sim_minus_model": (record.effort_sim, model_compared, tau),
            "effort_sim_minus_measured": (record.effort_sim, record.effort_measured, tau),
            "position_sim_minus_measured": (record.q, record.q_measured, pos),
        }
        for kind, (a, b, unit) in errors.items():
            if b is not None and np.isfinite(b[:, j]).any():
                _series(rec, f"errors/{kind}/{joint}", times, a[:, j] - b[:, j], f"{joint} ({unit})", COLORS["error"])


def _arm_segments(record: RunRecord, model: PsmModel) -> dict[str, list[tuple[str | None, str]]]:
    """Group -> (parent body, body) segments to draw, each body joined to its
    parent link (the tree, counterweight included); None stands for the base origin."""
    names = list(record.body_positions)
    by_key = {link.key: link for link in model.links.values()}
    groups: dict[str, list[tuple[str | None, str]]] = {}
    for name in names:
        try:
            link = model.link_by_name(name)
        except DvrkDartError:  # a body the model does not know: drawn as a point only
            continue
        parent = by_key.get(link.parent)
        while parent is not None and parent.name not in record.body_positions:
            parent = by_key.get(parent.parent)  # skip massless frames that were not logged
        groups.setdefault(link.group or "chain", []).append((None if parent is None else parent.name, name))
    return groups


def _log_arm(rec: rr.RecordingStream, record: RunRecord, model: PsmModel) -> None:
    if not record.body_positions:
        return
    t = np.asarray(record.t, dtype=float)
    # the 3D view is subsampled to ARM_UPDATE_HZ: one row per shown instant
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    step = max(1, int(round(1.0 / (ARM_UPDATE_HZ * dt)))) if dt > 0 else 1
    rows = np.arange(0, len(t), step)
    times = rr.TimeColumn(TIMELINE, duration=t[rows])
    n = len(rows)
    origin = np.zeros((n, 3))

    def at(name: str | None) -> np.ndarray:
        return origin if name is None else np.asarray(record.body_positions[name], dtype=float)[rows]

    for group, segments in _arm_segments(record, model).items():
        if not segments:
            continue
        strips = np.stack([np.stack([at(a), at(b)], axis=1) for a, b in segments], axis=1)  # (n, S, 2, 3)
        color = GROUP_COLORS.get(group, (160, 160, 160))
        rec.log(f"world/arm/links/{group}", rr.LineStrips3D.from_fields(colors=[color], radii=[0.003]), static=True, strict=True)
        rec.send_columns(
            f"world/arm/links/{group}",
            indexes=[times],
            columns=rr.LineStrips3D.columns(strips=strips.reshape(-1, 2, 3)).partition(np.full(n, len(segments))),  # one array: rerun's numpy path
            strict=True,
        )

    for entity, names, color, radius in (
        ("world/arm/bodies", [b for b in record.body_positions if "counterweight" not in b], (40, 40, 40), 0.004),
        ("world/arm/counterweight_body", [b for b in record.body_positions if "counterweight" in b], COUNTERWEIGHT_COLOR, 0.012),
    ):
        if not names:
            continue
        xyz = np.stack([at(name) for name in names], axis=1)  # (n, B, 3)
        rec.log(entity, rr.Points3D.from_fields(labels=names, colors=[color], radii=[radius], show_labels=False), static=True, strict=True)
        rec.send_columns(
            entity,
            indexes=[times],
            columns=rr.Points3D.columns(positions=xyz.reshape(-1, 3)).partition(np.full(n, len(names))),
            strict=True,
        )


def _log_markers(rec: rr.RecordingStream, record: RunRecord) -> None:
    for name, point in record.markers.items():
        color = COUNTERWEIGHT_COLOR if "counterweight" in name else MARKER_COLORS.get(name, DEFAULT_MARKER_COLOR)
        rec.log(
            f"world/markers/{name}",
            rr.Points3D([np.asarray(point, dtype=float)], colors=[color], radii=[0.008], labels=[name], show_labels=True),
            static=True,
            strict=True,
        )


def _log_tool(rec: rr.RecordingStream, record: RunRecord, times: rr.TimeColumn) -> None:
    for label, pose, color in (("actual", record.tool_pose, COLORS["sim"]), ("reference", record.tool_pose_ref, COLORS["reference"])):
        if pose is None:
            continue
        pose = np.asarray(pose, dtype=float)
        rec.log(f"world/tool/{label}_path", rr.LineStrips3D([pose[:, :3]], colors=[color], radii=[0.0005]), static=True, strict=True)
        rec.log(f"world/tool/{label}", rr.Points3D.from_fields(colors=[color], radii=[0.003]), static=True, strict=True)
        rec.send_columns(f"world/tool/{label}", indexes=[times], columns=rr.Points3D.columns(positions=pose[:, :3]), strict=True)
    if record.tool_pose is not None:
        pose = np.asarray(record.tool_pose, dtype=float)
        rec.log("world/tool/frame", rr.TransformAxes3D(0.02), static=True, strict=True)
        rec.send_columns(
            "world/tool/frame", indexes=[times], columns=rr.Transform3D.columns(translation=pose[:, :3], quaternion=pose[:, 3:7]),
            strict=True,
        )
    if record.tool_pose is not None and record.tool_pose_ref is not None:
        error = np.linalg.norm(np.asarray(record.tool_pose)[:, :3] - np.asarray(record.tool_pose_ref)[:, :3], axis=1)
        _series(rec, "errors/tool_position_m", times, error, "|actual - reference| (m)", COLORS["error"])


def _log_run_info(rec: rr.RecordingStream, record: RunRecord) -> None:
    for name, content in (("config", record.config), ("metrics", record.metrics)):
        text = json.dumps(content, indent=2, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
        rec.log(f"run/{name}", rr.TextDocument(f"```json\n{text}\n```", media_type=rr.MediaType.MARKDOWN), static=True, strict=True)


def blueprint(record: RunRecord) -> rrb.Blueprint:
    """3D view beside one effort plot per joint; errors, model terms, run info in tabs."""
    def per_joint(root: str, title: str) -> rrb.Grid:
        return rrb.Grid(*[rrb.TimeSeriesView(origin=f"{root}/{j}", name=j) for j in JOINT_NAMES], name=title)

    tabs = [per_joint("efforts", "Efforts (sim red, model blue, measured green)")]
    if record.effort_model:
        tabs.append(per_joint("errors/effort_sim_minus_model", "Effort sim - model (the terms simulated)"))
        tabs.append(per_joint("model_terms", "Model terms"))
    if record.effort_measured is not None:
        tabs.append(per_joint("errors/effort_sim_minus_measured", "Effort sim - measured"))
    if record.q_measured is not None:
        tabs.append(per_joint("errors/position_sim_minus_measured", "Position sim - measured"))
    left: list = [rrb.Spatial3DView(origin="world", name="Arm")]
    small = []
    if record.tool_pose is not None and record.tool_pose_ref is not None:
        small.append(rrb.TimeSeriesView(origin="errors/tool_position_m", name="Tool position error (m)"))
    if record.closure_residual_m is not None:
        small.append(rrb.TimeSeriesView(origin="closure", name="Closure residual (m)"))
    left += small
    tabs.append(rrb.Horizontal(rrb.TextDocumentView(origin="run/config"), rrb.TextDocumentView(origin="run/metrics"), name="Run"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*left, row_shares=[3] + [1] * len(small)),
            rrb.Tabs(*tabs),
            column_shares=[2, 3],
        ),
        collapse_panels=False,
    )


def write_rrd(record: RunRecord, path: str | os.PathLike, model: PsmModel) -> None:
    """Write the recording of `model`'s arm to `path` (atomically), with its
    default blueprint: the arm drawn as the model's link tree, its joints' units."""
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
    times = rr.TimeColumn(TIMELINE, duration=np.asarray(record.t, dtype=float))
    with atomic_output(path) as tmp:
        rec.save(tmp, default_blueprint=blueprint(record))
        try:
            rec.send_recording_name(record.name)
            _log_run_info(rec, record)
            _log_arm(rec, record, model)
            _log_markers(rec, record)
            _log_tool(rec, record, times)
            _log_joint_series(rec, record, times, model)
            if record.closure_residual_m is not None:
                _series(rec, "closure/residual_m", times, record.closure_residual_m, "closure residual (m)", COLORS["closure"])
            rec.flush()
        finally:
            rec.disconnect()  # closes the file (and writes its footer) before it is moved

"""A force estimate's logs (`dvrk-dart force`): force.csv, force.mcap (one
JSON message per sample on /force, Foxglove opens it) and force.rrd (the
instrument point's path and the force as an arrow at it, and the three
components as series, in the Rerun viewer)."""

from __future__ import annotations

import json
import uuid
from pathlib import Path

import numpy as np
import pandas as pd
import rerun as rr
from mcap.writer import Writer

from dvrk_dart.io.atomic import atomic_path, write_text_atomic

TIMELINE = "time"
#: the arrow's length per newton in the viewer (m/N): 1 N draws 2 cm
ARROW_M_PER_N = 0.02
#: samples between two arrows logged (the series keep every sample)
ARROW_EVERY = 10
FORCE_SCHEMA = {"type": "object", "properties": {
    "t_s": {"type": "number"}, "point_m": {"type": "array"}, "force_n": {"type": "array"},
    "determined_n": {"type": "array"}, "lever_m": {"type": "number"}}}


def force_table(t: np.ndarray, point: np.ndarray, force: np.ndarray, determined: np.ndarray, lever: np.ndarray) -> pd.DataFrame:
    columns = {"t_s": t}
    for i, axis in enumerate("xyz"):
        columns[f"f{axis}_n"] = force[:, i]
    for i, axis in enumerate("xyz"):
        columns[f"determined_f{axis}_n"] = determined[:, i]
    for i, axis in enumerate("xyz"):
        columns[f"point_{axis}_m"] = point[:, i]
    columns["lever_m"] = lever
    return pd.DataFrame(columns)


def write_force_logs(folder: Path, table: pd.DataFrame, name: str) -> None:
    write_text_atomic(folder / "force.csv", table.to_csv(index=False, na_rep="nan"))
    _write_mcap(folder / "force.mcap", table)
    _write_rrd(folder / "force.rrd", table, name)


def _vectors(table: pd.DataFrame, prefix: str, suffix: str) -> np.ndarray:
    return table[[f"{prefix}{axis}{suffix}" for axis in "xyz"]].to_numpy()


def _write_mcap(path: Path, table: pd.DataFrame) -> None:
    force, determined, point = _vectors(table, "f", "_n"), _vectors(table, "determined_f", "_n"), _vectors(table, "point_", "_m")
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("dvrk_dart/InstrumentForce", "jsonschema", json.dumps(FORCE_SCHEMA).encode())
        channel = writer.register_channel("/force", "json", schema)
        for k, t in enumerate(table["t_s"].to_numpy()):
            message = {"t_s": float(t), "point_m": point[k].tolist(), "lever_m": float(table["lever_m"].iat[k]),
                       "force_n": [None if not np.isfinite(v) else float(v) for v in force[k]], "determined_n": determined[k].tolist()}
            stamp = int(round(t * 1e9))
            writer.add_message(channel, log_time=stamp, publish_time=stamp, data=json.dumps(message).encode(), sequence=k)
        writer.finish()


def _write_rrd(path: Path, table: pd.DataFrame, name: str) -> None:
    rec = rr.RecordingStream("dvrk_dart", recording_id=uuid.uuid4())
    with atomic_path(path) as tmp:
        rec.save(tmp)
        try:
            rec.send_recording_name(f"force {name}")
            _log_force(rec, table)
            rec.flush()
        finally:
            rec.disconnect()  # closes the file before it is moved


def _log_force(rec: rr.RecordingStream, table: pd.DataFrame) -> None:
    t = table["t_s"].to_numpy()
    force, point = _vectors(table, "f", "_n"), _vectors(table, "point_", "_m")
    for i, axis in enumerate("xyz"):
        rec.log(f"force/{axis}", rr.SeriesLines(names=[f"F{axis} (N)"]), static=True)
        known = np.isfinite(force[:, i])  # a direction not determined has no value, not 0 N
        rec.send_columns(f"force/{axis}", indexes=[rr.TimeColumn(TIMELINE, duration=t[known])], columns=rr.Scalars.columns(scalars=force[known, i]))
    rec.log("world/point_path", rr.LineStrips3D([point]), static=True)
    for k in range(0, len(t), ARROW_EVERY):
        if not np.all(np.isfinite(force[k])):
            continue
        rec.set_time(TIMELINE, duration=float(t[k]))
        rec.log("world/force", rr.Arrows3D(origins=[point[k]], vectors=[force[k] * ARROW_M_PER_N]))

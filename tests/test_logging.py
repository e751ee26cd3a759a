"""The run logs: the MCAP file holds everything to rebuild the RunRecord (the
analysis reads runs from MCAP only), writes are atomic, and the .rrd is a
recording the Rerun tools can load."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from dvrk_dart.io import mcap_bulk
from dvrk_dart.io import mcap_log as log_mcap
from dvrk_dart.io.mcap_log import write_mcap
from dvrk_dart.io.mcap_read import read_mcap
from dvrk_dart.io.rerun_log import write_rrd
from dvrk_dart.model.joints import JOINT_NAMES
from dvrk_dart.io.record import RunRecord
from arms import PSM

N_SAMPLES = 500
BODIES = ("yaw", "pitch_back", "pitch_front", "insertion_carriage", "counterweight", "tool_roll")
TERMS = ("inertia", "coriolis", "gravity", "friction")
ARRAY_FIELDS = (
    "t", "q", "dq", "ddq", "effort_sim", "q_measured", "dq_measured", "effort_measured",
    "effort_command", "tool_pose", "tool_pose_ref", "closure_residual_m",
)


def full_record(n: int = N_SAMPLES) -> RunRecord:
    """Every optional field filled, with values that do not round-trip through short decimals."""
    rng = np.random.default_rng(7)

    def joints(scale: float = 1.0) -> np.ndarray:
        return scale * rng.standard_normal((n, 7))

    quat = rng.standard_normal((n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    pose = np.hstack([0.1 * rng.standard_normal((n, 3)), quat])
    effort_measured = joints()
    effort_measured[3, 2] = np.nan  # a gap in the measured data: written as JSON null
    return RunRecord(
        name="replay-synthetic-cw_on",
        config={"scenario": "replay", "dt_s": 1e-3, "gains": {"kp": [1.5, 2.0], "kd": 0.1}, "counterweight": True},
        t=np.cumsum(rng.uniform(1e-3, 2e-3, n)) - 1e-3 + 0.1 / 3,
        q=joints(),
        dq=joints(),
        ddq=joints(10.0),
        effort_sim=joints(),
        effort_model={term: joints(0.5) for term in TERMS},
        q_measured=joints(),
        dq_measured=joints(),
        effort_measured=effort_measured,
        effort_command=joints(),
        tool_pose=pose,
        tool_pose_ref=pose + 1e-4 * rng.standard_normal((n, 7)),
        closure_residual_m=1e-9 * rng.random(n),
        body_positions={name: 0.2 * rng.standard_normal((n, 3)) for name in BODIES},
        markers={"rcm": np.array([0.0, 0.0, 0.1]), "counterweight_pivot": np.array([0.0, -0.1, 0.05])},
        metrics={"rms_effort_error": rng.random(7).tolist(), "relative_error": 0.12345678901234567, "ok": True},
    )


def minimal_record(n: int = 50) -> RunRecord:
    rng = np.random.default_rng(3)
    return RunRecord(
        name="minimal",
        config={},
        t=np.arange(n) * 1e-3,
        q=rng.standard_normal((n, 7)),
        dq=rng.standard_normal((n, 7)),
        ddq=rng.standard_normal((n, 7)),
        effort_sim=rng.standard_normal((n, 7)),
    )


def expected_topics(record: RunRecord) -> set[str]:
    topics = {log_mcap.TOPIC_SIM}
    if record.effort_model:
        topics |= {log_mcap.TOPIC_MODEL_PREFIX + term for term in record.effort_model} | {log_mcap.TOPIC_MODEL_TOTAL}
    optional = {
        log_mcap.TOPIC_MEASURED: record.effort_measured,
        log_mcap.TOPIC_COMMAND: record.effort_command,
        log_mcap.TOPIC_TOOL_POSE: record.tool_pose,
        log_mcap.TOPIC_TOOL_POSE_REF: record.tool_pose_ref,
        log_mcap.TOPIC_CLOSURE_RESIDUAL: record.closure_residual_m,
        log_mcap.TOPIC_BODIES: record.body_positions or None,
    }
    return topics | {topic for topic, value in optional.items() if value is not None}


def assert_same_record(back: RunRecord, record: RunRecord) -> None:
    assert back.name == record.name
    assert back.config == record.config
    assert back.metrics == record.metrics
    for name in ARRAY_FIELDS:
        a, b = getattr(back, name), getattr(record, name)
        assert (a is None) == (b is None), name
        if b is not None:
            assert a.dtype == np.float64 and a.shape == b.shape, name
            np.testing.assert_array_equal(a, b, err_msg=name)  # exact: JSON floats are shortest round-trip text
    assert list(back.effort_model) == list(record.effort_model)
    for term, effort in record.effort_model.items():
        np.testing.assert_array_equal(back.effort_model[term], effort)
    assert list(back.body_positions) == list(record.body_positions)
    for body, xyz in record.body_positions.items():
        np.testing.assert_array_equal(back.body_positions[body], xyz)
    assert list(back.markers) == list(record.markers)
    for marker, xyz in record.markers.items():
        np.testing.assert_array_equal(back.markers[marker], xyz)


@pytest.mark.parametrize("make", [full_record, minimal_record], ids=["full", "minimal"])
def test_mcap_round_trip(tmp_path: Path, make) -> None:
    record = make()
    path = tmp_path / "run.mcap"
    write_mcap(record, path, PSM)
    assert_same_record(read_mcap(path), record)
    assert [p.name for p in tmp_path.iterdir()] == ["run.mcap"]  # no temporary left behind


def test_mcap_channels_counts_and_values(tmp_path: Path) -> None:
    """Read with the plain mcap reader, as Foxglove or another tool would."""
    record = full_record()
    path = tmp_path / "run.mcap"
    write_mcap(record, path, PSM)
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        channels = {c.id: c for c in summary.channels.values()}
        schemas = summary.schemas
        assert {c.topic for c in channels.values()} == expected_topics(record)
        for channel_id, count in summary.statistics.channel_message_counts.items():
            assert count == len(record), channels[channel_id].topic
        for channel in channels.values():
            schema = schemas[channel.schema_id]
            assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
            assert json.loads(schema.data)["type"] == "object"
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}

        expected_ns = np.round(record.t * 1e9).astype(np.int64)
        sim, total, poses = [], [], []
        for _, channel, message in reader.iter_messages(
            topics=[log_mcap.TOPIC_SIM, log_mcap.TOPIC_MODEL_TOTAL, log_mcap.TOPIC_TOOL_POSE], log_time_order=False
        ):
            body = json.loads(message.data)
            stamp = body["timestamp"]["sec"] * 10**9 + body["timestamp"]["nsec"]
            assert stamp == message.log_time == message.publish_time
            {log_mcap.TOPIC_SIM: sim, log_mcap.TOPIC_MODEL_TOTAL: total, log_mcap.TOPIC_TOOL_POSE: poses}[
                channel.topic
            ].append((message.log_time, body))

    assert [ns for ns, _ in sim] == expected_ns.tolist()
    first = sim[0][1]["joints"]
    assert [j["name"] for j in first] == list(JOINT_NAMES)
    for field, array in (("position", record.q), ("velocity", record.dq), ("acceleration", record.ddq), ("effort", record.effort_sim)):
        np.testing.assert_array_equal([[j[field] for j in body["joints"]] for _, body in sim], array)
    np.testing.assert_array_equal([body["effort"] for _, body in total], record.model_total())
    assert poses[0][1]["frame_id"] == "base"
    assert set(poses[0][1]["pose"]["orientation"]) == {"x", "y", "z", "w"}

    assert metadata["config"] == {k: json.dumps(v) for k, v in record.config.items()}
    assert {k: json.loads(v) for k, v in metadata["metrics"].items()} == record.metrics
    assert {k: json.loads(v) for k, v in metadata["markers"].items()} == {k: v.tolist() for k, v in record.markers.items()}
    versions = metadata["versions"]
    assert {"python", "numpy", "dartpy", "pinocchio", "rerun-sdk", "mcap", "dvrk_dart", "git_revision"} <= set(versions)
    assert versions["mcap"] == "1.6.0"
    assert metadata["run"]["name"] == record.name


def test_nan_is_valid_json(tmp_path: Path) -> None:
    """Foxglove parses JSON strictly: a NaN must be written as null."""
    record = full_record()
    path = tmp_path / "run.mcap"
    write_mcap(record, path, PSM)
    with open(path, "rb") as stream:
        for _, _, message in make_reader(stream).iter_messages(topics=[log_mcap.TOPIC_MEASURED]):
            json.loads(message.data, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))


@pytest.mark.parametrize("existing", [False, True], ids=["new", "overwrite"])
def test_interrupted_mcap_write_leaves_no_file(tmp_path: Path, monkeypatch, existing: bool) -> None:
    path = tmp_path / "run.mcap"
    if existing:
        path.write_bytes(b"previous run")
    original = mcap_bulk._File.chunk
    calls = {"n": 0}

    def failing_chunk(self, *args, **kwargs):  # the first chunk is on disk when the second fails
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("simulated crash while writing")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(mcap_bulk._File, "chunk", failing_chunk)
    with pytest.raises(RuntimeError, match="simulated crash"):
        write_mcap(full_record(), path, PSM)
    assert [p.name for p in tmp_path.iterdir()] == (["run.mcap"] if existing else [])
    if existing:
        assert path.read_bytes() == b"previous run"


def test_model_total_is_reserved(tmp_path: Path) -> None:
    record = minimal_record()
    record.effort_model = {"total": np.zeros_like(record.q)}
    with pytest.raises(Exception, match="total"):
        write_mcap(record, tmp_path / "run.mcap", PSM)
    assert not list(tmp_path.iterdir())


def _rerun_cli() -> str | None:
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


@pytest.mark.parametrize("make", [full_record, minimal_record], ids=["full", "minimal"])
def test_rrd_written_and_loadable(tmp_path: Path, make) -> None:
    path = tmp_path / "run.rrd"
    write_rrd(make(), path, PSM)
    assert [p.name for p in tmp_path.iterdir()] == ["run.rrd"]
    assert path.stat().st_size > 20_000
    cli = _rerun_cli()
    if cli is None:
        pytest.skip("no rerun CLI to verify the file with")
    done = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_rrd_with_model_tree(tmp_path: Path) -> None:
    """With the PSM model, links are drawn as the model's tree (the real link names)."""

    path = tmp_path / "run.rrd"
    write_rrd(full_record(), path, PSM)
    assert path.stat().st_size > 20_000


def test_interrupted_rrd_write_leaves_no_file(tmp_path: Path, monkeypatch) -> None:
    import dvrk_dart.io.rerun_log as log_rerun

    def crash(*args, **kwargs):
        raise RuntimeError("simulated crash while writing")

    monkeypatch.setattr(log_rerun, "_log_joint_series", crash)
    with pytest.raises(RuntimeError, match="simulated crash"):
        write_rrd(full_record(), tmp_path / "run.rrd", PSM)
    assert not list(tmp_path.iterdir())

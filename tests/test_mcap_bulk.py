"""The bulk MCAP writer writes, byte for byte, the file mcap's own Writer writes
from the same messages (chunking, indexes, summary), and the JSON numbers of
the run logs read back as the very same float64."""

from __future__ import annotations

import io
import json

import numpy as np
import pyarrow as pa
import pytest
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import Writer

from dvrk_dart.io.mcap_bulk import BulkChannel, read_bulk, write_bulk
from dvrk_dart.io.mcap_log import _json_numbers

SCHEMAS = {"a": (SchemaEncoding.JSONSchema, b'{"type": "object"}'), "b": (SchemaEncoding.JSONSchema, b'{"type": "object", "x": 1}')}
METADATA = [("run", {"name": "x", "format": "f"}), ("metrics", {"rms": "[1.5, 2]"})]


def _channels(n: int, seed: int) -> list[BulkChannel]:
    rng = np.random.default_rng(seed)
    channels = []
    for c in range(5):  # messages of varied lengths, some empty
        texts = ["" if rng.random() < 0.05 else json.dumps({"v": rng.standard_normal(rng.integers(1, 40)).tolist()}) for _ in range(n)]
        channels.append(BulkChannel(f"/topic/{c}", "ab"[c % 2], {"units": "m"} if c else {}, pa.array(texts)))
    return channels


def _with_library(channels: list[BulkChannel], times: np.ndarray, chunk_size: int, use_chunking: bool = True) -> bytes:
    """What write_mcap did before: one Writer.add_message per message, sample by sample."""
    stream = io.BytesIO()
    writer = Writer(stream, chunk_size=chunk_size, use_chunking=use_chunking)
    writer.start(profile="", library="test 1")
    schema_ids = {name: writer.register_schema(name, encoding, data) for name, (encoding, data) in SCHEMAS.items()}
    ids = [writer.register_channel(c.topic, MessageEncoding.JSON, schema_ids[c.schema], c.metadata) for c in channels]
    payloads = [[m.as_py().encode() for m in c.messages] for c in channels]
    for i, stamp in enumerate(times.tolist()):
        for channel_id, messages in zip(ids, payloads):
            writer.add_message(channel_id, stamp, messages[i], stamp, i)
    for name, data in METADATA:
        writer.add_metadata(name, data)
    writer.finish()
    return stream.getvalue()


@pytest.mark.parametrize("n, chunk_size", [(1, 1024 * 1024), (300, 1024 * 1024), (300, 4096), (300, 100), (250, 20_000)])
def test_bulk_file_is_the_library_writers_file(n: int, chunk_size: int) -> None:
    times = np.round(np.cumsum(np.full(n, 1e-3)) * 1e9).astype(np.int64) - 1_000_000
    channels = _channels(n, seed=n + chunk_size)
    stream = io.BytesIO()
    write_bulk(stream, SCHEMAS, channels, MessageEncoding.JSON, times, METADATA, library="test 1", chunk_size=chunk_size)
    expected = _with_library(channels, times, chunk_size)
    assert stream.getvalue() == expected
    # and the reader finds every message through the indexes
    reader = make_reader(io.BytesIO(stream.getvalue()))
    assert reader.get_summary().statistics.message_count == 5 * n
    assert sum(1 for _ in reader.iter_messages(topics=["/topic/3"])) == n


def _read_by_library(data: bytes) -> dict[str, list[bytes]]:
    messages: dict[str, list[bytes]] = {}
    for _, channel, message in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
        messages.setdefault(channel.topic, []).append(message.data)
    return messages


@pytest.mark.parametrize("n, chunk_size, use_chunking", [(1, 1024 * 1024, True), (300, 100, True), (250, 20_000, True), (40, 4096, False)])
def test_bulk_reading_is_the_library_readers(n: int, chunk_size: int, use_chunking: bool) -> None:
    """read_bulk yields what mcap's reader yields in file order, topic by topic, with a topic left out or not, and
    reads a file without chunks (no index to find them by) through the library."""
    data = _with_library(_channels(n, seed=n), np.arange(n, dtype=np.int64) * 1_000_000, chunk_size, use_chunking)
    chunks = len(make_reader(io.BytesIO(data)).get_summary().chunk_indexes)
    assert (chunks > 1 if n > 1 and use_chunking else chunks <= 1)  # the fast path over several chunks, the library's without
    library = _read_by_library(data)
    assert sum(map(len, library.values())) == 5 * n and read_bulk(io.BytesIO(data)) == library
    assert read_bulk(io.BytesIO(data), without=("/topic/3",)) == {t: m for t, m in library.items() if t != "/topic/3"}


def test_json_numbers_read_back_as_the_same_float64() -> None:
    rng = np.random.default_rng(3)
    special = [0.0, -0.0, 1.0, -1.0, 1e16, 1e22, 1e-7, 5e-324, 2.2250738585072014e-308, 1.7976931348623157e308, 0.1, 1 / 3, 123456789.0]
    values = np.concatenate([special, rng.standard_normal(20000) * 10.0 ** rng.integers(-30, 30, 20000), [np.nan, np.inf, -np.inf]])
    text = _json_numbers(values).to_pylist()
    back = np.array([json.loads(t) for t in text], dtype=float)  # null -> NaN
    finite = np.isfinite(values)
    assert np.array_equal(back[finite].view(np.int64), values[finite].view(np.int64))  # bit for bit, -0.0 included
    assert text[-3:] == ["null"] * 3
    assert _json_numbers(np.array([0, 7, 1_000_000_000], dtype=np.int64)).to_pylist() == ["0", "7", "1000000000"]

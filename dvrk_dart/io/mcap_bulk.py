"""Many messages into an MCAP file at once, without a Python call per message.

`write_bulk` writes the file that mcap's own `Writer` writes when it is given
the same schemas, channels, messages (sample by sample, every channel at each
sample, in channel order, `sequence` = the sample's index) and metadata,
byte for byte: the same records, chunks (zstd, at most `chunk_size` bytes of
records each, schemas and channels in the first), message indexes, summary
and footer (tests/test_mcap_bulk.py compares the two). Only the Message and
MessageIndex records, which are many, are laid out here with array
operations; the other records are the mcap library's own.

Messages come as Arrow binary/string arrays, one per channel, one element per
sample (see `mcap_log.py`, which builds them from whole columns).

`read_bulk` is the way back: every message's data by topic, in file order, the
chunks found and decompressed by the library and only their Message records
split here (the library's reader spends a Python call per record: about
half of reading a run log, the JSON decoding most of the rest).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import IO

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import zstandard
from mcap.data_stream import ReadDataStream, RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import get_chunk_data_stream
from mcap.writer import MCAP0_MAGIC

#: chunks compressed at once (zstd frames are independent: the file is the same)
COMPRESSION_THREADS = 2

#: mcap.writer.Writer's default chunk size (bytes of uncompressed records)
CHUNK_SIZE = 1024 * 1024
#: Message record: opcode, record length, then channel id, sequence, log time, publish time, data
_MESSAGE_HEADER = np.dtype([("op", "u1"), ("len", "<u8"), ("channel", "<u2"), ("sequence", "<u4"), ("log", "<u8"), ("publish", "<u8")])
_MESSAGE_FIELDS_SIZE = _MESSAGE_HEADER.itemsize - 9  # the record length counts what follows opcode and length


@dataclass(frozen=True)
class BulkChannel:
    topic: str
    schema: str  # a name in write_bulk's `schemas`
    metadata: dict[str, str]
    messages: pa.Array  # binary or string, one message per sample


def _records(builder_write) -> bytes:
    builder = RecordBuilder()
    builder_write(builder)
    return builder.end()


def _message_records(channels: Sequence[BulkChannel], log_times: np.ndarray) -> tuple[pa.Array, np.ndarray, np.ndarray]:
    """All Message records, sample by sample and channel by channel: (records as
    one large_binary array, channel id of each, log time of each)."""
    n, c = len(log_times), len(channels)
    data = pa.concat_arrays([ch.messages.cast(pa.large_binary()) for ch in channels])
    order = (np.arange(c)[None, :] * n + np.arange(n)[:, None]).ravel()  # sample-major interleave
    data = data.take(pa.array(order))
    offsets = np.frombuffer(data.buffers()[1], dtype=np.int64, count=len(data) + 1, offset=data.offset * 8)
    header = np.empty(n * c, dtype=_MESSAGE_HEADER)
    header["op"] = Opcode.MESSAGE
    header["len"] = _MESSAGE_FIELDS_SIZE + np.diff(offsets)
    header["channel"] = np.tile(np.arange(1, c + 1), n)
    header["sequence"] = np.repeat(np.arange(n), c)
    header["log"] = header["publish"] = np.repeat(log_times, c)
    header_offsets = np.arange(n * c + 1, dtype=np.int64) * _MESSAGE_HEADER.itemsize
    headers = pa.Array.from_buffers(pa.large_binary(), n * c, [None, pa.py_buffer(header_offsets), pa.py_buffer(header.tobytes())])
    records = pc.binary_join_element_wise(headers, data, pa.scalar(b"", pa.large_binary()))
    return records, header["channel"], header["log"]


def _message_index(channel_id: int, times: np.ndarray, offsets: np.ndarray) -> bytes:
    pairs = np.column_stack([times, offsets]).astype("<u8").tobytes()
    return struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + len(pairs), channel_id, len(pairs)) + pairs


class _File:
    """The output stream and the summary being gathered, as in mcap's Writer."""

    def __init__(self, stream: IO[bytes]):
        self.stream = stream
        self.offset = 0
        self.chunk_indexes: list[ChunkIndex] = []
        self.metadata_indexes: list[MetadataIndex] = []

    def write(self, data: bytes) -> None:
        self.stream.write(data)
        self.offset += len(data)

    def chunk(self, data: bytes, compressed: bytes, prefix_length: int, channel_ids: np.ndarray, times: np.ndarray,
              offsets: np.ndarray) -> None:
        """One chunk: `data` is a prefix (schemas, channels) then the messages'
        records, `compressed` its zstd frame; offsets: each message's record
        offset after the prefix."""
        start, end = int(times.min()), max(0, int(times.max()))
        chunk = _records(Chunk(compression="zstd", data=compressed, message_start_time=start, message_end_time=end,
                               uncompressed_crc=zlib.crc32(data), uncompressed_size=len(data)).write)
        chunk_start = self.offset
        self.write(chunk)
        index_start = self.offset
        index_offsets = {}
        indexes = []
        _, first = np.unique(channel_ids, return_index=True)
        for channel_id in channel_ids[np.sort(first)].tolist():  # in order of first message, as mcap's ChunkBuilder
            mine = channel_ids == channel_id
            index_offsets[channel_id] = index_start + sum(map(len, indexes))
            indexes.append(_message_index(channel_id, times[mine], prefix_length + offsets[mine]))
        self.write(b"".join(indexes))
        self.chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=chunk_start, chunk_length=len(chunk),
            message_index_offsets=index_offsets, message_index_length=self.offset - index_start, compression="zstd",
            compressed_size=len(compressed), uncompressed_size=len(data),
        ))

    def metadata(self, name: str, data: dict[str, str]) -> None:
        offset = self.offset
        record = _records(Metadata(name=name, metadata=data).write)
        self.write(record)
        self.metadata_indexes.append(MetadataIndex(offset=offset, length=len(record), name=name))


def write_bulk(
    stream: IO[bytes],
    schemas: dict[str, tuple[str, bytes]],
    channels: Sequence[BulkChannel],
    message_encoding: str,
    log_times: np.ndarray,
    metadata: Sequence[tuple[str, dict[str, str]]] = (),
    library: str = "",
    chunk_size: int = CHUNK_SIZE,
) -> None:
    """Write an MCAP file: `schemas` name -> (encoding, data); every channel has
    one message per entry of `log_times` (ns; also the publish time)."""
    log_times = np.asarray(log_times, dtype=np.int64)
    if any(len(ch.messages) != len(log_times) for ch in channels):
        raise ValueError("write_bulk: every channel needs one message per log time")
    out = _File(stream)
    out.write(MCAP0_MAGIC)
    out.write(_records(Header(profile="", library=library).write))
    schema_records = [Schema(id=i, data=data, encoding=encoding, name=name) for i, (name, (encoding, data)) in enumerate(schemas.items(), 1)]
    schema_ids = {s.name: s.id for s in schema_records}
    channel_records = [
        Channel(id=i, topic=ch.topic, message_encoding=message_encoding, schema_id=schema_ids[ch.schema], metadata=ch.metadata)
        for i, ch in enumerate(channels, 1)
    ]
    prefix = b"".join(_records(r.write) for r in (*schema_records, *channel_records))

    records, channel_ids, times = _message_records(channels, log_times)
    offsets = np.frombuffer(records.buffers()[1], dtype=np.int64, count=len(records) + 1, offset=records.offset * 8)
    body = records.buffers()[2]
    # mcap's Writer closes a chunk as soon as its records pass chunk_size; the last one at finish()
    chunks, start, first = [], 0, True
    while start < len(records):
        room = chunk_size - (len(prefix) if first else 0)
        end = int(np.searchsorted(offsets, offsets[start] + room, side="right"))  # first message past the room, + 1
        end = max(end, start + 1)  # a chunk holds at least the message that filled it
        chunks.append((start, min(end, len(records)), first, end <= len(records)))
        start, first = end, False

    datas = [(prefix if with_prefix else b"") + body[offsets[start]:offsets[end]].to_pybytes() for start, end, with_prefix, _ in chunks]
    with ThreadPoolExecutor(max_workers=COMPRESSION_THREADS) as pool:  # zstd releases the GIL; the same bytes
        compressed = list(pool.map(zstandard.compress, datas))

    def write_chunk(i: int) -> None:
        start, end, with_prefix, _ = chunks[i]
        out.chunk(datas[i], compressed[i], len(prefix) if with_prefix else 0, channel_ids[start:end], times[start:end],
                  offsets[start:end] - offsets[start])

    for i, (*_, closed) in enumerate(chunks):
        if closed:
            write_chunk(i)
    for name, data in metadata:
        out.metadata(name, data)
    if chunks and not chunks[-1][3]:
        write_chunk(len(chunks) - 1)
    _finish(out, schema_records, channel_records, channels, log_times, len(metadata))


def _finish(out: _File, schemas: list[Schema], channels: list[Channel], bulk: Sequence[BulkChannel], log_times: np.ndarray,
            metadata_count: int) -> None:
    """Data end, summary (schemas, channels, statistics, chunk/attachment/metadata
    indexes, their offsets) and footer, as mcap.writer.Writer.finish."""
    out.write(_records(DataEnd(0).write))
    summary_start = out.offset
    n = len(log_times)
    statistics = Statistics(
        attachment_count=0,
        channel_count=len(channels),
        channel_message_counts={c.id: n for c in channels} if n else {},
        chunk_count=len(out.chunk_indexes),
        message_count=n * len(channels),
        metadata_count=metadata_count,
        message_start_time=int(log_times.min()) if n and channels else 0,
        message_end_time=max(0, int(log_times.max())) if n and channels else 0,
        schema_count=len(schemas),
    )
    groups = [
        (Opcode.SCHEMA, schemas),
        (Opcode.CHANNEL, channels),
        (Opcode.STATISTICS, [statistics]),
        (Opcode.CHUNK_INDEX, out.chunk_indexes),
        (Opcode.ATTACHMENT_INDEX, []),
        (Opcode.METADATA_INDEX, out.metadata_indexes),
    ]
    summary = RecordBuilder()
    offsets = []
    for opcode, records in groups:
        group_start = summary.count
        for record in records:
            record.write(summary)
        offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + group_start, group_length=summary.count - group_start))
    summary_offset_start = summary_start + summary.count
    for offset in offsets:
        offset.write(summary)
    data = summary.end()
    crc = zlib.crc32(data)
    crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start if data else 0, summary_offset_start), crc)
    out.write(data)
    out.write(_records(Footer(summary_start=summary_start if data else 0, summary_offset_start=summary_offset_start, summary_crc=crc).write))
    out.write(MCAP0_MAGIC)


def read_bulk(stream: IO[bytes], without: tuple[str, ...] = ()) -> dict[str, list[bytes]]:
    """Every message's data by topic (`without`: topics left out), in file order: what mcap's reader yields with
    `log_time_order=False`. A file without chunk indexes is read by the library's reader."""
    stream.seek(0)
    reader = make_reader(stream)
    summary = reader.get_summary()
    if summary is None or not summary.chunk_indexes:
        messages: dict[str, list[bytes]] = {}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic not in without:
                messages.setdefault(channel.topic, []).append(message.data)
        return messages
    by_channel: dict[int, list[bytes]] = {}
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        stream.seek(index.chunk_start_offset + 1 + 8)  # past the Chunk record's opcode and length
        data_stream, length = get_chunk_data_stream(Chunk.read(ReadDataStream(stream)))
        data, at = data_stream.read(length), 0
        while at < length:  # records: opcode (1 byte), length (8), then the fields
            opcode, size = struct.unpack_from("<BQ", data, at)
            at += 9
            if opcode == Opcode.MESSAGE:
                (channel_id,) = struct.unpack_from("<H", data, at)
                by_channel.setdefault(channel_id, []).append(data[at + _MESSAGE_FIELDS_SIZE:at + size])
            at += size
    topics = {channel_id: summary.channels[channel_id].topic for channel_id in by_channel}
    return {topics[i]: items for i, items in by_channel.items() if topics[i] not in without}

"""Many MCAP messages written into the open chunk at once: a fast path written against mcap 1.6.0's
private Writer internals, taken only when that exact mcap is installed; any other release goes through
mcap's public Writer API (the same messages, slower).

mcap 1.6.0's `Writer.add_message` costs ~3 µs per message in pure Python (a dataclass, a dozen small
writes and struct calls). The fast path writes the same Message records into the open chunk with one
struct.pack per message, updates the same chunk index and statistics, then lets the writer finish the
chunk if it is full. It reads and writes the Writer's name-mangled attributes (`_Writer__statistics`,
`_Writer__chunk_builder`, `_Writer__maybe_finalize_chunk`) and a chunk's `record_writer._buffer`: this
module is the only place in adaptive_mj that does (tests/test_record.py checks both paths write the same
bytes, and the independent @mcap/core reader reads the files, tests/test_foxglove.py). `add_rows_fast` does
the same for a block of logged rows (format 6's six JSON messages a row) with the message heads built by numpy:
~0.45 µs a message instead of ~0.7 (600 messages, measured here). `add_packed_rows_fast` writes a block of rows
whose payloads are fixed-size binary (format 8's CDR, one /row message a row; format 7 wrote six): the whole block,
message heads and payloads, is one packed numpy record array (`message_rows`, one or more channels a row) written
with one `tobytes`; nothing is built per message but its index entry.
"""
from __future__ import annotations

import struct
from importlib.metadata import version
from typing import Any, Callable

import numpy as np
from mcap.opcode import Opcode
from mcap.records import MessageIndex
from mcap.writer import Writer

#: the mcap release whose Writer internals the fast path was written for (and checked against)
WRITTEN_FOR = "1.6.0"

Batch = list[tuple[int, int, bytes]]  # (channel_id, log_time = publish_time [ns], JSON payload)

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log_time, publish_time
_OPCODE_MESSAGE = 0x05


def add_messages_public(writer: Writer, batch: Batch) -> None:
    """Writer.add_message for each (channel_id, time_ns, data), publish_time = log_time (any mcap)."""
    for channel_id, ns, data in batch:
        writer.add_message(channel_id, ns, data, ns)


class _PackedMessageIndex(MessageIndex):
    """mcap's MessageIndex, serialised with one struct.pack instead of two calls per entry
    (same bytes: channel u16, byte length u32, then (log_time u64, offset u64) pairs)."""

    def write(self, stream) -> None:
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write2(self.channel_id)
        stream.write4(len(self.records) * 16)
        flat = [v for pair in self.records for v in pair]
        stream.write(struct.pack(f"<{len(flat)}Q", *flat))
        stream.finish_record()


def add_messages_fast(writer: Writer, batch: Batch) -> None:
    """What add_messages_public writes, straight into mcap 1.6.0's open chunk (see the module's doc)."""
    if not batch:
        return
    internals: Any = writer  # its name-mangled attributes are private: Writer's type does not show them
    stats = internals._Writer__statistics
    chunk = internals._Writer__chunk_builder
    if chunk is None:  # a writer without chunking: nothing to write into
        add_messages_public(writer, batch)
        return
    buf = chunk.record_writer._buffer
    pack = _MESSAGE_HEAD.pack
    indices = chunk.message_indices
    counts = stats.channel_message_counts
    lo = min(ns for _, ns, _ in batch)
    hi = max(ns for _, ns, _ in batch)
    offset = buf.tell()
    parts = []
    for channel_id, ns, data in batch:
        index = indices.get(channel_id)
        if index is None:
            index = indices[channel_id] = _PackedMessageIndex(channel_id=channel_id, records=[])
        index.records.append((ns, offset))
        head = pack(_OPCODE_MESSAGE, 22 + len(data), channel_id, 0, ns, ns)
        offset += len(head) + len(data)
        parts.append(head)
        parts.append(data)
        counts[channel_id] += 1
    buf.write(b"".join(parts))  # one write: the offsets above are where each record lands
    _count(writer, chunk, stats, lo, hi, len(batch))


def _count(writer: Writer, chunk, stats, lo: int, hi: int, count: int) -> None:
    """After `count` messages of log times lo..hi [ns] went into the open chunk: its and the file's time
    range and message counts, as Writer.add_message keeps them; then the writer finishes the chunk if
    it is full."""
    chunk.message_start_time = lo if chunk.num_messages == 0 else min(chunk.message_start_time, lo)
    chunk.message_end_time = max(chunk.message_end_time, hi)
    chunk.num_messages += count
    stats.message_start_time = lo if stats.message_count == 0 else min(stats.message_start_time, lo)
    stats.message_end_time = max(stats.message_end_time, hi)
    stats.message_count += count
    internals: Any = writer  # its name-mangled attributes are private: Writer's type does not show them
    internals._Writer__maybe_finalize_chunk()


def add_rows_public(writer: Writer, channel_ids: list[int], log_ns: np.ndarray, blob: bytes) -> None:
    """A block of rows, each row one message per channel of `channel_ids` at its time log_ns[i] [ns]:
    the payloads are `blob` split at NUL bytes, row by row (row i, channel j is piece i·len(channel_ids) + j),
    through Writer.add_message (any mcap)."""
    if len(log_ns) == 0:
        return
    payloads = blob.split(b"\0")
    times = [ns for ns in log_ns.tolist() for _ in channel_ids]
    add_messages_public(writer, list(zip(channel_ids * len(log_ns), times, payloads, strict=True)))


_HEAD = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"), ("log_time", "<u8"),
                  ("publish_time", "<u8")])  # _MESSAGE_HEAD as a packed numpy record (31 bytes)
assert _HEAD.itemsize == _MESSAGE_HEAD.size


def add_rows_fast(writer: Writer, channel_ids: list[int], log_ns: np.ndarray, blob: bytes) -> None:
    """The messages add_rows_public writes, straight into mcap 1.6.0's open chunk (as add_messages_fast:
    the same bytes while the block fits in the chunk; a block that crosses the chunk size closes the
    chunk after it, not after the message that crossed): the message heads built by numpy as one packed
    array, each record's offset from a cumulative sum of the record sizes, heads and payloads
    interleaved and written in one go."""
    if len(log_ns) == 0:
        return
    internals: Any = writer  # its name-mangled attributes are private: Writer's type does not show them
    chunk = internals._Writer__chunk_builder
    if chunk is None:
        add_rows_public(writer, channel_ids, log_ns, blob)
        return
    stats = internals._Writer__statistics
    buf = chunk.record_writer._buffer
    topics, rows = len(channel_ids), len(log_ns)
    payloads = blob.split(b"\0")
    count = topics * rows
    if len(payloads) != count:
        raise ValueError(f"add_rows_fast: {len(payloads)} payloads for {rows} rows of {topics} channels")
    lengths = np.fromiter(map(len, payloads), dtype=np.int64, count=count)
    head = np.zeros(count, dtype=_HEAD)
    head["opcode"] = _OPCODE_MESSAGE
    head["length"] = 22 + lengths
    head["channel"] = np.tile(np.asarray(channel_ids, dtype=np.uint16), rows)
    head["log_time"] = head["publish_time"] = np.repeat(np.asarray(log_ns, dtype=np.uint64), topics)
    size = _HEAD.itemsize + lengths
    offset = buf.tell()
    offsets = (np.cumsum(size) - size + offset).tolist()  # where each record lands
    heads = head.tobytes()
    step = _HEAD.itemsize
    parts: list[bytes] = [b""] * (2 * count)
    parts[0::2] = [heads[i:i + step] for i in range(0, step * count, step)]
    parts[1::2] = payloads
    buf.write(b"".join(parts))
    ns = np.asarray(log_ns, dtype=np.int64).tolist()
    indices, counts = chunk.message_indices, stats.channel_message_counts
    for j, channel_id in enumerate(channel_ids):
        index = indices.get(channel_id)
        if index is None:
            index = indices[channel_id] = _PackedMessageIndex(channel_id=channel_id, records=[])
        index.records.extend(zip(ns, offsets[j::topics], strict=True))
        counts[channel_id] += rows
    lo, hi = min(ns), max(ns)
    _count(writer, chunk, stats, lo, hi, count)


def message_rows(channel_ids: list[int], payload_dtypes: list[np.dtype]) -> np.ndarray:
    """A template row (a packed record array of one row) of one Message record per channel: field h<j> the
    record's head (_HEAD: opcode, record length, channel_ids[j], sequence 0; times 0), field p<j> its payload
    (payload_dtypes[j], fixed size, zeros). A block of rows is np.repeat(template, rows) with its payloads filled
    by the caller and its times by add_packed_rows; the array's bytes are then the records as they go into the
    chunk."""
    fields: list[tuple[str, Any]] = []
    for j, payload in enumerate(payload_dtypes):
        fields += [(f"h{j}", _HEAD), (f"p{j}", payload)]
    template = np.zeros(1, dtype=np.dtype(fields))  # packed (align=False): no byte between two records
    for j, channel_id in enumerate(channel_ids):
        head = template[f"h{j}"]
        head["opcode"] = _OPCODE_MESSAGE
        head["length"] = 22 + payload_dtypes[j].itemsize
        head["channel"] = channel_id
    return template


def _set_times(channel_ids: list[int], log_ns: np.ndarray, records: np.ndarray) -> None:
    """Every message head of `records` (message_rows) stamped with its row's log_ns [ns] (log and publish time)."""
    ns = np.asarray(log_ns, dtype=np.uint64)
    for j in range(len(channel_ids)):
        head = records[f"h{j}"]
        head["log_time"] = ns
        head["publish_time"] = ns


def add_packed_rows_public(writer: Writer, channel_ids: list[int], log_ns: np.ndarray, records: np.ndarray) -> None:
    """A block of rows of fixed-size payloads (rows of message_rows' template, payloads filled), row i channel j at
    log_ns[i] [ns], through Writer.add_message (any mcap)."""
    batch: Batch = []
    payloads = [records[f"p{j}"] for j in range(len(channel_ids))]
    for i, ns in enumerate(np.asarray(log_ns, dtype=np.int64).tolist()):
        batch.extend((channel_id, ns, payloads[j][i].tobytes()) for j, channel_id in enumerate(channel_ids))
    add_messages_public(writer, batch)


def add_packed_rows_fast(writer: Writer, channel_ids: list[int], log_ns: np.ndarray, records: np.ndarray) -> None:
    """What add_packed_rows_public writes, straight into mcap 1.6.0's open chunk (as add_rows_fast: the same bytes
    while the block fits in the chunk): the heads' times set by numpy, the whole block written as the array's bytes,
    the message index entries from the fixed record stride."""
    rows = len(log_ns)
    if rows == 0:
        return
    internals: Any = writer  # its name-mangled attributes are private: Writer's type does not show them
    chunk = internals._Writer__chunk_builder
    if chunk is None:
        add_packed_rows_public(writer, channel_ids, log_ns, records)
        return
    stats = internals._Writer__statistics
    buf = chunk.record_writer._buffer
    _set_times(channel_ids, log_ns, records)
    base = buf.tell()
    buf.write(records.tobytes())
    stride = records.dtype.itemsize
    ns = np.asarray(log_ns, dtype=np.int64).tolist()
    indices, counts = chunk.message_indices, stats.channel_message_counts
    fields: Any = records.dtype.fields  # a structured dtype's fields: name -> (dtype, byte offset)
    for j, channel_id in enumerate(channel_ids):
        index = indices.get(channel_id)
        if index is None:
            index = indices[channel_id] = _PackedMessageIndex(channel_id=channel_id, records=[])
        first = base + fields[f"h{j}"][1]
        index.records.extend(zip(ns, range(first, first + stride * rows, stride), strict=True))
        counts[channel_id] += rows
    _count(writer, chunk, stats, min(ns), max(ns), rows * len(channel_ids))


def writer_for(mcap_version: str) -> Callable[[Writer, Batch], None]:
    """The batch writer for an installed mcap release: the fast path for WRITTEN_FOR only."""
    return add_messages_fast if mcap_version == WRITTEN_FOR else add_messages_public


def rows_writer_for(mcap_version: str) -> Callable[[Writer, list[int], np.ndarray, bytes], None]:
    """The row-block writer for an installed mcap release: the fast path for WRITTEN_FOR only."""
    return add_rows_fast if mcap_version == WRITTEN_FOR else add_rows_public


def packed_rows_writer_for(mcap_version: str) -> Callable[[Writer, list[int], np.ndarray, np.ndarray], None]:
    """The packed-row writer for an installed mcap release: the fast path for WRITTEN_FOR only."""
    return add_packed_rows_fast if mcap_version == WRITTEN_FOR else add_packed_rows_public


#: the ones used by the Recorder, chosen once for the mcap installed
add_messages = writer_for(version("mcap"))
add_rows = rows_writer_for(version("mcap"))
add_packed_rows = packed_rows_writer_for(version("mcap"))

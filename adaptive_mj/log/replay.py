"""Read a run log (MCAP, see docs/LOG_FORMAT.md) back into a Trajectory.

`read_log(path)` reads a closed log through its index (`mcap.reader.make_reader`),
and a log whose footer is missing or damaged (a killed run, a cut copy, a bad
chunk) by scanning it from the start and keeping every row that was written
whole before the end or the damage. Anything that is not a readable
adaptive-mj log raises LogFormatError with one line naming the file.
"""
from __future__ import annotations

import io
import json
import math
import os
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Callable, Optional

import numpy as np
from mcap.decoder import DecoderFactory
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from adaptive_mj.errors import LogFormatError
from adaptive_mj.log.record import (
    ASSET_ATTACHMENT_PREFIX,
    CDR_HEADER,
    CRASHED_SINCE_VERSION,
    EVENT_TOPIC,
    HEADER_METADATA,
    LOG_FORMAT_VERSION,
    embedded_digest,
    MODEL_SOURCE_ATTACHMENT,
    MODEL_XML_ATTACHMENT,
    NONFINITE_KEY,
    ROW_PARTS,
    ROW_TOPIC,
    ROW_TOPICS,
    SCENARIO_METADATA,
    STATUS_METADATA,
    SUMMARY_TOPIC,
    VERSION_KEY_PREFIX,
    close_statuses,
    row_fields,
)
from adaptive_mj.trajectory import Status, Trajectory, ending

MCAP_MAGIC = b"\x89MCAP0\r\n"
# Footer record: opcode, record length, summary_start, summary_offset_start, summary CRC.
_FOOTER = struct.Struct("<BQQQI")
_FOOTER_BODY_LEN = 8 + 8 + 4


class JsonDecoderFactory(DecoderFactory):
    """Decodes "json" messages for mcap readers (mcap ships no JSON decoder):
    make_reader(f, decoder_factories=[JsonDecoderFactory()]).iter_decoded_messages()."""

    def decoder_for(self, message_encoding: str,
                    schema: Optional[Schema]) -> Optional[Callable[[bytes], Any]]:
        return json.loads if message_encoding == "json" else None


@dataclass(frozen=True)
class LoggedRun:
    """A run read back from its log.

    header: the "adaptive_mj" metadata, decoded (numbers as numbers,
    param_names/overrides as lists, versions as a dict under "versions").
    trajectory: rows at the logging rate (every log_every-th physics step).
    events: the /events payloads, in order; summary: the /summary payload
    (None when status is "truncated": the rows do not cover the whole run; a log before format 9 that closed a
    crash as "failed", "crashed at t = …", reads with status "crashed", here and in `status`).
    status: "ok", "failed", "crashed", "diverged", "interrupted", or "truncated" when
    the rows are a recovered prefix (the run never closed its log, or part of
    the file is damaged); note says what was recovered ("" for a whole log).
    damaged: part of the file is corrupt (a chunk failing its CRC, an unreadable
    record), not just cut off.
    """

    header: dict
    scenario_text: str
    overrides: tuple[str, ...]
    model_xml: str | None
    model_source: str | None
    model_assets: dict[str, bytes]
    trajectory: Trajectory
    events: list[dict]
    summary: dict | None
    status: str
    recovered_rows: int
    note: str = ""
    damaged: bool = False
    # the model the log embedded was removed whole (a tool stripped its attachments): rows and summary intact,
    # --verify impossible
    model_missing: bool = False


@dataclass
class _Scan:
    """What a pass over the file found, messages still undecoded."""

    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    messages: list[tuple[str, bytes]] = field(default_factory=list)   # (topic, payload)
    encodings: dict[str, str] = field(default_factory=dict)  # topic -> its channel's message encoding
    library: str = ""
    complete: bool = False      # reached a footer with every record before it readable
    problem: str = ""           # where and why reading stopped short ("" when complete)
    damaged: bool = False       # a chunk or record is corrupt (not just cut off)


def read_log(path: str | os.PathLike) -> LoggedRun:
    """Read the run log at `path`.

    Raises LogFormatError for an empty or non-MCAP file, an MCAP file not
    written by adaptive_mj, a log format newer than LOG_FORMAT_VERSION, and a
    damaged log with no row to recover. OSError (missing file) passes through.
    """
    name = os.fspath(path)
    with open(name, "rb") as f:
        data = f.read()
    if not data:
        raise LogFormatError(f"{name}: empty file (0 bytes), expected an adaptive-mj MCAP log")
    if not data.startswith(MCAP_MAGIC):
        raise LogFormatError(f"{name}: not an MCAP file (starts with {data[:8]!r}), "
                             f"expected the MCAP magic {MCAP_MAGIC!r}")
    try:
        return _read(name, data)
    except LogFormatError:
        raise
    except Exception as e:   # any other failure on odd bytes is still a format error
        raise LogFormatError(f"{name}: unreadable adaptive-mj log "
                             f"({type(e).__name__}: {e})") from e


def _read(name: str, data: bytes) -> LoggedRun:
    scan = None
    if _has_valid_footer(data):
        try:
            scan = _scan_indexed(data)
        except Exception:
            scan = None     # damaged inside: the linear scan finds where
    if scan is None:
        scan = _scan_linear(data)

    header = _decode_header(name, scan)
    if SCENARIO_METADATA not in scan.metadata:
        raise LogFormatError(f"{name}: no '{SCENARIO_METADATA}' metadata record "
                             f"({scan.problem or 'the log is whole'}), expected the scenario text")
    scenario_text = scan.metadata[SCENARIO_METADATA].get("text", "")
    order, log_every, dt = header["order"], header["log_every"], header["dt"]
    names = tuple(header["param_names"])
    joints = tuple(header.get("joint_names", ()))  # format 1: always a 1-DOF run
    controls = tuple(header.get("control_names", ()))  # format 6: () before (u one per joint)
    states = tuple(header.get("state_names", ()))  # format 6

    times, cols, events, summary = _rows(name, scan.messages, order, names, joints, controls, states,
                                         encodings=scan.encodings)
    n_rows = len(times)
    status, reason, note = _final_status(name, scan, summary, n_rows, span=n_rows * log_every * dt,
                                         version=header["log_format_version"])
    if summary is not None and status == Status.CRASHED:  # an older log's "failed": the crash it was
        summary = {**summary, "status": str(status)}

    event_list = [(_number(e.get("t"), name, EVENT_TOPIC, "t"), str(e.get("label", "")))
                  for e in events]
    control = cols["/control"]
    n, m = len(times), len(joints)
    k = len(controls) or m  # the controls' columns come first in /control
    trajectory = Trajectory(
        t=np.array(times, dtype=float),
        x=cols["/state"].reshape(n, order, m) if joints else cols["/state"],
        u=control[:, :k].copy() if joints else control[:, 0].copy(),
        s=control[:, k:k + m].copy() if joints else control[:, 1].copy(),
        ref=cols["/reference"].reshape(n, order + 1, m) if joints else cols["/reference"],
        theta_hat=cols["/estimates"],
        theta=cols["/true_params"],
        V=cols["/lyapunov"][:, 0].copy(),
        names=names,
        status=status,
        reason=reason,
        joint_names=joints,
        control_names=controls,
        meta={"dt": dt, "order": order, "events": event_list, "log_every": log_every,
              **_limits_meta(header)},
    )
    assets = {k[len(ASSET_ATTACHMENT_PREFIX):]: v for k, v in scan.attachments.items()
              if k.startswith(ASSET_ATTACHMENT_PREFIX)}
    model_xml = _text(scan.attachments.get(MODEL_XML_ATTACHMENT), name, MODEL_XML_ATTACHMENT)
    model_source = _text(scan.attachments.get(MODEL_SOURCE_ATTACHMENT), name, MODEL_SOURCE_ATTACHMENT)
    missing = _check_embedded(name, header, model_xml, model_source, assets)
    if missing:
        note = (f"{note}; " if note else "") + ("warning: the log's embedded model is missing (its attachments were "
                                                "removed): its rows and summary are intact; --verify needs the model")
    return LoggedRun(
        header=header,
        scenario_text=scenario_text,
        overrides=tuple(header["overrides"]),
        model_xml=model_xml,
        model_source=model_source,
        model_assets=assets,
        trajectory=trajectory,
        events=events,
        summary=None if status == Status.TRUNCATED else summary,
        status=status,
        recovered_rows=n_rows,
        note=note,
        damaged=scan.damaged,
        model_missing=missing,
    )


def _limits_meta(header: dict) -> dict:
    """The trajectory's ctrl_range and joint_limits (format 5; null ends are unlimited), for the
    saturation and joint-limit metrics of a log summarised from its rows."""
    out: dict = {}
    if header.get("ctrl_range") is not None:
        out["ctrl_range"] = tuple(header["ctrl_range"])
    if header.get("joint_limits") is not None:
        out["joint_limits"] = [[-math.inf if lo is None else lo, math.inf if hi is None else hi]
                               for lo, hi in header["joint_limits"]]
    if header.get("state_names"):  # format 6: the oscillation metric's rows (report.metrics.rate_oscillation)
        out["state_names"] = tuple(header["state_names"])
    return out


def _check_embedded(name: str, header: dict, model_xml, model_source, assets) -> bool:
    """Format 5: what the log embeds must hash to the header's embedded_sha256; an altered model is a
    LogFormatError, never a silent re-simulation on something else. Returns True when the model was removed whole
    (no model, no source, no asset: a tool stripped the attachments), which leaves the rows readable."""
    want = header.get("embedded_sha256")
    if want is None:
        return False
    got = embedded_digest(model_xml, model_source, assets)
    if got != want and model_xml is None and model_source is None and not assets:
        return True
    if got != want:
        present = [what for what, v in (("model.xml", model_xml), ("model_source.xml", model_source)) if v is not None]
        raise LogFormatError(f"{name}: the embedded model does not match the log's embedded_sha256 ({want[:12]}, "
                             f"found {got[:12]} over {', '.join(present) or 'no model'} and {len(assets)} asset(s)): "
                             "the log was altered after it was written")
    return False


def _rows(name: str, messages: list[tuple[str, bytes]], order: int, names: tuple[str, ...],
          joints: tuple[str, ...] = (), controls: tuple[str, ...] = (), states: tuple[str, ...] = (),
          encodings: dict[str, str] | None = None):
    """Decode the messages: (times, {row topic: (N, fields) array}, events, summary). A log with a /row channel
    (format 8) has one CDR message a row (_row_messages); otherwise a row topic's messages are JSON objects
    (formats 1-6, and log.encoding = "json") or CDR (format 7), as its channel says (`encodings`, topic -> message
    encoding; JSON where absent), and a row is kept only if every row topic has a message at its t (a cut log may
    end mid-row)."""
    encodings = encodings or {}
    fields = row_fields(order, names, joints, controls, states)
    raw_rows: dict[str, list[bytes]] = {topic: [] for topic in (*ROW_TOPICS, ROW_TOPIC)}
    events: list[dict] = []
    summary = None
    for topic, raw in messages:
        if topic in raw_rows:
            raw_rows[topic].append(raw)
            continue
        payload = _json_object(raw, name, topic)
        if topic == EVENT_TOPIC:
            events.append(payload)
        elif topic == SUMMARY_TOPIC:
            summary = payload
    if ROW_TOPIC in encodings:
        times, cols = _row_messages(raw_rows[ROW_TOPIC], fields, encodings[ROW_TOPIC], name)
        return times, cols, events, summary
    # per row topic: its messages' times in order, and t -> the row's values (the last message at a t wins)
    by_t: dict[str, dict[float, Any]] = {}
    state_times: list[float] = []
    for topic in ROW_TOPICS:
        encoding = encodings.get(topic, "json")
        if encoding == "cdr":
            values = _cdr_rows(raw_rows[topic], len(fields[topic]), name, topic)
            topic_times = values[:, 0].tolist()
            by_t[topic] = dict(zip(topic_times, values[:, 1:], strict=True))
        elif encoding == "json":
            payloads = [_json_object(raw, name, topic) for raw in raw_rows[topic]]
            topic_times = [_number(p.get("t"), name, topic, "t") for p in payloads]
            by_t[topic] = dict(zip(topic_times, payloads, strict=True))
        else:
            raise LogFormatError(f"{name}: the {topic} channel's message encoding is {encoding!r}, "
                                 f"expected 'cdr' or 'json'")
        if topic == "/state":
            state_times = topic_times
    times = [t for t in state_times if all(t in by_t[topic] for topic in ROW_TOPICS)]
    cols = {}
    for topic in ROW_TOPICS:
        rows = [by_t[topic][t] for t in times]
        if encodings.get(topic, "json") == "json":
            rows = [_values(payload, fields[topic], name, topic) for payload in rows]
        cols[topic] = np.array(rows, dtype=float).reshape(len(times), len(fields[topic]))
    return times, cols, events, summary


def _row_messages(raws: list[bytes], fields: dict[str, tuple[str, ...]], encoding: str,
                  name: str) -> tuple[list[float], dict[str, np.ndarray]]:
    """Format 8: the /row messages (CDR: the encapsulation header, t, then every row topic's fields in ROW_TOPICS'
    order, all little-endian float64) decoded in one np.frombuffer: (times [s] in file order, {row topic: (N,
    fields) array}), the same arrays format 7 gives for the same run. Where two messages have the same t the
    last one's values stand at that t, as in format 7."""
    if encoding != "cdr":
        raise LogFormatError(f"{name}: the {ROW_TOPIC} channel's message encoding is {encoding!r}, expected 'cdr'")
    widths = [len(fields[topic]) for topic in ROW_TOPICS]
    parts = ", ".join(f"{part} {w}" for part, w in zip(ROW_PARTS, widths, strict=True))
    values = _cdr_rows(raws, sum(widths), name, ROW_TOPIC, f" ({parts})")
    times = values[:, 0].tolist()
    if len(set(times)) != len(times):  # the last message at a t wins
        last = {t: i for i, t in enumerate(times)}
        values = values[[last[t] for t in times]]
    cols, at = {}, 1
    for topic, width in zip(ROW_TOPICS, widths, strict=True):
        cols[topic] = np.ascontiguousarray(values[:, at:at + width])
        at += width
    return times, cols


def _json_object(raw: bytes, name: str, topic: str) -> dict:
    payload = json.loads(raw)
    if not isinstance(payload, dict):
        raise LogFormatError(f"{name}: a {topic} message is {type(payload).__name__}, "
                             f"expected a JSON object")
    return payload


def _cdr_rows(raws: list[bytes], width: int, name: str, topic: str, detail: str = "") -> np.ndarray:
    """A topic's CDR messages of fixed size (the encapsulation header, then t and `width` little-endian float64:
    a format-7 row topic, or format 8's /row) as an (N, 1 + width) array [t in s, then the fields], decoded in one
    np.frombuffer; any other size or header is a LogFormatError naming the file, the size and header expected
    (`detail`: what the float64 are) and the message's."""
    size = len(CDR_HEADER) + 8 * (1 + width)
    bad = next((raw for raw in raws if len(raw) != size or raw[:len(CDR_HEADER)] != CDR_HEADER), None)
    if bad is not None:
        raise LogFormatError(f"{name}: a {topic} message is {len(bad)} bytes starting {bytes(bad[:4])!r}, expected "
                             f"{size} bytes of CDR (header {CDR_HEADER!r}, t and {width} float64{detail})")
    block = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), size)
    values = np.ascontiguousarray(block[:, len(CDR_HEADER):]).view("<f8")
    t = values[:, 0]
    if not (np.isfinite(t).all() and (t >= 0).all()):
        raise LogFormatError(f"{name}: a {topic} message has t = {t[~(np.isfinite(t) & (t >= 0))][0]!r}, "
                             f"expected a finite time >= 0 [s]")
    return values.astype(float, copy=False)


def _final_status(name: str, scan: _Scan, summary: dict | None, n_rows: int,
                  *, span: float, version: int) -> tuple[Status, str, str]:
    """(status, reason, note): the run's own status when its rows are all there (as this version names it: a
    crash that a log before format 9 closed as "failed" is "crashed"), else "truncated" with a note saying what
    was recovered (span [s])."""
    if scan.damaged:
        if n_rows == 0:
            raise LogFormatError(f"{name}: {scan.problem}, and no whole row precedes it; "
                                 f"nothing to recover")
        note = f"recovered {n_rows} rows ({span:.1f} s) before {scan.problem}"
        if summary is not None:
            note += f"; the run itself ended with status {summary.get('status')!r}"
        return Status.TRUNCATED, note, note
    final = summary if summary is not None else (
        scan.metadata.get(STATUS_METADATA) if scan.complete else None)
    if final is None:
        cause = scan.problem or "the log has no final status"
        note = f"recovered {n_rows} rows ({span:.1f} s) of a truncated log ({cause})"
        return Status.TRUNCATED, note, note
    status, allowed = final.get("status"), close_statuses(version)
    if status not in allowed:
        raise LogFormatError(f"{name}: final status is {status!r}, expected one of "
                             f"{allowed}")
    # /summary is written after the last row, so its presence means no row is missing.
    note = "" if scan.complete else (
        f"all {n_rows} rows ({span:.1f} s) read; the footer is missing ({scan.problem})")
    reason = str(final.get("reason", ""))
    return (ending(status, reason) if version < CRASHED_SINCE_VERSION else Status(status)), reason, note


# -- the two ways through the file ----------------------------------------------------------

def _has_valid_footer(data: bytes) -> bool:
    """True if data ends with a footer and magic whose summary CRC checks out."""
    foot = len(data) - len(MCAP_MAGIC) - _FOOTER.size
    if foot < len(MCAP_MAGIC) or not data.endswith(MCAP_MAGIC):
        return False
    opcode, length, summary_start, _, crc = _FOOTER.unpack_from(data, foot)
    if opcode != Opcode.FOOTER or length != _FOOTER_BODY_LEN:
        return False
    start = summary_start or foot
    if not len(MCAP_MAGIC) <= start <= foot:
        return False
    return crc == 0 or zlib.crc32(data[start:foot + _FOOTER.size - 4]) == crc


def _scan_indexed(data: bytes) -> _Scan:
    """Read a whole log through its summary section and indexes, checking chunk CRCs."""
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    scan = _Scan(complete=True, library=reader.get_header().library)
    for record in reader.iter_metadata():
        scan.metadata.setdefault(record.name, dict(record.metadata))
    for attachment in reader.iter_attachments():
        scan.attachments[attachment.name] = attachment.data
    summary = reader.get_summary()
    channels = summary.channels.values() if summary is not None else ()
    scan.encodings = {channel.topic: channel.message_encoding for channel in channels}
    scan.messages = [(channel.topic, message.data)
                     for _, channel, message in reader.iter_messages(log_time_order=False)]
    return scan


def _scan_linear(data: bytes) -> _Scan:  # noqa: C901 (one branch per record kind and recovery case)
    """Read records from the start until the footer, the end of the data or damage.

    A chunk that fails its CRC (or does not decompress) ends the rows and
    events; later chunks are still read for the /summary message (its status
    goes into the note).
    """
    scan = _Scan()
    stream = io.BytesIO(data)
    records = StreamReader(stream, emit_chunks=True, record_size_limit=len(data)).records
    topics: dict[int, str] = {}

    def take(message: Message) -> None:
        topic = topics.get(message.channel_id)
        if topic is None:
            raise ValueError(f"message on unknown channel {message.channel_id}")
        if not scan.damaged or topic == SUMMARY_TOPIC:
            scan.messages.append((topic, message.data))

    while True:
        start = stream.tell()
        try:
            record = next(records)
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as e:
                    if not scan.damaged:
                        scan.damaged = True
                        scan.problem = f"a damaged chunk at byte {start} ({e})"
                    continue
                for r in inner:
                    if isinstance(r, Channel):
                        topics[r.id] = r.topic
                        scan.encodings[r.topic] = r.message_encoding
                    elif isinstance(r, Message):
                        take(r)
            elif isinstance(record, Channel):
                topics[record.id] = record.topic
                scan.encodings[record.topic] = record.message_encoding
            elif isinstance(record, Message):
                take(record)
            elif isinstance(record, Metadata):
                scan.metadata.setdefault(record.name, dict(record.metadata))
            elif isinstance(record, Attachment):
                scan.attachments[record.name] = record.data
            elif isinstance(record, Header):
                scan.library = record.library
            elif isinstance(record, Footer):
                scan.complete = not scan.damaged
                return scan
        except StopIteration:
            break
        except Exception as e:
            if not scan.problem:
                scan.problem, cut = _stop_reason(data, start, e)
                scan.damaged = not cut
            break
    if not scan.problem:
        scan.problem = f"the file ends at byte {len(data)} without a footer"
    return scan


def _stop_reason(data: bytes, start: int, error: Exception) -> tuple[str, bool]:
    """Why reading stopped at the record that begins at byte `start`, and whether
    the file was simply cut off there (rather than damaged)."""
    if start >= len(data):
        return f"the file ends at byte {len(data)} without a footer", True
    if len(data) - start < 9:
        return f"the file ends inside a record at byte {start}", True
    _, length = struct.unpack_from("<BQ", data, start)
    if start + 9 + length > len(data):
        return f"the file ends inside a record at byte {start}", True
    detail = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
    return f"an unreadable record at byte {start} ({detail})", False


# -- decoding helpers -------------------------------------------------------------------------

def _decode_header(name: str, scan: _Scan) -> dict:
    meta = scan.metadata.get(HEADER_METADATA)
    if meta is None:
        if scan.complete:
            raise LogFormatError(f"{name}: MCAP file without '{HEADER_METADATA}' metadata, "
                                 f"expected a log written by adaptive_mj.log.record "
                                 f"(this one was written by {scan.library!r})")
        raise LogFormatError(f"{name}: no '{HEADER_METADATA}' metadata record "
                             f"({scan.problem}), expected an adaptive-mj log header")
    raw_version = meta.get("log_format_version")
    try:
        if raw_version is None:
            raise TypeError("no log_format_version")
        version = int(raw_version)
    except (TypeError, ValueError):
        raise LogFormatError(f"{name}: '{HEADER_METADATA}' metadata has log_format_version "
                             f"{raw_version!r}, expected an integer") from None
    if version > LOG_FORMAT_VERSION:
        raise LogFormatError(f"{name}: log format version {version} is newer than this "
                             f"adaptive_mj reads (up to {LOG_FORMAT_VERSION}); upgrade adaptive_mj")
    if version < 1:
        raise LogFormatError(f"{name}: log_format_version {version}, expected 1 to "
                             f"{LOG_FORMAT_VERSION}")

    def str_list(text: str) -> list[str]:
        value = json.loads(text)
        if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
            raise ValueError("not a JSON list of strings")
        return value

    convert: dict[str, Callable[[str], Any]] = {
        "log_format_version": int, "seed": int, "log_every": int, "order": int,
        "log_rate_hz": float, "dt": float, "created_unix": float,
        "param_names": str_list, "overrides": str_list, "joint_names": str_list, "notes": str_list,
        "control_names": str_list, "state_names": str_list,  # format 6
        "law_plugin": json.loads,  # format 3: {name, distribution, version, source_sha256} or null
        "plant_plugin": json.loads,  # format 3: the same, or null
        "control_period": float,  # format 4: [s]
        "ctrl_range": json.loads,  # format 5: [lo, hi] or null
        "joint_limits": json.loads,  # format 5: (m, 2) with null for unlimited ends, or null
    }
    header: dict[str, Any] = {}
    versions: dict[str, str] = {}
    for key, text in meta.items():
        if key.startswith(VERSION_KEY_PREFIX):
            versions[key[len(VERSION_KEY_PREFIX):]] = text
            continue
        try:
            header[key] = convert[key](text) if key in convert else text
        except (ValueError, TypeError) as e:
            raise LogFormatError(f"{name}: '{HEADER_METADATA}' metadata {key} = {text!r} "
                                 f"is invalid ({e})") from None
    header["versions"] = versions
    header.setdefault("overrides", [])
    header.setdefault("control_mode", "continuous")  # formats 1-3: the law ran at every stage
    if "dt" in header:
        header.setdefault("control_period", header["dt"])
    for key, ok, expected in (
            ("order", lambda v: v >= 1, "an integer >= 1"),
            ("log_every", lambda v: v >= 1, "an integer >= 1"),
            ("dt", lambda v: math.isfinite(v) and v > 0, "a number > 0 [s]"),
            ("param_names", lambda v: True, "a JSON list of names")):
        if key not in header or not ok(header[key]):
            raise LogFormatError(f"{name}: '{HEADER_METADATA}' metadata {key} is "
                                 f"{header.get(key, 'missing')!r}, expected {expected}")
    return header


def _number(value: Any, name: str, topic: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise LogFormatError(f"{name}: a {topic} message has {key} = {value!r}, expected a number")
    return float(value)


def _values(payload: dict, fields: tuple[str, ...], name: str, topic: str) -> list[float]:
    """The payload's fields as floats; a non-finite one is absent and listed in "nonfinite"."""
    nonfinite = payload.get(NONFINITE_KEY)
    if not isinstance(nonfinite, dict):
        nonfinite = {}
    out = []
    for key in fields:
        if key in payload:
            out.append(_number(payload[key], name, topic, key))
        elif nonfinite.get(key) in ("inf", "-inf", "nan"):
            out.append(float(nonfinite[key]))
        else:
            raise LogFormatError(f"{name}: a {topic} message lacks {key!r}, expected the fields "
                                 f"{list(fields)}")
    return out


def _text(data: bytes | None, name: str, what: str) -> str | None:
    if data is None:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise LogFormatError(f"{name}: attachment {what} is not UTF-8 text ({e})") from None

"""The run log: one MCAP file per run, written while the run goes.

A `Recorder` is the loop's `Sink`. It keeps every `log_every`-th physics step
(global step index k with k % log_every == 0) and writes each kept row stamped with the simulation time.
Format 8 (the default) writes a row as ONE message on /row: CDR with a ros2msg schema (adaptive_mj/msg/Row),
float64 t, then the sub-messages state, reference, control, estimates, true_params, lyapunov, each its fields as
float64 (no t of their own). `log.encoding = "json"` writes format 6 exactly: a row as six JSON messages, one
per row topic (ROW_TOPICS; format 7 had the same six topics in CDR):

    /state        {t, y, y_dot[, y_ddot, ...]}            n entries         /row.state
    /reference    {t, y_d, y_d_dot, y_d_ddot[, ...]}      n+1 entries       /row.reference
    /control      {t, u, s, y_tilde}                                        /row.control
    /estimates    {t, <param>: θ̂_i, ...}                                    /row.estimates
    /true_params  {t, <param>: θ_i, ...}                                    /row.true_params
    /lyapunov     {t, V}                                                    /row.lyapunov
    /events       {t, label, ...detail}                   one per event
    /summary      {...summary, status, reason}            once, at close()

Every row carries the exact float `t` (CDR holds the float64 itself; JSON floats are written with
repr, which round-trips), so replay rebuilds the arrays bit for bit. /events and /summary are JSON in both. The
full layout is in docs/LOG_FORMAT.md; `adaptive_mj.log.replay.read_log` reads it (formats 1 to 8).

Bounded loss: each `write_rows` call ends by closing the chunk in progress
and flushing the file, so a run killed at any instant leaves a readable file
that holds every row of every completed `write_rows` call. The loop calls
`write_rows` every `sink_every` physics steps (1000 by default: 1 s at
dt = 1 ms), so that block is the most a killed run loses. A stop signal
(SIGINT, SIGTERM, see adaptive_mj.sim.interrupt) never cuts a write or the close
in half: it is raised once the call is done.
"""
from __future__ import annotations

import functools
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import numpy as np
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

# the batch writer: fast on the mcap it was written for, mcap's public Writer API on any other
from adaptive_mj.log.fast_mcap import (
    add_messages as _add_messages,
    add_packed_rows as _add_packed_rows,
    add_rows as _add_rows,
    message_rows as _message_rows,
)
from adaptive_mj.sim.interrupt import deferred
from adaptive_mj.trajectory import Status

# 6: control_names and state_names in the header (a plant whose controls are not one per joint and whose state
#    rows are not the output's derivatives: the quadrotor's 4 rotor thrusts on its 3 position axes, x = [p; v; φ; Ω]);
# 5: ctrl_range, joint_limits and embedded_sha256 (checked on every read) in the header;
# 4: control_mode, control_period in the header; 3: law_plugin, plant_plugin;
# 7: the row topics in CDR (ros2msg schemas: float64 t, then one float64 per field), packed by numpy a block at a
#    time; /events and /summary JSON as before; `encoding = "cdr"` in the header. log.encoding = "json" writes 6.
# 8: the six CDR row topics become one topic /row, one message a row (ROW_TOPIC: float64 t, then the six parts as
#    nested ros2msg sub-messages of float64 fields; field names lower-case, as ROS 2 and Foxglove require): a
#    sixth of the messages, so a sixth of the MCAP message index (16 bytes a message).
# 9: a run may close as "crashed" (Status.CRASHED: the vehicle hit the ground or tipped over), in /summary, the
#    "status" metadata and the Summary schema's enum; formats 1 to 8 closed a crash as "failed" with the reason
#    "crashed at t = …", which replay reads as crashed. The rows are format 8's. log.encoding = "json" still
#    writes 6, byte for byte in kind: a crash closes there as "failed" with that reason (status_written).
LOG_FORMAT_VERSION = 9  # 2: joint_names/notes, per-joint fields (1: 1-DOF only)

#: The row encodings a Recorder writes (LogHeader.encoding, the scenario's log.encoding): "cdr" (format 8, the
#: default) or "json" (JSON text, written exactly as format 6, which every reader of format 6 reads).
ENCODINGS = ("cdr", "json")
#: The format version log.encoding = "json" writes: its layout is format 6's, byte for byte in kind.
JSON_LOG_FORMAT_VERSION = 6
#: The first format whose logs may close as "crashed" (before: "failed", the reason "crashed at t = …").
CRASHED_SINCE_VERSION = 9
#: A CDR payload's encapsulation header: CDR_LE (plain CDR, little-endian), options 0.
CDR_HEADER = b"\x00\x01\x00\x00"

def embedded_digest(model_xml: str | None, model_source: str | None, assets: dict[str, bytes]) -> str:
    """SHA-256 (hex) of what a log embeds to re-simulate its run: the compiled model's XML, the exact
    source compiled, and every asset by name (format 5 writes it; the reader checks it on every read)."""
    import hashlib

    h = hashlib.sha256()
    for label, part in (("model.xml", model_xml), ("model_source.xml", model_source)):
        h.update(label.encode() + b"\0" + (b"\1" + part.encode() if part is not None else b"\0"))
    for name, data in sorted(assets.items()):
        h.update(b"asset\0" + name.encode() + b"\0" + len(data).to_bytes(8, "little") + bytes(data))
    return h.hexdigest()


def _finite_or_null(rows):
    """JSON cannot hold ±inf: unlimited ends become null."""
    if rows is None:
        return None
    return [[v if v is not None and abs(v) != float("inf") else None for v in row] for row in rows]


#: Statuses a run can be closed with (replay adds "truncated" for a log that was never closed).
CLOSE_STATUSES = (Status.OK, Status.DIVERGED, Status.INTERRUPTED, Status.FAILED, Status.CRASHED)


def close_statuses(version: int) -> tuple[Status, ...]:
    """The statuses a log of format `version` closes with: CLOSE_STATUSES, less "crashed" before format 9."""
    return CLOSE_STATUSES if version >= CRASHED_SINCE_VERSION else tuple(s for s in CLOSE_STATUSES
                                                                        if s != Status.CRASHED)


def status_written(status: str, version: int) -> Status:
    """The status a log of format `version` records for a run that ended with `status`: "crashed" is "failed"
    before format 9 (its reason, "crashed at t = …", says it crashed; trajectory.ending reads it back)."""
    return Status.FAILED if status == Status.CRASHED and version < CRASHED_SINCE_VERSION else Status(status)

#: Topics that make up one logged row in formats 1 to 7 (and log.encoding = "json"), in the order they are written.
ROW_TOPICS = ("/state", "/reference", "/control", "/estimates", "/true_params", "/lyapunov")
#: Format 8: the one topic of a logged row, its message the six parts above nested in this order.
ROW_TOPIC = "/row"
#: Format 8: the Row message's sub-message field of each row topic (its name without the slash), in order.
ROW_PARTS = tuple(topic[1:] for topic in ROW_TOPICS)
#: Format 8: the Row schema's name; its sub-message types are adaptive_mj/<Type> (State, Reference, ...).
ROW_SCHEMA_NAME = "adaptive_mj/msg/Row"
#: The line ros2msg puts before each dependent definition (ROS 2's rosbag2 and Foxglove split on it): 80 "=".
ROS2MSG_SEPARATOR = "=" * 80
EVENT_TOPIC = "/events"
SUMMARY_TOPIC = "/summary"

#: Key of the optional payload object that carries the non-finite values ("inf", "-inf",
#: "nan") of fields left out of a row message.
NONFINITE_KEY = "nonfinite"

HEADER_METADATA = "adaptive_mj"
SCENARIO_METADATA = "scenario"
STATUS_METADATA = "status"
MODEL_XML_ATTACHMENT = "model.xml"
MODEL_SOURCE_ATTACHMENT = "model_source.xml"
ASSET_ATTACHMENT_PREFIX = "asset/"
VERSION_KEY_PREFIX = "version."

_NS_PER_S = 1_000_000_000


def derivative_name(base: str, j: int) -> str:
    """Field name of the j-th time derivative of `base`: y, y_dot, y_ddot, y_dddot, ..."""
    return base if j == 0 else f"{base}_{'d' * j}ot"


def state_fields(order: int) -> tuple[str, ...]:
    """/state field names for a plant of order n: (y, y_dot, ..., y^(n-1))."""
    return tuple(derivative_name("y", j) for j in range(order))


def reference_fields(order: int) -> tuple[str, ...]:
    """/reference field names for order n: (y_d, y_d_dot, ..., y_d^(n))."""
    return tuple(derivative_name("y_d", j) for j in range(order + 1))


CONTROL_FIELDS = ("u", "s", "y_tilde")
LYAPUNOV_FIELDS = ("V",)


def row_fields(order: int, names: tuple[str, ...], joint_names: tuple[str, ...] = (),
               control_names: tuple[str, ...] = (), state_names: tuple[str, ...] = ()) -> dict[str, tuple[str, ...]]:
    """Field names of each row topic. A 1-DOF run (no joint names) uses y, y_dot, ..., u, s,
    y_tilde (format 1 and 2 alike); a run of m joints names one field per joint:
    q_<joint>, q_dot_<joint> (/state, derivative-major, as x (n, m) flattened),
    q_d_<joint>, q_d_dot_<joint>, q_d_ddot_<joint> (/reference), tau_<joint>, s_<joint>,
    q_tilde_<joint> (/control). Format 6: a run with state_names (one per row of x, e.g. p, v, phi, omega) names
    /state <row>_<joint> and its output <first>; with control_names (k actuators) /control starts with
    u_<actuator> (k fields) instead of tau_<joint>."""
    if not joint_names:
        state, ref, control = state_fields(order), reference_fields(order), CONTROL_FIELDS
    else:
        def per(bases):
            return tuple(f"{b}_{j}" for b in bases for j in joint_names)

        out = state_names[0] if state_names else "q"
        state = per(state_names) if state_names else per(derivative_name("q", k) for k in range(order))
        ref = per(derivative_name(f"{out}_d", k) for k in range(order + 1))
        u = tuple(f"u_{a}" for a in control_names) if control_names else per(("tau",))
        control = u + per(("s", f"{out}_tilde"))
    return {"/state": state, "/reference": ref, "/control": control, "/estimates": tuple(names),
            "/true_params": tuple(names), "/lyapunov": LYAPUNOV_FIELDS}


@dataclass(frozen=True)
class LogHeader:
    """What a log records about its run before the first row.

    scenario_text: the TOML text of the scenario file as given.
    scenario_source: where it came from (a path string), informational.
    overrides: the --set expressions applied on top of the text.
    log_rate_hz: requested logging rate [Hz]; dt: physics step [s].
    order: n, the state is [y, y', ..., y^(n-1)] and the reference has n+1 entries.
    param_names: names of θ, e.g. ("d", "b", "c").
    model_xml: mujoco.mj_saveLastXML of the compiled model (None without MJCF).
    model_source: the exact XML string that was compiled; model_assets: its assets.
    versions: {"adaptive_mj": ..., "mujoco": ..., ...}.
    created_unix: wall-clock creation time [s since the epoch], metadata only.
    """

    scenario_name: str
    scenario_text: str
    scenario_source: str
    overrides: tuple[str, ...]
    seed: int
    log_rate_hz: float
    dt: float
    order: int
    param_names: tuple[str, ...]
    model_xml: str | None
    model_source: str | None
    model_assets: dict[str, bytes] = field(default_factory=dict)
    versions: dict[str, str] = field(default_factory=dict)
    created_unix: float = 0.0
    joint_names: tuple[str, ...] = ()  # () for a 1-DOF plant; the m joint names otherwise
    notes: tuple[str, ...] = ()  # edits made to the model for the run (e.g. servo_to_torque)
    law_plugin: dict | None = None  # a plugin law: {name, distribution, version, source_sha256}
    plant_plugin: dict | None = None  # a plugin plant: the same fields
    control_mode: str = "continuous"  # format 4: "continuous" (the law at every stage) or "sampled"
    control_period: float = 0.0  # format 4: [s] the law's sampling period (continuous: dt)
    ctrl_range: list | None = None  # format 5: [lo, hi] actuator limits [control units], lists per joint
    joint_limits: list | None = None  # format 5: (m, 2) joint ranges [rad or m], null entries unlimited
    control_names: tuple[str, ...] = ()  # format 6: the k actuators where u is not one per joint (else ())
    state_names: tuple[str, ...] = ()  # format 6: a name per row of x where they are not y's derivatives (else ())
    encoding: str = "cdr"  # the rows' encoding (ENCODINGS): "cdr" writes format 8 (/row), "json" format 6
    # a Slotine–Li law's evaluation of Y π̂ and Yᵀ s, "recursive" (O(n)) or "regressor" (Y whole); "" for other
    # laws. Written since the O(n) form; a log without it ran the regressor form (runs.verify re-runs it so). A flight
    # law's allocation ("yaw_last", "exact_clip"), written since issue 52's; a quadrotor log with "" ran "exact_clip"
    law_evaluation: str = ""

    @property
    def log_every(self) -> int:
        """Physics steps per logged row: max(1, round(1 / (log_rate_hz * dt)))."""
        return max(1, round(1.0 / (self.log_rate_hz * self.dt)))


# The header's checks take its fields as `object`: a LogHeader is built from anything a caller passes
# (its annotations are not enforced at run time), and these checks are what stands between that and the log.

def _positive_number(value: object) -> bool:
    """A finite int or float > 0."""
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


def _int_at_least(value: object, lowest: int) -> bool:
    """An int (or numpy integer, not a bool) >= lowest."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool) and bool(value >= lowest)


def _name(value: object) -> bool:
    """A non-empty str."""
    return isinstance(value, str) and bool(value)


def _check_header(header: LogHeader) -> None:
    if not _positive_number(header.dt):
        raise ValueError(f"LogHeader.dt must be a finite number > 0 [s], got {header.dt!r}")
    if not _positive_number(header.log_rate_hz):
        raise ValueError(f"LogHeader.log_rate_hz must be a finite number > 0 [Hz], "
                         f"got {header.log_rate_hz!r}")
    if not _int_at_least(header.order, 1):
        raise ValueError(f"LogHeader.order must be an int >= 1, got {header.order!r}")
    names = tuple(header.param_names)
    reserved = {"t", NONFINITE_KEY}
    if len(set(names)) != len(names) or not all(_name(n) for n in names) or reserved & set(names):
        raise ValueError(f"LogHeader.param_names must be distinct non-empty strings other than "
                         f"{sorted(reserved)}, got {names!r}")
    joints = tuple(header.joint_names)
    if not all(_name(j) for j in joints):
        raise ValueError(f"LogHeader.joint_names must be non-empty strings, got {joints!r}")
    if joints:
        fields = [f for topic_fields in row_fields(header.order, (), joints, tuple(header.control_names),
                                                   tuple(header.state_names)).values() for f in topic_fields]
        if len(set(fields)) != len(fields) or len(set(joints)) != len(joints):
            raise ValueError(f"LogHeader.joint_names {joints!r} make clashing field names")
    if header.encoding not in ENCODINGS:
        raise ValueError(f"LogHeader.encoding must be one of {ENCODINGS}, got {header.encoding!r}")
    if header.state_names and len(header.state_names) != header.order:
        raise ValueError(f"LogHeader.state_names must name the {header.order} rows of x, got {header.state_names!r}")
    versions: Iterable[tuple[object, object]] = header.versions.items()
    for key, value in versions:
        if not isinstance(key, str) or not isinstance(value, str):
            raise ValueError(f"LogHeader.versions must map str to str, got {key!r}: {value!r}")
    assets: Iterable[tuple[object, object]] = header.model_assets.items()
    for name, data in assets:
        if not isinstance(name, str) or not isinstance(data, (bytes, bytearray)):
            raise ValueError(f"LogHeader.model_assets must map str to bytes, got {name!r}")


def _row_schema(title: str, description: str, fields: Mapping[str, str]) -> dict:
    """JSON Schema of a row payload {t, fields...}. Kept to what Foxglove's JSON Schema
    parser accepts: one "type" string per property, "properties" on every object."""
    properties: dict[str, dict] = {"t": {"type": "number", "description": "simulation time [s]"}}
    absent = f"absent when non-finite (see {NONFINITE_KEY})"
    properties.update({name: {"type": "number", "description": f"{text}; {absent}"}
                       for name, text in fields.items()})
    properties[NONFINITE_KEY] = {
        "type": "object",
        "description": "present only when a field is non-finite: its value, 'inf', '-inf' or 'nan'",
        "properties": {name: {"type": "string", "enum": ["inf", "-inf", "nan"]} for name in fields},
    }
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": ["t"],
        "additionalProperties": False,
    }


def _schemas(order: int, names: tuple[str, ...], joint_names: tuple[str, ...] = (),
             control_names: tuple[str, ...] = (), state_names: tuple[str, ...] = (),
             statuses: tuple[Status, ...] = CLOSE_STATUSES) -> dict[str, tuple[str, dict]]:
    """topic -> (schema name, JSON Schema); statuses: those /summary's status may hold (close_statuses)."""
    state = {n: f"output derivative {j} (y in m or rad)" for j, n in enumerate(state_fields(order))}
    ref = {n: f"reference derivative {j}" for j, n in enumerate(reference_fields(order))}
    control = {"u": "applied control after saturation [N or N*m]",
               "s": "sliding variable (first order: the tracking error)",
               "y_tilde": "tracking error y_d - y"}
    if joint_names:
        f = row_fields(order, names, joint_names, control_names, state_names)
        m = len(joint_names)
        state = {n: (f"axis {joint_names[i % m]}: state row {state_names[i // m]}" if state_names else
                     f"joint {joint_names[i % m]}: position derivative {i // m} [rad or m, per s^k]")
                 for i, n in enumerate(f["/state"])}
        ref = {n: f"joint {joint_names[i % m]}: reference derivative {i // m}" for i, n in enumerate(f["/reference"])}
        what = ("joint torque applied after saturation [N m or N]", "sliding variable s = q_tilde' + lambda q_tilde",
                "tracking error q_d - q [rad or m]")
        k = len(control_names)
        control = {n: (f"actuator {control_names[i]}: control applied after saturation" if i < k else
                       f"joint {joint_names[(i - k) % m]}: {what[1 + (i - k) // m]}") if control_names else
                   f"joint {joint_names[i % m]}: {what[i // m]}" for i, n in enumerate(f["/control"])}
    return {
        "/state": ("adaptive_mj.State", _row_schema(
            "State", "true plant state [y, y', ..., y^(n-1)] at the start of the step", state)),
        "/reference": ("adaptive_mj.Reference", _row_schema(
            "Reference", "reference [y_d, ..., y_d^(n)] at the start of the step", ref)),
        "/control": ("adaptive_mj.Control", _row_schema(
            "Control", "control applied over the step and the law's signals", control)),
        "/estimates": ("adaptive_mj.Estimates", _row_schema(
            "Estimates", "parameter estimates theta_hat", {n: f"estimate of {n}" for n in names})),
        "/true_params": ("adaptive_mj.TrueParams", _row_schema(
            "TrueParams", "true parameters theta", {n: f"true value of {n}" for n in names})),
        "/lyapunov": ("adaptive_mj.Lyapunov", _row_schema(
            "Lyapunov", "the law's Lyapunov function", {"V": "Lyapunov function value"})),
        EVENT_TOPIC: ("adaptive_mj.Event", {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": "Event",
            "description": "a scheduled event applied at the start of a step, with its details",
            "type": "object",
            "properties": {"t": {"type": "number", "description": "simulation time [s]"},
                           "label": {"type": "string"}},
            "required": ["t", "label"],
            "additionalProperties": True,
        }),
        SUMMARY_TOPIC: ("adaptive_mj.Summary", {
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": "Summary",
            "description": "the run's summary metrics, with its final status and reason",
            "type": "object",
            "properties": {"status": {"type": "string", "enum": list(statuses)},
                           "reason": {"type": "string"}},
            "required": ["status", "reason"],
            "additionalProperties": True,
        }),
    }


def ros2msg_field(name: str) -> str:
    """A field name as ROS 2 and Foxglove accept it in a ros2msg schema (format 8): a lower-case letter, then
    lower-case letters and digits in runs joined by single underscores (Foxglove's ros2msg parser refuses any other
    field name, `^[a-z](?:_?[a-z0-9]+)*$`). Letters are lower-cased, a run of other characters becomes one _, an
    _ at either end is dropped, and a name that then does not start with a letter gets f_ in front
    (payload/body.Ixx -> payload_body_ixx, V -> v, 2nd -> f_2nd). Only the schema (what Foxglove shows and
    plots) uses it; the reader decodes by position. Format 7 wrote names with their case kept."""
    out: list[str] = []
    gap = False
    for c in name:
        if c.isascii() and c.isalnum():
            if gap and out:
                out.append("_")
            out.append(c.lower())
            gap = False
        else:
            gap = True
    text = "".join(out)
    return text if text[:1].isalpha() else ("f_" + text if text else "f")


def _ros2msg_lines(schema: dict) -> list[str]:
    """The ros2msg field lines of a row topic's JSON Schema (_row_schema), t left out: one float64 per field in the
    payload's order, each with its description as a comment; names made distinct where ros2msg_field made two
    alike (a _2, _3 suffix)."""
    lines = []
    seen: set[str] = set()
    for name, prop in schema["properties"].items():
        if name in (NONFINITE_KEY, "t"):
            continue
        field_name, k = ros2msg_field(name), 2
        while field_name in seen:
            field_name, k = f"{ros2msg_field(name)}_{k}", k + 1
        seen.add(field_name)
        alias = "" if field_name == name else f" (field {name})"
        description = prop["description"].split("; absent when")[0]
        lines.append(f"float64 {field_name}  # {description}{alias}")
    return lines


def _ros2msg_row(schemas: Mapping[str, tuple[str, dict]]) -> bytes:
    """Format 8: the ros2msg text of the Row message (adaptive_mj/msg/Row), its dependencies concatenated as ROS 2
    and Foxglove read them: the top-level definition first (float64 t, then a field of type adaptive_mj/<Type> per
    row topic, ROW_PARTS' names), then for each row topic a line of 80 "=", a line "MSG: adaptive_mj/<Type>" (the
    name the field's type gives, which Foxglove matches exactly) and the type's float64 fields (_ros2msg_lines).
    `schemas`: _schemas' topic -> (name adaptive_mj.<Type>, JSON Schema)."""
    lines = ["# Row: one logged row, at the start of the physics step it was logged at",
             "float64 t  # simulation time [s]"]
    for topic, part in zip(ROW_TOPICS, ROW_PARTS, strict=True):
        name, schema = schemas[topic]
        lines.append(f"{name.replace('.', '/')} {part}  # {schema['description']}")
    for topic in ROW_TOPICS:
        name, schema = schemas[topic]
        lines += [ROS2MSG_SEPARATOR, f"MSG: {name.replace('.', '/')}",
                  f"# {schema['title']}: {schema['description']}", *_ros2msg_lines(schema)]
    return ("\n".join(lines) + "\n").encode()


def _template(fields: tuple[str, ...]) -> str:
    """A %-format string for a payload {t, fields...} of finite Python floats (%r = repr). t takes %s: a
    float formats as its repr there too (str(float) is repr(float)), or it is given as that text already
    (Recorder._write_finite_block formats a row's t once for its six messages)."""
    return "{" + ",".join([f"{json.dumps('t')}:%s", *(f"{json.dumps(k)}:%r" for k in fields)]) + "}"


def _dumps(payload: Any) -> bytes:
    """Compact, standard JSON (no NaN/Infinity literals)."""
    return json.dumps(payload, allow_nan=False, separators=(",", ":")).encode()


def _slow_payload(fields: tuple[str, ...], values: list[float]) -> bytes:
    """Payload of a row with non-finite values: those are left out and listed in "nonfinite"
    (JSON has no inf/nan, and an absent field is a gap in a Foxglove plot)."""
    payload: dict[str, Any] = {"t": values[0]}
    nonfinite = {}
    for name, v in zip(fields, values[1:], strict=True):
        if math.isfinite(v):
            payload[name] = v
        else:
            nonfinite[name] = "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    payload[NONFINITE_KEY] = nonfinite
    return _dumps(payload)


def jsonable(value: Any, where: str = "value") -> Any:
    """`value` as plain JSON data: numpy scalars and arrays become numbers and lists,
    tuples become lists, non-finite floats become None. Raises ValueError naming
    `where` for anything else (sets, objects, non-string keys)."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (np.bool_,)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist(), where)
    if isinstance(value, (list, tuple)):
        return [jsonable(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise ValueError(f"{where} has a non-string key {k!r}; JSON needs string keys")
            out[k] = jsonable(v, f"{where}[{k!r}]")
        return out
    raise ValueError(f"{where} is a {type(value).__name__} ({value!r}), "
                     f"expected a number, string, bool, None, list or dict")


def _ns(t: float) -> int:
    """Simulation time [s] -> MCAP log time [ns] (uint64)."""
    if not (math.isfinite(t) and t >= 0):
        raise ValueError(f"log times must be finite and >= 0 s, got t={t!r}")
    return round(t * _NS_PER_S)


def _whole(method):
    """A stop signal waits until the method is done (adaptive_mj.sim.interrupt.deferred)."""
    @functools.wraps(method)
    def whole(*args, **kwargs):
        with deferred():
            return method(*args, **kwargs)

    return whole


class Recorder:
    """Writes one run to an MCAP file at `path`; implements `loop.Sink`.

    path: the log's file, written in place (created, or truncated if it exists:
    the caller picks the path and reserves it, see runner.reserve_log_path).
    header: what the run is (see LogHeader); written first and flushed, so even
    a run killed before its first row leaves a readable log.
    flush_every_rows: besides the flush at the end of every write_rows call,
    also flush after every this many logged rows inside a call (bounds the loss
    for callers that pass long blocks). None: only at the end of each call.

    Use as a context manager: leaving the block closes the log, with status
    "interrupted" after a KeyboardInterrupt, "failed" after any other
    exception, and "ok" otherwise; call close() yourself to record the
    run's real status and summary.
    """

    @_whole
    def __init__(self, path: str | os.PathLike, header: LogHeader, *,
                 flush_every_rows: int | None = None):
        _check_header(header)
        every: object = flush_every_rows  # checked as any value (annotations are not enforced at run time)
        if every is not None and (not isinstance(every, int) or every < 1):
            raise ValueError(f"flush_every_rows must be an int >= 1 or None, "
                             f"got {flush_every_rows!r}")
        self.path = os.fspath(path)
        self.header = header
        self.log_every = header.log_every
        self.order = int(header.order)
        self.names = tuple(header.param_names)
        self.joint_names = tuple(header.joint_names)
        self.joint_shape = (len(self.joint_names),) if self.joint_names else ()
        self.control_names, self.state_names = tuple(header.control_names), tuple(header.state_names)
        self.control_shape = (len(self.control_names),) if self.control_names else self.joint_shape
        self._flush_every = flush_every_rows
        self._next_k = 0          # first global step index not yet seen
        self._rows = 0            # logged rows written
        self._t_last = 0.0        # latest simulation time written [s]
        self._closed = False

        self.encoding = header.encoding
        self.format_version = LOG_FORMAT_VERSION if header.encoding == "cdr" else JSON_LOG_FORMAT_VERSION
        self._file = open(self.path, "wb")
        try:
            self._writer = Writer(self._file, compression=CompressionType.ZSTD)
            self._writer.start(library=f"adaptive_mj log format {self.format_version}; "
                                       f"{LIBRARY_IDENTIFIER}")
            self._write_header()
            self._writer.flush()
        except BaseException:
            self._file.close()
            raise

    # -- header -------------------------------------------------------------

    def _write_header(self) -> None:
        h = self.header
        self._channels: dict[str, int] = {}
        cdr = self.encoding == "cdr"
        schemas = _schemas(self.order, self.names, self.joint_names, self.control_names, self.state_names,
                           close_statuses(self.format_version))
        fields = row_fields(self.order, self.names, self.joint_names, self.control_names, self.state_names)
        if cdr:  # format 8: the six row topics' parts in one /row message
            schema_id = self._writer.register_schema(ROW_SCHEMA_NAME, "ros2msg", _ros2msg_row(schemas))
            self._channels[ROW_TOPIC] = self._writer.register_channel(ROW_TOPIC, "cdr", schema_id)
        for topic, (name, schema) in schemas.items():
            if cdr and topic in ROW_TOPICS:
                continue
            schema_id = self._writer.register_schema(
                name, "jsonschema", json.dumps(schema, separators=(",", ":")).encode())
            self._channels[topic] = self._writer.register_channel(topic, "json", schema_id)
        # JSON (format 6): a row is six messages, one per row topic (channel id, the topic's fields)
        self._row_fields = [] if cdr else [(self._channels[topic], fields[topic]) for topic in ROW_TOPICS]
        self._templates = [_template(fields) for _, fields in self._row_fields]
        self._row_template: str | None = None  # the templates joined (_write_finite_block)
        # CDR (format 8): a row is one message, the 4-byte encapsulation header, then t and every part's fields as
        # little-endian float64 (8-aligned counted from after the header: no padding between float64s)
        self._row_width = sum(len(fields[topic]) for topic in ROW_TOPICS)  # float64 a row but t
        self._row_records: np.ndarray | None = None  # a row's message as written but for t, its values and times
        if cdr:
            payload = np.dtype([("cdr", "u1", (4,)), ("values", "<f8", (1 + self._row_width,))])
            self._row_records = _message_rows([self._channels[ROW_TOPIC]], [payload])
            self._row_records["p0"]["cdr"] = np.frombuffer(CDR_HEADER, dtype=np.uint8)

        meta = {
            "log_format_version": str(self.format_version),
            "scenario_name": h.scenario_name,
            "scenario_source": h.scenario_source,
            "seed": str(int(h.seed)),
            "log_rate_hz": repr(float(h.log_rate_hz)),
            "log_every": str(self.log_every),
            "dt": repr(float(h.dt)),
            "order": str(self.order),
            "param_names": json.dumps(list(self.names)),
            "overrides": json.dumps(list(h.overrides)),
            "joint_names": json.dumps(list(self.joint_names)),
            "control_names": json.dumps(list(self.control_names)),
            "state_names": json.dumps(list(self.state_names)),
            "notes": json.dumps(list(h.notes)),
            "law_plugin": json.dumps(h.law_plugin),
            "plant_plugin": json.dumps(h.plant_plugin),
            "control_mode": h.control_mode,
            "control_period": repr(float(h.control_period or h.dt)),
            "ctrl_range": json.dumps(h.ctrl_range),
            "joint_limits": json.dumps(_finite_or_null(h.joint_limits)),
            "embedded_sha256": embedded_digest(h.model_xml, h.model_source, h.model_assets),
            "created_unix": repr(float(h.created_unix)),
            "law_evaluation": h.law_evaluation,
        }
        if cdr:
            meta["encoding"] = "cdr"  # formats 7 and 8: the rows' message encoding
        meta.update({VERSION_KEY_PREFIX + k: v for k, v in sorted(h.versions.items())})
        self._writer.add_metadata(HEADER_METADATA, meta)
        self._writer.add_metadata(SCENARIO_METADATA, {"text": h.scenario_text})
        if h.model_xml is not None:
            self._writer.add_attachment(0, 0, MODEL_XML_ATTACHMENT, "application/xml",
                                        h.model_xml.encode())
        if h.model_source is not None:
            self._writer.add_attachment(0, 0, MODEL_SOURCE_ATTACHMENT, "application/xml",
                                        h.model_source.encode())
        for name, data in sorted(h.model_assets.items()):
            self._writer.add_attachment(0, 0, ASSET_ATTACHMENT_PREFIX + name,
                                        "application/octet-stream", bytes(data))

    # -- loop.Sink ------------------------------------------------------------

    @_whole
    def write_rows(self, k0, t, x, u, s, ref, theta_hat, theta, V) -> None:
        """Log the kept rows of a block of consecutive physics steps k0, k0+1, ...

        t: (N,) [s]; x: (N, n); u, s: (N,); ref: (N, n+1) (m joints: x (N, n, m), u, s
        (N, m), ref (N, n+1, m)); theta_hat, theta: (N, n_theta); V: (N,). Rows with k % log_every == 0
        are written; the file is flushed before returning.
        """
        self._check_open()
        k0 = int(k0)
        if k0 < self._next_k:
            raise ValueError(f"write_rows: rows must come in order; got k0={k0} after "
                             f"step {self._next_k - 1} was written")
        t = np.asarray(t, dtype=float)
        if t.ndim != 1:
            raise ValueError(f"write_rows: t has shape {t.shape}, expected (N,)")
        n = t.shape[0]
        js = self.joint_shape
        cols = {"x": (x, (n, self.order) + js), "u": (u, (n,) + self.control_shape), "s": (s, (n,) + js),
                "ref": (ref, (n, self.order + 1) + js), "theta_hat": (theta_hat, (n, len(self.names))),
                "theta": (theta, (n, len(self.names))), "V": (V, (n,))}
        arrays = {}
        for name, (value, shape) in cols.items():
            a = np.asarray(value, dtype=float)
            if a.shape != shape:
                raise ValueError(f"write_rows: {name} has shape {a.shape}, expected {shape} "
                                 f"(t has shape {t.shape}, order {self.order}, "
                                 f"params {self.names})")
            arrays[name] = a
        self._next_k = k0 + n
        keep = slice((-k0) % self.log_every, n, self.log_every)
        tk = t[keep]
        if tk.size:
            if not (np.all(np.isfinite(tk)) and tk.min() >= 0):
                raise ValueError("write_rows: times must be finite and >= 0 s")
            x, ref = arrays["x"][keep], arrays["ref"][keep]
            u, s = arrays["u"][keep], arrays["s"][keep]
            m = len(tk)
            blocks = [x.reshape(m, -1), ref.reshape(m, -1),
                      np.column_stack([u.reshape(m, -1), s.reshape(m, -1), (ref[:, 0] - x[:, 0]).reshape(m, -1)]),
                      arrays["theta_hat"][keep], arrays["theta"][keep], arrays["V"][keep, None]]
            self._write_block(tk, blocks)
        self._writer.flush()

    def _write_block(self, tk: np.ndarray, blocks: list[np.ndarray]) -> None:
        ns = np.rint(tk * _NS_PER_S).astype(np.int64)
        if self.encoding == "cdr":
            self._write_cdr_block(tk, ns, blocks)
            return
        if self._flush_every is None and all(np.isfinite(b).all() for b in blocks):
            self._write_finite_block(tk, ns, blocks)
            return
        log_ns = ns.tolist()
        t_list = tk.tolist()
        rows = [b.tolist() for b in blocks]
        finite = [np.isfinite(b).all(axis=1).tolist() for b in blocks]
        channels = self._row_fields
        templates = self._templates
        batch: list[tuple[int, int, bytes]] = []
        for i, (ti, ns) in enumerate(zip(t_list, log_ns, strict=True)):
            for j, (channel_id, fields) in enumerate(channels):
                values = rows[j][i]
                if finite[j][i]:
                    data = (templates[j] % (ti, *values)).encode()
                else:
                    data = _slow_payload(fields, [ti, *values])
                batch.append((channel_id, ns, data))
            self._rows += 1
            if self._flush_every is not None and self._rows % self._flush_every == 0:
                _add_messages(self._writer, batch)
                batch = []
                self._writer.flush()
        _add_messages(self._writer, batch)
        self._t_last = max(self._t_last, t_list[-1])

    def _write_finite_block(self, tk: np.ndarray, log_ns: np.ndarray, blocks: list[np.ndarray]) -> None:
        """_write_block's payloads for rows of finite numbers, formatted in one %-operation for the whole
        block: every row's messages are the row templates joined by NUL bytes (which no template or float
        repr contains), repeated per row, and the text goes to fast_mcap.add_rows, which splits it into
        messages. A row's t is formatted once for its six messages. The same bytes as one template per
        message, at a fifth of the cost (the per-message Python work was most of a logged run's logging
        time); 100 rows of the heave vehicle: 1.72-1.83 -> 1.46-1.61 ms with add_rows and t once."""
        m = len(tk)
        values = np.hstack([np.column_stack([tk, b]) for b in blocks]).ravel().tolist()
        width = len(values) // m  # numbers per row, each topic's t first
        t_text = list(map(repr, tk.tolist()))  # a row's t formatted once, for its six messages
        for first in self._t_columns(blocks):
            values[first::width] = t_text
        if self._row_template is None:
            self._row_template = "\0".join(self._templates)
        text = "\0".join([self._row_template] * m) % tuple(values)
        _add_rows(self._writer, [channel_id for channel_id, _ in self._row_fields], log_ns, text.encode())
        self._rows += m
        self._t_last = max(self._t_last, float(tk[-1]))

    def _write_cdr_block(self, tk: np.ndarray, log_ns: np.ndarray, blocks: list[np.ndarray]) -> None:
        """Format 8: the block's rows as one packed record array (fast_mcap.message_rows: each row's one /row
        Message record, head and CDR payload), filled by numpy (the encapsulation header is the template's; t, then
        each part's columns side by side: blocks[j] (m, width_j) in ROW_TOPICS' order) and written in one go;
        non-finite values are float64 like any other. tk: (m,) [s]; log_ns: (m,) [ns]. With flush_every_rows, the
        block is cut where the count of rows written reaches a multiple of it."""
        m, start = len(tk), 0
        channel_ids = [self._channels[ROW_TOPIC]]
        assert self._row_records is not None  # set for "cdr" in _write_header
        row = np.hstack([tk[:, None], *blocks])  # (m, 1 + row width): a row's payload after its header
        while start < m:
            every = self._flush_every
            end = m if every is None else min(m, start + every - self._rows % every)
            records = np.repeat(self._row_records, end - start)  # the heads and CDR headers, as written
            records["p0"]["values"] = row[start:end]
            _add_packed_rows(self._writer, channel_ids, log_ns[start:end], records)
            self._rows += end - start
            if every is not None and self._rows % every == 0:
                self._writer.flush()
            start = end
        self._t_last = max(self._t_last, float(tk[-1]))

    @staticmethod
    def _t_columns(blocks: list[np.ndarray]) -> list[int]:
        """Where each topic's t stands in a row of _write_finite_block's values (t, then the topic's columns)."""
        firsts, at = [], 0
        for b in blocks:
            firsts.append(at)
            at += 1 + b.shape[1]
        return firsts

    @_whole
    def write_event(self, t: float, label: str, **detail) -> None:
        """Log an event applied at simulation time t [s]; detail: extra JSON-able fields.
        Written with the next flush (the end of the next write_rows call, or close)."""
        self._check_open()
        t = float(t)
        ns = _ns(t)
        payload = {"t": t, "label": str(label)}
        payload.update(jsonable(detail, "write_event detail"))
        self._writer.add_message(self._channels[EVENT_TOPIC], ns, _dumps(payload), ns)
        self._t_last = max(self._t_last, t)

    # -- closing --------------------------------------------------------------

    @_whole
    def close(self, status: str, reason: str = "",
              summary: Mapping[str, Any] | None = None) -> None:
        """Write /summary ({...summary, status, reason}) and the "status" metadata,
        then finish the file (summary section and footer). status: one of CLOSE_STATUSES ("crashed" is written
        "failed" in a format before 9, the JSON encoding's: status_written; the reason must then say it crashed)."""
        self._check_open()
        if status not in CLOSE_STATUSES:
            raise ValueError(f"close: status must be one of {CLOSE_STATUSES}, got {status!r}")
        payload = jsonable(dict(summary or {}), "close summary")
        for key, value in (("status", status), ("reason", str(reason))):
            if key in payload and payload[key] != value:
                raise ValueError(f"close: summary[{key!r}] = {payload[key]!r} disagrees with "
                                 f"the {key} argument {value!r}")
            payload[key] = value
        payload["status"] = status = str(status_written(status, self.format_version))
        ns = _ns(self._t_last)
        self._writer.add_message(self._channels[SUMMARY_TOPIC], ns, _dumps(payload), ns)
        self._writer.flush()
        self._writer.add_metadata(STATUS_METADATA, {"status": status, "reason": str(reason)})
        self._writer.finish()
        self._closed = True
        self._file.close()

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def rows_written(self) -> int:
        """Logged rows written so far."""
        return self._rows

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"{self.path}: the log is already closed")

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._closed:
            return
        if exc_type is None:
            self.close("ok", "", {})
            return
        status = Status.INTERRUPTED if issubclass(exc_type, KeyboardInterrupt) else Status.FAILED
        try:
            self.close(status, f"{exc_type.__name__}: {exc}", {})
        except Exception:
            # The original exception matters more; the file keeps its flushed prefix.
            self._file.close()


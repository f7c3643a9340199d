"""MCAP run log: Recorder writes, read_log reads back, bit for bit, whole or cut."""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer

from adaptive_mj.log import record
from adaptive_mj.errors import LogFormatError
from adaptive_mj.log.record import LogHeader, Recorder
from adaptive_mj.log.replay import JsonDecoderFactory, read_log

DT = 0.001          # physics step [s]
RATE = 100.0        # logging rate [Hz]
LOG_EVERY = 10      # = round(1 / (RATE * DT))
NAMES = ("d", "b", "c")
ROW_TOPICS = ("/state", "/reference", "/control", "/estimates", "/true_params", "/lyapunov")


def make_header(*, order: int = 2, names=NAMES, model: bool = True, **kw) -> LogHeader:
    fields = dict(
        scenario_name="heave_tracking",
        scenario_text='name = "heave_tracking"\n[law]\ngamma = 2.0\n',
        scenario_source="scenarios/heave_tracking.toml",
        overrides=("law.gamma=2.0", "duration=5"),
        seed=7,
        log_rate_hz=RATE,
        dt=DT,
        order=order,
        param_names=tuple(names),
        model_xml="<mujoco model='saved'/>" if model else None,
        model_source="<mujoco model='source'/>" if model else None,
        model_assets={"mesh.stl": b"\x00\x01binary\xff"} if model else {},
        versions={"adaptive_mj": "0.1.0", "mujoco": "3.17.0", "mcap": "1.6.0"},
        created_unix=1_700_000_000.25,
    )
    fields.update(kw)
    return LogHeader(**fields)


def synthetic(n: int, *, order: int = 2, n_theta: int = 3, seed: int = 0) -> dict:
    """n physics steps of plausible rows with full-precision floats."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    x = np.column_stack([np.sin(t + j) + 1e-3 * rng.standard_normal(n) for j in range(order)])
    ref = np.column_stack([np.sin(t + j) for j in range(order + 1)])
    s = 1e-2 * rng.standard_normal(n)
    theta_hat = np.column_stack([1 + 0.1 * np.sin(t * (j + 1)) + 1e-4 * rng.standard_normal(n)
                                 for j in range(n_theta)])
    return dict(t=t, x=x, u=10 * np.cos(t) + rng.standard_normal(n), s=s, ref=ref,
                theta_hat=theta_hat, theta=np.tile(np.arange(1.0, n_theta + 1) * 0.7, (n, 1)),
                V=0.5 * s**2 + rng.random(n))


def write_block(rec: Recorder, rows: dict, k0: int, k1: int) -> None:
    sl = slice(k0, k1)
    rec.write_rows(k0, rows["t"][sl], rows["x"][sl], rows["u"][sl], rows["s"][sl],
                   rows["ref"][sl], rows["theta_hat"][sl], rows["theta"][sl], rows["V"][sl])


def write_log(path, rows: dict, *, block: int = 1000, close: bool = True, header=None,
              events=((0.5, "payload swap", {"mass": 2.5}), (2.0, "gust", {}))) -> Recorder:
    n = len(rows["t"])
    rec = Recorder(path, header or make_header(order=rows["x"].shape[1],
                                               names=NAMES[:rows["theta"].shape[1]]))
    pending = sorted(events)
    for k0 in range(0, n, block):
        while pending and pending[0][0] <= rows["t"][k0]:
            t_e, label, detail = pending.pop(0)
            rec.write_event(t_e, label, **detail)
        write_block(rec, rows, k0, min(n, k0 + block))
    if close:
        rec.close("ok", "", {"rmse_y": 0.0123, "n_rows": rec.rows_written})
    return rec


def assert_rows_equal(traj, rows: dict, keep) -> None:
    assert np.array_equal(traj.t, rows["t"][keep])
    assert np.array_equal(traj.x, rows["x"][keep])
    assert np.array_equal(traj.u, rows["u"][keep])
    assert np.array_equal(traj.s, rows["s"][keep])
    assert np.array_equal(traj.ref, rows["ref"][keep])
    assert np.array_equal(traj.theta_hat, rows["theta_hat"][keep])
    assert np.array_equal(traj.theta, rows["theta"][keep])
    assert np.array_equal(traj.V, rows["V"][keep])


@pytest.fixture
def full_log(tmp_path):
    rows = synthetic(5000)
    path = tmp_path / "run.mcap"
    write_log(path, rows)
    return path, rows


# -- round trip ---------------------------------------------------------------------------------

def test_round_trip_is_exact(full_log):
    path, rows = full_log
    run = read_log(path)
    assert run.status == "ok" and run.note == ""
    assert run.recovered_rows == 500
    traj = run.trajectory
    assert_rows_equal(traj, rows, slice(0, None, LOG_EVERY))
    assert traj.names == NAMES
    assert traj.status == "ok" and traj.reason == ""
    assert traj.meta["dt"] == DT and traj.meta["order"] == 2 and traj.meta["log_every"] == LOG_EVERY
    assert run.summary == {"rmse_y": 0.0123, "n_rows": 500, "status": "ok", "reason": ""}


def test_header_metadata_and_model_round_trip(full_log):
    path, _ = full_log
    run = read_log(path)
    h = make_header()
    assert run.header["log_format_version"] == record.LOG_FORMAT_VERSION
    assert run.header["scenario_name"] == h.scenario_name
    assert run.header["scenario_source"] == h.scenario_source
    assert run.header["seed"] == 7 and run.header["order"] == 2
    assert run.header["dt"] == DT and run.header["log_rate_hz"] == RATE
    assert run.header["log_every"] == LOG_EVERY
    assert run.header["param_names"] == list(NAMES)
    assert run.header["created_unix"] == h.created_unix
    assert run.header["versions"] == h.versions
    assert run.scenario_text == h.scenario_text
    assert run.overrides == h.overrides
    assert run.model_xml == h.model_xml and run.model_source == h.model_source
    assert run.model_assets == h.model_assets


def test_events_round_trip(full_log):
    path, _ = full_log
    run = read_log(path)
    assert run.events == [{"t": 0.5, "label": "payload swap", "mass": 2.5},
                          {"t": 2.0, "label": "gust"}]
    assert run.trajectory.meta["events"] == [(0.5, "payload swap"), (2.0, "gust")]


@pytest.mark.parametrize("block", [333, 1000, 7])
def test_decimation_keeps_global_steps_divisible_by_log_every(tmp_path, block):
    rows = synthetic(2500)
    path = tmp_path / "run.mcap"
    write_log(path, rows, block=block, events=())
    traj = read_log(path).trajectory
    k = np.flatnonzero(np.isin(rows["t"], traj.t))
    assert np.array_equal(k, np.arange(0, 2500, LOG_EVERY))
    assert_rows_equal(traj, rows, slice(0, None, LOG_EVERY))


def test_log_every_follows_rate_and_step():
    assert make_header(log_rate_hz=100.0, dt=0.001).log_every == 10
    assert make_header(log_rate_hz=2000.0, dt=0.001).log_every == 1
    assert make_header(log_rate_hz=30.0, dt=0.002).log_every == 17


def test_first_order_log(tmp_path):
    rows = synthetic(3000, order=1, n_theta=2)
    path = tmp_path / "first.mcap"
    write_log(path, rows, events=())
    run = read_log(path)
    assert run.status == "ok"
    assert run.trajectory.x.shape == (300, 1) and run.trajectory.ref.shape == (300, 2)
    assert run.trajectory.names == ("d", "b")
    assert_rows_equal(run.trajectory, rows, slice(0, None, LOG_EVERY))


@pytest.mark.parametrize("encoding", ["cdr", "json"])
def test_non_finite_values_round_trip(tmp_path, encoding):
    rows = synthetic(100)
    rows["u"][50] = math.inf
    rows["V"][50] = math.nan
    rows["theta_hat"][60, 1] = -math.inf
    path = tmp_path / "diverged.mcap"
    rec = Recorder(path, make_header(encoding=encoding))
    write_block(rec, rows, 0, 100)
    rec.close("diverged", "non-finite control inf", {"rmse_y": float("nan")})
    run = read_log(path)
    assert run.status == "diverged" and run.trajectory.reason == "non-finite control inf"
    traj = run.trajectory
    assert traj.u[5] == math.inf and math.isnan(traj.V[5]) and traj.theta_hat[6, 1] == -math.inf
    assert np.array_equal(traj.u, rows["u"][::LOG_EVERY])
    assert np.array_equal(traj.V, rows["V"][::LOG_EVERY], equal_nan=True)
    assert run.summary["rmse_y"] is None      # non-finite summary values become null
    y_tilde = rows["ref"][50, 0] - rows["x"][50, 0]
    if encoding == "json":
        with open(path, "rb") as f:
            control = [m.data for _, _, m in make_reader(f).iter_messages("/control")]
        assert json.loads(control[5]) == {"t": 0.05, "s": rows["s"][50], "y_tilde": y_tilde,
                                          "nonfinite": {"u": "inf"}}
    else:  # CDR (format 8, one /row message a row): the float64 themselves, inf and NaN included
        with open(path, "rb") as f:
            data = [m.data for _, _, m in make_reader(f).iter_messages("/row")]
        values = np.frombuffer(data[5][4:], "<f8")  # t, state 2, reference 3, control 3, estimates 3, true 3, V
        assert data[5][:4] == record.CDR_HEADER and len(values) == 1 + 2 + 3 + 3 + 3 + 3 + 1
        assert values[6:9].tobytes() == np.array([math.inf, rows["s"][50], y_tilde], "<f8").tobytes()
        assert values[0] == 0.05 and math.isnan(values[-1])
        assert np.frombuffer(data[6][4:], "<f8")[9 + 1] == -math.inf  # theta_hat[60, 1]


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(values=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=40, max_size=40))
def test_any_float_round_trips_bit_for_bit(tmp_path, values):
    rows = synthetic(40)
    v = np.array(values)
    rows["u"], rows["V"] = v, v[::-1].copy()
    rows["x"][:, 1] = v
    rows["theta_hat"][:, 2] = -v
    path = tmp_path / f"floats{len(list(tmp_path.iterdir()))}.mcap"
    rec = Recorder(path, make_header(log_rate_hz=1000.0))
    write_block(rec, rows, 0, 40)
    rec.close("ok", "", {})
    traj = read_log(path).trajectory
    for name in ("u", "V", "x", "theta_hat"):
        got, want = getattr(traj, name), rows[name]
        assert np.array_equal(got, want, equal_nan=True), name
        number = ~np.isnan(want)
        assert np.array_equal(np.signbit(got[number]), np.signbit(want[number])), name   # -0.0


def test_same_inputs_give_the_same_bytes(tmp_path):
    rows = synthetic(2000)
    write_log(tmp_path / "a.mcap", rows)
    write_log(tmp_path / "b.mcap", rows)
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def assert_foxglove_can_parse(schema: dict, where: str) -> None:
    """The subset of JSON Schema that Foxglove's parseJsonSchema accepts: an object with
    "properties", each property one "type" string; nested objects recurse."""
    assert schema["type"] == "object" and isinstance(schema["properties"], dict), where
    for name, prop in schema["properties"].items():
        assert prop["type"] in ("boolean", "string", "number", "integer", "object", "array"), \
            f"{where}.{name}: {prop['type']!r}"
        if prop["type"] == "object":
            assert_foxglove_can_parse(prop, f"{where}.{name}")


# -- what standard MCAP tools see ---------------------------------------------------------------

def test_json_channels_have_json_schemas(tmp_path):
    """log.encoding = "json": every channel JSON with a JSON Schema, written as format 6."""
    path = tmp_path / "json.mcap"
    write_log(path, synthetic(5000), header=make_header(encoding="json"))
    assert read_log(path).header["log_format_version"] == record.JSON_LOG_FORMAT_VERSION == 6
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
        summary = reader.get_summary()
        topics = {ch.topic: ch for ch in summary.channels.values()}
        assert set(topics) == {*ROW_TOPICS, "/events", "/summary"}
        first = {}
        for _schema, channel, message, decoded in reader.iter_decoded_messages():
            assert message.log_time == message.publish_time
            if "t" in decoded:
                assert message.log_time == round(decoded["t"] * 1e9)
            first.setdefault(channel.topic, decoded)
    for topic, channel in topics.items():
        assert channel.message_encoding == "json"
        schema = summary.schemas[channel.schema_id]
        assert schema.encoding == "jsonschema"
        body = json.loads(schema.data)
        assert_foxglove_can_parse(body, topic)
        assert set(body["required"]) <= set(first[topic])
        if not body["additionalProperties"]:
            assert set(first[topic]) <= set(body["properties"])
    estimates = json.loads(summary.schemas[topics["/estimates"].schema_id].data)
    assert set(estimates["properties"]) == {"t", *NAMES, "nonfinite"}
    assert set(first["/state"]) == {"t", "y", "y_dot"}
    assert set(first["/reference"]) == {"t", "y_d", "y_d_dot", "y_d_ddot"}
    assert set(first["/control"]) == {"t", "u", "s", "y_tilde"}
    assert set(first["/lyapunov"]) == {"t", "V"}
    assert summary.statistics.message_count == 500 * 6 + 2 + 1


SEPARATOR = "=" * 80
# Foxglove's ros2msg field-name rule (@foxglove/rosmsg buildRos2Type: "Invalid field name" otherwise), as ROS 2's
ROS2_FIELD = r"[a-z](?:_?[a-z0-9]+)*"


def parse_ros2msg(text: str) -> tuple[list[tuple[str, str]], dict[str, list[tuple[str, str]]]]:
    """(top-level fields, {MSG: type name -> its fields}) of a ros2msg text with dependent definitions, split as
    ROS 2 and Foxglove split it: a line of 80 "=" then "MSG: <name>" before each dependency; comments dropped;
    fields as (type, name)."""
    sections = text.split(SEPARATOR + "\n")
    top, deps = sections[0], {}
    def fields(body):
        out = []
        for line in body.splitlines():
            words = line.split("#")[0].split()
            if words and words[0] != "MSG:":
                assert len(words) == 2, line
                out.append((words[0], words[1]))
        return out
    for body in sections[1:]:
        head = body.splitlines()[0]
        assert head.startswith("MSG: "), head
        deps[head[len("MSG: "):]] = fields(body)
    return fields(top), deps


def test_cdr_rows_are_one_row_message_with_a_nested_ros2msg_schema(full_log):
    """Format 8 (the default): a row is one CDR message on /row whose ros2msg schema (adaptive_mj/msg/Row) is
    float64 t, then one sub-message per row topic, each type defined after a separator line and a MSG: line as ROS
    2 and Foxglove concatenate them; the payload is the header, t, then every part's float64 with no padding;
    /events and /summary stay JSON; the message count is a sixth of format 7's."""
    path, rows = full_log
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {ch.topic: ch for ch in summary.channels.values()}
        messages = [m for _, _, m in reader.iter_messages(topics=["/row"])]
    assert set(topics) == {"/row", "/events", "/summary"}
    channel = topics["/row"]
    schema = summary.schemas[channel.schema_id]
    assert (channel.message_encoding, schema.encoding, schema.name) == ("cdr", "ros2msg", "adaptive_mj/msg/Row")
    text = schema.data.decode()
    top, deps = parse_ros2msg(text)
    types = ["State", "Reference", "Control", "Estimates", "TrueParams", "Lyapunov"]
    assert top == [("float64", "t")] + [(f"adaptive_mj/{t}", part)
                                        for t, part in zip(types, record.ROW_PARTS, strict=True)]
    assert list(deps) == [f"adaptive_mj/{t}" for t in types]  # the names the fields' types give, exactly
    fields = record.row_fields(2, NAMES)
    for t, topic in zip(types, ROW_TOPICS, strict=True):
        want = [record.ros2msg_field(name) for name in fields[topic]]
        assert deps[f"adaptive_mj/{t}"] == [("float64", name) for name in want], t
    assert deps["adaptive_mj/Lyapunov"] == [("float64", "v")]  # V: ROS 2 field names are lower-case
    assert "float64 v  # Lyapunov function value (field V)" in text
    width = sum(len(f) for f in fields.values())
    assert len(messages) == 500 and all(len(m.data) == 4 + 8 * (1 + width) for m in messages)
    assert {m.data[:4] for m in messages} == {b"\x00\x01\x00\x00"}
    first = np.frombuffer(messages[0].data[4:], "<f8")
    assert first[0] == 0.0 and first[1:3].tolist() == rows["x"][0].tolist()
    assert first[-1] == rows["V"][0] and first[-4:-1].tolist() == rows["theta"][0].tolist()
    assert [m.log_time for m in messages] == [round(t * 1e9) for t in rows["t"][::LOG_EVERY]]
    for topic in ("/events", "/summary"):
        assert topics[topic].message_encoding == "json"
        assert summary.schemas[topics[topic].schema_id].encoding == "jsonschema"
    assert summary.statistics.message_count == 500 + 2 + 1


def test_format8_is_at_most_half_the_size_of_format6_json(tmp_path):
    """The same 2000 synthetic heave rows (full-precision floats, 20 s at 100 Hz): format 8 (one /row message a row)
    is at most half the file of format 6 JSON (measured: 248 402 against 533 176 bytes; format 7's six CDR topics
    were 452 330), and its MCAP message index holds one 16-byte entry a row."""
    import io

    from mcap.records import MessageIndex
    from mcap.stream_reader import StreamReader

    rows = synthetic(20000)
    sizes, entries = {}, {}
    for encoding in ("cdr", "json"):
        path = tmp_path / f"{encoding}.mcap"
        write_log(path, rows, header=make_header(encoding=encoding), events=())
        data = path.read_bytes()
        sizes[encoding] = len(data)
        entries[encoding] = sum(len(r.records) for r in StreamReader(io.BytesIO(data)).records
                                if isinstance(r, MessageIndex))
    assert sizes["cdr"] <= 0.5 * sizes["json"], sizes
    assert entries == {"cdr": 2000 + 1, "json": 6 * 2000 + 1}  # the rows and the /summary message


def test_ros2msg_field_names_are_ros2_field_names():
    """Every name ros2msg_field gives matches ROS 2's and Foxglove's field-name rule (lower case, single
    underscores between runs, a letter first)."""
    import re

    cases = {"payload/body.m": "payload_body_m", "shoulder_pan.armature": "shoulder_pan_armature",
             "Jxx": "jxx", "V": "v", "2nd": "f_2nd", "a__b_": "a_b", "_x": "x", "": "f", "__": "f",
             "payload/body.Ixx": "payload_body_ixx", "q_tilde_elbow-1": "q_tilde_elbow_1"}
    for name, want in cases.items():
        assert record.ros2msg_field(name) == want, name
        assert re.fullmatch(ROS2_FIELD, want), want
    schema = "\n".join(record._ros2msg_lines(record._schemas(2, ("a.b", "a/b", "J", "j"))["/estimates"][1]))
    assert "float64 a_b  #" in schema and "float64 a_b_2  #" in schema and "(field a/b)" in schema
    assert "float64 j  # estimate of J (field J)" in schema and "float64 j_2  # estimate of j" in schema


def test_metadata_and_attachments_present(full_log):
    path, _ = full_log
    with open(path, "rb") as f:
        reader = make_reader(f)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        attachments = {a.name: a for a in reader.iter_attachments()}
    assert set(metadata) == {"adaptive_mj", "scenario", "status"}
    assert metadata["adaptive_mj"]["log_format_version"] == str(record.LOG_FORMAT_VERSION)
    assert metadata["adaptive_mj"]["log_every"] == "10"
    assert json.loads(metadata["adaptive_mj"]["param_names"]) == list(NAMES)
    assert metadata["adaptive_mj"]["version.mujoco"] == "3.17.0"
    assert metadata["status"] == {"status": "ok", "reason": ""}
    assert set(attachments) == {"model.xml", "model_source.xml", "asset/mesh.stl"}
    assert attachments["model.xml"].media_type == "application/xml"


def test_log_without_model(tmp_path):
    rows = synthetic(500)
    path = tmp_path / "nomodel.mcap"
    write_log(path, rows, header=make_header(model=False), events=())
    run = read_log(path)
    assert run.model_xml is None and run.model_source is None and run.model_assets == {}


# -- cut and killed logs ------------------------------------------------------------------------

def test_truncated_logs_recover_a_prefix(full_log, tmp_path):
    path, rows = full_log
    data = path.read_bytes()
    full = read_log(path).trajectory
    counts = []
    for tenth in range(1, 10):
        cut = tmp_path / f"cut{tenth}.mcap"
        cut.write_bytes(data[:len(data) * tenth // 10])
        run = read_log(cut)
        assert run.status == "truncated" and run.trajectory.status == "truncated"
        assert run.summary is None
        n = run.recovered_rows
        assert len(run.trajectory) == n
        span = n * LOG_EVERY * DT
        assert run.note.startswith(f"recovered {n} rows ({span:.1f} s) of a truncated log")
        for name in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
            assert np.array_equal(getattr(run.trajectory, name), getattr(full, name)[:n])
        counts.append(n)
    assert counts == sorted(counts)
    assert counts[-1] >= 400 and counts[-1] > counts[0]


def test_killed_run_leaves_a_readable_prefix_after_every_block(tmp_path):
    rows = synthetic(4000)
    path = tmp_path / "live.mcap"
    rec = Recorder(path, make_header())
    snapshot = tmp_path / "snapshot.mcap"
    shutil.copyfile(path, snapshot)            # killed before the first row
    assert snapshot.stat().st_size > 0
    run = read_log(snapshot)
    assert run.status == "truncated" and run.recovered_rows == 0
    assert run.scenario_text == make_header().scenario_text
    for k0 in range(0, 4000, 1000):
        write_block(rec, rows, k0, k0 + 1000)
        shutil.copyfile(path, snapshot)        # what a SIGKILL right now would leave
        run = read_log(snapshot)
        assert run.status == "truncated"
        assert_rows_equal(run.trajectory, rows, slice(0, k0 + 1000, LOG_EVERY))
    rec.close("ok", "", {})


_KILLED_WRITER = textwrap.dedent("""
    import sys
    import numpy as np
    from adaptive_mj.log.record import LogHeader, Recorder
    path = sys.argv[1]
    header = LogHeader(scenario_name="killed", scenario_text="", scenario_source="", overrides=(),
                       seed=0, log_rate_hz=100.0, dt=0.001, order=2, param_names=("d", "b", "c"),
                       model_xml=None, model_source=None)
    rec = Recorder(path, header)
    for block in range(1000):
        k0 = 1000 * block
        t = (k0 + np.arange(1000)) * 0.001
        one = np.ones(1000)
        rec.write_rows(k0, t, np.column_stack([t, one]), t, t, np.column_stack([t, one, one]),
                       np.column_stack([t, t, t]), np.ones((1000, 3)), t)
        print(block + 1, flush=True)
        sys.stdin.readline()
""")


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs POSIX SIGKILL")
def test_sigkilled_process_leaves_every_written_block(tmp_path):
    path = tmp_path / "killed.mcap"
    with subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(path)],
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True) as proc:
        try:
            for _ in range(3):
                blocks = int(proc.stdout.readline())
                proc.stdin.write("\n")
                proc.stdin.flush()
            blocks = int(proc.stdout.readline())   # 4 blocks written; kill it mid-run
        finally:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    assert blocks == 4
    run = read_log(path)
    assert run.status == "truncated" and run.recovered_rows == 400
    assert np.array_equal(run.trajectory.t, np.arange(0, 4000, 10) * 0.001)
    assert run.note == "recovered 400 rows (4.0 s) of a truncated log " \
                       f"(the file ends at byte {path.stat().st_size} without a footer)"


@pytest.mark.parametrize("encoding", ["cdr", "json"])
def test_flush_every_rows_bounds_loss_inside_long_blocks(tmp_path, encoding):
    rows = synthetic(3000)
    path = tmp_path / "long.mcap"
    rec = Recorder(path, make_header(encoding=encoding), flush_every_rows=50)
    # Die in the middle of one long write_rows call (at row 120): flushed chunks survive.
    class Killed(BaseException):
        pass

    import adaptive_mj.log.record as record_mod

    original = record_mod._add_messages
    written = []

    def dying_add(writer, batch):  # rows go to the writer in batches of flush_every_rows
        if sum(written) + len(batch) // 6 > 120:
            raise Killed
        written.append(len(batch) // 6)
        return original(writer, batch)

    original_packed = record_mod._add_packed_rows

    def dying_add_packed(writer, channel_ids, log_ns, records):  # CDR: the same, a packed block at a time
        if sum(written) + len(log_ns) > 120:
            raise Killed
        written.append(len(log_ns))
        return original_packed(writer, channel_ids, log_ns, records)

    record_mod._add_messages, record_mod._add_packed_rows = dying_add, dying_add_packed
    try:
        with pytest.raises(Killed):
            write_block(rec, rows, 0, 3000)
    finally:
        record_mod._add_messages, record_mod._add_packed_rows = original, original_packed
    rec._file.close()
    run = read_log(path)
    assert run.status == "truncated" and run.recovered_rows == 100


def test_footer_missing_but_summary_written(full_log, tmp_path):
    path, rows = full_log
    data = path.read_bytes()
    cut = tmp_path / "nofooter.mcap"
    cut.write_bytes(data[:-20])
    run = read_log(cut)
    assert run.status == "ok" and run.recovered_rows == 500
    assert "footer is missing" in run.note


# -- context manager ----------------------------------------------------------------------------

@pytest.mark.parametrize("exc, status", [(KeyboardInterrupt, "interrupted"),
                                         (RuntimeError, "failed")])
def test_context_manager_records_how_the_run_ended(tmp_path, exc, status):
    rows = synthetic(1000)
    path = tmp_path / "cm.mcap"
    with pytest.raises(exc):
        with Recorder(path, make_header()) as rec:
            write_block(rec, rows, 0, 1000)
            raise exc("stop")
    run = read_log(path)
    assert run.status == status and run.recovered_rows == 100
    assert run.trajectory.reason == f"{exc.__name__}: stop"


def test_context_manager_closes_ok(tmp_path):
    rows = synthetic(1000)
    with Recorder(tmp_path / "cm.mcap", make_header()) as rec:
        write_block(rec, rows, 0, 1000)
    assert rec.closed and read_log(tmp_path / "cm.mcap").status == "ok"


def test_recorder_refuses_bad_use(tmp_path):
    path = tmp_path / "x.mcap"
    rec = Recorder(path, make_header())
    rows = synthetic(100)
    with pytest.raises(ValueError, match=r"x has shape \(100, 3\), expected \(100, 2\)"):
        rec.write_rows(0, rows["t"], np.zeros((100, 3)), rows["u"], rows["s"], rows["ref"],
                       rows["theta_hat"], rows["theta"], rows["V"])
    write_block(rec, rows, 0, 100)
    with pytest.raises(ValueError, match="rows must come in order"):
        write_block(rec, rows, 50, 100)
    with pytest.raises(ValueError, match="status must be one of"):
        rec.close("great", "", {})
    rec.close("ok", "", {})
    with pytest.raises(RuntimeError, match="already closed"):
        write_block(rec, rows, 0, 100)
    with pytest.raises(ValueError, match="param_names"):
        Recorder(tmp_path / "y.mcap", make_header(param_names=("t", "b")))
    assert not (tmp_path / "y.mcap").exists()


# -- unreadable files ---------------------------------------------------------------------------

def test_zero_byte_file(tmp_path):
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    with pytest.raises(LogFormatError, match=r"empty\.mcap: empty file \(0 bytes\)"):
        read_log(path)


def test_non_mcap_file(tmp_path):
    path = tmp_path / "notes.mcap"
    path.write_text("name = 'not a log'\n")
    with pytest.raises(LogFormatError, match=r"notes\.mcap: not an MCAP file"):
        read_log(path)


def test_mcap_from_another_tool(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(library="someone-else")
        sid = w.register_schema("S", "jsonschema", b"{}")
        cid = w.register_channel("/x", "json", sid)
        w.add_message(cid, 0, b"{}", 0)
        w.finish()
    with pytest.raises(LogFormatError,
                       match=r"other\.mcap: MCAP file without 'adaptive_mj' metadata"
                             r".*someone-else"):
        read_log(path)


def test_newer_log_format(tmp_path, monkeypatch):
    monkeypatch.setattr(record, "LOG_FORMAT_VERSION", record.LOG_FORMAT_VERSION + 1)
    path = tmp_path / "future.mcap"
    write_log(path, synthetic(200), events=())
    monkeypatch.undo()
    newer = record.LOG_FORMAT_VERSION + 1
    with pytest.raises(LogFormatError, match=rf"future\.mcap: log format version {newer} is newer"):
        read_log(path)


def _chunk_offsets(path) -> list[int]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes)


def _break_crc(data: bytearray, chunk_offset: int) -> None:
    crc_at = chunk_offset + 9 + 8 + 8 + 8       # opcode, length, start, end, uncompressed size
    (crc,) = struct.unpack_from("<I", data, crc_at)
    struct.pack_into("<I", data, crc_at, crc ^ 0xFFFF)


def test_crc_mismatch_in_first_chunk_is_unrecoverable(full_log, tmp_path):
    path, _ = full_log
    data = bytearray(path.read_bytes())
    _break_crc(data, _chunk_offsets(path)[0])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match=r"bad\.mcap: a damaged chunk at byte \d+ \(crc "
                                             r"validation failed.*nothing to recover"):
        read_log(bad)


def test_crc_mismatch_later_recovers_the_rows_before_it(full_log, tmp_path):
    path, rows = full_log
    data = bytearray(path.read_bytes())
    offsets = _chunk_offsets(path)
    _break_crc(data, offsets[2])
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    run = read_log(bad)
    assert run.status == "truncated" and run.recovered_rows == 200
    assert run.note.startswith(
        f"recovered 200 rows (2.0 s) before a damaged chunk at byte {offsets[2]}")
    assert_rows_equal(run.trajectory, rows, slice(0, 2000, LOG_EVERY))
    assert run.summary is None
    assert run.note.endswith("; the run itself ended with status 'ok'")   # later chunk intact
    assert run.events == [{"t": 0.5, "label": "payload swap", "mass": 2.5}]


def test_no_input_bytes_escape_as_another_exception(tmp_path):
    rows = synthetic(300)
    path = tmp_path / "small.mcap"
    write_log(path, rows, block=100)
    data = path.read_bytes()
    rng = np.random.default_rng(1)
    probe = tmp_path / "probe.mcap"
    cases = [data[:n] for n in range(0, len(data), 13)]
    for _ in range(300):
        mutated = bytearray(data)
        for at in rng.integers(0, len(data), size=rng.integers(1, 4)):
            mutated[at] = int(rng.integers(0, 256))
        cases.append(bytes(mutated))
    cases += [b"\x89MCAP0\r\n", b"\x89MCAP0\r\n" + bytes(100), b"\x89MCAP0\r\n" + b"\xff" * 64]
    for case in cases:
        probe.write_bytes(case)
        try:
            run = read_log(probe)
        except LogFormatError as e:
            assert "probe.mcap" in str(e) and "\n" not in str(e)
        else:
            assert run.status in ("ok", "truncated")
            assert len(run.trajectory) == run.recovered_rows


# -- fuzzing the reader on a real run's log (hypothesis) --------------------------------------------

@pytest.fixture(scope="module")
def real_log(tmp_path_factory):
    """A 3 s log of a real run: the MuJoCo heave vehicle with sensor noise (model attached)."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.runs.runner import execute

    path = tmp_path_factory.mktemp("real") / "heave.mcap"
    scn = sc.load(sc.SCENARIOS_DIR / "heave_tracking.toml",
                  overrides=["simulation.duration=3.0", "noise.std={y=0.001, y_dot=0.01}"])
    execute(scn, log_path=path)
    return path, path.read_bytes(), read_log(path)


def _check_readable_or_refused(path, data: bytes, full) -> None:
    """read_log either refuses the bytes with a one-line LogFormatError naming the file, or
    returns a consistent run whose rows, when the log's own, are a prefix of the real ones."""
    path.write_bytes(data)
    try:
        run = read_log(path)
    except LogFormatError as e:
        assert str(e).startswith(f"{path}: ") and "\n" not in str(e)
        return
    assert run.status in ("ok", "diverged", "interrupted", "failed", "truncated")
    assert len(run.trajectory) == run.recovered_rows and run.trajectory.status == run.status
    if run.status == "truncated":
        assert run.summary is None and run.note.startswith(f"recovered {run.recovered_rows} rows (")


def _rows_start(data: bytes) -> int:
    """Where the records after the header, metadata and attachments (the model) begin: the rows' first chunk."""
    import io

    from mcap.records import Attachment, Metadata
    from mcap.stream_reader import StreamReader

    stream = io.BytesIO(data)
    end = 0
    for r in StreamReader(stream, emit_chunks=True).records:
        if not isinstance(r, (Attachment, Metadata)) and end:
            return end
        end = stream.tell()
    raise AssertionError("no record after the attachments")


def test_real_log_cut_at_every_tenth_recovers_a_growing_prefix(real_log, tmp_path):
    """Cut at every tenth of what follows the header and the embedded model (format 8's rows are a small part of
    a 3 s heave log: a tenth of the whole file ends inside the model's attachments)."""
    _, data, full = real_log
    assert full.status == "ok" and full.recovered_rows == 300
    head = _rows_start(data)
    counts = []
    for tenth in range(10):
        cut = tmp_path / f"cut{tenth}.mcap"
        cut.write_bytes(data[:head + (len(data) - head) * tenth // 10] if tenth else b"")
        if tenth == 0:
            with pytest.raises(LogFormatError, match=r"cut0\.mcap: empty file \(0 bytes\)"):
                read_log(cut)
            continue
        run = read_log(cut)
        assert run.status == "truncated" and run.summary is None
        n = run.recovered_rows
        assert run.note.startswith(f"recovered {n} rows ({n * 0.01:.1f} s) of a truncated log")
        for name in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
            assert np.array_equal(getattr(run.trajectory, name), getattr(full.trajectory, name)[:n])
        assert run.scenario_text == full.scenario_text and run.model_source == full.model_source
        counts.append(n)
    assert counts == sorted(counts) and counts[-1] >= 200


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True), st.integers(0, 7)), min_size=1, max_size=4))
def test_fuzz_bit_flips_in_a_real_log(real_log, tmp_path, flips):
    _, data, full = real_log
    mutated = bytearray(data)
    for where, bit in flips:
        mutated[int(where * len(data))] ^= 1 << bit
    _check_readable_or_refused(tmp_path / "flipped.mcap", bytes(mutated), full)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=2000), magic=st.booleans(), cut=st.floats(0.0, 1.0))
def test_fuzz_random_bytes_and_random_cuts(real_log, tmp_path, data, magic, cut):
    _, real, full = real_log
    probe = tmp_path / "random.mcap"
    _check_readable_or_refused(probe, (b"\x89MCAP0\r\n" if magic else b"") + data, full)
    # a real log's start followed by random bytes
    _check_readable_or_refused(probe, real[:int(cut * len(real))] + data, full)


# -- a stop signal never cuts a write in half ----------------------------------------------------------

@pytest.mark.skipif(not hasattr(signal, "SIGTERM"), reason="needs POSIX signals")
def test_a_signal_during_write_rows_is_raised_after_the_whole_block(tmp_path):
    from adaptive_mj.errors import Interrupted
    from adaptive_mj.sim.interrupt import stop_on_signals

    rows = synthetic(2000)
    path = tmp_path / "signalled.mcap"
    with stop_on_signals():
        rec = Recorder(path, make_header())
        import adaptive_mj.log.record as record_mod

        original = record_mod._add_packed_rows  # a block of rows is written through it (CDR)

        def add_and_signal(writer, *block):  # a SIGTERM, then a second signal while the first waits
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGINT)
            return original(writer, *block)

        record_mod._add_packed_rows = add_and_signal
        try:
            with pytest.raises(Interrupted, match="interrupted by SIGTERM") as stop:
                write_block(rec, rows, 0, 1000)
        finally:
            record_mod._add_packed_rows = original
        assert stop.value.exit_code == 143
        assert rec.rows_written == 100  # the block went in whole before the signal was raised
        write_block(rec, rows, 1000, 2000)  # the second signal changed nothing
        rec.close("interrupted", "interrupted by SIGTERM", {})
    run = read_log(path)
    assert run.status == "interrupted" and run.recovered_rows == 200
    assert_rows_equal(run.trajectory, rows, slice(0, 2000, LOG_EVERY))


@pytest.mark.parametrize("encoding", ["cdr", "json"])
def test_batched_message_writing_gives_the_same_bytes_as_mcap_add_message(tmp_path, monkeypatch, encoding):
    """The fast chunk writer (adaptive_mj/log/fast_mcap.py, for the mcap it was written for) and mcap's
    public Writer.add_message (any other mcap) write the same file, byte for byte, hence the same messages."""
    import adaptive_mj.log.record as record_mod
    from adaptive_mj.log import fast_mcap

    rows = synthetic(2500)
    header = make_header(encoding=encoding)
    paths = {}
    for name, writer, rows_writer, packed_writer in (
            ("fast", fast_mcap.add_messages_fast, fast_mcap.add_rows_fast, fast_mcap.add_packed_rows_fast),
            ("public", fast_mcap.add_messages_public, fast_mcap.add_rows_public, fast_mcap.add_packed_rows_public)):
        monkeypatch.setattr(record_mod, "_add_messages", writer)
        monkeypatch.setattr(record_mod, "_add_rows", rows_writer)
        monkeypatch.setattr(record_mod, "_add_packed_rows", packed_writer)
        paths[name] = tmp_path / f"{name}.mcap"
        rec = Recorder(paths[name], header)
        write_block(rec, rows, 0, 1300)
        rec.write_event(0.5, "payload_swap", mass=2.0)  # Writer.add_message between two batches
        write_block(rec, rows, 1300, 2500)
        rec.close("ok", "", {"x": 1})
    messages = {}
    for name, path in paths.items():
        assert_rows_equal(read_log(path).trajectory, rows, slice(0, 2500, LOG_EVERY))
        with open(path, "rb") as f:
            messages[name] = [(ch.topic, m.log_time, m.publish_time, m.sequence, m.data)
                              for _, ch, m in make_reader(f).iter_messages()]
    per_row = 6 if encoding == "json" else 1  # format 6: a message per row topic; format 8: one /row message
    assert len(messages["fast"]) == per_row * 250 + 2 and messages["fast"] == messages["public"]
    assert paths["fast"].read_bytes() == paths["public"].read_bytes()


def test_the_fast_writer_is_taken_only_on_the_mcap_it_was_written_for():
    from importlib.metadata import version

    from adaptive_mj.log import fast_mcap, record

    assert fast_mcap.writer_for(fast_mcap.WRITTEN_FOR) is fast_mcap.add_messages_fast
    for other in ("1.5.0", "1.6.1", "1.7.0", "2.0.0"):
        assert fast_mcap.writer_for(other) is fast_mcap.add_messages_public
    assert record._add_messages is fast_mcap.writer_for(version("mcap"))
    assert record._add_messages is fast_mcap.add_messages_fast  # constraints.txt pins the mcap it was written for
    assert fast_mcap.rows_writer_for(fast_mcap.WRITTEN_FOR) is fast_mcap.add_rows_fast
    for other in ("1.5.0", "1.6.1", "2.0.0"):
        assert fast_mcap.rows_writer_for(other) is fast_mcap.add_rows_public
    assert record._add_rows is fast_mcap.add_rows_fast
    assert fast_mcap.packed_rows_writer_for(fast_mcap.WRITTEN_FOR) is fast_mcap.add_packed_rows_fast
    for other in ("1.5.0", "1.6.1", "2.0.0"):
        assert fast_mcap.packed_rows_writer_for(other) is fast_mcap.add_packed_rows_public
    assert record._add_packed_rows is fast_mcap.add_packed_rows_fast


def test_only_the_fast_writer_touches_mcap_internals():
    from pathlib import Path

    package = Path(record.__file__).resolve().parents[1]
    hits = [p.relative_to(package).as_posix() for p in package.rglob("*.py") if "_Writer__" in p.read_text()]
    assert hits == ["log/fast_mcap.py"]


@pytest.mark.parametrize("order, n_theta", [(2, 3), (3, 2)])
def test_a_block_of_finite_rows_formatted_at_once_gives_the_bytes_of_one_message_at_a_time(tmp_path, order, n_theta):
    """Recorder._write_finite_block (one %-operation for a whole block of finite rows) against the
    per-message path it stands in for (taken when flush_every_rows is set, or a row has a non-finite
    value): the same file, byte for byte, also with a non-finite row in the other block."""
    rows = synthetic(2500, order=order, n_theta=n_theta)
    rows["x"][1710, 0] = np.nan  # the second block goes the per-message way in both files
    header = make_header(order=order, names=NAMES[:n_theta], encoding="json")
    paths = {}
    for name, flush_every in (("block", None), ("per_message", 10**9)):
        paths[name] = tmp_path / f"{name}.mcap"
        rec = Recorder(paths[name], header, flush_every_rows=flush_every)
        write_block(rec, rows, 0, 1300)
        write_block(rec, rows, 1300, 2500)
        rec.close("ok", "", {})
        assert rec.rows_written == 250
    assert paths["block"].read_bytes() == paths["per_message"].read_bytes()
    np.testing.assert_array_equal(read_log(paths["block"]).trajectory.x[:130], rows["x"][0:1300:LOG_EVERY])


FORMAT7_FIXTURE = Path(__file__).parent / "data" / "heave_drift_format7.mcap"


@pytest.mark.parametrize("source, topic, size", [("format 8", "/row", 4 + 8 * 16), ("format 7", "/state", 28)])
@pytest.mark.parametrize("change, cut", [(lambda d: d[:-1], True), (lambda d: b"\x00\x00" + d[2:], False)])
def test_a_cdr_message_of_another_size_or_header_is_refused(tmp_path, source, topic, size, change, cut):
    """read_log decodes CDR rows by their fixed layout (format 8: the one /row message of t and 15 float64 of a
    heave row; format 7, the fixture: a /state message of t, y, y_dot); a message cut short or in another
    encapsulation (big-endian CDR) is a LogFormatError naming the file, the topic, the size and header that came
    and the size expected, never a misread row."""
    from mcap.writer import Writer

    src = FORMAT7_FIXTURE
    if source == "format 8":
        src = tmp_path / "good.mcap"
        write_log(src, synthetic(500), events=())
    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = list(reader.iter_messages())
        metadata = list(reader.iter_metadata())
        library = reader.get_header().library
    bad = tmp_path / "bad.mcap"
    seen = 0
    with open(bad, "wb") as f:
        w = Writer(f)
        w.start(library=library)
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channels = {cid: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id])
                    for cid, c in summary.channels.items()}
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        for _schema, channel, msg in messages:
            data = msg.data
            if channel.topic == topic:
                seen += 1
                if seen == 10:
                    assert len(data) == size
                    data = change(data)
            w.add_message(channels[channel.id], msg.log_time, data, msg.publish_time)
        w.finish()
    came = (rf"is {size - 1} bytes starting b'\\x00\\x01\\x00\\x00'" if cut else
            rf"is {size} bytes starting b'\\x00\\x00")
    with pytest.raises(LogFormatError, match=rf"bad\.mcap: a {topic} message {came}.*, expected {size} bytes of CDR"):
        read_log(bad)

"""Foxglove: docs/foxglove_layout.json is a Foxglove layout whose every message path names
a real topic and field of a real log (heave and arm), every channel carries the schema Foxglove needs
(format 7: the row topics CDR with a ros2msg schema, /events and /summary JSON with a JSON Schema), and an
independent MCAP reader (TypeScript @mcap/core, run with Node: tools/mcap_count.mjs) counts the same messages
per topic as the Python reader and decodes every message (JSON, or CDR by its ros2msg schema)."""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from mcap.reader import make_reader

from adaptive_mj.cli import main

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "docs" / "foxglove_layout.json"
TOOLS = REPO / "tools"
HEAVE_PARAMS = {"d", "b", "c"}
ARM_PARAMS = {"J", "b", "g_sin", "g_cos"}
PATH_RE = re.compile(r"^(/[A-Za-z_][A-Za-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)$")


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("foxglove_logs")
    runs = {
        "heave": ["heave_tracking", "--set", "simulation.duration=0.3", "--set", "success.tail_rms=inf"],
        "arm": ["arm_payload_swap", "--set", "simulation.duration=0.3",
                "--set", "events=[{t=0.1, kind='payload_mass', value=2.0}]"],
    }
    paths = {}
    for name, args in runs.items():
        paths[name] = d / f"{name}.mcap"
        assert main(["run", args[0], "-o", str(paths[name]), *args[1:]]) == 0
    return paths


@pytest.fixture(scope="module")
def layout():
    return json.loads(LAYOUT.read_text(encoding="utf-8"))


def _leaves(node):
    if isinstance(node, str):
        return [node]
    assert set(node) >= {"first", "second", "direction"}, node
    assert node["direction"] in ("row", "column")
    assert 0 < node.get("splitPercentage", 50) < 100
    return _leaves(node["first"]) + _leaves(node["second"])


def _plot_paths(layout):
    return [p["value"] for cid, cfg in layout["configById"].items() if cid.startswith("Plot!")
            for p in cfg["paths"]]


def _ros2msg_fields(text: str) -> dict:
    """{field: {"type": ...}} of a ros2msg schema of float64 fields (what Foxglove parses), in order."""
    fields = {}
    for line in text.splitlines():
        words = line.split("#")[0].split()
        if words:
            assert len(words) == 2 and words[0] == "float64" and re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", words[1]), line
            fields[words[1]] = {"type": "number"}
    return fields


def _schemas(log):
    """topic -> (schema encoding, message encoding, schema as a JSON Schema) of the log's channels; a ros2msg
    schema is given as {"type": "object", "properties": {field: {"type": "number"}}}."""
    with open(log, "rb") as f:
        summary = make_reader(f).get_summary()
    out = {}
    for channel in summary.channels.values():
        schema = summary.schemas[channel.schema_id]
        if schema.encoding == "ros2msg":
            body = {"type": "object", "properties": _ros2msg_fields(schema.data.decode())}
        else:
            body = json.loads(schema.data)
        out[channel.topic] = (schema.encoding, channel.message_encoding, body)
    return out


def test_layout_has_the_shape_of_a_foxglove_layout(layout):
    assert {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"} <= set(layout)
    leaves = _leaves(layout["layout"])
    assert sorted(leaves) == sorted(layout["configById"]), "every panel is placed exactly once"
    for panel_id, config in layout["configById"].items():
        kind = panel_id.split("!")[0]
        assert kind in ("Plot", "RawMessages"), panel_id
        if kind == "Plot":
            assert config["xAxisVal"] == "timestamp"
            assert config["paths"]
            for p in config["paths"]:
                assert set(p) >= {"value", "enabled", "timestampMethod"}
                assert p["enabled"] is True
                assert p["timestampMethod"] in ("receiveTime", "headerStamp")
        else:
            assert config["topicPath"] in ("/summary", "/events")


def test_layout_plots_what_the_issue_asks_for(layout):
    paths = set(_plot_paths(layout))
    assert {"/state.y", "/reference.y_d", "/control.s", "/control.u", "/control.y_tilde",
            "/lyapunov.V"} <= paths
    for name in HEAVE_PARAMS | ARM_PARAMS:
        assert {f"/estimates.{name}", f"/true_params.{name}"} <= paths, name
    raw = {cfg["topicPath"] for cid, cfg in layout["configById"].items() if cid.startswith("RawMessages!")}
    assert raw == {"/summary", "/events"}


def test_every_layout_path_names_a_real_topic_and_field(layout, logs):
    schemas = {plant: _schemas(log) for plant, log in logs.items()}
    params = {"heave": HEAVE_PARAMS, "arm": ARM_PARAMS}
    for value in _plot_paths(layout):
        match = PATH_RE.match(value)
        assert match, f"{value!r} is not /topic.field"
        topic, field = match.groups()
        owners = [plant for plant, s in schemas.items()
                  if topic in s and field in s[topic][2]["properties"]]
        assert owners, f"{value}: no log has this topic and field"
        if topic in ("/estimates", "/true_params"):
            assert owners == [p for p in ("heave", "arm") if field in params[p]], value
        else:
            assert owners == ["heave", "arm"], f"{value}: missing from a log"
    for plant, s in schemas.items():
        assert {"/summary", "/events"} <= set(s), plant


def test_every_channel_has_a_schema_with_the_plotted_fields(layout, logs):
    plotted = {}
    for value in _plot_paths(layout):
        topic, field = PATH_RE.match(value).groups()
        plotted.setdefault(topic, set()).add(field)
    for plant, log in logs.items():
        names = HEAVE_PARAMS if plant == "heave" else ARM_PARAMS
        for topic, (schema_encoding, message_encoding, schema) in _schemas(log).items():
            row_topic = topic not in ("/events", "/summary")  # format 7: the row topics CDR, the others JSON
            assert (schema_encoding, message_encoding) == (("ros2msg", "cdr") if row_topic else
                                                           ("jsonschema", "json")), topic
            assert schema["type"] == "object" and "properties" in schema, topic
            for prop in schema["properties"].values():   # what Foxglove's parser accepts
                assert isinstance(prop.get("type"), str), (topic, prop)
            fields = plotted.get(topic, set())
            if topic in ("/estimates", "/true_params"):
                fields = fields & names
                assert set(schema["properties"]) - {"t", "nonfinite"} == names, topic
            assert fields <= set(schema["properties"]), (plant, topic, fields)
            for field in fields:
                assert schema["properties"][field]["type"] == "number", (topic, field)


def _python_counts(log):
    with open(log, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        stats = {summary.channels[cid].topic: n
                 for cid, n in summary.statistics.channel_message_counts.items()}
        read = {channel.topic: 0 for channel in summary.channels.values()}
        for _, channel, _ in reader.iter_messages():
            read[channel.topic] += 1
    return stats, read


def _node_reason():
    if shutil.which("node") is None:
        return "node is not on PATH (tools/mcap_count.mjs needs Node)"
    if not (TOOLS / "node_modules" / "@mcap" / "core").is_dir():
        return "tools/node_modules is missing: run `npm ci --prefix tools`"
    return None


@pytest.mark.skipif(_node_reason() is not None, reason=_node_reason() or "")
@pytest.mark.parametrize("plant", ["heave", "arm"])
def test_typescript_mcap_reader_counts_the_same_messages(logs, plant):
    r = subprocess.run(["node", str(TOOLS / "mcap_count.mjs"), str(logs[plant])],
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    ts = json.loads(r.stdout)
    stats, read = _python_counts(logs[plant])
    assert ts["counts"] == read
    assert ts["statistics"] == stats
    assert {k: v for k, v in read.items() if v} == stats
    assert ts["json_errors"] == 0 and ts["cdr_errors"] == 0
    assert ts["cdr_decoded"] == 6 * read["/state"]  # every row message decoded by its ros2msg schema
    assert ts["library"].startswith("adaptive_mj log format")
    rows = read["/state"]
    assert rows == 30 and all(read[t] == rows for t in ("/reference", "/control", "/estimates",
                                                         "/true_params", "/lyapunov"))
    assert read["/summary"] == 1 and read["/events"] == (1 if plant == "arm" else 0)
    for topic, (schema_name, schema_encoding, message_encoding) in ts["schemas"].items():
        if topic in ("/events", "/summary"):
            assert schema_name.startswith("adaptive_mj.") and schema_encoding == "jsonschema", topic
            assert message_encoding == "json", topic
        else:
            assert schema_name.startswith("adaptive_mj/msg/") and schema_encoding == "ros2msg", topic
            assert message_encoding == "cdr", topic
    assert {"adaptive_mj", "scenario", "status"} <= set(ts["metadata"])
    assert "model_source.xml" in ts["attachments"]

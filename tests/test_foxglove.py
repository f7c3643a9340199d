"""Foxglove: docs/foxglove_layout.json is a Foxglove layout whose every message path names
a real topic, sub-message and field of a real log (heave and arm), every channel carries the schema Foxglove needs
(format 8: /row CDR with a ros2msg schema of nested sub-messages, its dependencies after MSG: lines as ROS 2 and
Foxglove's parser read them; /events and /summary JSON with a JSON Schema), and an independent MCAP reader
(TypeScript @mcap/core, run with Node: tools/mcap_count.mjs) counts the same messages per topic as the Python
reader and decodes every message (JSON, or CDR by its ros2msg schema)."""
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from mcap.reader import make_reader

from adaptive_mj.cli import main
from adaptive_mj.log import record

REPO = Path(__file__).resolve().parents[1]
LAYOUT = REPO / "docs" / "foxglove_layout.json"
TOOLS = REPO / "tools"
# the parameters' fields in the Row schema (ros2msg_field: ROS 2 field names are lower-case, the arm's J is j)
HEAVE_PARAMS = {"d", "b", "c"}
ARM_PARAMS = {"j", "b", "g_sin", "g_cos"}
# a Foxglove message path into a format-8 log: /row.<sub-message>.<field>
PATH_RE = re.compile(r"^(/row)\.([a-z][a-z0-9_]*)\.([a-z][a-z0-9_]*)$")
SEPARATOR = "=" * 80
# Foxglove's ros2msg parser (@foxglove/rosmsg buildRos2Type) refuses any other field name, as ROS 2 does
FIELD_NAME = re.compile(r"[a-z](?:_?[a-z0-9]+)*")


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
    """{field: {"type": "number"}} or {field: {"type": "object", "properties": ...}} of a ros2msg schema with its
    dependencies, in order, resolved as Foxglove's parser resolves them: the definitions split at lines starting
    "==", a dependency named by its "MSG: <name>" line, a field of a complex type matched to the definition of
    exactly that name; every field name one Foxglove accepts; float64 the only primitive here."""
    sections, current = [[]], None
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("=="):
            assert line == SEPARATOR, line
            sections.append([])
        elif line and not line.startswith("#"):
            sections[-1].append(line)
    definitions = {}
    for k, lines in enumerate(sections):
        current = None
        if k:
            assert lines[0].startswith("MSG: "), lines[0]
            current, lines = lines[0][len("MSG: "):], lines[1:]
        fields = []
        for line in lines:
            words = line.split("#")[0].split()
            assert len(words) == 2 and FIELD_NAME.fullmatch(words[1]), line
            fields.append(tuple(words))
        assert current not in definitions, current
        definitions[current] = fields

    def resolve(name):
        out = {}
        for kind, field in definitions[name]:
            out[field] = {"type": "number"} if kind == "float64" else {"type": "object", "properties": resolve(kind)}
        return out

    return resolve(None)


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
    assert {"/row.state.y", "/row.reference.y_d", "/row.control.s", "/row.control.u", "/row.control.y_tilde",
            "/row.lyapunov.v"} <= paths
    for name in HEAVE_PARAMS | ARM_PARAMS:
        assert {f"/row.estimates.{name}", f"/row.true_params.{name}"} <= paths, name
    raw = {cfg["topicPath"] for cid, cfg in layout["configById"].items() if cid.startswith("RawMessages!")}
    assert raw == {"/summary", "/events"}


def test_every_layout_path_names_a_real_topic_and_field(layout, logs):
    schemas = {plant: _schemas(log) for plant, log in logs.items()}
    params = {"heave": HEAVE_PARAMS, "arm": ARM_PARAMS}
    for value in _plot_paths(layout):
        match = PATH_RE.match(value)
        assert match, f"{value!r} is not /row.part.field"
        topic, part, field = match.groups()
        owners = [plant for plant, s in schemas.items()
                  if topic in s and field in s[topic][2]["properties"].get(part, {}).get("properties", {})]
        assert owners, f"{value}: no log has this topic, sub-message and field"
        if part in ("estimates", "true_params"):
            assert owners == [p for p in ("heave", "arm") if field in params[p]], value
        else:
            assert owners == ["heave", "arm"], f"{value}: missing from a log"
    for plant, s in schemas.items():
        assert {"/summary", "/events"} <= set(s), plant


def test_every_channel_has_a_schema_with_the_plotted_fields(layout, logs):
    plotted = {}
    for value in _plot_paths(layout):
        _topic, part, field = PATH_RE.match(value).groups()
        plotted.setdefault(part, set()).add(field)
    parts = ["state", "reference", "control", "estimates", "true_params", "lyapunov"]
    for plant, log in logs.items():
        names = HEAVE_PARAMS if plant == "heave" else ARM_PARAMS
        schemas = _schemas(log)
        assert set(schemas) == {"/row", "/events", "/summary"}, plant
        for topic, (schema_encoding, message_encoding, schema) in schemas.items():
            row_topic = topic == "/row"  # format 8: the rows one CDR topic, the others JSON
            assert (schema_encoding, message_encoding) == (("ros2msg", "cdr") if row_topic else
                                                           ("jsonschema", "json")), topic
            assert schema["type"] == "object" and "properties" in schema, topic
            for prop in schema["properties"].values():   # what Foxglove's parser accepts
                assert isinstance(prop.get("type"), str), (topic, prop)
        row = schemas["/row"][2]["properties"]
        assert list(row) == ["t", *parts] and row["t"] == {"type": "number"}
        for part in parts:
            fields = plotted.get(part, set())
            sub = row[part]["properties"]
            if part in ("estimates", "true_params"):
                fields = fields & names
                assert set(sub) == names, part
            assert fields <= set(sub), (plant, part, fields)
            for field in fields:
                assert sub[field]["type"] == "number", (part, field)


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
    assert ts["json_errors"] == 0 and ts["cdr_errors"] == 0 and ts["ros2msg_bad_names"] == []
    assert ts["cdr_decoded"] == read["/row"] == 30  # every row message decoded by its nested ros2msg schema
    assert ts["library"].startswith(f"adaptive_mj log format {record.LOG_FORMAT_VERSION}")
    assert set(read) == {"/row", "/events", "/summary"}
    assert read["/summary"] == 1 and read["/events"] == (1 if plant == "arm" else 0)
    assert ts["schemas"]["/row"] == ["adaptive_mj/msg/Row", "ros2msg", "cdr"]
    for topic in ("/events", "/summary"):
        schema_name, schema_encoding, message_encoding = ts["schemas"][topic]
        assert schema_name.startswith("adaptive_mj.") and schema_encoding == "jsonschema", topic
        assert message_encoding == "json", topic
    # the TypeScript reader's leaf paths of the Row schema are the layout's: /row.<part>.<field>
    schema = _schemas(logs[plant])["/row"][2]["properties"]
    want = ["t"] + [f"{part}.{field}" for part, sub in schema.items() if part != "t" for field in sub["properties"]]
    assert ts["row_fields"] == want
    assert {"adaptive_mj", "scenario", "status"} <= set(ts["metadata"])
    assert "model_source.xml" in ts["attachments"]


@pytest.mark.skipif(_node_reason() is not None, reason=_node_reason() or "")
@pytest.mark.parametrize("name, rows, bad", [
    ("heave_drift_format7.mcap", 50, ["adaptive_mj/msg/Lyapunov: V"]),
    ("heave_drift_format6.mcap", 50, [])])
def test_typescript_mcap_reader_reads_the_older_fixtures(name, rows, bad):
    """The independent reader still decodes format 7's six flat CDR topics (six messages a row) and format 6's JSON;
    it names the field names of format 7 that Foxglove's ros2msg parser refuses (V: upper case), which format 8
    writes lower-case."""
    log = REPO / "tests" / "data" / name
    r = subprocess.run(["node", str(TOOLS / "mcap_count.mjs"), str(log)],
                       capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert r.returncode == 0, r.stderr
    ts = json.loads(r.stdout)
    assert ts["counts"] == _python_counts(log)[1]
    assert ts["json_errors"] == 0 and ts["cdr_errors"] == 0 and ts["row_fields"] == []
    assert ts["cdr_decoded"] == (6 * rows if "format7" in name else 0)
    assert ts["ros2msg_bad_names"] == bad

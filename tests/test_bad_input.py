"""Bad input through the command line: every case exits 2 and prints exactly one line,
``adaptive-mj: error: <file>: <key or line>: <expected>, got <what came>``, with no
traceback (that only with --debug); damaged or foreign logs likewise. Also output
safety: nothing is written outside the chosen folder, nothing overwritten."""
from __future__ import annotations

import re
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from adaptive_mj.log import record
from adaptive_mj.cli import main
from adaptive_mj.errors import ScenarioError

from test_scenario import GOOD  # the same valid scenario, edited case by case

REPO = Path(__file__).resolve().parents[1]

ARM = GOOD.replace('kind = "heave"', 'kind = "arm"').replace(
    "gamma = { d = 0.0025, b = 0.002, c = 0.5 }", "gamma = 1.0")

BROKEN_XML = "<mujoco><worldbody><body><geom type='sphere'/></body></worldbody></mujoco2>"
NO_JOINT_XML = ("<mujoco><option density='1000'/><worldbody><body><geom type='box' size='.1 .1 .1' mass='1'/>"
                "</body></worldbody></mujoco>")
TWO_JOINT_XML = ("<mujoco><worldbody><body><joint name='a' type='hinge'/><geom type='capsule' fromto='0 0 0 .3 0 0' "
                 "size='.02' mass='1'/><body pos='.3 0 0'><joint name='b' type='hinge'/><geom type='capsule' "
                 "fromto='0 0 0 .3 0 0' size='.02' mass='1'/></body></body></worldbody><actuator>"
                 "<motor joint='a'/><motor joint='b'/></actuator></mujoco>")
HINGE_XML = ("<mujoco><option density='1000'/><worldbody><body><joint name='heave' type='hinge'/>"
             "<geom type='box' size='.1 .1 .1' mass='1'/></body></worldbody><actuator><motor joint='heave'/>"
             "</actuator></mujoco>")


def error_line(capsys) -> str:
    """The one line on stderr (asserting there is exactly one and no traceback)."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert err.startswith("adaptive-mj: error: "), err
    return err[len("adaptive-mj: error: "):-1]


# (case, scenario text, extra arguments, the message after "<file>: "); the scenario file is bad.toml.
SCENARIO_CASES = [
    ("TOML syntax error", "schema_version = 1\n[plant]\nkind = \n", [],
     r"TOML syntax error: Invalid value \(at line 3, column 8\)"),
    ("unknown key", GOOD.replace("[law]", "[law]\nkk = 3"), [], r"unknown key 'law\.kk' \(did you mean 'k'\?\)"),
    ("misspelt section", GOOD.replace("[law]", "[lwa]\nk = 1.0\n[law]"), [],
     r"unknown key 'lwa' \(did you mean 'law'\?\)"),
    ("wrong type", GOOD.replace("k = 200.0", 'k = "fast"'), [], r"law\.k must be a number, got 'fast'"),
    ("wrong type of table", GOOD, ["--set", "simulation=3"], r"simulation must be a table, got 3"),
    ("NaN", GOOD.replace("k = 200.0", "k = nan"), [], r"law\.k must be a finite number, got nan"),
    ("infinity", GOOD.replace("lambda = 5.0", "lambda = inf"), [], r"law\.lambda must be a finite number, got inf"),
    ("NaN in an array", GOOD.replace("[1.0, 0.0]", "[1.0, nan]"), [],
     r"simulation\.initial_state\[1\] must be a finite number, got nan"),
    ("payload mass <= 0", ARM, ["--set", "plant.payload_mass=0.0"], r"plant\.payload_mass must be > 0, got 0\.0"),
    ("mass <= 0 in an event", ARM, ["--set", "events=[{t=1.0, kind='payload_mass', value=-2.0}]"],
     r"events\[0\]\.value must be > 0, got -2\.0"),
    ("twin mass <= 0", GOOD.replace('backend = "mujoco"', 'backend = "twin"\ntheta = {d = -1.0, b = 1.0, c = 1.0}'),
     [], r"plant\.theta\.d must be > 0, got -1\.0"),
    ("gamma <= 0", GOOD, ["--set", "law.gamma=-1"], r"law\.gamma must be > 0, got -1\.0"),
    ("one gamma <= 0", GOOD, ["--set", "law.gamma.c=0.0"], r"law\.gamma\.c must be > 0, got 0\.0"),
    ("gamma a string", GOOD, ["--set", "law.gamma='fast'"],
     r"law\.gamma must be a number > 0, or a table \{parameter = number > 0\}, got 'fast'"),
    ("timestep = 0", GOOD, ["--set", "simulation.timestep=0"], r"simulation\.timestep must be > 0, got 0\.0"),
    ("timestep < 0", GOOD, ["--set", "simulation.timestep=-0.001"], r"simulation\.timestep must be > 0, got -0\.001"),
    ("timestep > duration", GOOD, ["--set", "simulation.timestep=5.0"],
     r"simulation\.timestep must be <= simulation\.duration \(2\.0\), got 5\.0"),
    ("duration = 0", GOOD, ["--set", "simulation.duration=0"], r"simulation\.duration must be > 0, got 0\.0"),
    ("duration < 0", GOOD, ["--set", "simulation.duration=-3"], r"simulation\.duration must be > 0, got -3\.0"),
    ("event after the end", GOOD, ["--set", "events=[{t=3.0, kind='constant_force', value=1.0}]"],
     r"events\[0\]\.t must be <= simulation\.duration \(2\.0\), got 3\.0"),
    ("unknown reference kind", GOOD, ["--set", "reference.kind=square"],
     r"reference\.kind must be one of 'constant', 'cosine', 'sine', 'sum_of_sines', 'smooth_step', 'waypoints', "
     r"'reference_model', got 'square'"),
    ("unknown law kind", GOOD, ["--set", "law.kind=mpc"],
     r"law\.kind must be one of 'sliding_adaptive', .*, got 'mpc'"),
    ("schema version", GOOD.replace("schema_version = 1", "schema_version = 7"), [],
     r"schema_version must be 1 \(this adaptive-mj reads version 1\), got 7"),
    ("name with a path", GOOD, ["--set", 'name="../../outside"'],
     r"name must be a plain name of 1 to 100 characters for log files \(no '/', '\\', control characters "
     r"or leading '\.'\), got '\.\./\.\./outside'"),
    ("negative --seed", GOOD, ["--seed", "-1"], r"noise\.seed must be an integer >= 0, got -1"),
]


@pytest.mark.parametrize("case, text, args, message", SCENARIO_CASES, ids=[c[0] for c in SCENARIO_CASES])
def test_bad_scenario_exits_2_with_one_line(tmp_path, capsys, case, text, args, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    log = tmp_path / "run.mcap"
    assert main(["run", str(path), "-o", str(log), *args]) == 2
    line = error_line(capsys)
    assert re.fullmatch(re.escape(f"{path}: ") + message, line), line
    assert not log.exists()  # nothing ran, no file left


# Models: the scenario names a model file next to it (written by the test).
MODEL_CASES = [
    ("missing model file", None, ["plant.model=no_such_model"],
     r"{scn}: plant\.model '{models}/no_such_model\.xml' not found"),
    ("MJCF that fails to compile", BROKEN_XML, ["plant.model='model.xml'"],
     r"{dir}/model\.xml: MuJoCo could not compile the model: XML parse error 14: "
     r"Error=XML_ERROR_MISMATCHED_ELEMENT ErrorID=14 \(0xe\) Line number=1: XMLElement name=mujoco"),
    ("model without a joint", NO_JOINT_XML, ["plant.model='model.xml'"],
     r"{dir}/model\.xml: this plant is one slide joint driven by one motor \(1 degree of freedom\), the model "
     r"has 0; for a multi-joint arm use plant\.kind = \"manipulator\""),
    ("a two-joint arm as a 1-DOF plant", TWO_JOINT_XML, ["plant.model='model.xml'"],
     r"{dir}/model\.xml: this plant is one slide joint driven by one motor \(1 degree of freedom\), the model "
     r"has 2; for a multi-joint arm use plant\.kind = \"manipulator\""),
    ("a hinge where the plant needs a slide", HINGE_XML, ["plant.model='model.xml'"],
     r"{dir}/model\.xml: joint 'heave' must be a slide joint, got a hinge joint"),
    ("model without the named joint", None, ["plant.joint=lift"],
     r"{models}/heave_vehicle\.xml: no joint named 'lift' \(the model has \['heave'\]\)"),
    ("model without the named actuator", None, ["plant.actuator=rudder"],
     r"{models}/heave_vehicle\.xml: no actuator named 'rudder' \(the model has \['thrust'\]\)"),
]


@pytest.mark.parametrize("case, xml, overrides, message", MODEL_CASES, ids=[c[0] for c in MODEL_CASES])
def test_bad_model_exits_2_with_one_line(tmp_path, capsys, case, xml, overrides, message):
    scn = tmp_path / "scn.toml"
    scn.write_text(GOOD)
    if xml is not None:
        (tmp_path / "model.xml").write_text(xml)
    log = tmp_path / "run.mcap"
    assert main(["run", str(scn), "-o", str(log), *[a for o in overrides for a in ("--set", o)]]) == 2
    line = error_line(capsys)
    expected = message.format(scn=re.escape(str(scn)), dir=re.escape(str(tmp_path)),
                              models=re.escape(str(REPO / "models")))
    assert re.fullmatch(expected, line), line
    assert not log.exists()


SET_CASES = [
    ("law.k", r"--set 'law\.k': expected key=value, e\.g\. law\.k=50"),
    ("law..k=3", r"--set 'law\.\.k=3': key 'law\.\.k' must be a dotted path like law\.gamma"),
    ("=3", r"--set '=3': key '' must be a dotted path like law\.gamma"),
    ("law.k=[1,", r"--set 'law\.k=\[1,': value '\[1,' is not a TOML value \(expected a number, true/false, "
                  r"a string, an array or an inline table\)"),
    ("law.k.x=1", r"--set 'law\.k\.x=1': law\.k is not a table in .*heave_tracking\.toml"),
]


@pytest.mark.parametrize("expr, message", SET_CASES, ids=[c[0] for c in SET_CASES])
def test_malformed_set_exits_2_with_one_line(capsys, expr, message):
    assert main(["run", "heave_tracking", "--set", expr]) == 2
    assert re.fullmatch(message, error_line(capsys))


GRID_CASES = [  # more in tests/test_sweep.py::test_bad_input_exits_2_before_any_run
    ("law.k=1:2:x", r"--grid 'law\.k=1:2:x': N must be an integer >= 1, got 'x' \(expected KEY=LO:HI:N\)"),
    ("law.k=a:2:3", r"--grid 'law\.k=a:2:3': LO must be a finite number, got 'a' \(expected KEY=LO:HI:N\)"),
    ("law.k=1:nan:3", r"--grid 'law\.k=1:nan:3': HI must be a finite number, got 'nan' \(expected KEY=LO:HI:N\)"),
    ("law.k=1,,2", r"--grid 'law\.k=1,,2': value 2 is empty \(expected KEY=V1,V2,\.\.\.\)"),
    ("zzz=1", r"--grid 'zzz=1': no scenario key named 'zzz' \(write a dotted key like law\.k\)"),
    ("law.k", r"--grid 'law\.k': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
]


@pytest.mark.parametrize("expr, message", GRID_CASES, ids=[c[0] for c in GRID_CASES])
def test_malformed_grid_exits_2_with_one_line(tmp_path, capsys, expr, message):
    out = tmp_path / "sweep"
    assert main(["sweep", "heave_tracking", "--grid", expr, "-o", str(out)]) == 2
    assert re.fullmatch(message, error_line(capsys))
    assert not out.exists()


def test_missing_scenario_file_and_bad_options(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.toml")]) == 2
    assert error_line(capsys) == f"{tmp_path / 'nope.toml'}: scenario file not found"
    with pytest.raises(SystemExit) as exit_:
        main(["run", "heave_tracking", "--seed", "two"])
    assert exit_.value.code == 2
    assert capsys.readouterr().err.endswith("adaptive-mj run: error: argument --seed: invalid int value: 'two'\n")


def test_traceback_only_with_debug(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(GOOD.replace("k = 200.0", "k = -1.0"))
    with pytest.raises(ScenarioError, match=r"law\.k must be >= 0, got -1\.0"):
        main(["--debug", "run", str(path)])
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "run", str(path)], capture_output=True, text=True,
                       cwd=REPO, timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == f"adaptive-mj: error: {path}: law.k must be >= 0, got -1.0\n"


# -- damaged or foreign logs --------------------------------------------------------------------

@pytest.fixture(scope="module")
def real_log(tmp_path_factory) -> Path:
    """A 3 s log of a real run (first-order twin: fast), four flushed blocks."""
    path = tmp_path_factory.mktemp("log") / "real.mcap"
    assert main(["run", "lecture_first_order", "-o", str(path), "--set", "simulation.duration=3.0",
                 "--set", "success.tail_rms=inf"]) == 0  # 3 s: not converged, and not the point here
    return path


def chunk_offsets(path: Path) -> list[int]:
    with open(path, "rb") as f:
        return sorted(c.chunk_start_offset for c in make_reader(f).get_summary().chunk_indexes)


def flip_crc(data: bytes, chunk_offset: int) -> bytes:
    """The chunk's CRC with bits flipped (record: opcode, length, start, end, size, then the CRC)."""
    data = bytearray(data)
    at = chunk_offset + 9 + 8 + 8 + 8
    struct.pack_into("<I", data, at, struct.unpack_from("<I", data, at)[0] ^ 0xFFFF)
    return bytes(data)


def test_replay_of_a_non_mcap_file(tmp_path, capsys):
    path = tmp_path / "notes.mcap"
    path.write_text("name = 'not a log'\n")
    assert main(["replay", str(path)]) == 2
    assert error_line(capsys) == (f"{path}: not an MCAP file (starts with b\"name = '\"), "
                                  f"expected the MCAP magic b'\\x89MCAP0\\r\\n'")


def test_replay_of_a_zero_byte_file(tmp_path, capsys):
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    assert main(["replay", str(path)]) == 2
    assert error_line(capsys) == f"{path}: empty file (0 bytes), expected an adaptive-mj MCAP log"


def test_replay_of_a_missing_file(tmp_path, capsys):
    assert main(["replay", str(tmp_path / "gone.mcap")]) == 2
    assert error_line(capsys) == f"{tmp_path / 'gone.mcap'}: no such log file"


def test_replay_of_an_mcap_from_another_tool(tmp_path, capsys):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(library="someone-else")
        w.add_message(w.register_channel("/x", "json", w.register_schema("S", "jsonschema", b"{}")), 0, b"{}", 0)
        w.finish()
    assert main(["replay", str(path)]) == 2
    assert error_line(capsys) == (f"{path}: MCAP file without 'adaptive_mj' metadata, expected a log written by "
                                  f"adaptive_mj.log.record (this one was written by 'someone-else')")


def test_replay_of_a_newer_log_format(tmp_path, capsys, monkeypatch):
    path = tmp_path / "future.mcap"
    monkeypatch.setattr(record, "LOG_FORMAT_VERSION", record.LOG_FORMAT_VERSION + 1)
    assert main(["run", "lecture_first_order", "-o", str(path), "--set", "simulation.duration=0.5",
                 "--set", "success.tail_rms=inf"]) == 0  # 0.5 s is too short to converge: the log is the point
    monkeypatch.undo()
    capsys.readouterr()
    assert main(["replay", str(path)]) == 2
    v = record.LOG_FORMAT_VERSION
    assert error_line(capsys) == (f"{path}: log format version {v + 1} is newer than this adaptive_mj reads "
                                  f"(up to {v}); upgrade adaptive_mj")


def test_replay_of_a_log_with_a_bad_crc_in_its_first_chunk(real_log, tmp_path, capsys):
    path = tmp_path / "bad.mcap"
    path.write_bytes(flip_crc(real_log.read_bytes(), chunk_offsets(real_log)[0]))
    assert main(["replay", str(path)]) == 2
    line = error_line(capsys)
    assert re.fullmatch(re.escape(f"{path}: a damaged chunk at byte {chunk_offsets(real_log)[0]} (crc validation "
                                  "failed") + r".*\), and no whole row precedes it; nothing to recover", line), line


def test_replay_of_a_log_with_a_bad_crc_later_says_how_much_was_recovered(real_log, tmp_path, capsys):
    offsets = chunk_offsets(real_log)
    path = tmp_path / "bad.mcap"
    path.write_bytes(flip_crc(real_log.read_bytes(), offsets[2]))
    assert main(["replay", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith("lecture_first_order: truncated (recovered 200 rows (2.0 s) before a damaged "
                                   f"chunk at byte {offsets[2]}")
    assert ", 2.000 s simulated, 2000 steps" in captured.out.splitlines()[0]
    err = captured.err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"adaptive-mj: error: {path}: damaged log: recovered 200 rows (2.0 s) before a damaged "
                          f"chunk at byte {offsets[2]} (crc validation failed")
    assert err.rstrip().endswith("the run itself ended with status 'ok'")


def test_replay_of_a_cut_log_reports_truncated_and_how_much(real_log, tmp_path, capsys):
    path = tmp_path / "cut.mcap"
    data = real_log.read_bytes()
    path.write_bytes(data[:chunk_offsets(real_log)[2] + 50])  # cut inside the third block
    assert main(["replay", str(path)]) == 1  # not bad input: a run that did not finish its log
    out = capsys.readouterr().out
    assert out.startswith("lecture_first_order: truncated (recovered 200 rows (2.0 s) of a truncated log "
                          "(the file ends inside a record at byte")


# -- output safety --------------------------------------------------------------------------------

def test_scenario_name_cannot_write_outside_the_logs_folder(tmp_path, capsys, monkeypatch):
    from adaptive_mj.runs import runner

    monkeypatch.setattr(runner, "LOGS_DIR", tmp_path / "logs")
    scn = tmp_path / "evil.toml"
    for name in ("../escaped", "sub/dir", "..", ".hidden", "a\\b", "tab\there", ""):
        scn.write_text(f"name = {name!r}\n" + GOOD)
        assert main(["run", str(scn)]) == 2
        assert ": name must be a plain name" in error_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["evil.toml"]  # nothing written anywhere


def test_run_never_overwrites_without_force(tmp_path, capsys):
    log = tmp_path / "x.mcap"
    log.write_bytes(b"precious")
    assert main(["run", "lecture_first_order", "-o", str(log), "--set", "simulation.duration=0.2"]) == 2
    assert error_line(capsys) == f"{log}: file exists; pass --force to overwrite it"
    assert log.read_bytes() == b"precious"
    folder = tmp_path / "folder.mcap"
    folder.mkdir()
    assert main(["run", "lecture_first_order", "-o", str(folder), "--force"]) == 2
    assert error_line(capsys) == f"{folder}: not a regular file; choose a log file name"


def test_bench_and_sweep_never_write_into_a_used_folder(tmp_path, capsys):
    used = tmp_path / "used"
    used.mkdir()
    (used / "summary.json").write_text("keep")
    assert main(["bench", "--quick", "-o", str(used)]) == 2
    assert error_line(capsys) == f"{used}: exists and is not an empty folder; choose a new -o DIR"
    assert main(["sweep", "heave_tracking", "--grid", "law.k=1,2", "-o", str(used)]) == 2
    assert error_line(capsys) == f"{used}: exists and is not an empty folder; choose a new -o DIR"
    assert [p.name for p in used.iterdir()] == ["summary.json"]


def test_an_analysis_is_picked_from_a_closed_set(tmp_path):
    from adaptive_mj.study.job import EXTRAS, RunSpec, run_job

    result = run_job(RunSpec(REPO / "scenarios" / "lecture_first_order.toml", overrides=("simulation.duration=0.2",),
                         extras=("__class__",)))
    assert result.status == "error"
    assert result.error == f"unknown analysis '__class__'; expected one of {', '.join(EXTRAS)}"
    from adaptive_mj.study import analysis

    assert all(callable(getattr(analysis, name)) for name in EXTRAS)


# Reviewed uses: (file, code) -> why no input reaches it.
REVIEWED = {
    ("adaptive_mj/report/video.py", "importlib.import_module(wanted)"):
        "wanted comes from the module's fixed table of headless GL backends",
    ("adaptive_mj/study/__init__.py", 'importlib.import_module("adaptive_mj.study.api")'):
        "a fixed name: a study command module's call goes to the API module",
    ("adaptive_mj/__init__.py", 'importlib.import_module("adaptive_mj.study.api")'):
        "a fixed name: adaptive_mj.run_scenario and adaptive_mj.score are the API module's",
    ("adaptive_mj/study/__init__.py", 'importlib.import_module(f"adaptive_mj.study.{name}")'):
        "name is one of the fixed tuple COMMANDS (checked on the line before)",
    ("adaptive_mj/plugins.py", "importlib.import_module(package)"):
        "scan_built_in's package is a fixed name its two callers pass: adaptive_mj.plants or adaptive_mj.laws",
    ("adaptive_mj/plugins.py", 'importlib.import_module(f"{package}.{info.name}")'):
        "the modules of that package itself (pkgutil over its own folder)",
    ("adaptive_mj/sim/loop.py", "importlib.import_module(plant.compiled_loop)"):
        "a plant class's own declared attribute (protocol.Plant.compiled_loop: the module name its class states, "
        "e.g. AnalyticPlant's adaptive_mj.sim.native_chunk), never scenario text",
    ("adaptive_mj/plants/kinds.py", "importlib.import_module(self.module)"):
        "a built-in kind's module is the __name__ of the module that registered it, never scenario text",
}


def test_no_input_is_ever_executed():
    """No eval/exec, no pickle, no import by a name that came from input, anywhere in the package."""
    forbidden = re.compile(r"(?<![.\w])(eval|exec|compile|__import__)\s*\(|\bimport_module\b|\bpickle\b"
                           r"|\bmarshal\b|\bshelve\b|\byaml\.load\b")
    for source in sorted((REPO / "adaptive_mj").rglob("*.py")):
        name = source.relative_to(REPO).as_posix()
        code = "\n".join(line.split("#", 1)[0] for line in source.read_text().splitlines())
        code = re.sub(r'""".*?"""', "", code, flags=re.S)
        for path, snippet in REVIEWED:
            if path == name:
                code = code.replace(snippet, "")
        hit = forbidden.search(code)
        assert not hit, f"{name}: {hit.group(0)}"


def test_a_misspelt_bundled_scenario_gets_a_suggestion(capsys):
    assert main(["run", "heave_trackin"]) == 2
    line = error_line(capsys)
    assert line == ("heave_trackin: no such scenario file, nor a bundled scenario (did you mean "
                    "'heave_tracking'? `adaptive-mj list` shows the bundled ones)")


def test_a_model_given_on_the_command_line_is_found_from_the_current_directory(tmp_path, monkeypatch, capsys):
    """--set plant.model=my.xml resolves against the current directory (then next to the scenario);
    found in neither, one line names both places."""
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load

    monkeypatch.chdir(tmp_path)
    (tmp_path / "my_vehicle.xml").write_text((SCENARIOS_DIR.parent / "models" / "heave_vehicle.xml").read_text())
    scn = load(SCENARIOS_DIR / "heave_tracking.toml", overrides=["plant.model=my_vehicle.xml"])
    assert scn.plant.model == tmp_path / "my_vehicle.xml"
    assert main(["run", "heave_tracking", "--set", "plant.model=nope.xml", "--set", "simulation.duration=0.01"]) == 2
    line = error_line(capsys)
    assert line.endswith(f"plant.model 'nope.xml' (from --set) not found in the current directory "
                         f"({tmp_path / 'nope.xml'}) nor next to the scenario ({SCENARIOS_DIR / 'nope.xml'})")


# -- arms, studies and plugins (issue 19 §5): a generated corpus of broken multi-joint inputs -------
# Every bad file, in every place a run reads one, is refused before anything runs: exit 2, one line
# naming the file, no traceback, no log.

MJCF_OK = ('<mujoco><worldbody><body name="body"><geom type="sphere" size=".05" mass="{mass}"/></body></worldbody>'
           '</mujoco>')
BAD_FILES = {  # name -> (content, what the line says after "<file>: ")
    "malformed XML": (MJCF_OK.format(mass=0.5).replace("</mujoco>", "</mujoco2>"), r"not well-formed XML"),
    "XML that is not MJCF": ("<html><body>a web page</body></html>", r"not an MJCF model: the root element is <html>"),
    "binary": (bytes(range(256)) * 4, r"not a text file \(binary data"),
    "empty": (b"", r"empty payload file \(0 bytes\)"),
    "only whitespace": ("\n  \n", r"empty payload file \(4 bytes\)"),
    "massless geoms": (MJCF_OK.format(mass=0), r"the payload has no mass \(its bodies weigh 0 kg in all\)"),
    "NaN mass": (MJCF_OK.format(mass="nan"), r"<geom> mass='nan': not a finite number \(MuJoCo would replace"),
    "infinite mass": (MJCF_OK.format(mass="inf"), r"<geom> mass='inf': not a finite number"),
    "overflowing mass": (MJCF_OK.format(mass="1e999"), r"<geom> mass='1e999': not a finite number"),
    "negative mass": (MJCF_OK.format(mass=-1), r"<geom> mass='-1': a mass must be >= 0 kg"),
    "NaN position": (MJCF_OK.format(mass=0.5).replace('size=".05"', 'size=".05" pos="0 nan 0"'),
                     r"<geom> pos='0 nan 0': not a finite number"),
    "MJCF that does not compile": (MJCF_OK.format(mass=0.5).replace('type="sphere"', 'type="blob"'),
                                   r"MuJoCo could not compile the payload: "),
}
# (place, run arguments: PATH is the bad file)
PAYLOAD_PLACES = {
    "manipulator plant.payload": ["ur5e_identification", "--set", "plant.payload='PATH'"],
    "manipulator plant.payload with payload_mass": ["ur5e_identification", "--set", "plant.payload='PATH'",
                                                    "--set", "plant.payload_mass=1.0"],
    "manipulator payload_swap event": ["ur5e_identification", "--set",
                                       "events=[{t=0.01, kind='payload_swap', payload='PATH'}]"],
    "1-DOF arm plant.payload": ["arm_payload_swap", "--set", "events=[]", "--set", "plant.payload='PATH'"],
}
PAYLOAD_CASES = [(f, p) for f in BAD_FILES for p in PAYLOAD_PLACES]


def _write(path: Path, content) -> Path:
    (path.write_bytes if isinstance(content, bytes) else path.write_text)(content)
    return path


@pytest.mark.parametrize("bad, place", PAYLOAD_CASES, ids=[f"{f} as {p}" for f, p in PAYLOAD_CASES])
def test_a_bad_payload_file_exits_2_with_one_line_naming_it(tmp_path, capsys, bad, place):
    content, message = BAD_FILES[bad]
    path = _write(tmp_path / "payload.xml", content)
    log = tmp_path / "run.mcap"
    args = [a.replace("PATH", str(path)) for a in PAYLOAD_PLACES[place]]
    assert main(["run", *args, "-o", str(log), "--set", "simulation.duration=0.02"]) == 2
    line = error_line(capsys)
    assert re.fullmatch(re.escape(f"{path}: ") + message + ".*", line), line
    assert not log.exists()


SWAP_CASES = {
    "no body named 'body'": ('<mujoco><worldbody><body name="block"><geom type="box" size=".1 .1 .1" mass="1"/>'
                             '</body></worldbody></mujoco>',
                             r"a payload_swap takes the inertial of the body named 'body', which this payload "
                             r"does not have \(bodies: \['block'\]\)"),
    "'body' of mass 0": ('<mujoco><worldbody><body name="body"><body name="inner"><geom type="sphere" size=".05" '
                         'mass="1"/></body></body></worldbody></mujoco>',
                         r"the body 'body' has mass 0 kg; a payload_swap needs a finite mass > 0 \(give its geoms "
                         r"a mass\)"),
}


@pytest.mark.parametrize("case", SWAP_CASES)
def test_a_swapped_in_payload_without_a_massive_body_is_refused_up_front(tmp_path, capsys, case):
    content, message = SWAP_CASES[case]
    path = _write(tmp_path / "swap.xml", content)
    log = tmp_path / "run.mcap"
    assert main(["run", "ur5e_identification", "-o", str(log), "--set", "simulation.duration=0.02", "--set",
                 f"events=[{{t=0.01, kind='payload_swap', payload='{path}'}}]"]) == 2
    assert re.fullmatch(re.escape(f"{path}: ") + message, error_line(capsys))
    assert not log.exists()


def test_a_missing_payload_names_every_place_it_was_looked_for(tmp_path, capsys, monkeypatch):
    """A relative payload path is looked for next to the scenario, then in the current directory."""
    monkeypatch.chdir(tmp_path)
    scn = tmp_path / "scenarios" / "swap.toml"
    scn.parent.mkdir()
    scn.write_text((REPO / "scenarios" / "ur5e_payload_swap.toml").read_text().replace(
        'payload = "sphere"', 'payload = "loads/gone.xml"'))
    assert main(["run", str(scn), "--set", "simulation.duration=20.0"]) == 2
    assert error_line(capsys) == (f"{scn}: the payload_swap event at t=15 s: payload 'loads/gone.xml' not found next "
                                  f"to the scenario ({scn.parent / 'loads/gone.xml'}) nor in the current directory "
                                  f"({tmp_path / 'loads/gone.xml'})")
    assert main(["run", "ur5e_identification", "--set", "plant.payload=nosuch"]) == 2
    assert error_line(capsys).endswith("plant.payload 'nosuch' is not a bundled payload (box_offset, quad_box, "
                                       "quad_cable, sphere, tool_offset); give one of those or a path to an MJCF "
                                       "file ending in .xml")


def test_an_event_payload_resolves_next_to_the_scenario_and_the_log_verifies_from_anywhere(tmp_path, monkeypatch,
                                                                                          capsys):
    """payload_swap's file, relative, is found next to the scenario from any working directory; the
    log embeds its text, so it re-simulates bit for bit from another folder, the file gone."""
    made, elsewhere = tmp_path / "made", tmp_path / "elsewhere"
    (made / "loads").mkdir(parents=True)
    elsewhere.mkdir()
    (made / "loads" / "heavy.xml").write_text(MJCF_OK.format(mass=0.9))
    scn = made / "swap.toml"
    scn.write_text((REPO / "scenarios" / "ur5e_payload_swap.toml").read_text().replace(
        'payload = "sphere"', 'payload = "loads/heavy.xml"').replace("t = 15.0", "t = 0.05"))
    monkeypatch.chdir(elsewhere)
    log = tmp_path / "swap.mcap"
    assert main(["run", str(scn), "-o", str(log), "--set", "simulation.duration=0.1",
                 "--set", "success.tail_rms=inf"]) == 0  # 0.1 s: the swap is the point, not convergence
    capsys.readouterr()
    from adaptive_mj.log.replay import read_log

    assert read_log(log).events[0]["label"] == "payload_swap payload/body = loads/heavy.xml (0.9 kg)"
    (made / "loads" / "heavy.xml").unlink()
    monkeypatch.chdir(tmp_path)
    assert main(["replay", str(log), "--verify"]) == 0
    assert "bit-identical" in capsys.readouterr().out


# A user's arm: two hinges, each driven by a motor or a position servo.
USER_ARM = """<mujoco model="user_arm"><option timestep="0.001" integrator="RK4"/>
<worldbody><body name="upper" pos="0 0 0.5"><joint name="shoulder" axis="0 1 0" armature="0.05"/>
<geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1.2" contype="0" conaffinity="0"/>
<body name="lower" pos="0.3 0 0"><joint name="elbow" axis="0 1 0" armature="0.05"/>
<geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.025" mass="0.6" contype="0" conaffinity="0"/>
<site name="tip" pos="0.25 0 0"/></body></body></worldbody>
<actuator>{actuators}</actuator></mujoco>"""
USER_SCENARIO = """schema_version = 1
[plant]
kind = "manipulator"
model = "arm.xml"
unknown = "all"
{plant}
[simulation]
duration = 0.05
[reference]
kind = "joint_sum_of_sines"
amplitudes = [0.1]
omegas = [1.0]
[law]
kind = "slotine_li"
lambda = 10.0
kd = 5.0
gamma = 0.2
[success]
tail_rms = inf
"""
MOTORS = '<motor name="m_shoulder" joint="shoulder"/><motor name="m_elbow" joint="elbow"/>'
SERVOS = '<position name="s_shoulder" joint="shoulder" kp="50"/><position name="s_elbow" joint="elbow" kp="30"/>'


def _user_arm(tmp_path, actuators: str, plant: str = "") -> Path:
    (tmp_path / "arm.xml").write_text(USER_ARM.format(actuators=actuators))
    scn = tmp_path / "user.toml"
    scn.write_text(USER_SCENARIO.format(plant=plant))
    return scn


USER_ARM_CASES = [
    ("a motor of gear 0", MOTORS.replace('joint="elbow"', 'joint="elbow" gear="0"'), "",
     r"{arm}: actuator\(s\) 'm_elbow' \(gear 0\) cannot drive their joint: the joint torque is gear \* ctrl, so the "
     r"law's torque needs a finite, nonzero gear \(set gear, e\.g\. gear=\"1\"\)"),
    ("servos without a forcerange", SERVOS, "servo_to_torque = true",
     r"{scn}: plant\.servo_to_torque: 2 servo\(s\) have no forcerange to limit the torque motor each becomes: "
     r"'s_shoulder' \(joint 'shoulder'\), 's_elbow' \(joint 'elbow'\); give plant\.forcerange = L .*"),
    ("a forcerange table that misses one servo", SERVOS, "servo_to_torque = true\nforcerange = { shoulder = 20.0 }",
     r"{scn}: plant\.servo_to_torque: 1 servo\(s\) have no forcerange .*: 's_elbow' \(joint 'elbow'\); .*"),
    ("a forcerange table naming no servo", SERVOS, "servo_to_torque = true\nforcerange = { wrist = 20.0 }",
     r"{scn}: plant\.forcerange names 'wrist', which is no servo's joint or actuator name \(servos: "
     r"'s_shoulder' \(joint 'shoulder'\), 's_elbow' \(joint 'elbow'\)\)"),
    ("forcerange without servo_to_torque", MOTORS, "forcerange = 20.0",
     r"{scn}: plant\.forcerange must be absent unless plant\.servo_to_torque = true .*, got 20\.0"),
    ("a forcerange <= 0", SERVOS, "servo_to_torque = true\nforcerange = { elbow = 0.0 }",
     r"{scn}: plant\.forcerange\.elbow must be > 0, got 0\.0"),
    ("a forcerange of the wrong type", SERVOS, "servo_to_torque = true\nforcerange = \"strong\"",
     r"{scn}: plant\.forcerange must be a number > 0 or a table \{{joint = number > 0\}}, got 'strong'"),
]


@pytest.mark.parametrize("case, actuators, plant, message", USER_ARM_CASES, ids=[c[0] for c in USER_ARM_CASES])
def test_a_users_arm_that_cannot_be_driven_exits_2_with_one_line(tmp_path, capsys, case, actuators, plant, message):
    scn = _user_arm(tmp_path, actuators, plant)
    log = tmp_path / "run.mcap"
    assert main(["run", str(scn), "-o", str(log)]) == 2
    line = error_line(capsys)
    assert re.fullmatch(message.format(scn=re.escape(str(scn)), arm=re.escape(str(tmp_path / "arm.xml"))), line), line
    assert not log.exists()


@pytest.mark.parametrize("plant, limits", [
    ("forcerange = 25.0", [25.0, 25.0]),
    ("forcerange = { shoulder = 40.0, s_elbow = 15.0 }", [40.0, 15.0]),  # by joint or by actuator name
])
def test_servos_without_a_forcerange_take_the_scenarios_limit(tmp_path, capsys, plant, limits):
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load

    setup = build(load(_user_arm(tmp_path, SERVOS, "servo_to_torque = true\n" + plant)))
    lo, hi = setup.plant.ctrl_range
    assert list(hi) == limits and list(lo) == [-x for x in limits]
    assert len(setup.notes) == 1 and setup.notes[0].startswith("plant.servo_to_torque: servo(s) rebuilt as torque ")
    assert setup.notes[0].endswith(f"'s_elbow' |tau| <= [-{limits[1]:g}, {limits[1]:g}] N*m from plant.forcerange")


# Model files: every bad file as plant.model of each kind of plant (the message after the file is the
# model reader's or MuJoCo's own; the point is one line naming the file).
MODEL_PLACES = {"heave": "heave_tracking", "manipulator": "ur5e_identification", "1-DOF arm": "arm_payload_swap"}
MODEL_FILE_CASES = [(f, p) for f in ("malformed XML", "XML that is not MJCF", "binary", "empty", "only whitespace")
                    for p in MODEL_PLACES]


@pytest.mark.parametrize("bad, place", MODEL_FILE_CASES, ids=[f"{f} as the {p} model" for f, p in MODEL_FILE_CASES])
def test_a_bad_model_file_exits_2_with_one_line_naming_it(tmp_path, capsys, bad, place):
    path = _write(tmp_path / "model.xml", BAD_FILES[bad][0])
    log = tmp_path / "run.mcap"
    assert main(["run", MODEL_PLACES[place], "-o", str(log), "--set", f"plant.model='{path}'", "--set", "events=[]",
                 "--set", "simulation.duration=0.02"]) == 2
    assert error_line(capsys).startswith(f"{path}: ")
    assert not log.exists()


@pytest.mark.parametrize("scenario, model", [("heave_tracking", "heave_vehicle"), ("arm_payload_swap", "pendulum_arm")])
def test_a_motor_of_gear_0_is_refused_on_a_1dof_plant(tmp_path, capsys, scenario, model):
    """The law divides by the gear (u = τ / gear): a gear of 0 is one line, not a ZeroDivisionError."""
    path = tmp_path / "model.xml"
    text = (REPO / "models" / f"{model}.xml").read_text()
    assert text.count('gear="1"') == 1
    path.write_text(text.replace('gear="1"', 'gear="0"'))
    log = tmp_path / "run.mcap"
    assert main(["run", scenario, "-o", str(log), "--set", f"plant.model='{path}'", "--set", "events=[]",
                 "--set", "simulation.duration=0.02"]) == 2
    line = error_line(capsys)
    assert re.fullmatch(re.escape(f"{path}: actuator ") + r"'\w+' has gear 0; the force on the joint is gear \* ctrl, "
                        r"so the law needs a finite, nonzero gear \(set gear, e\.g\. gear=\"1\"\)", line), line
    assert not log.exists()


# Studies: every grid point, every scenario given to bench, and a resumed study's manifest are
# checked (built: model, payload files, names, keyframes) before anything runs.
STUDY_GRID_CASES = [
    ("a keyframe the model does not have", ["reference.center=home,nokey"],
     r"grid point reference\.center=nokey: .*ur5e_identification\.toml: reference\.center names keyframe 'nokey', "
     r"which the model does not have \(keyframes: \['home'\]\)"),
    ("a payload that does not exist", ["plant.payload=sphere,nosuch"],
     r"grid point plant\.payload=nosuch: .*plant\.payload 'nosuch' is not a bundled payload .*"),
    ("a body the model does not have", ["plant.unknown=['payload/body'],['nobody']"],
     r"grid point plant\.unknown=.*nobody.*: .*plant\.unknown names body 'nobody', which the model does not have .*"),
]


@pytest.mark.parametrize("case, grid, message", STUDY_GRID_CASES, ids=[c[0] for c in STUDY_GRID_CASES])
def test_a_grid_point_that_cannot_be_built_stops_the_sweep_before_any_run(tmp_path, capsys, case, grid, message):
    out = tmp_path / "sweep"
    args = [a for g in grid for a in ("--grid", g)]
    assert main(["sweep", "ur5e_identification", *args, "-o", str(out), "--set", "simulation.duration=0.02"]) == 2
    line = error_line(capsys)
    assert re.fullmatch(message, line), line
    assert not out.exists()


def test_a_grid_point_with_a_bad_payload_file_stops_the_sweep_before_any_run(tmp_path, capsys):
    good = _write(tmp_path / "good.xml", MJCF_OK.format(mass=0.5))
    bad = _write(tmp_path / "bad.xml", MJCF_OK.format(mass="nan"))
    out = tmp_path / "sweep"
    assert main(["sweep", "ur5e_identification", "--grid", f"plant.payload='{good}','{bad}'", "-o", str(out),
                 "--set", "simulation.duration=0.02"]) == 2
    assert error_line(capsys).startswith(f"grid point plant.payload={bad}: {bad}: <geom> mass='nan'")
    assert not out.exists()


def test_a_breaking_point_end_that_cannot_be_built_stops_before_any_run(tmp_path, capsys):
    out = tmp_path / "bp"
    scn = _user_arm(tmp_path, MOTORS.replace('joint="elbow"', 'joint="elbow" gear="0"'))
    assert main(["sweep", str(scn), "--breaking-point", "law.kd=1:10", "--tail-bound", "1", "-o", str(out)]) == 2
    assert error_line(capsys).startswith(f"--breaking-point law.kd=1: {tmp_path / 'arm.xml'}: actuator(s) 'm_elbow'")
    assert not out.exists()


def test_bench_checks_your_scenarios_before_the_catalogue_runs(tmp_path, capsys, monkeypatch):
    from adaptive_mj.study import bench_catalogue

    ran = []
    monkeypatch.setattr(bench_catalogue, "catalogue", lambda *, quick, logs: ran.append(quick) or [])
    bad = tmp_path / "bad.toml"
    bad.write_text((REPO / "scenarios" / "ur5e_identification.toml").read_text().replace('"home"', '"nokey"'))
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "-o", str(out), "--scenario", str(REPO / "scenarios" / "heave_tracking.toml"),
                 "--scenario", str(bad)]) == 2
    assert error_line(capsys) == (f"{bad}: reference.center names keyframe 'nokey', which the model does not have "
                                  "(keyframes: ['home'])")
    assert not out.exists() and ran == []
    assert main(["bench", "--quick", "-o", str(out), "--scenario", str(tmp_path / "gone.toml")]) == 2
    assert error_line(capsys) == f"{tmp_path / 'gone.toml'}: scenario file not found"


@pytest.mark.parametrize("manifest, got", [
    ("[1, 2]", "a JSON array"),
    ('"a sweep"', "a JSON string"),
    ("null", "a JSON null"),
    ("3", "a JSON number"),
    ('{"grid": ["law.k=1,2"]}', "an object without format, scenario, scenario_text, seeds, overrides"),
])
def test_resume_on_a_manifest_of_the_wrong_shape_exits_2_with_one_line(tmp_path, capsys, manifest, got):
    study = tmp_path / "study"
    study.mkdir()
    (study / "manifest.json").write_text(manifest)
    assert main(["sweep", "heave_tracking", "--grid", "law.k=1,2", "--resume", str(study)]) == 2
    assert error_line(capsys) == (f"sweep --resume {study}: manifest.json is not a sweep manifest (expected an object "
                                  f"with format, scenario, scenario_text, grid, seeds, overrides; got {got}); resume "
                                  "only a folder that sweep wrote")
    assert sorted(p.name for p in study.iterdir()) == ["manifest.json"]


# Plugins: a plant plugin's model file, bad in each way, as the plugin's own or as plant.model.
CART_XML = ("<mujoco><option timestep='0.001'/><worldbody><body name='cart'><joint name='x' type='slide' "
            "axis='1 0 0'/><geom type='box' size='.1 .05 .05' mass='2'/></body></worldbody><actuator>"
            "<motor joint='x'/></actuator></mujoco>")
CART_SCENARIO = """schema_version = 1
[plant]
kind = "cart"
[simulation]
duration = 0.05
[reference]
kind = "cosine"
[law]
kind = "sliding_adaptive"
lambda = 10.0
k = 50.0
gamma = { d = 0.05, b = 0.05 }
"""


@pytest.fixture
def cart_plugin(tmp_path, monkeypatch):
    """A plant plugin "cart" (as an installed distribution would register it), its MJCF in tmp_path."""
    from adaptive_mj import plugins
    from adaptive_mj.form import ModelForm
    from adaptive_mj.plants import plugin as plant_plugins
    from adaptive_mj.plants.mujoco_plant import MujocoPlant, find_joint_and_actuator

    def make(model, params, where):
        import mujoco

        j, a = find_joint_and_actuator(model, joint=None, actuator=None, joint_type=mujoco.mjtJoint.mjJNT_SLIDE,
                                       where=where)
        return MujocoPlant(model, joint_id=j, actuator_id=a,
                           form=ModelForm(order=2, p_names=("b",), phi=lambda x: x[1:2] * -1.0),
                           theta_fn=lambda m: [m.body_mass[1], m.dof_damping[0]], where=where)

    model = _write(tmp_path / "cart.xml", CART_XML)
    inst = plugins.Installed("cart", plant_plugins.PlantPlugin(model=model, make=make), "cart-plant", "0.1.0", "0" * 64)
    monkeypatch.setattr(plant_plugins, "installed", lambda: {"cart": inst})
    scn = tmp_path / "cart.toml"
    scn.write_text(CART_SCENARIO)
    return scn


def test_a_plant_plugins_motor_of_gear_0_exits_2_with_one_line(cart_plugin, tmp_path, capsys):
    model = _write(tmp_path / "cart.xml", CART_XML.replace("<motor joint='x'/>", "<motor joint='x' gear='0'/>"))
    assert main(["run", str(cart_plugin), "-o", str(tmp_path / "run.mcap")]) == 2
    assert error_line(capsys).startswith(f"{model}: actuator '#0' has gear 0; ")


@pytest.mark.parametrize("bad", ["malformed XML", "XML that is not MJCF", "binary", "empty"])
def test_a_plant_plugins_bad_model_file_exits_2_with_one_line(cart_plugin, tmp_path, capsys, bad):
    model = _write(tmp_path / "cart.xml", BAD_FILES[bad][0])  # the plugin's own file, damaged
    assert main(["run", str(cart_plugin), "-o", str(tmp_path / "run.mcap")]) == 2
    assert error_line(capsys).startswith(f"{model}: ")
    _write(tmp_path / "other.xml", BAD_FILES[bad][0])  # or the one the scenario names
    out = tmp_path / "sweep"
    assert main(["sweep", str(cart_plugin), "--grid", "plant.model='cart.xml','other.xml'", "-o", str(out)]) == 2
    assert error_line(capsys).startswith(f"grid point plant.model=cart.xml: {model}: ")
    assert not out.exists() and not (tmp_path / "run.mcap").exists()


def test_a_control_delay_in_seconds_is_refused_with_its_unit_and_the_steps_it_would_be(capsys):
    """simulation.control_delay counts physics steps: 0.02 (seconds, by mistake) is refused in one line that says
    the unit and what 0.02 s is at the scenario's timestep."""
    from adaptive_mj.cli import main

    assert main(["run", "heave_tracking", "--set", "simulation.control_delay=0.02"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert ("simulation.control_delay must be a whole number of physics steps (not seconds); 0.02 s is 20 steps "
            "of 0.001 s, got 0.02") in err


# ---- a run that asks for more steps than memory can hold (issue 35) -----------------------------------------

@pytest.mark.parametrize("override", ["simulation.timestep=1e-12", "simulation.duration=1e9",
                                      "simulation.duration=1e300"])
def test_a_billion_step_scenario_is_refused_before_the_run_in_one_line(override, tmp_path, capsys):
    log = tmp_path / "run.mcap"
    assert main(["run", "heave_tracking", "--set", override, "-o", str(log)]) == 2
    line = error_line(capsys)
    assert "simulation.duration / simulation.timestep must ask for at most" in line, line
    assert re.search(r"= (\d(\.\d+)?e\+\d+|more than 1e308) steps, which would need [\d.e+]+ [KMGTPE]iB", line), line
    assert "bytes held per step" in line and not log.exists()


def test_the_step_memory_check_sits_on_its_bound_and_counts_the_rows_the_loop_holds():
    """check_run_memory: a run needing exactly the limit passes, one byte less refuses; row_bytes is what
    sim.loop.Rows allocates per step (the heave vehicle and the 6-joint arm)."""
    from adaptive_mj.setup.build import build, check_run_memory, row_bytes
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.sim.loop import Rows

    for name, sets in (("heave_tracking", []), ("ur5e_payload_swap", ["events=[]"])):
        scn = load(SCENARIOS_DIR / f"{name}.toml", overrides=["simulation.duration=1.0", *sets])
        s = build(scn)
        rows = Rows(s.plant, s.law, 1000, None, 1000)
        held = sum(getattr(rows, f).nbytes for f in ("t", "x", "u", "s", "ref", "theta_hat", "V"))
        assert row_bytes(s.plant, s.law) * 1000 == held, name
        steps = round(1.0 / s.plant.dt)
        need = steps * row_bytes(s.plant, s.law)
        check_run_memory(scn, s.plant, s.law, memory=need)
        with pytest.raises(ScenarioError, match=rf"at most {steps - 1:.3g} physics steps"):
            check_run_memory(scn, s.plant, s.law, memory=need - 1)

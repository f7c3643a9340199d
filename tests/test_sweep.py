"""adaptive-mj sweep: grid expressions parse (or fail with a message naming the
expression), the grid is the product of its axes, every point is validated
before anything runs, and an end-to-end sweep writes one log per run and a
CSV/JSON whose metrics are the ones stored in each log."""
import csv
import itertools
import json
import math
import re
import tomllib
from pathlib import Path

import pytest

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import sweep
from adaptive_mj.cli import main
from adaptive_mj.errors import AdaptiveMJError, ScenarioError
from adaptive_mj.study.parallel import RunSpec, RunOutcome

REPO = Path(__file__).resolve().parents[1]
ARM = REPO / "scenarios" / "arm_payload_swap.toml"
HEAVE = REPO / "scenarios" / "heave_tracking.toml"


def doc_of(path: Path) -> dict:
    return tomllib.loads(path.read_text())


@pytest.fixture(scope="module")
def arm_doc() -> dict:
    return doc_of(ARM)


# --------------------------------------------------------------------------
# parse_grid
def test_linear_grid_includes_both_endpoints_evenly_spaced(arm_doc):
    key, values = sweep.parse_grid("law.k=0.25:4:8", arm_doc)
    assert key == "law.k"
    assert len(values) == 8
    assert values[0] == 0.25 and values[-1] == 4.0
    steps = [b - a for a, b in itertools.pairwise(values)]
    assert all(math.isclose(d, 3.75 / 7) for d in steps)


def test_linear_grid_can_run_downwards_and_n1_gives_lo(arm_doc):
    assert sweep.parse_grid("law.k=4:1:4", arm_doc)[1] == [4.0, 3.0, 2.0, 1.0]
    assert sweep.parse_grid("law.k=2.5:9:1", arm_doc)[1] == [2.5]


def test_explicit_values_are_toml(arm_doc):
    assert sweep.parse_grid("law.k=1,2.5,10", arm_doc) == ("law.k", [1, 2.5, 10])
    assert sweep.parse_grid("reference.kind=sine, cosine", arm_doc) == ("reference.kind", ["sine", "cosine"])
    key, values = sweep.parse_grid("noise.std={y=0.01, y_dot=0.1},{y=0.0}", arm_doc)
    assert key == "noise.std" and values == [{"y": 0.01, "y_dot": 0.1}, {"y": 0.0}]
    assert sweep.parse_grid("law.k=5", arm_doc)[1] == [5]


def test_bare_key_resolves_to_the_one_key_that_ends_with_it(arm_doc):
    assert sweep.parse_grid("payload_mass=0.25:4:8", arm_doc)[0] == "plant.payload_mass"
    assert sweep.parse_grid("lambda=1,2", arm_doc)[0] == "law.lambda"
    assert sweep.parse_grid("gamma.J=0.01,0.1", arm_doc)[0] == "law.gamma.J"  # a dotted suffix
    # documented keys the file leaves at their default resolve too
    assert sweep.parse_grid("viscosity=0,1", arm_doc)[0] == "plant.viscosity"
    assert sweep.parse_grid("rate_hz=50", arm_doc)[0] == "log.rate_hz"


def test_dotted_key_of_a_section_is_taken_as_written(arm_doc):
    assert sweep.parse_grid("noise.std.y=0,0.01", arm_doc)[0] == "noise.std.y"


def test_ambiguous_bare_key_lists_the_candidates():
    with pytest.raises(ScenarioError, match=r"--grid 'b=1,2': 'b' is ambiguous: it could be "
                                            r"law\.gamma\.b, law\.initial_estimates\.b; write the dotted key"):
        sweep.parse_grid("b=1,2", doc_of(HEAVE))
    with pytest.raises(ScenarioError, match=r"'kind' is ambiguous: .*plant\.kind.*law\.kind"):
        sweep.parse_grid("kind=x", doc_of(HEAVE))


def test_unknown_bare_key_suggests_close_keys(arm_doc):
    with pytest.raises(ScenarioError, match=r"--grid 'payload_mas=1,2': no scenario key named 'payload_mas' "
                                            r"\(candidates: plant\.payload_mass"):
        sweep.parse_grid("payload_mas=1,2", arm_doc)
    with pytest.raises(ScenarioError, match=r"no scenario key named 'zzz' \(write a dotted key like law\.k\)"):
        sweep.parse_grid("zzz=1", arm_doc)


@pytest.mark.parametrize("expr, message", [
    ("law.k", r"--grid 'law\.k': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
    ("=1,2", r"--grid '=1,2': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
    ("law.k=1:2", r"--grid 'law\.k=1:2': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
    ("law.k=1:2:3:4", r"--grid 'law\.k=1:2:3:4': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
    ("law.k=1:2:2.5", r"--grid 'law\.k=1:2:2\.5': N must be an integer >= 1, got '2\.5'"),
    ("law.k=1:2:x", r"--grid 'law\.k=1:2:x': N must be an integer >= 1, got 'x'"),
    ("law.k=1:2:0", r"--grid 'law\.k=1:2:0': N must be an integer >= 1, got '0'"),
    ("law.k=1:2:-3", r"N must be an integer >= 1, got '-3'"),
    ("law.k=a:2:3", r"--grid 'law\.k=a:2:3': LO must be a finite number, got 'a' \(expected KEY=LO:HI:N\)"),
    ("law.k=1:inf:3", r"--grid 'law\.k=1:inf:3': HI must be a finite number, got 'inf'"),
    ("law.k=", r"--grid 'law\.k=': empty value list \(expected KEY=V1,V2,\.\.\.\)"),
    ("law.k=1,,2", r"--grid 'law\.k=1,,2': value 2 is empty \(expected KEY=V1,V2,\.\.\.\)"),
    ("law.k=[1", r"--grid 'law\.k=\[1': value '\[1' is not a TOML value"),
    ("law k=1", r"--grid 'law k=1': key 'law k' must be a dotted scenario key like law\.k"),
])
def test_malformed_grid_expressions_name_the_expression(arm_doc, expr, message):
    with pytest.raises(ScenarioError, match=message):
        sweep.parse_grid(expr, arm_doc)


def test_grid_points_is_the_product_first_axis_slowest():
    points = sweep.grid_points([("a", [1, 2]), ("b", ["x", "y", "z"])])
    assert points == [{"a": 1, "b": "x"}, {"a": 1, "b": "y"}, {"a": 1, "b": "z"},
                      {"a": 2, "b": "x"}, {"a": 2, "b": "y"}, {"a": 2, "b": "z"}]
    assert sweep.grid_points([("a", [0.5])]) == [{"a": 0.5}]


def test_a_law_scoped_axis_expands_only_under_its_own_law():
    """--grid law.kind=sliding_adaptive,robust_sliding --grid law.robust_sliding.K=0,5,20: the scoped axis reaches
    only robust_sliding's runs (scenario._scoped_law_keys), so sliding_adaptive runs once, not three times."""
    axes = [("law.kind", ["sliding_adaptive", "robust_sliding"]), ("law.robust_sliding.K", [0.0, 5.0, 20.0]),
            ("law.k", [100, 200])]
    assert sweep.scoped_axes(axes) == {"law.robust_sliding.K": "robust_sliding"}
    points = sweep.grid_points(axes)
    assert points == [
        {"law.kind": "sliding_adaptive", "law.robust_sliding.K": None, "law.k": 100},
        {"law.kind": "sliding_adaptive", "law.robust_sliding.K": None, "law.k": 200},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 0.0, "law.k": 100},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 0.0, "law.k": 200},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 5.0, "law.k": 100},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 5.0, "law.k": 200},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 20.0, "law.k": 100},
        {"law.kind": "robust_sliding", "law.robust_sliding.K": 20.0, "law.k": 200}]
    # the unscoped point gives no override for the scoped axis, and its run name leaves it out
    assert sweep._grid_overrides(points[0]) == ["law=sliding_adaptive", "law.k=100"]
    assert sweep._grid_overrides(points[4]) == ["law=robust_sliding", "law.robust_sliding.K=5.0", "law.k=100"]
    names = sweep.short_names(list(points[0]))
    assert sweep.run_name(0, points[0], 0, names=names) == "0000-kind=sliding_adaptive-k=100-seed0"
    assert sweep.label(None) == "-"
    # a law.X.key axis is scoped only when X is one of the swept kinds (law.gamma.J is a per-parameter table)
    assert sweep.scoped_axes([("law.kind", ["a", "b"]), ("law.gamma.J", [1, 2])]) == {}
    assert sweep.scoped_axes([("law.robust_sliding.K", [1, 2])]) == {}  # no law.kind axis: the product as before
    assert len(sweep.grid_points([("law.kind", ["a", "b"]), ("law.c.K", [1, 2])])) == 4


def test_a_law_scoped_sweep_runs_each_law_s_own_points_only(tmp_path, capsys):
    """End to end: 1 + 2 points, not 2 × 2; the CSV leaves the other law's axis empty."""
    out = tmp_path / "out"
    code = main(["sweep", "heave_tracking", "--grid", "law.kind=sliding_adaptive,robust_sliding", "--grid",
                     "law.robust_sliding.K=0,2", "--set", "simulation.duration=1", "--set", "law.lambda=5.0",
                 "--set", "law.k=200.0", "--set", "law.robust_sliding.boundary_layer=0.05", "--set",
                 "success.tail_rms=inf", "--jobs", "1", "-o", str(out)])
    assert code == 0, capsys.readouterr()
    table = list(csv.DictReader((out / "sweep.csv").open()))
    assert [(r["law.kind"], r["law.robust_sliding.K"]) for r in table] == [
        ("sliding_adaptive", ""), ("robust_sliding", "0"), ("robust_sliding", "2")]
    assert {r["status"] for r in table} == {"ok"}
    assert (out / "sweep.png").stat().st_size > 5_000


def test_a_categorical_axis_is_plotted_as_categories_without_lines(tmp_path, monkeypatch):
    """A sweep over law kinds (a category first) draws markers at the categories, with no line joining them and
    the min-max band as error bars; a numeric axis keeps its line."""
    import matplotlib.figure

    drawn = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", lambda fig, *a, **k: drawn.append(fig))
    table = [{"law.kind": kind, "law.k": k, "seed": seed, "status": "ok", "rms_tracking_error_tail": 0.1 * k + seed}
             for kind in ("a", "b", "c") for k in (1.0, 2.0) for seed in (0, 1)]
    sweep.plot_sweep(table, ["law.kind", "law.k"], ["rms_tracking_error_tail"], tmp_path / "cat.png")
    sweep.plot_sweep(table, ["law.k", "law.kind"], ["rms_tracking_error_tail"], tmp_path / "num.png")
    cat, num = (fig.axes[0] for fig in drawn)
    data = [line for line in cat.get_lines() if len(line.get_xdata()) == 3]  # one series: the three categories
    assert data and all(line.get_linestyle() == "None" for line in data)
    assert [t.get_text() for t in cat.get_xticklabels()] == ["a", "b", "c"]
    assert cat.collections  # the error bars
    assert any(line.get_linestyle() == "-" and len(line.get_xdata()) == 2 for line in num.get_lines())


@pytest.mark.parametrize("value", [1, -2.5, 1 / 3, 1e-300, True, "sine", 'a "quoted" str', [1.0, 2],
                                   {"y": 0.01, "y_dot": 0.1}, {"J": [1, {"b": False}]}])
def test_grid_values_round_trip_through_their_toml_text(value):
    assert sc.parse_value(sweep.to_toml(value), what="test") == value


def test_every_section_key_is_one_the_validator_knows():
    """Each key a bare grid key can resolve to is read by the validator in some bundled scenario."""
    for section, names in sweep.DOCUMENTED_KEYS.items():
        for name in names:
            key = f"{section}.{name}"
            messages = []
            for path in sc.bundled():
                try:  # true: a value no key accepts; law.K and law.boundary_layer are robust_sliding's
                    sc.load(path, overrides=[*(["law.kind=robust_sliding"] if name in ("K", "boundary_layer") else []),
                                             f"{key}=true"])
                    messages.append("accepted")
                except ScenarioError as exc:
                    messages.append(str(exc))
            assert any("unknown key" not in m for m in messages), (key, messages)


def test_run_names_are_readable_and_unique():
    names = sweep.short_names(["plant.payload_mass", "noise.std.y"])
    assert names == {"plant.payload_mass": "payload_mass", "noise.std.y": "std.y"}
    assert (sweep.run_name(7, {"plant.payload_mass": 1.3571428571428572}, 2, names=names)
            == "0007-payload_mass=1.357-seed2")
    assert sweep.short_names(["law.gamma", "plant.gamma"]) == {"law.gamma": "law.gamma", "plant.gamma": "plant.gamma"}
    assert sweep.short_names(["law.k", "noise.k"]) == {"law.k": "law.k", "noise.k": "noise.k"}
    odd = sweep.run_name(12, {"noise.std": {"y": 0.01}}, 0, names={"noise.std": "std"}, width=5)
    assert odd == "00012-std=_y_=_0.01_-seed0"


# --------------------------------------------------------------------------
# rows and files (no simulation)
def _result(tmp_path, seed, status, metrics, *, error=""):
    log = tmp_path / "logs" / f"run{seed}.mcap"
    summary = None if status == "error" else {"status": status, "reason": "why" if status != "ok" else "",
                                              "metrics": metrics}
    return RunOutcome(RunSpec(ARM, seed=seed, log=log, tag=f"run{seed}"), status, summary, error=error)


def test_rows_flatten_metrics_and_keep_failures(tmp_path):
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "run0.mcap").write_bytes(b"x")
    m = {"rms_tracking_error_tail": 0.5, "param_error_final": {"J": 0.1, "b": -0.2}}
    table = sweep.rows([({"law.k": 1.0}, _result(tmp_path, 0, "ok", m)),
                        ({"law.k": 1.0}, _result(tmp_path, 1, "diverged", {"rms_tracking_error_tail": None})),
                        ({"law.k": 2.0}, _result(tmp_path, 2, "error", {}, error="boom"))], root=tmp_path)
    assert table[0] == {"run": "run0", "law.k": 1.0, "seed": 0, "status": "ok", "reason": "",
                        "rms_tracking_error_tail": 0.5, "param_error_final.J": 0.1, "param_error_final.b": -0.2,
                        "log": "logs/run0.mcap"}
    assert table[1]["status"] == "diverged" and table[1]["reason"] == "why" and table[1]["log"] == ""
    assert table[2]["status"] == "error" and table[2]["reason"] == "boom"
    stats = sweep.point_stats(table, ["law.k"], "rms_tracking_error_tail")
    assert [(s.point, s.mean, s.n_ok, s.n) for s in stats[:1]] == [({"law.k": 1.0}, 0.5, 1, 2)]
    assert math.isnan(stats[1].mean) and (stats[1].n_ok, stats[1].n) == (0, 1)
    text = sweep.summary_table(table, ["law.k"], ["rms_tracking_error_tail"])
    assert text.splitlines()[1].split() == ["1", "0.5", "1/2"]
    assert text.splitlines()[2].split() == ["2", "n/a", "0/1"]


def test_metric_units_follow_the_plant():
    assert sweep.metric_label("rms_tracking_error_tail", "arm") == "rms_tracking_error_tail [rad]"
    assert sweep.metric_label("max_abs_tracking_error_tail", "heave") == "max_abs_tracking_error_tail [m]"
    assert sweep.metric_label("control_rms", "arm") == "control_rms [N m]"  # the arm kind's declared unit
    assert sweep.metric_label("rms_tracking_error", "first_order") == "rms_tracking_error"
    assert sweep.key_label("noise.std.y", "heave") == "noise.std.y [m]"


def test_output_dir_refuses_a_non_empty_folder_and_never_reuses_a_default(tmp_path):
    from adaptive_mj.runs.runner import new_output_dir

    full = tmp_path / "full"
    full.mkdir()
    (full / "keep").write_text("keep")
    with pytest.raises(AdaptiveMJError, match=r"full: exists and is not an empty folder; choose a new -o DIR"):
        new_output_dir(full, "sweep-s", logs_dir=tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert new_output_dir(empty, "sweep-s", logs_dir=tmp_path) == empty
    a = new_output_dir(None, "sweep-s", logs_dir=tmp_path / "logs")
    b = new_output_dir(None, "sweep-s", logs_dir=tmp_path / "logs")
    assert a != b and a.is_dir() and b.is_dir() and a.name.startswith("sweep-s-")


# --------------------------------------------------------------------------
# the command end to end
FAST = ["--set", "simulation.duration=0.5", "--set", "events=[]"]


def test_sweep_end_to_end_logs_csv_json_png_match_the_logs(tmp_path, capsys):
    from adaptive_mj.log.replay import read_log

    out = tmp_path / "sweep"
    code = main(["sweep", "arm_payload_swap", "--grid", "payload_mass=0.5:2:2", "--seeds", "2", "--jobs", "2",
                 "-o", str(out), *FAST, "--set", "noise.std={y=0.001}"])
    printed = capsys.readouterr().out
    assert code == 0
    logs = sorted((out / "logs").glob("*.mcap"))
    assert [p.name for p in logs] == ["0000-payload_mass=0.5-seed0.mcap", "0001-payload_mass=0.5-seed1.mcap",
                                      "0002-payload_mass=2-seed0.mcap", "0003-payload_mass=2-seed1.mcap"]
    with open(out / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 4
    cols = list(table[0])
    assert cols[:5] == ["run", "plant.payload_mass", "seed", "status", "reason"] and cols[-1] == "log"
    assert {"rms_tracking_error_tail", "control_rms", "param_error_final.J", "param_error_final.g_cos"} <= set(cols)
    assert [(r["plant.payload_mass"], r["seed"], r["status"]) for r in table] == [
        ("0.5", "0", "ok"), ("0.5", "1", "ok"), ("2.0", "0", "ok"), ("2.0", "1", "ok")]
    for row in table:
        logged = read_log(out / row["log"])
        m = logged.summary["metrics"]
        assert float(row["rms_tracking_error_tail"]) == m["rms_tracking_error_tail"]
        assert float(row["param_error_final.J"]) == m["param_error_final"]["J"]
        assert logged.header["seed"] == int(row["seed"])
        assert f"plant.payload_mass={row['plant.payload_mass']}" in logged.overrides
    # the seeds differ (noise), the grid values differ (mass)
    assert table[0]["rms_tracking_error_tail"] != table[1]["rms_tracking_error_tail"]
    assert table[0]["control_rms"] != table[2]["control_rms"]

    saved = json.loads((out / "sweep.json").read_text())
    assert saved["inputs"]["scenario"].endswith("arm_payload_swap.toml")
    assert saved["inputs"]["grid"] == [{"expr": "payload_mass=0.5:2:2", "key": "plant.payload_mass",
                                        "values": [0.5, 2.0]}]
    assert saved["inputs"]["overrides"] == ["simulation.duration=0.5", "events=[]", "noise.std={y=0.001}"]
    assert saved["inputs"]["seeds"] == 2 and saved["counts"] == {"ok": 4}
    assert [r["rms_tracking_error_tail"] for r in saved["rows"]] == [float(r["rms_tracking_error_tail"])
                                                                     for r in table]
    assert (out / "sweep.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "sweep.png").stat().st_size > 10_000
    lines = printed.splitlines()
    assert lines[0].split() == ["payload_mass", "mean", "rms_tracking_error_tail", "ok/total"]
    assert [line.split()[0] for line in lines[1:3]] == ["0.5", "2"] and lines[1].split()[-1] == "2/2"
    assert lines[-1] == f"4/4 runs ok; output: {out}"


def test_sweep_records_diverged_runs_and_exits_1(tmp_path, capsys):
    out = tmp_path / "sweep"
    code = main(["sweep", "lecture_first_order", "--grid", "state_bound=0.2,5", "--jobs", "1", "-o", str(out),
                 "--set", "simulation.duration=2", "--set", "success.tail_rms=inf",  # 2 s: not converged yet
                 "--metric", "rms_tracking_error,control_rms"])
    assert code == 1
    with open(out / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [(r["simulation.state_bound"], r["status"]) for r in table] == [("0.2", "diverged"), ("5", "ok")]
    assert "beyond the bound 0.2" in table[0]["reason"]
    assert (out / table[0]["log"]).is_file()  # a diverged run keeps its log
    assert json.loads((out / "sweep.json").read_text())["counts"] == {"diverged": 1, "ok": 1}
    assert (out / "sweep.png").is_file()
    assert "1/2 runs ok" in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["--grid", "law.k=-1,1"], r"grid point law\.k=-1: .*law\.k must be >= 0, got -1\.0"),
    (["--grid", "law.k=1:2"], r"--grid 'law\.k=1:2': expected KEY=LO:HI:N or KEY=V1,V2,\.\.\."),
    (["--grid", "noise.seed=1,2"], r"noise\.seed is set per run; use --seeds N"),
    (["--grid", "law.k=1,2", "--grid", "k=3"], r"--grid 'k=3': law\.k is already a grid axis"),
    (["--grid", "law.k=1", "--metric", "rms"], r"--metric 'rms': expected one of rms_tracking_error, "),
    (["--grid", "law.k=1", "--seeds", "0"], r"--seeds must be an integer >= 1, got 0"),
    ([], r"sweep needs at least one --grid"),
])
def test_bad_input_exits_2_before_any_run(tmp_path, capsys, args, message):
    out = tmp_path / "sweep"
    code = main(["sweep", "arm_payload_swap", "-o", str(out), *FAST, *args])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("adaptive-mj: error: ")
    assert re.search(message, err), err
    assert not out.exists()  # nothing ran, no folder, no logs


def test_sweep_refuses_a_non_empty_output_folder(tmp_path, capsys):
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "old.csv").write_text("keep")
    assert main(["sweep", "arm_payload_swap", "--grid", "law.k=1", "-o", str(out), *FAST]) == 2
    assert "exists and is not an empty folder" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["old.csv"]


def test_progress_is_plain_lines_when_not_a_terminal():
    """Redirected output gets no carriage returns: a line at most every few seconds, and one at the end."""
    import io
    from pathlib import Path

    from adaptive_mj.study.parallel import PLAIN_PROGRESS_EVERY, RunSpec, RunOutcome, progress_printer

    class Pipe(io.StringIO):
        def isatty(self):
            return False

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    now = [0.0]
    pipe = Pipe()
    update = progress_printer(5, stream=pipe, clock=lambda: now[0])
    job = RunSpec(Path("x.toml"), tag="run")
    for t in (0.1, 0.2, PLAIN_PROGRESS_EVERY + 0.3, PLAIN_PROGRESS_EVERY + 0.4, PLAIN_PROGRESS_EVERY + 0.5):
        now[0] = t
        update(RunOutcome(job, "ok", None))
    lines = pipe.getvalue().splitlines()
    assert "\r" not in pipe.getvalue() and len(lines) == 2
    assert lines[0].startswith("3/5 runs done, 34.0/min after 5 s") and lines[1].startswith("5/5 runs")
    term = Terminal()  # on a terminal: a tqdm bar redrawn in place, closed with a newline after the last run
    update = progress_printer(2, stream=term)
    update(RunOutcome(job, "ok", None))
    update.retried(job, "its worker died")
    update(RunOutcome(job, "diverged", None))
    out = term.getvalue()
    assert out.startswith("\rruns:") and out.endswith("\n") and out.count("\n") == 2
    assert "\rretrying run: its worker died\n" in out  # a line of its own, above the bar
    final = out.rstrip("\n").rsplit("\r", 1)[1]
    assert "100%" in final and "2/2" in final and "failed 1, retried 1; last: run (diverged)" in final


def test_sweep_notes_what_the_grid_will_not_do():
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.study.sweep import sweep_notes

    arm = load(SCENARIOS_DIR / "arm_payload_swap.toml")
    notes = sweep_notes(arm, ["plant.payload_mass"], 2)
    assert len(notes) == 2
    assert notes[0].startswith("--seeds 2 on a scenario without noise (noise.std is empty): the seed changes nothing")
    assert notes[1] == ("plant.payload_mass sets the payload's initial mass only: events[0] still sets it to 2 kg "
                        "at t = 20 s in every run (override `events` to change or remove it)")
    assert sweep_notes(arm, ["noise.std.y"], 3) == []
    assert sweep_notes(load(SCENARIOS_DIR / "heave_drift.toml"), ["law.k"], 3) == []  # it has noise


def test_resume_finishes_a_killed_study_with_an_identical_table(tmp_path, capsys):
    """A study whose folder lost runs (missing logs, a log cut short as by SIGKILL, no table yet) is
    finished by --resume: only those runs run again, and sweep.csv is byte-identical to the
    uninterrupted study's. A resume with another grid is refused with one line."""
    from adaptive_mj.cli import main

    args = ["sweep", "heave_drift", "--grid", "law.k=100,200,300", "--seeds", "2", "--set", "simulation.duration=0.5",
            "--jobs", "2"]
    full = tmp_path / "full"
    assert main([*args, "-o", str(full)]) == 0
    assert (full / "manifest.json").is_file()
    study = tmp_path / "killed"
    import shutil

    shutil.copytree(full, study)
    (study / "sweep.csv").unlink()
    (study / "sweep.json").unlink()
    logs = sorted((study / "logs").glob("*.mcap"))
    assert len(logs) == 6
    logs[1].unlink()
    logs[4].unlink()
    data = logs[2].read_bytes()
    logs[2].write_bytes(data[: len(data) // 2])  # killed mid-write
    capsys.readouterr()
    assert main([*args, "--resume", str(study)]) == 0
    err = capsys.readouterr().err
    assert "(3 already finished, 3 to run)" in err
    assert (study / "sweep.csv").read_text() == (full / "sweep.csv").read_text()
    for a, b in zip(sorted((full / "logs").glob("*.mcap")), sorted((study / "logs").glob("*.mcap")), strict=True):
        from adaptive_mj.log.replay import read_log

        import numpy as np

        np.testing.assert_array_equal(read_log(a).trajectory.x, read_log(b).trajectory.x)
    assert main(["sweep", "heave_drift", "--grid", "law.k=100,200", "--seeds", "2", "--set",
                 "simulation.duration=0.5", "--resume", str(study)]) == 2
    line = capsys.readouterr().err.strip().splitlines()
    assert len(line) == 1 and "the study was started with grid ['law.k=100,200,300'], this command has " \
                               "['law.k=100,200']" in line[0]


def test_a_log_that_cannot_be_written_is_reported_and_the_study_goes_on(tmp_path):
    """A file-size limit (as a full disk) stops the long run's log: that run is reported as an error
    naming the log, the short run is ok, the table is written, and the cut log replays as truncated;
    `run` says it in one line with exit 1."""
    import subprocess
    import sys

    out = tmp_path / "out"
    script = (f"ulimit -f 60; exec {sys.executable} -m adaptive_mj sweep heave_tracking "
              f"--grid simulation.duration=1,20 --set success.tail_rms=inf -o {out} --jobs 1")
    r = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=300)
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    cut = out / "logs" / "0001-duration=20-seed0.mcap"
    assert f"{cut}: the log could not be written (File too large); what was written reads as truncated" in r.stderr
    rows = (out / "sweep.csv").read_text().splitlines()
    assert len(rows) == 3 and ",ok," in rows[1] and ",error," in rows[2]
    from adaptive_mj.log.replay import read_log

    logged = read_log(cut)
    assert logged.status == "truncated" and len(logged.trajectory) >= 100
    r = subprocess.run(["bash", "-c", f"ulimit -f 30; exec {sys.executable} -m adaptive_mj run heave_tracking "
                                      f"-o {tmp_path / 'run.mcap'}"], capture_output=True, text=True, timeout=300)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(err) == 1 and "the log could not be written (File too large)" in err[0]


def test_a_killed_local_worker_loses_no_run(tmp_path):
    """SIGKILL of a local worker process mid-run breaks the process pool: the runs it held are
    submitted again to a new pool (their half-written logs removed), the sweep completes with every
    run ok exactly once, and the table equals an undisturbed sweep's."""
    import os
    import signal
    import subprocess
    import sys
    import time

    args = ["sweep", "heave_tracking", "--grid", "law.k=150,250,350", "--set", "simulation.duration=100",
            "--jobs", "2"]
    env = dict(os.environ, MUJOCO_GL="egl")
    out = tmp_path / "killed"
    driver = subprocess.Popen([sys.executable, "-m", "adaptive_mj", *args, "-o", str(out)], cwd=REPO, env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    log = str(out / "logs" / "0000-k=150-seed0.mcap")
    deadline = time.monotonic() + 120
    victim = None
    while victim is None:
        assert time.monotonic() < deadline, "no worker wrote the first log"
        for child in Path(f"/proc/{driver.pid}/task/{driver.pid}/children").read_text().split():
            try:
                if any(os.readlink(fd) == log for fd in Path(f"/proc/{child}/fd").iterdir()):
                    victim = int(child)
            except OSError:
                continue
        time.sleep(0.02)
    time.sleep(0.2)
    os.kill(victim, signal.SIGKILL)
    _, stderr = driver.communicate(timeout=300)
    assert driver.returncode == 0, stderr
    assert "retrying 0000-k=150-seed0: attempt 2 of 4 (a worker process died)" in stderr
    rows = (out / "sweep.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == ["0000-k=150-seed0", "0001-k=250-seed0", "0002-k=350-seed0"]
    assert all(",ok," in r for r in rows)
    clean = tmp_path / "clean"
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", *args, "-o", str(clean)], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert (out / "sweep.csv").read_bytes() == (clean / "sweep.csv").read_bytes()



def _fake_jobs(monkeypatch, fake_run_job, folder: Path, *, n: int, crash: int):
    """n jobs for the local pool, job `crash` tagged "crash", each run by fake_run_job (the forked
    workers inherit the patch; a worker runs job.run_in_worker, which calls job.run_job) with no
    scenario compiled beforehand."""
    from adaptive_mj.study import job, parallel

    monkeypatch.setattr(job, "run_job", fake_run_job)
    monkeypatch.setattr(parallel, "_prewarm", lambda jobs, n_jobs=1: None)
    return [parallel.RunSpec(Path("unused.toml"), log=folder / f"{k}.mcap", tag="crash" if k == crash else f"run{k}")
            for k in range(n)]

def test_a_run_that_keeps_killing_its_worker_is_blamed_alone(tmp_path, monkeypatch):
    """Local pool, a run that kills its worker every time (as a segfault would): it is recorded as an
    error after the retry limit; every other run is ok exactly once (runs that had not started are
    never charged; the one beside it at the first death is re-run alone and passes)."""
    import os
    import time

    from adaptive_mj.study import parallel

    def fake_run_job(job):  # forked workers inherit this
        job.log.write_bytes(b"started")
        if job.tag == "crash":
            os._exit(1)
        time.sleep(0.05)
        return parallel.RunOutcome(job, "ok", {"tag": job.tag})

    jobs = _fake_jobs(monkeypatch, fake_run_job, tmp_path, n=12, crash=3)
    retried = []
    results = list(parallel.iter_results(jobs, parallel.Backend(jobs=2, retries=2),
                                         on_retry=lambda job, why: retried.append(job.tag)))
    assert sorted(i for i, _ in results) == list(range(12))
    by_index = dict(results)
    assert by_index[3].status == "error" and by_index[3].error == "a worker process died running it (tried 3 times)"
    assert all(by_index[k].status == "ok" and by_index[k].summary == {"tag": f"run{k}"} for k in range(12) if k != 3)
    assert retried.count("crash") == 2 and len(retried) <= 3, retried


def test_a_worker_dying_while_the_caller_is_busy_loses_no_run(tmp_path, monkeypatch):
    """The pool breaks while the caller handles a result, so the next submit finds it broken: that
    run goes back to the queue, nothing is lost, no exception reaches the caller."""
    import os
    import time

    from adaptive_mj.study import parallel

    marker = tmp_path / "crashed-once"

    def fake_run_job(job):
        job.log.write_bytes(b"started")
        if job.tag == "crash" and not marker.exists():
            marker.write_text("x")
            time.sleep(0.3)
            os._exit(1)
        return parallel.RunOutcome(job, "ok", {"tag": job.tag})

    jobs = _fake_jobs(monkeypatch, fake_run_job, tmp_path, n=20, crash=1)
    results = []
    for i, result in parallel.iter_results(jobs, parallel.Backend(jobs=2)):
        if not results:
            time.sleep(1.0)  # the crash happens meanwhile
        results.append((i, result))
    assert sorted(i for i, _ in results) == list(range(20))
    assert all(r.status == "ok" for _, r in results)


def test_a_sweep_whose_every_run_misses_its_criteria_shows_their_numbers_marked_failed(tmp_path, capsys,
                                                                                       monkeypatch):
    """Every run completes but misses success.tail_rms (1e-9): the table, report.md and the plot show each grid
    point's numbers (those in sweep.csv), marked "(failed)", not n/a and an empty plot (issue 35). Diverged runs
    stay out: their metrics are of a run cut short."""
    import matplotlib.pyplot as plt
    import numpy as np

    figures = []
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: (figures.append(fig), close(fig)))
    out = tmp_path / "sweep"
    assert main(["sweep", "lecture_first_order", "--grid", "law.k=2,50", "--set", "simulation.duration=1",
                 "--set", "success.tail_rms=1e-9", "--jobs", "1", "-o", str(out),
                 "--metric", "rms_tracking_error_tail,control_rms"]) == 1
    with open(out / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [r["status"] for r in table] == ["failed", "failed"]
    text = capsys.readouterr().out
    lines = text.splitlines()
    for row, line in zip(table, lines[1:3], strict=True):
        tail, control = float(row["rms_tracking_error_tail"]), float(row["control_rms"])
        assert line.split() == [row["law.k"], f"{tail:.4g}", "(failed)", f"{control:.4g}", "(failed)", "0/1"], line
    report = (out / "report.md").read_text()
    assert f"| 50 | {float(table[1]['rms_tracking_error_tail']):.6g} (failed) |" in report and "n/a" not in report
    fig = figures[-1]
    for ax, metric in zip(fig.axes, ("rms_tracking_error_tail", "control_rms"), strict=True):
        ys = sorted(float(y) for line in ax.lines for y in np.atleast_1d(line.get_ydata())
                    if line.get_transform() == ax.transData and np.isfinite(float(y)))
        assert {float(r[metric]) for r in table} <= set(ys), (metric, ys)


def test_point_stats_fall_back_to_failed_runs_only_where_no_ok_run_has_a_value():
    """ok runs first (the mean over them, as before); a point with no ok run takes its failed runs' values,
    marked; diverged runs never count."""
    rows = [(1, "ok", 1.0), (1, "failed", 9.0), (2, "failed", 3.0), (2, "failed", 5.0), (3, "diverged", 7.0)]
    table = [{"law.k": k, "seed": i % 2, "status": status, "e": e} for i, (k, status, e) in enumerate(rows)]
    one, two, three = sweep.point_stats(table, ["law.k"], "e")
    assert (one.mean, one.basis, one.failed_only, one.shown()) == (1.0, "ok", False, "1")
    assert (two.mean, two.lo, two.hi, two.failed_only, two.shown()) == (4.0, 3.0, 5.0, True, "4 (failed)")
    assert math.isnan(three.mean) and three.shown() == "n/a"
    text = sweep.summary_table(table, ["law.k"], ["e"])
    assert [line.split() for line in text.splitlines()[1:]] == [["1", "1", "1/2"], ["2", "4", "(failed)", "0/2"],
                                                                ["3", "n/a", "0/1"]]

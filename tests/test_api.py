"""The studies from Python (adaptive_mj.study.api): a sweep and a breaking point called with keyword
arguments return a Study (rows as dicts, a pandas-free table, the folder, report.md/.html, .plot());
the command line gives the same tables, being a layer over these; bad options fail with one line
before any folder is made."""
import csv
import math
import re

import pytest

from adaptive_mj import study
from adaptive_mj.cli import main
from adaptive_mj.errors import ScenarioError
from adaptive_mj.study import api

FAST = ["simulation.duration=0.5", "noise.std={y=0.001}", "success.tail_rms=inf"]


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("api") / "sweep"
    return study.sweep("heave_tracking", grid={"law.k": [100, 300]}, seeds=2, overrides=FAST, out=out, jobs=2)


def test_sweep_returns_rows_a_table_and_the_folder(swept):
    assert swept.kind == "sweep" and swept.ok and swept.exit_code == 0
    assert [(r["law.k"], r["seed"], r["status"]) for r in swept.rows] == [
        (100, 0, "ok"), (100, 1, "ok"), (300, 0, "ok"), (300, 1, "ok")]
    table = swept.table
    assert len(table) == 4 and table.columns[:5] == ("run", "law.k", "seed", "status", "reason")
    assert table.columns[-1] == "log" and table["seed"] == [0, 1, 0, 1]
    with open(swept.out / "sweep.csv", newline="") as f:
        csv_rows = list(csv.DictReader(f))
    assert [float(r["rms_tracking_error_tail"]) for r in csv_rows] == table["rms_tracking_error_tail"]
    assert all((swept.out / r["log"]).is_file() for r in swept.rows)
    assert swept.report == swept.out / "report.md" and swept.html == swept.out / "report.html"
    assert swept.html.is_file() and swept.info["keys"] == ["law.k"] and swept.info["counts"] == {"ok": 4}
    text = str(table).splitlines()
    assert text[0].split()[:3] == ["run", "law.k", "seed"] and len(text) == 5
    assert table.to_markdown().splitlines()[1] == "|" + "---|" * len(table.columns)
    with pytest.raises(KeyError, match=r"no column 'nope'; the columns are run, law\.k, seed"):
        table["nope"]
    assert '<table class="sortable">' in table._repr_html_()


def test_plot_draws_the_chosen_metrics(swept, tmp_path):
    path = swept.plot(tmp_path / "u.png", metrics=["control_rms", "rms_tracking_error"])
    assert path == tmp_path / "u.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000
    with pytest.raises(ScenarioError, match=r"--metric 'rms': expected one of"):
        swept.plot(tmp_path / "x.png", metrics=["rms"])


def test_the_command_line_gives_the_same_table(swept, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["sweep", "heave_tracking", "--grid", "law.k=100,300", "--seeds", "2", "--jobs", "2", "-o", str(out),
                 *[a for o in FAST for a in ("--set", o)]]) == 0
    assert (out / "sweep.csv").read_text() == (swept.out / "sweep.csv").read_text()
    assert capsys.readouterr().out.splitlines()[-1] == f"4/4 runs ok; output: {out}"


def test_grid_forms_are_the_same_expressions():
    assert api.grid_expressions({"law.k": [100, 2.5], "reference.kind": ["sine"]}) == [
        "law.k=100,2.5", 'reference.kind="sine"']
    assert api.grid_expressions({"payload_mass": "0.5:2:4"}) == ["payload_mass=0.5:2:4"]
    assert api.grid_expressions(["law.k=1,2", "seed_free=3"]) == ["law.k=1,2", "seed_free=3"]
    with pytest.raises(ScenarioError, match=r"grid\['law\.k'\]: expected a list of values or 'LO:HI:N', got 5"):
        api.grid_expressions({"law.k": 5})


@pytest.mark.parametrize("kwargs, message", [
    (dict(seeds=0), r"--seeds must be an integer >= 1, got 0"),
    (dict(jobs=0), r"--jobs must be an integer >= 1, got 0"),
    (dict(backend="cloud"), r"--backend must be one of local, ray, got 'cloud'"),
    (dict(ray_logs="shared"), r"--ray-logs is for --backend ray"),
    (dict(engine="gpu"), r"--engine must be one of process, batch, got 'gpu'"),
    (dict(logs="none"), r"--logs must be 'all' or 'summary', got 'none'"),
    (dict(resume="somewhere"), r"sweep --resume somewhere writes into that folder; -o .* cannot be combined"),
    (dict(grid={"law.k": [-1]}), r"grid point law\.k=-1: .*law\.k must be >= 0"),
    (dict(metrics=["rms"]), r"--metric 'rms': expected one of"),
])
def test_bad_options_raise_one_line_before_any_folder(tmp_path, kwargs, message):
    out = tmp_path / "never"
    args = dict(grid={"law.k": [100]}, overrides=FAST, out=out, jobs=1) | kwargs
    with pytest.raises(ScenarioError, match=message) as err:
        study.sweep("heave_tracking", **args)
    assert "\n" not in str(err.value)
    assert not out.exists()


def test_stress_and_bench_options_are_checked_first(tmp_path):
    with pytest.raises(ScenarioError, match=r"--duration must be > 0 \[s\], got -1"):
        study.stress(duration=-1, out=tmp_path / "s")
    with pytest.raises(ScenarioError, match=r"--steps must be an integer >= 0, got 1.5"):
        study.stress(steps=1.5, out=tmp_path / "s")
    with pytest.raises(ScenarioError, match=r"nope: no such scenario file, nor a bundled scenario"):
        study.bench(scenarios=["nope"], out=tmp_path / "b")
    assert not (tmp_path / "s").exists() and not (tmp_path / "b").exists()


def test_breaking_point_from_python(tmp_path):
    s = study.breaking_point("heave_tracking", key="simulation.control_delay", lo=0, hi=200, tail_bound=0.01,
                             steps=2, overrides=["simulation.duration=3"], out=tmp_path / "bp", jobs=2)
    assert s.kind == "breaking_point" and s.ok
    assert s.info["key"] == "simulation.control_delay" and s.info["integer"]
    assert 0 <= s.info["margin"] < s.info["first_fail"] <= 200
    values = s.table["value"]
    assert values == sorted(values) and {0, 200} <= set(values) and len(values) == 4
    assert all(r["passes"] == (r["value"] <= s.info["margin"]) for r in s.rows)
    assert re.match(r"\nsimulation\.control_delay: margin \d+", s.text)
    assert "Breaking point of simulation.control_delay" in (s.out / "report.md").read_text()
    assert s.plot(tmp_path / "bp.png").stat().st_size > 10_000
    with pytest.raises(ScenarioError, match=r"give key='KEY=LO:HI', or key='KEY' with both lo and hi"):
        study.breaking_point("heave_tracking", key="law.k", lo=1, tail_bound=1)


def test_the_command_modules_stay_modules_and_are_callable():
    from adaptive_mj.study import sweep

    assert callable(sweep) and sweep.parse_grid("law.k=1,2", {})[1] == [1, 2]
    assert study.Study is api.Study and study.Table is api.Table
    with pytest.raises(AttributeError, match="has no attribute 'nope'"):
        _ = study.nope


def test_stress_from_python_on_a_reduced_study(tmp_path, monkeypatch):
    """The stress study cut to two searches on the heave vehicle: its Study has a row per margin (as
    margins.csv), report.md and report.html with the same table, and plot() draws the margins' grid."""
    from adaptive_mj.study import stress as stress_module

    full = stress_module.study

    def two(**kw):
        return [s for s in full(**kw) if s.label == "heave/adaptive" and s.stressor.name in ("noise σ_y", "delay")]

    monkeypatch.setattr(stress_module, "study", two)
    s = study.stress(seeds=1, steps=1, duration=1.0, out=tmp_path / "stress", jobs=2)
    assert s.kind == "stress" and s.ok and [r["stressor"] for r in s.rows] == ["noise σ_y", "delay"]
    with open(s.out / "margins.csv", newline="") as f:
        assert [r["stressor"] for r in csv.DictReader(f)] == s.table["stressor"]
    assert all(r["lo"] < r["hi"] and 0.0 <= stress_module.margin_position(r) <= 1.0 for r in s.rows)
    html = s.html.read_text()
    assert "<td>heave/adaptive</td>" in html and "breaking-point searches" in html
    png = s.plot(tmp_path / "margins.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_margin_position_is_on_the_bisections_scale():
    from adaptive_mj.study.stress import margin_position

    row = {"lo": 1e-4, "hi": 0.1, "margin": 1e-2, "first_fail": 2e-2}
    assert margin_position(row) == pytest.approx(2 / 3)  # geometric: 3 decades, 2 of them passed
    assert margin_position({**row, "lo": 0, "hi": 200, "margin": 50, "first_fail": 60}) == 0.25
    assert margin_position({**row, "margin": None}) == 0.0 and margin_position({**row, "first_fail": None}) == 1.0


def test_overrides_given_as_python_values_are_the_same_run_as_the_set_expressions():
    """run_scenario(set={key: value}) writes each value as the TOML a scenario holds: the same run as the strings."""
    from adaptive_mj import run_scenario

    typed = run_scenario("heave_tracking", set={"simulation.duration": 0.5, "noise.std": {"y": 0.001},
                                                "success.tail_rms": math.inf, "law.k": 150})
    text = run_scenario("heave_tracking", set=[*FAST, "law.k=150"])
    assert typed.summary == text.summary and typed.trajectory.x.tobytes() == text.trajectory.x.tobytes()
    assert api.overrides_of("--set", {"law.dead_zone": {"width": 0.01}, "law.kind": "sigma", "x": [1, True]}) == [
        "law.dead_zone={width = 0.01}", 'law.kind="sigma"', "x=[1, true]"]
    with pytest.raises(ScenarioError, match=r"--set: expected scenario keys \(e\.g\. 'law\.k'\) as the dict's keys, "
                                            r"got 3"):
        api.overrides_of("--set", {3: 1})

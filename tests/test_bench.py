"""adaptive-mj bench on a reduced catalogue: report, figures, logs and
summary.json are written, a diverged run is reported and the rest go on."""
import json

import pytest

from adaptive_mj.study import bench, bench_catalogue
from adaptive_mj.cli import main


@pytest.fixture
def small_catalogue(monkeypatch):
    full = bench_catalogue.catalogue

    def reduced(*, quick, logs):
        sections = full(quick=quick, logs=logs)
        keep = {s.key: s for s in sections if s.key in ("first_order", "phase", "payload_swap")}
        out = []
        for s in keep.values():
            swap = ("simulation.duration=2.0", "events=[{t=1.0, kind='payload_mass', value=2.0}]")
            jobs = tuple(type(j)(scenario=j.scenario, overrides=j.overrides + ("simulation.duration=1.0",)
                                 if s.key != "payload_swap" else j.overrides + swap,
                                 log=j.log, tag=j.tag, extras=j.extras) for j in s.jobs)
            out.append(bench_catalogue.Section(s.key, s.title, s.claim, jobs, s.analyze))
        # one run that diverges on purpose: the bench must go on
        div = bench_catalogue._job("diverge", "lecture_heave", "lecture_heave", logs, ["simulation.state_bound=0.5"],
                                   expect="fail")
        out.append(bench_catalogue.Section("diverge", "Divergence", "none", (div,),
                                           lambda res, out_dir: bench_catalogue.SectionReport(
                                               "diverged run: " + res[div.tag].status,
                                               [bench_catalogue._row("diverge", "x", res[div.tag])])))
        return out

    monkeypatch.setattr(bench_catalogue, "catalogue", reduced)


def test_quick_bench_on_a_reduced_catalogue(tmp_path, small_catalogue, capsys):
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "-o", str(out), "--jobs", "2"]) == 0
    report = (out / "report.md").read_text()
    for title in ("1. Adaptive control of a first-order system", "2. Phase-space view", "7. Payload swap on the arm",
                  "Divergence"):
        assert f"## {title}" in report
    assert "diverged run: diverged" in report
    for fig in ("first_order", "phase_portrait", "payload_swap"):
        assert (out / "figures" / f"{fig}.png").stat().st_size > 10_000
        assert f"figures/{fig}.png" in report
    html = (out / "report.html").read_text()  # the same report for a browser: every figure embedded
    assert html.count('src="data:image/png;base64,') == 3 and "not found" not in html
    assert "<td>first-order</td>" in html and "diverged run: diverged" in html
    summary = json.loads((out / "summary.json").read_text())
    assert summary["diverge/lecture_heave"]["status"] == "diverged"
    # cut to 1 s, the lecture's first-order run has not converged: its verdict says so, the section still reports it
    first = summary["first_order/lecture"]
    assert first["status"] == "failed" and "(success.tail_rms)" in first["summary"]["reason"]
    assert "## 1. Adaptive control of a first-order system" in report and "Run failed." not in report
    assert summary["payload_swap/adaptive"]["extras"]["swap_response"]["event_time"] == 1.0
    logs = sorted(p.name for p in (out / "logs").glob("*.mcap"))
    assert len(logs) == len(summary)
    # the disk the logs take, stated from the files written (10⁶ bytes per MB)
    mb = sum(p.stat().st_size for p in (out / "logs").rglob("*") if p.is_file()) / 1e6
    assert f"The logs take {mb:.0f} MB." in report
    # each run against what it was declared for: the divergence is a demonstration meant to fail; the lecture's
    # first-order run is meant to pass, and cut to 1 s it fails: counted, and named, as unexpected
    assert summary["diverge/lecture_heave"]["expected"] == "fail" and summary["diverge/lecture_heave"]["as_expected"]
    assert summary["first_order/lecture"]["expected"] == "ok" and summary["first_order/lecture"]["as_expected"] is False
    unexpected = sorted(tag for tag, v in summary.items() if v["as_expected"] is False)
    assert "first_order/lecture" in unexpected
    assert f"**{len(unexpected)} unexpected** (" in report and "`first_order/lecture`" in report.split("\n\n")[1]
    assert "1 failing as meant" in report and "| failed (unexpected) |" in report and "diverged (as meant)" in report
    printed = capsys.readouterr().out
    assert "section" in printed and "report:" in printed
    # the terminal says what the report's headline says, and marks every run that is not ok with what it was for
    assert f"{len(unexpected)} unexpected (" in printed and "ended as expected" in printed
    assert bench.STATUS_LEGEND in printed
    lines = printed.split(bench.STATUS_LEGEND)[0].splitlines()
    head = next(i for i, line in enumerate(lines) if line.lstrip().startswith("section"))
    a, b = lines[head].index("status"), lines[head].index("rms err tail")  # the status column (text: left-aligned)
    statuses = [line[a:b].strip() for line in lines[head + 2:] if line.strip()]
    assert len(statuses) == len(summary) and "ok" in statuses
    assert all(s == "ok" or s.endswith(("(as meant)", "(measured)", "(unexpected)")) for s in statuses), statuses


def test_the_results_page_is_written_from_the_run_and_its_numbers_are_summary_json_s(tmp_path, small_catalogue):
    """bench --results FILE (docs/RESULTS.md in the repository): the page the docs link to, written from the run
    itself; every run's tail error on it is the one summary.json holds, formatted as the main table formats it."""
    import re

    out, page = tmp_path / "bench", tmp_path / "RESULTS.md"
    assert main(["bench", "--quick", "-o", str(out), "--jobs", "2", "--results", str(page)]) == 0
    text = page.read_text()
    assert text == (out / "results.md").read_text()
    assert text.startswith("# Measured results\n\nWritten by `adaptive-mj bench --quick --results docs/RESULTS.md` on ")
    assert re.search(r"on 20\d\d-\d\d-\d\d \d\d:\d\d UTC: adaptive-mj ", text) and "ended as expected" in text
    summary = json.loads((out / "summary.json").read_text())
    rows = [line.split(" | ") for line in text.splitlines() if line.startswith("| ") and not line.startswith(
        ("| run |", "|---"))]
    assert len(rows) == len(summary)
    measured = sorted("n/a" if v is None else format(v, ".3g") for v in (
        ((e.get("summary") or {}).get("metrics") or {}).get("rms_tracking_error_tail") for e in summary.values()))
    assert sorted(row[2].split(" ")[0] for row in rows) == measured  # (a row's run label is not its tag)
    assert sorted(row[1].split(" ")[0] for row in rows) == sorted(e["status"] for e in summary.values())


def test_every_status_but_an_expected_ok_is_marked_with_what_the_run_was_for():
    rows = {("ok", "ok", True): "ok", ("failed", "ok", False): "failed (unexpected)",
            ("failed", "fail", True): "failed (as meant)", ("diverged", "fail", True): "diverged (as meant)",
            ("ok", "fail", False): "ok (unexpected)", ("failed", "measured", None): "failed (measured)",
            ("crashed", "measured", None): "crashed (measured)", ("ok", "measured", None): "ok"}
    for (status, expect, as_expected), shown in rows.items():
        assert bench.status_text({"status": status, "expect": expect, "as_expected": as_expected}) == shown


def test_bench_only_runs_the_sections_asked_for_and_refuses_a_key_it_does_not_know(tmp_path, small_catalogue, capsys):
    """`bench --only KEY` (repeatable, or KEY,KEY): those sections alone, the report saying so; a key that names no
    section, or the breaking-point study under --quick (which has none), is refused in one line naming the keys."""
    out = tmp_path / "bench"
    assert main(["bench", "--quick", "--only", "phase", "-o", str(out), "--jobs", "2"]) == 0
    report = (out / "report.md").read_text()
    assert [line for line in report.splitlines() if line.startswith("## ")] == ["## 2. Phase-space view"]
    assert "**Only the sections asked for** (`--only`): `phase`." in report
    assert {tag.split("/")[0] for tag in json.loads((out / "summary.json").read_text())} == {"phase"}
    capsys.readouterr()
    nope = "--only 'nope': not a section of the bench (sections: first_order, phase, lyapunov, "
    study = "--only breaking_points: bench --quick runs no breaking-point study\n"
    for only, says in ((["phase", "nope"], nope), (["phase,breaking_points"], study), (["breaking_points"], study)):
        assert main(["bench", "--quick", *[a for o in only for a in ("--only", o)], "-o", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"adaptive-mj: error: {says}") and err.count("\n") == 1, err
        assert says == study or err.endswith(", quadrotor, breaking_points)\n"), err  # every key, the study's last
    assert not (tmp_path / "x").exists()


def test_bench_refuses_a_non_empty_output_dir(tmp_path):
    (tmp_path / "keep.txt").write_text("x")
    assert main(["bench", "--quick", "-o", str(tmp_path)]) == 2


def test_bench_from_python_returns_its_main_table(tmp_path, small_catalogue):
    from adaptive_mj import study

    s = study.bench(quick=True, out=tmp_path / "b", jobs=2)
    assert s.kind == "bench" and s.ok and s.html == tmp_path / "b" / "report.html"
    assert ("Divergence" not in s.table["section"]) and ("diverge", "x") in zip(s.table["section"], s.table["run"],
                                                                               strict=True)
    assert {r["status"] for r in s.rows} >= {"ok", "diverged"}
    png = s.plot()
    assert png == tmp_path / "b" / "figures" / "tails.png" and png.stat().st_size > 10_000


def test_the_bench_s_breaking_point_runs_log_their_summary_and_a_row_per_second(tmp_path):
    """The study's margins come from the full-rate rows; its logs keep the summary and a row per second
    (stress.SUMMARY_LOG_RATE_HZ) unless `bench --full-logs`."""
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.study.stress import SUMMARY_LOG_RATE_HZ, run_study

    kw = dict(seeds=1, steps=0, composite=False, n_jobs=2, duration=3.0, plant_names=("heave",))
    slim, text, _ = run_study(tmp_path / "slim", log_rate_hz=SUMMARY_LOG_RATE_HZ, **kw)
    full, _, _ = run_study(tmp_path / "full", **kw)
    assert "a row every 1 s" in text
    assert [[ev.tails for ev in m.evaluations] for m in slim] == [[ev.tails for ev in m.evaluations] for m in full]
    one = sorted((tmp_path / "slim" / "logs").rglob("*.mcap"))[0]
    same = tmp_path / "full" / one.relative_to(tmp_path / "slim")
    assert len(read_log(one).trajectory.t) <= 5 < len(read_log(same).trajectory.t)  # 3 s: rows at 0, 1, 2 s (+ last)


def test_the_quadrotor_margin_grid_logs_summaries_unless_full_logs_and_judges_on_the_full_trajectory(tmp_path):
    """Bench section 18's margin grid (a breaking-point kind of study: 432 of the bench's runs) logs its summary and a
    row per second by default; `bench --full-logs` gives every row; a run's success is the same either way."""
    from adaptive_mj.study import bench_catalogue, flight
    from adaptive_mj.study.job import SUMMARY_LOG_RATE_HZ, run_job
    from adaptive_mj.study.sections import quadrotor_flight

    slim = quadrotor_flight.section(True, tmp_path / "a", duration=1.0)
    full = quadrotor_flight.section(True, tmp_path / "b", duration=1.0, full_logs=True)
    grid = [j for j in slim.jobs if "quadrotor-margins" in str(j.log)]
    assert grid and all(f"log.rate_hz={SUMMARY_LOG_RATE_HZ!r}" in j.overrides for j in grid)
    assert not any(o == f"log.rate_hz={SUMMARY_LOG_RATE_HZ!r}" for j in full.jobs for o in j.overrides)  # 20 Hz
    tags = [s.key for s in bench_catalogue.catalogue(quick=True, logs=tmp_path / "c", full_logs=True)]
    assert "quadrotor" in tags
    one = grid[len(grid) // 2]
    twin = next(j for j in full.jobs if j.tag == one.tag)
    a, b = run_job(one), run_job(twin)
    assert flight.succeeded(a) == flight.succeeded(b) and a.summary["metrics"] == b.summary["metrics"]
    from adaptive_mj.log.replay import read_log

    assert len(read_log(one.log).trajectory.t) <= 2 < len(read_log(twin.log).trajectory.t)  # 1 s: 1 Hz against 20 Hz


def test_full_bench_runs_the_analyses_beside_the_breaking_point_study(tmp_path, small_catalogue, monkeypatch):
    """The full bench draws its sections' analyses and figures in a forked process while the breaking-point study
    runs (adaptive_mj.study.beside): the same report, section 14 in its place, the figures written by that process."""
    from adaptive_mj.study import stress
    from adaptive_mj.study.beside import can_fork

    monkeypatch.setattr(stress, "BENCH_SETTINGS", {"seeds": 1, "steps": 0, "duration": 1.0,
                                                   "plant_laws": {"ur5e": ("adaptive",)}, "plant_names": ("heave",)})
    out = tmp_path / "bench"
    assert main(["bench", "-o", str(out), "--jobs", "2"]) == 0
    report = (out / "report.md").read_text()
    titles = [line for line in report.splitlines() if line.startswith("## ")]
    assert titles[:3] == ["## 1. Adaptive control of a first-order system", "## 2. Phase-space view",
                          "## 7. Payload swap on the arm"]
    assert titles[3].startswith("## 14. Breaking points") and titles[-1] == "## Divergence"
    for fig in ("first_order", "phase_portrait", "payload_swap"):
        assert (out / "figures" / f"{fig}.png").stat().st_size > 10_000
    assert ("(in a process of their own, beside the breaking-point study)" in report) == can_fork()
    assert "diverged run: diverged" in report


def test_the_bench_s_progress_counts_runs_not_ok_and_of_them_the_unexpected_not_failed_526():
    """The bench's progress said "failed 526" of runs most of which failed as meant or are measurements: where runs
    declare what they are for, it says how many are not ok and how many of those did not end as declared."""
    import io
    from pathlib import Path

    from adaptive_mj.study.parallel import RunOutcome, RunSpec, progress_printer

    stream = io.StringIO()
    update = progress_printer(4, stream=stream, clock=lambda: 0.0)
    for expect, status in (("ok", "ok"), ("fail", "diverged"), ("measured", "failed"), ("ok", "failed")):
        update(RunOutcome(RunSpec(Path("x.toml"), tag=f"{expect}-{status}", expect=expect), status, None))
    assert stream.getvalue().startswith("4/4 runs done, not ok 3 (1 unexpected), ")


def test_the_breaking_point_study_s_probes_are_measurements_so_its_progress_says_not_ok():
    """The newcomer's bench printed "failed 546" through its breaking-point study, whose probes are meant to find
    where each law fails: every probe is declared a measurement (RunSpec.expect "measured"), so the progress line
    counts them "not ok N (0 unexpected)"."""
    import io
    from pathlib import Path

    from adaptive_mj.study import breaking_point as bp
    from adaptive_mj.study.parallel import RunOutcome, progress_printer
    from adaptive_mj.study.stress import BENCH_SETTINGS, study

    searches = study(composite=False, duration=BENCH_SETTINGS["duration"], plant_laws=BENCH_SETTINGS["plant_laws"],
                     plant_names=BENCH_SETTINGS["plant_names"])[:3]
    batches = bp._Batches(searches, [], seeds=2, logs=Path("logs"), n_jobs=1, backend=None, on_done=None,
                          keep_trajectory=False, screen=False)
    jobs = [job for i, s in enumerate(searches) for job in batches.jobs_for(i, s.stressor.hi, range(2))]
    assert len(jobs) == 6 and {job.expect for job in jobs} == {"measured"}
    stream = io.StringIO()
    update = progress_printer(len(jobs), stream=stream, clock=lambda: 0.0)
    for job in jobs:
        update(RunOutcome(job, "failed", None))
    assert stream.getvalue().startswith("6/6 runs done, not ok 6 (0 unexpected), "), stream.getvalue()

"""adaptive-mj bench: run the catalogue of lecture-7 phenomena headless, in
parallel processes, and write DIR/report.md (tables + PNG figures),
DIR/summary.json (every run's summary object) and one MCAP log per run in
DIR/logs/. A run that diverges is reported as diverged; the rest go on.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from adaptive_mj.study import callable_module
from adaptive_mj.report.html import write_html
from adaptive_mj.report.metrics import TAIL_FRACTION
from adaptive_mj.study.beside import Beside
from adaptive_mj.study.job import RunOutcome, as_expected
from adaptive_mj.study.parallel import Backend, progress_printer, run_jobs, session
from adaptive_mj.study.result import Study, Table
from adaptive_mj.study.sections.quadrotor_flight import MARGIN_LOGS
from adaptive_mj.trajectory import Status


def _fmt(v, spec=".3g") -> str:
    if v is None:
        return "n/a"
    if isinstance(v, str):
        return v
    return format(v, spec)


def status_text(r: dict) -> str:
    """A row's status as the tables show it: "(unexpected)" after a run that did not end as declared
    (RunSpec.expect), "(as meant)" after a demonstration that failed as it was meant to, "(measured)" after a
    measured run that is not ok (a baseline, a sweep point or a margin probe: its verdict is the result). A plain
    status is an ok run meant to be ok, so no failure in the table goes unexplained (STATUS_LEGEND)."""
    if r.get("as_expected") is False:
        return f"{r['status']} (unexpected)"
    if r.get("as_expected") and r["status"] != Status.OK:
        return f"{r['status']} (as meant)"
    if r.get("expect") == "measured" and r["status"] != Status.OK:
        return f"{r['status']} (measured)"
    return str(r["status"])


#: what status_text's marks mean, printed under the terminal's table
STATUS_LEGEND = ("(as meant): a demonstration of a failure mode, declared to fail; (measured): a baseline, sweep "
                 "point or margin probe whose verdict is the result; (unexpected): did not end as declared")


def main_table(rows: list[dict]) -> Table:
    """The main table: one row per run, each number with its unit (the run's output and control units); its
    to_text is the terminal's, its to_markdown report.md's (and so a sortable table in report.html)."""
    def with_unit(v, unit: str) -> str:
        return _fmt(v) + (f" {unit}" if v is not None and unit and unit != "-" else "")

    return Table.of([{"section": r["section"], "run": r["run"], "status": status_text(r),
                      "rms err tail": with_unit(r.get("tail"), r.get("y_unit", "")),
                      "u rms": with_unit(r.get("u_rms"), r.get("u_unit", "")),
                      "u TV": with_unit(r.get("u_tv"), r.get("u_unit", "")), "key result": r.get("key", "")}
                     for r in rows], MAIN_COLUMNS)


MAIN_COLUMNS = ("section", "run", "status", "rms err tail", "u rms", "u TV", "key result")
TEXT_LEFT = ("section", "run", "status", "key result")  # the terminal table's text columns (numbers: right)


#: `bench --only`'s key for the full bench's breaking-point study (section 14, not a catalogue section)
BREAKING_POINTS = "breaking_points"


def section_keys() -> list[str]:
    """The keys `bench --only` takes: every catalogue section's (in the report's order) and BREAKING_POINTS."""
    from adaptive_mj.study.sections.common import entries

    import adaptive_mj.study.bench_catalogue  # noqa: F401 (imported for its sections' registration)

    return [e.key for e in entries()] + [BREAKING_POINTS]


def run_bench(*, quick: bool, scenarios: list, out, backend: Backend, law: str | None = None,
              gains: Path | None = None, sets: tuple[str, ...] = (), full_logs: bool = False,
              only: tuple[str, ...] | None = None, results: Path | None = None) -> Study:
    """The bench with options adaptive_mj.study.api.bench has checked: the catalogue (quick: shorter runs,
    no breaking-point study) and a section for the user's scenario files, written to `out`. law: a law kind
    (built in or a plugin) with its `gains` file and --set keys, scored against the baselines in a section of
    its own (adaptive-mj score's quick suite, in `out/score`) and, in the full bench, added to the
    breaking-point study's laws on the plants it serves. full_logs: the breaking-point study's runs log every row
    (default: their summary and a row per second, job.SUMMARY_LOG_RATE_HZ, as do the quadrotor margin grid's; the
    catalogue's other runs log in full). only: the keys of the sections to run (section_keys(); BREAKING_POINTS: the
    full bench's study), None for all of them. results: a file to write the measured results page to (results_page;
    `results.md` in `out` is written in any case)."""
    from adaptive_mj.study.bench_catalogue import catalogue

    from adaptive_mj.runs.runner import new_output_dir

    scoring = None
    if law is not None:  # every option and the law's gains checked before any run (adaptive_mj.study.score.plan)
        from adaptive_mj.study.score import plan

        scoring = dict(law=law, gains=gains, sets=sets)
        plan(law, label=None, sets=sets, gains=gains, against=None, suite_name="quick", seeds=None, plants=None)

    if scenarios:  # a scenario of yours that cannot run fails now: checked and built, not after the catalogue
        from adaptive_mj.setup.build import check
        from adaptive_mj.setup.scenario import load

        for path in scenarios:
            check(load(path))
    out = new_output_dir(out, "bench-quick" if quick else "bench")
    sections = catalogue(quick=quick, logs=out / "logs", **({"full_logs": True} if full_logs else {}))
    if only is not None:
        sections = [s for s in sections if s.key in only]
    if scenarios:
        from adaptive_mj.study.bench_catalogue import user_section

        sections.append(user_section(list(scenarios), out / "logs"))
    jobs = [job for s in sections for job in s.jobs]
    with session(backend):
        return _bench(quick, out, sections, jobs, backend, scoring, full_logs, only, results)


def _number(title: str) -> float:
    """A section's number ("15. Ship steering ..." -> 15); inf for one without (the user's scenarios)."""
    head = title.split(".", 1)[0]
    return float(head) if head.isdigit() else float("inf")


def _law_section(out: Path, backend: Backend, law: str, gains: Path | None, sets: tuple[str, ...]) -> tuple[str, int]:
    """`bench --law`: the law scored against the baselines (score's quick suite, into out/score) as a report
    section (its leaderboards, figures and how it scores), and the number of runs it took."""
    from adaptive_mj.study.score import run_score

    card = run_score(law, sets=sets, gains=gains, out=out / "score", backend=backend)
    text = (out / "score" / "scorecard.md").read_text(encoding="utf-8")
    body = text.split("\n", 1)[1].replace("](", "](score/").replace("\n## ", "\n### ")
    runs = card.data["runs"]["tasks"] + card.data["runs"]["margins"]
    notes = "".join(f"\n- {note}" for note in card.notes)
    body += f"\n**Runs that could not be set up:**{notes}\n" if notes else ""
    return (f"## Your law: {law} against the baselines\n\n**The lecture:** an adaptive law is judged by how it "
            "tracks, re-adapts after a change and holds still under noise, and by how far it goes before it fails; "
            f"`adaptive-mj score {law}` ranks it on every plant it serves (the whole card: `score/scorecard.md`)."
            f"\n{body}\n"), runs


def expectation_text(results: list[RunOutcome]) -> str:
    """The catalogue's runs against what each was declared for (RunSpec.expect): "N as expected (K ok, M failing as
    meant: demonstrations), U unexpected: tags; X measured (baselines, sweeps, margin probes: Y of them ok)"."""
    ok_ok = sum(1 for r in results if r.job.expect == "ok" and r.status == Status.OK)
    meant = sum(1 for r in results if r.job.expect == "fail" and as_expected(r))
    unexpected = [r.job.tag for r in results if as_expected(r) is False]
    measured = [r for r in results if r.job.expect == "measured"]
    text = (f"Of the {len(results)} catalogue runs, {ok_ok + meant} ended as expected ({ok_ok} ok, {meant} failing "
            f"as meant: demonstrations of a failure mode), **{len(unexpected)} unexpected**")
    if unexpected:
        shown = ", ".join(f"`{t}`" for t in unexpected[:20]) + (" ..." if len(unexpected) > 20 else "")
        text += f" ({shown})"
    return text + (f"; {len(measured)} are measurements whose verdict is the result (baselines, sweep points and "
                   f"margin probes: {sum(r.status == Status.OK for r in measured)} of them ok).")


def _git_commit() -> str:
    """The repository's commit the bench ran from (short hash, "+dirty" with local changes), or "" outside a git
    checkout (an installed wheel)."""
    import subprocess

    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return ""
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=here,
                               capture_output=True, text=True, timeout=10)
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return ""


def results_page(rows: list[dict], results: list[RunOutcome], *, quick: bool, elapsed: float, n_runs: int,
                 where: str) -> str:
    """docs/RESULTS.md as the bench writes it from its own run (`results.md` in its folder; `bench --results FILE`
    copies it): when and on what it ran, the headline (how many runs ended as declared), then per section its main
    table's rows (status, tail RMS error with its unit, the key result): every number measured in that run, none
    typed by hand."""
    import datetime
    import platform

    import mujoco

    from adaptive_mj import __version__

    now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    commit = _git_commit()
    lines = ["# Measured results", "",
             f"Written by `adaptive-mj bench{' --quick' if quick else ''} --results docs/RESULTS.md` on {now}: "
             f"adaptive-mj {__version__}" + (f" (commit {commit})" if commit else "") + f", mujoco "
             f"{mujoco.__version__}, Python {platform.python_version()}, {where}; {n_runs} runs in {elapsed:.0f} s "
             "wall time. Every figure below was measured in that run; the bench's report (`report.md`, "
             "`report.html`, beside this page's copy in its folder) has each section's analysis and figures. Run "
             "the same command to measure them on your machine.", "",
             expectation_text(results).replace("**", ""), "",
             f"Status marks: {STATUS_LEGEND}. Tail: the last {100 * TAIL_FRACTION:g} % of a run (docs/METRICS.md).",
             ""]
    sections = list(dict.fromkeys(r["section"] for r in rows))
    for section in sections:
        lines += [f"## {section}", "", "| run | status | tail RMS error | key result |", "|---|---|---|---|"]
        for r in (r for r in rows if r["section"] == section):
            unit = r.get("y_unit", "")
            tail = _fmt(r.get("tail")) + (f" {unit}" if r.get("tail") is not None and unit and unit != "-" else "")
            key = str(r.get("key", "")).replace("|", "\\|").replace("\n", " ")
            lines.append(f"| {r['run']} | {status_text(r)} | {tail} | {key} |")
        lines.append("")
    return "\n".join(lines)


def _disk_mb(folder: Path) -> float:
    """[MB] what the files under `folder` take (10⁶ bytes)."""
    return sum(f.stat().st_size for f in folder.rglob("*") if f.is_file()) / 1e6 if folder.exists() else 0.0


def _bench(quick: bool, out, sections, jobs, backend, scoring: dict | None = None, full_logs: bool = False,
           only: tuple[str, ...] | None = None, results_file: Path | None = None) -> Study:
    t0 = time.perf_counter()
    study = not quick and (only is None or BREAKING_POINTS in only)  # the breaking-point study: the full bench's
    results = run_jobs(jobs, backend=backend, on_done=progress_printer(len(jobs)))
    run_seconds = time.perf_counter() - t0
    by_tag = {r.job.tag: r for r in results}

    def analyses() -> tuple[list[str], list[dict], float]:
        """Every section's report text and main-table rows (its figures written under `out`), and the seconds taken."""
        t_analyses, parts, rows = time.perf_counter(), [], []
        for section in sections:
            rep = section.analyze({job.tag: by_tag[job.tag] for job in section.jobs}, out)
            parts.append(f"## {section.title}\n\n**The lecture:** {section.claim}\n\n{rep.text}\n")
            rows.extend(rep.rows)
        return parts, rows, time.perf_counter() - t_analyses

    # the full bench: the analyses and figures in a forked process beside the breaking-point study (both cores
    # busy meanwhile, adaptive_mj.study.beside); quick, or where fork is unsafe: here, before it
    beside = Beside(analyses, fork=None if study and backend.kind == "local" else False)
    overlapped = beside.forked
    n_runs = len(results)
    study_seconds = 0.0
    if not study:
        parts, rows, analysis_seconds = beside.result()
    else:  # the breaking-point study: its own batches (bisection), a reduced `adaptive-mj stress`
        from adaptive_mj.study.stress import BENCH_SETTINGS, SUMMARY_LOG_RATE_HZ, run_study

        extra = {}
        if scoring is not None:
            from adaptive_mj.study.score import read_gains

            extra = {"law": scoring["law"], "sets": tuple(scoring["sets"]), "gains": read_gains(scoring["gains"])}
        t_study = time.perf_counter()
        try:
            margins, text, _ = run_study(out / "stress", n_jobs=backend.jobs, composite=False, backend=backend,
                                         log_rate_hz=None if full_logs else SUMMARY_LOG_RATE_HZ, **BENCH_SETTINGS,
                                         **extra)
        except BaseException:
            beside.cancel()
            raise
        study_seconds = time.perf_counter() - t_study
        parts, rows, analysis_seconds = beside.result()
        n_runs += sum(len(e.tails) for m in margins for e in m.evaluations)
        before = sum(1 for section in sections if _number(section.title) < 14)  # in order: before 15, 16, ...
        parts.insert(before, "## 14. Breaking points: law × stressor margins\n\n**The lecture:** the modifications "
                     "make adaptation robust to noise, disturbances and unmodelled dynamics; here is how far each law "
                     f"goes before it fails.\n\n{text}\n\n(Logs in `stress/logs/`. `adaptive-mj stress` runs the "
                     "study at full size: 20 s runs, 4 bisection steps, optionally composite adaptation.)\n")
    if scoring is not None:
        section, runs = _law_section(out, backend, **scoring)
        parts.append(section)
        n_runs += runs
    elapsed = time.perf_counter() - t0
    failed = [r for r in results if r.status == Status.ERROR]  # diverged runs are results, not failures
    header = (f"# adaptive-mj benchmark report{' (quick)' if quick else ''}\n\n"
              f"{n_runs} runs on MuJoCo physics and "
              f"the analytic twin, {_where(backend)}. {expectation_text(results)} The {len(results)} catalogue runs "
              f"took {run_seconds:.1f} s, their sections' analyses and figures {analysis_seconds:.1f} s"
              + (" (in a process of their own, beside the breaking-point study)" if overlapped else "")
              + ("" if not study else f", the breaking-point study {study_seconds:.1f} s")
              + f", the whole bench {elapsed:.1f} s wall time. Every number below was measured in this run; "
              f"every catalogue run's MCAP log is in `logs/`"
              + ("" if full_logs or not (out / "logs" / MARGIN_LOGS).is_dir() else
                 f" (the quadrotor margin grid's, `logs/{MARGIN_LOGS}/`, each its summary and a row per second)")
              + ("" if not study else ", the breaking-point study's in `stress/logs/`"
                 + ("" if full_logs else " (each its summary and a row per second: `bench --full-logs` keeps every "
                    "row)"))
              + " (replay with `adaptive-mj replay logs/<run>.mcap --verify`). "
              + f"The logs take {_disk_mb(out / 'logs'):.0f} MB"
              + ("" if not study else f", the breaking-point study's {_disk_mb(out / 'stress'):.0f} MB") + ".\n\n"
              + ("" if only is None else "**Only the sections asked for** (`--only`): "
                 + ", ".join(f"`{k}`" for k in only) + ".\n\n")
              + f"**Tail**, wherever a table or figure says it: the last {100 * TAIL_FRACTION:g} % of a run "
              "(docs/METRICS.md). On an arm of m joints a tail RMS error is the RMS over the joints and the tail's "
              "rows, i.e. the RMS of ‖q̃‖ divided by √m. **u TV** (total variation Σ|Δu|), wherever a table gives "
              "it: over every physics step of the run, not the log's 100 Hz rows (which would give a lower bound "
              "where u chatters faster).\n\n"
              + ("**Quick mode:** runs are shorter (15–60 s instead of 20–200 s), so estimates that need "
                 "time to converge (first-order example, payload swap, drift) have not; run `adaptive-mj bench` "
                 "for the full catalogue.\n\n" if quick else "")
              + main_table(rows).to_markdown() + "\n\n")
    (out / "report.md").write_text(header + "\n".join(parts), encoding="utf-8")
    write_html(out / "report.md")  # report.html: the same text, figures embedded, for a browser
    summary = {r.job.tag: {"scenario": str(r.job.scenario.name), "overrides": list(r.job.overrides),
                           "log": str(r.job.log.relative_to(out)) if r.job.log else None,
                           "status": r.status, "expected": r.job.expect, "as_expected": as_expected(r),
                           "error": r.error, "summary": r.summary, "extras": r.extras}
               for r in results}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=_json_default), encoding="utf-8")
    page = results_page(rows, results, quick=quick, elapsed=elapsed, n_runs=n_runs, where=_where(backend))
    (out / "results.md").write_text(page, encoding="utf-8")
    if results_file is not None:  # `bench --results docs/RESULTS.md`: the measured results the docs link to
        Path(results_file).write_text(page, encoding="utf-8")
    text = (main_table(rows).to_text(left=TEXT_LEFT, rule=True) + f"\n{STATUS_LEGEND}\n\n"
            + expectation_text(results).replace("**", "")
            + f"\n\nreport: {out / 'report.md'}  ({n_runs} runs, {elapsed:.1f} s)\nhtml: {out / 'report.html'}")
    return Study("bench", out, 0 if not failed else 1, out / "report.md", out / "report.html", text,
                 info={"runs": n_runs, "seconds": elapsed}, load_rows=lambda: rows,
                 plotter=lambda path=None: plot_tails(rows, path or out / "figures" / "tails.png"))


def plot_tails(rows: list[dict], path) -> Path:
    """Every catalogue run's tail RMS tracking error, one panel per output unit (m, rad, dimensionless),
    one bar per run grouped by section, hatched where the run was not ok."""
    import math

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_unit: dict[str, list[dict]] = {}
    for r in rows:
        if isinstance(r.get("tail"), (int, float)) and math.isfinite(r["tail"]) and r["tail"] > 0:
            by_unit.setdefault(r.get("y_unit") or "-", []).append(r)
    fig, axes = plt.subplots(len(by_unit), 1, figsize=(11, 3.2 * len(by_unit) + 0.8), constrained_layout=True,
                             squeeze=False)
    for ax, (unit, group) in zip(axes[:, 0], by_unit.items(), strict=True):
        sections = list(dict.fromkeys(r["section"] for r in group))
        colors = [f"C{sections.index(r['section']) % 10}" for r in group]
        bars = ax.bar(range(len(group)), [r["tail"] for r in group], color=colors)
        for bar, r in zip(bars, group, strict=True):
            if r["status"] != Status.OK:
                bar.set_hatch("//")
                bar.set_edgecolor("k")
        ax.set_yscale("log")
        ax.set_xticks(range(len(group)), [f"{r['section']}: {r['run']}" for r in group], rotation=60, ha="right",
                      fontsize=7)
        ax.set_ylabel(f"tail RMS error [{unit}]" if unit != "-" else "tail RMS error [-]")
        ax.grid(alpha=0.3, axis="y")
    axes[0, 0].set_title("every catalogue run's tail RMS tracking error (hatched: not ok)", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _where(backend: Backend) -> str:
    if backend.kind == "ray":
        return f"one Ray task per run ({backend.address or 'Ray started on this machine'})"
    return f"{backend.jobs} worker process{'es' if backend.jobs > 1 else ''}"


def _json_default(o):
    import numpy as np

    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


callable_module(__name__)  # adaptive_mj.study.bench(...) calls adaptive_mj.study.api.bench(...)

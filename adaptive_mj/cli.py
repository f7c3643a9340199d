"""The command line: adaptive-mj list | run | replay | bench | sweep | stress | score | warmup.

Exit codes: 0 success; 1 the run failed (diverged, failed, a truncated log) or a
verify mismatch; 2 bad input (a bad scenario, model or log, a bad option);
130 / 143 interrupted by SIGINT / SIGTERM (every open log closed with status
"interrupted"). A user mistake prints one line on stderr; a traceback only
with --debug.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import functools
import sys
from pathlib import Path

from adaptive_mj.errors import AdaptiveMJError, Interrupted, LogFormatError, ScenarioError
from adaptive_mj.trajectory import Status

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: one line, exit 2
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="adaptive-mj", description="Adaptive control on MuJoCo physics (lecture 7).")
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    debug = _Parser(add_help=False)  # --debug also after the command
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def add_parser(name: str, **kw) -> _Parser:  # each command takes --debug after its name too
        return sub.add_parser(name, parents=[debug], **kw)

    ls = add_parser("list", help="the bundled scenarios, one line each (--laws: the laws)")
    ls.add_argument("--laws", action="store_true",
                    help="the law kinds: built in, and installed plugins with where each comes from and its keys")
    ls.add_argument("--plants", action="store_true",
                    help="the plant kinds: built in, and installed plugins with where each comes from and its keys")

    r = add_parser("run", help="run a scenario headless and write an MCAP log")
    r.add_argument("scenario", help="a scenario file, or the name of a bundled one")
    r.add_argument("-o", "--output", type=Path, help="log file (default: a new file under logs/)")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set law.k=50 (repeatable)")
    r.add_argument("--law", metavar="NAME", help=LAW_HELP)
    r.add_argument("--seed", type=int, help="noise seed (overrides noise.seed)")
    r.add_argument("--json", action="store_true", help="print the summary object as JSON")
    r.add_argument("--force", action="store_true", help="overwrite -o FILE if it exists")
    r.add_argument("--plot", type=Path, metavar="FILE.png", help="also draw the run")
    r.add_argument("--python-callback", action="store_true",
                   help="run the law in the Python control callback, not the compiled one (for debugging a law; "
                        "the same as --set simulation.python_callback=true)")
    r.add_argument("--strict", action="store_true",
                   help="refuse a run whose loop the pre-flight check finds unstable by construction (exit 2) "
                        "instead of warning; the same as --set success.preflight='refuse'")

    rp = add_parser("replay", help="read a log: summary, plot, bit-identical re-simulation")
    rp.add_argument("log", type=Path)
    rp.add_argument("--json", action="store_true", help="print the summary object as JSON")
    rp.add_argument("--plot", type=Path, metavar="FILE.png", help="draw tracking, error, u and s, estimates, V")
    rp.add_argument("--verify", action="store_true",
                    help="re-simulate from the log's scenario and model; report whether bit-identical")
    rp.add_argument("--video", type=Path, metavar="FILE.mp4|.gif",
                    help="render the run headless from the log's model: scene, tracking error, estimates")
    rp.add_argument("--video-fps", type=float, metavar="FPS", help="video frames per second (default 30, real time)")
    rp.add_argument("--video-size", metavar="WxH", help="video frame size in pixels (default 800x400)")
    rp.add_argument("--video-range", metavar="T0:T1", help="only simulation times T0..T1 [s], e.g. 18:26")
    rp.add_argument("--video-groups", metavar="G1,G2,...",
                    help="the model's geom groups to draw (default: MuJoCo's 0, 1, 2 and the groups of any body whose "
                         "geoms are all outside them, e.g. a menagerie arm's collision geoms in group 3)")
    b = add_parser("bench", help="run the benchmark catalogue: report.md, figures, logs, summary.json")
    b.add_argument("--quick", action="store_true",
                   help="shorter runs and fewer variants, no breaking-point study (under a minute on 2 cores)")
    b.add_argument("-o", "--output", type=Path, help="output directory (default: a new folder under logs/)")
    b.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help=JOBS_HELP)
    b.add_argument("--scenario", action="append", default=[], metavar="FILE",
                   help="also run your own scenario in a section of its own (repeatable; any law, a plugin too)")
    b.add_argument("--law", metavar="NAME", help="also score this law kind (built in or an installed plugin) against "
                   "the baselines in a section of its own, and add it to the breaking-point study")
    b.add_argument("--gains", type=Path, metavar="FILE.toml", help="with --law: its keys per plant kind (as score)")
    b.add_argument("--set", dest="overrides", action="append", default=[], metavar="law.KEY=VALUE",
                   help="with --law: a key of that law (repeatable)")
    b.add_argument("--full-logs", action="store_true",
                   help="the breaking-point study's and the quadrotor margin grid's runs log every row (default: "
                        "their summary and a row per second)")
    b.add_argument("--only", action="append", default=[], metavar="SECTION",
                   help="run only this section of the catalogue, by its key (repeatable, or KEY,KEY; e.g. first_order, "
                        "payload_swap, quadrotor; breaking_points: the full bench's study, section 14); a wrong key "
                        "is refused with the list of them")
    b.add_argument("--results", type=Path, metavar="FILE.md",
                   help="also write the measured-results page (results.md in the output folder) to FILE.md, e.g. "
                        "docs/RESULTS.md")
    _backend_arguments(b)

    w = add_parser("warmup", help="compile every control callback the bench needs, in parallel, so that the bench "
                   "and any run of the same plants and laws start from numba's cache")
    w.add_argument("--quick", action="store_true", help="only what `bench --quick` needs")
    w.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="worker processes, each compiling a variant (default: all cores)")

    sw = add_parser("sweep", help="run a scenario over a grid of keys and seeds, in parallel")
    sw.add_argument("scenario", help="a scenario file, or the name of a bundled one")
    sw.add_argument("--grid", action="append", default=[], metavar="KEY=LO:HI:N",
                    help="a grid axis: KEY=LO:HI:N (N values, linear) or KEY=V1,V2,... (repeatable); "
                         "KEY is a dotted scenario key or a bare key that names one uniquely")
    sw.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    sw.add_argument("--law", metavar="NAME", help=LAW_HELP)
    sw.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 per grid point")
    sw.add_argument("--resume", type=Path, metavar="DIR",
                    help="finish the study in DIR (the same command that started it): runs whose log is complete "
                         "are read back, the rest (missing, truncated or interrupted logs) run again")
    sw.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help=JOBS_HELP)
    sw.add_argument("-o", "--output", type=Path, help="output directory (default: a new folder under logs/)")
    sw.add_argument("--metric", action="append", default=[],
                    help="metric(s) to plot against the grid (default: rms_tracking_error_tail)")
    sw.add_argument("--breaking-point", metavar="KEY=LO:HI",
                    help="instead of a grid: bisect KEY between LO and HI for the largest value at which every "
                         "seed passes (integers when LO and HI are; control.period: whole physics steps, "
                         "run under control.mode='sampled'); needs --tail-bound")
    sw.add_argument("--tail-bound", type=float, metavar="B",
                    help="with --breaking-point: a run fails when it diverges or its tail RMS error exceeds B")
    sw.add_argument("--steps", type=int, default=5, help="with --breaking-point: bisection steps (default 5)")
    sw.add_argument("--logs", choices=("all", "summary"), default="all",
                    help="all: an MCAP log per run (default); summary: the table rows only, no logs (very large "
                         "studies; no --resume)")
    _backend_arguments(sw)
    st = add_parser("stress", help="breaking points: every law x stressor x plant, margins by bisection "
                    "over seeded runs; report.md and margins.csv")
    st.add_argument("--seeds", type=int, default=5, help="seeds per stress value (default 5)")
    st.add_argument("--steps", type=int, default=4, help="bisection steps after the two ends (default 4)")
    st.add_argument("--duration", type=float, default=20.0, help="seconds per run (default 20)")
    st.add_argument("--composite", action="store_true",
                    help="also composite adaptation (a row per plant that has one)")
    st.add_argument("--plants", metavar="P,Q,...", help="only these plants (heave, arm, ur5e, quadrotor)")
    st.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help=JOBS_HELP)
    st.add_argument("-o", "--output", type=Path, help="output directory (default: a new folder under logs/)")
    st.add_argument("--law", metavar="NAME", help="also this law kind (built in or an installed plugin), beside the "
                    "built-in laws on every plant it serves, with its --set law.* keys")
    st.add_argument("--set", dest="overrides", action="append", default=[], metavar="law.KEY=VALUE",
                    help="with --law: a key of that law (repeatable)")
    _backend_arguments(st)
    sc_ = add_parser("score", help="rank a law against the baselines on every plant it serves: tasks, breaking "
                     "points, scores with 95 %% intervals; scorecard.json/.md/.html")
    sc_.add_argument("law", nargs="?", metavar="LAW",
                     help="a law kind, built in or an installed plugin (`list --laws`); leave out with --merge, or "
                          "to score the baselines alone")
    sc_.add_argument("--set", dest="overrides", action="append", default=[], metavar="law.KEY=VALUE",
                     help="a key of the law, on every plant (repeatable)")
    sc_.add_argument("--gains", type=Path, metavar="FILE.toml",
                     help="the law's keys per plant kind: a table each, e.g. [heave] lambda = 5.0")
    sc_.add_argument("--against", metavar="A,B,...", help="only these baselines (default: all of each plant's)")
    sc_.add_argument("--suite", choices=("quick", "full"), default="quick",
                     help="quick: 5 seeds, 6 bisection steps, 5 s margin runs (default); full: 8 seeds, 8 steps, 20 s")
    sc_.add_argument("--seeds", type=int, help="seeds per figure (default: the suite's)")
    sc_.add_argument("--plants", metavar="P,Q,...", help="only these plants (heave, arm, ur5e, quadrotor)")
    sc_.add_argument("--scenario", action="append", default=[], type=Path, metavar="FILE.toml",
                     help="score on your own plant too: a scenario file, tracked as given, its payload changed and "
                          "its start held; its plant kind's stressors (repeatable; alone: only these plants)")
    sc_.add_argument("--label", metavar="NAME", help="the law's name on the card (default LAW)")
    sc_.add_argument("--full-logs", action="store_true",
                     help="the margin runs' logs at the scenario's rate (default: their summary and a row per second)")
    sc_.add_argument("--merge", nargs="+", type=Path, metavar="CARD.json",
                     help="instead of running: join cards of one suite version into one leaderboard "
                          "(scorecard.json/.md/.html and leaderboard.html)")
    sc_.add_argument("--verify", type=Path, metavar="CARD.json",
                     help="instead of running: re-run the card's runs from the specs it records, each bit for bit, "
                          "and check its figures, scores and ranks against them (exit 1 naming the first that "
                          "differs)")
    sc_.add_argument("--sample", type=int, metavar="N",
                     help="with --verify: re-run N of the card's run records (a law's seed on a plant, or one seed's "
                          "breaking-point search), picked by the card's own hash (default: all)")
    sc_.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help=JOBS_HELP)
    sc_.add_argument("-o", "--output", type=Path, help="output directory (default: a new folder under logs/)")
    _backend_arguments(sc_)
    return p


LAW_HELP = ("swap the scenario's law for this law kind (built in or an installed plugin; `list --laws`): its "
            "[law] table replaced by the law's defaults, keeping law.initial_estimates and law.nominal, plus the "
            "--set law.* keys given")
JOBS_HELP = ("worker processes (default: all cores); with --backend ray and no --address, the CPUs of the Ray "
             "started here")


def _backend_arguments(p: argparse.ArgumentParser) -> None:
    """--backend, --address, --ray-logs, --retries (adaptive_mj.study.parallel.Backend)."""
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="local: worker processes on this machine (default); ray: one Ray task per run "
                        "(needs the [ray] extra)")
    p.add_argument("--address", metavar="ADDR",
                   help="with --backend ray: 'auto' (the cluster `ray start` runs on this machine), HOST:PORT (its "
                        "GCS address) or ray://HOST:PORT (Ray Client) joins a running cluster; default: start a "
                        "new Ray here with --jobs CPUs")
    p.add_argument("--ray-logs", choices=("bytes", "shared"), default="bytes",
                   help="with --backend ray: bytes (each log is sent back to this machine; default) or shared "
                        "(each node writes its logs itself: the output folder must be on shared storage)")
    p.add_argument("--engine", choices=("process", "batch"), default="process",
                   help="process (one run at a time per worker process or Ray task; default) or batch (runs' "
                        "physics stepped together in mujoco.batch: with --backend local in this process on --jobs "
                        "threads, with --backend ray up to 32 runs per task; the same rows, logs and verdicts)")
    p.add_argument("--retries", type=int, default=3,
                   help="times a run is submitted again when its worker process (or Ray node) dies (default 3; "
                        "local --jobs 1 runs in this process, where there is no worker to lose)")


def _scenario_path(arg: str) -> Path:
    from adaptive_mj.study.api import scenario_path

    return scenario_path(arg)


def _print_identification(ident: dict | None) -> None:
    """The summary's "identification" (report.identification) in one line: identified, off (with the error),
    and which parameters the reference did not excite over the tail."""
    if not ident:
        return
    rel = ident.get("relative_error") or {}
    parts = []
    if ident.get("identified"):
        parts.append("identified " + ", ".join(ident["identified"]))
    if ident.get("off"):
        parts.append("off " + ", ".join(f"{n} {100 * rel[n]:.3g} %" for n in ident["off"]))
    if "not_excited" in ident:
        parts.append(("not excited by the reference over the tail (their estimates say nothing): "
                      + ", ".join(ident["not_excited"])) if ident["not_excited"] else
                     f"every parameter excited over the tail (index {ident['excitation_index']:.2g})")
    if parts:
        print(f"  identification (within {100 * ident['tolerance']:g} % of the truth): " + "; ".join(parts))


def _print_summary(summary: dict, *, as_json: bool, log: Path | None = None, note: str = "",
                   kind: str | None = None) -> None:
    if as_json:
        print(json.dumps(summary, sort_keys=False))
        return
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares
    from adaptive_mj.report.metrics import TAIL_FRACTION

    m = summary["metrics"]
    yu, uu = units.output_unit(kind or ""), units.control_unit(kind or "")
    print(f"{summary['scenario']}: {summary['status']}"
          + (f" ({summary['reason']})" if summary.get("reason") else "")
          + f", {summary['duration']:.3f} s simulated, {summary['steps']} steps")

    def f(v, unit=""):
        return "n/a" if v is None else f"{v:.3g}" + (f" {unit}" if unit and unit != "-" else "")

    if m:
        print(f"  tracking error rms {f(m['rms_tracking_error'], yu)}, tail rms {f(m['rms_tracking_error_tail'], yu)}, "
              f"tail max {f(m['max_abs_tracking_error_tail'], yu)}")
        rate = m.get("control_total_variation_rate_hz")
        print(f"  control rms {f(m['control_rms'], uu)}, total variation {f(m['control_total_variation'], uu)}"
              + (f" (over the rows at {rate:.4g} Hz: a lower bound where the control moves faster)" if rate else ""))
        if "rms_tracking_error_tail_per_joint" in m:
            own = units.lookup(kind)  # a kind of named state rows (a quadrotor) has position axes, not joints
            word = "axis" if own is not None and own.noise_signals else "joint"
            print(f"  tail rms per {word} [{yu or 'rad'}]: " + ", ".join(
                f"{j} {f(v)}" for j, v in m["rms_tracking_error_tail_per_joint"].items()))
        if m.get("saturation_fraction"):
            per = m.get("saturation_fraction_per_joint") or {}
            print(f"  time at the actuator limit: {100 * m['saturation_fraction']:.3g} % (worst)"
                  + (": " + ", ".join(f"{j} {100 * v:.3g} %" for j, v in per.items() if v) if per else ""))
        for body, e in (m.get("identification") or {}).items():
            rel = e["inertia_error_relative"]
            com = e.get("com_undefined") or f(e["com_error_mm"], "mm")  # m̂ = 0: no centre of mass to compare
            print(f"  identified {body}: mass {f(e['mass_error_percent'])} %, centre of mass "
                  f"{com}, inertia {f(e['inertia_error'], 'kg m²')} "
                  f"({f(None if rel is None else 100 * rel)} % of |I|) at the last row")
            tl = e.get("tail")
            if tl:  # the estimates may swing: the tail's mean [min, max] beside the last row
                def rng(k, scale=1.0, unit="", tl=tl):
                    v = tl[k]
                    return (f"{f(None if v['mean'] is None else scale * v['mean'], unit)} "
                            f"[{f(None if v['min'] is None else scale * v['min'])}, "
                            f"{f(None if v['max'] is None else scale * v['max'])}]")
                print(f"    over the tail (last {100 * TAIL_FRACTION:g} %, mean [min, max]): mass "
                      f"{rng('mass_error_percent')} %, centre of mass {rng('com_error_mm', unit='mm')}, inertia "
                      f"{rng('inertia_error', unit='kg m²')}")
    _print_identification(summary.get("identification"))
    final = summary["final"]
    unit = functools.partial(units.param_unit, kind)
    parts = [f"{n} {f(final['theta_hat'][n], unit(n))} (true {f(final['theta'][n], unit(n))})"
             for n in final["theta_hat"]]
    if parts:
        print("  estimates: " + ", ".join(parts))
    pre = summary.get("preflight") or {}
    if pre.get("checked") and not pre.get("ok"):
        figure = (f"a delay of {1e3 * pre['figure']:.3g} ms >= the delay margin {1e3 * pre['limit']:.3g} ms"
                  if pre.get("measure") == "delay" else f"μh = {pre['figure']:.3g} > {pre['limit']:.3g}")
        print(f"  pre-flight: {figure} ({pre['scheme']})"
              + (f" on {pre['joint']}" if pre.get("joint") else ""))
    for w in summary.get("warnings") or ():
        print(f"  warning: {w}")
    if note:
        print(f"  {note}")
    if log is not None:
        print(f"  log: {log}")


def cmd_list(args) -> int:
    from adaptive_mj.setup import scenario as sc

    if getattr(args, "plants", False):
        from adaptive_mj.plants.plugin import ENTRY_POINT_GROUP as PLANT_GROUP, installed as installed_plants

        from adaptive_mj.plants.kinds import built_in

        for kind in built_in().values():
            forms = ", ".join(sorted(f.value for f in kind.forms))
            model = f"; model {kind.default_model}" if kind.default_model else "; analytic"
            keys = ", ".join(k.describe() for k in kind.keys if k.name != "kind")  # its declared plant.* keys
            events = ", ".join(e.name for e in kind.events)
            print(f"{kind.name:24s} built in: offers {forms}; {kind.doc}{model}; y [{kind.output_unit}], "
                  f"u [{kind.control_unit}]; default law {kind.default_law}; keys: {keys or 'none'}; "
                  f"events: {events or 'none'}")
        plants = installed_plants()
        for name, inst in sorted(plants.items()):
            keys = ", ".join(p.name + (f" [{p.unit}]" if p.unit else "") for p in inst.plugin.params)
            print(f"{name:24s} plugin from {inst.distribution} {inst.version} (source {inst.source_sha256[:12]}): "
                  f"{inst.plugin.doc}; model {inst.plugin.model}; keys: {keys or 'none'}")
        if not plants:
            print(f"(no plant plugins installed: a package registers one under {PLANT_GROUP!r})")
        return EXIT_OK
    if getattr(args, "laws", False):
        from adaptive_mj.laws import kinds as law_kinds
        from adaptive_mj.laws.plugin import ENTRY_POINT_GROUP, installed

        plugins = installed()
        for name, law_kind in law_kinds.all_kinds().items():
            forms = ", ".join(sorted(f.value for f in law_kind.forms))
            line = f"{name:24s} {law_kind.origin}: serves {forms}; {law_kind.doc}"
            if name in plugins:
                line += f"; keys: {plugins[name].plugin.describe_keys() or 'none'}"
            elif law_kind.keys:  # a built-in kind's declared keys (law.kind itself left out)
                line += "; keys: " + ", ".join(k.describe() for k in law_kind.keys if k.name != "kind")
            print(line)
        if not plugins:
            print(f"(no law plugins installed: a package registers one under the entry-point group "
                  f"{ENTRY_POINT_GROUP!r}; see docs/ADDING_A_LAW.md)")
        return EXIT_OK

    for path in sc.bundled():
        try:
            s = sc.load(path)
            plant = f"{s.plant.kind}/{s.plant.backend}"
            print(f"{s.name:24s} {plant:18s} {s.description}")
        except AdaptiveMJError as exc:
            print(f"{path.stem:24s} {'INVALID':18s} {_one_line(exc)}")
    return EXIT_OK


def cmd_run(args) -> int:
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.runs.runner import execute, reserve_log_path

    overrides = [*([sc.law_swap(args.law)] if args.law else []), *args.overrides,
                 *(["simulation.python_callback=true"] if args.python_callback else []),
                 *(["success.preflight='refuse'"] if args.strict else [])]
    scn = sc.load(_scenario_path(args.scenario), overrides=overrides, seed=args.seed)
    log = reserve_log_path(scn, out=args.output, force=args.force)
    try:
        result = execute(scn, log_path=log, single=True)
    except OSError as exc:  # the log could not be written (disk full, a file-size limit)
        if args.debug:
            raise
        from adaptive_mj.study.job import log_write_error

        print(f"adaptive-mj: error: {log_write_error(log, exc)}", file=sys.stderr)
        return EXIT_FAILED
    except BaseException as exc:
        if log.is_file() and log.stat().st_size == 0:
            log.unlink()  # the run never started: leave no file that looks like a log
        elif isinstance(exc, Interrupted) and exc.summary is not None:
            _print_summary(exc.summary, as_json=args.json, log=None if args.json else log, kind=scn.plant.kind)
            exc.note = f"{exc.summary['duration']:.3f} s simulated, log closed with status 'interrupted': {log}"
        raise
    if args.plot:
        from adaptive_mj.report.plot import plot_run

        plot_run(result.trajectory, args.plot, title=scn.name, kind=scn.plant.kind)
    _print_summary(result.summary, as_json=args.json, log=None if args.json else log, kind=scn.plant.kind)
    if args.json:
        print(f"log: {log}", file=sys.stderr)
    return EXIT_OK if result.summary["status"] == Status.OK else EXIT_FAILED


def cmd_warmup(args) -> int:
    """Compile what the bench needs (adaptive_mj.study.warmup): each variant said on stderr as it compiles, then a
    line of what was done; exit 1 when a run could not be set up."""
    from adaptive_mj.study.api import count
    from adaptive_mj.study.warmup import warmup

    done = warmup(quick=args.quick, jobs=count("--jobs", args.jobs, 1))
    print(done.text())
    return EXIT_FAILED if done.errors else EXIT_OK


def cmd_replay(args) -> int:
    from adaptive_mj.report.metrics import clean_json, summary as make_summary
    from adaptive_mj.log.replay import read_log

    if not args.log.is_file():
        raise LogFormatError(f"{args.log}: no such log file")
    logged = read_log(args.log)
    summary = logged.summary
    if summary is None or "metrics" not in summary:  # truncated, or closed without metrics: summarise the rows
        traj = logged.trajectory
        summary = clean_json(make_summary(logged.header.get("scenario_name", args.log.stem), traj,
                                          steps=len(traj) * int(logged.header.get("log_every", 1))))
        summary["status"] = logged.status
        summary["reason"] = logged.trajectory.reason
    from adaptive_mj.plants.kinds import kind_of as plant_kind_of

    kind = plant_kind_of(logged.scenario_text)
    _print_summary(summary, as_json=args.json, note=logged.note, kind=kind)
    if args.plot:
        from adaptive_mj.report.plot import plot_run

        plot_run(logged.trajectory, args.plot, title=f"{summary['scenario']} (replay)", kind=kind)
    if args.video:
        from adaptive_mj.report.video import parse_groups, render_log

        video = render_log(args.log, args.video, fps=args.video_fps, size=args.video_size,
                           t_range=_time_range(args.video_range), groups=parse_groups(args.video_groups))
        print(f"video: {video.path} ({video.frames} frames at {video.fps:g} fps, "
              f"{video.size[0]}x{video.size[1]}; rendered at {video.render_rate:.1f} frames/s)",
              file=sys.stderr if args.json else sys.stdout)
    if logged.damaged:  # what could be read is shown above; the file itself is bad input
        raise LogFormatError(f"{args.log}: damaged log: {logged.note}")
    code = EXIT_OK if summary["status"] == Status.OK else EXIT_FAILED
    if args.verify:
        from adaptive_mj.runs.verify import verify

        if logged.model_missing:
            raise LogFormatError(f"{args.log}: --verify needs the model the log embedded, and its attachments were "
                                 "removed (replay without --verify shows its rows and summary)")
        ok, message = verify(logged)
        print(message, file=sys.stderr if args.json else sys.stdout)
        if not ok:
            code = EXIT_FAILED
    return code


def _one_line(text: object) -> str:
    """A message on one line (MuJoCo's compiler messages span several)."""
    return " ".join(part.strip() for part in str(text).splitlines() if part.strip())


def _time_range(text: str | None) -> tuple[float, float] | None:
    """'T0:T1' -> (T0, T1) in seconds; a malformed range is bad input."""
    if text is None:
        return None
    try:
        t0, t1 = (float(v) for v in text.split(":"))
    except ValueError:
        raise AdaptiveMJError(f"--video-range {text!r}: expected T0:T1 in seconds, e.g. 18:26") from None
    if not t0 < t1:
        raise AdaptiveMJError(f"--video-range {text!r}: expected T0 < T1")
    return t0, t1


def _study(args):
    """`bench`, `sweep` and `stress`: the parsed options handed to adaptive_mj.study.api, which checks them."""
    from adaptive_mj.study import api

    where = dict(backend=args.backend, jobs=args.jobs, address=args.address, ray_logs=args.ray_logs,
                 retries=args.retries, engine=args.engine)
    if args.command == "bench":
        if args.gains is not None and args.law is None:
            raise ScenarioError("--gains needs --law")
        return api.bench(quick=args.quick, scenarios=[_scenario_path(p) for p in args.scenario], out=args.output,
                         law=args.law, gains=args.gains, set=args.overrides, full_logs=args.full_logs,
                         only=[k for item in args.only for k in item.split(",")] or None, results=args.results,
                         **where)
    if args.command == "stress":
        return api.stress(seeds=args.seeds, steps=args.steps, duration=args.duration, composite=args.composite,
                          out=args.output, law=args.law, set=args.overrides, plants=args.plants, **where)
    if args.command == "score":
        if args.merge and args.law:
            raise ScenarioError("score: give LAW or --merge, not both")
        if not args.merge and args.overrides and not args.law:
            raise ScenarioError("score: --set needs LAW (the baselines keep their own keys)")
        return api.score(args.law, set=args.overrides, gains=args.gains, against=args.against, suite=args.suite,
                         seeds=args.seeds, plants=args.plants, label=args.label, out=args.output,
                         full_logs=args.full_logs, merge=args.merge or (), scenarios=args.scenario,
                         verify=args.verify, sample=args.sample, **where)
    if args.breaking_point:  # sweep --breaking-point: one key bisected instead of a grid
        if args.grid:
            raise ScenarioError("--breaking-point and --grid cannot be combined (one stressor at a time)")
        if args.logs == "summary" or args.resume is not None:
            raise ScenarioError("--logs summary writes no logs, and --resume and --breaking-point read the runs' logs "
                                "back; leave out --logs summary" if args.logs == "summary" else
                                "--resume is for a grid sweep; --breaking-point starts a new search")
        return api.breaking_point(_scenario_path(args.scenario), key=args.breaking_point, tail_bound=args.tail_bound,
                                  seeds=args.seeds, steps=args.steps, overrides=api.with_law(args.law, args.overrides),
                                  out=args.output, **where)
    return api.sweep(_scenario_path(args.scenario), grid=args.grid, seeds=args.seeds, overrides=args.overrides,
                     metrics=args.metric, out=args.output, resume=args.resume, logs=args.logs, law=args.law, **where)


def _print_study(study) -> int:
    """A study's result on stdout, its notes (metrics no run has, runs not ok) on stderr; the exit code."""
    print(study.text)
    for note in study.notes:
        print(note, file=sys.stderr)
    return study.exit_code


#: MUJOCO_GL -> (the library mujoco's backend loads, the Debian package that ships it)
GL_LIBRARIES = {"osmesa": ("OSMesa", "libosmesa6"), "egl": ("EGL", "libegl1")}


def gl_library_missing(backend: str | None, *, load=None) -> str | None:
    """One line when MUJOCO_GL names a backend whose library cannot be loaded (mujoco would fail on import
    with a traceback from PyOpenGL), else None. load(name) opens a shared library (ctypes, by default)."""
    wanted = GL_LIBRARIES.get((backend or "").strip().lower())
    if wanted is None:
        return None
    import ctypes
    import ctypes.util

    name, package = wanted
    if load is None:
        def load(lib):
            return ctypes.CDLL(ctypes.util.find_library(lib) or f"lib{lib}.so", mode=ctypes.RTLD_GLOBAL)
    try:
        load(name)
    except OSError:
        other = "MUJOCO_GL=egl" if name != "EGL" else "MUJOCO_GL=osmesa (Debian package libosmesa6)"
        return (f"MUJOCO_GL={backend} needs the {name} library (lib{name}.so), which is not installed: install the "
                f"Debian package {package} (apt-get install {package}), or use {other}")
    return None


def main(argv: list[str] | None = None) -> int:
    from adaptive_mj.sim.interrupt import stop_on_signals

    args = _parser().parse_args(argv)
    from adaptive_mj.notes import show_on_stderr

    show_on_stderr()  # a run's notes and warnings (the "adaptive_mj" logger) on stderr, one whole line each
    missing = gl_library_missing(os.environ.get("MUJOCO_GL"))
    if missing:  # before anything imports mujoco, which would end in PyOpenGL's traceback
        print(f"adaptive-mj: error: {missing}", file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        with stop_on_signals():  # SIGINT, SIGTERM: errors.Interrupted, handled in _dispatch
            return _dispatch(args)
    except BrokenPipeError:  # e.g. `adaptive-mj list | head -1`: the reader left; not an error of ours
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so the interpreter's final flush does not fail again
        return EXIT_OK
    finally:
        if argv is None:  # the command itself (adaptive-mj, python -m adaptive_mj): the process ends now
            _before_exit()


def _before_exit() -> None:
    """The interpreter's last garbage collections walk every object numba and LLVM made, 0.3 s of
    a short run's 0.7 s; frozen, they go with the process's memory instead. Only objects in
    reference cycles are concerned: everything else is freed as before, and what must happen at
    exit is done explicitly or by atexit and weakref.finalize, which still run (every log is closed
    by the run itself, with its status)."""
    import gc

    gc.freeze()


def _dispatch(args) -> int:
    try:
        if args.command in ("bench", "sweep", "stress", "score"):
            return _print_study(_study(args))
        return {"list": cmd_list, "run": cmd_run, "replay": cmd_replay, "warmup": cmd_warmup}[args.command](args)
    except AdaptiveMJError as exc:
        if args.debug:
            raise
        print(f"adaptive-mj: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:  # a log or report could not be written: not a bug, not bad input
        if args.debug:
            raise
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"adaptive-mj: error: {where}could not write ({exc.strerror or exc}); a log cut short reads as "
              "truncated with `adaptive-mj replay`", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt as exc:
        if not isinstance(exc, Interrupted):
            exc = Interrupted(signal.SIGINT)
        print(f"adaptive-mj: {exc}" + (f"; {exc.note}" if exc.note else ""), file=sys.stderr)
        return exc.exit_code


if __name__ == "__main__":
    sys.exit(main())

"""Scaling benchmark (issue 13): how sweeps use cores and clusters, measured on this machine.

  ceiling   the machine's own parallel ceiling: a pure-Python CPU loop in 2 processes at
            once against 1 (the most any 2-process sweep can gain here)
  local     sweep throughput (runs per minute) on --runs logged 30 s heave runs, 1 job against
            2, through the sweep's runner (parallel.iter_results), interleaved repetitions;
            and what is serial in `adaptive-mj sweep`: import, validating the grid, compiling
            the native callback, forking the workers, collecting results, writing the tables
  ray       the same runs on Ray started here with 2 CPUs (the workers warmed by one batch
            first), and Ray's own cost per task: --tasks no-op tasks through the same driver
            loop shape (submit window, ray.wait, ray.get)
  study     a --study-runs study of 2 s runs through `adaptive-mj sweep` (local, 2 jobs):
            wall time, runs/s, and the driver's peak RSS (VmHWM, polled) for it and for a
            study 10× smaller (bounded memory: the two should be close); against the bare-stepping limit
            and the closed loop's own ceiling (issue 51: the same runs compiled, only their mj_step calls
            timed, 2 processes at once), each measured just before and just after the study
  batch     issue 20: simulation-steps per second for the heave vehicle, the 1-DOF arm and the
            6-joint arm at nsim --batch-sims (100, 1000, 10^4): the bare-stepping limit (a Batch
            of the model with no law, 2 threads); run_batch (built runs, unlogged); the batched
            engine end to end (building, stepping, verdicts; without logs and with MCAP logs at
            100 Hz); the process pool on the same study, without and with logs (nsim --pool-sims); the driver's
            memory per prepared run, and the bytes of a Batch state row, an MjData, an MjModel
  per_run   what one run of a study costs in one process, against bare stepping of its model
            (mj_step, the same steps): building the run, and the whole run (run_job: build, step,
            verdict) without a log and with its MCAP log at 100 Hz, for the heave vehicle and the
            1-DOF arm at 1, 2 and 30 s (heave also 5 s; 30 s is the bundled scenarios' length) and the
            6-joint arm at 0.2 s and 2 s (--per-run-runs runs, median of --reps); the ratio bare / run is
            about the most a study of such runs can reach against the bare-stepping limit on any number
            of cores, whatever the engine (a run's fixed cost weighs less as runs get longer); and the
            time of the run's physics steps alone, the compiled law in MuJoCo's control callback (its
            mj_step calls, timed): bare / that is the law's ceiling, what an engine with no Python per
            run at all would reach

Every figure is the median of --reps repetitions with [min, max] where repeated.
Usage: python benchmarks/scaling.py [--reps 3] [--runs 8] [--only local,ray,...] [--study-runs 10000] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HEAVE = REPO / "scenarios" / "heave_tracking.toml"
SECONDS = 30.0  # simulated seconds per run in the throughput figures (the issue's 30 s heave runs)


def med(xs):
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs), "n": len(xs)}


def _busy(n: int) -> None:
    x = 0
    for i in range(n):
        x += i * i


def ceiling(reps: int) -> dict:
    """Speed-up of 2 processes each doing the work of 1 (pure Python, no I/O, no shared state)."""
    import multiprocessing as mp

    n = 15_000_000
    ctx = mp.get_context("fork")
    ratios, one = [], []
    for _ in range(reps):
        t0 = time.perf_counter()
        _busy(n)
        t1 = time.perf_counter() - t0
        procs = [ctx.Process(target=_busy, args=(n,)) for _ in range(2)]
        t0 = time.perf_counter()
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        t2 = time.perf_counter() - t0
        ratios.append(2 * t1 / t2)
        one.append(t1)
    return {"ratio_2_over_1": med(ratios), "seconds_1": med(one)}


def _jobs(folder: Path, runs: int, tag: str):
    from adaptive_mj.study.parallel import RunSpec

    return [RunSpec(HEAVE, (f"simulation.duration={SECONDS}", f"law.k={150.0 + i}"), seed=0,
                log=folder / f"{tag}-{i}.mcap", tag=f"{tag}-{i}", keep_trajectory=False) for i in range(runs)]


def _throughput(backend, runs: int, tag: str) -> tuple[float, float]:
    """(runs per minute, the driver's CPU seconds) for `runs` logged heave runs on `backend`."""
    from adaptive_mj.study.parallel import iter_results

    with tempfile.TemporaryDirectory() as tmp:
        jobs = _jobs(Path(tmp), runs, tag)
        c0 = time.process_time()
        t0 = time.perf_counter()
        statuses = [r.status for _, r in iter_results(jobs, backend)]
        el = time.perf_counter() - t0
        cpu = time.process_time() - c0
    assert statuses == ["ok"] * runs, statuses
    return runs / el * 60.0, cpu


def serial_parts(runs: int) -> dict:
    """Seconds of each serial part of `adaptive-mj sweep` (measured in a fresh interpreter)."""
    code = f"""
import json, sys, time, tempfile
from pathlib import Path
t0 = time.perf_counter()
from adaptive_mj.study import sweep, parallel
t_import = time.perf_counter() - t0
from adaptive_mj.setup import scenario as sc
p = Path({str(HEAVE)!r})
t0 = time.perf_counter()
doc, base = sweep._document(p, ['simulation.duration={SECONDS}'])
axes = sweep._axes(['law.k=150:250:{runs}'], doc)
points = sweep.grid_points(axes)
sweep._validate_points(p, ['simulation.duration={SECONDS}'], points)
t_validate = time.perf_counter() - t0
with tempfile.TemporaryDirectory() as tmp:
    out = Path(tmp)
    planned = sweep.plan(p, points, seeds=1, overrides=['simulation.duration={SECONDS}'], logs=out / 'logs')
    jobs = [j for _, j in planned]
    t0 = time.perf_counter(); parallel._prewarm(jobs); t_compile = time.perf_counter() - t0
    import concurrent.futures as cf, multiprocessing as mp
    t0 = time.perf_counter()
    with cf.ProcessPoolExecutor(2, mp_context=mp.get_context('fork'), initializer=parallel._init_worker) as pool:
        list(pool.map(int, [0, 1]))
    t_fork = time.perf_counter() - t0
    t0 = time.perf_counter()
    with open(out / 'rows.jsonl', 'w') as stream:
        for i, r in parallel.iter_results(jobs, parallel.Backend(jobs=2)):
            sweep._append_row(stream, i, sweep.rows([(planned[i][0], r)], root=out)[0])
    t_runs = time.perf_counter() - t0
    t0 = time.perf_counter()
    table, _ = sweep.write_tables(out / 'rows.jsonl', len(jobs), {{}}, out,
                                  keep=['law.k', 'seed', 'rms_tracking_error_tail'])
    sweep.plot_sweep(table, ['law.k'], ['rms_tracking_error_tail'], out / 'sweep.png', plant_kind='heave')
    t_tables = time.perf_counter() - t0
print(json.dumps(dict(import_s=t_import, validate_grid_s=t_validate, compile_native_s=t_compile,
                      fork_workers_s=t_fork, runs_s=t_runs, tables_and_plot_s=t_tables)))
"""
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(r.stderr[-3000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def local(reps: int, runs: int) -> dict:
    from adaptive_mj.study.parallel import Backend, _prewarm

    with tempfile.TemporaryDirectory() as tmp:
        _prewarm(_jobs(Path(tmp), 1, "warm"))  # compiled once here, as the sweep command does
    one, two, ratio, cpu2 = [], [], [], []
    for _ in range(reps):  # interleaved, so a slow spell of the shared machine hits both
        a, _ = _throughput(Backend(jobs=1), runs, "one")
        b, c = _throughput(Backend(jobs=2), runs, "two")
        one.append(a)
        two.append(b)
        ratio.append(b / a)
        cpu2.append(c)
    return {"runs": runs, "seconds_per_run": SECONDS, "jobs1_runs_per_min": med(one), "jobs2_runs_per_min": med(two),
            "ratio": med(ratio), "driver_cpu_s_jobs2": med(cpu2), "serial_parts_s": serial_parts(runs)}


def ray_figures(reps: int, runs: int, tasks: int) -> dict:
    import ray

    from adaptive_mj.study.parallel import Backend
    from adaptive_mj.study.ray_backend import WINDOW_PER_CPU

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    t0 = time.perf_counter()
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    start_s = time.perf_counter() - t0
    try:
        @ray.remote(num_cpus=1, max_retries=0)
        def noop(x):
            return x

        ray.get([noop.remote(i) for i in range(50)])  # workers up
        per_task = []
        for _ in range(reps):
            pending, n, t0 = {}, 0, time.perf_counter()
            while pending or n < tasks:
                while n < tasks and len(pending) < WINDOW_PER_CPU * 2:
                    pending[noop.remote(n)] = n
                    n += 1
                ready, _ = ray.wait(list(pending), num_returns=1)
                for ref in ready:
                    pending.pop(ref)
                    ray.get(ref)
            per_task.append((time.perf_counter() - t0) / tasks * 1e3)
        backend = Backend(kind="ray", jobs=2)
        t0 = time.perf_counter()
        _throughput(backend, 4, "warm")  # each worker compiles the native callback once
        warm_s = time.perf_counter() - t0
        thr, cpu, thr_shared, cpu_shared, loc = [], [], [], [], []
        for _ in range(reps):  # interleaved with the local backend (2 processes) beside the idle Ray
            a, c = _throughput(backend, runs, "ray")
            thr.append(a)
            cpu.append(c)
            a, c = _throughput(Backend(kind="ray", jobs=2, logs="shared"), runs, "shared")
            thr_shared.append(a)
            cpu_shared.append(c)
            loc.append(_throughput(Backend(jobs=2), runs, "local")[0])
    finally:
        ray.shutdown()
    return {"ray_start_s": start_s, "noop_task_ms": med(per_task), "tasks": tasks,
            "first_batch_s_4_runs": warm_s, "runs_per_min": med(thr), "driver_cpu_s": med(cpu),
            "runs_per_min_shared_logs": med(thr_shared), "driver_cpu_s_shared_logs": med(cpu_shared),
            "runs": runs, "local_runs_per_min": med(loc),
            "ratio_to_local": med([a / b for a, b in zip(thr, loc, strict=True)]),
            "overhead_per_run_ms": med([60e3 / a - 60e3 / b for a, b in zip(thr, loc, strict=True)])}


def ray_nodes(runs: int, seconds: float = 2.0) -> dict:
    """Issue 20 §3: runs per hour of batched Ray tasks (--engine batch, logs as bytes and shared) on a
    local Ray cluster of 1 and then 2 nodes (one CPU each, ray.cluster_utils.Cluster, as tests/test_ray.py),
    `runs` logged heave_drift runs of `seconds` s, and the driver's CPU per run: the driver writes every
    log that comes back as bytes, so 3600 / (driver CPU s per run) runs per hour is where adding nodes
    stops helping with logs as bytes; with shared logs the driver only takes the summaries."""
    from ray.cluster_utils import Cluster

    from adaptive_mj.setup.scenario import SCENARIOS_DIR
    from adaptive_mj.study.job import Backend, RunSpec
    from adaptive_mj.study.parallel import iter_results

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False,
                                                       "object_store_memory": 200 * 2**20})
    out: dict = {"runs": runs, "seconds": seconds, "nodes": {}}
    try:
        for nodes in (1, 2):
            if nodes == 2:
                c.add_node(num_cpus=1, object_store_memory=200 * 2**20)
            c.wait_for_nodes()
            row = {}
            for logs in ("bytes", "shared"):
                backend = Backend(kind="ray", jobs=nodes, address=c.address, logs=logs, engine="batch")
                with tempfile.TemporaryDirectory() as tmp:
                    warm = [RunSpec(SCENARIOS_DIR / "heave_drift.toml", ("simulation.duration=0.1",), seed=i,
                                log=Path(tmp) / f"w{i}.mcap") for i in range(4 * nodes)]
                    list(iter_results(warm, backend))  # the workers up and their callbacks loaded
                    jobs = [RunSpec(SCENARIOS_DIR / "heave_drift.toml", (f"simulation.duration={seconds!r}",
                                                                     f"law.k={150 + i % 100}"), seed=i,
                                log=Path(tmp) / f"r{i:05d}.mcap", keep_trajectory=False) for i in range(runs)]
                    c0, t0 = time.process_time(), time.perf_counter()
                    statuses = [r.status for _, r in iter_results(jobs, backend)]
                    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                    mb = sum(p.stat().st_size for p in Path(tmp).glob("r*.mcap")) / 2**20
                assert statuses == ["ok"] * runs, set(statuses)
                row[logs] = {"wall_s": wall, "runs_per_hour": 3600 * runs / wall, "driver_cpu_ms_per_run":
                             1e3 * cpu / runs, "log_mb_per_s": mb / wall,
                             "driver_bound_runs_per_hour": 3600 * runs / cpu if cpu > 0 else None}
                print(f"  ray {nodes} node(s), logs {logs}: {row[logs]}", file=sys.stderr, flush=True)
            out["nodes"][nodes] = row
    finally:
        c.shutdown()
    return out


def _peak_rss_kb(pid: int, stop: threading.Event, out: list) -> None:
    while not stop.is_set():
        try:
            for line in open(f"/proc/{pid}/status"):
                if line.startswith("VmHWM:"):
                    out.append(int(line.split()[1]))
        except OSError:
            pass
        stop.wait(0.2)


#: [s] the simulated length of each run of the study figure (the issue's 10⁴-run study: 2 s heave_drift runs)
STUDY_SECONDS = 2.0


def _bare_runs(args) -> None:
    """In a worker process: `runs` bare runs of the scenario's model of `seconds` [s] each (mj_resetData, then
    mj_step of all its steps), no law."""
    import mujoco

    from adaptive_mj.plants.mujoco_plant import timers_off
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load

    name, seconds, runs, timers = args
    model = build(load(SCENARIOS_DIR / f"{name}.toml", overrides=[f"simulation.duration={seconds!r}"])).plant.model
    data = mujoco.MjData(model)
    steps = int(round(seconds / model.opt.timestep))
    with timers_off(not timers):
        for _ in range(runs):
            mujoco.mj_resetData(model, data)
            mujoco.mj_step(model, data, nstep=steps)


def bare_limit(n: int, jobs: int = 2, sample: int = 1000, timers: bool = True) -> dict:
    """The bare-stepping limit of study(n): `jobs` processes at once, each stepping `sample` bare 2-s heave_drift
    runs (the model only: no law, no log), timed from all started to all done; the limit for n runs is
    n / (jobs · sample) times that wall time (the machine's parallel ceiling included, as the study has it).
    timers: MuJoCo's profiling timers on (mj_step as MuJoCo ships it) or off (plants.mujoco_plant.timers_off, as
    the native runs step). The bare-stepping figures are measured both ways: "bare" as MuJoCo ships mj_step (its
    clock read around each timed stage), "bare, timers off" the floor the runs themselves step at."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    with ctx.Pool(jobs) as pool:
        pool.map(_bare_runs, [("heave_drift", STUDY_SECONDS, 2, timers)] * jobs)  # imports, model built: warm
        t0 = time.perf_counter()
        pool.map(_bare_runs, [("heave_drift", STUDY_SECONDS, sample, timers)] * jobs)
        wall = time.perf_counter() - t0
    return {"sample_runs": jobs * sample, "sample_wall_s": wall, "limit_s": wall * n / (jobs * sample)}


def _closed_loop_runs(args) -> float:
    """In a worker process: `runs` of the study's 2-s heave_drift runs (its law.k grid and seeds), each compiled
    and unlogged (run_job); returns the seconds spent inside their mj_step calls only (the physics with the
    compiled law in MuJoCo's control callback: the closed loop with no Python between chunks)."""
    from adaptive_mj.study.job import RunSpec, run_job
    from adaptive_mj.setup.scenario import SCENARIOS_DIR

    first, runs, points = args
    jobs = [RunSpec(SCENARIOS_DIR / "heave_drift.toml", seed=i,
                    overrides=(f"simulation.duration={STUDY_SECONDS!r}",
                               f"law.k={100.0 + 200.0 * (i % points) / max(points - 1, 1)!r}"),
                    log=None, keep_trajectory=False) for i in range(first, first + runs)]
    with _timed_mj_step() as stepping:
        for job in jobs:
            run_job(job)
    return stepping[0]


def closed_loop_limit(n: int, jobs: int = 2, sample: int = 500, points: int = 100) -> dict:
    """The closed loop's own ceiling for study(n) (issue 51's target): `jobs` processes at once, each running
    `sample` of the study's runs compiled and timing only their mj_step calls (_closed_loop_runs); the ceiling for
    n runs is n / (jobs · sample) times the processes' mean stepping time (both cores busy, as in the study)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    with ctx.Pool(jobs) as pool:
        pool.map(_closed_loop_runs, [(0, 2, points)] * jobs)  # imports, the callback loaded: warm
        totals = pool.map(_closed_loop_runs, [(k * sample, sample, points) for k in range(jobs)])
    return {"sample_runs": jobs * sample, "stepping_s": totals,
            "limit_s": statistics.mean(totals) * n / (jobs * sample)}


def study(n: int, jobs: int = 2, backend: str = "local", engine: str = "process", logs: str = "all") -> dict:
    """`adaptive-mj sweep` over n 2-s runs of heave_drift (noise: the seeds differ); driver peak RSS; and the
    bare-stepping limit of the same runs measured just before and just after it (bare_limit, their mean), so
    the ratio limit / wall is taken at the machine's load of the moment.
    engine: --engine (process or batch); logs: --logs (all, or summary: the table only)."""
    before, before_off = bare_limit(n, jobs), bare_limit(n, jobs, timers=False)
    loop_before = closed_loop_limit(n, jobs)
    points = 100 if n >= 1000 else 10
    seeds = n // points
    folder = Path(tempfile.mkdtemp(prefix="scaling-study-"))
    try:
        cmd = [sys.executable, "-m", "adaptive_mj", "sweep", "heave_drift", "--grid", f"law.k=100:300:{points}",
               "--seeds", str(seeds), "--set", f"simulation.duration={STUDY_SECONDS!r}", "--jobs", str(jobs),
               "-o", str(folder / "out"), "--backend", backend, "--engine", engine, "--logs", logs]
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                env=dict(os.environ, MUJOCO_GL="egl"))
        stop, rss = threading.Event(), []
        th = threading.Thread(target=_peak_rss_kb, args=(proc.pid, stop, rss))
        th.start()
        _, err = proc.communicate()
        stop.set()
        th.join()
        wall = time.perf_counter() - t0
        assert proc.returncode == 0, err[-2000:]
        lines = (folder / "out" / "sweep.csv").read_text().count("\n") - 1
        size = sum(p.stat().st_size for p in (folder / "out" / "logs").glob("*.mcap")) if logs == "all" else 0
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    after, after_off = bare_limit(n, jobs), bare_limit(n, jobs, timers=False)
    loop_after = closed_loop_limit(n, jobs)
    loop = 0.5 * (loop_before["limit_s"] + loop_after["limit_s"])
    limit = 0.5 * (before["limit_s"] + after["limit_s"])
    limit_off = 0.5 * (before_off["limit_s"] + after_off["limit_s"])
    return {"backend": backend, "engine": engine, "logs": logs, "runs": points * seeds, "rows": lines, "wall_s": wall,
            "runs_per_s": points * seeds / wall, "driver_peak_rss_mb": max(rss) / 1024 if rss else None,
            "logs_mb": size / 2**20, "bare_limit_s": limit, "bare_limit_before_after_s": [before["limit_s"],
                                                                                         after["limit_s"]],
            "to_limit": limit / wall, "bare_limit_timers_off_s": limit_off, "to_limit_timers_off": limit_off / wall,
            "closed_loop_limit_s": loop, "closed_loop_before_after_s": [loop_before["limit_s"], loop_after["limit_s"]],
            "to_closed_loop": loop / wall}


def _batch_spec(name: str, overrides: list[str]) -> dict:
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load

    scn = load(SCENARIOS_DIR / f"{name}.toml", overrides=overrides)
    st = build(scn)
    return dict(plant=st.plant, law=st.law, reference=st.reference, duration=scn.simulation.duration,
                theta_hat0=st.theta_hat0, noise_std=st.noise_std, rng=st.rng, events=st.events,
                state_bound=scn.simulation.state_bound, sensors=st.sensors)


def _rss_kb() -> int:
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


#: plant -> (run lengths [s] measured) for per_run
PER_RUN_SECONDS = {"heave": (1.0, 2.0, 5.0, 30.0), "arm": (1.0, 2.0, 30.0), "ur5e": (0.2, 2.0)}


def per_run(reps: int, runs: int, cases: str = "") -> dict:
    """One run's cost in this process (see the module's doc): ms per run, median [min, max] of reps, each
    over `runs` runs; the runs vary as in the batch figures (BATCH_CASES), every run its own seed. cases: e.g.
    "ur5e=2" or "heave=2;ur5e=0.2,2" (plant=lengths [s], plants separated by ";"; "" = PER_RUN_SECONDS)."""
    import mujoco

    from adaptive_mj.plants.mujoco_plant import timers_off
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.runs.runner import start
    from adaptive_mj.study.job import run_job

    out: dict = {}
    chosen: dict[str, tuple[float, ...]] = {}
    for part in cases.split(";") if cases else ():
        plant, _, lengths = part.partition("=")
        chosen[plant] = tuple(float(v) for v in lengths.split(",")) if lengths else PER_RUN_SECONDS[plant]
    for label, lengths in (chosen or PER_RUN_SECONDS).items():
        name, _, vary = BATCH_CASES[label]
        for seconds in lengths:
            scn = load(SCENARIOS_DIR / f"{name}.toml", overrides=[f"simulation.duration={seconds!r}", *vary(0)])
            model = build(scn).plant.model
            data = mujoco.MjData(model)
            steps = int(round(seconds / model.opt.timestep))
            for job in _batch_jobs(name, seconds, vary, 2, None):  # the compiled callback loaded, caches warm
                run_job(job)
            times: dict[str, list[float]] = {"bare": [], "bare_timers_off": [], "start": [], "unlogged": [],
                                             "law_stepping": [], "logged": []}
            for _rep in range(reps):
                for key, off in (("bare", False), ("bare_timers_off", True)):
                    with timers_off(off):
                        t0 = time.perf_counter()
                        for _ in range(runs):
                            mujoco.mj_resetData(model, data)
                            mujoco.mj_step(model, data, nstep=steps)
                        times[key].append((time.perf_counter() - t0) / runs)
                scns = [load(SCENARIOS_DIR / f"{name}.toml", overrides=[f"simulation.duration={seconds!r}", *vary(i)],
                             seed=i) for i in range(runs)]
                t0 = time.perf_counter()
                for one in scns:
                    start(one)
                times["start"].append((time.perf_counter() - t0) / runs)
                for logged in (False, True):
                    folder = Path(tempfile.mkdtemp(prefix="scaling-per-run-")) if logged else None
                    try:
                        jobs = _batch_jobs(name, seconds, vary, runs, folder)
                        with _timed_mj_step() as stepping:
                            t0 = time.perf_counter()
                            results = [run_job(job) for job in jobs]
                            times["logged" if logged else "unlogged"].append((time.perf_counter() - t0) / runs)
                        if not logged:
                            times["law_stepping"].append(stepping[0] / runs)
                    finally:
                        if folder is not None:
                            shutil.rmtree(folder, ignore_errors=True)
                    assert all(r.status == "ok" for r in results), {r.status for r in results}
            row = {k: med([1e3 * v for v in vs]) for k, vs in times.items()}
            row["steps"] = steps
            row["unlogged_to_bare"] = row["bare"]["median"] / row["unlogged"]["median"]
            row["logged_to_bare"] = row["bare"]["median"] / row["logged"]["median"]
            row["law_ceiling"] = row["bare"]["median"] / row["law_stepping"]["median"]
            off = row["bare_timers_off"]["median"]  # the same ratios against bare stepping with the timers off
            row["unlogged_to_bare_timers_off"] = off / row["unlogged"]["median"]
            row["logged_to_bare_timers_off"] = off / row["logged"]["median"]
            row["law_ceiling_timers_off"] = off / row["law_stepping"]["median"]
            out[f"{label} {seconds:g} s"] = row
            print(f"  per_run {label} {seconds:g} s: " + ", ".join(
                f"{k} {v['median']:.2f} ms" if isinstance(v, dict) else f"{k} {v:.3g}" for k, v in row.items()),
                file=sys.stderr, flush=True)
    return out


@contextmanager
def _timed_mj_step():
    """Inside the block every mujoco.mj_step call (the plants' native chunks: the physics with the compiled
    law in MuJoCo's control callback) is timed; yields a one-element list holding their total [s]."""
    import mujoco

    total, step = [0.0], mujoco.mj_step

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return step(*args, **kwargs)
        finally:
            total[0] += time.perf_counter() - t0

    mujoco.mj_step = timed
    try:
        yield total
    finally:
        mujoco.mj_step = step


def print_per_run(fig: dict | None) -> None:
    for case, r in (fig or {}).items():
        def f(m):
            return f"{m['median']:.2f} [{m['min']:.2f}, {m['max']:.2f}]"
        print(f"per_run {case} ({r['steps']} steps): bare stepping {f(r['bare'])} ms; start (build) {f(r['start'])} "
              f"ms; run unlogged {f(r['unlogged'])} ms ({r['unlogged_to_bare']:.2f}x bare); run logged "
              f"{f(r['logged'])} ms ({r['logged_to_bare']:.2f}x bare); its physics with the law in the callback "
              f"{f(r['law_stepping'])} ms (the law's ceiling: {r['law_ceiling']:.2f}x bare); bare stepping with "
              f"MuJoCo's timers off {f(r['bare_timers_off'])} ms (against it: unlogged "
              f"{r['unlogged_to_bare_timers_off']:.2f}x, logged {r['logged_to_bare_timers_off']:.2f}x, the law's "
              f"ceiling {r['law_ceiling_timers_off']:.2f}x)")


#: plant -> (scenario, simulated seconds per run, the --set that varies a run i). The 6-joint runs are
#: shorter: 10^4 of them at 2 s would take minutes of stepping alone.
BATCH_CASES = {
    "heave": ("heave_drift", 1.0, lambda i: [f"law.k={150 + 100 * (i % 2)}"]),
    "arm": ("arm_payload_swap", 1.0, lambda i: ["events=[]", f"plant.payload_mass={0.5 + 0.1 * (i % 10)!r}"]),
    "ur5e": ("ur5e_identification", 0.2, lambda i: [f"law.kd={45.0 + i % 10}"]),
}


def _batch_jobs(name: str, seconds: float, vary, n: int, folder: Path | None):
    from adaptive_mj.study.job import RunSpec
    from adaptive_mj.setup.scenario import SCENARIOS_DIR

    return [RunSpec(SCENARIOS_DIR / f"{name}.toml", overrides=(f"simulation.duration={seconds!r}", "log.rate_hz=100",
                                                           *vary(i)),
                seed=i, log=None if folder is None else folder / f"{i:05d}.mcap", keep_trajectory=False)
            for i in range(n)]


#: runs per run_batch call in the batch figures (each prepared run holds its MjData, MjModel and row buffers:
#: 0.4-1 MB; 10^4 at once held 8 GB and left the process too big to fork the process pool afterwards)
RUN_BATCH_GROUP = 1000


def batch_figures(sizes: list[int], pool_nsim: int, threads: int = 2, plants: tuple[str, ...] = (),
                  durations: dict[str, float] | None = None) -> dict:
    """Issue 20's figures, per plant and nsim: the bare-stepping limit (a Batch of nsim simulations of the
    model with no law, `threads` threads) in simulation-steps per second; run_batch (the law, built runs,
    unlogged); the batched engine end to end (sweep's path, parallel.iter_results with engine "batch":
    building, stepping, verdicts) without logs and with MCAP logs at 100 Hz; the process pool on the same
    study (pool_nsim runs, without and with logs); durations: simulated seconds per run by plant, in place of
    BATCH_CASES's; and the memory a prepared run holds in the driver (VmRSS growth per run
    while nsim runs are held, divided by nsim)."""
    import gc

    import mujoco
    import mujoco.batch

    from adaptive_mj.sim.batch import run_batch
    from adaptive_mj.study.job import Backend
    from adaptive_mj.study.parallel import iter_results

    out: dict = {}
    for label, (name, seconds, vary) in BATCH_CASES.items():
        if plants and label not in plants:
            continue
        seconds = (durations or {}).get(label, seconds)
        steps = int(round(seconds / 0.001))
        warm = [_batch_spec(name, [f"simulation.duration={seconds!r}", *vary(i)]) for i in range(2)]
        run_batch(warm, nthread=threads)  # load the compiled callback outside the timings
        model = warm[0]["plant"].model
        rows = []
        for nsim in sizes:
            pool_s: dict[bool, float] = {}
            if nsim == pool_nsim:  # first: forking the pool from a process that has held 10^3 runs can fail (ENOMEM)
                for logged in (False, True):
                    folder = Path(tempfile.mkdtemp(prefix="scaling-pool-")) if logged else None
                    try:
                        jobs = _batch_jobs(name, seconds, vary, nsim, folder)
                        t0 = time.perf_counter()
                        res = [r for _, r in iter_results(jobs, Backend(jobs=threads))]
                        pool_s[logged] = time.perf_counter() - t0
                    finally:
                        if folder is not None:
                            shutil.rmtree(folder, ignore_errors=True)
            bare = mujoco.batch.Batch(model, nsim=nsim, nthread=threads)
            t0 = time.perf_counter()
            bare.step(nstep=steps)
            bare_s = time.perf_counter() - t0
            del bare
            gc.collect()
            build_s = step_s = 0.0
            held_kb = None
            for g in range(0, nsim, RUN_BATCH_GROUP):  # groups, as the engine holds them (memory: ~1 MB a run)
                rss0 = _rss_kb()
                t0 = time.perf_counter()
                runs = [_batch_spec(name, [f"simulation.duration={seconds!r}", f"noise.seed={i}", *vary(i)])
                        for i in range(g, min(nsim, g + RUN_BATCH_GROUP))]
                build_s += time.perf_counter() - t0
                t0 = time.perf_counter()
                run_batch(runs, nthread=threads)
                step_s += time.perf_counter() - t0
                held_kb = held_kb if held_kb is not None else (_rss_kb() - rss0) / len(runs)
                del runs
                gc.collect()
            row = {"nsim": nsim, "seconds": seconds, "sim_steps": nsim * steps,
                   "bare_steps_per_s": nsim * steps / bare_s,
                   "run_batch_steps_per_s": nsim * steps / step_s, "build_ms_per_run": 1e3 * build_s / nsim,
                   "driver_kb_per_run_held": held_kb}
            for logged in (False, True):
                folder = Path(tempfile.mkdtemp(prefix="scaling-batch-")) if logged else None
                try:
                    jobs = _batch_jobs(name, seconds, vary, nsim, folder)
                    t0 = time.perf_counter()
                    res = [r for _, r in iter_results(jobs, Backend(jobs=threads, engine="batch"))]
                    wall = time.perf_counter() - t0
                finally:
                    if folder is not None:
                        shutil.rmtree(folder, ignore_errors=True)
                assert all(r.status == "ok" for r in res), {r.status for r in res}
                row["engine_logged_steps_per_s" if logged else "engine_steps_per_s"] = nsim * steps / wall
            for logged, wall in pool_s.items():
                row["pool_logged_steps_per_s" if logged else "pool_steps_per_s"] = nsim * steps / wall
            for key in ("run_batch", "engine", "engine_logged", "pool", "pool_logged"):
                if f"{key}_steps_per_s" in row:
                    row[f"{key}_to_limit"] = row[f"{key}_steps_per_s"] / row["bare_steps_per_s"]
            rows.append(row)
            print(f"  batch {label} nsim {nsim}: " + ", ".join(
                f"{k} {v:.3g}" for k, v in row.items() if k not in ("nsim",)), file=sys.stderr, flush=True)
        state_bytes = 8 * mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_INTEGRATION)
        out[label] = {"rows": rows, "state_bytes": state_bytes, "mjdata_bytes": mujoco.MjData(model).nbuffer,
                      "mjmodel_bytes": model.nbuffer}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--runs", type=int, default=8, help="runs per throughput measurement (default 8)")
    ap.add_argument("--tasks", type=int, default=2000, help="no-op Ray tasks per overhead measurement")
    ap.add_argument("--study-runs", type=int, default=10000)
    ap.add_argument("--study-backend", default="local", choices=("local", "ray"))
    ap.add_argument("--study-engine", default="process", choices=("process", "batch"))
    ap.add_argument("--study-logs", default="all", choices=("all", "summary"))
    ap.add_argument("--batch-sims", default="100,1000,10000", help="nsim in the batch figures (default 100,1000,10000)")
    ap.add_argument("--pool-sims", type=int, default=1000, help="nsim at which the process pool runs the same study")
    ap.add_argument("--batch-plants", default="", help="comma-separated subset of heave,arm,ur5e (default: all)")
    ap.add_argument("--batch-seconds", default="", help="simulated seconds per run by plant, e.g. heave=2,arm=2 "
                    "(default: heave 1, arm 1, ur5e 0.2)")
    ap.add_argument("--ray-node-runs", type=int, default=400, help="runs per measurement in the ray_nodes figure")
    ap.add_argument("--per-run-runs", type=int, default=20, help="runs per repetition in the per_run figures")
    ap.add_argument("--per-run-cases", default="", help="the per_run figures' plants and run lengths [s], e.g. "
                    "'ur5e=2' or 'heave=2;ur5e=0.2,2' (default: every plant at every length of PER_RUN_SECONDS)")
    ap.add_argument("--only", default="ceiling,local,ray,study,batch,ray_nodes,per_run")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    parts = set(args.only.split(","))
    res = {"cpus": os.cpu_count()}
    if "ceiling" in parts:
        res["ceiling"] = ceiling(args.reps)
    if "local" in parts:
        res["local"] = local(args.reps, args.runs)
    if "ray" in parts:
        res["ray"] = ray_figures(args.reps, args.runs, args.tasks)
    if "study" in parts:
        kw = dict(backend=args.study_backend, engine=args.study_engine, logs=args.study_logs)
        res["study_small"] = study(max(100, args.study_runs // 10), **kw)
        res["study"] = study(args.study_runs, **kw)
    if "ray_nodes" in parts:
        res["ray_nodes"] = ray_nodes(args.ray_node_runs)
    if "per_run" in parts:
        res["per_run"] = per_run(args.reps, args.per_run_runs, args.per_run_cases)
    if "batch" in parts:
        durations = {k: float(v) for k, v in (kv.split("=") for kv in args.batch_seconds.split(",") if kv)}
        res["batch"] = batch_figures([int(n) for n in args.batch_sims.split(",")], args.pool_sims,
                                     plants=tuple(p for p in args.batch_plants.split(",") if p), durations=durations)
    if args.json:
        print(json.dumps(res, indent=1))
        return

    def f(m, fmt="{:.1f}"):
        return f"{fmt.format(m['median'])} [{fmt.format(m['min'])}, {fmt.format(m['max'])}]"

    if "ceiling" in res:
        print(f"ceiling: 2 busy processes vs 1: {f(res['ceiling']['ratio_2_over_1'], '{:.2f}')}x")
    if "local" in res:
        lo = res["local"]
        print(f"local: {lo['runs']} logged {SECONDS:g} s heave runs: 1 job {f(lo['jobs1_runs_per_min'])} runs/min, "
              f"2 jobs {f(lo['jobs2_runs_per_min'])} runs/min, ratio {f(lo['ratio'], '{:.2f}')}x; driver CPU "
              f"{f(lo['driver_cpu_s_jobs2'], '{:.3f}')} s with 2 jobs")
        print("  serial parts of a sweep [s]: " + ", ".join(f"{k} {v:.3f}" for k, v in lo["serial_parts_s"].items()))
    if "ray" in res:
        r = res["ray"]
        print(f"ray (started here, 2 CPUs): start {r['ray_start_s']:.1f} s; "
              f"no-op task {f(r['noop_task_ms'], '{:.2f}')} ms each; "
              f"first batch of 4 runs {r['first_batch_s_4_runs']:.1f} s (worker start + compile); then "
              f"{f(r['runs_per_min'])} runs/min (logs as bytes; shared logs {f(r['runs_per_min_shared_logs'])}), "
              f"driver CPU for {r['runs']} runs {f(r['driver_cpu_s'], '{:.3f}')} s (shared logs "
              f"{f(r['driver_cpu_s_shared_logs'], '{:.3f}')} s); local backend meanwhile {f(r['local_runs_per_min'])} "
              f"runs/min: Ray/local {f(r['ratio_to_local'], '{:.2f}')}, {f(r['overhead_per_run_ms'])} ms more per run")
    for key in ("study_small", "study"):
        if key in res:
            s = res[key]
            print(f"study ({s['backend']} backend, engine {s['engine']}, logs {s['logs']}): {s['runs']} runs of "
                  f"{STUDY_SECONDS:g} s ({s['rows']} rows): {s['wall_s']:.0f} s, "
                  f"{s['runs_per_s']:.1f} runs/s, driver peak RSS {s['driver_peak_rss_mb']:.0f} MB, "
                  f"logs {s['logs_mb']:.0f} MB; bare stepping of the same runs on 2 processes "
                  f"{s['bare_limit_s']:.1f} s (before/after {s['bare_limit_before_after_s'][0]:.1f}/"
                  f"{s['bare_limit_before_after_s'][1]:.1f}): {s['to_limit']:.2f}x the bare-stepping limit; with "
                  f"MuJoCo's timers off (as the runs step) {s['bare_limit_timers_off_s']:.1f} s: "
                  f"{s['to_limit_timers_off']:.2f}x; the closed loop's own ceiling (the same runs compiled, only "
                  f"their mj_step calls timed) {s['closed_loop_limit_s']:.1f} s (before/after "
                  f"{s['closed_loop_before_after_s'][0]:.1f}/{s['closed_loop_before_after_s'][1]:.1f}): "
                  f"{s['to_closed_loop']:.2f}x")
    print_batch(res.get("batch", {}))
    print_ray_nodes(res.get("ray_nodes"))
    print_per_run(res.get("per_run"))


def print_ray_nodes(fig: dict | None) -> None:
    for nodes, row in (fig or {}).get("nodes", {}).items():
        for logs, r in row.items():
            print(f"ray_nodes: {nodes} node(s), --engine batch, logs {logs}: {r['runs_per_hour']:.0f} runs/h "
                  f"({fig['runs']} runs of {fig['seconds']:g} s in {r['wall_s']:.1f} s), "
                  f"driver {r['driver_cpu_ms_per_run']:.1f} ms CPU/run -> at most "
                  f"{r['driver_bound_runs_per_hour']:.0f} runs/h by the driver, logs {r['log_mb_per_s']:.2f} MB/s")


def print_batch(figures: dict) -> None:
    for label, b in figures.items():
        print(f"batch {label} ({b['rows'][0]['seconds']:g} s runs; state row {b['state_bytes']} B, MjData "
              f"{b['mjdata_bytes']} B, MjModel {b['mjmodel_bytes']} B): sim-steps/s, and x the bare limit")
        for r in b["rows"]:
            cells = [f"nsim {r['nsim']:>6}", f"bare {r['bare_steps_per_s']:.3g}",
                     f"run_batch {r['run_batch_steps_per_s']:.3g} ({r['run_batch_to_limit']:.2f}x)",
                     f"engine {r['engine_steps_per_s']:.3g} ({r['engine_to_limit']:.2f}x)",
                     f"engine+logs {r['engine_logged_steps_per_s']:.3g} ({r['engine_logged_to_limit']:.2f}x)"]
            if "pool_steps_per_s" in r:
                cells.append(f"process pool {r['pool_steps_per_s']:.3g} ({r['pool_to_limit']:.2f}x)")
            if "pool_logged_steps_per_s" in r:
                cells.append(f"process pool+logs {r['pool_logged_steps_per_s']:.3g} ({r['pool_logged_to_limit']:.2f}x)")
            cells.append(f"build {r['build_ms_per_run']:.2f} ms/run, held {r['driver_kb_per_run_held']:.0f} kB/run")
            print("  " + "; ".join(cells))


if __name__ == "__main__":
    main()

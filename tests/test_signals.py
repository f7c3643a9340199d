"""Interruption with real signals to a real process: SIGINT and SIGTERM finish every open
log (readable by make_reader, status "interrupted") and leave no worker behind; SIGKILL
loses at most the last second of simulated data; a run that fails leaves no good-looking log."""
from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
import weakref
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from adaptive_mj.cli import main
from adaptive_mj.log.replay import JsonDecoderFactory, read_log
from adaptive_mj.sim.compile_note import is_note as is_compile_note

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL") or not Path("/proc").is_dir(),
                                reason="needs POSIX signals and /proc")

REPO = Path(__file__).resolve().parents[1]
LONG = "simulation.duration=3000.0"  # far longer than any test waits: the signal always comes mid-run


def start(*args: str) -> subprocess.Popen:
    """The CLI in its own process group (as a shell runs a foreground job)."""
    env = dict(os.environ, MUJOCO_GL="egl")
    return subprocess.Popen([sys.executable, "-m", "adaptive_mj", *map(str, args)], cwd=REPO, env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def wait_for(condition, proc: subprocess.Popen, *, timeout: float = 120.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the process ended (rc={proc.returncode}) before {what}:\n{out}\n{err}")
        if time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.05)


def children(pid: int) -> set[int]:
    """Direct children of pid (from /proc)."""
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.add(int(stat.parent.name))
    return out


def alive(pid: int) -> bool:
    """Running (a zombie, exited but not yet reaped by init, counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def assert_gone(pids: set[int], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while any(alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [p for p in pids if alive(p)], "orphan processes left behind"


def closed_status(path: Path) -> dict:
    """The /summary of a log read through its index: make_reader needs the footer."""
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[JsonDecoderFactory()])
        assert reader.get_summary() is not None
        summaries = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/summary"])]
    assert len(summaries) == 1
    return summaries[0]


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_signal_during_run_closes_the_log_as_interrupted(tmp_path, capsys, sig, code):
    log = tmp_path / "run.mcap"
    proc = start("run", "heave_drift", "-o", log, "--json", "--set", LONG)
    wait_for(lambda: log.is_file() and log.stat().st_size > 100_000, proc, what="the log to grow")
    os.kill(proc.pid, sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    name = signal.Signals(sig).name
    lines = [ln for ln in err.strip().splitlines() if not is_compile_note(ln)]
    assert len(lines) == 1 and lines[0].startswith(f"adaptive-mj: interrupted by {name}; ")
    assert f"log closed with status 'interrupted': {log}" in lines[0]
    printed = json.loads(out)
    assert printed["status"] == "interrupted" and printed["reason"] == f"interrupted by {name}"
    assert 2.0 < printed["duration"] < 3000.0

    logged = closed_status(log)
    assert logged == printed  # the log's /summary is the summary printed
    run = read_log(log)
    assert run.status == "interrupted" and run.note == ""
    # every row simulated before the signal is in the log, not only the whole 1 s blocks
    row_span = run.header["log_every"] * run.header["dt"]
    t_end = run.trajectory.t[-1] + row_span  # the logged rows cover [0, t_end)
    assert printed["duration"] - 1e-9 <= t_end < printed["duration"] + row_span
    assert main(["replay", str(log), "--json"]) == 1  # not ok, not bad input
    assert json.loads(capsys.readouterr().out) == printed


def sweep_in_two_workers(tmp_path: Path) -> tuple[subprocess.Popen, Path, set[int]]:
    """A 3-run sweep in 2 worker processes, once both workers' logs are growing: (process, logs folder, workers)."""
    out_dir = tmp_path / "sweep"
    proc = start("sweep", "heave_drift", "--grid", "law.k=100,200,300", "--jobs", "2", "-o", out_dir,
                 "--set", LONG)
    logs = out_dir / "logs"
    wait_for(lambda: len([p for p in logs.glob("*.mcap") if p.stat().st_size > 50_000]) == 2, proc,
             what="both workers' logs to grow")
    return proc, logs, children(proc.pid)


def test_sigint_to_the_process_group_during_sweep_closes_every_log_and_leaves_no_worker(tmp_path):
    proc, logs, workers = sweep_in_two_workers(tmp_path)
    assert len(workers) >= 2
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: every process of the group
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    last = err.strip().splitlines()[-1]
    assert last == ("adaptive-mj: interrupted by SIGINT; 0 of 3 runs had finished; "
                    "the run(s) in progress closed their logs as 'interrupted'")
    assert "Traceback" not in err
    assert_gone(workers)
    written = sorted(logs.glob("*.mcap"))
    assert len(written) == 2  # the third run never started, and left no file
    for path in written:
        summary = closed_status(path)
        assert summary["status"] == "interrupted" and summary["duration"] > 1.0
        assert read_log(path).status == "interrupted"


def test_sigterm_to_one_sweep_worker_stops_the_whole_sweep_cleanly(tmp_path):
    proc, logs, workers = sweep_in_two_workers(tmp_path)
    parent_cmd = Path(f"/proc/{proc.pid}/cmdline").read_bytes()
    worker = next(p for p in workers  # forked workers share the parent's command line (spawned: spawn_main)
                  if Path(f"/proc/{p}/cmdline").read_bytes() in (parent_cmd,) or b"spawn_main" in
                  Path(f"/proc/{p}/cmdline").read_bytes())
    os.kill(worker, signal.SIGTERM)  # e.g. a scheduler stopping one process: all runs stop, none half-logged
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert err.strip().splitlines()[-1].startswith("adaptive-mj: interrupted by SIGTERM; 0 of 3 runs had finished")
    assert_gone(workers)
    assert sorted(closed_status(path)["status"] for path in logs.glob("*.mcap")) == ["interrupted"] * 2


def test_sigterm_to_bench_closes_every_log_and_leaves_no_worker(tmp_path):
    out_dir = tmp_path / "bench"
    proc = start("bench", "--quick", "--jobs", "2", "-o", out_dir)
    logs = out_dir / "logs"

    def open_sizes() -> dict:
        """The sizes of the logs not closed yet (no MCAP footer) [bytes]."""
        out = {}
        for p in logs.glob("*.mcap"):
            try:
                data = p.read_bytes()
            except OSError:
                continue
            if not data.endswith(b"\x89MCAP0\r\n"):
                out[p] = len(data)
        return out

    def a_log_is_being_written() -> bool:
        """A log past its header that is still growing: its run is under way now, so the signal lands in a run (a
        log merely open and large could be about to close, and a signal between runs closes none as interrupted)."""
        before = open_sizes()
        time.sleep(0.05)
        after = open_sizes()
        return any(size > 20_000 and after.get(p, 0) > size for p, size in before.items())

    # a cold numba cache: the workers compile the bench's callbacks first (minutes on a loaded 2-core machine)
    wait_for(a_log_is_being_written, proc, timeout=600, what="a worker to be writing a log")
    workers = children(proc.pid)
    assert len(workers) >= 2
    os.kill(proc.pid, signal.SIGTERM)  # the parent only: it stops its workers itself
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    last = err.strip().splitlines()[-1]
    assert last.startswith("adaptive-mj: interrupted by SIGTERM; ") and "Traceback" not in err
    assert_gone(workers)
    # every log closed, but one a worker left unfinished when it was killed after the grace period (deep in a
    # native call, a compile of a cold cache under load): named in the message, and read as truncated
    statuses = [closed_status(path)["status"] if str(path) not in last else read_log(path).status
                for path in logs.glob("*.mcap")]
    assert statuses and set(statuses) <= {"ok", "diverged", "interrupted", "truncated"}
    assert "interrupted" in statuses or "truncated" in statuses
    assert not (out_dir / "report.md").exists()  # no report made of an interrupted bench


# One compiled call of about spin_s seconds: spinner(spin_s) compiles it in the process that calls it and returns it
# (in the call, as in an LLVM pass that long, no Python signal handler can run until it returns).
_SPIN = textwrap.dedent("""
    import math, time
    import numba


    def spinner(spin_s):
        @numba.njit(cache=False)
        def spin(n):
            x = 0.0
            for i in range(n):
                x = math.sin(x + 1e-9 * i)
            return x

        spin(10)  # compiled here
        t0 = time.perf_counter()
        spin(2_000_000)
        n = int(2_000_000 * spin_s / max(time.perf_counter() - t0, 1e-6))
        return lambda: spin(n)
""")

# A study whose workers compile: the parent does not compile their callbacks first (parallel._prewarm off, as
# where fork is missing or a job's variant is not among the parent's), and numba's cache is empty (the test's
# NUMBA_CACHE_DIR). With SPIN set, each worker first spends about a minute in one compiled call before it
# compiles (an LLVM pass as long as that: no Python signal handler can run until it returns), having touched
# <MARKERS>/<pid> so the test knows it is there.
_COMPILING_STUDY = _SPIN + textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from adaptive_mj.study import parallel
    from adaptive_mj.sim import loop
    from adaptive_mj.cli import main

    parallel._prewarm = lambda jobs, n_jobs=1: None
    markers, spin_s = Path(sys.argv[1]), float(sys.argv[2])
    native_controller = loop._native_controller
    in_the_call = spinner(spin_s) if spin_s > 0 else (lambda: None)  # compiled in the parent

    def marked_native_controller(*args, **kwargs):
        (markers / str(os.getpid())).touch()
        in_the_call()
        return native_controller(*args, **kwargs)

    loop._native_controller = marked_native_controller
    sys.exit(main(sys.argv[3:]))
""")


def start_compiling_sweep(tmp_path: Path, spin_s: float) -> tuple[subprocess.Popen, Path, Path]:
    out_dir, markers = tmp_path / "sweep", tmp_path / "markers"
    markers.mkdir()
    env = dict(os.environ, MUJOCO_GL="egl", NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"))
    proc = subprocess.Popen([sys.executable, "-c", _COMPILING_STUDY, str(markers), str(spin_s), "sweep", "heave_drift",
                             "--grid", "law.k=100,200,300", "--jobs", "2", "-o", str(out_dir), "--set", LONG],
                            cwd=REPO, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    return proc, out_dir / "logs", markers


def sigterm_when_marked(proc: subprocess.Popen, markers: Path, *, what: str, timeout: float):
    """Wait until two processes of proc have touched <markers>/<pid> (each is one of proc's children), SIGTERM
    proc alone, and wait for it: (those children's pids, stdout, stderr, seconds from the signal to the exit)."""
    wait_for(lambda: len(list(markers.iterdir())) == 2, proc, timeout=300, what=what)
    pids = children(proc.pid)
    assert {int(m.name) for m in markers.iterdir()} <= pids
    t0 = time.monotonic()
    os.kill(proc.pid, signal.SIGTERM)
    out, err = proc.communicate(timeout=timeout)
    return pids, out, err, time.monotonic() - t0


def test_sigterm_while_the_workers_compile_ends_the_sweep_within_seconds(tmp_path):
    """The signal comes while both workers compile their first run's callback from an empty numba cache: the sweep
    ends within seconds, every log closed as 'interrupted' (or, for a worker that had to be killed, named as
    unfinished), no worker left."""
    proc, logs, markers = start_compiling_sweep(tmp_path, spin_s=0.0)
    workers, out, err, took = sigterm_when_marked(proc, markers, what="both workers to start compiling", timeout=60)
    assert proc.returncode == 143, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last.startswith("adaptive-mj: interrupted by SIGTERM; 0 of 3 runs had finished"), last
    assert took < 20.0, f"{took:.1f} s from SIGTERM to exit"
    assert_gone(workers)
    written = sorted(logs.glob("*.mcap"))
    assert len(written) == 2
    for path in written:
        if str(path) in last:  # a worker killed after the grace period: named, and read as truncated
            assert read_log(path).status == "truncated"
        else:
            assert closed_status(path)["status"] == "interrupted"


def test_the_parent_does_not_wait_for_a_worker_deep_in_a_native_call(tmp_path):
    """Each worker is a minute deep in one compiled call (as in a long LLVM pass) when the parent gets SIGTERM: it
    gives them parallel.STOP_GRACE s, kills them, and says which logs they left unfinished; it does not wait the
    minute. (Before: the parent waited up to 30 s for each.)"""
    from adaptive_mj.study.parallel import STOP_GRACE

    proc, logs, markers = start_compiling_sweep(tmp_path, spin_s=120.0)
    workers, out, err, took = sigterm_when_marked(proc, markers, what="both workers to be in the call", timeout=100)
    assert proc.returncode == 143, err
    assert STOP_GRACE <= took < 15.0, f"{took:.1f} s from SIGTERM to exit"  # a minute, had it waited
    last = err.strip().splitlines()[-1]
    assert last.startswith("adaptive-mj: interrupted by SIGTERM; 0 of 3 runs had finished"), last
    assert f"2 worker(s) had not stopped {STOP_GRACE:g} s after SIGTERM and were killed" in last
    assert_gone(workers)
    written = sorted(logs.glob("*.mcap"))
    assert len(written) == 2
    assert last.endswith(", ".join(map(str, written))) or last.endswith(", ".join(map(str, reversed(written))))
    assert [read_log(path).status for path in written] == ["truncated", "truncated"]


def test_workers_whose_parent_is_killed_close_their_logs_and_exit(tmp_path):
    """SIGKILL to the parent (no handler runs there): its workers see it (parallel._watch_parent), close
    their runs' logs as 'interrupted' and exit; none runs on."""
    proc, logs, workers = sweep_in_two_workers(tmp_path)
    assert len(workers) == 2
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    assert_gone(workers, timeout=15.0)
    written = sorted(logs.glob("*.mcap"))
    assert len(written) == 2
    for path in written:
        assert closed_status(path)["status"] == "interrupted"


# A parent holding a pool of study workers (forked, started by parallel._init_worker as every study's are), idle
# between runs: it prints their pids, then waits
_IDLE_POOL = textwrap.dedent("""
    import concurrent.futures as cf, multiprocessing as mp, os, time
    from adaptive_mj.study import parallel

    pool = cf.ProcessPoolExecutor(2, mp_context=mp.get_context("fork"), initializer=parallel._init_worker,
                                  initargs=(os.getpid(),))
    pool.submit(os.getpid).result()  # a fork pool starts all its workers at its first submit
    print(*sorted(pool._processes), flush=True)
    time.sleep(600)
""")


def test_idle_workers_whose_parent_is_killed_exit_within_seconds():
    """SIGKILL to a parent whose workers wait for their next run (in the pool's queue: no run to interrupt): each
    sees it (parallel._watch_parent) and exits within seconds; none waits on for a job that will never come."""
    from adaptive_mj.study.parallel import PARENT_POLL_S

    proc = subprocess.Popen([sys.executable, "-c", _IDLE_POOL], cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        workers = set(map(int, proc.stdout.readline().split()))
        assert len(workers) == 2 and workers <= children(proc.pid) and all(alive(p) for p in workers)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert_gone(workers, timeout=5.0 + PARENT_POLL_S)


def test_a_stop_raised_inside_a_weakref_callback_is_raised_again_in_the_main_code(capfd):
    """Python drops an exception raised inside a weakref callback (printed as "Exception ignored"): a stop signal
    whose handler ran there would be lost, and the process would go on (seen: a bench's worker ran its run to the
    end, a bench ran all 241 runs after SIGTERM). interrupt delivers it again until it is raised where it can be."""
    from adaptive_mj.errors import Interrupted
    from adaptive_mj.sim import interrupt
    from adaptive_mj.sim.interrupt import stop_on_signals

    class Thing:
        pass

    hook = sys.unraisablehook
    t0 = time.monotonic()
    with pytest.raises(Interrupted) as info, stop_on_signals():
        thing = Thing()
        ref = weakref.ref(thing, lambda r: signal.raise_signal(signal.SIGTERM))  # the handler runs inside it
        del thing  # Python drops the Interrupted raised in the callback
        while time.monotonic() - t0 < 5.0:  # plain Python code: where the second delivery raises
            pass
    assert info.value.signum == signal.SIGTERM
    assert time.monotonic() - t0 < 2.0
    assert ref() is None
    assert "Exception ignored" not in capfd.readouterr().err  # taken by interrupt's hook, not printed
    assert sys.unraisablehook is hook  # put back when the block ends
    assert interrupt.requested() is None


def test_a_redelivery_that_lands_while_the_hook_still_runs_is_raised_by_the_next(monkeypatch, capfd):
    """The dropped stop's redelivery can land while interrupt's unraisable hook is still starting the thread that
    sends it (seen under load: the thread's start waited, the handler ran inside the hook, and its Interrupted was
    dropped there too, so a SIGTERM was lost). Here that delivery is made to land inside the hook: it is not raised
    there, and the next one raises it in the main code."""
    import threading

    from adaptive_mj.errors import Interrupted
    from adaptive_mj.sim.interrupt import stop_on_signals

    start = threading.Timer.start

    def start_late(self):
        signal.raise_signal(signal.SIGTERM)  # the handler runs now, inside the hook
        start(self)

    monkeypatch.setattr(threading.Timer, "start", start_late)

    class Thing:
        pass

    t0 = time.monotonic()
    with pytest.raises(Interrupted) as info, stop_on_signals():
        thing = Thing()
        ref = weakref.ref(thing, lambda r: signal.raise_signal(signal.SIGTERM))
        del thing
        while time.monotonic() - t0 < 5.0:
            pass
    assert info.value.signum == signal.SIGTERM and time.monotonic() - t0 < 2.0
    assert ref() is None
    assert "Exception ignored" not in capfd.readouterr().err


# The pool of the test below, for its forked worker to reach the result pipe's write end.
_POOL: list = []


def _half_a_result(_):
    """A worker that has sent half of a result (a 1 MB message's length and its first 100 bytes) and is then deaf
    to SIGTERM: killed after the grace period."""
    import struct

    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    os.write(_POOL[0]._result_queue._writer.fileno(), struct.pack("!i", 1_000_000) + bytes(100))
    time.sleep(120)


@pytest.mark.skipif("fork" not in __import__("multiprocessing").get_all_start_methods(), reason="needs fork")
def test_a_worker_killed_while_it_sends_a_result_does_not_hang_the_parent():
    """The CI hang of issue 55: a worker killed in the middle of sending its result left the pool's manager thread
    waiting for the rest of the message, and concurrent.futures joins that thread at exit: the bench printed its
    stop line and never ended. After _stop_workers, the thread ends within seconds."""
    import concurrent.futures as cf
    import multiprocessing as mp

    from adaptive_mj.study.parallel import _stop_workers

    pool = cf.ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("fork"))
    _POOL[:] = [pool]
    try:
        future = pool.submit(_half_a_result, None)
        manager = pool._executor_manager_thread
        time.sleep(1.0)  # the worker has written its half message, and the manager thread waits for the rest
        assert manager.is_alive() and not future.done()
        assert _stop_workers(pool, grace=0.5) == 1  # deaf to SIGTERM: killed
        manager.join(10.0)
        assert not manager.is_alive(), "the pool's manager thread still waits for the half-sent result"
        assert isinstance(future.exception(timeout=5), cf.process.BrokenProcessPool)
    finally:
        _POOL.clear()
        pool.shutdown(wait=False)


# A `run` whose every reading of the plant state also stores the simulated time reached in a
# shared 8-byte file, so the test knows how far the run had got when it was killed.
_TRACED_RUN = textwrap.dedent("""
    import mmap, struct, sys
    from adaptive_mj.runs import runner
    from adaptive_mj.cli import main

    with open(sys.argv[1], "r+b") as f:
        reached = mmap.mmap(f.fileno(), 8)
    build = runner.build

    def traced_build(scn, **kw):
        setup = build(scn, **kw)
        plant, observe = setup.plant, setup.plant.observe

        def traced_observe():
            x = observe()
            struct.pack_into("<d", reached, 0, plant.time)
            return x

        plant.observe = traced_observe
        return setup

    runner.build = traced_build
    sys.exit(main(sys.argv[2:]))
""")


@pytest.mark.parametrize("scenario, grow_to", [("heave_drift", 150_000), ("lecture_first_order", 150_000)])
def test_sigkill_loses_at_most_one_second_and_replay_reports_truncated(tmp_path, scenario, grow_to):
    log = tmp_path / "killed.mcap"
    shared = tmp_path / "reached"
    shared.write_bytes(bytes(8))
    env = dict(os.environ, MUJOCO_GL="egl")
    proc = subprocess.Popen([sys.executable, "-c", _TRACED_RUN, str(shared), "run", scenario, "-o", str(log),
                             "--set", LONG], cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: log.is_file() and log.stat().st_size > grow_to, proc, what="the log to grow")
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    (reached,) = struct.unpack("<d", shared.read_bytes())

    run = read_log(log)
    assert run.status == "truncated" and run.summary is None
    row_span = run.header["log_every"] * run.header["dt"]
    recovered = run.trajectory.t[-1] + row_span  # the rows cover [0, recovered)
    lost = reached - recovered
    assert reached > 2.0
    assert -1e-9 <= lost <= 1.0 + 1e-9, f"reached {reached} s, recovered up to {recovered} s"
    assert run.note.startswith(f"recovered {run.recovered_rows} rows ({run.recovered_rows * row_span:.1f} s) "
                               "of a truncated log")

    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "replay", str(log)], cwd=REPO, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and r.stderr == ""
    assert r.stdout.startswith(f"{scenario}: truncated (recovered {run.recovered_rows} rows")


# -- a run that fails never leaves a file that looks like a good log ------------------------------

def test_run_that_fails_to_start_leaves_no_file(tmp_path, capsys):
    log = tmp_path / "x.mcap"
    code = main(["run", "heave_tracking", "-o", str(log), "--set", "plant.model=no_such_model"])
    assert code == 2 and "no_such_model.xml' not found" in capsys.readouterr().err
    assert not log.exists()


def test_interrupted_before_the_log_opens_leaves_no_file(tmp_path, capsys, monkeypatch):
    from adaptive_mj.runs import runner

    def interrupted_build(scn, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "build", interrupted_build)
    log = tmp_path / "x.mcap"
    assert main(["run", "lecture_first_order", "-o", str(log)]) == 130
    assert capsys.readouterr().err == "adaptive-mj: interrupted by SIGINT\n"
    assert not log.exists()


def test_force_keeps_the_old_log_when_the_new_run_cannot_start(tmp_path, capsys):
    log = tmp_path / "x.mcap"
    assert main(["run", "lecture_first_order", "-o", str(log), "--set", "simulation.duration=0.5",
                 "--set", "success.tail_rms=inf"]) == 0  # 0.5 s: not converged, and not the point here
    before = log.read_bytes()
    code = main(["run", "heave_tracking", "-o", str(log), "--force", "--set", "plant.model=no_such_model"])
    assert code == 2
    assert log.read_bytes() == before


def test_crash_mid_run_leaves_a_failed_log_that_replay_reports(tmp_path, capsys, monkeypatch):
    from adaptive_mj.runs import runner

    run = runner.run

    def crashing_run(plant, law, reference, **kw):  # the reference fails once the run is under way
        def crashing_reference(t, n):  # t: one time (the Python path) or a chunk's stage times (the compiled loop)
            if np.max(t) > 1.5:
                raise RuntimeError("sensor driver crashed")
            return reference(t, n)

        return run(plant, law, crashing_reference, **kw)

    monkeypatch.setattr(runner, "run", crashing_run)
    log = tmp_path / "crash.mcap"
    with pytest.raises(RuntimeError, match="sensor driver crashed"):
        main(["run", "lecture_first_order", "-o", str(log)])
    monkeypatch.undo()
    capsys.readouterr()
    run = read_log(log)
    assert run.status == "failed" and run.trajectory.reason == "RuntimeError: sensor driver crashed"
    assert closed_status(log)["status"] == "failed"
    assert main(["replay", str(log)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("lecture_first_order: failed (RuntimeError: sensor driver crashed), 1.000 s simulated")


def test_sigint_during_a_batched_sweep_closes_every_log_of_the_batch_as_interrupted(tmp_path):
    """--engine batch: the runs of a group are stepped together in the driver's mujoco.batch.Batch; Ctrl-C
    mid-batch closes every one of their logs as "interrupted" (each readable through its index, with the
    rows simulated before the signal), exit 130, one line, and the runs of later groups never start."""
    out_dir = tmp_path / "sweep"
    proc = start("sweep", "heave_drift", "--grid", "law.k=100,200,300", "--engine", "batch", "--jobs", "2",
                 "-o", out_dir, "--set", LONG)
    logs = out_dir / "logs"
    wait_for(lambda: len([p for p in logs.glob("*.mcap") if p.stat().st_size > 50_000]) == 3, proc,
             what="the batch's three logs to grow")
    os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    last = err.strip().splitlines()[-1]
    assert last == ("adaptive-mj: interrupted by SIGINT; 0 of 3 runs had finished; "
                    "the run(s) in progress closed their logs as 'interrupted'")
    written = sorted(logs.glob("*.mcap"))
    assert len(written) == 3
    durations = []
    for path in written:
        summary = closed_status(path)
        assert summary["status"] == "interrupted" and summary["duration"] > 1.0
        run = read_log(path)
        assert run.status == "interrupted"
        assert run.trajectory.t[-1] > 1.0  # the rows simulated before the signal are in the log
        durations.append(summary["duration"])
    assert max(durations) - min(durations) <= 1.0 + 1e-9  # stepped together: at most one chunk (1 s) apart


def test_a_signal_during_a_flush_waits_until_its_rows_are_written():
    """A stop signal that comes while a block of rows is being flushed (its V computed, then written) is raised
    once the block is in the sink: before, one that came after the block was marked flushed but before the
    write left those rows out of the log while the run's summary counted them (seen once in CI as a log
    ending at 8 s of a summary's 9 s)."""
    import numpy as np

    from adaptive_mj.errors import Interrupted
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.sim.interrupt import stop_on_signals
    from adaptive_mj.sim.loop import Rows

    setup = build(load(SCENARIOS_DIR / "heave_tracking.toml"))
    written = []

    class Sink:
        def write_rows(self, start, t, *rest):
            written.append((start, len(t)))

    class SignalInV:  # the signal arrives while V is computed for the block
        names = setup.law.names

        def lyapunov(self, s, theta_hat, theta, M=None):
            os.kill(os.getpid(), signal.SIGTERM)
            return np.zeros(len(s))

    rows = Rows(setup.plant, SignalInV(), 10, Sink(), 5)
    row = (np.zeros(1), np.zeros((1, 2)), np.zeros(1), np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)))  # one step's
    with pytest.raises(Interrupted), stop_on_signals():
        for _ in range(5):
            rows.put_block(row, np.ones(3), 1)
    assert written == [(0, 5)] and rows.flushed == 5


def test_a_stop_between_the_last_step_and_the_verdict_still_closes_the_log(tmp_path, monkeypatch):
    """A stop signal after a run's last step, before its verdict closed the log (a compiled twin run's loop is over in
    20 ms, its verdict takes about as long): the log is closed as "interrupted" with every row, never left
    unfinished."""
    from adaptive_mj.errors import Interrupted
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.scenario import SCENARIOS_DIR
    from adaptive_mj.runs import runner

    def stopped(*args, **kwargs):
        raise Interrupted(signal.SIGTERM)

    monkeypatch.setattr(runner, "verdict", stopped)
    log = tmp_path / "phase.mcap"
    with pytest.raises(Interrupted):
        runner.execute(sc.load(SCENARIOS_DIR / "lecture_phase_space.toml"), log_path=log)
    assert closed_status(log)["status"] == "interrupted"
    assert len(read_log(log).trajectory.t) == 2000  # every row of the 20 s run, at the log's 100 Hz


def test_a_stop_in_the_loop_body_between_two_results_stops_the_workers_before_it_goes_on(tmp_path):
    """A stop signal delivered again (interrupt's hook) may land in run_jobs' own loop body, between two results,
    not inside the pool's generator: it is thrown into the generator there, so the workers are stopped and the note
    says how many runs had finished before the message is printed (seen in CI: a bench's stop line with no note)."""
    import multiprocessing as mp

    from adaptive_mj.errors import Interrupted
    from adaptive_mj.setup.scenario import SCENARIOS_DIR
    from adaptive_mj.study.parallel import RunSpec, run_jobs, stopping_with

    def stop_after_the_first(result):
        raise Interrupted(signal.SIGTERM)

    jobs = [RunSpec(SCENARIOS_DIR / "lecture_first_order.toml", overrides=("simulation.duration=0.5",), seed=k,
                log=tmp_path / f"{k}.mcap") for k in range(4)]
    with pytest.raises(Interrupted) as info:
        run_jobs(jobs, n_jobs=2, on_done=stop_after_the_first)
    assert info.value.note.startswith("1 of 4 runs had finished") or info.value.note.startswith("2 of 4 runs")
    assert not [p for p in mp.active_children() if p.is_alive()]  # the pool's workers are gone already

    def plain():  # a generator that writes no note: the block writes it from the caller's count
        yield 0, "a"
        yield 1, "b"

    gen = plain()
    with pytest.raises(Interrupted) as info, stopping_with(gen, 2, lambda: 1):
        for _ in gen:
            raise Interrupted(signal.SIGINT)
    assert info.value.note == "1 of 2 runs had finished; the run(s) in progress closed their logs as 'interrupted'"


# A cold bench: its parent loads only what numba's cache holds (parallel._prewarm, compile_note.loading_only), and
# the first run of each scenario file compiles its controller in a worker while the other worker compiles another
# file's (parallel._Held). Here each worker is a minute deep in one compiled call (as in a long LLVM pass) at the
# start of that compile; the parent's own pass does not spin.
_COMPILING_SIDE_BY_SIDE = _SPIN + textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from adaptive_mj.sim import loop
    from adaptive_mj.cli import main

    markers, spin_s, parent = Path(sys.argv[1]), float(sys.argv[2]), os.getpid()
    in_the_call = spinner(spin_s)
    native_controller = loop._native_controller

    def spinning(*args, **kwargs):
        if os.getpid() != parent:
            (markers / str(os.getpid())).touch()
            in_the_call()
        return native_controller(*args, **kwargs)

    loop._native_controller = spinning
    sys.exit(main(sys.argv[3:]))
""")


def test_sigterm_while_a_cold_bench_s_workers_compile_side_by_side_ends_it_within_seconds(tmp_path):
    """Two scenario files (bench --quick's nth_order section), an empty numba cache: each worker compiles one file's
    controller (their other runs held back), each deep in a native call when the parent gets SIGTERM. The parent
    gives them parallel.STOP_GRACE s, kills them and exits 143 within seconds, with no process left and every log
    either closed as 'interrupted' or named as unfinished."""
    from adaptive_mj.study.parallel import STOP_GRACE

    markers = tmp_path / "markers"
    markers.mkdir()
    env = dict(os.environ, MUJOCO_GL="egl", NUMBA_CACHE_DIR=str(tmp_path / "numba_cache"))
    proc = subprocess.Popen([sys.executable, "-c", _COMPILING_SIDE_BY_SIDE, str(markers), "120", "bench", "--quick",
                             "--only", "nth_order", "--jobs", "2", "-o", str(tmp_path / "bench")],
                            cwd=REPO, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    compiling, out, err, took = sigterm_when_marked(proc, markers, what="both workers to be in the call",
                                                    timeout=100)
    assert proc.returncode == 143, err
    assert "Traceback" not in err, err
    assert took < STOP_GRACE + 15.0, f"{took:.1f} s from SIGTERM to exit"
    assert_gone(compiling)
    last = err.strip().splitlines()[-1]
    assert last.startswith("adaptive-mj: interrupted by SIGTERM; 0 of "), last
    for path in (tmp_path / "bench").rglob("*.mcap"):
        if str(path) in last:  # a worker killed after the grace period: named, and read as truncated
            assert read_log(path).status == "truncated"
        else:
            assert closed_status(path)["status"] == "interrupted"

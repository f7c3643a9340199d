"""Run many scenarios in parallel worker processes (bench and sweep).

A RunSpec (adaptive_mj.study.job, shared with the Ray backend) names a scenario
file plus overrides and a seed; each worker loads,
validates, runs and logs it, and sends back a small RunOutcome: the summary,
extra metrics computed on the full-rate trajectory, and the trajectory
decimated to the logging rate (for figures). One run that diverges or fails
is reported as such; the others go on.

SIGINT and SIGTERM. Workers ignore SIGINT (a Ctrl-C reaches the whole process
group; stopping is the parent's job). On KeyboardInterrupt (the CLI turns
SIGTERM into one too) the parent sends each worker SIGTERM: a worker in a run
raises errors.Interrupted there, so the run's log is closed with status
"interrupted", and starts no further job. The parent gives them STOP_GRACE s to
exit, kills any still running (one deep in a native call, such as an LLVM pass of
numba's compiler, runs no Python handler until the call returns) and re-raises;
the message names any log a killed worker left unfinished. Workers are started
(forked, after the parent loaded the native callbacks it found in numba's cache;
spawned where fork is missing; a callback not in the cache is compiled by the
first run that needs it, in a worker, while the others run other scenarios)
with both signals blocked until their handlers are in place, so no signal
can kill one half set up. A worker whose parent died (SIGKILL, a crash) sees it
within PARENT_POLL_S (a thread of its own): it closes the log of its run as
"interrupted" and exits, and exits at once between runs.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections import deque
from pathlib import Path
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import wait as wait_ready
from contextlib import contextmanager
from typing import Callable, Generator, Iterator, Sequence, cast

from adaptive_mj.sim import interrupt
from adaptive_mj.errors import Interrupted
# RunSpec, RunOutcome and Backend are imported from here by the study's commands, tests and benchmarks
from adaptive_mj.study.job import (Backend, RunSpec, RunOutcome, as_expected, interrupted_note, run_in_worker, run_job,
                                   run_jobs_batched)
from adaptive_mj.trajectory import Status

_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def _quiet(message: str) -> None:
    """MuJoCo's warning handler in a study's worker: nothing printed (a run MuJoCo finds unstable ends diverged,
    its reason naming MuJoCo's warning: plants.mujoco_plant.new_warnings)."""


#: [s] how long a worker told to stop (SIGTERM) has to close its run's log and exit before it is killed
STOP_GRACE = 5.0

#: [s] how often a worker looks whether its parent is still there
PARENT_POLL_S = 0.2

# the process that started this worker (set in each worker by _init_worker; empty in the parent)
_parent_pid: list[int] = []


def _orphaned() -> bool:
    """Whether this worker's parent has died (the worker now belongs to init or a subreaper)."""
    return bool(_parent_pid) and os.getppid() != _parent_pid[0]


def _exit_if_orphaned(signum: int) -> None:
    """A stop signal between runs (interrupt.install's `unarmed`): a worker whose parent is gone ends at once (no
    one will send it another job or read its results); with its parent alive it only takes note (run_in_worker
    starts no further run)."""
    if _orphaned():
        os._exit(128 + signum)


def _watch_parent() -> None:
    """A worker's daemon thread: once the parent is gone (killed, crashed), SIGTERM to this worker's main thread,
    so that a run in progress closes its log as "interrupted" and the worker exits (_run_in_pool_worker; between
    runs, _exit_if_orphaned); if it is still here STOP_GRACE s later, it ends."""
    while not _orphaned():
        time.sleep(PARENT_POLL_S)
    signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGTERM)  # (the main thread has an ident)
    time.sleep(STOP_GRACE)
    os._exit(128 + signal.SIGTERM)


def _init_worker(parent_pid: int | None = None) -> None:
    import warnings

    import mujoco

    os.environ.setdefault("MUJOCO_GL", "egl")
    # a study's diverging runs are results, each with its status and reason in the table and its log: numpy's
    # overflow warnings and MuJoCo's "simulation is unstable" lines on the terminal would only bury the progress
    warnings.simplefilter("ignore", RuntimeWarning)
    mujoco.set_mju_user_warning(_quiet)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # raised only inside a run (interrupt.armed); between runs, an orphan exits
    interrupt.install([signal.SIGTERM], unarmed=_exit_if_orphaned)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)  # blocked by the parent for the spawn
    if parent_pid is not None:
        _parent_pid[:] = [parent_pid]
        threading.Thread(target=_watch_parent, name="adaptive-mj parent watch", daemon=True).start()


def _run_in_pool_worker(job: RunSpec) -> RunOutcome:
    """run_in_worker in a pool's worker; one whose parent died meanwhile exits after the run (its log closed)."""
    result = run_in_worker(job)
    if _orphaned():
        os._exit(128 + signal.SIGTERM)
    return result


@contextmanager
def _stop_signals_blocked():
    """SIGINT and SIGTERM held back in this thread (and in processes spawned meanwhile)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)  # a signal that came meanwhile is raised now


def _stop_workers(pool: cf.ProcessPoolExecutor, *, grace: float = STOP_GRACE) -> int:
    """SIGTERM every worker (its run closes its log as "interrupted"), cancel what has not started, give them
    `grace` s to exit, and kill those still running (a native call, such as a compile, lets no handler run until it
    returns). Returns how many were killed."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    results = getattr(pool, "_result_queue", None)  # (shutdown forgets it)
    for p in procs:
        if p.is_alive():
            p.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace
    killed = 0
    for p in procs:
        # exited once its end of the sentinel pipe is closed (is_alive may still be True then: not yet reaped)
        if not wait_ready([p.sentinel], max(0.0, deadline - time.monotonic())):
            p.kill()
            killed += 1
        p.join()
    if killed and results is not None:
        # A worker killed while it sent a result left half a message in the pipe, and the pool's manager thread
        # waits for the rest; this process holds the pipe's last write end (the workers are gone): closed, the
        # thread reads end-of-file, marks the pool broken and ends, instead of hanging this process at exit
        # (concurrent.futures joins it; seen in CI as a bench that printed its stop line and never exited).
        results._writer.close()
    return killed


def _unfinished_logs(jobs: Sequence[RunSpec]) -> list[Path]:
    """The logs of `jobs` that exist but were not closed (no MCAP footer: a worker killed in its run wrote them)."""
    from adaptive_mj.log.replay import MCAP_MAGIC  # the last bytes of a closed MCAP file

    out = []
    for path in (job.log for job in jobs if job.log is not None):
        try:
            with open(path, "rb") as f:
                f.seek(-len(MCAP_MAGIC), os.SEEK_END)
                closed = f.read() == MCAP_MAGIC
        except (OSError, ValueError):  # no log yet, or shorter than the magic
            continue
        if not closed:
            out.append(path)
    return out


def _killed_note(killed: int, unfinished: list[Path]) -> str:
    """What the stop left behind when workers had to be killed (empty when none was)."""
    if not killed:
        return ""
    text = f"; {killed} worker(s) had not stopped {STOP_GRACE:g} s after SIGTERM and were killed"
    if unfinished:
        text += (f", leaving {len(unfinished)} log(s) unfinished (`adaptive-mj replay` reads them as 'truncated' and "
                 f"recovers their rows): " + ", ".join(map(str, unfinished)))
    return text


@contextmanager
def session(backend: Backend):
    """The backend ready for several batches of runs (Ray: connected once); nothing for local processes."""
    if backend.kind == "ray":
        from adaptive_mj.study import ray_backend

        with ray_backend.session(backend):
            yield
    else:
        yield


def iter_results(jobs: Sequence[RunSpec], backend: Backend | None = None, *,
                 on_retry: Callable[[RunSpec, str], None] | None = None
                 ) -> Generator[tuple[int, RunOutcome], None, None]:
    """(index into `jobs`, result) for each job as it finishes, exactly once per job.

    on_retry(job, why) is called when the Ray backend submits a run again (its worker died)."""
    backend = backend or Backend()
    if backend.kind == "ray":
        from adaptive_mj.study import ray_backend

        yield from ray_backend.iter_results(jobs, backend, on_retry=on_retry)
    elif backend.engine == "batch":
        yield from _iter_batched(jobs, backend.jobs)
    elif backend.jobs <= 1:
        for i, job in enumerate(jobs):
            try:
                result = run_job(job)
            except KeyboardInterrupt as exc:
                if isinstance(exc, Interrupted):
                    exc.note = interrupted_note(i, len(jobs))
                raise
            yield i, result
    else:
        yield from _iter_local_pool(jobs, backend.jobs, retries=backend.retries, on_retry=on_retry)


#: Runs per mujoco.batch.Batch under --engine batch: the driver holds this many runs' buffers at once.
BATCH_RUNS = 256


def _iter_batched(jobs: Sequence[RunSpec], nthread: int) -> Iterator[tuple[int, RunOutcome]]:
    """--engine batch: the jobs in groups of BATCH_RUNS, each group's physics in one Batch of nthread threads
    in this process (job.run_jobs_batched)."""
    for g in range(0, len(jobs), BATCH_RUNS):
        group = jobs[g:g + BATCH_RUNS]
        try:
            results = run_jobs_batched(group, nthread=nthread)
        except KeyboardInterrupt as exc:
            if isinstance(exc, Interrupted):
                exc.note = interrupted_note(g + getattr(exc, "finished", 0), len(jobs))
            raise
        yield from ((g + k, r) for k, r in enumerate(results))


@contextmanager
def stopping_with(results: Generator[tuple[int, RunOutcome], None, None], total: int, finished: Callable[[], int]):
    """A loop over iter_results' `results` in this block. A stop signal that comes in the loop's own body, between
    two results (interrupt's second delivery lands anywhere), is thrown into the generator at its yield: its workers
    are stopped and its note written there, before the signal goes on (else the note says `finished()` of
    `total`). The generator is closed when the block ends, whatever ended it."""
    try:
        yield
    except Interrupted as exc:
        try:
            results.throw(exc)
        except (Interrupted, StopIteration):
            pass
        if not exc.note:
            exc.note = interrupted_note(finished(), total)
        raise
    finally:
        results.close()


def run_jobs(jobs: Sequence[RunSpec], *, n_jobs: int = 1, on_done: Callable[[RunOutcome], None] | None = None,
             backend: Backend | None = None) -> list[RunOutcome]:
    """Run jobs (on `backend`, default local processes, n_jobs of them); results in the order of `jobs`."""
    backend = backend or Backend(jobs=n_jobs)
    results: list[RunOutcome | None] = [None] * len(jobs)
    gen = iter_results(jobs, backend, on_retry=getattr(on_done, "retried", None))
    with stopping_with(gen, len(jobs), lambda: sum(r is not None for r in results)):
        for i, result in gen:
            results[i] = result
            if on_done:
                on_done(result)
    return cast("list[RunOutcome]", results)  # every slot filled: iter_results yields each job once


#: Runs submitted ahead per worker process: keeps the workers busy while bounding what the
#: parent holds (futures, pickled jobs) however long the study.
WINDOW_PER_WORKER = 4


def _iter_local_pool(jobs: Sequence[RunSpec], n_jobs: int, *, retries: int = 3,
                     on_retry: Callable[[RunSpec, str], None] | None = None) -> Iterator[tuple[int, RunOutcome]]:
    """Results from n_jobs forked workers as they finish.

    A worker that dies (SIGKILL, out of memory) breaks the pool. Runs that had not started go back
    to the queue as they were; runs that had started (their log exists) lose their half-written log
    and are run again, one at a time in a pool of one worker, so that a further death is blamed on
    its own run alone. Each started run is charged an attempt per death it was in; after `retries`
    more attempts it is recorded as an error."""
    ctx, pending = _worker_context(jobs, n_jobs)
    finished = 0
    attempts = [0] * len(jobs)
    queue = deque(range(len(jobs)))
    held = _Held(queue, jobs, pending)  # the queue, with runs that wait for a compile held back
    suspects: deque[int] = deque()  # in flight when a worker died: run alone next

    while held or suspects:
        alone = bool(suspects)
        width = 1 if alone else n_jobs
        lost: list[int] = []
        with cf.ProcessPoolExecutor(max_workers=width, mp_context=ctx, initializer=_init_worker,
                                    initargs=(os.getpid(),)) as pool:
            futures: dict[cf.Future, int] = {}
            try:
                while (suspects if alone else held) or futures:
                    if alone:
                        _fill(pool, futures, jobs, lambda: suspects.popleft() if suspects else None,
                              suspects.appendleft, 1)
                    else:
                        _fill(pool, futures, jobs, held.next, held.put_back, WINDOW_PER_WORKER * n_jobs)
                        _fill(pool, futures, jobs, held.spare, held.put_back, n_jobs)  # no worker idles
                    if not futures:
                        if not alone and held.compiler:  # nothing in flight compiles: no run may wait for it
                            held.release()
                            continue
                        break
                    done, _ = cf.wait(futures, return_when=cf.FIRST_COMPLETED)
                    for fut in done:
                        i = futures.pop(fut)  # the future (and its result) is not kept once handed on
                        if isinstance(fut.exception(), BrokenProcessPool):
                            lost.append(i)
                            continue
                        result = _take(fut, jobs[i])
                        held.finished(i)
                        finished += 1
                        yield i, result
                    if lost:  # the pool is broken: what it still holds is lost too, unless it finished
                        for fut, i in futures.items():
                            if fut.done() and fut.exception() is None:
                                result = _take(fut, jobs[i])
                                held.finished(i)
                                finished += 1
                                yield i, result
                            else:
                                lost.append(i)
                        futures.clear()
                        held.release()
                        break
            except (KeyboardInterrupt, GeneratorExit) as exc:  # a signal, or the caller stopped reading
                in_flight = [jobs[i] for fut, i in futures.items() if not fut.done()]
                killed = _stop_workers(pool)
                if isinstance(exc, Interrupted):
                    if finished:
                        sys.stderr.write("\n")  # end the progress line
                    exc.note = interrupted_note(finished, len(jobs)) + _killed_note(killed,
                                                                                     _unfinished_logs(in_flight))
                raise
        for i, result in _put_back_lost(lost, jobs, attempts, retries, queue, suspects, on_retry):
            finished += 1
            yield i, result


def _fill(pool: cf.ProcessPoolExecutor, futures: dict[cf.Future, int], jobs: Sequence[RunSpec],
          take: Callable[[], int | None], put_back: Callable[[int], None], limit: int) -> None:
    """Submit the runs take() gives (indices into `jobs`) until `limit` are in flight or it gives None; one that
    cannot be submitted (a worker died since the last wait: the pool is broken) is put back."""
    with _stop_signals_blocked():  # the first submits spawn the workers
        while len(futures) < limit:
            i = take()
            if i is None:
                return
            try:
                futures[pool.submit(_run_in_pool_worker, jobs[i])] = i
            except BrokenProcessPool:
                put_back(i)
                return


def _take(fut: cf.Future, job: RunSpec) -> RunOutcome:
    """The result of a finished future (an error result if the job could not be sent or returned)."""
    try:
        result = fut.result()
    except Exception as exc:  # noqa: BLE001 (the job could not be sent or returned)
        result = RunOutcome(job, "error", None, error=f"{type(exc).__name__}: {exc}")
    if result.status == Status.INTERRUPTED:  # a worker was told to stop: stop them all
        raise Interrupted(signal.SIGTERM)
    return result


def _put_back_lost(lost: list[int], jobs: Sequence[RunSpec], attempts: list[int], retries: int, queue: deque[int],
                   suspects: deque[int],
                   on_retry: Callable[[RunSpec, str], None] | None) -> Iterator[tuple[int, RunOutcome]]:
    """The runs a broken pool lost (indices into `jobs`): one that had not started goes back to
    `queue` when a started one is there to blame; a started one is charged an attempt and goes to
    `suspects` (run alone next), or, its retries spent, is yielded as an error."""
    started = {i for i in lost if (log := jobs[i].log) is None or log.exists()}
    for i in sorted(lost, reverse=True):
        job = jobs[i]
        if started and i not in started:
            queue.appendleft(i)  # never started, and a started run is there to blame: not its fault
            continue
        if attempts[i] < retries:
            attempts[i] += 1
            if job.log is not None:
                job.log.unlink(missing_ok=True)  # cut short when its worker died
            if on_retry:
                on_retry(job, f"attempt {attempts[i] + 1} of {retries + 1} (a worker process died)")
            suspects.appendleft(i)
        else:
            yield i, RunOutcome(job, "error", None, error=f"a worker process died running it (tried "
                                                        f"{attempts[i] + 1} times)")


def _worker_context(jobs: Sequence[RunSpec], n_jobs: int = 1):
    """(the context to start workers with, _prewarm's function giving a job's controller still to compile (None:
    unknown, every job may go at once)). Workers are forked from a parent that has loaded the jobs' native
    callbacks (_prewarm), so that no worker loads or compiles them again; spawned where fork is missing. Forking is
    safe here: no control callback is installed between runs, and the compiled callback's buffers are module
    globals at the same addresses in the child."""
    if "fork" not in mp.get_all_start_methods():
        return mp.get_context("spawn"), None
    return mp.get_context("fork"), _prewarm(jobs, n_jobs)


def _compile_native(job: RunSpec) -> None:
    """Compile (or load from numba's disk cache) the native controller of `job`'s scenario in this process: the
    1-DOF, arm and quadrotor callbacks and the analytic plants' compiled loops (loop.compile_native). Only a head
    start: a job that cannot be set up or compiled is left to its worker, which reports what is wrong."""
    import contextlib

    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build
    from adaptive_mj.sim.compile_note import CompileLines
    from adaptive_mj.sim.loop import compile_native

    try:
        setup = build(sc.load(job.scenario, overrides=list(job.overrides), seed=job.seed))
        # a compile is said (sim.compile_note); the rest, a plugin's "could not be compiled" too, the worker says
        with contextlib.redirect_stderr(CompileLines(sys.stderr)):
            compile_native(setup.plant, setup.law, setup.reference, setup.theta_hat0)
    except Exception as exc:  # noqa: BLE001 (only a head start: the worker runs the job and reports what is wrong)
        interrupt.reraise_stop(exc)  # a stop signal that came while numba compiled, wrapped by Python


#: the overrides that may change which compiled controller a run takes (its law, plant model, control mode): runs
#: of one scenario file that differ in no other override are probed once for it (_prewarm); a hint for scheduling
#: only (two runs that share a controller wait for one compile under compile_note's lock whatever it says)
VARIANT_KEYS = ("law", "law.kind", "law.projection", "plant.kind", "plant.model", "control.mode")


def _hint(job: RunSpec) -> tuple:
    """(scenario file, the overrides among VARIANT_KEYS): runs with the same hint take the same controller."""
    return job.scenario, tuple(o for o in job.overrides if o.split("=", 1)[0].strip() in VARIANT_KEYS)


def _prewarm(jobs: Sequence[RunSpec], n_jobs: int = 1) -> Callable[[RunSpec], object] | None:
    """Load, in this process, the native controllers the jobs take (the workers forked from it inherit them), one
    job per _hint; a function giving a job's controller that is still to compile (None: loaded here).

    With one worker it compiles what is not in numba's disk cache too (nothing is then left to compile). With
    n_jobs > 1 it only loads (compile_note.loading_only): a controller that would have to compile is left to the
    first run that takes it, in a worker, while the other workers run runs whose controllers are loaded or compile
    others (_iter_local_pool holds back the runs that need it until then). Compiling here first would take one core
    while the others waited."""
    from adaptive_mj.sim import compile_note

    pending: dict[tuple, object] = {}
    seen: set[tuple] = set()
    for job in jobs:
        hint = _hint(job)
        if hint in seen:
            continue
        seen.add(hint)
        if n_jobs <= 1:
            _compile_native(job)
            continue
        try:
            with compile_note.loading_only():
                _compile_native(job)
        except compile_note.NotInCache as exc:
            pending[hint] = exc.variant
    return lambda job: pending.get(_hint(job))


class _Held:
    """The run queue of a pool whose workers compile: a run whose controller is still to compile (`pending(job)`,
    from _prewarm; None: loaded) waits while the first run that takes it (which compiles it) is in flight, so that
    no two workers compile one controller and none waits for another's compile while other runs are left.
    pending None: every run goes in order (nothing known)."""

    def __init__(self, order: deque[int], jobs: Sequence[RunSpec], pending: Callable[[RunSpec], object] | None):
        self.order, self.jobs = order, jobs
        self.pending = pending or (lambda job: None)
        self.done: set = set()  # controllers compiled since
        self.compiler: dict = {}  # controller -> its run in flight that compiles it
        self.waiting: dict = {}  # controller -> the other runs that take it, in order

    def __bool__(self) -> bool:
        return bool(self.order) or any(self.waiting.values())

    def _key(self, i: int):
        key = self.pending(self.jobs[i])
        return None if key in self.done else key

    def next(self) -> int | None:
        """The next run to submit, or None while every run left waits for a compile in flight."""
        while self.order:
            i = self.order.popleft()
            key = self._key(i)
            if key is None:
                return i
            if key in self.compiler:
                self.waiting.setdefault(key, []).append(i)
                continue
            self.compiler[key] = i
            return i
        return None

    def spare(self) -> int | None:
        """A waiting run for a worker that would otherwise idle (nothing else is left): the first waiting run of
        the controller whose compile started first. It waits in its worker for that compile (compile_note's lock)
        and then loads it, rather than waiting here for the compiling run's whole run to end."""
        for key in self.compiler:
            if self.waiting.get(key):
                return self.waiting[key].pop(0)
        return None

    def _free(self, key) -> None:
        del self.compiler[key]
        self.order.extendleft(reversed(self.waiting.pop(key, [])))

    def put_back(self, i: int) -> None:
        """A run that was taken but not submitted (the pool broke): first again, before the runs that waited for
        it."""
        key = self._key(i)
        if key is not None and self.compiler.get(key) == i:
            self._free(key)
        self.order.appendleft(i)

    def finished(self, i: int) -> None:
        """Run i came back (whatever its status): its controller is in numba's cache now (or cannot compile, which
        every run says), and the runs that waited for it go first, in order."""
        key = self._key(i)
        if key is not None and key in self.compiler:  # its compiling run, or a spare one that waited for it
            self.done.add(key)
            self._free(key)

    def release(self) -> None:
        """The pool broke: its compiling runs are lost (and put back by the caller); the runs that waited for them
        go back to the queue, and the next run of each compiles it."""
        for key in list(self.compiler):
            self._free(key)


PLAIN_PROGRESS_EVERY = 5.0  # s between progress lines when stderr is not a terminal


class Progress:
    """Progress on stderr: runs done (and how many of them failed: any status but ok), runs
    retried, and the rate. On a terminal a tqdm bar redrawn in place as runs finish (the counts and
    the last run in its postfix); otherwise (a file, a pipe, CI) a plain line at most every
    PLAIN_PROGRESS_EVERY seconds and one at the end, so redirected output holds no carriage returns.
    Call it with each RunOutcome; `retried(job, why)` counts a run submitted again (the Ray backend,
    when a worker died)."""

    def __init__(self, total: int, *, label: str = "runs", stream=None, clock: Callable[[], float] | None = None):
        self.total, self.label = total, label
        self.stream = stream or sys.stderr
        self.clock = clock or time.monotonic
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.n = self.failed = self.n_retried = self.unexpected = 0
        self.declared = False  # some run declared it is meant to fail or is a measurement (the bench's catalogue)
        self.t0 = self.last = self.clock()
        self._bar = None
        if self.tty:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=label, unit="run", file=self.stream, dynamic_ncols=True, leave=True)

    def _counts(self, now: float) -> str:
        rate = 60.0 * self.n / (now - self.t0) if now > self.t0 else 0.0
        return f"{self.n}/{self.total} {self.label} done{self._extra()}, {rate:.1f}/min"

    def _extra(self) -> str:
        """", failed N, retried M"; where runs declare what they are for (RunSpec.expect: the bench), the runs not
        ok are not all failures: ", not ok N (U unexpected)"."""
        if self.declared:
            counts = (("not ok", f"{self.failed} ({self.unexpected} unexpected)" if self.failed else 0),
                      ("retried", self.n_retried))
        else:
            counts = (("failed", self.failed), ("retried", self.n_retried))
        return "".join(f", {k} {v}" for k, v in counts if v)

    def __call__(self, result: RunOutcome) -> None:
        self.n += 1
        self.failed += result.status != Status.OK
        self.declared = self.declared or result.job.expect != "ok"
        self.unexpected += as_expected(result) is False
        now = self.clock()
        last = f"last: {result.job.tag or result.job.scenario.stem} ({result.status})"
        if self._bar is not None:
            extra = self._extra().lstrip(", ")  # "failed 1, retried 2" or ""
            self._bar.set_postfix_str(f"{extra}; {last}" if extra else last, refresh=False)
            self._bar.update(1)
            if self.n >= self.total:
                self._bar.close()
            return
        if self.n == self.total or now - self.last >= PLAIN_PROGRESS_EVERY:
            self.last = now
            self.stream.write(f"{self._counts(now)} after {now - self.t0:.0f} s; {last}\n")
            self.stream.flush()

    def retried(self, job: RunSpec, why: str) -> None:
        self.n_retried += 1
        line = f"retrying {job.tag or job.scenario.stem}: {why}"
        if self._bar is not None:
            self._bar.write(line, file=self.stream)  # above the bar, which is redrawn below it
            return
        self.stream.write(line + "\n")
        self.stream.flush()


def progress_printer(total: int, *, label: str = "runs", stream=None,
                     clock: Callable[[], float] | None = None) -> Progress:
    """A Progress for `total` runs (see Progress)."""
    return Progress(total, label=label, stream=stream, clock=clock)

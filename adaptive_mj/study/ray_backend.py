"""The Ray backend of bench and sweep: each RunSpec is one Ray task (`--backend ray`), or with
`--engine batch` each task carries up to RUNS_PER_TASK jobs stepped in one mujoco.batch.Batch.

    driver ── submit (at most WINDOW_PER_CPU × cluster CPUs in flight) ──► task: run_job on a node
           ◄── (RunOutcome, log bytes | None) ──  as each finishes: the log written, the result yielded

Ray is an optional extra (``pip install -e '.[ray]'``). With no address Ray starts on this
machine with `jobs` CPUs (and is shut down afterwards); ``--address auto`` or
``ray://host:port`` joins a running cluster. Every node must have adaptive-mj (the same
version) installed and see the scenario files (and the models they name) at the same paths.

Logs (`Backend.logs`):
- "bytes": the task writes its MCAP log in its node's temporary folder and returns the bytes;
  the driver writes them to the job's path (to NAME.partial first, renamed when complete).
- "shared": the task writes the job's path itself (NAME.partial, renamed when closed), so the
  output folder must be on storage every node sees; nothing but the summary travels back.
Either way the log's messages are the same bytes as the local backend's (tests/test_ray.py).

Faults. A task whose worker process or node dies (any Ray error but an exception raised by the
run itself) is submitted again, at most `Backend.retries` times (default 3), after removing what
its last attempt left; then the run is recorded as an error naming the cause. A run that raises,
diverges or fails is a result and is never retried. The driver takes one result per job, so no
run appears twice.

Interruption (SIGINT or SIGTERM in the driver). Every task not finished is cancelled: Ray raises
SIGINT in a running task, where adaptive_mj.sim.interrupt turns it into a clean stop, so its log is
closed as "interrupted" (and, with "bytes", still comes back and is written); queued tasks never
start. The driver waits up to job.STOP_TIMEOUT s for them, force-cancels what remains (its
log then stays NAME.partial), shuts down a Ray it started, and re-raises.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import signal
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Callable, Iterator, Sequence

from adaptive_mj.errors import AdaptiveMJError, Interrupted
from adaptive_mj.study.job import (STOP_TIMEOUT, Backend, RunOutcome, RunSpec, interrupted_note, log_write_error,
                                   ray_module, run_in_worker, run_jobs_batched)
from adaptive_mj.trajectory import Status

#: Tasks in flight per CPU of the cluster: enough to keep every worker busy while results come
#: back, few enough that the driver holds a bounded number of results and arguments.
WINDOW_PER_CPU = 2
PARTIAL = ".partial"


def partial_path(log: Path) -> Path:
    """Where a log is written until it is complete (then renamed to `log`)."""
    return log.with_name(log.name + PARTIAL)


# --------------------------------------------------------------------------
# the task (runs on a cluster node)
def _scratch(job: RunSpec) -> Path:
    """The task's temporary folder on its node: one per job, so a retry on the same node removes
    what a killed attempt left."""
    digest = hashlib.sha256(repr(job).encode()).hexdigest()[:16]
    return Path(tempfile.gettempdir()) / "adaptive-mj-ray" / digest


def _task_log(job: RunSpec, logs: str) -> tuple[Path | None, RunOutcome | None]:
    """Where a task writes job's log (its node's scratch folder with "bytes", NAME.partial with "shared"),
    or the error result that stops it first (its scenario missing on this node, its log already there)."""
    if not job.scenario.is_file():
        import socket

        why = (f"{job.scenario}: no such file on the Ray node {socket.gethostname()} (every node must see the "
               "scenarios and models at the same paths)")
        return None, RunOutcome(job, Status.ERROR, None, error=why)
    if job.log is None:
        return None, None
    if logs == "bytes":
        scratch = _scratch(job)
        shutil.rmtree(scratch, ignore_errors=True)
        scratch.mkdir(parents=True)
        return scratch / job.log.name, None
    if job.log.exists():
        return None, RunOutcome(job, Status.ERROR, None, error=f"{job.log}: file exists")
    where = partial_path(job.log)
    where.unlink(missing_ok=True)  # left by an attempt whose worker died
    return where, None


def _task_collect(job: RunSpec, logs: str, where: Path | None, result: RunOutcome) -> tuple[RunOutcome, bytes | None]:
    """A task's result with the caller's job and log path, and the log's bytes with logs="bytes" (the
    scratch folder removed); with "shared" the log renamed from NAME.partial."""
    data = None
    if where is not None and where.is_file():
        if logs == "bytes":
            data = where.read_bytes()
        else:
            assert job.log is not None  # _task_log gives a place only to a job with a log
            os.replace(where, job.log)
    error = result.error.replace(str(where), str(job.log)) if where is not None else result.error
    return replace(result, job=job, error=error), data


def _task_cleanup(job: RunSpec, logs: str, where: Path | None) -> None:
    if where is not None and logs == "bytes":
        shutil.rmtree(where.parent, ignore_errors=True)


def run_task(job: RunSpec, logs: str) -> tuple[RunOutcome, bytes | None]:
    """One job on a Ray worker: (its result with the caller's job, the log's bytes with logs="bytes").

    SIGINT (ray.cancel) and SIGTERM stop the run cleanly: the log is closed as "interrupted"."""
    from adaptive_mj.sim import interrupt

    os.environ.setdefault("MUJOCO_GL", "egl")
    where, refused = _task_log(job, logs)
    if refused is not None:
        return refused, None
    try:
        with interrupt.stop_on_signals((signal.SIGINT, signal.SIGTERM)):
            result = run_in_worker(replace(job, log=where))
        return _task_collect(job, logs, where, result)
    finally:
        _task_cleanup(job, logs, where)


def run_task_batch(jobs: Sequence[RunSpec], logs: str) -> list[tuple[RunOutcome, bytes | None]]:
    """Several jobs on one Ray worker (`--engine batch`): their physics stepped together in one
    mujoco.batch.Batch of one thread (job.run_jobs_batched), each with run_task's result and log. A stop
    signal closes every log of the batch as "interrupted" (a run that had ended keeps its verdict) and
    every result not yet made is "interrupted"."""
    from adaptive_mj.sim import interrupt

    os.environ.setdefault("MUJOCO_GL", "egl")
    out: list[tuple[RunOutcome, bytes | None] | None] = [None] * len(jobs)
    places: dict[int, Path | None] = {}
    for k, job in enumerate(jobs):
        where, refused = _task_log(job, logs)
        if refused is not None:
            out[k] = (refused, None)
        else:
            places[k] = where
    ks = list(places)
    try:
        try:
            signum = interrupt.requested()
            if signum is not None:  # stopped before it started: no run begins (run_in_worker's rule)
                raise Interrupted(signum)
            with interrupt.stop_on_signals((signal.SIGINT, signal.SIGTERM)):
                results = run_jobs_batched([replace(jobs[k], log=places[k]) for k in ks], nthread=1)
        except KeyboardInterrupt as exc:
            why = str(exc) or "interrupted"
            results = [RunOutcome(jobs[k], Status.INTERRUPTED, None, error=why) for k in ks]
        for k, result in zip(ks, results, strict=True):
            out[k] = _task_collect(jobs[k], logs, places[k], result)
    finally:
        for k in ks:
            _task_cleanup(jobs[k], logs, places[k])
    return [o for o in out if o is not None]


# --------------------------------------------------------------------------
# the driver
def _check_reachable(address: str) -> None:
    """host:port or ray://host:port answers a TCP connection within 5 s (Ray itself would wait
    without end for an address where nothing listens)."""
    import socket

    hostport = address.removeprefix("ray://")
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise AdaptiveMJError(f"--address {address!r}: expected auto, HOST:PORT (the cluster's GCS, as `ray start "
                              "--head` prints it) or ray://HOST:PORT (Ray Client)")
    try:
        socket.create_connection((host, int(port)), timeout=5.0).close()
    except OSError as exc:
        raise AdaptiveMJError(f"--address {address!r}: nothing answers at {host}:{port} ({exc.strerror or exc}); "
                              "start the cluster (ray start --head) or check the address") from None


def _connect(ray, backend: Backend) -> bool:
    """Connect to (or start) Ray; True when this call started it (and so must shut it down).

    With no address a new local Ray is always started (address="local"), never a cluster that happens
    to run on this machine. Ray's driver installs its own SIGINT/SIGTERM handlers; the ones in place
    before (the CLI's clean stop, adaptive_mj.sim.interrupt) are put back."""
    import threading

    if ray.is_initialized():
        return False
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if not getattr(sys.stderr, "isatty", lambda: False)():
        os.environ.setdefault("RAY_COLOR_PREFIX", "0")  # workers' output forwarded without colour codes
    if backend.address not in (None, "auto"):
        _check_reachable(backend.address)
    main = threading.current_thread() is threading.main_thread()
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)} if main else {}
    kwargs = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=True, configure_logging=True)
    try:
        if backend.address is None:
            ray.init(address="local", num_cpus=backend.jobs, **kwargs)
        else:
            ray.init(address=backend.address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = "a local Ray" if backend.address is None else f"the Ray cluster at {backend.address!r}"
        hint = (" (Ray Client needs the ray[client] extra: pip install -e '.[ray]')"
                if "ray[client]" in str(exc) else "")
        raise AdaptiveMJError(f"--backend ray: cannot start or reach {where}: "
                              f"{str(exc).splitlines()[0]}{hint}") from None
    finally:
        for sig, handler in handlers.items():
            if handler is not None:
                signal.signal(sig, handler)
    return True


@contextmanager
def session(backend: Backend):
    """Ray connected (or started) for the whole block, so that a command running several batches
    (the bench's breaking-point study) starts it once; shut down at the end if this block started it."""
    ray = ray_module()
    started = _connect(ray, backend)
    try:
        yield
    finally:
        if started:
            ray.shutdown()


def _write_log(job: RunSpec, data: bytes) -> str:
    """The returned log bytes to job.log (through NAME.partial); "" or the error's one line."""
    log = job.log
    assert log is not None  # a task returns log bytes only for a job with a log (_task_log)
    part = partial_path(log)
    try:
        log.parent.mkdir(parents=True, exist_ok=True)
        part.write_bytes(data)
    except OSError as exc:  # disk full, a file-size limit: what was written reads as truncated
        if part.is_file():
            os.replace(part, log)
        return log_write_error(log, exc)
    os.replace(part, log)
    return ""


def _write_returned_log(job: RunSpec, result: RunOutcome, data: bytes | None) -> RunOutcome:
    """The log bytes that came back with a result (None: none) written to job.log; the result, made
    an error if its log could not be written."""
    if data is None:
        return result
    error = _write_log(job, data)
    return replace(result, status=Status.ERROR, error=error) if error else result


def _system_failure(ray, exc: BaseException) -> bool:
    """A Ray error that is not the run's own exception: the worker or node died, an object was lost."""
    return isinstance(exc, ray.exceptions.RayError) and not isinstance(exc, ray.exceptions.RayTaskError)


#: Runs per Ray task under --engine batch: one Batch per task, so per-task costs (scheduling, the
#: worker's numba start-up, the result's trip back) are shared by this many runs.
RUNS_PER_TASK = 32


def _units(n: int, backend: Backend, cpus: int) -> list[list[int]]:
    """The job indices each task carries: one per task, or with --engine batch up to RUNS_PER_TASK, fewer
    when the study is small (about two tasks per CPU of the cluster's `cpus`)."""
    if backend.engine != "batch":
        return [[i] for i in range(n)]
    size = max(1, min(RUNS_PER_TASK, -(-n // (2 * cpus))))
    return [list(range(a, min(n, a + size))) for a in range(0, n, size)]


def iter_results(jobs: Sequence[RunSpec], backend: Backend, *,
                 on_retry: Callable[[RunSpec, str], None] | None = None) -> Iterator[tuple[int, RunOutcome]]:
    """(index, result) for each job as it finishes on Ray, exactly once per job (see the module docstring).
    With backend.engine "batch" each task carries several jobs (run_task_batch)."""
    from adaptive_mj.sim import interrupt

    ray = ray_module()
    started = _connect(ray, backend)
    one = ray.remote(run_task).options(num_cpus=1, max_retries=0, name="adaptive-mj-run")
    many = ray.remote(run_task_batch).options(num_cpus=1, max_retries=0, name="adaptive-mj-run")
    cpus = max(1, int(ray.cluster_resources().get("CPU", backend.jobs)))
    window = WINDOW_PER_CPU * cpus
    units = _units(len(jobs), backend, cpus)
    pending: dict = {}  # ObjectRef -> unit index
    attempts = [0] * len(units)
    nxt = finished = 0

    def submit(u: int) -> None:
        ids = units[u]
        pending[many.remote([jobs[i] for i in ids], backend.logs) if backend.engine == "batch"
                else one.remote(jobs[ids[0]], backend.logs)] = u

    try:
        while pending or nxt < len(units):
            while nxt < len(units) and len(pending) < window:
                units[nxt], exist = _drop_existing(units[nxt], jobs)
                finished += len(exist)
                yield from exist
                if units[nxt]:
                    submit(nxt)
                nxt += 1
            if not pending:
                continue
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)  # a timeout: signals get through
            for ref in ready:
                u = pending.pop(ref)
                ids = units[u]
                pairs = _task_results(ray, ref, ids, jobs, u, attempts, backend, on_retry)
                if pairs is None:
                    submit(u)
                    continue
                if _stopped_again(pairs, jobs, u, attempts, backend, on_retry):
                    submit(u)  # stopped from outside: a node shutting down, preempted
                    continue
                for i, (res, data) in pairs:
                    finished += 1
                    yield i, _write_returned_log(jobs[i], res, data)
    except GeneratorExit:  # the caller stopped reading (its own error): stop the tasks, keep what they wrote
        _stop(ray, pending, units, jobs, backend)
        raise
    except KeyboardInterrupt as exc:
        _stop(ray, pending, units, jobs, backend)
        # Ray's wait may re-raise the CLI's Interrupted as a plain KeyboardInterrupt: the signal is on record
        stop = exc if isinstance(exc, Interrupted) else Interrupted(interrupt.requested() or signal.SIGINT)
        stop.note = interrupted_note(finished, len(jobs))
        if stop is exc:
            raise
        raise stop from exc
    finally:
        if started:
            ray.shutdown()


def _drop_existing(ids: list[int], jobs: Sequence[RunSpec]) -> tuple[list[int], list[tuple[int, RunOutcome]]]:
    """(the jobs of a task still to run, an error result for each whose log is already there)."""
    exist = [i for i in ids if (log := jobs[i].log) is not None and log.exists()]
    return ([i for i in ids if i not in exist],
            [(i, RunOutcome(jobs[i], "error", None, error=f"{jobs[i].log}: file exists")) for i in exist])


_Returned = tuple[RunOutcome, bytes | None]


def _task_results(ray, ref, ids: list[int], jobs: Sequence[RunSpec], u: int, attempts: list[int], backend: Backend,
                  on_retry: Callable[[RunSpec, str], None] | None) -> list[tuple[int, _Returned]] | None:
    """What finished task u (carrying jobs[i] for i in ids) sent back: (job index, (result, log bytes)) for
    each of its jobs; a Ray error (its worker or node died) gives None when the task has an attempt left
    (the caller submits it again), an error result for each job when not or when the run itself raised."""
    try:
        got = ray.get(ref)
        return list(zip(ids, got if backend.engine == "batch" else [got], strict=True))
    except Exception as exc:  # noqa: BLE001 (a Ray error: sorted below)
        why = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
        if _system_failure(ray, exc) and _retry(ids, jobs, u, attempts, backend, on_retry, why):
            return None
        tried = f" (tried {attempts[u] + 1} times)" if attempts[u] else ""
        return [(i, (RunOutcome(jobs[i], "error", None, error=f"the Ray task failed{tried}: {why}"
                               + _keep_leftovers(jobs[i], backend)), None)) for i in ids]


def _stopped_again(pairs: list[tuple[int, _Returned]], jobs: Sequence[RunSpec], u: int, attempts: list[int],
                   backend: Backend, on_retry: Callable[[RunSpec, str], None] | None) -> bool:
    """Task u came back with a run "interrupted": after a stop signal here (Ctrl-C reached the task too)
    its logs are written and errors.Interrupted raised; otherwise (its node stopped it) True when it has
    an attempt left, to be submitted again. False when no run of it was interrupted."""
    from adaptive_mj.sim import interrupt

    stopped = [res for _, (res, _) in pairs if res.status == Status.INTERRUPTED]
    if not stopped:
        return False
    signum = interrupt.requested()
    if signum is not None:
        for i, (res, data) in pairs:
            _write_returned_log(jobs[i], res, data)
        raise Interrupted(signum)
    return _retry([i for i, _ in pairs], jobs, u, attempts, backend, on_retry,
                  f"its node stopped it: {stopped[0].error}")


def _retry(ids: list[int], jobs: Sequence[RunSpec], u: int, attempts: list[int], backend: Backend,
           on_retry: Callable[[RunSpec, str], None] | None, why: str) -> bool:
    """Whether task u (carrying jobs[i] for i in ids) has an attempt left; if so it is charged one, what its
    last attempt left is removed and on_retry is told why for each job, for the caller to submit it again."""
    if attempts[u] >= backend.retries:
        return False
    attempts[u] += 1
    for i in ids:
        _remove_leftovers(jobs[i], backend)
        if on_retry:
            on_retry(jobs[i], f"attempt {attempts[u] + 1} of {backend.retries + 1} ({why})")
    return True


def _remove_leftovers(job: RunSpec, backend: Backend) -> None:
    """What a dead or stopped attempt may have left on shared storage: its NAME.partial, or the log it
    renamed before its result was lost (the driver checked that no log was there before the first
    attempt, so whatever is there now came from one)."""
    if job.log is not None and backend.logs == "shared":
        partial_path(job.log).unlink(missing_ok=True)
        job.log.unlink(missing_ok=True)


def _keep_leftovers(job: RunSpec, backend: Backend) -> str:
    """A run given up: what its last attempt wrote on shared storage becomes its log (it reads as
    truncated); the text to add to the error."""
    log = job.log
    if log is None or backend.logs != "shared":
        return ""
    part = partial_path(log)
    if not part.is_file():
        return ""
    if part.stat().st_size == 0:  # killed before its first write
        part.unlink()
        return "; its last attempt wrote no log"
    os.replace(part, log)
    return f"; what its last attempt wrote reads as truncated ({log})"


def _stop(ray, pending: dict, units: list[list[int]], jobs: Sequence[RunSpec], backend: Backend, *,
          timeout: float = STOP_TIMEOUT) -> None:
    """Cancel every outstanding task (a running one closes its logs as "interrupted"), write the
    logs that come back, and force-cancel what has not ended after `timeout` s."""
    for ref in pending:
        ray.cancel(ref)
    deadline = time.monotonic() + timeout
    left = dict(pending)
    while left and time.monotonic() < deadline:
        ready, _ = ray.wait(list(left), num_returns=len(left), timeout=max(0.0, deadline - time.monotonic()))
        for ref in ready:
            ids = units[left.pop(ref)]
            try:
                got = ray.get(ref)
            except Exception:  # noqa: BLE001 (cancelled before it started)
                continue
            for i, (_, data) in zip(ids, got if backend.engine == "batch" else [got], strict=True):
                if data is not None:
                    _write_log(jobs[i], data)
        if not ready:
            break
    for ref in left:
        ray.cancel(ref, force=True)
    if left:
        print(f"{len(left)} Ray task(s) did not stop within {timeout:g} s and were killed; their logs stay as "
              f"*{PARTIAL}", file=sys.stderr)

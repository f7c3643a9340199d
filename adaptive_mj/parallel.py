"""Run many scenarios in parallel worker processes (bench and sweep).

A Job names a scenario file plus overrides and a seed; each worker loads,
validates, runs and logs it, and sends back a small JobResult: the summary,
extra metrics computed on the full-rate trajectory, and the trajectory
decimated to the logging rate (for figures). One run that diverges or fails
is reported as such; the others go on.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing as mp
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from adaptive_mj.errors import AdaptiveMJError
from adaptive_mj.trajectory import Trajectory


@dataclass(frozen=True)
class Job:
    """scenario: a scenario file; overrides: --set expressions; seed: noise seed or None;
    log: the MCAP path to write (None: no log); tag: caller's label;
    extras: names of functions in adaptive_mj.analysis run on the full-rate trajectory."""

    scenario: Path
    overrides: tuple[str, ...] = ()
    seed: int | None = None
    log: Path | None = None
    tag: str = ""
    extras: tuple[str, ...] = ()


@dataclass(frozen=True)
class JobResult:
    job: Job
    status: str  # the summary status, or "error" when the run could not be set up
    summary: dict | None
    extras: dict = field(default_factory=dict)
    trajectory: Trajectory | None = None  # decimated to the scenario's logging rate
    error: str = ""


def decimate(traj: Trajectory, every: int) -> Trajectory:
    """Every `every`-th row of a trajectory (the logging rate)."""
    if every <= 1:
        return traj
    rows = slice(None, None, every)
    meta = dict(traj.meta, log_every=every)
    return replace(traj, t=traj.t[rows], x=traj.x[rows], u=traj.u[rows], s=traj.s[rows], ref=traj.ref[rows],
                   theta_hat=traj.theta_hat[rows], theta=traj.theta[rows], V=traj.V[rows], meta=meta)


def run_job(job: Job) -> JobResult:
    """Load, run and log one job (in a worker or in-process)."""
    from adaptive_mj import analysis
    from adaptive_mj import scenario as sc
    from adaptive_mj.build import build
    from adaptive_mj.runner import execute

    try:
        scn = sc.load(job.scenario, overrides=list(job.overrides), seed=job.seed)
        if job.log is not None:
            job.log.parent.mkdir(parents=True, exist_ok=True)
            if job.log.exists():
                raise AdaptiveMJError(f"{job.log}: file exists")
        result = execute(scn, log_path=job.log)
        traj = result.trajectory
        setup = None
        extras = {}
        for name in job.extras:
            if setup is None:
                setup = build(scn)  # law and form, for analyses that need them (no run)
            extras[name] = getattr(analysis, name)(traj, setup)
        every = max(1, round(1.0 / (scn.log_rate_hz * traj.meta["dt"])))
        return JobResult(job, result.summary["status"], result.summary, extras, decimate(traj, every))
    except AdaptiveMJError as exc:
        return JobResult(job, "error", None, error=str(exc))


def _init_worker() -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")


def run_jobs(jobs: Sequence[Job], *, n_jobs: int = 1,
             on_done: Callable[[JobResult], None] | None = None) -> list[JobResult]:
    """Run jobs (in n_jobs processes when > 1); results in the order of `jobs`."""
    results: list[JobResult | None] = [None] * len(jobs)
    if n_jobs <= 1:
        for i, job in enumerate(jobs):
            results[i] = run_job(job)
            if on_done:
                on_done(results[i])
        return results  # type: ignore[return-value]
    ctx = mp.get_context("spawn")  # a clean MuJoCo (and control callback) per worker
    with cf.ProcessPoolExecutor(max_workers=n_jobs, mp_context=ctx, initializer=_init_worker) as pool:
        futures = {pool.submit(run_job, job): i for i, job in enumerate(jobs)}
        try:
            for fut in cf.as_completed(futures):
                i = futures[fut]
                try:
                    results[i] = fut.result()
                except Exception as exc:  # a worker crashed: record it, go on
                    results[i] = JobResult(jobs[i], "error", None, error=f"{type(exc).__name__}: {exc}")
                if on_done:
                    on_done(results[i])
        except KeyboardInterrupt:
            for fut in futures:
                fut.cancel()
            raise
    return results  # type: ignore[return-value]


def progress_printer(total: int, *, label: str = "runs", stream=None) -> Callable[[JobResult], None]:
    """A text progress bar on stderr, one update per finished job."""
    import sys

    stream = stream or sys.stderr
    done = {"n": 0}

    def update(result: JobResult) -> None:
        done["n"] += 1
        n = done["n"]
        bar = "#" * int(30 * n / total)
        mark = result.status
        stream.write(f"\r[{bar:<30s}] {n}/{total} {label}  last: {result.job.tag or result.job.scenario.stem} "
                     f"({mark})".ljust(100)[:100])
        if n == total:
            stream.write("\n")
        stream.flush()

    return update

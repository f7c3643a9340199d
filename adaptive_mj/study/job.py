"""One run of a study, as every backend sees it: the RunSpec (a scenario file, overrides, a seed, where
to log), the RunOutcome sent back (its Status, summary, analyses, and the figures studies judge, with `passes`,
the one predicate every study's pass or fail goes through), the Backend the runs go to, and run_job /
run_in_worker, which run one job in this process, a worker process (adaptive_mj.study.parallel) or a Ray task
(adaptive_mj.study.ray_backend).

The two backends share these pieces through this module: parallel.py dispatches to ray_backend.py
for `--backend ray`, and ray_backend.py imports nothing from parallel.py (no import cycle).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from adaptive_mj.errors import AdaptiveMJError, PreflightRefused
from adaptive_mj.sim import interrupt
from adaptive_mj.trajectory import Status, Trajectory, ending


#: the bench's breaking-point and margin-grid runs log their summary and a row per second (bench --full-logs: every
#: row); their verdicts and figures come from the full trajectory either way
SUMMARY_LOG_RATE_HZ = 1.0  # Hz

@dataclass(frozen=True)
class RunSpec:
    """One run as a study asks for it. scenario: a scenario file; overrides: --set expressions (a law swapped in
    comes first: setup.scenario.law_swap); seed: noise seed or None; log: the MCAP path to write (None: no log);
    tag: caller's label;
    extras: names of functions in adaptive_mj.study.analysis run on the full-rate trajectory (from EXTRAS);
    keep_trajectory: send the decimated trajectory back (False: the summary only, as a sweep needs);
    expect: what the run is for (EXPECTATIONS): "ok", meant to meet its [success] criteria (a failure is a
    regression); "fail", a demonstration meant to fail or diverge (the lecture's failure modes); "measured", a
    baseline, a sweep point or a breaking-point probe whose verdict is the measurement itself."""

    scenario: Path
    overrides: tuple[str, ...] = ()
    seed: int | None = None
    log: Path | None = None
    tag: str = ""
    extras: tuple[str, ...] = ()
    keep_trajectory: bool = True
    expect: str = "ok"


EXPECTATIONS = ("ok", "fail", "measured")


def as_expected(r: "RunOutcome") -> bool | None:
    """Whether a run ended as its job expected (None: a measured run, which expects nothing): an "ok" run ok, a
    "fail" run failed, crashed or diverged."""
    if r.job.expect == "measured":
        return None
    if r.job.expect == "fail":
        return r.status in FAILURES
    return r.status == Status.OK


#: The endings of a run that ran and did not make it: what a "fail" job expects.
FAILURES = (Status.FAILED, Status.CRASHED, Status.DIVERGED)


#: The analyses a RunSpec may name (a closed set, so no text from a scenario or log picks a function).
EXTRAS = ("excitation_index", "excitation_rate", "drift_rate", "estimate_drift", "swap_response", "lyapunov_check",
          "manipulator_response", "sudden_failure", "chattering", "change_response", "flight_metrics")

#: Seconds the parent waits, after SIGTERM, for the workers to close their logs and exit.
STOP_TIMEOUT = 30.0


@dataclass(frozen=True)
class RunOutcome:
    """One run's outcome, as every backend sends it back and every study reads it.

    job: its RunSpec; status: how it ended (a Status: the summary's verdict "ok", "failed", "crashed", "diverged";
    "interrupted"; "error" when it could not be set up, "refused" when its pre-flight check refused it; a "failed"
    run whose reason is a crash's, as older logs and rows have it, reads as "crashed": trajectory.ending);
    summary: the run's summary (None when it did not run or was stopped before one); extras: the analyses its
    spec asked for (EXTRAS: name -> result); trajectory: its rows decimated to the scenario's logging rate (None
    unless the spec keeps them); error: why it did not run (one line)."""

    job: RunSpec
    status: str  # given as a Status or its text; a Status once made (__post_init__)
    summary: dict | None
    extras: dict = field(default_factory=dict)
    trajectory: Trajectory | None = None
    error: str = ""

    def __post_init__(self):
        object.__setattr__(self, "status", ending(self.status, self.reason))

    @property
    def spec(self) -> RunSpec:
        """What was run (the same as .job)."""
        return self.job

    @property
    def reason(self) -> str:
        """Why it ended so: its summary's reason ("" for an ok run), or for a run that never ran, its error."""
        return self.error if self.summary is None else str(self.summary.get("reason") or "")

    @property
    def completed(self) -> bool:
        """It ran to its end (status ok or failed, its summary there): not crashed, diverged, interrupted, refused
        or in error; its figures are the whole run's."""
        return self.status in COMPLETED and self.summary is not None

    @property
    def crashed(self) -> bool:
        """Its vehicle hit the ground or tipped over (a quadrotor), cutting the run short."""
        return self.status == Status.CRASHED

    @property
    def tail_error(self) -> float:
        """The tail RMS tracking error [m or rad] (TAIL_METRICS: the 1-DOF one, else the joint-norm one); inf when
        the run did not complete or the figure is absent or not finite."""
        if not self.completed:
            return math.inf
        metrics = (self.summary or {}).get("metrics") or {}
        return _finite_or_inf(next((metrics[k] for k in TAIL_METRICS if metrics.get(k) is not None), None))

    @property
    def unstable(self) -> list[str]:
        """The stability criteria the run missed (setup.success.unstable on its summary's metrics, against the
        bounds its summary's `success` records): [] when it met them, or has no summary or no such bounds."""
        from adaptive_mj.setup.success import unstable

        summary = self.summary or {}
        crit = summary.get("success") or {}
        return unstable(summary.get("metrics") or {}, crit.get("tail_saturation"), crit.get("oscillation"))

    @property
    def max_position_error(self) -> float:
        """The largest position error ‖p_d − p‖ over the run [m] (the flight_metrics analysis, a quadrotor's); inf
        where the run has no such analysis or its figure is not finite."""
        return _finite_or_inf((self.extras.get("flight_metrics") or {}).get("max_error"))

    @property
    def predicted_unstable(self) -> bool:
        """The run's pre-flight check found its loop past the stability limit (its summary's `preflight`)."""
        pre = (self.summary or {}).get("preflight") or {}
        return bool(pre.get("checked")) and pre.get("ok") is False


#: the names before 0.2.0 (a plugin or a script may still import them)
Job = RunSpec
JobResult = RunOutcome

#: Endings of a run that ran to its end, every row there: judged by their figures, whatever the scenario's verdict.
COMPLETED = (Status.OK, Status.FAILED)

#: The summary metrics that hold the tail RMS tracking error, in the order read: the 1-DOF one [m or rad] (on a
#: plant with joints the RMS over every joint's error), then the RMS of the joint error norm |q̃| [rad or m].
TAIL_METRICS = ("rms_tracking_error_tail", "rms_tracking_error_norm_tail")


def _finite_or_inf(value: float | None) -> float:
    """A summary's or an analysis's figure as a float, inf where it is absent (None) or not finite."""
    v = math.inf if value is None else float(value)
    return v if math.isfinite(v) else math.inf


def passes(result: RunOutcome, *, tail_bound: float | None = None, max_error: float | None = None,
           stable: bool = True) -> bool:
    """Whether a study's run passes, the one predicate every study's pass or fail goes through (the breaking
    points of the stress study, the scorecard and the control-rate section by a tail bound; the quadrotor's flight
    margins by a position-error bound; the bench's quadrotor tasks): it completed (ok or failed: it ran to its
    end, the scenario's own [success] verdict aside; so it did not crash, diverge, or stop interrupted, refused or
    in error) and each bound given holds: its tail RMS tracking error at most tail_bound [m or rad]
    (RunOutcome.tail_error), its largest position error at most max_error [m] (RunOutcome.max_position_error).
    None: that bound is not asked. A crash fails whatever its figures: the tail of a run cut short is not the tail
    of the run. stable: the run must also meet its stability criteria (RunOutcome.unstable: its tail saturated
    more than success.tail_saturation, or its body rate oscillating past success.oscillation; the quadrotor's by
    default), whatever its [success] verdict says of the rest."""
    return (result.completed and not result.crashed
            and (tail_bound is None or result.tail_error <= tail_bound)
            and (max_error is None or result.max_position_error <= max_error)
            and not (stable and result.unstable))


def decimate(traj: Trajectory, every: int) -> Trajectory:
    """Every `every`-th row of a trajectory (the logging rate), and its last row: a report's "final"
    values read from the decimated rows are then the full-rate run's own (docs/METRICS.md)."""
    if every <= 1:
        return traj
    rows = np.arange(0, len(traj.t), every)
    if len(traj.t) and rows[-1] != len(traj.t) - 1:
        rows = np.append(rows, len(traj.t) - 1)
    meta = dict(traj.meta, log_every=every)
    return replace(traj, t=traj.t[rows], x=traj.x[rows], u=traj.u[rows], s=traj.s[rows], ref=traj.ref[rows],
                   theta_hat=traj.theta_hat[rows], theta=traj.theta[rows], V=traj.V[rows], meta=meta)


#: Study rows (sweep, stress, score, breaking points, the flight margins) run every probe, whatever the law, and
#: judge it by its outcome: the pre-flight check (sim.preflight) never stands in for a run, so a law that declares
#: its feedback (and is checked) and one that does not are measured alike. Its result goes into the run's summary
#: (`preflight`), not onto the terminal. It comes first in a job's overrides, so a user's own --set
#: success.preflight wins.
RECORD_PREFLIGHT = "success.preflight='record'"


def log_write_error(log: Path | None, exc: OSError) -> str:
    """One line for a run whose log could not be written: what failed, and what is left."""
    what = exc.strerror or type(exc).__name__
    left = (f"; what was written reads as truncated (adaptive-mj replay {log})" if log is not None and log.is_file()
            and log.stat().st_size > 0 else "")
    return f"{log}: the log could not be written ({what}){left}"


def _job_scenario(job: RunSpec):
    """A job's scenario, loaded with its overrides and seed, after checking its analyses and that its log
    can be made (its folder, and no file there yet); an AdaptiveMJError (or OSError) otherwise."""
    from adaptive_mj.setup import scenario as sc

    for name in job.extras:
        if name not in EXTRAS:
            raise AdaptiveMJError(f"unknown analysis {name!r}; expected one of {', '.join(EXTRAS)}")
    scn = sc.load(job.scenario, overrides=list(job.overrides), seed=job.seed, keep=True)  # a study's: kept
    if job.log is not None:
        job.log.parent.mkdir(parents=True, exist_ok=True)
        if job.log.exists():
            raise AdaptiveMJError(f"{job.log}: file exists")
    return scn


def run_job(job: RunSpec) -> RunOutcome:
    """Load, run and log one job (in a worker or in-process)."""
    from adaptive_mj.study import analysis
    from adaptive_mj.setup.build import build
    from adaptive_mj.runs.runner import execute

    try:
        scn = _job_scenario(job)
        result = execute(scn, log_path=job.log, label=job.tag)
        traj = result.trajectory
        setup = None
        extras = {}
        for name in job.extras:
            if setup is None:
                setup = build(scn)  # law and form, for analyses that need them (no run)
            extras[name] = getattr(analysis, name)(traj, setup)
        every = max(1, round(1.0 / (scn.log_rate_hz * traj.meta["dt"])))
        return RunOutcome(job, result.summary["status"], result.summary, extras,
                         decimate(traj, every) if job.keep_trajectory else None)
    except PreflightRefused as exc:  # the loop cannot be stable: a result of the study, not a broken job
        return RunOutcome(job, Status.REFUSED, None, error=str(exc))
    except AdaptiveMJError as exc:
        return RunOutcome(job, "error", None, error=str(exc))
    except OSError as exc:  # the log could not be written (disk full, a file-size limit, a read-only folder)
        return RunOutcome(job, "error", None, error=log_write_error(job.log, exc))


def run_jobs_batched(jobs: Sequence[RunSpec], *, nthread: int = 0) -> list[RunOutcome]:
    """run_job for each of `jobs`, their physics stepped together in one mujoco.batch.Batch of nthread
    threads (runner.execute_batch's pieces): the same logs, summaries and verdicts. A job that cannot be
    set up is an "error" (or "refused") result and the others go on. A stop signal closes every log of
    the group as "interrupted" and comes out as the KeyboardInterrupt."""
    from adaptive_mj.runs.runner import start, step_batch

    out: list[RunOutcome | None] = [None] * len(jobs)
    started = {}
    for i, job in enumerate(jobs):
        try:
            started[i] = start(_job_scenario(job), log_path=job.log, label=job.tag)
        except PreflightRefused as exc:
            out[i] = RunOutcome(job, Status.REFUSED, None, error=str(exc))
        except AdaptiveMJError as exc:
            out[i] = RunOutcome(job, "error", None, error=str(exc))
        except OSError as exc:
            out[i] = RunOutcome(job, "error", None, error=log_write_error(job.log, exc))
    ids = list(started)
    trajs = step_batch(list(started.values()), nthread=nthread)
    for i, traj in zip(ids, trajs, strict=True):
        out[i] = _job_result(jobs[i], started[i], traj)
    return [r for r in out if r is not None]


def _job_result(job: RunSpec, st, traj: Trajectory) -> RunOutcome:
    """A started run's verdict, log closed, analyses and decimated rows, as run_job returns them."""
    from adaptive_mj.study import analysis

    try:
        result = st.finish(traj)
    except OSError as exc:
        return RunOutcome(job, "error", None, error=log_write_error(job.log, exc))
    extras = {name: getattr(analysis, name)(result.trajectory, st.setup) for name in job.extras}
    every = max(1, round(1.0 / (st.scn.log_rate_hz * result.trajectory.meta["dt"])))
    return RunOutcome(job, result.summary["status"], result.summary, extras,
                     decimate(result.trajectory, every) if job.keep_trajectory else None)


def run_in_worker(job: RunSpec) -> RunOutcome:
    """run_job in a worker process or a Ray task: a stop signal interrupts the run (its log closed as "interrupted");
    once one came, jobs still queued are not started."""
    if interrupt.requested() is not None:
        return RunOutcome(job, "interrupted", None, error="not started: the runs were interrupted")
    try:
        with interrupt.armed():
            return run_job(job)
    except KeyboardInterrupt as exc:
        return RunOutcome(job, "interrupted", getattr(exc, "summary", None), error=str(exc) or "interrupted")


def interrupted_note(finished: int, total: int) -> str:
    return f"{finished} of {total} runs had finished; the run(s) in progress closed their logs as 'interrupted'"


def _int_at_least(value: object, lowest: int) -> bool:
    """An int (not a bool) >= lowest: an option checked as any value its caller passed."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= lowest


@dataclass(frozen=True)
class Backend:
    """Where the runs go. kind "local": worker processes on this machine (`jobs` of them; 1 runs
    in this process). kind "ray": one Ray task per run (adaptive_mj.study.ray_backend): `address`
    None starts Ray on this machine with `jobs` CPUs, "auto" or "ray://host:port" joins a cluster;
    `logs` "bytes" (each log comes back to the driver as bytes) or "shared" (each task writes its
    log itself, on storage every node sees); `retries` (both kinds): how often a run whose worker
    process or node died is submitted again."""

    kind: str = "local"
    jobs: int = 1
    address: str | None = None
    logs: str = "bytes"
    retries: int = 3
    engine: str = "process"  # "process": one run per worker process or Ray task; "batch": runs stepped together
    # in a mujoco.batch.Batch (local: in this process, --jobs threads; ray: up to RUNS_PER_TASK runs per task)

    @classmethod
    def from_args(cls, args) -> "Backend":
        """The Backend a command line asks for (--jobs, --backend, --address, --ray-logs, --retries,
        --engine; absent ones at their defaults), checked by `checked`."""
        return cls.checked(getattr(args, "backend", "local"), jobs=args.jobs, address=getattr(args, "address", None),
                           logs=getattr(args, "ray_logs", "bytes"), retries=getattr(args, "retries", 3),
                           engine=getattr(args, "engine", "process"))

    @classmethod
    def checked(cls, kind: str = "local", *, jobs: int | None = None, address: str | None = None,
                logs: str = "bytes", retries: int = 3, engine: str = "process") -> "Backend":
        """The one place a backend's options are checked (the command line's and the Python API's,
        adaptive_mj.study.api): a Ray option without kind "ray" is refused with one line, as are a
        bad count or choice; jobs None: every core."""
        import os

        from adaptive_mj.errors import ScenarioError

        for opt, value, choices in (("--backend", kind, ("local", "ray")), ("--ray-logs", logs, ("bytes", "shared")),
                                    ("--engine", engine, ("process", "batch"))):
            if value not in choices:
                raise ScenarioError(f"{opt} must be one of {', '.join(choices)}, got {value!r}")
        if kind != "ray":
            for opt, given, default in (("--address", address, None), ("--ray-logs", logs, "bytes")):
                if given != default:
                    raise ScenarioError(f"{opt} is for --backend ray (this command runs on --backend {kind})")
        if jobs is None:
            jobs = os.cpu_count() or 1
        if not _int_at_least(jobs, 1):
            raise ScenarioError(f"--jobs must be an integer >= 1, got {jobs}")
        if not _int_at_least(retries, 0):
            raise ScenarioError(f"--retries must be an integer >= 0, got {retries}")
        if kind == "ray":
            ray_module()  # not installed: one line now, before any folder is made
        return cls(kind=kind, jobs=jobs, address=address, logs=logs, retries=retries, engine=engine)


def ray_module():
    """The ray module, or one line saying how to install it (Ray is an optional extra)."""
    try:
        import ray
    except ImportError:
        raise AdaptiveMJError("--backend ray needs Ray, an optional extra: pip install -e '.[ray]' "
                              "(or pip install 'adaptive-mj[ray]')") from None
    return ray

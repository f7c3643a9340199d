"""Run a scenario end to end: build, simulate with the MCAP recorder attached,
summarise. Also where log file names are chosen (never overwriting)."""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import logging
import os
import platform
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Sequence

from adaptive_mj import __version__
from adaptive_mj.laws import kinds as law_kinds
from adaptive_mj.plants import ModelSource
from adaptive_mj.plants.mujoco_plant import reusing_run_data
from adaptive_mj.setup.build import Setup, build
from adaptive_mj.errors import AdaptiveMJError, Interrupted, PreflightRefused, ScenarioError
from adaptive_mj.notes import say
from adaptive_mj.sim.loop import limits_meta, plant_order, run
from adaptive_mj.sim.stage import ControlTiming
from adaptive_mj.report.metrics import clean_json, summary as make_summary
from adaptive_mj.setup.scenario import Scenario
from adaptive_mj.setup.success import Criteria, criteria, judge
from adaptive_mj.sim import preflight
from adaptive_mj.sim import interrupt
from adaptive_mj.sim.interrupt import deferred
from adaptive_mj.trajectory import Status, Trajectory

# Run outputs: logs/ under the current directory (in the repository, its logs/, ignored by git), or
# $ADAPTIVE_MJ_LOGS; read when a run needs it (default_logs_dir()). A Path set here replaces both.
LOGS_DIR: Path | None = None


def default_logs_dir() -> Path:
    """The folder new logs and study folders go to by default (absolute: LOGS_DIR, $ADAPTIVE_MJ_LOGS or ./logs)."""
    return Path(LOGS_DIR or os.environ.get("ADAPTIVE_MJ_LOGS") or "logs").absolute()


@dataclass(frozen=True)
class RunResult:
    """One run: its trajectory (every physics step), its summary (metrics, the verdict against the scenario's
    [success] criteria, as `adaptive-mj run` prints it) and its log's path (None: no log)."""

    trajectory: Trajectory
    summary: dict
    log_path: Path | None

    @property
    def status(self) -> str:
        """The verdict: "ok" only when the run completed and met its [success] criteria; "failed", "diverged"."""
        return str(self.summary["status"])

    @property
    def ok(self) -> bool:
        return self.status == Status.OK


@functools.cache
def _versions() -> tuple[tuple[str, str], ...]:
    import mcap
    import mujoco
    from importlib.metadata import version

    return tuple({"adaptive_mj": __version__, "mujoco": mujoco.__version__, "dm_control": version("dm-control"),
                  "mcap": getattr(mcap, "__version__", version("mcap")), "python": platform.python_version()}.items())


def versions() -> dict[str, str]:
    """The versions a log records (read once per process: importlib.metadata scans the installed
    distributions, ~0.4 ms a call, which a study of 10^4 runs would pay 2·10^4 times)."""
    return dict(_versions())


def reserve_log_path(scn: Scenario, *, out: Path | None = None, directory: Path | None = None,
                     force: bool = False) -> Path:
    """The log's path, created empty so no later run can take it.

    out: an explicit file; refused if it exists unless force (then it is left as it
    is until the run starts writing, so a run that fails to start keeps the old file).
    Otherwise <directory>/<scenario>-<UTC time>-seed<N>[-i].mcap, never an existing name.
    """
    if out is not None:
        out = Path(out)
        if out.exists() and not force:
            raise AdaptiveMJError(f"{out}: file exists; pass --force to overwrite it")
        if out.exists() and not out.is_file():
            raise AdaptiveMJError(f"{out}: not a regular file; choose a log file name")
        out.parent.mkdir(parents=True, exist_ok=True)
        if not out.exists():
            out.write_bytes(b"")
        return out
    directory = Path(directory) if directory is not None else default_logs_dir()
    directory.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    stem = f"{scn.name}-{stamp}-seed{scn.noise.seed}"
    for i in range(10_000):
        path = directory / (f"{stem}.mcap" if i == 0 else f"{stem}-{i}.mcap")
        try:
            with open(path, "xb"):
                return path
        except FileExistsError:
            continue
    raise AdaptiveMJError(f"{directory}: could not find a free log name for {stem}")


def control_timing(scn: Scenario, setup: Setup) -> ControlTiming:
    """The run's ControlTiming from [control] and simulation.control_delay, checked against the
    plant's timestep and the law (a ScenarioError naming the key otherwise)."""
    c = scn.control
    try:
        timing = ControlTiming.of(setup.plant.dt, mode=c.mode, period=c.period, delay=scn.simulation.control_delay)
    except ValueError:
        raise ScenarioError(f"{scn.source}: control.period must be a whole multiple of the physics timestep "
                            f"{setup.plant.dt!r} s, got {c.period!r}") from None
    if timing.sampled and setup.law.has_filters:
        kind = law_kinds.built_in().get(scn.law.kind)
        key = kind.filters_key if kind is not None else "law.composite"  # the law kind's own (MRAC: its MIT rule)
        raise ScenarioError(f"{scn.source}: {key} runs under control.mode = 'continuous' only "
                            "(its filters integrate the stage states), got control.mode = 'sampled'")
    return timing


def log_header(scn: Scenario, setup: Setup):
    """The record.LogHeader of a run of `scn` built as `setup` (also used by adaptive_mj.env)."""
    from adaptive_mj.log.record import LogHeader

    plant = setup.plant
    timing = control_timing(scn, setup)
    limits = limits_meta(plant)  # the verdict's metrics of a log summarised from its rows (format 5)
    return LogHeader(
        scenario_name=scn.name, scenario_text=scn.text, scenario_source=scn.source, overrides=scn.overrides,
        seed=scn.noise.seed, log_rate_hz=scn.log_rate_hz, dt=plant.dt, order=plant_order(plant),
        joint_names=tuple(plant.joint_names), notes=tuple(setup.notes),
        control_names=tuple(getattr(plant, "control_names", ())), state_names=tuple(getattr(plant, "state_names", ())),
        param_names=tuple(setup.law.names), model_xml=setup.model_xml,
        model_source=setup.source.xml if setup.source else None,
        model_assets=dict(setup.source.assets) if setup.source else {},
        versions=versions(), created_unix=time.time(),
        law_plugin=setup.law.installed.describe() if setup.law.installed is not None else None,
        plant_plugin=_plant_plugin(scn), control_mode=timing.describe()["control_mode"],
        control_period=timing.period, ctrl_range=_list(limits.get("ctrl_range")),
        joint_limits=limits.get("joint_limits"), encoding=scn.log_encoding, law_evaluation=law_evaluation(setup.law))


def law_evaluation(law) -> str:
    """How a Slotine–Li law evaluates Y π̂ and Yᵀ s ("recursive": O(n), "regressor": Y whole), a flight law's
    allocation (law.allocation: "yaw_last" or "exact_clip"; written since issue 52's allocation), "" for another
    law."""
    allocation = getattr(law, "allocation", None)
    if isinstance(allocation, str):
        return allocation
    recursive = getattr(law, "recursive", None)
    return "" if recursive is None else ("recursive" if recursive else "regressor")


def _list(value) -> list | None:
    return None if value is None else list(value)


def _plant_plugin(scn: Scenario) -> dict | None:
    """{name, distribution, version, source_sha256} of an installed plant plugin, else None."""
    if scn.plant.plugin_params is None:
        return None
    from adaptive_mj.plants.plugin import installed

    inst = installed().get(scn.plant.kind)
    return inst.describe() if inst is not None else None


def new_output_dir(requested: Path | None, name: str, *, logs_dir: Path | None = None) -> Path:
    """A folder for a bench or sweep: `requested` if new or empty (created), else a new
    <logs_dir>/<name>-<UTC time>[-i] that no earlier run used (logs_dir: default_logs_dir())."""
    if requested is not None:
        out = Path(requested)
        if out.exists() and (not out.is_dir() or any(out.iterdir())):
            raise AdaptiveMJError(f"{out}: exists and is not an empty folder; choose a new -o DIR")
        out.mkdir(parents=True, exist_ok=True)
        return out
    logs_dir = Path(logs_dir) if logs_dir is not None else default_logs_dir()
    logs_dir.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    for i in range(10_000):
        path = logs_dir / (f"{name}-{stamp}" + (f"-{i}" if i else ""))
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue
    raise AdaptiveMJError(f"{logs_dir}: could not find a free folder name for {name}-{stamp}")


# A 1-DOF run this short takes the Python callback when it is the only run of its process
# (`adaptive-mj run`): loading the compiled callback costs ~0.55 s of numba start-up (its type
# registries; the compile itself is cached on disk), the Python callback ~75 µs per physics step,
# and both give the same rows bit for bit (tests/test_control_step.py). Measured in PERFORMANCE.md.
QUICK_START_MAX_STEPS = 5000


def execute(scn: Scenario, *, log_path: Path | None = None, source: ModelSource | None = None,
            single: bool = False, label: str = "") -> RunResult:
    """Build and run one scenario; stream it to log_path (MCAP) when given. Before the first step,
    the pre-flight check (sim.preflight; a PreflightRefused under success.preflight = "refuse");
    after the last, the verdict against the scenario's [success] criteria (setup.success).

    single: the only run of this process (the CLI's `run`): a short 1-DOF run then takes the
    Python callback (QUICK_START_MAX_STEPS); studies leave it False and stay compiled."""
    st = start(scn, log_path=log_path, source=source, single=single, label=label)
    traj = None
    try:
        traj = run(st.setup.plant, st.setup.law, st.setup.reference, sink=st.recorder, **st.kwargs)
        return st.finish(traj)
    except BaseException as exc:  # a stop signal after the last step, before the verdict closed the log: all rows
        stop = interrupt.stop_or(exc)  # also a stop Python wrapped while numba compiled (sim.interrupt)
        st.abandon(stop, traj)
        if stop is not exc:
            raise stop from exc
        raise


def execute_batch(scenarios: Sequence[tuple[Scenario, Path | None]], *, nthread: int = 0) -> list[RunResult]:
    """execute() for each (scenario, log path) with their physics stepped together in one
    mujoco.batch.Batch (adaptive_mj.sim.batch): the same rows, logs and verdicts as execute gives each
    alone. Runs that cannot take the compiled callback, or that need another callback than the first,
    run one by one. An exception (a stop signal) closes every log as loop.run's would."""
    starts = [start(scn, log_path=log) for scn, log in scenarios]
    return [st.finish(traj) for st, traj in zip(starts, step_batch(starts, nthread=nthread), strict=True)]


def step_batch(starts: Sequence[Started], *, nthread: int = 0) -> list[Trajectory]:
    """The started runs' physics stepped together in one mujoco.batch.Batch of nthread threads
    (adaptive_mj.sim.batch.run_batch): their trajectories, in order, each log still open for its verdict
    (Started.finish). An exception closes every log (settle_batch: a stop signal, also one Python wrapped, as
    "interrupted", the runs that had ended with their verdict; the Interrupted's `finished` counts those) and goes
    on."""
    from adaptive_mj.sim.batch import run_batch

    try:
        return run_batch([dict(plant=st.setup.plant, law=st.setup.law, reference=st.setup.reference,
                               sink=st.recorder, **st.kwargs) for st in starts], nthread=nthread)
    except BaseException as exc:
        stop = interrupt.stop_or(exc)  # also a stop Python wrapped (sim.interrupt)
        ended = settle_batch(starts, stop)
        if isinstance(stop, Interrupted):  # the runs that had ended before the signal count as finished
            stop.finished = sum(r is not None for r in ended)
        if stop is not exc:
            raise stop from exc
        raise


def settle_batch(starts: Sequence[Started], exc: BaseException) -> list[RunResult | None]:
    """Close the logs of a batch that `exc` stopped (run_batch): a run that had ended gets its verdict
    (its RunResult), one cut short by a stop signal is closed as "interrupted" with its rows so far, and
    any other exception closes every log as "failed" (None for those)."""
    partial = getattr(exc, "trajectories", None) or [None] * len(starts)
    out: list[RunResult | None] = []
    for st, traj in zip(starts, partial, strict=True):
        if traj is not None and traj.status != Status.INTERRUPTED:
            out.append(st.finish(traj))
        else:
            st.abandon(exc, traj)
            out.append(None)
    return out


def identification_of(setup: Setup, traj: Trajectory) -> dict | None:
    """What the run identified (report.identification), or None for a run that estimates nothing: each
    parameter's final relative error against its truth, and, where the plant (`regressor_rows`: the manipulators)
    or the law's model form gives the regressor, which parameters the reference does not excite over the tail."""
    from adaptive_mj.form import ModelForm
    from adaptive_mj.report import identification as ident
    from adaptive_mj.report.metrics import tail_mask
    from adaptive_mj.setup.success import reference_rows

    if not len(traj) or not traj.names:
        return None
    tail = traj.t[tail_mask(traj)]
    rows = None
    if len(tail):
        ts = ident.tail_times(float(tail[0]), float(tail[-1]))
        plant, form = setup.plant, getattr(setup.law, "form", None)
        by_plant = getattr(plant, "regressor_rows", None)
        if by_plant is not None and tuple(getattr(plant, "names", ())) == tuple(traj.names):
            r = reference_rows(setup.reference, ts, 2)  # (3, N, m): q_d, q̇_d, q̈_d
            rows = by_plant(r[0], r[1], r[2])
        elif isinstance(form, ModelForm) and tuple(form.names) == tuple(traj.names):
            r = reference_rows(setup.reference, ts, form.order)  # (n+1, N, 1)
            rows = ident.form_rows(form, r[:, :, 0].T)
    return ident.identification(traj.names, traj.theta_hat[-1], traj.theta[-1], rows)


@dataclass
class Started:
    """One run built, checked and its log opened (runner.start), waiting for its trajectory."""

    scn: Scenario
    setup: Setup
    crit: Criteria
    pre: preflight.Preflight
    kwargs: dict[str, Any]  # loop.run's keyword arguments (sink apart)
    recorder: Any | None  # the MCAP Recorder, or None without a log
    log_path: Path | None

    def finish(self, traj: Trajectory) -> RunResult:
        """The verdict, and the log closed with it. The plant's MjData is handed back for the next run
        (MujocoPlant.release): setup.plant has none after this."""
        try:
            with deferred():  # a stop signal during the verdict waits until the log is closed with it
                traj, result = verdict(self.scn, traj, self.crit, self.pre)
                ident = identification_of(self.setup, traj)
                if ident is not None:
                    result["identification"] = clean_json(ident)
                if self.recorder is not None:
                    self.recorder.close(traj.status, traj.reason, result)
        finally:
            self._release()
        return RunResult(traj, result, self.log_path)

    def _release(self) -> None:
        """The run's MjData handed back for the next run's plant (MujocoPlant.release), where the plant can."""
        self.setup.plant.release()

    def abandon(self, exc: BaseException, partial: Trajectory | None = None) -> None:
        """The run did not end: its log closed as "interrupted" (with the rows it had, a stop signal)
        or "failed" (anything else). partial: the run's rows so far (default: the exception's
        `trajectory`, as loop.run's Interrupted carries it). The plant's MjData is handed back, as in finish."""
        self._release()
        if self.recorder is None or self.recorder.closed:  # closed already: the signal came after the verdict
            return
        if isinstance(exc, KeyboardInterrupt):  # loop.run has handed the recorder every whole row
            partial = partial if partial is not None else getattr(exc, "trajectory", None)
            summary = {} if partial is None else clean_json(make_summary(self.scn.name, partial))
            reason = summary.get("reason") or str(exc) or "interrupted"
            if summary:  # a run whose last step came before the signal, its verdict not: closed as interrupted too
                summary.update(status=str(Status.INTERRUPTED), reason=reason)
            self.recorder.close(Status.INTERRUPTED, reason, summary)
            if isinstance(exc, Interrupted):
                exc.summary = summary or None
        else:
            self.recorder.close(Status.FAILED, f"{type(exc).__name__}: {exc}", {})




def start(scn: Scenario, *, log_path: Path | None = None, source: ModelSource | None = None,
          single: bool = False, label: str = "") -> Started:
    """Build `scn`, say its notes, check it before flight and open its log (see execute). The plant may
    take the MjData of an ended run (mujoco_plant.reusing_run_data); Started hands it back at the end.
    label: the run's name in a study (its job's tag), said with every note and warning."""
    with reusing_run_data():
        setup = build(scn, source=source)
    plant = setup.plant
    where = f"{scn.source} ({label})" if label else str(scn.source)
    for note in setup.notes:  # model edits the scenario asked for: said on the terminal and kept in the log
        say(f"{where}: note: {note}")
    timing = control_timing(scn, setup)
    pre = preflight_of(scn, setup, timing, where=where)
    crit = criteria(scn, setup.reference, plant_order(plant), tuple(setup.law.names))
    short = single and not plant.joint_shape and scn.simulation.duration < QUICK_START_MAX_STEPS * plant.dt
    sink_every = max(1, round(1.0 / plant.dt))  # flush about once per simulated second
    kwargs: dict[str, Any] = dict(
        duration=scn.simulation.duration, theta_hat0=setup.theta_hat0, noise_std=setup.noise_std, rng=setup.rng,
        events=setup.events, state_bound=scn.simulation.state_bound, sink_every=sink_every,
        control_delay=scn.simulation.control_delay, control_mode=scn.control.mode, control_period=timing.period,
        sensors=setup.sensors, native=False if scn.simulation.python_callback or short else None)
    recorder = None
    if log_path is not None:
        from adaptive_mj.log.record import Recorder

        try:
            recorder = Recorder(log_path, log_header(scn, setup))
        except BaseException:
            with contextlib.suppress(OSError):
                Path(log_path).unlink()  # a half-written header must not pass for a log
            raise
    return Started(scn, setup, crit, pre, kwargs, recorder, log_path)


def preflight_of(scn: Scenario, setup: Setup, timing: ControlTiming, *, where: str = "") -> preflight.Preflight:
    """The run's pre-flight check, its lines said on stderr (after `where`, default the scenario's source: a
    study's run adds its name); a PreflightRefused when it fails and success.preflight = "refuse"."""
    where = where or str(scn.source)
    pre = preflight.check(setup.plant, setup.law, setup.reference, duration=scn.simulation.duration, timing=timing)
    if scn.success.preflight == "record":  # a study's run: judged by its outcome, the check in its summary
        return pre
    for line in pre.outside + pre.plant_lines:
        say(f"{where}: warning: {line}", logging.WARNING)
    for failed in ([pre.line()] if not pre.ok else []) + [line for line in (pre.gravity, pre.following) if line]:
        if scn.success.preflight == "refuse":
            raise PreflightRefused(f"{where}: refused (success.preflight = 'refuse'): {failed}")
        say(f"{where}: warning: {failed}", logging.WARNING)
    return pre


def verdict(scn: Scenario, traj: Trajectory, crit: Criteria, pre: preflight.Preflight) -> tuple[Trajectory, dict]:
    """(trajectory, summary) with the verdict: a completed run ("ok") that misses a [success] criterion
    becomes "failed", its reason naming each criterion missed and the measured value (and the
    pre-flight figure when the check had warned)."""
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    result = clean_json(make_summary(scn.name, traj))
    if traj.status == Status.OK:
        missed = judge(result, crit, unit=units.output_unit(scn.plant.kind))
        if missed:
            if not pre.ok:
                missed.append(f"the pre-flight check had warned: {pre.figure_text()}"
                              + (f" on {pre.joint}" if pre.joint else ""))
            if pre.gravity:
                missed.append("the pre-flight check had warned: gravity alone at the reference needs more than the "
                              "actuator's limit")
            traj = dataclasses.replace(traj, status=Status.FAILED, reason="; ".join(missed))
            result["status"], result["reason"] = traj.status, traj.reason
    result["success"] = clean_json(crit.describe())
    result["preflight"] = clean_json(pre.describe())
    return traj, result

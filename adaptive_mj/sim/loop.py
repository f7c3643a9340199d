"""The closed loop: one definition of a control step, driven on the Python path (the policy inside
MuJoCo's control callback, or an analytic twin's stages), on the native path (a compiled
callback, adaptive_mj.sim.native_mujoco, built from the kind's kernel spec (plants.one_dof_kernel,
manipulator_kernel, quadrotor_kernel); for an analytic plant, a compiled chunk of
the plant's own steps, adaptive_mj.sim.native_chunk, built from the kernel its kind declares: the linear plant
under MRAC's Lyapunov rule, the analytic twin and the process tank under the first-order or a sliding law) and by
adaptive_mj.env; each plant names its compiled loop (protocol.Plant.compiled_loop). The
native path is taken wherever the plant and law have one (`_native_controller`; else, and with
simulation.python_callback = true, the Python path): what is compiled is the MuJoCo plants' sliding laws,
composite adaptation and law plugins, the arms' and the quadrotor's laws, the linear plant with MRAC and the twin
with the first-order and sliding laws; the wing-rock plant, the MIT rule and the twin under composite adaptation
run in Python.

The order of a control step, written once:
    events due → measure (true state + the step's noise) → reference → law (at the integrator's
    stages, or once per control period) → limits (clamp) → delay line → apply → physics →
    advance the estimates → divergence check → the step's row
Within the physics step, what happens at each integrator stage ("law … apply", the row's control, the estimates'
advance at the step's end) is adaptive_mj.sim.stage.control_stage: `Controller` runs it with this path's pieces
(the Law protocol, the control handed back to the plant), and the compiled callbacks run the same function
compiled with theirs (adaptive_mj.sim.native_step). Between physics steps (events, noise, divergence check, rows,
the plant's termination) every path is driven by adaptive_mj.sim.driver: the Python path a chunk of one step
(driver.PythonSteps around `Controller`; adaptive_mj.env drives it one agent step at a time), the native path
chunks of many steps.

How the estimates are integrated (adaptive_mj.sim.stage): under continuous control the law is
evaluated at every stage MuJoCo's integrator calls the callback at, with the stage estimate of the
classic Runge-Kutta tableau, and θ̂ advances once per step with the tableau's weights; under
sampled-data control (`ControlTiming.mode`), once per control period, the output held.

The plant and the law are the protocols adaptive_mj.plants.protocol.Plant and
adaptive_mj.laws.protocol.Law. A law with a parameter projection (``law.bounds`` = (lower, upper))
has every stage estimate and every θ̂_{k+1} clipped into its box. A law with filters of its own
(``law.has_filters``, composite adaptation: ``law.reset()``, ``law.step_begins(x)``,
``law.step_ends(xs, us, weights, h)``) is reset when the controller is made, told the measured state
at each step's start, and given the stage states, stage controls and RK4 weights of each step once it
is done (continuous control only); on the native path the 1-DOF callback runs the composite law's filters
itself (adaptive_mj.plants.one_dof_kernel, laws.composite), the quadrotor's L1 filters likewise
(plants.quadrotor_kernel).
"""
from __future__ import annotations

import importlib
import math
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

import numpy as np

from adaptive_mj.errors import Interrupted
from adaptive_mj.laws.common import LawStep
from adaptive_mj.laws.protocol import Law
from adaptive_mj.plants import Event, plant_order
from adaptive_mj.plants.protocol import CtrlRange, Plant, control_shape, has_joints
from adaptive_mj.sim import stage as st
from adaptive_mj.sim import interrupt
from adaptive_mj.sim import native_step
from adaptive_mj.sim.driver import Drive, PythonSteps
from adaptive_mj.sim.interrupt import deferred
from adaptive_mj.sim.stage import TABLEAU, ControlTiming
from adaptive_mj.trajectory import Status, Trajectory

if TYPE_CHECKING:
    from adaptive_mj.sim.native_context import ContextOwner

__all__ = ["Event", "ControlTiming", "Controller", "Sink", "run", "prepare", "PreparedRun", "drive", "plant_order",
           "TABLEAU", "NATIVE_CHUNK"]


class StepContext:
    """The Python path's context for stage.control_stage: the fields a compiled callback's context record has
    (the kinds' CONTEXT: plants.one_dof_kernel, plants.manipulator_kernel), as attributes, its buffers as arrays.
    theta (n_theta,): the estimate at the step's start, advanced in place at each step's end (or control
    period's); u_hold (m,): the law's clamped control, held; rows: the steps armed so far (Controller.arm)."""

    def __init__(self, theta: np.ndarray, lower: np.ndarray, upper: np.ndarray, m: int, stages: int, dt: float,
                 timing: ControlTiming):
        nth = theta.shape[0]
        self.stage, self.row, self.rows, self.step, self.t = 0, 0, 0, 0, 0.0
        self.nstages, self.nth, self.nbox, self.m, self.h = stages, nth, lower.shape[0], m, dt
        self.mode, self.period_steps, self.period, self.delay = timing.mode, timing.steps, timing.period, timing.delay
        self.weights = TABLEAU[stages][1]
        self.theta, self.lower, self.upper = theta, lower, upper
        self.rsum, self.prev, self.rate = np.zeros(nth), np.zeros(nth), np.zeros(nth)
        self.u_hold, self.delayed, self.ring = np.zeros(m), np.zeros(m), np.zeros((timing.delay + 1, m))


_COMPILED: dict = {}


def _compiled_estimates():
    """(stage.stage_estimate, stage.advance_estimates) compiled with numba, once per process."""
    if not _COMPILED:
        import numba

        from adaptive_mj.numba_util import jit_tree

        _COMPILED["stage"] = jit_tree(st.stage_estimate, numba.njit)
        _COMPILED["advance"] = jit_tree(st.advance_estimates, numba.njit)
    return _COMPILED["stage"], _COMPILED["advance"]


def _as_array(a: np.ndarray, shape) -> np.ndarray:
    """stage.control_stage's `view` on the Python path: the context's buffers are arrays of their shape."""
    return a


class Controller:
    """The policy the plant calls at every stage: stage.control_stage (the order of a control step, the one the
    compiled callbacks run too) with this path's pieces: the law through the Law protocol, the control handed
    back to the plant (which applies it), the row kept for driver.PythonSteps. See the module docstring.

    theta_hat: (n_theta,) the estimate at the step's start; after each step, step_u (the applied
    control), step_out (the law's LawStep) and step_ref hold what the step's row records."""

    def __init__(self, law: Law, reference, theta_hat0, ctrl_range: CtrlRange | None, order: int, stages: int,
                 dt: float, joint_shape: tuple = (), timing: ControlTiming | None = None,
                 sensors: st.Sensors | None = None, controls: tuple | None = None):
        from adaptive_mj.numba_util import with_globals

        self.law, self.reference, self.order = law, reference, order
        self.timing = timing or ControlTiming(period=dt)
        theta_hat = np.array(theta_hat0, dtype=float)
        n_theta = theta_hat.shape[0]
        self.lo: float | np.ndarray = -math.inf  # control limits: floats, or (m,) on a plant of m joints
        self.hi: float | np.ndarray = math.inf
        if ctrl_range is not None:
            self.lo, self.hi = ctrl_range
        self.joints = bool(joint_shape)
        self.noise = np.zeros((order,) + tuple(joint_shape))
        # an arm's sensors (stage.sense): None = the law sees x + noise
        self.sensors = sensors if sensors is not None and self.joints and not sensors.ideal else None
        if self.sensors is not None:
            m = joint_shape[0]
            self.q_prev, self.v_est = np.zeros(m), np.zeros(m)
            self.sense_period = self.timing.period if self.timing.sampled else dt
            self.alpha = self.sensors.alpha(self.sense_period)
        self.inc, self.weights = TABLEAU[stages]
        self.h = dt
        box = law.bounds
        lower, upper = box if box is not None else (np.full(n_theta, -np.inf), np.full(n_theta, np.inf))
        k = (controls or joint_shape or (1,))[0]  # the number of controls (one per joint unless named apart)
        self.ctx = StepContext(theta_hat, np.asarray(lower, dtype=float), np.asarray(upper, dtype=float),
                               k, stages, dt, self.timing)
        self.theta_hat = self.ctx.theta  # the same array, advanced in place
        self.th = np.zeros(n_theta)  # the stage estimate the law sees
        self.held_out: LawStep | None = None  # the LawStep of the law's last evaluation (held with u_hold)
        self.step_out: LawStep | None = None
        self.step_ref: np.ndarray | None = None
        self.step_u: float | np.ndarray = 0.0
        self._applied: float | np.ndarray = 0.0  # the control of the current stage, handed back to the plant
        self._ref_t, self._ref_v = (math.nan, math.nan), (None, None)
        self.filters = law.has_filters  # a law with filters of its own (composite)
        if self.filters and self.timing.sampled:
            raise ValueError("composite adaptation runs under continuous control only")
        self.stage_xs: list = []
        self.stage_us: list = []
        # a physically consistent projection (a record past the box) runs compiled here too: the same numbers as the
        # callback's, at its speed (pure Python it costs about 50 ms a stage while it is active)
        self._stage_estimate, end = st.stage_estimate, st.end_stage
        if self.ctx.nbox > n_theta:
            self._stage_estimate, advance = _compiled_estimates()
            end = with_globals(st.end_stage, advance_estimates=advance)
        self._stage = with_globals(st.control_stage, view=_as_array, law_stage=self._law_stage,
                                   apply_control=self._apply_control, record_row=self._record_row, end_stage=end)
        law.reset()

    def arm(self, noise: np.ndarray | None) -> None:
        """Mark the start of a physics step; noise: that step's measurement noise (None: none)."""
        if noise is not None:
            self.noise = noise
        self.ctx.rows = self.ctx.row + 1

    def _ref(self, t: float):
        # RK4 evaluates stages 2 and 3 at the same t + h/2, and stage 4 at the next step's t:
        # the last two reference evaluations are kept (same t, same numbers)
        if t == self._ref_t[0]:
            return self._ref_v[0]
        if t == self._ref_t[1]:
            return self._ref_v[1]
        ref = self.reference(t, self.order)
        self._ref_t, self._ref_v = (t, self._ref_t[0]), (ref, self._ref_v[0])
        return ref

    def __call__(self, t: float, x: np.ndarray):
        ctx = self.ctx
        if ctx.stage >= ctx.nstages or ctx.row >= ctx.rows:  # a call past the step's stages (an extra
            return self.step_u                                # mj_forward): change nothing
        self._stage(ctx, (t, x))
        return self._applied

    def _law_stage(self, ctx: StepContext, io, stage: int, row: int, theta, prev, lower, upper) -> None:
        """This path's law at a stage (stage.control_stage's law_stage): the law on the measured state, its
        clamped u into ctx.u_hold, its rate into ctx.rate, its LawStep kept."""
        t, x = io
        ref = self._ref(t)
        self._stage_estimate(theta, prev, self.inc[stage], self.h, lower, upper, self.th)
        if self.sensors is None:
            seen = x + self.noise
        else:
            seen = np.empty_like(x)
            sn = self.sensors
            st.sense(x[0], x[1], self.noise, sn.quantum, sn.differentiated, stage == 0, ctx.step == 0,
                     self.alpha, self.sense_period, self.q_prev, self.v_est, seen)
        if self.filters:
            if stage == 0:
                self.law.step_begins(seen)
                self.stage_xs, self.stage_us = [], []
            self.stage_xs.append(seen)
        out = self.law(t, seen, ref, self.th.copy())
        if self.joints:
            ctx.u_hold[:] = np.minimum(np.maximum(out.u, self.lo), self.hi)
        else:
            ctx.u_hold[0] = min(max(out.u, self.lo), self.hi)
        ctx.rate[:] = np.asarray(out.theta_hat_dot, dtype=float)
        self.held_out = out

    def _apply_control(self, ctx: StepContext, io, row: int, u: np.ndarray) -> None:
        """This path's "apply" (stage.control_stage's apply_control): u handed back to the plant, which applies
        it (a copy: the held buffers change at the next evaluation)."""
        self._applied = u.copy() if self.joints else float(u[0])
        if self.filters:
            self.stage_us.append(self._applied)

    def _record_row(self, ctx: StepContext, io, row: int, u: np.ndarray, theta) -> None:
        """This path's row (stage.control_stage's record_row): the applied control, the law's (held) output and
        the reference at t_k, for driver.PythonSteps."""
        t, _ = io
        self.step_u, self.step_out, self.step_ref = self._applied, self.held_out, self._ref(t)

    def finish_step(self) -> None:
        """After the plant's step: every stage was called (the estimates advanced at its last: every step under
        continuous control, at the end of a control period under sampled), and a law with filters updated."""
        ctx = self.ctx
        if ctx.row != ctx.rows or ctx.stage != 0:
            raise RuntimeError(f"the plant called the controller {ctx.stage} times in a step, "
                               f"expected {ctx.nstages}")
        if self.filters:
            self.law.step_ends(self.stage_xs, self.stage_us, self.weights, self.h)


class EventQueue:
    """Events not yet applied, in time order; `due` applies those due at a step's start."""

    def __init__(self, events: Sequence[Event], dt: float):
        self.pending = sorted(events, key=lambda e: e.t)
        self.applied: list[tuple[float, str]] = []
        self.dt = dt

    def due(self, t_k: float, plant: Plant, sink: Sink | None = None) -> None:
        """Apply every event with t_k >= t_event - dt/2 (told to sink as it is applied)."""
        while self.pending and t_k >= self.pending[0].t - 0.5 * self.dt:
            event = self.pending.pop(0)
            event.apply(plant)
            self.applied.append((t_k, event.label))
            if sink is not None:
                sink.write_event(t_k, event.label)

    def is_due(self, t_k: float) -> bool:
        """An event is due at the step starting at t_k (`due` would apply it)."""
        return bool(self.pending) and t_k >= self.pending[0].t - 0.5 * self.dt

    def steps_to_next(self, t_k: float) -> int | None:
        """Whole steps from t_k until the next event is due (at least 1), or None without one."""
        if not self.pending:
            return None
        return max(1, math.ceil((self.pending[0].t - 0.5 * self.dt - t_k) / self.dt))


class Sink(Protocol):
    """Where rows go while a run is going (the MCAP recorder): in blocks, in order."""

    def write_rows(self, k0: int, t, x, u, s, ref, theta_hat, theta, V) -> None: ...

    def write_event(self, t: float, label: str) -> None: ...


def limits_meta(plant: Plant) -> dict:
    """A trajectory's meta entries for the verdict's metrics: "ctrl_range" (lo, hi) [control units],
    lists of one entry per actuator (saturation), and "joint_limits" (m, 2) [rad or m] when a joint is
    limited (joints reaching their range); also used by adaptive_mj.env."""
    out: dict = {}
    if plant.ctrl_range is not None:
        out["ctrl_range"] = tuple(np.atleast_1d(np.asarray(b, dtype=float)).tolist() for b in plant.ctrl_range)
    limits = plant.joint_limits
    if limits is not None and np.isfinite(limits).any():
        out["joint_limits"] = np.asarray(limits, dtype=float).tolist()
    states = tuple(getattr(plant, "state_names", ()) or ())
    if states:  # rows of x that are not y's derivatives (a quadrotor's p, v, phi, omega): the oscillation metric's
        out["state_names"] = states
    return out


NATIVE_CHUNK = 1000  # physics steps per mj_step(nstep) call on the native path (results do not depend on it)


def run(plant: Plant, law: Law, reference, *, duration: float, theta_hat0: Sequence[float] | np.ndarray,
        noise_std: Sequence[float] | None = None, rng: np.random.Generator | None = None,
        events: Sequence[Event] = (), state_bound: float = math.inf,
        sink: Sink | None = None, sink_every: int = 1000, native: bool | None = None,
        control_delay: int = 0, control_mode: str = "continuous", control_period: float | None = None,
        sensors: st.Sensors | None = None) -> Trajectory:
    """Run plant under law tracking reference for `duration` seconds.

    theta_hat0: (n_theta,) initial estimates (the nominal values for baselines).
    noise_std: (n,) std of Gaussian noise added to each measured state component the law sees
    (drawn once per physics step from rng). events: applied at the first step whose start time is
    >= event.t. state_bound: |x_i| above this counts as divergence. sink: receives the rows every
    `sink_every` steps and at the end, and each event as it is applied, so a killed run loses at
    most one block. control_delay: D >= 0 whole physics steps between computing a control and
    applying it (zero before). control_mode: "continuous" (the law at every integrator stage) or
    "sampled" (once per control_period [s], a whole multiple of the timestep; default the timestep).
    native: run the law as a compiled MuJoCo callback; None = whenever the plant and law support it.
    sensors: an arm's encoders and velocity estimate (stage.Sensors; None: the law sees x + noise).

    Returns a Trajectory with one row per physics step (the state at the step's start and what was
    applied during it). A run that diverges stops at that step with status "diverged" and the
    reason; one whose plant crashed (its termination(): a quadrotor) stops there with status "crashed".
    A KeyboardInterrupt (SIGINT, or SIGTERM through the CLI) first hands the sink every whole row, then
    comes out as errors.Interrupted carrying them (status "interrupted").
    """
    r = prepare(plant, law, reference, duration=duration, theta_hat0=theta_hat0, noise_std=noise_std, rng=rng,
                events=events, state_bound=state_bound, sink=sink, sink_every=sink_every, native=native,
                control_delay=control_delay, control_mode=control_mode, control_period=control_period,
                sensors=sensors)
    return drive(r, law, reference)


def drive(r: PreparedRun, law: Law, reference) -> Trajectory:
    """Run a prepared run to its end on its own (adaptive_mj.sim.driver.Drive): the native callback chunk by chunk,
    or the Python path a step at a time."""
    plant = r.plant
    with _interruptible(r.rows.stopped):
        if r.nc is not None:
            with r.nc.plant.controlled_natively(r.nc.callback), r.nc:
                status, reason = Drive(plant, r.nc, r.rows, r.queue, r.noise, r.state_bound).run()
        else:
            ctrl = Controller(law, reference, r.theta_hat0, plant.ctrl_range, r.order, plant.stages, plant.dt,
                              plant.joint_shape, r.timing, r.sensors, control_shape(plant))
            with plant.controlled_by(ctrl):
                status, reason = Drive(plant, PythonSteps(plant, ctrl), r.rows, r.queue, r.noise,
                                       r.state_bound).run()
    return r.result(status, reason)


@dataclass
class PreparedRun:
    """One run set up for a driver (loop.run's, or adaptive_mj.sim.batch's): its rows, events, noise,
    control timing and native controller (None: the Python path)."""

    plant: Plant
    rows: Rows
    queue: EventQueue
    noise: _NoiseSource
    timing: ControlTiming
    nc: ContextOwner | None
    theta_hat0: np.ndarray
    order: int
    state_bound: float
    sensors: st.Sensors | None = None

    def result(self, status: Status, reason: str) -> Trajectory:
        meta = {"native": self.nc is not None, "events": self.queue.applied, **self.timing.describe()}
        if self.timing.delay:
            meta["control_delay"] = int(self.timing.delay)  # [physics steps]
        if self.sensors is not None:
            meta["sensors"] = self.sensors.describe()
        return self.rows.result(self.rows.k, status, reason, meta)


def prepare(plant: Plant, law: Law, reference, *, duration: float, theta_hat0, noise_std=None, rng=None,
            events: Sequence[Event] = (), state_bound: float = math.inf, sink: Sink | None = None,
            sink_every: int = 1000, native: bool | None = None, control_delay: int = 0,
            control_mode: str = "continuous", control_period: float | None = None,
            sensors: st.Sensors | None = None, chunk: int = NATIVE_CHUNK) -> PreparedRun:
    """Check run()'s arguments and set one run up (see run); chunk: the most physics steps a native
    chunk takes (its buffers' rows)."""
    order = plant_order(plant)
    if order != law.order:
        raise ValueError(f"law of order {law.order} on a plant of order {order}")
    theta_hat0 = np.asarray(theta_hat0, dtype=float)
    if theta_hat0.shape != (len(law.names),):
        raise ValueError(f"theta_hat0 must have {len(law.names)} entries {tuple(law.names)}, got {theta_hat0.shape}")
    if noise_std is not None and rng is None:
        raise ValueError("noise_std needs an rng (np.random.Generator)")
    timing = ControlTiming.of(plant.dt, mode=control_mode, period=control_period, delay=control_delay)
    rows = Rows(plant, law, int(round(duration / plant.dt)), sink, sink_every)
    queue = EventQueue(events, plant.dt)
    rows.events = queue.applied
    noise = _NoiseSource(noise_std, rng, (order,) + plant.joint_shape)
    if sensors is not None and sensors.ideal:
        sensors = None
    if sensors is not None and not plant.joint_shape:
        raise ValueError(f"encoder quantisation and differentiated velocity are for plants with joints "
                         f"(plant.kind = 'manipulator'), not a {type(plant).__name__}")
    nc = _native_controller(plant, law, reference, theta_hat0, timing, native, sensors, chunk)
    return PreparedRun(plant, rows, queue, noise, timing, nc, theta_hat0, order, state_bound, sensors)


def compile_native(plant: Plant, law: Law, reference, theta_hat0) -> bool:
    """Compile (or load from numba's disk cache) the native controller a run of this plant and law would take, and
    run nothing: a parent process does it before it forks its workers, so they do not each compile the same
    variant. True where there is one (every shape: the 1-DOF, arm and quadrotor callbacks, the analytic plants'
    compiled loops)."""
    timing = ControlTiming(period=plant.dt)
    nc = _native_controller(plant, law, reference, np.asarray(theta_hat0, dtype=float), timing, None, chunk=1)
    if nc is None:
        return False
    if nc.in_mujoco:  # the controller bound itself to the plant's MjData: let it go
        nc.__exit__(None, None, None)
    return True


def _native_controller(plant: Plant, law: Law, reference, theta_hat0, timing: ControlTiming,
                       native: bool | None, sensors: st.Sensors | None = None,
                       chunk: int = NATIVE_CHUNK) -> ContextOwner | None:
    """The native controller for this run, or None for the Python path (native False, or not supported;
    a law plugin numba cannot compile falls back with one line on stderr)."""
    if plant.compiled_loop is None:  # the plant declares its compiled loop (protocol.Plant.compiled_loop), or none
        return None
    loop_module = importlib.import_module(plant.compiled_loop)
    make: Callable[..., ContextOwner] = loop_module.Controller
    supported: Callable[[Plant, Law], bool] = loop_module.supported
    if native is None:
        native = supported(plant, law)
    if not native:
        return None
    try:
        if sensors is not None:
            nc = make(plant, law, reference, theta_hat0, chunk, control=timing, sensors=sensors)
        else:
            nc = make(plant, law, reference, theta_hat0, chunk, control=timing)
        native_step.projection_ready(nc.context)  # a run with the physically consistent projection: compiled once
        return nc
    except Exception as exc:  # a user's law numba cannot compile: say why, run it in Python
        interrupt.reraise_stop(exc)  # a stop signal that came while numba compiled, wrapped by Python
        plugin = law.installed
        if plugin is None:
            raise
        import logging

        from adaptive_mj import notes
        from adaptive_mj.sim.compile_note import fallback_line

        notes.say(fallback_line(plugin.name, exc), logging.WARNING)  # the plugin's file and line, numba's reason
        return None


class _NoiseSource:
    """Measurement noise of shape `shape` per physics step from rng (None without noise_std)."""

    def __init__(self, std, rng, shape: tuple):
        self.std = None if std is None else np.asarray(std, dtype=float)
        self.rng, self.shape = rng, shape

    def draw(self) -> np.ndarray | None:
        return self.rng.normal(0.0, self.std) if self.std is not None else None

    def draw_block(self, rows: int) -> np.ndarray | None:
        return self.rng.normal(0.0, self.std, size=(rows,) + self.shape) if self.std is not None else None


class Rows:
    """A run's rows (one per physics step), flushed to the sink in blocks with V computed on the way: the one
    place rows, V and the Trajectory are made, for loop.run and the dm_env episodes (adaptive_mj.env).

    True θ is piecewise constant (it changes only at events): kept as segments (first row, value)
    and expanded only where asked, so a long run holds no (n_steps, n_theta) copy of a constant.
    lyapunov: False for rows no law's V belongs to (an agent drives the plant): V is NaN."""

    def __init__(self, plant: Plant, law: Law, n: int, sink, every: int, *, lyapunov: bool = True):
        order, js, nth = plant_order(plant), plant.joint_shape, len(law.names)
        cs = control_shape(plant)
        self.plant, self.law, self.n, self.sink, self.every, self.nth = plant, law, n, sink, every, nth
        self.lyapunov = lyapunov
        self.t, self.x = np.empty(n), np.empty((n, order) + js)
        self.u, self.s = np.empty((n,) + cs), np.empty((n,) + js)
        self.ref, self.theta_hat = np.empty((n, order + 1) + js), np.empty((n, nth))
        self.V = np.empty(n)  # filled block by block (no full-length temporaries at the end)
        self.segments: list[tuple[int, np.ndarray]] = []
        self.mass: list[tuple[int, np.ndarray]] = []  # (first row, M (N, m, m)) recorded by a native callback
        self.k = self.flushed = 0
        self.events: list[tuple[float, str]] = []  # the events applied so far (the run's EventQueue.applied)

    def note_theta(self, row: int, value: np.ndarray) -> None:
        last = self.segments[-1][1] if self.segments else None
        if last is None or (last is not value and not np.array_equal(last, value)):
            self.segments.append((row, np.array(value, dtype=float)))

    def put_block(self, block, theta: np.ndarray, keep: int, mass: np.ndarray | None = None) -> None:
        """A native chunk's (t, x, u, s, ref, theta_hat) rows, of which the first `keep` count; mass: M(q)
        (n, m, m) at each row, where the callback recorded it (flush uses it for V instead of recomputing)."""
        k, n = self.k, len(block[0])
        rows = slice(k, k + n)
        self.t[rows], self.x[rows], self.u[rows], self.s[rows], self.ref[rows], self.theta_hat[rows] = block
        if mass is not None:
            self.mass.append((k, mass))
        self.note_theta(k, theta)
        self.k = k + keep
        if self.k % self.every == 0:
            self.flush(self.k)

    def recorded_mass(self, a: int, b: int) -> np.ndarray | None:
        """(b - a, m, m) the recorded M(q) of rows a..b-1 when the chunks recorded cover them all (chunks end
        where flushes do), else None; what is flushed is dropped."""
        pieces, first = [], a
        for k, M in self.mass:
            if k <= first < k + len(M):
                take = M[first - k:min(len(M), b - k)]
                pieces.append(take)
                first += len(take)
        self.mass = [(k, M) for k, M in self.mass if k + len(M) > b]
        if first != b:
            return None
        return pieces[0] if len(pieces) == 1 else np.concatenate(pieces)

    def theta_rows(self, a: int, b: int) -> np.ndarray:
        """(b - a, n_theta) true θ of rows a..b-1."""
        if len(self.segments) == 1:
            return np.broadcast_to(self.segments[0][1], (b - a, self.nth))
        out = np.empty((b - a, self.nth))
        for i, (start, value) in enumerate(self.segments):
            end = self.segments[i + 1][0] if i + 1 < len(self.segments) else b
            lo, hi = max(start, a), min(end, b)
            if lo < hi:
                out[lo - a:hi - a] = value
        return out

    def flush(self, upto: int) -> None:
        """Compute V for rows not yet flushed and hand them to the sink. A stop signal that comes meanwhile is
        raised when the rows are written (interrupt.deferred): before, one that came after `flushed` moved on
        but before the write left those rows out of the log while the run's summary counted them."""
        if upto <= self.flushed:
            return
        with deferred():
            self._flush(upto)

    def _flush(self, upto: int) -> None:
        rows = slice(self.flushed, upto)
        self.flushed = upto  # first: a write cut short by an interruption is never repeated
        theta = self.theta_rows(rows.start, rows.stop)
        plant = self.plant
        if not self.lyapunov:
            self.V[rows] = np.nan
        elif has_joints(plant):  # V = ½ sᵀ M(q) s + ...: M as the callback recorded it, or from the plant at q
            M = self.recorded_mass(rows.start, rows.stop)
            if M is None:
                M = plant.mass_matrices(self.x[rows, 0])
            self.V[rows] = self.law.lyapunov(self.s[rows], self.theta_hat[rows], theta, M=M)
        else:
            self.V[rows] = self.law.lyapunov(self.s[rows], self.theta_hat[rows], theta)
        if self.sink is not None:
            self.sink.write_rows(rows.start, self.t[rows], self.x[rows], self.u[rows], self.s[rows], self.ref[rows],
                                 self.theta_hat[rows], theta, self.V[rows])

    def result(self, n: int, status: Status, reason: str, meta: dict) -> Trajectory:
        self.flush(n)
        keep = slice(0, n)
        meta = {"dt": self.plant.dt, "order": self.x.shape[1], **meta}
        contact = self.plant.first_contact
        if contact is not None:
            meta["warnings"] = [f"t={contact[0]:.6g} s: {contact[1]} (the regressor has no contact forces)"]
        meta.update(limits_meta(self.plant))
        return Trajectory(t=self.t[keep], x=self.x[keep], u=self.u[keep], s=self.s[keep], ref=self.ref[keep],
                          theta_hat=self.theta_hat[keep], theta=self.theta_rows(0, n), V=self.V[keep],
                          names=tuple(self.law.names), status=status, reason=reason,
                          joint_names=tuple(self.plant.joint_names), meta=meta,
                          control_names=tuple(getattr(self.plant, "control_names", ())))

    def stopped(self, reason: str) -> Trajectory:
        """Rows 0..k-1 (and all flushed) are whole when an interruption comes."""
        n = max(self.k, self.flushed)
        return self.result(n, Status.INTERRUPTED, reason, {"events": self.events})


@contextmanager
def _interruptible(stopped: Callable[[str], Trajectory]):
    """Turn a KeyboardInterrupt into errors.Interrupted carrying stopped(reason), the rows so far."""
    try:
        yield
    except BaseException as exc:
        stop = interrupt.stop_behind(exc)  # also one Python wrapped (interrupt's module docstring)
        if stop is None and not isinstance(exc, KeyboardInterrupt):
            raise
        interrupted = stop if stop is not None else Interrupted()
        interrupted.trajectory = stopped(str(interrupted))
        if interrupted is exc:
            raise
        raise interrupted from exc

"""The pieces of one control step that run at every call of the control callback, as plain
array code: the Python controller (adaptive_mj.sim.loop) calls them as they are, and the
compiled callbacks (adaptive_mj.sim.native_mujoco from the kinds' kernels) call the same
functions compiled by numba. Nothing here imports mujoco or numba.

Continuous control (``control.mode = "continuous"``, the lecture's): the law is evaluated at
every integrator stage i with the stage estimate θ̂_i = θ̂_k + h a_i k_{i-1}, and after the last
stage the estimates advance once with the tableau's weights b_i:
    θ̂_{k+1} = θ̂_k + h Σ b_i k_i          (TABLEAU: RK4 or a one-stage integrator)
Sampled-data control (``control.mode = "sampled"``, period T = N h): the law is evaluated once per
control period, at the first stage of the period's first physics step, on the state measured
there; its output is held (zero-order hold) over the period's N steps and all their stages, and
the estimates advance once per period with the rate computed at the sample,
    θ̂_{j+1} = θ̂_j + T θ̂'_j,
which is Euler's rule and, because the rate is held over the period exactly as the control is,
also the exact integral of the held rate (docs/THEORY.md, "Sampled-data control").

Every estimate the law sees and every estimate the step ends with is clipped into the
projection box [lower, upper] (±inf where a parameter is free).

An arm's sensors (encoders, the velocity estimate): adaptive_mj.sensors (its `sense` runs here,
at the stages the law runs at).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptive_mj.laws.common import clip_into
from adaptive_mj.sensors import Sensors, sense

# Per stage count: increments a_i (θ̂_i = θ̂_k + h a_i k_{i-1}) and weights b_i. For the
# classic RK4 tableau a_i are also the stage-time offsets c_i (MuJoCo evaluates stage i at
# t + c_i h), which the compiled paths use to evaluate the reference ahead of a chunk.
TABLEAU = {
    1: ((0.0,), (1.0,)),
    4: ((0.0, 0.5, 0.5, 1.0), (1 / 6, 1 / 3, 1 / 3, 1 / 6)),
}

CONTINUOUS, SAMPLED = 0, 1  # control modes, as the compiled callbacks store them

__all__ = ["ControlTiming", "Sensors", "sense", "TABLEAU", "CONTINUOUS", "SAMPLED", "clip_into", "stage_estimate",
           "accumulate_rate", "advance_estimates", "is_sample_step", "period_ends", "delay_slot"]


@dataclass(frozen=True)
class ControlTiming:
    """When the law runs. mode: CONTINUOUS (at every integrator stage) or SAMPLED (once per
    control period, output held: zero-order hold); steps: the control period in physics steps;
    period: the same in seconds (steps · dt); delay: whole physics steps between computing a
    control and applying it."""

    mode: int = CONTINUOUS
    steps: int = 1
    period: float = 0.0
    delay: int = 0

    @classmethod
    def of(cls, dt: float, *, mode: str = "continuous", period: float | None = None, delay: int = 0) -> ControlTiming:
        """From scenario terms: mode "continuous" | "sampled", period [s] (None: dt), delay [steps]."""
        steps = 1 if period is None else int(round(period / dt))
        if steps < 1 or abs(steps * dt - (period if period is not None else dt)) > 1e-9 * max(1.0, steps * dt):
            raise ValueError(f"the control period {period} s is not a whole multiple of the timestep {dt} s")
        if mode not in ("continuous", "sampled"):
            raise ValueError(f"control mode must be 'continuous' or 'sampled', got {mode!r}")
        if mode == "continuous" and steps != 1:
            raise ValueError("a control period longer than the timestep needs sampled-data control (mode 'sampled')")
        return cls(SAMPLED if mode == "sampled" else CONTINUOUS, steps, steps * dt, int(delay))

    @property
    def sampled(self) -> bool:
        return self.mode == SAMPLED

    def describe(self) -> dict:
        """For a log's header and a trajectory's meta."""
        return {"control_mode": "sampled" if self.sampled else "continuous", "control_period": self.period,
                "control_period_steps": self.steps}


def stage_estimate(theta, prev, step_fraction, h, lower, upper, out):
    """out (n_theta,) = the estimate a stage sees: θ̂_k + (h a_i) k_{i-1} (θ̂_k itself when
    step_fraction a_i is 0), clipped into the box. prev: k_{i-1}, the previous stage's rate."""
    c = h * step_fraction
    for i in range(theta.shape[0]):
        out[i] = theta[i] + c * prev[i] if step_fraction != 0.0 else theta[i]
    clip_into(out, lower, upper)


def accumulate_rate(rsum, prev, rate, weight):
    """After a stage: rsum += b_i k_i and prev = k_i (both (n_theta,), in place)."""
    for i in range(rate.shape[0]):
        rsum[i] += weight * rate[i]
        prev[i] = rate[i]


def advance_estimates(theta, rsum, h, lower, upper):
    """End of a step (or of a control period): θ̂ += h Σ b_i k_i, clipped; rsum reset to 0.
    For a sampled law h is the control period T and rsum the rate at the sample."""
    for i in range(theta.shape[0]):
        theta[i] = theta[i] + h * rsum[i]
        rsum[i] = 0.0
    clip_into(theta, lower, upper)


def is_sample_step(step: int, period_steps: int) -> bool:
    """Whether physics step `step` (counted from the run's start) begins a control period."""
    return step % period_steps == 0


def period_ends(step: int, period_steps: int) -> bool:
    """Whether physics step `step` is the last of its control period."""
    return (step + 1) % period_steps == 0


def delay_slot(step: int, delay: int) -> tuple[int, int]:
    """(slot to store step's control in, slot holding the control of step - delay) of a ring of
    delay + 1 controls; the second is -1 while step < delay (nothing sent yet: zero applied)."""
    size = delay + 1
    return step % size, ((step - delay) % size if step >= delay else -1)


def end_stage(ctx, stage, theta, rsum, lower, upper, sampled):
    """A compiled callback's stage is done: the next stage, or at the end of the physics step the estimates
    advanced once (continuous control: every step, by h; sampled-data control: at the end of each control
    period, by the period) and the run's row, step and time moved on. ctx: either callback's context record
    (the kinds' CONTEXT: plants.one_dof_kernel, plants.manipulator_kernel: the fields stage, row, step, t, h, period,
    period_steps, nstages are the same in both); stage: the stage just evaluated; theta, rsum, lower, upper
    (n_theta,). The one definition of the step's end for both compiled callbacks."""
    stage += 1
    if stage == ctx.nstages:
        if not sampled:
            advance_estimates(theta, rsum, ctx.h, lower, upper)
        elif period_ends(ctx.step, ctx.period_steps):
            advance_estimates(theta, rsum, ctx.period, lower, upper)
        ctx.row = ctx.row + 1
        ctx.step = ctx.step + 1
        ctx.t = ctx.t + ctx.h
        stage = 0
    ctx.stage = stage


def control_stage(ctx, io):
    """One call of the control policy at an integrator stage: the order of a control step, written once. The
    Python path (adaptive_mj.sim.loop.Controller) and both compiled callbacks (adaptive_mj.sim.native_step: the
    1-DOF plants and the arms) run this same function; each binds the names below to its own pieces
    (numba_util.with_globals in Python, numba_util.jit_tree compiled):
        view(a, shape)                        a buffer of the context as an array (compiled: from its address)
        law_stage(ctx, io, stage, row, θ̂, k_{i-1}, lower, upper)
                                              measure x (+ noise), the stage estimate θ̂_i, the law's u, s and
                                              rate; u clamped into the limits, held in u_hold with s in s_hold
        apply_control(ctx, io, row, u)        u (m,) to the plant (and the step's disturbance)
        record_row(ctx, io, row, u, θ̂)        at stage 0, the step's row: t, true x, u, s, ref, θ̂
    In order: the law when due (every stage under continuous control; the first stage of each control period
    under sampled-data control, its output then held: zero-order hold) → the rate weighted into the step's sum
    → the delay line (the stage-0 control of D steps ago, held over the step; zero before) → apply → the row
    at stage 0 → end_stage (at the step's end θ̂ advanced once, row, step and t moved on).

    ctx: the run's context (a compiled callback's CONTEXT record, or the Python path's loop.StepContext): the
    fields stage, row, step, nstages, nth, nbox (lower and upper's length: n_theta, or more with the physically
    consistent projection's record, common.Modification), m (controls), mode, period_steps, delay, h, period, t,
    weights and
    the buffers theta, rsum, prev, rate (n_theta,), lower, upper (nbox,), u_hold, delayed (m,), ring (delay + 1, m).
    io: what the pieces reach the plant through (compiled: (mjData address, mjModel address, struct offsets);
    Python: (t [s], x) of the stage)."""
    stage, row, nth, m = ctx.stage, ctx.row, ctx.nth, ctx.m
    theta, rsum, prev = view(ctx.theta, nth), view(ctx.rsum, nth), view(ctx.prev, nth)
    lower, upper = view(ctx.lower, ctx.nbox), view(ctx.upper, ctx.nbox)  # the box, then any pseudo-inertia record
    sampled = ctx.mode == SAMPLED
    if (is_sample_step(ctx.step, ctx.period_steps) and stage == 0) if sampled else True:
        law_stage(ctx, io, stage, row, theta, prev, lower, upper)
        accumulate_rate(rsum, prev, view(ctx.rate, nth), 1.0 if sampled else ctx.weights[stage])
    u = view(ctx.u_hold, m)
    if ctx.delay > 0:
        delayed = view(ctx.delayed, m)
        if stage == 0:
            ring = view(ctx.ring, (ctx.delay + 1, m))
            put, get = delay_slot(ctx.step, ctx.delay)
            for j in range(m):
                ring[put, j] = u[j]
                delayed[j] = ring[get, j] if get >= 0 else 0.0
        u = delayed
    apply_control(ctx, io, row, u)
    if stage == 0:
        record_row(ctx, io, row, u, theta)
    end_stage(ctx, stage, theta, rsum, lower, upper, sampled)


# The names control_stage calls that each path binds to its own (see control_stage); unbound, they say so.
def view(a, shape):
    """A context buffer as an array of `shape` (bound by each path)."""
    raise NotImplementedError("control_stage runs with its pieces bound (loop.Controller, native_step)")


def law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """The law at a stage (bound by each path; see control_stage)."""
    raise NotImplementedError("control_stage runs with its pieces bound (loop.Controller, native_step)")


def apply_control(ctx, io, row, u):
    """The control to the plant (bound by each path; see control_stage)."""
    raise NotImplementedError("control_stage runs with its pieces bound (loop.Controller, native_step)")


def record_row(ctx, io, row, u, theta):
    """The step's row at stage 0 (bound by each path; see control_stage)."""
    raise NotImplementedError("control_stage runs with its pieces bound (loop.Controller, native_step)")


def step_times(t0: float, h: float, rows: int) -> np.ndarray:
    """(rows,) the times [s] at the start of `rows` physics steps of h [s] from t0, as MuJoCo accumulates
    them (t += h at each step), bit for bit: numpy's cumulative sum adds left to right, one term at a
    time (no pairwise summation, unlike np.sum), so it is the same sequence of roundings."""
    terms = np.full(rows, h)
    terms[0] = t0
    return np.cumsum(terms)


def stage_references(reference, t0: float, h: float, rows: int, offsets: np.ndarray, order: int):
    """(t (rows,), refs (rows · stages, order+1, ...)): the start times of `rows` physics steps of h [s] from t0 (as
    MuJoCo accumulates them, step_times) and the reference [y_d, ..., y_d^(order)] at every stage time t + c_i h
    (offsets (stages,): c_i), evaluated once per distinct time in one vectorised call (distinct_times), row-major
    by step then stage: what a compiled callback reads at (row, stage).

    A reference is a pure function of its parameters (the frozen dataclasses of adaptive_mj.reference): the chunks
    of a study's runs of one reference are the same numbers, so the last REFERENCE_CACHE ones are kept (by an equal
    reference and the same t0, h, rows, offsets and order; only a frozen dataclass that can be hashed: any other
    callable is evaluated each time) and handed out read-only."""
    key = None
    params = getattr(reference, "__dataclass_params__", None)
    if params is not None and params.frozen:  # a frozen dataclass: equal ones are the same function of t
        try:
            key = (reference, float(t0), float(h), int(rows), tuple(np.asarray(offsets, dtype=float).tolist()),
                   int(order))
            hash(key)
        except TypeError:  # a field that cannot be hashed (an array)
            key = None
    if key is not None and key in _STAGE_REFERENCES:
        return _STAGE_REFERENCES[key]
    t = step_times(t0, h, rows)
    times, which = distinct_times((t[:, None] + h * offsets[None, :]).ravel())
    refs = np.moveaxis(np.asarray(reference(times, order)), 1, 0)[which]
    if key is not None:
        t.flags.writeable = refs.flags.writeable = False
        if len(_STAGE_REFERENCES) >= REFERENCE_CACHE:
            del _STAGE_REFERENCES[next(iter(_STAGE_REFERENCES))]  # the oldest
        _STAGE_REFERENCES[key] = (t, refs)
    return t, refs


REFERENCE_CACHE = 32  # chunks of stage references kept per process (a UR5e chunk of 1000 RK4 steps: 0.6 MB)
_STAGE_REFERENCES: dict = {}


def distinct_times(stage_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(times, which): each distinct value of the stage times stage_t (N,) [s] once, and for every stage
    time the index of its value in `times` (stage_t == times[which]). Under RK4 stages 2 and 3 share
    t + h/2, and stage 4's t + h is the next step's t, the same number: the reference is evaluated at
    half the times. Stage times come in order (one pass); otherwise np.unique sorts them."""
    if np.all(stage_t[1:] >= stage_t[:-1]):
        new = np.empty(stage_t.size, dtype=bool)
        new[0] = True
        np.not_equal(stage_t[1:], stage_t[:-1], out=new[1:])
        return stage_t[new], np.cumsum(new) - 1
    return np.unique(stage_t, return_inverse=True)

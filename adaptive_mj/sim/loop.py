"""The closed loop: the law runs on plant state at every evaluation of the
dynamics (inside MuJoCo's control callback for MuJoCo plants), and the
estimates advance exactly once per physics step.

How the estimates are integrated. MuJoCo calls the control callback once
per step with Euler/implicit integrators and four times with RK4, at the
stage states of the classic Runge-Kutta tableau. The controller counts the
calls since the step began and gives the law the matching stage estimate:
    RK4:   θ̂_1 = θ̂_k,  θ̂_2 = θ̂_k + h/2 k_1,  θ̂_3 = θ̂_k + h/2 k_2,  θ̂_4 = θ̂_k + h k_3
           θ̂_{k+1} = θ̂_k + h/6 (k_1 + 2 k_2 + 2 k_3 + k_4)
    Euler: θ̂_{k+1} = θ̂_k + h k_1
(k_i: the law's θ̂' at stage i). So plant and estimates are integrated
together as one ODE by the same method, and the estimates advance exactly
once per physics step. Calls past the last stage (an extra mj_forward) see
θ̂_k and change nothing.

A law with a parameter projection (``law.bounds`` = (lower, upper)) has every
stage estimate and every θ̂_{k+1} clipped into its box, so no estimate the law
sees or the log records ever leaves it. A law with filters of its own
(composite adaptation: ``law.reset()``, ``law.step_begins(x)``,
``law.step_ends(xs, us, weights, h)``) is reset when the controller is made, told
the measured state at each step's start, and given the stage states, stage
controls and RK4 weights b_i of each step once it is done.
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Protocol, Sequence

import numpy as np

from adaptive_mj.errors import Interrupted
from adaptive_mj.trajectory import Trajectory


@dataclass(frozen=True)
class Event:
    """At time t [s] (first step with t_k >= t), call apply(plant). label: text for logs."""

    t: float
    label: str
    apply: Callable[[object], None]


# Per stage count: increments a_i (θ̂_i = θ̂_k + h a_i k_{i-1}) and weights b_i. For the
# classic RK4 tableau a_i are also the stage-time offsets c_i (MuJoCo evaluates stage i at
# t + c_i h), which adaptive_mj.sim.native uses to evaluate the reference ahead of a chunk.
TABLEAU = {
    1: ((0.0,), (1.0,)),
    4: ((0.0, 0.5, 0.5, 1.0), (1 / 6, 1 / 3, 1 / 3, 1 / 6)),
}


class _Controller:
    """The policy the plant calls at every stage: the law on (noisy) measured
    state with the stage's estimate; see the module docstring."""

    def __init__(self, law, reference, theta_hat0, ctrl_range, order: int, stages: int, dt: float,
                 joint_shape: tuple = (), delay: int = 0):
        self.law = law
        self.reference = reference
        self.order = order
        self.theta_hat = np.array(theta_hat0, dtype=float)
        self.lo, self.hi = ctrl_range if ctrl_range is not None else (-math.inf, math.inf)
        self.joints = bool(joint_shape)
        self.noise = np.zeros((order,) + tuple(joint_shape))
        self.inc, self.weights = TABLEAU[stages]
        self.h = dt
        self.stage = len(self.inc)
        self.prev_rate = None
        self.rate_sum = np.zeros_like(self.theta_hat)
        self.step_out = None
        self.step_ref = None
        self.step_u = 0.0
        bounds = getattr(law, "bounds", None)
        self.lower, self.upper = bounds if bounds is not None else (None, None)
        # A control delay of D >= 1 physics steps: the step's applied control is the (clamped)
        # stage-0 control computed D steps earlier, held over all its stages; zero before that.
        self.delay = int(delay)
        self.sent: list = []  # stage-0 controls of the last D steps, oldest first
        self._ref_t, self._ref_v = (math.nan, math.nan), (None, None)  # see __call__
        self.filters = hasattr(law, "step_ends")  # a law with filters of its own (composite)
        self.stage_xs: list = []
        self.stage_us: list = []
        if hasattr(law, "reset"):
            law.reset()

    def arm(self, noise: np.ndarray | None) -> None:
        """Mark the start of a physics step."""
        if noise is not None:
            self.noise = noise
        self.stage = 0
        self.rate_sum = np.zeros_like(self.theta_hat)

    def __call__(self, t: float, x: np.ndarray) -> float:
        i = self.stage
        # RK4 evaluates stages 2 and 3 at the same t + h/2, and stage 4 at the next step's t:
        # the last two reference evaluations are kept (same t, same numbers)
        if t == self._ref_t[0]:
            ref = self._ref_v[0]
        elif t == self._ref_t[1]:
            ref = self._ref_v[1]
        else:
            ref = self.reference(t, self.order)
            self._ref_t = (t, self._ref_t[0])
            self._ref_v = (ref, self._ref_v[0])
        if i == 0 or i >= len(self.inc):
            theta_i = self.theta_hat
        else:
            theta_i = self.theta_hat + (self.h * self.inc[i]) * self.prev_rate
            if self.lower is not None:
                theta_i = np.minimum(np.maximum(theta_i, self.lower), self.upper)
        seen = x + self.noise
        if self.filters and i < len(self.inc):
            if i == 0:
                self.law.step_begins(seen)
                self.stage_xs, self.stage_us = [], []
            self.stage_xs.append(seen)
        out = self.law(t, seen, ref, theta_i)
        u = np.minimum(np.maximum(out.u, self.lo), self.hi) if self.joints else min(max(out.u, self.lo), self.hi)
        if self.delay and i < len(self.inc):
            if i == 0:
                self.sent.append(u)
            held = self.sent[-1 - self.delay] if len(self.sent) > self.delay else 0.0 * u
            u = held
        if i < len(self.inc):
            if self.filters:
                self.stage_us.append(u)
            self.prev_rate = out.theta_hat_dot
            self.rate_sum = self.rate_sum + self.weights[i] * out.theta_hat_dot
            if i == 0:
                self.step_out, self.step_ref, self.step_u = out, ref, u
            self.stage = i + 1
        return u

    def finish_step(self) -> None:
        """Advance the estimates once, with the stages' weighted rates."""
        if self.stage != len(self.inc):
            raise RuntimeError(f"the plant called the controller {self.stage} times in a step, "
                               f"expected {len(self.inc)}")
        self.theta_hat = self.theta_hat + self.h * self.rate_sum
        if self.delay and len(self.sent) > self.delay:
            del self.sent[0]
        if self.lower is not None:
            self.theta_hat = np.minimum(np.maximum(self.theta_hat, self.lower), self.upper)
        if self.filters:
            self.law.step_ends(self.stage_xs, self.stage_us, self.weights, self.h)


class Sink(Protocol):
    """Where rows go while a run is going (the MCAP recorder): in blocks, in order."""

    def write_rows(self, k0: int, t, x, u, s, ref, theta_hat, theta, V) -> None: ...

    def write_event(self, t: float, label: str) -> None: ...


NATIVE_CHUNK = 250  # physics steps per mj_step(nstep) call on the native path


def run(plant, law, reference, *, duration: float, theta_hat0: Sequence[float],
        noise_std: Sequence[float] | None = None, rng: np.random.Generator | None = None,
        events: Sequence[Event] = (), state_bound: float = math.inf,
        sink: Sink | None = None, sink_every: int = 1000, native: bool | None = None,
        control_delay: int = 0) -> Trajectory:
    """Run plant under law tracking reference for `duration` seconds.

    theta_hat0: (n_theta,) initial estimates (the nominal values for baselines).
    noise_std: (n,) std of Gaussian noise added to each measured state
    component the law sees (drawn once per physics step from rng).
    events: applied at the first step whose start time is >= event.t.
    state_bound: |x_i| above this counts as divergence.
    sink: receives the rows every `sink_every` steps and at the end, and each
    event as it is applied, so a killed run loses at most one block.
    control_delay: D >= 0 whole physics steps between computing a control and applying
    it (the stage-0 control of step k is applied, held, over step k + D; zero before).
    native: run the law as a compiled MuJoCo callback (adaptive_mj.sim.native);
    None = whenever the plant and law support it. The two paths agree to
    ~1e-12; on the native path a MuJoCo warning is detected per chunk of
    NATIVE_CHUNK steps instead of per step.

    Returns a Trajectory with one row per physics step (the state at the step's
    start and what was applied during it). A run that diverges stops at that
    step and comes back with status "diverged" and the reason. A KeyboardInterrupt
    (SIGINT, or SIGTERM through the CLI) first hands the sink every whole row, then
    comes out as errors.Interrupted carrying them (status "interrupted").
    """
    order = plant_order(plant)
    joint_shape = tuple(getattr(plant, "joint_shape", ()))  # () for 1-DOF plants, (m,) for m joints
    if order != law.order:
        raise ValueError(f"law of order {law.order} on a plant of order {order}")
    names = tuple(law.names)
    n_theta = len(names)
    theta_hat0 = np.asarray(theta_hat0, dtype=float)
    if theta_hat0.shape != (n_theta,):
        raise ValueError(f"theta_hat0 must have {n_theta} entries {names}, got {theta_hat0.shape}")
    dt = plant.dt
    n_steps = int(round(duration / dt))
    if noise_std is not None:
        noise_std = np.asarray(noise_std, dtype=float)
        if rng is None:
            raise ValueError("noise_std needs an rng (np.random.Generator)")

    t = np.empty(n_steps)
    x = np.empty((n_steps, order) + joint_shape)
    u = np.empty((n_steps,) + joint_shape)
    s = np.empty((n_steps,) + joint_shape)
    ref = np.empty((n_steps, order + 1) + joint_shape)
    theta_hat = np.empty((n_steps, n_theta))
    # True θ is piecewise constant (it changes only at events): kept as segments
    # (first row, value) and expanded only where asked, so a long run does not hold an
    # (n_steps, n_theta) copy of a constant.
    segments: list[tuple[int, np.ndarray]] = []

    def note_theta(row: int, value: np.ndarray) -> None:
        if not segments or (segments[-1][1] is not value and not np.array_equal(segments[-1][1], value)):
            segments.append((row, np.array(value, dtype=float)))

    def theta_rows(a: int, b: int) -> np.ndarray:
        """(b - a, n_theta) true θ of rows a..b-1."""
        if len(segments) == 1:
            return np.broadcast_to(segments[0][1], (b - a, n_theta))
        out = np.empty((b - a, n_theta))
        for i, (start, value) in enumerate(segments):
            end = segments[i + 1][0] if i + 1 < len(segments) else b
            lo, hi = max(start, a), min(end, b)
            if lo < hi:
                out[lo - a:hi - a] = value
        return out

    V = np.empty(n_steps)  # filled block by block (no full-length temporaries at the end)

    ctrl = _Controller(law, reference, theta_hat0, plant.ctrl_range, order, plant.stages, dt, joint_shape,
                       control_delay)
    pending = sorted(events, key=lambda e: e.t)
    applied: list[tuple[float, str]] = []
    status, reason, k = "ok", "", 0
    flushed = 0

    def flush(upto: int) -> None:
        """Compute V for rows not yet flushed and hand them to the sink."""
        nonlocal flushed
        if upto > flushed:
            rows = slice(flushed, upto)
            flushed = upto  # first: a write cut short by an interruption is never repeated
            theta = theta_rows(rows.start, rows.stop)
            if joint_shape:  # V = ½ sᵀ M(q) s + ...: the plant gives M at the logged q
                V[rows] = law.lyapunov(s[rows], theta_hat[rows], theta, M=plant.mass_matrices(x[rows, 0]))
            else:
                V[rows] = law.lyapunov(s[rows], theta_hat[rows], theta)
            if sink is not None:
                sink.write_rows(rows.start, t[rows], x[rows], u[rows], s[rows], ref[rows],
                                theta_hat[rows], theta, V[rows])

    def result(n: int, status: str, reason: str) -> Trajectory:
        keep = slice(0, n)
        flush(n)
        meta = {"dt": dt, "order": order, "events": applied, "native": bool(native)}
        if control_delay:
            meta["control_delay"] = int(control_delay)  # [physics steps]
        contact = getattr(plant, "first_contact", None)
        if contact is not None:
            meta["warnings"] = [f"t={contact[0]:.6g} s: {contact[1]} (the regressor has no contact forces)"]
        return Trajectory(t=t[keep], x=x[keep], u=u[keep], s=s[keep], ref=ref[keep],
                          theta_hat=theta_hat[keep], theta=theta_rows(0, n), V=V[keep], names=names,
                          status=status, reason=reason, joint_names=tuple(getattr(plant, "joint_names", ())),
                          meta=meta)

    def stopped(reason: str) -> Trajectory:  # rows 0..k-1 (and all flushed) are whole when an interruption comes
        n = max(k, flushed)
        flush(n)
        return result(n, "interrupted", reason)

    def apply_events(t_k: float) -> None:
        while pending and t_k >= pending[0].t - 0.5 * dt:
            event = pending.pop(0)
            event.apply(plant)
            applied.append((t_k, event.label))
            if sink is not None:
                sink.write_event(t_k, event.label)

    if joint_shape:  # a manipulator: its own compiled callback (regressor inside)
        from adaptive_mj.sim import native_manipulator as native_mod
        from adaptive_mj.sim.native_manipulator import NativeManipulatorController as NativeController
    else:
        from adaptive_mj.sim import native as native_mod
        from adaptive_mj.sim.native import NativeController
    if native is None:
        native = native_mod.supported(plant, law) and (not control_delay or not joint_shape)
    nc = None
    if native:
        try:
            nc = NativeController(plant, law, reference, theta_hat0, NATIVE_CHUNK, delay=control_delay)
        except Exception as exc:  # a user's law numba cannot compile: say why, run it in Python
            plugin = getattr(law, "installed", None)
            if plugin is None:
                raise
            import sys

            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            print(f"adaptive-mj: note: law plugin {plugin.name!r} could not be compiled for the native callback "
                  f"({type(exc).__name__}: {first[:200]}); running it through the Python callback", file=sys.stderr)
            native = False
    if native:
        with _interruptible(stopped), plant.controlled_natively(nc.callback):
            while k < n_steps:
                t_k = plant.time
                apply_events(t_k)
                rows = min(NATIVE_CHUNK, n_steps - k, sink_every - k % sink_every)
                if pending:  # stop at the step where the next event applies
                    rows = min(rows, max(1, math.ceil((pending[0].t - 0.5 * dt - t_k) / dt)))
                noise = rng.normal(0.0, noise_std, size=(rows, order) + joint_shape) if noise_std is not None \
                    else None
                theta_now = plant.true_theta()
                block = slice(k, k + rows)
                t[block], x[block], u[block], s[block], ref[block], theta_hat[block] = nc.chunk(rows, noise)
                note_theta(k, theta_now)
                bad, reason = _first_divergence(plant, x[block], u[block], theta_hat[block], nc.theta,
                                                state_bound)
                if bad is not None:
                    k, status = k + bad, "diverged"
                    break
                k += rows
                if k % sink_every == 0:
                    flush(k)
        flush(k)
        return result(k, status, reason)

    with _interruptible(stopped), plant.controlled_by(ctrl):
        for k in range(n_steps):
            t_k = plant.time
            apply_events(t_k)
            t[k] = t_k
            x[k] = plant.observe()
            note_theta(k, plant.true_theta())
            theta_hat[k] = ctrl.theta_hat
            noise = rng.normal(0.0, noise_std) if noise_std is not None else None
            ctrl.arm(noise)
            plant.step()
            out = ctrl.step_out
            u[k] = ctrl.step_u
            s[k] = out.s
            ref[k] = ctrl.step_ref
            ctrl.finish_step()
            reason = _divergence(plant, x[k], u[k], ctrl.theta_hat, state_bound)
            if reason:
                status = "diverged"
                k += 1
                break
            if (k + 1) % sink_every == 0:
                flush(k + 1)
        else:
            k = n_steps
    flush(k)
    return result(k, status, reason)


def plant_order(plant) -> int:
    """n: the order of the plant's output dynamics (2 for a manipulator: x = [q; q̇])."""
    form = getattr(plant, "form", None)
    return form.order if form is not None else plant.order


@contextmanager
def _interruptible(stopped: Callable[[str], Trajectory]):
    """Turn a KeyboardInterrupt into errors.Interrupted carrying stopped(reason), the rows so far."""
    try:
        yield
    except KeyboardInterrupt as exc:
        interrupted = exc if isinstance(exc, Interrupted) else Interrupted()
        interrupted.trajectory = stopped(str(interrupted))
        if interrupted is exc:
            raise
        raise interrupted from exc


def _first_divergence(plant, x, u, theta_hat, theta_next, bound):
    """For a native chunk: (rows to keep, reason) at the first step that diverged, or (None, '').

    Row j's state and estimate are the result of step j-1; the state after the chunk's
    last step is read from the plant. Mirrors `_divergence`, step by step."""
    n = len(x)
    x_next = np.concatenate([x[1:], plant.observe()[None]]).reshape(n, -1)
    th_next = np.vstack([theta_hat[1:], theta_next[None, :]])
    u_rows = np.asarray(u).reshape(n, -1)
    bad = (~np.all(np.isfinite(x_next), axis=1) | ~np.all(np.isfinite(u_rows), axis=1)
           | ~np.all(np.isfinite(th_next), axis=1) | np.any(np.abs(x_next) > bound, axis=1))
    if bad.any():
        j = int(np.argmax(bad))
        if not np.all(np.isfinite(x_next[j])):
            return j + 1, f"non-finite state {x_next[j].tolist()}"
        if not np.all(np.isfinite(u[j])):
            return j + 1, f"non-finite control {np.asarray(u[j]).tolist()}"
        if not np.all(np.isfinite(th_next[j])):
            return j + 1, f"non-finite estimate {th_next[j].tolist()}"
        return j + 1, f"state {x_next[j].tolist()} beyond the bound {bound}"
    warning = plant.instability()
    if warning:
        return len(u), f"{warning} (within the {len(u)} steps before t={plant.time:.6g} s)"
    return None, ""


def _all_within(values, bound: float) -> bool:
    """Every entry finite and |v| <= bound (plain floats: cheaper than numpy on a few entries)."""
    for v in values:
        if not (math.isfinite(v) and -bound <= v <= bound):
            return False
    return True


def _divergence(plant, x_k, u_k, theta_hat, bound) -> str:
    """Text naming the first sign of divergence after a step, or ''."""
    x_next = plant.observe()
    if (_all_within(x_next.ravel().tolist(), bound) and _all_within(np.ravel(u_k).tolist(), math.inf)
            and _all_within(theta_hat.tolist(), math.inf)):  # the usual case, decided on plain floats
        warning = plant.instability()
        return warning or ""
    if not np.all(np.isfinite(x_next)):
        return f"non-finite state {x_next.tolist()}"
    if not np.all(np.isfinite(u_k)):
        return f"non-finite control {np.asarray(u_k).tolist()}"
    if not np.all(np.isfinite(theta_hat)):
        return f"non-finite estimate {theta_hat.tolist()}"
    if np.any(np.abs(x_next) > bound):
        return f"state {x_next.tolist()} beyond the bound {bound}"
    warning = plant.instability()
    return warning or ""

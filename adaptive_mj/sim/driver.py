"""The step driver: what happens between physics steps, written once for every path.

    events due → the steps' noise → a chunk of n physics steps → its rows → the divergence check → the
    plant's termination (a crash)

`chunks` is that order as a generator: it yields each chunk's step count n and waits until the plant has stepped
n physics steps; it returns (status, reason). Who steps the plant differs, nothing else does:
  - `Drive` steps it through the chunk's own `Steps` (`Steps.advance`): a compiled callback over n steps
    (adaptive_mj.sim.native_mujoco, a ContextOwner), an analytic plant's compiled loop, or the Python path, a chunk
    of one step (`PythonSteps`: the law in the Python control callback, adaptive_mj.sim.loop.Controller);
    loop.run drives a run to its end with it, adaptive_mj.env one physics step at a time (the agent's held
    control is `AgentSteps`);
  - adaptive_mj.sim.batch steps many runs' chunks together in one mujoco.batch.Batch.

Within a physics step, what happens at each integrator stage (law, limits, delay, apply, the estimates'
advance) is adaptive_mj.sim.stage.control_stage. The divergence check is `first_divergence`, one function for
every path: a row whose next state, control or next estimate is non-finite, or whose next state is beyond
simulation.state_bound, ends the run there with that row kept; a MuJoCo warning ends it after the chunk (named as
the step's when a chunk is one step, `Steps.steps_apart`). A plant's termination() (a quadrotor's crash) is asked
after the divergence check; a compiled callback that finds the crash mid-chunk says at which row (`Steps.crash`).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Generator, Protocol

import numpy as np

from adaptive_mj.plants.protocol import Plant, has_joints
from adaptive_mj.trajectory import Status

if TYPE_CHECKING:
    from adaptive_mj.laws.protocol import Law
    from adaptive_mj.sim.loop import Controller, EventQueue, Rows, _NoiseSource

__all__ = ["Steps", "OneStep", "PythonSteps", "AgentSteps", "Drive", "chunks", "first_divergence"]

#: a chunk's rows: (t (n,), x (n, order)+J, u (n,)+C, s (n,)+J, ref (n, order+1)+J, theta_hat (n, n_theta))
Block = tuple[np.ndarray, ...]


class Steps(Protocol):
    """What steps a plant a chunk at a time for `chunks`: the compiled controllers (native_context.ContextOwner,
    which documents rows_recorded, finish, crash, end_of_chunk and mass_rows), PythonSteps and AgentSteps."""

    max_rows: int  # the most physics steps one chunk takes
    theta: np.ndarray  # (n_theta,) the estimate after the steps taken
    steps_apart: bool  # True: a chunk is one step, so a MuJoCo warning after it is that step's

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """Set the next `rows` steps up; noise: (rows, order)+J their measurement noise, or None."""
        ...

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps (the chunk prepared)."""
        ...

    def rows_recorded(self) -> int: ...

    def finish(self, rows: int, *, partial: bool = False) -> Block: ...

    def crash(self) -> tuple[int, str] | None: ...

    def end_of_chunk(self) -> None: ...

    def mass_rows(self, rows: int) -> np.ndarray | None: ...


class OneStep:
    """A chunk of one physics step (the Python path's, and an agent's in adaptive_mj.env): its row is made as it
    steps (`advance`), and a MuJoCo warning after it is that step's."""

    max_rows = 1
    steps_apart = True
    noise: np.ndarray | None = None  # the coming step's measurement noise (what the law sees on top of the state)
    _row: Block = ()

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        self.noise = None if noise is None else noise[0]

    def rows_recorded(self) -> int:
        return 1

    def finish(self, rows: int, *, partial: bool = False) -> Block:
        return self._row

    def crash(self) -> tuple[int, str] | None:
        return None  # the plant's termination() says it after the step

    def end_of_chunk(self) -> None:
        return None

    def mass_rows(self, rows: int) -> np.ndarray | None:
        return None


class PythonSteps(OneStep):
    """The Python path's chunk: one physics step with the law in the Python control callback (loop.Controller,
    installed by the caller with plant.controlled_by). Its row: t_k, the true state at the step's start, the
    applied control, the law's s and the reference at t_k, the estimate at the step's start."""

    def __init__(self, plant: Plant, controller: Controller):
        self.plant, self.controller = plant, controller
        self.theta = controller.theta_hat  # the same array, advanced in place

    def advance(self, rows: int) -> None:
        plant, ctrl = self.plant, self.controller
        t_k, x_k, theta_hat = plant.time, plant.observe(), ctrl.theta_hat.copy()
        ctrl.arm(self.noise)
        plant.step()
        out, ref = ctrl.step_out, ctrl.step_ref
        assert out is not None and ref is not None  # set at the step's stage 0
        self._row = (np.array([t_k]), x_k[None], np.asarray(ctrl.step_u)[None], np.asarray(out.s)[None], ref[None],
                     theta_hat[None])
        ctrl.finish_step()


class AgentSteps(OneStep):
    """adaptive_mj.env's agent: its held control `u` (set between agent steps) over one physics step, installed by
    the caller (plant.controlled_by(agent.policy)). Its row: as PythonSteps's, with the law's s of the measured
    state at the estimate theta_hat0, and the estimate NaN (an agent has none)."""

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0: np.ndarray, order: int):
        self.plant, self.law, self.reference, self.order = plant, law, reference, order
        self.theta = theta_hat0  # what the divergence check reads as the estimate after a step
        self.u: float | np.ndarray = np.zeros(plant.joint_shape) if plant.joint_shape else 0.0

    def policy(self, t: float, x: np.ndarray):
        return self.u

    def advance(self, rows: int) -> None:
        plant = self.plant
        t_k, x = plant.time, plant.observe()
        ref = self.reference(t_k, self.order)
        seen = x + self.noise if self.noise is not None else x
        s = self.law(t_k, seen, ref, self.theta).s
        self._row = (np.array([t_k]), x[None], np.asarray(self.u)[None], np.asarray(s)[None], np.asarray(ref)[None],
                     np.full((1, len(self.theta)), np.nan))
        plant.step()


def chunks(plant: Plant, steps: Steps, rows: Rows, queue: EventQueue, noise: _NoiseSource,
           state_bound: float) -> Generator[int, None, tuple[Status, str]]:
    """A run between its steps (the module docstring's order): before each chunk the events due are applied (told
    to rows.sink) and the chunk prepared with its noise, then it yields the chunk's step count n and waits for
    the plant to have stepped n physics steps; then the rows, the divergence check and the plant's termination.
    Returns (status, reason). A chunk ends where the rows are flushed and where the next event applies."""
    while rows.k < rows.n:
        k, t_k = rows.k, plant.time
        if has_joints(plant) and steps.mass_rows(0) is None and queue.is_due(t_k):
            rows.flush(k)  # V of the rows so far with the inertia they had, before an event changes it
        queue.due(t_k, plant, rows.sink)
        n = min(steps.max_rows, rows.n - k, rows.every - k % rows.every)
        to_event = queue.steps_to_next(t_k)
        if to_event is not None:  # stop at the step where the next event applies
            n = min(n, to_event)
        theta_now = plant.true_theta()
        steps.prepare(n, noise.draw_block(n))
        yield n
        done = steps.rows_recorded()
        warning = plant.instability() if done < n else None
        if warning is not None:  # MuJoCo found the state bad mid-chunk, reset it and stepped on
            block = steps.finish(done, partial=True)  # the rows to the step that diverged, as the Python path keeps
            rows.put_block(block, theta_now, done, mass=steps.mass_rows(done))
            t_bad = block[0][-1] if done else t_k
            return Status.DIVERGED, f"{warning} in the step from t={t_bad:.6g} s (MuJoCo reset the state)"
        crash = steps.crash()  # a plant that crashes (a quadrotor): the rows up to the step that crashed, unless
        if crash is not None:  # one of them diverged first (the divergence check comes before termination)
            keep, reason = crash
            block = steps.finish(keep + 1, partial=True)  # row `keep`: the state the crashing step left
            t, x, u, s, ref, th = block
            bad, why = first_divergence(x[1:keep + 1], u[:keep], th[1:keep + 1], state_bound)
            rows.put_block(tuple(a[:keep] for a in block), theta_now, keep if bad is None else bad)
            return (Status.CRASHED, reason) if bad is None else (Status.DIVERGED, why)
        block = steps.finish(n)
        x_next, theta_next = plant.observe()[None], steps.theta[None]  # what the chunk's last step left
        if n > 1:
            x_next, theta_next = np.concatenate([block[1][1:], x_next]), np.concatenate([block[5][1:], theta_next])
        bad, reason = first_divergence(x_next, block[2], theta_next, state_bound)
        if bad is None:
            warning = plant.instability()
            if warning:
                bad = n
                reason = warning if steps.steps_apart else \
                    f"{warning} (within the {n} steps before t={plant.time:.6g} s)"
        rows.put_block(block, theta_now, n if bad is None else bad, mass=steps.mass_rows(n))
        if bad is not None:
            return Status.DIVERGED, reason
        steps.end_of_chunk()
        ended = plant.termination()
        if ended:
            return Status.CRASHED, ended
    return Status.OK, ""


class Drive:
    """A run driven chunk by chunk through its own Steps (see the module docstring): made, it has applied the
    first step's events and prepared its first chunk; `advance()` steps that chunk and prepares the next; `run()`
    to the end. status, reason: Status.OK and "" while the run goes on, then how it ended. The caller installs the
    plant's control callback (plant.controlled_by or controlled_natively) around the steps."""

    def __init__(self, plant: Plant, steps: Steps, rows: Rows, queue: EventQueue, noise: _NoiseSource,
                 state_bound: float):
        self.steps = steps
        self.status, self.reason = Status.OK, ""
        self.done = False
        self._chunks = chunks(plant, steps, rows, queue, noise, state_bound)
        self._n = self._resume()

    def _resume(self) -> int:
        """The next chunk's step count (0 once the run has ended)."""
        try:
            return next(self._chunks)
        except StopIteration as ended:
            self.done = True
            self.status, self.reason = ended.value
            return 0

    def advance(self) -> bool:
        """Step the chunk prepared and go on to the next: whether the run goes on."""
        if self.done:
            return False
        self.steps.advance(self._n)
        self._n = self._resume()
        return not self.done

    def run(self) -> tuple[Status, str]:
        """Drive the run to its end: (status, reason)."""
        while self.advance():
            pass
        return self.status, self.reason


def first_divergence(x_next, u, theta_next, bound: float) -> tuple[int | None, str]:
    """The divergence check, for every path: (rows to keep, reason) at the first step whose next state x_next[j],
    control u[j] or next estimate theta_next[j] is non-finite, or whose next state is beyond the bound (|x_i| >
    bound), or (None, ''). x_next (n, order)+J, u (n,)+C, theta_next (n, n_theta): what step j left."""
    n = len(u)
    if n == 0 or _within(x_next, bound) and _within(u, math.inf) and _within(theta_next, math.inf):
        return None, ""  # the common case: two reductions per array, no row to look for
    xs, us, ts = np.asarray(x_next).reshape(n, -1), np.asarray(u).reshape(n, -1), np.asarray(theta_next).reshape(n, -1)
    bad = (~np.all(np.isfinite(xs), axis=1) | ~np.all(np.isfinite(us), axis=1) | ~np.all(np.isfinite(ts), axis=1)
           | np.any(np.abs(xs) > bound, axis=1))
    if not bad.any():
        return None, ""
    j = int(np.argmax(bad))
    return j + 1, _what_diverged(x_next[j], u[j], theta_next[j], bound)


def _within(a, bound: float) -> bool:
    """Every entry of the array finite and |v| <= bound: a few entries (a chunk of one step) as Python floats, more
    in two reductions (a NaN makes the maximum NaN, which fails the comparison)."""
    a = np.asarray(a)
    if a.size <= _FEW:
        for v in a.ravel().tolist():
            if not (math.isfinite(v) and -bound <= v <= bound):
                return False
        return True
    return bool(np.isfinite(a).all() and np.abs(a).max() <= bound)


_FEW = 32  # entries below which Python floats are cheaper than numpy's reductions


def _what_diverged(x_next, u_k, theta_hat, bound) -> str:
    if not np.all(np.isfinite(x_next)):
        return f"non-finite state {np.asarray(x_next).tolist()}"
    if not np.all(np.isfinite(u_k)):
        return f"non-finite control {np.asarray(u_k).tolist()}"
    if not np.all(np.isfinite(theta_hat)):
        return f"non-finite estimate {np.asarray(theta_hat).tolist()}"
    return f"state {np.asarray(x_next).tolist()} beyond the bound {bound}"

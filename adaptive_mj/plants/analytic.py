"""The plants stepped without MuJoCo (the analytic twin, plants.twin; the linear plant, plants.linear): one step
written once, and the kernel each kind declares beside its own code.

A kind's dynamics are an `AnalyticKernel`: plain array functions (its rate, the RK4 right-hand side, and its
observation, the state the law sees) over a tuple of the plant's parameters. `analytic_step` is one physics step
of any such plant, RK4 (or semi-implicit Euler) with the plant's input delay line and the step's external force:
the Python path (`AnalyticPlant.step`) calls it with the kind's functions and the run's policy bound
(numba_util.with_globals), and the compiled chunk (adaptive_mj.sim.native_chunk) compiles the same function with
the same functions and the control stage (stage.control_stage) bound, so both paths do the same operations in the
same order, bit for bit (tests/test_native_analytic.py, tests/test_native_twin.py, tests/test_analytic_kernel.py).

A new analytic kind subclasses AnalyticPlant and sets `kernel` to its AnalyticKernel; adaptive_mj.sim runs it
compiled where the run's law has a compiled form (sim.native_chunk.supported), on the Python path otherwise.
Nothing here imports mujoco or numba.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Iterator

import numpy as np

from adaptive_mj.plants.protocol import Policy


def _no_functions(plant) -> dict[str, Callable]:
    return {}


def _any_plant(plant) -> bool:
    return True


@dataclass(frozen=True)
class AnalyticKernel:
    """What an analytic plant kind declares beside its code, for both paths (AnalyticPlant.step and the compiled
    chunk, adaptive_mj.sim.native_chunk). All functions but `params`, `functions` and `supports` are plain array
    code (numba compiles them; no Python objects, no allocation needed):

    name: the kind's name (in the compiled chunk's cache key and messages).
    params(plant) -> tuple: the plant's parameters as the rate and observation read them (arrays and numbers),
        taken before every step (Python) or chunk (compiled): an event that changes them takes effect at once.
    rate(p, x, u, force, out): out (n_x,) = x' at state x (n_x,) under the control u and the external force
        `force` (force_offset + disturbance(t) of the step) [the plant's units].
    observe(p, x, y): y (order,) = the state the law sees (measured before noise), from the plant's state x.
    functions(plant) -> {name: function}: globals of rate/observe bound per plant (the twin's form's φ, f, h),
        compiled in and hashed into the cache key; {} by default.
    supports(plant) -> bool: whether the compiled chunk runs this plant (limits of size or of the machine);
        True by default."""

    name: str
    params: Callable[[Any], tuple]
    rate: Callable[..., None]
    observe: Callable[..., None]
    functions: Callable[[Any], dict[str, Callable]] = field(default=_no_functions)
    supports: Callable[[Any], bool] = field(default=_any_plant)


def clamp(u, lo, hi):
    """min(max(u, lo), hi) as Python computes it (a NaN passes; ±inf bounds change nothing)."""
    v = lo if lo > u else u
    return hi if hi < v else v


# The names analytic_step calls that each path binds (see analytic_step); unbound, they say so.
def rate(p, x, u, force, out):
    """The kind's rate (AnalyticKernel.rate; bound by each path)."""
    raise NotImplementedError("analytic_step runs with the kind's functions bound (AnalyticPlant, sim.native_chunk)")


def observe(p, x, y):
    """The kind's observation (AnalyticKernel.observe; bound by each path)."""
    raise NotImplementedError("analytic_step runs with the kind's functions bound (AnalyticPlant, sim.native_chunk)")


def control(ctx, io, stage):
    """The control at integrator stage `stage` for the observation io[0] (bound by each path: the run's policy on
    the Python path, stage.control_stage compiled)."""
    raise NotImplementedError("analytic_step runs with its control bound (AnalyticPlant, sim.native_chunk)")


def analytic_step(p, x, force, k, delay, ring, h, rk4, lo, hi, ctx, io, xs, ks):
    """One physics step of h [s] of an analytic plant, x (n_x,) advanced in place: classic RK4 (rk4) with the
    control evaluated at the stages t, t + h/2, t + h/2, t + h on x, x + (h/2) k1, x + (h/2) k2, x + h k3, or
    semi-implicit Euler (the highest derivative first, then each lower one with the freshly updated value, as
    MuJoCo's Euler does; the state's rows are the output's derivatives).

    p: the kind's params; force: the step's external force; k: the plant's step count; delay: D whole steps of
    input delay (0: none): the stage-0 control of step k - D is held over the step (zero before), the controls of
    the other stages only evaluated (the law's estimates integrate by RK4), ring (D + 1,) the delay line; lo, hi:
    the plant's control limits (±inf: none; each control clamped); ctx, io: what `control` takes (io[0] (order,):
    the observation buffer); xs (n_x,), ks (4, n_x): scratch."""
    n = x.shape[0]
    y = io[0]
    u = 0.0
    # one call site each of observe, control and rate (compiled, each is inlined where it is called: two sites
    # would compile the whole control stage twice); stage 0 on a copy of x, the same values
    for j in range(4 if rk4 else 1):
        if j == 0:
            for i in range(n):
                xs[i] = x[i]
        else:
            c = h if j == 3 else h / 2
            for i in range(n):
                xs[i] = x[i] + c * ks[j - 1, i]
        observe(p, xs, y)
        v = clamp(control(ctx, io, j), lo, hi)
        if j == 0:
            if delay > 0:  # the delay line: this step's stage-0 control in, the one of D steps ago held over the step
                ring[k % (delay + 1)] = v
                v = ring[(k - delay) % (delay + 1)] if k >= delay else 0.0
            u = v
        rate(p, xs, v if delay == 0 else u, force, ks[j])
    if rk4:
        for i in range(n):
            x[i] = x[i] + h / 6 * (ks[0, i] + 2 * ks[1, i] + 2 * ks[2, i] + ks[3, i])
    else:
        x[n - 1] = x[n - 1] + h * ks[0, n - 1]
        for i in range(n - 2, -1, -1):
            x[i] = x[i] + h * x[i + 1]


def policy_at(plant, io, stage):
    """The Python path's `control`: the run's policy at the stage's time (t, t + h/2, t + h/2, t + h) on a copy of
    the observation io[0]."""
    policy = plant._policy
    if policy is None:
        raise RuntimeError(f"{type(plant).__name__}.step outside controlled_by(policy)")
    t, h = plant._t, plant.dt
    return policy(t if stage == 0 else (t + h if stage == 3 else t + h / 2), io[0].copy())


class AnalyticPlant:
    """What the plants stepped without MuJoCo share: their kind's kernel (`kernel`, an AnalyticKernel), the state
    x (n_x,), the time and step count, the input delay line, the external force (force_offset + disturbance(t)),
    the control limits, a control policy (t, y) -> u installed for the length of a run (protocol.Plant
    .controlled_by) and `step`, one analytic_step. The compiled chunk (adaptive_mj.sim.native_chunk) steps the
    same plant chunk by chunk through controlled_natively/step_native and leaves it where `step` would
    (moved_to). A subclass sets in its __init__: dt, x, ctrl_range, and delay_steps where it has an input delay
    (then init_steps)."""

    kernel: ClassVar[AnalyticKernel]
    dt: float
    x: np.ndarray
    ctrl_range: tuple[float, float] | None = None
    delay_steps: int = 0
    force_offset: float = 0.0  # a constant external force, added to u [the control's units]
    disturbance: Callable[[float], float] | None = None  # t -> external force at each step's start
    _policy: Policy | None = None
    _advance: Callable[[int], None] | None = None  # the compiled chunk (controlled_natively)
    # the module of its compiled closed loop (protocol.Plant.compiled_loop): the one chunk engine, for every
    # analytic kind (it compiles the kernel the kind declares)
    compiled_loop: ClassVar[str | None] = "adaptive_mj.sim.native_chunk"
    _t: float = 0.0
    _k: int = 0

    def init_steps(self, n_obs: int) -> None:
        """The step's buffers: the delay line (D + 1,) of stage-0 controls, the observation (n_obs,), scratch."""
        self._ring = np.zeros(self.delay_steps + 1)
        self._y = np.zeros(n_obs)
        self._xs, self._ks = np.empty(self.x.shape[0]), np.empty((4, self.x.shape[0]))
        self._python_step: Callable | None = None
        self._t, self._k = 0.0, 0

    @property
    def time(self) -> float:
        return self._t

    def termination(self) -> str | None:
        """None: an analytic plant does not crash (protocol.Plant.termination)."""
        return None

    @property
    def stages(self) -> int:
        """Policy calls per step: 4 under RK4 (the default), 1 under semi-implicit Euler."""
        return 4

    def restart(self) -> None:
        """Time, step count and delay line back to 0 (set_state)."""
        self._t, self._k = 0.0, 0
        self._ring[:] = 0.0

    def limits(self) -> tuple[float, float]:
        """(lo, hi) of ctrl_range as floats, ±inf where there is none."""
        if self.ctrl_range is None:
            return -math.inf, math.inf
        return float(self.ctrl_range[0]), float(self.ctrl_range[1])

    def step_force(self) -> float:
        """The external force held over the step starting now."""
        return self.force_offset + (self.disturbance(self._t) if self.disturbance is not None else 0.0)

    def step(self) -> None:
        """One physics step on the Python path: analytic_step with the kind's functions and the policy bound."""
        if self._python_step is None:
            from adaptive_mj.numba_util import with_globals

            kernel = self.kernel
            self._python_step = with_globals(analytic_step, rate=with_globals(kernel.rate, **kernel.functions(self)),
                                             observe=kernel.observe, control=policy_at)
        lo, hi = self.limits()
        self.x = np.ascontiguousarray(self.x, dtype=np.float64)
        self._python_step(self.kernel.params(self), self.x, self.step_force(), self._k, self.delay_steps,
                          self._ring, self.dt, self.stages == 4, lo, hi, self, (self._y,), self._xs, self._ks)
        self._t = self._t + self.dt  # time as MuJoCo keeps it: one addition of h per step
        self._k += 1

    def moved_to(self, t: float, steps: int) -> None:
        """The compiled chunk stepped `steps` steps (x in place) and left the time at t [s]."""
        self._t = t
        self._k += steps

    def instability(self) -> str | None:
        return None

    def unmodelled_drag(self) -> float | None:
        """None: the plant integrates its own equations, nothing acts outside them."""
        return None

    def release(self) -> None:
        """Nothing to hand back (no MjData)."""
        return None

    @contextlib.contextmanager
    def controlled_by(self, policy: Policy) -> Iterator[None]:
        self._policy = policy
        try:
            yield
        finally:
            self._policy = None

    @contextlib.contextmanager
    def controlled_natively(self, advance: Callable[[int], None]) -> Iterator[None]:
        """For the length of a compiled run: step_native(n) calls advance(n) (the compiled chunk's controller,
        which steps this plant n steps in one compiled call)."""
        self._advance = advance
        try:
            yield
        finally:
            self._advance = None

    def step_native(self, nstep: int) -> None:
        """nstep physics steps under the compiled chunk (controlled_natively): the same steps as `step`, bit for
        bit."""
        if self._advance is None:
            raise RuntimeError(f"{type(self).__name__}.step_native outside controlled_natively(advance)")
        self._advance(nstep)

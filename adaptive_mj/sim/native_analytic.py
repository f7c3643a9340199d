"""The compiled closed loop of an analytic plant stepped without MuJoCo: the linear plant
(adaptive_mj.plants.linear.LinearPlant) under direct MRAC with the Lyapunov rule (laws.mrac).

There is no mj_step to call a control callback: one numba function (`chunk_factory`'s) steps a whole chunk of
physics steps, each plants.analytic.analytic_step with the linear plant's kernel (plants.linear: its RK4 with its
input delay line, the very function LinearPlant.step calls), and at
each of the four stages runs adaptive_mj.sim.stage.control_stage, the order of a control step that the Python
controller (adaptive_mj.sim.loop.Controller) runs too, compiled (as adaptive_mj.sim.native_step does for the
MuJoCo callbacks) with this module's pieces: `_law_stage` (measure y = C x (+ the step's noise), the stage
estimate, the law: laws.mrac.mrac_regressor and mrac_values, the same functions MracLaw calls; u clamped),
`_apply_control` (u handed back to the plant's stage) and `_record_row` (the step's row). loop.native_steps
drives it chunk by chunk like the MuJoCo callbacks (events, noise, divergence and rows between chunks), with
the plant's `step_native(n)` calling this controller's `advance`.

Before each chunk Python evaluates the reference at the stage times (reference.ModelResponse.scalar_rows: the
scalar calls' bits, vectorised; another reference is called once per distinct stage time as the Python path
calls it) and the input disturbance per step (force_offset + disturbance(t), LinearPlant.step's arithmetic).
Every product and sum is the Python path's, in its order: the dots of a few entries (C x, θ̂ᵀω, αᵀx_m) are
plain loops from 0 with no fused multiply-add, as the Python path sums them (form.plain_dot: numpy's dot is
BLAS's, which fuses on AVX-512); A x is numba's np.dot, the BLAS matrix-vector product
numpy's A @ x calls (`supported` checks on the run's A that the two agree, else the run takes the Python path).
tests/test_native_analytic.py shows the two paths give the same rows bit for bit.

The context record (CONTEXT: stage.control_stage's fields, then this shape's) holds the run's state and its
buffers' addresses; the compiled function is cached on disk (numba cache=True) under a key of every source it
compiles in (native_context.source_key).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from adaptive_mj.laws.mrac import MRAC_GAINS, mrac_regressor, mrac_values
from adaptive_mj.laws.protocol import Law
from adaptive_mj.plants.analytic import analytic_step
from adaptive_mj.plants.linear import linear_output, linear_params, linear_rate
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.sim import native_step
from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_context import ContextOwner, addr, inlined, source_key, unique_factory

if TYPE_CHECKING:
    from adaptive_mj.plants.linear import LinearPlant

    # injected into the compiled functions' globals; declared for the type checker only
    numba: Any
    carray: Any
    fptr: Any
    gains_ptr: Any
    control_stage: Any
    stage_estimate: Any

_i8, _f8 = np.int64, np.float64
#: this shape's context fields after native_step.STAGE_CONTEXT: the state's and law's sizes (n: the law's
#: order, 1), the clamp [lo, hi], the plant's input delay (in_delay steps) and step count (k), the buffers
#: (addresses): th, the stage estimate; ref (rows · stages, n+1); noise (rows, n); seen (n,), the measured
#: state; omega, dummy (n_theta,); s_hold (1,), the law's s held; the law's arrays; the row records
CONTEXT = native_step.context_dtype([
    ("n", _i8), ("lo", _f8), ("hi", _f8), ("in_delay", _i8), ("k", _i8),
    ("th", _i8), ("ref", _i8), ("noise", _i8), ("seen", _i8), ("omega", _i8), ("dummy", _i8), ("s_hold", _i8),
    ("gains", _i8), ("alpha", _i8), ("pb", _i8), ("gamma", _i8), ("inv_gamma", _i8), ("theta0", _i8),
    ("rec_t", _i8), ("rec_y", _i8), ("rec_u", _i8), ("rec_s", _i8), ("rec_ref", _i8), ("rec_theta", _i8),
])


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """This shape's law at a stage (stage.control_stage's law_stage): y of the stage (io[0]) + the step's noise,
    the stage estimate θ̂_i, MRAC on the stage's reference (laws.mrac.mrac_regressor, mrac_values: the Python
    path's MracLaw arithmetic), u clamped into [lo, hi] as Python's min(max(u, lo), hi) (a NaN passes) and held
    with -s (u_hold, s_hold), the rate into ctx.rate."""
    n, nth = ctx.n, ctx.nth
    g = carray(gains_ptr(ctx.gains), 1)[0]  # noqa: F821 (injected)
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)  # noqa: F821 (injected)
    r0 = (row * ctx.nstages + stage) * (n + 1)
    ref = carray(fptr(ctx.ref), r0 + n + 1)[r0:r0 + n + 1]  # noqa: F821 (injected)
    noise = carray(fptr(ctx.noise), (row + 1) * n)  # noqa: F821 (injected)
    seen = carray(fptr(ctx.seen), n)  # noqa: F821 (injected)
    y = io[0]
    seen[0] = y[0] + noise[row * n]
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)  # noqa: F821 (injected)
    omega = carray(fptr(ctx.omega), nth)  # noqa: F821 (injected)
    mrac_regressor(seen, ref, carray(fptr(ctx.alpha), n), g.beta, carray(fptr(ctx.dummy), 0), omega)  # noqa: F821
    u, s = mrac_values(seen, ref, th, omega, carray(fptr(ctx.dummy), nth), carray(fptr(ctx.pb), n),  # noqa: F821
                       carray(fptr(ctx.gamma), nth), carray(fptr(ctx.inv_gamma), nth), g.sign_b, False,  # noqa: F821
                       g.always, g.dz_width, g.dz_on_s, g.sigma, g.e_mod, carray(fptr(ctx.theta0), nth),  # noqa: F821
                       lower, upper, rate)
    hi, lo = ctx.hi, ctx.lo
    v = lo if lo > u else u
    carray(fptr(ctx.u_hold), 1)[0] = hi if hi < v else v  # noqa: F821 (injected)
    carray(fptr(ctx.s_hold), 1)[0] = -s  # noqa: F821 (injected)


def _apply_control(ctx, io, row, u):
    """This shape's "apply": u[0] handed back to the plant's stage (io[1])."""
    io[1][0] = u[0]


def _record_row(ctx, io, row, u, theta):
    """The step's row at stage 0: t, y = C x at the step's start (io[0], before noise), the applied u, the held s,
    the reference at t_k and θ̂ at the step's start."""
    n, nth = ctx.n, ctx.nth
    carray(fptr(ctx.rec_t), row + 1)[row] = ctx.t  # noqa: F821 (injected)
    carray(fptr(ctx.rec_y), row + 1)[row] = io[0][0]  # noqa: F821 (injected)
    carray(fptr(ctx.rec_u), row + 1)[row] = u[0]  # noqa: F821 (injected)
    carray(fptr(ctx.rec_s), row + 1)[row] = carray(fptr(ctx.s_hold), 1)[0]  # noqa: F821 (injected)
    r0 = row * ctx.nstages * (n + 1)
    ref = carray(fptr(ctx.ref), r0 + n + 1)  # noqa: F821 (injected)
    rec_ref = carray(fptr(ctx.rec_ref), (row + 1) * (n + 1))  # noqa: F821 (injected)
    for j in range(n + 1):
        rec_ref[row * (n + 1) + j] = ref[r0 + j]
    rec_th = carray(fptr(ctx.rec_theta), (row + 1) * nth)  # noqa: F821 (injected)
    for j in range(nth):
        rec_th[row * nth + j] = theta[j]


def _stage_control(ctx, io, stage):
    """plants.analytic.analytic_step's control, compiled: stage.control_stage (its context counts the stages), the
    control it hands back (io[1])."""
    control_stage(ctx, io)  # noqa: F821 (injected: stage.control_stage, compiled)
    return io[1][0]


def chunk_factory(key):
    """The chunk stepper's source, closed over the cache key only (native_context.unique_factory names it apart)."""

    @numba.njit(cache=True, nogil=True)  # noqa: F821 (injected)
    def callback(context, p, x, ring, dist, lo, hi, rows):
        """`rows` steps of the plant (plants.analytic.analytic_step with the linear plant's kernel, the step
        LinearPlant.step runs) from the context's state: p (A, B, C); x (n_x,) advanced in place; ring (D + 1,) the
        plant's delay line of stage-0 controls; dist (rows,) the input disturbance of each step; lo, hi the plant's
        ctrl_range (±inf: none)."""
        if key == 0:  # never: keeps the cache key in the closure
            return
        ctx = context[0]
        nx = x.shape[0]
        io = (np.zeros(1), np.zeros(1))
        xs, ks = np.empty(nx), np.empty((4, nx))
        for r in range(rows):
            analytic_step(p, x, dist[r], ctx.k, ctx.in_delay, ring, ctx.h, True, lo, hi, ctx, io, xs, ks)
            ctx.k = ctx.k + 1

    return callback


_compiled: dict = {}


def key_functions() -> tuple:
    """The functions compiled into the chunk stepper (and, through native_context.reached_functions, every function
    they call): the cache key hashes their modules' source, so an edit to any of them compiles afresh."""
    return (chunk_factory, stage_code.control_stage, native_step.view, _law_stage, _apply_control, _record_row,
            analytic_step, _stage_control, linear_rate, linear_output, mrac_regressor, mrac_values,
            stage_code.stage_estimate, stage_code.end_stage, stage_code.advance_estimates)


def compiled():
    """The chunk stepper, compiled (in memory per process, on disk across processes)."""
    if "linear_mrac" in _compiled:
        return _compiled["linear_mrac"]
    import numba
    from numba import carray, types

    from adaptive_mj.numba_util import jit_tree, pointer

    key = source_key(*key_functions(), extra=(numba.__version__, str(CONTEXT), str(MRAC_GAINS), "linear_mrac"))
    tag = f"_{key:x}"
    inline = inlined(numba)
    common: dict[str, Any] = {"carray": carray, "fptr": pointer(types.float64), "np": np,
                              "SAMPLED": stage_code.SAMPLED}
    common.update(native_step.stage_functions(numba, inline, tag))
    gains_ptr = pointer(numba.from_dtype(MRAC_GAINS))
    pieces: dict[str, Any] = {"law_stage": jit_tree(_law_stage, inline, tag=tag, gains_ptr=gains_ptr, **common),
                              "apply_control": jit_tree(_apply_control, inline, tag=tag, **common),
                              "record_row": jit_tree(_record_row, inline, tag=tag, **common)}
    step = jit_tree(stage_code.control_stage, inline, tag=tag,
                    view=jit_tree(native_step.view, inline, tag=tag, **common), **common, **pieces)
    one_step = jit_tree(analytic_step, inline, tag=tag, rate=jit_tree(linear_rate, inline, tag=tag),
                        observe=jit_tree(linear_output, inline, tag=tag),
                        control=jit_tree(_stage_control, inline, tag=tag, control_stage=step))
    g = {**chunk_factory.__globals__, **common, "numba": numba, "analytic_step": one_step}
    fn = unique_factory(chunk_factory, g, key)(key)
    _compiled["linear_mrac"] = fn
    return fn


def supported(plant: Plant, law: Law) -> bool:
    """The compiled analytic loop runs this plant and law: a LinearPlant of order n_x <= plants.linear.MAX_STATES
    with RK4 (4 stages) under MRAC with the Lyapunov rule and no ψ (MracLaw.compiled_form), on a machine where
    numba's matrix-vector product is numpy's (plants.linear.compiled_supports). Anything else (the MIT rule: its
    filter is Python's) takes the Python path."""
    from adaptive_mj.laws.mrac import MracLaw
    from adaptive_mj.plants.linear import LinearPlant

    return (isinstance(plant, LinearPlant) and isinstance(law, MracLaw) and law.compiled_form
            and law.order == 1 and plant.kernel.supports(plant))


class AnalyticLoop(ContextOwner):
    """What the compiled loops of the plants stepped without MuJoCo share (this module's, and the twin's:
    adaptive_mj.sim.native_twin): no MjData to bind, the plant's step_native(n) calls `advance(n)` (the
    `callback` loop._run_native hands the plant); the context record made from the run's sizes, limits and
    timing; the steps' external force as the plant's own step computes it; a chunk is prepare, advance, finish."""

    in_mujoco = False
    buffers: dict[str, np.ndarray]
    gains: np.ndarray  # the law's (1,) gains record, read by the compiled law through its address
    dist: np.ndarray  # (max_rows,) the external force of each step of a chunk
    lo: float  # the plant's control limits (±inf: none)
    hi: float

    def new_context(self, dtype: np.dtype, *, n: int, nth: int, nst: int, h: float,
                    control: stage_code.ControlTiming) -> np.ndarray:
        """The (1,) context record of `dtype`: stage.control_stage's fields (the tableau of nst stages, the run's
        timing, the law's sizes n and n_theta, one control), the clamp [lo, hi] (set as self.lo, self.hi), the
        gains' and every buffer's address."""
        inc, weights = stage_code.TABLEAU[nst]
        ctx = np.zeros(1, dtype=dtype)
        c = ctx[0]
        c["nstages"], c["n"], c["m"], c["nth"], c["h"], c["lo"], c["hi"] = nst, n, 1, nth, h, self.lo, self.hi
        c["delay"], c["mode"], c["period_steps"], c["period"] = control.delay, control.mode, control.steps, \
            control.period
        c["inc"][:len(inc)], c["weights"][:len(weights)] = inc, weights
        c["gains"] = self.gains.ctypes.data  # the law's record (kept alive by self.gains)
        for name, buf in self.buffers.items():
            c[name] = addr(buf)
        c["nbox"] = len(self.buffers["lower"])
        return ctx

    def forces(self, t: np.ndarray, rows: int) -> None:
        """self.dist[:rows]: the external force over each step starting at t (rows,) [s], as the plant's step
        computes it (force_offset + disturbance(t), or the offset + 0.0 without one: the same arithmetic)."""
        plant = self.plant
        if plant.disturbance is None:
            self.dist[:rows] = plant.force_offset + 0.0
        else:
            for k in range(rows):
                self.dist[k] = plant.force_offset + plant.disturbance(float(t[k]))

    def bind(self) -> None:
        """Nothing to bind: the plant has no MjData; its step_native calls `advance` (controlled_natively)."""
        return None

    def __exit__(self, *exc) -> None:
        return None

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps (the compiled chunk; prepare first)."""
        raise NotImplementedError

    def chunk(self, rows: int, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Step `rows` physics steps; return (t, x, u, s, ref, theta_hat) rows, each (rows, ...)."""
        self.prepare(rows, noise)
        self.advance(rows)
        return self.finish(rows)


class NativeAnalyticController(AnalyticLoop):
    """Owns the context and buffers of one compiled analytic run and steps its plant chunk by chunk: the plant's
    step_native(n) calls `advance(n)` (the `callback` it is given by loop._run_native).

    plant: a LinearPlant; law: a MracLaw `supported` accepts; reference: the law's reference; theta_hat0:
    (n_theta,); max_rows: the most steps a chunk takes; control: the run's ControlTiming."""

    plant: LinearPlant  # type: ignore[assignment]  # not a MuJoCo plant: no MjData to bind

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0, max_rows: int, *,
                 control: stage_code.ControlTiming | None = None):
        from adaptive_mj.laws.mrac import MracLaw
        from adaptive_mj.plants.linear import LinearPlant

        if not isinstance(plant, LinearPlant) or not isinstance(law, MracLaw):
            raise TypeError(f"the compiled analytic loop drives a LinearPlant under MRAC, got a "
                            f"{type(plant).__name__} and a {type(law).__name__}")
        self.plant, self.law, self.reference = plant, law, reference
        self.max_rows = int(max_rows)
        control = control if control is not None else stage_code.ControlTiming(period=plant.dt)
        self.callback = self.advance
        self._kernel = compiled()
        p = law.native_arrays()
        n, nth, nst = law.order, len(law.names), plant.stages
        self.n, self.nth, self.nst = n, nth, nst
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
        self.gains = p["gains"]
        if self.gains.dtype != MRAC_GAINS or self.gains.shape != (1,):
            raise TypeError(f"MracLaw.native_arrays()['gains'] must be a (1,) {MRAC_GAINS} record")
        self.buffers = {
            "theta": f64(np.array(theta_hat0, dtype=float).reshape(nth)), "rsum": np.zeros(nth), "prev": np.zeros(nth),
            "rate": np.zeros(nth), "th": np.zeros(nth), "lower": f64(p["lower"]), "upper": f64(p["upper"]),
            "u_hold": np.zeros(1), "delayed": np.zeros(1), "ring": np.zeros((control.delay + 1, 1)),
            "ref": np.zeros(max_rows * nst * (n + 1)), "noise": np.zeros(max_rows * n), "seen": np.zeros(n),
            "omega": np.zeros(nth), "dummy": np.zeros(nth), "s_hold": np.zeros(1),
            "alpha": f64(p["alpha"]), "pb": f64(p["pb"]), "gamma": f64(p["gamma"]), "inv_gamma": f64(p["inv_gamma"]),
            "theta0": f64(p["theta0"]),
            "rec_t": np.zeros(max_rows), "rec_y": np.zeros(max_rows), "rec_u": np.zeros(max_rows),
            "rec_s": np.zeros(max_rows), "rec_ref": np.zeros(max_rows * (n + 1)), "rec_theta": np.zeros(max_rows * nth),
        }
        self.theta = self.buffers["theta"]
        self.lo, self.hi = plant.ctrl_range if plant.ctrl_range is not None else (-math.inf, math.inf)
        self.lo, self.hi = float(self.lo), float(self.hi)
        self.stage_offsets = np.asarray(stage_code.TABLEAU[nst][0])  # RK4: c_i = a_i (see stage.TABLEAU)
        self.dist = np.zeros(max_rows)
        self.context = self.new_context(CONTEXT, n=n, nth=nth, nst=nst, h=plant.dt, control=control)
        self.context[0]["in_delay"] = plant.delay_steps

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """The references at every stage time of the next `rows` steps, the steps' noise and disturbance, and the
        context set to the plant's time."""
        plant, n, h = self.plant, self.n, self.plant.dt
        t = stage_code.step_times(plant.time, h, rows)
        times, which = stage_code.distinct_times((t[:, None] + h * self.stage_offsets[None, :]).ravel())
        scalar_rows = getattr(self.reference, "scalar_rows", None)
        if scalar_rows is not None:  # the scalar calls' bits, vectorised (reference.ModelResponse)
            values = np.asarray(scalar_rows(times, n))
        else:  # another reference: called as the Python path calls it, once per distinct time
            values = np.stack([np.asarray(self.reference(float(s), n), dtype=float) for s in times], axis=1)
        self.buffers["ref"][: rows * self.nst * (n + 1)] = np.moveaxis(values, 1, 0)[which].ravel()
        self.buffers["noise"][: rows * n] = 0.0 if noise is None else noise.ravel()
        self.forces(t, rows)  # LinearPlant.step's force
        c = self.context[0]
        c["stage"], c["row"], c["rows"], c["t"], c["k"] = 0, 0, rows, t[0], plant._k

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps (the compiled chunk; prepare first) and leave its state, time and
        step count where LinearPlant.step would."""
        plant = self.plant
        plant.x = np.ascontiguousarray(plant.x, dtype=np.float64)
        self._kernel(self.context, linear_params(plant), plant.x, plant._ring, self.dist, self.lo, self.hi, rows)
        c = self.context[0]
        plant._t, plant._k = float(c["t"]), int(c["k"])

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """The rows recorded over the `rows` steps just taken: t (rows,) [s], x (rows, 1) y at each step's start,
        u (rows,) applied, s (rows,), ref (rows, n+1), theta_hat (rows, n_theta) at each step's start."""
        c, n, b = self.context[0], self.n, self.buffers
        if not partial and (int(c["row"]) != rows or int(c["stage"]) != 0):
            raise RuntimeError(f"the compiled analytic loop ran {int(c['row'])} steps (stage {int(c['stage'])}), "
                               f"expected {rows}")
        return (b["rec_t"][:rows].copy(), b["rec_y"][:rows].reshape(rows, 1).copy(), b["rec_u"][:rows].copy(),
                b["rec_s"][:rows].copy(), b["rec_ref"][: rows * (n + 1)].reshape(rows, n + 1).copy(),
                b["rec_theta"][: rows * self.nth].reshape(rows, self.nth).copy())


#: what loop._native_controller takes of a compiled loop's module (plants.twin.PythonStepped.compiled_loop)
Controller = NativeAnalyticController

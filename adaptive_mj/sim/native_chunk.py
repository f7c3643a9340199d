"""The analytic chunk engine: the compiled closed loop of every plant stepped without MuJoCo
(plants.analytic.AnalyticPlant: the linear plant, plants.linear; the analytic twin, plants.twin; a plant plugin's
or a new kind's analytic plant), built from the kernel its kind declares beside its code
(plants.analytic.AnalyticKernel: its parameters, rate, observation and the functions they call) and the law's
compiled form.

There is no mj_step to call a control callback: one numba function (`chunk_factory`'s) steps a whole chunk of
physics steps, each one plants.analytic.analytic_step, the step the Python path (AnalyticPlant.step) runs too,
compiled with the kind's rate and observation and, as its control at each stage, adaptive_mj.sim.stage
.control_stage (the order of a control step, the one the Python controller, loop.Controller, runs) with this
module's pieces: `_law_stage` (the observation + the step's noise, the stage estimate, the law, u clamped and held
with s), `_apply_control` (u handed back to the step) and `_record_row` (the step's row, in the record layout of
plants.mujoco_kernel.record_columns, the one row layout of every compiled loop: one writer here, one reader,
sim.native_step.recorded_rows). loop.native_steps drives it
chunk by chunk like the MuJoCo callbacks (events, noise, divergence and rows between chunks), the plant's
step_native(n) calling this controller's `advance`.

The law it compiles is the one the law object declares beside its kind (laws.protocol.Law.chunk_kernel: a
laws.kernel.LawKernel, found by declaration, with no list of law classes here): its kernel, with one signature
law(x, r, θ̂_i, gains, arrays, lower, upper, rate) -> (u, s) (`law_kernel`: its gains record passed as a record, its
arrays end to end in one buffer), bound per variant with the law form's φ, f, h and a law function in the plugin
form (laws.kernel's placeholders). The built-in ones: MRAC with the Lyapunov rule (laws.mrac.mrac_kernel; with
matched terms ψ, mrac_psi_kernel, ψ bound as psi_fn), the lecture's first-order law
(laws.first_order.first_order_kernel), the sliding laws (laws.sliding.sliding_kernel) and a law function in the
plugin form, a plugin's or a built-in kind's (laws.plugin.plugin_kernel: PluginLaw, KernelLaw), each the
arithmetic its Python law calls; a law that declares none (the MIT rule, composite
adaptation, a law in plain Python) takes the Python path. The law's form (φ, f, h of the model it is
designed on) and the plant's (what the twin integrates) are compiled apart.

Before each chunk Python evaluates the reference at the stage times (a reference with `scalar_rows`,
reference.ModelResponse: its scalar calls' bits, vectorised; any other: stage.stage_references, vectorised) and
the external force per step (force_offset + disturbance(t), AnalyticPlant.step_force's arithmetic). The context
record (CONTEXT: stage.control_stage's fields, then this engine's) holds the run's state and its buffers'
addresses (read as arrays through native_step.view: views without a reference count, which arrays carried in a
tuple through the inlined pieces would pay at every access, 3-5x the chunk's time per step); the compiled
function is cached on disk (numba cache=True) under a key of every source it compiles in (native_context
.source_key). tests/test_native_analytic.py, tests/test_native_twin.py and
tests/test_analytic_kernel.py (a kind declared in the test alone) show both paths give the same rows bit for bit.
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from adaptive_mj.laws.kernel import LawKernel, f64
from adaptive_mj.laws.protocol import Law
from adaptive_mj.plants import plant_order
from adaptive_mj.plants.analytic import AnalyticKernel, AnalyticPlant, analytic_step, clamp
from adaptive_mj.plants.mujoco_kernel import RowShapes, gains_record, record_columns
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.sim import native_step
from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_context import ContextOwner, addr, inlined, source_key, unique_factory
from adaptive_mj.sim.native_step import recorded_rows, view
from adaptive_mj.sim.stage import control_stage, stage_estimate

_i8, _f8 = np.int64, np.float64
#: the engine's context fields after native_step.STAGE_CONTEXT: the law's order n (the observation's length), the
#: plant's control limits [lo, hi] (±inf: none), its input delay (in_delay whole steps); the buffers (addresses:
#: read through native_step.view, no reference counts in the loop): ref (rows · stages, n+1) the references, noise
#: (rows, n), seen (n,) the measured state, th (n_theta,) the stage estimate, s_hold (1,) the law's s held, rec
#: (rows, record_columns' width) the rows, law (nlaw,) the law's arrays end to end (law_of)
CONTEXT = native_step.context_dtype([
    ("n", _i8), ("lo", _f8), ("hi", _f8), ("in_delay", _i8),
    ("ref", _i8), ("noise", _i8), ("seen", _i8), ("th", _i8), ("s_hold", _i8), ("rec", _i8), ("law", _i8),
    ("nlaw", _i8),
])


# --- the pieces of stage.control_stage, and the control of analytic_step --------------------------------------
def law_kernel(x, r, th, g, a, lower, upper, rate):
    # x (n,) the measured state, r (n+1,) the reference, th (n_theta,) the stage estimate, g the gains record, a the
    # law's arrays end to end (nlaw,), lower, upper the box, rate (n_theta,) out: returns (u, s)
    """The law at a stage (bound per variant: the kernel the law declares, laws.kernel.LawKernel.fn)."""
    raise NotImplementedError("the chunk engine binds the law's kernel (native_chunk.compiled)")


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """The law at a stage (stage.control_stage's law_stage): the stage's observation io[0] + the step's noise, the
    stage estimate θ̂_i, the law on the stage's reference (its gains record io[2]), u clamped into [lo, hi] as
    Python's min(max(u, lo), hi) and held with s (u_hold, s_hold), the rate into ctx.rate."""
    y = io[0]
    n, nth = ctx.n, ctx.nth
    r0 = (row * ctx.nstages + stage) * (n + 1)
    r = view(ctx.ref, r0 + n + 1)[r0:r0 + n + 1]
    noise, seen, th = view(ctx.noise, (row + 1) * n), view(ctx.seen, n), view(ctx.th, nth)
    for i in range(n):
        seen[i] = y[i] + noise[row * n + i]
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)
    u, s = law_kernel(seen, r, th, io[2], view(ctx.law, ctx.nlaw), lower, upper, view(ctx.rate, nth))
    view(ctx.u_hold, 1)[0] = clamp(u, ctx.lo, ctx.hi)
    view(ctx.s_hold, 1)[0] = s


def _apply_control(ctx, io, row, u):
    """The "apply": u[0] handed back to the step's stage (io[1])."""
    io[1][0] = u[0]


def _record_row(ctx, io, row, u, theta):
    """The step's row at stage 0 in the record buffer's named columns (plants.mujoco_kernel.record_columns): t, the
    observation at the step's start (io[0], before noise), the applied u, the held s, the reference at t_k and θ̂ at
    the step's start."""
    n, nth = ctx.n, ctx.nth
    col = record_columns(n, nth)
    rec = view(ctx.rec, (row + 1) * col.width)
    r0 = row * ctx.nstages * (n + 1)
    ref = view(ctx.ref, r0 + n + 1)
    o = row * col.width
    rec[o + col.t] = ctx.t
    for i in range(n):
        rec[o + col.x + i] = io[0][i]
    rec[o + col.u] = u[0]
    rec[o + col.s] = view(ctx.s_hold, 1)[0]
    for i in range(n + 1):
        rec[o + col.ref + i] = ref[r0 + i]
    for j in range(nth):
        rec[o + col.theta + j] = theta[j]


def _stage_control(ctx, io, stage):
    """analytic_step's control, compiled: stage.control_stage (its context counts the stages), the control it
    hands back."""
    control_stage(ctx, io)
    return io[1][0]


# --- the law -----------------------------------------------------------------------------------------------------
def law_of(law: Law, plant: Plant) -> LawKernel | None:
    """The compiled form of `law` on `plant`, as the law declares it beside its kind (laws.protocol.Law
    .chunk_kernel: a laws.kernel.LawKernel, or None for the Python path), on the plant's order."""
    return law.chunk_kernel(plant_order(plant))


def supported(plant: Plant, law: Law) -> bool:
    """The engine runs this plant and law: an AnalyticPlant whose kind's kernel supports it
    (AnalyticKernel.supports) under a law it compiles (law_of)."""
    return isinstance(plant, AnalyticPlant) and plant.kernel.supports(plant) and law_of(law, plant) is not None


# --- the compiled chunk -----------------------------------------------------------------------------------------
def chunk_factory(njit, key):
    """The chunk stepper's source, closed over the cache key only (native_context.unique_factory names it,
    `callback`, apart per variant: every variant of one kind and law has the same argument types)."""

    @njit(cache=True, nogil=True)
    def callback(context, p, x, ring, dist, k0, gains, rows):
        """`rows` analytic steps of the plant from the context's state: x (n_x,) advanced in place; p the kind's
        params; ring (D + 1,) the plant's delay line; dist (rows,) the external force of each step; k0 the plant's
        step count; gains the law's (1,) gains record."""
        if key == 0:  # never: keeps the cache key in the closure
            return
        ctx = context[0]
        nx = x.shape[0]
        io = (np.zeros(ctx.n), np.zeros(1), gains[0])
        xs, ks = np.empty(nx), np.empty((4, nx))
        rk4 = ctx.nstages == 4
        for r in range(rows):
            analytic_step(p, x, dist[r], k0 + r, ctx.in_delay, ring, ctx.h, rk4, ctx.lo, ctx.hi, ctx, io, xs, ks)

    return callback


_compiled: dict = {}


def key_functions(*law_fns: Callable) -> tuple:
    """The functions compiled into a variant (and, through native_context.reached_functions, every function they
    call): the engine's own and `law_fns`, the law's kernel (LawKernel.fn: its module and what it calls, however
    deep); the cache key hashes their modules' source, so an edit to any of them compiles afresh."""
    return (chunk_factory, analytic_step, _stage_control, control_stage, view, _law_stage, _apply_control,
            _record_row, record_columns, stage_code.end_stage, stage_code.advance_estimates, *law_fns)


def _code(fn: Callable) -> tuple:
    return fn.__code__, tuple(c.cell_contents for c in (fn.__closure__ or ()))


def compiled(kernel: AnalyticKernel, functions: dict[str, Callable], lk: LawKernel):
    """The chunk stepper for one kind's kernel (with its per-plant `functions`) and one law (in memory per process,
    on disk across processes)."""
    law_fns = (lk.form.phi, lk.form.f, lk.form.h) if lk.form is not None else ()
    fns = (kernel.rate, kernel.observe, *functions.values(), *law_fns, *((lk.user_law,) if lk.user_law else ()),
           *((lk.psi,) if lk.psi else ()))
    mem_key = (kernel.name, lk.fn.__name__, tuple(functions)) + tuple(_code(fn) for fn in (*fns, lk.fn))
    if mem_key in _compiled:
        return _compiled[mem_key]
    import numba
    from numba import carray, types

    from adaptive_mj.numba_util import jit_tree, pointer

    key = source_key(*fns, *key_functions(lk.fn), extra=(numba.__version__, str(CONTEXT), str(lk.dtype), kernel.name,
                                                     lk.fn.__name__, tuple(functions)))
    tag = f"_{key:x}"
    inline = inlined(numba)
    common: dict[str, Any] = {"carray": carray, "fptr": pointer(types.float64), "np": np,
                              "SAMPLED": stage_code.SAMPLED}
    common.update(native_step.stage_functions(numba, inline, tag))
    seen: dict = {}  # one compiled function per Python function in this variant
    compiled_view = jit_tree(view, inline, tag=tag, seen=seen, **common)
    forms: dict[str, Any] = {}
    if lk.form is not None:
        forms = {name: jit_tree(fn, inline, tag=tag)
                 for name, fn in zip(("phi_fn", "f_fn", "h_fn"), law_fns, strict=True)}
    if lk.user_law is not None:
        forms["user_law"] = jit_tree(lk.user_law, inline, tag=tag)
    if lk.psi is not None:
        forms["psi_fn"] = jit_tree(lk.psi, inline, tag=tag)
    law = jit_tree(lk.fn, inline, tag=tag, **forms)
    pieces: dict[str, Any] = {
        "law_stage": jit_tree(_law_stage, inline, tag=tag, seen=seen, law_kernel=law, view=compiled_view, **common),
        "apply_control": jit_tree(_apply_control, inline, tag=tag, seen=seen),
        "record_row": jit_tree(_record_row, inline, tag=tag, seen=seen)}
    step = jit_tree(control_stage, inline, tag=tag, seen=seen, view=compiled_view, **common, **pieces)
    plant_fns: dict[str, Any] = {name: jit_tree(fn, inline, tag=tag + "p") for name, fn in functions.items()}
    one_step = jit_tree(analytic_step, inline, tag=tag, seen=seen,
                        rate=jit_tree(kernel.rate, inline, tag=tag + "p", **plant_fns),
                        observe=jit_tree(kernel.observe, inline, tag=tag + "p"),
                        control=jit_tree(_stage_control, inline, tag=tag, control_stage=step))
    g = {**chunk_factory.__globals__, "np": np, "analytic_step": one_step}
    from adaptive_mj.sim.compile_note import announcing

    what, kind = _described(kernel, lk)
    njit = announcing(numba, what, kind=kind, variant=f"{key:x}").njit  # says a compile that misses the cache
    fn = unique_factory(chunk_factory, g, key)(njit, key)
    _compiled[mem_key] = fn
    return fn


def _described(kernel: AnalyticKernel, lk: LawKernel) -> tuple[str, str]:
    """What a compile note calls this variant, and its kind (compile_note.TYPICAL_CPU's key)."""
    law = lk.what or f"{lk.fn.__module__}.{lk.fn.__qualname__}"
    if lk.form is None:
        return f"the {kernel.name} plant's chunk stepper ({law})", "linear MRAC chunk"
    form = lk.form
    return (f"the {kernel.name} plant's chunk stepper (a plant form of order {form.order}, theta = "
            f"{', '.join(form.names)}; {law})", "twin chunk")


class ChunkController(ContextOwner):
    """Owns the context and buffers of one compiled analytic run and steps its plant chunk by chunk: the plant's
    step_native(n) calls `advance(n)` (the `callback` loop._run_native hands the plant); a chunk is prepare,
    advance, finish.

    plant: an AnalyticPlant; law: one `supported` accepts; reference: the law's reference; theta_hat0:
    (n_theta,); max_rows: the most steps a chunk takes; control: the run's ControlTiming."""

    plant: AnalyticPlant  # type: ignore[assignment]  # not a MuJoCo plant: no MjData to bind
    in_mujoco = False

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0, max_rows: int, *,
                 control: stage_code.ControlTiming | None = None):
        lk = law_of(law, plant) if isinstance(plant, AnalyticPlant) else None
        if not isinstance(plant, AnalyticPlant) or lk is None:
            raise TypeError(f"the analytic chunk engine drives an AnalyticPlant under a law it compiles, got a "
                            f"{type(plant).__name__} and a {type(law).__name__}")
        self.plant, self.law, self.reference = plant, law, reference
        self.max_rows = int(max_rows)
        control = control if control is not None else stage_code.ControlTiming(period=plant.dt)
        self.callback = self.advance
        kernel = plant.kernel
        self.kernel = kernel
        self._chunk = compiled(kernel, kernel.functions(plant), lk)
        n, nth, nst = plant_order(plant), len(law.names), plant.stages
        self.n, self.nth, self.nst = n, nth, nst
        self.columns = record_columns(n, nth)
        self.shapes = RowShapes((n,), (), (), (n + 1,), nth)
        self.gains = gains_record(lk.gains, lk.dtype)
        self.buffers = {
            "theta": f64(np.array(theta_hat0, dtype=float).reshape(nth)), "rsum": np.zeros(nth),
            "prev": np.zeros(nth), "rate": np.zeros(nth), "lower": lk.lower, "upper": lk.upper,
            "u_hold": np.zeros(1), "delayed": np.zeros(1), "ring": np.zeros((control.delay + 1, 1)),
            "ref": np.zeros(max_rows * nst * (n + 1)), "noise": np.zeros(max_rows * n), "seen": np.zeros(n),
            "th": np.zeros(nth), "s_hold": np.zeros(1), "rec": np.zeros(max_rows * self.columns.width),
            "law": lk.arrays}
        self.theta = self.buffers["theta"]
        self.stage_offsets = np.asarray(stage_code.TABLEAU[nst][0])  # RK4: c_i = a_i (see stage.TABLEAU)
        self.dist = np.zeros(max_rows)
        inc, weights = stage_code.TABLEAU[nst]
        ctx = np.zeros(1, dtype=CONTEXT)
        c = ctx[0]
        c["nstages"], c["n"], c["m"], c["nth"], c["h"], c["in_delay"] = nst, n, 1, nth, plant.dt, plant.delay_steps
        c["lo"], c["hi"] = plant.limits()
        c["delay"], c["mode"], c["period_steps"], c["period"] = control.delay, control.mode, control.steps, \
            control.period
        c["inc"][:len(inc)], c["weights"][:len(weights)] = inc, weights
        for name, buf in self.buffers.items():
            c[name] = addr(buf)
        c["nbox"], c["nlaw"] = len(lk.lower), len(lk.arrays)
        self.context = ctx

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """The references at every stage time of the next `rows` steps, the steps' noise and external force, and
        the context set to the plant's time."""
        plant, n, h = self.plant, self.n, self.plant.dt
        scalar_rows = getattr(self.reference, "scalar_rows", None)
        if scalar_rows is not None:  # the scalar calls' bits, vectorised (reference.ModelResponse)
            t = stage_code.step_times(plant.time, h, rows)
            times, which = stage_code.distinct_times((t[:, None] + h * self.stage_offsets[None, :]).ravel())
            refs = np.moveaxis(np.asarray(scalar_rows(times, n)), 1, 0)[which]
        else:
            t, refs = stage_code.stage_references(self.reference, plant.time, h, rows, self.stage_offsets, n)
        self.buffers["ref"][: rows * self.nst * (n + 1)] = refs.ravel()
        self.buffers["noise"][: rows * n] = 0.0 if noise is None else noise.ravel()
        if plant.disturbance is None:  # AnalyticPlant.step_force's arithmetic (the offset + 0.0 without one)
            self.dist[:rows] = plant.force_offset + 0.0
        else:
            for k in range(rows):
                self.dist[k] = plant.force_offset + plant.disturbance(float(t[k]))
        c = self.context[0]
        c["stage"], c["row"], c["rows"], c["t"] = 0, 0, rows, t[0]

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps (the compiled chunk; prepare first) and leave its state, time and
        step count where AnalyticPlant.step would."""
        plant = self.plant
        plant.x = np.ascontiguousarray(plant.x, dtype=np.float64)
        self._chunk(self.context, self.kernel.params(plant), plant.x, plant._ring, self.dist, plant._k, self.gains,
                    rows)
        plant.moved_to(float(self.context[0]["t"]), rows)

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """The rows recorded over the `rows` steps just taken: t (rows,) [s], x (rows, n) the observation at each
        step's start, u (rows,) applied, s (rows,), ref (rows, n+1), theta_hat (rows, n_theta) at each step's
        start."""
        return recorded_rows(self.context[0], self.buffers["rec"], self.columns, self.shapes, rows, partial,
                             f"the analytic chunk engine ({self.kernel.name})")

    def chunk(self, rows: int, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Step `rows` physics steps; return (t, x, u, s, ref, theta_hat) rows, each (rows, ...)."""
        self.prepare(rows, noise)
        self.advance(rows)
        return self.finish(rows)

    def bind(self) -> None:
        """Nothing to bind: the plant has no MjData; its step_native calls `advance` (controlled_natively)."""
        return None

    def __exit__(self, *exc) -> None:
        return None


#: the compiled loop's controller, as adaptive_mj.sim.loop dispatches to it (protocol.Plant.compiled_loop)
Controller = ChunkController

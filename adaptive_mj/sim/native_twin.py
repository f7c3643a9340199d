"""The compiled closed loop of the analytic twin (adaptive_mj.plants.twin.TwinPlant): d y^(n) = f + φ p + h u
integrated without MuJoCo under the lecture's first-order law (laws.first_order), a sliding law (laws.sliding) or a
law plugin (laws.plugin).

There is no mj_step to call a control callback: one numba function (`chunk_factory`'s) steps a whole chunk of
physics steps, each plants.analytic.analytic_step with the twin's kernel (plants.twin: its classic RK4 or its
semi-implicit Euler, the very function TwinPlant.step calls), and at
each stage runs adaptive_mj.sim.stage.control_stage, the order of a control step that the Python controller
(adaptive_mj.sim.loop.Controller) runs too, compiled (as adaptive_mj.sim.native_step does for the MuJoCo
callbacks) with this module's pieces: `_law_stage` (measure the stage's x + the step's noise, the stage estimate,
the law on the law's ModelForm, u clamped), `_apply_control` (u handed back to the plant's stage) and
`_record_row` (the step's row). loop.native_steps drives it chunk by chunk like the MuJoCo callbacks (events,
noise, divergence and rows between chunks), the plant's step_native(n) calling this controller's `advance`.

The law's form and the plant's form are compiled apart (a law may be designed on another model than the twin
integrates): the law's φ, f, h into the law (the names native._builtin_law and native._plugin_law call), the
plant's into plants.twin.twin_rate, ModelForm.highest_derivative's arithmetic in its order (φ·p summed from 0 with
no fused multiply-add, as form.plain_dot sums it). The references at the stage times are evaluated in Python before
each chunk, vectorised (stage.stage_references: TwinPlant.step's stage times t + h/2, t + h are the same numbers),
and so are the steps' external forces (force_offset + disturbance(t), TwinPlant.step's arithmetic).
tests/test_native_twin.py shows the two paths give the same rows bit for bit.

The context record (CONTEXT: stage.control_stage's fields, then this shape's) holds the run's state and its
buffers' addresses; the compiled function is cached on disk (numba cache=True) under a key of every source it
compiles in (native_context.source_key).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from adaptive_mj.laws.common import plugin_rate
from adaptive_mj.laws.first_order import FIRST_ORDER_GAINS, first_order_values
from adaptive_mj.laws.plugin import PLUGIN_GAINS
from adaptive_mj.laws.protocol import Law
from adaptive_mj.laws.sliding import SLIDING_GAINS, sliding_law_values
from adaptive_mj.plants.analytic import analytic_step, clamp
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.plants.twin import twin_params, twin_rate, twin_state
from adaptive_mj.sim import native, native_step
from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_analytic import AnalyticLoop
from adaptive_mj.sim.native_context import inlined, source_key, unique_factory

if TYPE_CHECKING:
    from adaptive_mj.plants.twin import TwinPlant

    # injected into the compiled functions' globals; declared for the type checker only
    numba: Any
    carray: Any
    fptr: Any
    gains_ptr: Any
    law: Any
    phi_fn: Any
    f_fn: Any
    h_fn: Any
    control_stage: Any
    stage_estimate: Any
    record_columns: Any

_i8, _f8 = np.int64, np.float64
#: this shape's context fields after native_step.STAGE_CONTEXT: the order n, the clamp [lo, hi], the law's gains
#: record (address); the buffers (addresses): ref (rows · stages, n+1), noise (rows, n), xbuf (n,) the measured
#: state, the law's arrays (coeffs (n,), gamma, theta0 (n_theta,), params: a plugin's), s_hold (1,) the law's s
#: held, rec (rows, native.record_columns' width) the rows
CONTEXT = native_step.context_dtype([
    ("n", _i8), ("lo", _f8), ("hi", _f8), ("gains", _i8),
    ("th", _i8), ("ref", _i8), ("noise", _i8), ("xbuf", _i8), ("coeffs", _i8), ("gamma", _i8), ("theta0", _i8),
    ("params", _i8),
    ("s_hold", _i8), ("rec", _i8),
])

#: the law variants: the lecture's first-order law, a sliding law (SLIDING_GAINS), a law plugin (PLUGIN_GAINS)
FIRST_ORDER, SLIDING, PLUGIN = "first_order", "sliding", "plugin"


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """This shape's law at a stage (stage.control_stage's law_stage): the stage's state io[0] + the step's noise,
    the stage estimate θ̂_i, the law on the stage's reference, u clamped into [lo, hi] as Python's
    min(max(u, lo), hi) and held with s (u_hold, s_hold), the rate into ctx.rate."""
    n, nth = ctx.n, ctx.nth
    xs = io[0]
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)  # noqa: F821 (injected)
    r0 = (row * ctx.nstages + stage) * (n + 1)
    r = carray(fptr(ctx.ref), r0 + n + 1)[r0:r0 + n + 1]  # noqa: F821 (injected)
    noise = carray(fptr(ctx.noise), (row + 1) * n)  # noqa: F821 (injected)
    x = carray(fptr(ctx.xbuf), n)  # noqa: F821 (injected)
    for i in range(n):
        x[i] = xs[i] + noise[row * n + i]
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)  # noqa: F821 (injected)
    u, s = law(x, r, th, ctx, carray(fptr(ctx.coeffs), n), carray(fptr(ctx.gamma), nth),  # noqa: F821 (injected)
               carray(fptr(ctx.theta0), nth), lower, upper, carray(fptr(ctx.params), 1 << 30), rate)  # noqa: F821,E501 (injected globals; one carray per line)
    carray(fptr(ctx.u_hold), 1)[0] = clamp(u, ctx.lo, ctx.hi)  # noqa: F821 (injected)
    carray(fptr(ctx.s_hold), 1)[0] = s  # noqa: F821 (injected)


def _first_order_law(x, r, th, ctx, coeffs, gamma, theta0, lower, upper, params, rate):
    """laws.first_order.first_order_values with the law's scalars read by name from its FIRST_ORDER_GAINS record
    (at the context's `gains` address) and the law's form evaluated here (phi_fn, f_fn, h_fn: globals)."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]  # noqa: F821 (injected)
    u, s = first_order_values(x, r, th, gains, gamma, theta0, lower, upper, phi_fn(x), f_fn(x), h_fn(x),  # noqa: F821
                              rate)
    return u, s


def _apply_control(ctx, io, row, u):
    """This shape's "apply": u[0] handed back to the plant's stage (io[1])."""
    io[1][0] = u[0]


def _record_row(ctx, io, row, u, theta):
    """The step's row at stage 0 in the record buffer's named columns (native.record_columns): t, the true state
    at the step's start (io[0] at stage 0, before noise), the applied u, the held s, the reference at t_k and θ̂
    at the step's start."""
    n, nth = ctx.n, ctx.nth
    col = record_columns(n, nth)  # noqa: F821 (injected)
    rec = carray(fptr(ctx.rec), (row + 1) * col.width)  # noqa: F821 (injected)
    r0 = row * ctx.nstages * (n + 1)
    r = carray(fptr(ctx.ref), r0 + n + 1)  # noqa: F821 (injected)
    o = row * col.width
    rec[o + col.t] = ctx.t
    for i in range(n):
        rec[o + col.x + i] = io[0][i]
    rec[o + col.u] = u[0]
    rec[o + col.s] = carray(fptr(ctx.s_hold), 1)[0]  # noqa: F821 (injected)
    for i in range(n + 1):
        rec[o + col.ref + i] = r[r0 + i]
    for j in range(nth):
        rec[o + col.theta + j] = theta[j]


def _stage_control(ctx, io, stage):
    """plants.analytic.analytic_step's control, compiled: stage.control_stage (its context counts the stages), the
    control it hands back (io[1])."""
    control_stage(ctx, io)  # noqa: F821 (injected: stage.control_stage, compiled)
    return io[1][0]


def chunk_factory(key):
    """The chunk stepper's source, closed over the cache key only (native_context.unique_factory names it, `callback`,
    apart per variant: every variant has the same argument types, so without the key in its name two variants
    compiled in two processes could define one symbol)."""

    @numba.njit(cache=True, nogil=True)  # noqa: F821 (injected)
    def callback(context, p, x, dist, lo, hi, rows):
        """`rows` steps of the twin (plants.analytic.analytic_step with the twin's kernel, the step TwinPlant.step
        runs) from the context's state: p (θ, d_known) the plant's twin_params; x (n,) advanced in place; dist
        (rows,) the external force of each step; lo, hi the plant's ctrl_range (±inf: none). RK4 with 4 stages,
        else semi-implicit Euler."""
        if key == 0:  # never: keeps the cache key in the closure
            return
        ctx = context[0]
        n = x.shape[0]
        io = (np.zeros(n), np.zeros(1))
        xs, ks, ring = np.empty(n), np.empty((4, n)), np.zeros(1)
        rk4 = ctx.nstages == 4
        for r in range(rows):
            analytic_step(p, x, dist[r], 0, 0, ring, ctx.h, rk4, lo, hi, ctx, io, xs, ks)

    return callback


_compiled: dict = {}


def key_functions() -> tuple:
    """The functions compiled into every variant of the chunk stepper (and, through native_context.reached_functions,
    every function they call): the cache key hashes their modules' source, so an edit to any of them compiles
    afresh."""
    return (chunk_factory, stage_code.control_stage, native_step.view, _law_stage, _first_order_law, _apply_control,
            _record_row, analytic_step, _stage_control, twin_rate, twin_state, clamp, native.record_columns,
            native._builtin_law, native._plugin_law,
            first_order_values, sliding_law_values, plugin_rate, stage_code.stage_estimate, stage_code.end_stage,
            stage_code.advance_estimates)


def _law_variant(law: Law) -> str | None:
    """FIRST_ORDER, SLIDING or PLUGIN: the variant that runs `law`, or None (composite adaptation, MRAC, any other
    law: the Python path)."""
    from adaptive_mj.laws.first_order import FirstOrderAdaptiveLaw

    if isinstance(law, FirstOrderAdaptiveLaw):
        return FIRST_ORDER
    if not law.native or getattr(law, "form", None) is None:
        return None
    p = law.native_params()
    if p.get("composite") is not None:
        return None
    return PLUGIN if p.get("plugin_law") is not None else SLIDING


def _form_functions(form) -> tuple:
    return (form.phi, form.f, form.h)


def compiled(law_form, plant_form, variant: str, plugin=None):
    """The chunk stepper for one law form, plant form and law variant (in memory per process, on disk across
    processes). plugin: a law plugin's function (the PLUGIN variant)."""
    fns = _form_functions(law_form) + _form_functions(plant_form) + ((plugin,) if plugin is not None else ())
    mem_key = (variant,) + tuple((fn.__code__, tuple(c.cell_contents for c in (fn.__closure__ or ())))
                                 for fn in fns)
    if mem_key in _compiled:
        return _compiled[mem_key]
    import numba
    from numba import carray, types

    from adaptive_mj.numba_util import jit_tree, pointer

    key = source_key(*fns, *key_functions(),
                     extra=(numba.__version__, str(CONTEXT), str(SLIDING_GAINS), str(PLUGIN_GAINS),
                            str(FIRST_ORDER_GAINS), "twin", variant))
    tag = f"_{key:x}"
    inline = inlined(numba)
    common: dict[str, Any] = {"carray": carray, "fptr": pointer(types.float64), "np": np,
                              "SAMPLED": stage_code.SAMPLED}
    common.update(native_step.stage_functions(numba, inline, tag))
    forms: dict[str, Any] = {name: jit_tree(fn, inline, tag=tag)
                             for name, fn in zip(("phi_fn", "f_fn", "h_fn"), _form_functions(law_form), strict=True)}
    plant_fns: dict[str, Any] = {name: jit_tree(fn, inline, tag=tag + "p")
                                 for name, fn in zip(("plant_phi", "plant_f", "plant_h"), _form_functions(plant_form),
                                                      strict=True)}
    if variant == FIRST_ORDER:
        law = jit_tree(_first_order_law, inline, tag=tag, carray=carray,
                       gains_ptr=pointer(numba.from_dtype(FIRST_ORDER_GAINS)), **forms)
    elif variant == SLIDING:
        law = jit_tree(native._builtin_law, inline, tag=tag, carray=carray,
                       gains_ptr=pointer(numba.from_dtype(SLIDING_GAINS)), **forms)
    else:
        law = jit_tree(native._plugin_law, inline, tag=tag, user_law=jit_tree(plugin, inline, tag=tag),
                       carray=carray, gains_ptr=pointer(numba.from_dtype(PLUGIN_GAINS)), **forms)
    pieces: dict[str, Any] = {
        "law_stage": jit_tree(_law_stage, inline, tag=tag, law=law, clamp=jit_tree(clamp, inline, tag=tag), **common),
        "apply_control": jit_tree(_apply_control, inline, tag=tag, **common),
        "record_row": jit_tree(_record_row, inline, tag=tag,
                               record_columns=jit_tree(native.record_columns, inline, tag=tag), **common)}
    step = jit_tree(stage_code.control_stage, inline, tag=tag,
                    view=jit_tree(native_step.view, inline, tag=tag, **common), **common, **pieces)
    one_step = jit_tree(analytic_step, inline, tag=tag, rate=jit_tree(twin_rate, inline, tag=tag, **plant_fns),
                        observe=jit_tree(twin_state, inline, tag=tag),
                        control=jit_tree(_stage_control, inline, tag=tag, control_stage=step))
    g = {**chunk_factory.__globals__, **common, "numba": numba, "analytic_step": one_step}
    fn = unique_factory(chunk_factory, g, key)(key)
    _compiled[mem_key] = fn
    return fn


def supported(plant: Plant, law: Law) -> bool:
    """The twin's compiled loop runs this plant and law: a TwinPlant whose compiled_loop is this module (not
    plants.wing_rock.MracWingRock, whose law is MRAC: compiled_loop None) of order <= plants.twin.MAX_ORDER with
    RK4 (4 stages) or Euler (1), under the first-order law, a sliding law or a law plugin with a form of the plant's
    order (laws' `native`; composite adaptation and every other law take the Python path)."""
    from adaptive_mj.plants.twin import TwinPlant

    return (isinstance(plant, TwinPlant) and plant.compiled_loop == __name__ and plant.stages in (1, 4)
            and plant.kernel.supports(plant) and _law_variant(law) is not None
            and getattr(getattr(law, "form", None), "order", None) == plant.order)


class NativeTwinController(AnalyticLoop):
    """Owns the context and buffers of one compiled twin run and steps the plant chunk by chunk: the plant's
    step_native(n) calls `advance(n)` (the `callback` it is given by loop._run_native).

    plant: a TwinPlant; law: one `supported` accepts; reference: the law's reference; theta_hat0: (n_theta,);
    max_rows: the most steps a chunk takes; control: the run's ControlTiming."""

    plant: TwinPlant  # type: ignore[assignment]  # not a MuJoCo plant: no MjData to bind

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0, max_rows: int, *,
                 control: stage_code.ControlTiming | None = None):
        from adaptive_mj.plants.twin import TwinPlant

        variant = _law_variant(law)
        if not isinstance(plant, TwinPlant) or variant is None:
            raise TypeError(f"the twin's compiled loop drives a TwinPlant under the first-order law, a sliding law or "
                            f"a law plugin, got a {type(plant).__name__} and a {type(law).__name__}")
        self.plant, self.law, self.reference = plant, law, reference
        self.max_rows = int(max_rows)
        control = control if control is not None else stage_code.ControlTiming(period=plant.dt)
        self.callback = self.advance
        form = law.form  # type: ignore[attr-defined]  # every variant's law has one (_law_variant)
        if variant == FIRST_ORDER:
            p = law.native_arrays()  # type: ignore[attr-defined]  # FirstOrderAdaptiveLaw's
            p["coeffs"] = np.zeros(1)  # the first-order law has no surface
            dtype = FIRST_ORDER_GAINS
        else:
            p = law.native_params()
            dtype = PLUGIN_GAINS if variant == PLUGIN else SLIDING_GAINS
        self.gains = native.gains_record(p["gains"], dtype)
        self._kernel = compiled(form, plant.form, variant, plugin=p.get("plugin_law"))
        n, nth, nst = plant.order, len(law.names), plant.stages
        self.n, self.nth, self.nst = n, nth, nst
        self.columns = native.record_columns(n, nth)
        self.ncol = self.columns.width
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
        self.buffers = {
            "theta": f64(np.array(theta_hat0, dtype=float).reshape(nth)), "rsum": np.zeros(nth), "prev": np.zeros(nth),
            "rate": np.zeros(nth), "th": np.zeros(nth), "lower": f64(p["lower"]), "upper": f64(p["upper"]),
            "u_hold": np.zeros(1), "delayed": np.zeros(1), "ring": np.zeros((control.delay + 1, 1)),
            "ref": np.zeros(max_rows * nst * (n + 1)), "noise": np.zeros(max_rows * n), "xbuf": np.zeros(n),
            "coeffs": f64(p["coeffs"]), "gamma": f64(p["gamma"]), "theta0": f64(p["theta0"]),
            "params": f64(p.get("plugin_params", np.zeros(1))), "s_hold": np.zeros(1),
            "rec": np.zeros(max_rows * self.ncol),
        }
        self.theta = self.buffers["theta"]
        lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (-math.inf, math.inf)
        self.lo, self.hi = float(lo), float(hi)
        self.stage_offsets = np.asarray(stage_code.TABLEAU[nst][0])  # RK4: c_i = a_i (see stage.TABLEAU)
        self.dist = np.zeros(max_rows)
        self.context = self.new_context(CONTEXT, n=n, nth=nth, nst=nst, h=plant.dt, control=control)

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """The references at every stage time of the next `rows` steps, the steps' noise and external force, and
        the context set to the plant's time."""
        plant, n = self.plant, self.n
        t, refs = stage_code.stage_references(self.reference, plant.time, plant.dt, rows, self.stage_offsets, n)
        self.buffers["ref"][: rows * self.nst * (n + 1)] = refs.ravel()
        self.buffers["noise"][: rows * n] = 0.0 if noise is None else noise.ravel()
        self.forces(t, rows)  # TwinPlant.step's force
        c = self.context[0]
        c["stage"], c["row"], c["rows"], c["t"] = 0, 0, rows, t[0]

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps (the compiled chunk; prepare first) and leave its state, time and
        step count where TwinPlant.step would."""
        plant = self.plant
        plant.x = np.ascontiguousarray(plant.x, dtype=np.float64)
        self._kernel(self.context, twin_params(plant), plant.x, self.dist, self.lo, self.hi, rows)
        c = self.context[0]
        plant.moved_to(float(c["t"]), rows)

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """The rows recorded over the `rows` steps just taken: t (rows,) [s], x (rows, n) the true state at each
        step's start, u (rows,) applied, s (rows,), ref (rows, n+1), theta_hat (rows, n_theta) at each step's
        start."""
        return native.recorded_rows(self.context[0], self.buffers["rec"], self.columns, self.n, rows, partial,
                             "the twin's compiled loop")


#: what loop._native_controller takes of a compiled loop's module (plants.twin.PythonStepped.compiled_loop)
Controller = NativeTwinController

"""The compiled control callback of every MuJoCo plant kind (built from the kind's kernel spec by the generic
controller, adaptive_mj.sim.native_mujoco): MuJoCo calls it at every stage of its integrator, and it
runs adaptive_mj.sim.stage.control_stage, the one definition of a control step's order that the Python path
(adaptive_mj.sim.loop.Controller) runs too, compiled with the plant shape's pieces:
    law_stage      measure x (+ noise), the stage estimate, the law, u clamped and held: the shape's own (a
                   ModelForm's phi/f/h on [q, q'], or the regressor of a kinematic tree read from MjData)
    apply_control  ctrl (and the step's disturbance torques)
    record_row     the step's row in the shape's record buffers
`compiled_callback` compiles them into control_stage and control_stage into the callback; the callback only
finds its run (mjData.userdata → the context record) and leaves alone an MjData no run owns, a call past the
step's stages (an extra mj_forward) and a call past the chunk's rows. tests/test_native.py,
tests/test_native_manipulator.py and tests/test_control_rate.py show the compiled and the Python paths give the
same rows bit for bit.

Each shape's context record (its CONTEXT dtype) holds the fields control_stage reads (stage.control_stage's
docstring), the buffers by address. Nothing here imports numba at import time: `carray`, `fptr`, the pointer
intrinsics and the pieces are globals that `compiled_callback` injects (as numba_util.jit_tree does for every
compiled function).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_context import context_functions, inlined, unique_factory

if TYPE_CHECKING:
    # injected by compiled_callback; declared for the type checker only
    numba: Any
    types: Any
    carray: Any
    address: Any
    cptr: Any
    fptr: Any
    context_address: Any
    control_stage: Any
    project_bodies: Any

_i8, _f8 = np.int64, np.float64
#: the context fields every shape's record holds because stage.control_stage and end_stage read them (its
#: docstring lists them): the run's state, when the law runs, and the estimate and delay-line buffers (addresses)
STAGE_CONTEXT = [
    ("stage", _i8), ("row", _i8), ("rows", _i8), ("step", _i8), ("t", _f8),
    ("nstages", _i8), ("nth", _i8), ("nbox", _i8), ("m", _i8), ("mode", _i8), ("period_steps", _i8), ("delay", _i8),
    ("h", _f8),
    ("period", _f8), ("inc", _f8, 4), ("weights", _f8, 4),
    ("theta", _i8), ("rsum", _i8), ("prev", _i8), ("rate", _i8), ("lower", _i8), ("upper", _i8), ("u_hold", _i8),
    ("delayed", _i8), ("ring", _i8),
]


def context_dtype(own: list) -> np.dtype:
    """A shape's context record: STAGE_CONTEXT, then its own fields (none of which may repeat one of them)."""
    shared = {f[0] for f in STAGE_CONTEXT}
    clash = [f[0] for f in own if f[0] in shared]
    if clash:
        raise ValueError(f"context fields {clash} are STAGE_CONTEXT's already")
    return np.dtype(STAGE_CONTEXT + list(own))


def recorded_rows(context, rec: np.ndarray, col, shapes, rows: int, partial: bool,
                  what: str) -> tuple[np.ndarray, ...]:
    """The rows a compiled loop recorded over the `rows` steps just taken, in the one row layout
    (plants.mujoco_kernel.row_columns: every MuJoCo kind's callback and the analytic chunk engine, sim.native_chunk),
    copied out of its record buffer `rec` (flat, float64; col: its RecordColumns): t (rows,) [s], x (rows, *shapes.x)
    the true state at each step's start, u (rows, *shapes.u) applied, s (rows, *shapes.s), ref (rows, *shapes.ref),
    theta_hat (rows, n_theta) at each step's start (shapes: plants.mujoco_kernel.RowShapes). context: the run's
    context record, whose row and stage must say the loop took exactly `rows` whole steps (unless partial: the
    first `rows` of a chunk cut short, ContextOwner.rows_recorded); what: the loop's name in the error otherwise."""
    if not partial and (int(context["row"]) != rows or int(context["stage"]) != 0):
        raise RuntimeError(f"{what} ran {int(context['row'])} steps (stage {int(context['stage'])}), expected {rows}")
    r = rec[: rows * col.width].reshape(rows, col.width)

    def take(first: int, shape: tuple) -> np.ndarray:
        if shape == ():
            return r[:, first].copy()
        return r[:, first:first + int(np.prod(shape, dtype=np.int64))].reshape((rows,) + tuple(shape)).copy()

    return (r[:, col.t].copy(), take(col.x, shapes.x), take(col.u, shapes.u), take(col.s, shapes.s),
            take(col.ref, shapes.ref), r[:, col.theta:col.extra].copy())


#: the stage functions (adaptive_mj.sim.stage) compiled into every callback and its pieces
STAGE_FUNCTIONS = ("stage_estimate", "accumulate_rate", "advance_estimates", "is_sample_step", "period_ends",
                   "delay_slot", "sense", "end_stage")


def callback_factory(off, key):
    """The callback's Python source, closed over MuJoCo's struct offsets (off: native_context.Offsets) and the
    cache key only: it finds its run's context through mjData.userdata and leaves alone an MjData no run owns
    (a scratch copy), a call past the step's stages (an extra mj_forward) and a call past the chunk's rows."""
    off_ud = off.userdata

    @numba.cfunc(types.void(types.voidptr, types.voidptr), nogil=True, cache=True)  # noqa: F821 (injected)
    def callback(m, d):
        if key == 0:  # never: keeps the cache key in the closure
            return
        base, mbase = address(d), address(m)  # noqa: F821 (injected)
        c = context_address(base, off_ud)  # noqa: F821 (injected)
        if c == 0:
            return
        ctx = carray(cptr(c), 1)[0]  # noqa: F821 (injected)
        if ctx.stage >= ctx.nstages or ctx.row >= ctx.rows:
            return
        control_stage(ctx, (base, mbase, off))  # noqa: F821 (injected: stage.control_stage, compiled)

    return callback


def view(a, shape):
    """A context buffer at address `a` as an array of `shape` (stage.control_stage's `view`, compiled)."""
    return carray(fptr(a), shape)  # noqa: F821 (injected)


#: the symbol of the process's one int64 cell holding the address of the compiled projection (projection_cell)
PROJECTION_SYMBOL = "adaptive_mj_project_bodies_address"
_PROJECTION: dict = {}


def projection_cell():
    """The int64 cell (ctypes, one per process) that the compiled code reads the projection's address from, by the
    symbol PROJECTION_SYMBOL: registered with LLVM's symbol table before any variant that names it is compiled or
    loaded from numba's cache (its machine code keeps the symbol, resolved when it is loaded: no address of this
    process is compiled in). 0 until projection_ready() puts the compiled projection there."""
    if "cell" not in _PROJECTION:
        import ctypes

        from llvmlite import binding as ll

        cell = ctypes.c_int64(0)
        ll.add_symbol(PROJECTION_SYMBOL, ctypes.addressof(cell))
        _PROJECTION["cell"] = cell
    return _PROJECTION["cell"]


def _projection_factory(key):
    """The physically consistent projection (laws.pseudo_inertia.project_bodies) as a C function of its own,
    (theta, n_theta, record, record length, offset): compiled once on a machine (numba's cache, keyed by `key`,
    the source of what it compiles in), loaded by a run that needs it (projection_ready)."""

    @numba.cfunc(types.void(types.CPointer(types.float64), types.int64, types.CPointer(types.float64),  # noqa: F821
                            types.int64, types.int64), nogil=True, cache=True)  # noqa: F821 (injected)
    def callback(theta, n, record, length, offset):
        if key == 0:  # never: keeps the cache key in the closure
            return
        project_bodies(carray(theta, n), carray(record, length), offset)  # noqa: F821 (injected)

    return callback


def projection_ready(context: np.ndarray) -> None:
    """Before a run whose context says its box goes on past n_theta (nbox > nth: a physically consistent projection's
    record, laws.common.clip_into): the projection compiled (or loaded) and its address in projection_cell(). A run
    without one compiles nothing here."""
    names = context.dtype.names or ()
    if "nbox" not in names or int(context[0]["nbox"]) <= int(context[0]["nth"]) or "cfunc" in _PROJECTION:
        return
    import numba
    from numba import carray, types

    from adaptive_mj.laws import pseudo_inertia
    from adaptive_mj.numba_util import jit_tree
    from adaptive_mj.sim.native_context import source_key, unique_factory

    key = source_key(pseudo_inertia.project_bodies, _projection_factory, extra=(numba.__version__,))
    g = {**_projection_factory.__globals__, "numba": numba, "types": types, "carray": carray,
         "project_bodies": jit_tree(pseudo_inertia.project_bodies, numba.njit)}
    fn = unique_factory(_projection_factory, g, key, what="the physically consistent projection",
                        kind="projection")(key)
    _PROJECTION["cfunc"] = fn
    projection_cell().value = fn.address


def project_indirect():
    """A numba intrinsic project(theta, record, offset) (C-contiguous float64 arrays, an integer offset): calls the
    compiled projection at the address in projection_cell() (numba_util's pointer intrinsics do the same with an
    address in the context). So the projection's eigen-solver and iteration are compiled once on a machine, not into
    every variant, and only where a run needs them."""
    if "intrinsic" in _PROJECTION:
        return _PROJECTION["intrinsic"]
    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic

    projection_cell()

    @intrinsic
    def project(typingctx, theta, record, offset):
        if not (isinstance(theta, types.Array) and isinstance(record, types.Array) and theta.layout == "C"
                and record.layout == "C" and theta.dtype == types.float64 and record.dtype == types.float64
                and isinstance(offset, types.Integer)):
            return None
        sig = types.void(theta, record, offset)

        def codegen(context, builder, signature, args):
            i64, dptr = ir.IntType(64), ir.DoubleType().as_pointer()
            th = context.make_array(signature.args[0])(context, builder, args[0])
            rc = context.make_array(signature.args[1])(context, builder, args[1])
            mod = builder.module
            cell = mod.globals.get(PROJECTION_SYMBOL)
            if cell is None:
                cell = ir.GlobalVariable(mod, i64, PROJECTION_SYMBOL)
            fnty = ir.FunctionType(ir.VoidType(), [dptr, i64, dptr, i64, i64])
            address = builder.load(cell)
            off = context.cast(builder, args[2], signature.args[2], types.int64)
            # 0: no projection_ready() in this process (a controller made outside sim.loop): nothing rather than a
            # call to address 0 (every MuJoCo controller readies it when it binds, sim.loop for every kind)
            with builder.if_then(builder.icmp_unsigned("!=", address, ir.Constant(i64, 0))):
                fp = builder.inttoptr(address, fnty.as_pointer())
                builder.call(fp, [th.data, builder.extract_value(th.shape, 0), rc.data,
                                  builder.extract_value(rc.shape, 0), off])
            return context.get_dummy_value()

        return sig, codegen

    _PROJECTION["intrinsic"] = project
    return project


def stage_functions(numba, inline, tag: str) -> dict[str, Any]:
    """STAGE_FUNCTIONS compiled for one callback variant (inlined into it), except the physically consistent
    projection (laws.pseudo_inertia.project_bodies, which clip_into calls): a C function of its own, compiled once
    on a machine and only for a run that needs it (projection_ready), called through its address
    (project_indirect), so its eigen-solver and iteration are compiled into no variant (they were 2-2.5 s of CPU of
    each variant's cold compile)."""
    from adaptive_mj.laws import common as law_common
    from adaptive_mj.numba_util import jit_tree

    clip = jit_tree(law_common.clip_into, inline, tag=tag, project_bodies=project_indirect())
    out = {name: jit_tree(getattr(stage_code, name), inline, tag=tag) for name in STAGE_FUNCTIONS
           if name not in ("stage_estimate", "advance_estimates", "end_stage")}
    out["stage_estimate"] = jit_tree(stage_code.stage_estimate, inline, tag=tag, clip_into=clip)
    out["advance_estimates"] = jit_tree(stage_code.advance_estimates, inline, tag=tag, clip_into=clip)
    out["end_stage"] = jit_tree(stage_code.end_stage, inline, tag=tag, advance_estimates=out["advance_estimates"])
    return out


def compiled_callback(context_dtype, off, key: int, pieces: Callable[[dict, str], dict[str, Any]], *,
                      what: str | None = None, kind: str | None = None):
    """The cfunc of one plant shape and law: control_stage with the shape's pieces, in the callback.

    context_dtype: the shape's CONTEXT; off: native_context.Offsets; key: the cache key (native_context.source_key
    over every function compiled in, this module's included); pieces(common, tag) -> {"law_stage",
    "apply_control", "record_row"}: the shape's pieces compiled (common: the globals every compiled function
    here sees: carray, fptr, iptr, np, the pointer intrinsics and the stage functions, compiled); what, kind: how a
    compile that is not a load from numba's cache is said (native_context.unique_factory)."""
    import numba
    import numpy as np
    from numba import carray, types

    from adaptive_mj.numba_util import address_of, jit_tree, pointer

    tag = f"_{key:x}"  # every function of this variant named apart (numba_util.jit_tree)
    inline = inlined(numba)
    common: dict[str, Any] = {"carray": carray, "iptr": pointer(types.int64), "fptr": pointer(types.float64),
                              "np": np, "SAMPLED": stage_code.SAMPLED}
    common.update(context_functions(numba, carray, common["iptr"], tag))
    common.update(stage_functions(numba, inline, tag))
    shape = pieces(common, tag)
    step = jit_tree(stage_code.control_stage, inline, tag=tag, view=jit_tree(view, inline, tag=tag, **common),
                    **common, **shape)
    g = {**callback_factory.__globals__, **common, "numba": numba, "types": types, "address": address_of(),
         "cptr": pointer(numba.from_dtype(context_dtype)), "control_stage": step}
    return unique_factory(callback_factory, g, key, what=what, kind=kind)(off, key)

"""Helpers for compiling plain-array Python functions with numba (numba is imported only when
they are called)."""
from __future__ import annotations

import sys
import types as pytypes
from typing import Any, Callable, Iterable

_registries_loaded = False


def load_registries() -> None:
    """Load numba's CPU target registries (the lowering of every numpy function numba knows) now,
    once per process, without the BLAS probe that comes with them.

    numba loads the registries before it compiles a function or loads one from its disk cache.
    One of them, numba.np.arraymath, asks at import whether BLAS is there (_check_blas) by importing
    scipy.linalg.cython_blas, and so all of scipy.linalg: 0.2 s of every run's start, while the
    answer depends only on scipy.linalg being installed. Here it is answered from that, without
    the import; numba's own ensure_blas is back in place before anything is lowered or run, so a
    function that does use BLAS imports it (and checks it) as before. The machine code is the same
    either way: nothing is compiled differently, the cache is not keyed on it."""
    global _registries_loaded
    if _registries_loaded:
        return
    _registries_loaded = True
    if "numba.np.arraymath" in sys.modules:  # numba has loaded them already
        return
    import importlib.util

    from numba.core.registry import cpu_target
    from numba.np import linalg as numba_linalg

    linalg: Any = numba_linalg  # Any: its ensure_blas is replaced for the load
    real = linalg.ensure_blas

    def blas_installed() -> None:
        if importlib.util.find_spec("scipy.linalg") is None:
            raise ImportError("scipy 0.16+ is required for linear algebra")

    linalg.ensure_blas = blas_installed
    try:
        cpu_target.target_context.refresh()
    finally:
        linalg.ensure_blas = real
        arraymath: Any = sys.modules.get("numba.np.arraymath")
        if arraymath is not None and getattr(arraymath, "ensure_blas", None) is blas_installed:
            arraymath.ensure_blas = real


#: the line of numba's InlineWorker.inline_ir (its copy_ir) that shared_inline_copies changes the meaning of
INLINE_COPY_SOURCE = "new_block = copy.deepcopy(the_ir.blocks[block_label])"
_inline_copies: dict[str, Any] = {}


def shared_inline_copies() -> bool:
    """Make numba's inliner copy a function's IR with one deepcopy memo for all its blocks; True where it does.

    numba inlines a function compiled with inline="always" (adaptive_mj.sim.native_context.inlined: every piece of a
    compiled controller) by copying the callee's IR twice (InlineWorker.inline_ir's copy_ir), each block with its
    own ``copy.deepcopy``. All blocks of a function share one Scope, which holds every variable of the function, so
    each block's copy copies the whole scope again: the copy grows as blocks x variables, and it was two thirds of
    a controller's compile (3.4 of 5.3 s of CPU for the heave vehicle's callback, numba 0.68.1). Here the blocks of
    one copy_ir call share one memo, as one deepcopy of the whole IR would: the copy has the original's structure
    (one scope for all blocks) rather than one scope per block. The IR, and so the machine code, is the same
    (tests/test_numba_util.py compares the compiled code with and without it).

    Installed only where numba's inline_ir still copies as this reads it (the line INLINE_COPY_SOURCE in its
    source; read on numba 0.68.1); elsewhere numba is left as it is (False) and compiles as before, only slower.
    A memo lives from one FunctionIR.copy (copy_ir's first step) to the next, and only for blocks of one scope,
    so two copies never share an object. ADAPTIVE_MJ_SHARED_INLINE_COPIES=0 in the environment leaves numba as it
    is."""
    if "installed" in _inline_copies:
        return _inline_copies["installed"]
    import os

    if os.environ.get("ADAPTIVE_MJ_SHARED_INLINE_COPIES", "1") == "0":  # numba as it is (a check, or a way out)
        _inline_copies["installed"] = False
        return False
    import copy
    import inspect

    from numba.core import inline_closurecall, ir

    try:
        readable = INLINE_COPY_SOURCE in inspect.getsource(inline_closurecall.InlineWorker.inline_ir)
    except (OSError, TypeError, AttributeError):
        readable = False
    if not readable or getattr(inline_closurecall, "copy", None) is not copy:
        _inline_copies["installed"] = False
        return False
    state: dict[str, Any] = {"scope": None, "memo": None}
    real_copy = ir.FunctionIR.copy

    def function_ir_copy(self):
        state["scope"] = state["memo"] = None  # copy_ir starts: a new memo for its blocks
        return real_copy(self)

    def deepcopy(x, memo=None, _nil=None):
        if memo is None and isinstance(x, ir.Block):
            if state["memo"] is None or state["scope"] is not x.scope:
                state["scope"], state["memo"] = x.scope, {}
            memo = state["memo"]
        return copy.deepcopy(x, memo)

    shim = pytypes.ModuleType("copy", "the copy module as numba's inliner sees it (numba_util.shared_inline_copies)")
    shim.__dict__.update({k: v for k, v in vars(copy).items() if not k.startswith("__")})
    vars(shim)["deepcopy"] = deepcopy
    ir.FunctionIR.copy = function_ir_copy  # type: ignore[method-assign]
    inline_closurecall.copy = shim
    _inline_copies["installed"] = True
    return True


def with_globals(fn, **replace):
    """The same function (same code object) seeing some globals replaced, e.g. by their numba versions."""
    return pytypes.FunctionType(fn.__code__, {**fn.__globals__, **replace}, fn.__name__, fn.__defaults__,
                                fn.__closure__)


def jit_tree(fn: Callable, njit: Callable, *, tag: str = "", seen: dict | None = None, inner: Callable | None = None,
             **replace) -> Callable:
    """fn compiled by njit, with every plain Python function it calls through its module globals
    compiled the same way (recursively), and globals in `replace` replaced. So a law written as
    plain array code, and the functions it calls, compile without a hand-kept list.

    tag: appended to every compiled function's name and qualified name. numba names a function's
    machine-code symbols after its qualified name and a counter that restarts in every process, so
    two variants of the same functions (other globals: another plant's phi) compiled in two
    processes and loaded from the disk cache into a third would define one symbol twice, and the
    JIT would link one variant's calls to the other's code. A tag per variant keeps them apart.

    inner: the njit for the functions fn calls (recursively), when not njit itself (e.g. inlined into fn
    while fn is compiled apart: adaptive_mj.sim.native_context.inlined)."""
    load_registries()
    shared_inline_copies()
    seen = {} if seen is None else seen
    if id(fn) in seen:
        return seen[id(fn)]
    names = set(global_names(fn.__code__))
    g = dict(fn.__globals__)
    for name in names:
        if name in replace:
            g[name] = replace[name]
            continue
        value = g.get(name)
        if value is scalar_power:  # the C library's pow, its exponent hidden from the optimiser
            g[name] = libm_pow()
            continue
        if isinstance(value, pytypes.FunctionType) and not _is_jitted(value):
            g[name] = jit_tree(value, inner or njit, tag=tag, seen=seen, inner=inner)
    code = fn.__code__
    if tag:
        code = code.replace(co_name=code.co_name + tag, co_qualname=code.co_qualname + tag)
    out = njit(pytypes.FunctionType(code, g, code.co_name, fn.__defaults__, fn.__closure__))
    seen[id(fn)] = out
    return out


def global_names(code) -> Iterable[str]:
    """The global names a code object (and the code objects nested in it) reads."""
    yield from code.co_names
    for const in code.co_consts:
        if isinstance(const, pytypes.CodeType):
            yield from global_names(const)


def _is_jitted(value) -> bool:
    return hasattr(value, "py_func")


def pointer(nbtype):
    """A numba intrinsic turning an int64 address into a typed pointer (for carray)."""
    from numba import types
    from numba.extending import intrinsic

    @intrinsic
    def to_ptr(typingctx, address):
        sig = types.CPointer(nbtype)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.CPointer(nbtype)))

        return sig, codegen

    return to_ptr


def address_of():
    """A numba intrinsic: the int64 address a voidptr holds."""
    from numba import types
    from numba.extending import intrinsic

    @intrinsic
    def address(typingctx, ptr):
        sig = types.int64(types.voidptr)

        def codegen(context, builder, signature, args):
            return builder.ptrtoint(args[0], context.get_value_type(types.int64))

        return sig, codegen

    return address


def scalar_power(v, e):
    """v ** e as numpy computes it for a float64 scalar v (and Python for a float): the C library's pow(v, e).

    Write a power in a plant's form (a ModelForm's φ, f, h) with it where the compiled and Python paths must agree
    bit for bit: numba (and numpy for an array) turns a constant exponent 2 into v·v, which is correctly rounded
    where pow may be one unit in the last place off, so the two paths part. jit_tree compiles this function as
    `libm_pow`: the same pow, called with the exponent hidden from the optimiser."""
    return v ** e


_INTRINSICS: dict[str, Any] = {}


def libm_pow():
    """A numba intrinsic (made once per process): pow(v, e) of the C library for float64 v and e, through LLVM's
    llvm.pow with e passed through an empty inline-assembly barrier, so that no constant exponent is folded into
    multiplications (numba lowers v ** 2 to v·v). The machine's register class for a double: "x" (x86-64, SSE) or
    "w" (AArch64); on another machine no barrier (its v ** 2 may then be v·v)."""
    if "libm_pow" in _INTRINSICS:
        return _INTRINSICS["libm_pow"]
    import platform

    from llvmlite import ir
    from numba import types
    from numba.extending import intrinsic

    reg = {"x86_64": "x", "amd64": "x", "aarch64": "w", "arm64": "w"}.get(platform.machine().lower())

    @intrinsic
    def libm_pow_(typingctx, v, e):
        if not all(isinstance(a, (types.Float, types.Integer)) for a in (v, e)):
            return None  # scalars only (numba then says which types it got)
        sig = types.float64(types.float64, types.float64)

        def codegen(context, builder, signature, args):
            x, y = args
            dbl = ir.DoubleType()
            if reg is not None:
                y = builder.asm(ir.FunctionType(dbl, [dbl]), "", f"={reg},0", [y], side_effect=False)
            return builder.call(builder.module.declare_intrinsic("llvm.pow", [dbl]), [x, y])

        return sig, codegen

    _INTRINSICS["libm_pow"] = libm_pow_
    return libm_pow_

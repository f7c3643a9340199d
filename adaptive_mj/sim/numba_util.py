"""Helpers for compiling plain-array Python functions with numba (no numba import here)."""
from __future__ import annotations

import types


def with_globals(fn, **replace):
    """The same function (same code object) seeing some globals replaced, e.g. by their numba versions."""
    return types.FunctionType(fn.__code__, {**fn.__globals__, **replace}, fn.__name__, fn.__defaults__,
                              fn.__closure__)


def pointer(nbtype):
    """A numba intrinsic turning an int64 address into a typed pointer (for carray), e.g.
    pointer(numba.types.float64)(addr). Imports numba when called."""
    from numba import types
    from numba.extending import intrinsic

    @intrinsic
    def to_ptr(typingctx, addr):
        sig = types.CPointer(nbtype)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.CPointer(nbtype)))

        return sig, codegen

    return to_ptr

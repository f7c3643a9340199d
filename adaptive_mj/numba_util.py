"""Helpers for compiling plain-array Python functions with numba (no numba import here)."""
from __future__ import annotations

import types


def with_globals(fn, **replace):
    """The same function (same code object) seeing some globals replaced, e.g. by their numba versions."""
    return types.FunctionType(fn.__code__, {**fn.__globals__, **replace}, fn.__name__, fn.__defaults__,
                              fn.__closure__)

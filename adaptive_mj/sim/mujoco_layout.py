"""Where MuJoCo's struct fields lie: the byte offset of every field of mjData and mjModel, from MuJoCo's own
introspection (`mujoco.introspect`, shipped with the bindings and generated from the same headers the library
was built from), laid out by ctypes with the C rules the compiler used. The compiled control callbacks read
mjData's array pointers (qpos, qvel, ctrl, ...) and a few of mjModel's at these offsets
(adaptive_mj.sim.native_context).

Nothing here reads a struct's memory at run time, except behind the version check: for a MuJoCo whose layout
has not been checked against the memory of a live struct (TESTED), `offsets()` checks the introspected offsets
of every array pointer against the pointers a probe model's MjData and MjModel actually hold (`scan`, which
reads them through the bindings' private `_address`) and takes the scan's offsets where the two disagree, with
one warning. tests/test_mujoco_layout.py runs that check on the installed MuJoCo.
"""
from __future__ import annotations

import ctypes
import math
import warnings
from functools import cache
from typing import Any

import numpy as np

#: MuJoCo versions (prefixes) whose introspected layout was checked against a live struct's memory, field by field
TESTED = ("3.17.",)

_SCALARS: dict[str, Any] = {
    "int": ctypes.c_int, "unsigned int": ctypes.c_uint, "float": ctypes.c_float, "double": ctypes.c_double,
    "char": ctypes.c_char, "unsigned char": ctypes.c_ubyte, "size_t": ctypes.c_size_t, "uintptr_t": ctypes.c_size_t,
    "int64_t": ctypes.c_int64, "uint64_t": ctypes.c_uint64, "uint8_t": ctypes.c_uint8,
    # mjtnum.h's typedefs (mjassert.h asserts mjtBool's size, 1)
    "mjtNum": ctypes.c_double, "mjtByte": ctypes.c_ubyte, "mjtBool": ctypes.c_ubyte, "mjtSize": ctypes.c_int64,
}


def _ctype(t) -> Any:
    """The ctypes type of an introspected C type."""
    from mujoco.introspect import ast_nodes as ast
    from mujoco.introspect import enums, structs

    if isinstance(t, ast.PointerType):
        return ctypes.c_void_p
    if isinstance(t, ast.ArrayType):
        return _ctype(t.inner_type) * math.prod(t.extents)
    if isinstance(t, (ast.AnonymousStructDecl, ast.AnonymousUnionDecl)):
        return _compose(t.fields, union=isinstance(t, ast.AnonymousUnionDecl))
    if isinstance(t, ast.ValueType):
        if t.name in _SCALARS:
            return _SCALARS[t.name]
        if t.name in enums.ENUMS:
            return ctypes.c_int
        if t.name in structs.STRUCTS:
            return struct_type(t.name)
    raise TypeError(f"no C layout known for MuJoCo's type {t!r}")


def _compose(fields, *, union: bool = False) -> Any:
    from mujoco.introspect import ast_nodes as ast

    members = [(f"_anonymous{i}", _ctype(f)) if isinstance(f, (ast.AnonymousStructDecl, ast.AnonymousUnionDecl))
               else (f.name, _ctype(f.type)) for i, f in enumerate(fields)]
    return type("Layout", (ctypes.Union if union else ctypes.Structure,), {"_fields_": members})


@cache
def struct_type(name: str) -> Any:
    """The ctypes Structure of MuJoCo's struct `name` (e.g. "mjData"), field for field as introspected."""
    from mujoco.introspect import structs

    if name not in structs.STRUCTS:
        raise KeyError(f"MuJoCo has no struct {name!r}")
    return _compose(structs.STRUCTS[name].fields)


def pointer_fields(struct: str) -> list[str]:
    """The names of the struct's array pointers into its buffer, in declaration order: the pointer fields from
    `buffer` on, up to the first field that is not a pointer (mjData's arena arrays, which live only during a
    step, come after it)."""
    from mujoco.introspect import ast_nodes as ast
    from mujoco.introspect import structs

    fields = structs.STRUCTS[struct].fields
    out = []
    for f in fields[[f.name for f in fields].index("buffer"):]:
        if not isinstance(getattr(f, "type", None), ast.PointerType):
            break
        out.append(f.name)
    return out


def introspected() -> dict[str, int]:
    """{field: byte offset} of every mjData array pointer, every mjModel array pointer ("model." prefix) and of
    mjModel.opt.gravity (inline, "model.gravity"), from MuJoCo's introspection."""
    data, model = struct_type("mjData"), struct_type("mjModel")
    out = {name: getattr(data, name).offset for name in pointer_fields("mjData")}
    out.update({f"model.{name}": getattr(model, name).offset for name in pointer_fields("mjModel")})
    out["model.gravity"] = model.opt.offset + struct_type("mjOption").gravity.offset
    return out


_PROBE = ('<mujoco><size nuserdata="1"/><worldbody><body><joint name="j" type="hinge"/><geom size="0.1"/></body>'
          '</worldbody><actuator><motor joint="j"/></actuator></mujoco>')


def scan(offsets: dict[str, int]) -> dict[str, int]:
    """The entries of `offsets` that a probe model's live MjData and MjModel contradict: {field: the offset at
    which the struct does hold that array's pointer} for every array of the probe that the struct holds (an
    array of its own size: a zero-size array shares its neighbour's address; an arena array the bindings show
    while the struct's pointer is NULL is not checked) and that is not where `offsets` says. Reads the structs'
    memory through the bindings' private `_address`: the check behind the version check, not the source of the
    offsets."""
    import mujoco

    previous = mujoco.get_mjcb_control()  # a Python callback installed makes compiling fail
    mujoco.set_mjcb_control(None)
    try:
        m = mujoco.MjModel.from_xml_string(_PROBE)
    finally:
        mujoco.set_mjcb_control(previous)
    d = mujoco.MjData(m)
    wrong: dict[str, int] = {}
    for obj, prefix, struct in ((d, "", "mjData"), (m, "model.", "mjModel")):
        names = pointer_fields(struct)
        arrays = {n: getattr(obj, n) for n in names if isinstance(getattr(obj, n, None), np.ndarray)}
        arrays = {n: a.ctypes.data for n, a in arrays.items() if a.size > 0}
        if len(set(arrays.values())) != len(arrays):  # a shared address tells nothing: drop the pair
            counts: dict[int, int] = {}
            for a in arrays.values():
                counts[a] = counts.get(a, 0) + 1
            arrays = {n: a for n, a in arrays.items() if counts[a] == 1}
        base = obj._address
        size = ctypes.sizeof(struct_type(struct))
        words = np.frombuffer(ctypes.string_at(base, size - size % 8), dtype=np.uint64)
        where = {int(w): 8 * i for i, w in enumerate(words)}
        for name, address in arrays.items():
            if address in where and ctypes.c_uint64.from_address(base + offsets[prefix + name]).value != address:
                wrong[prefix + name] = where[address]
    return wrong


@cache
def offsets() -> dict[str, int]:
    """{field: byte offset} as `introspected()` gives them; for a MuJoCo not in TESTED, checked against a live
    probe (`scan`) first, and corrected where the probe disagrees (one warning naming the fields)."""
    import mujoco

    out = introspected()
    if not mujoco.__version__.startswith(TESTED):
        wrong = scan(out)
        if wrong:
            warnings.warn(f"MuJoCo {mujoco.__version__}: the introspected offsets of {sorted(wrong)} disagree with "
                          f"a live struct; using the live struct's", RuntimeWarning, stacklevel=2)
            out.update(wrong)
    return out

"""What the compiled control callbacks share: how a callback finds its run, how plain-array
Python code is compiled for it, and the on-disk cache that makes the compile a one-time cost.

Finding the run. MuJoCo calls a control callback with (const mjModel*, mjData*) only. Each
plant's model is compiled with mjData.userdata (adaptive_mj.plants.mujoco_plant.USERDATA_SLOTS);
a native run writes the address of its context block (a numpy structured array: named fields,
one dtype per callback) into userdata[0] of its MjData. The callback reads the userdata pointer
from the mjData struct, then the context, then MjData's own arrays (qpos, qvel, ctrl, ...)
through their pointer fields: nothing is reached through an address compiled into the code.
An MjData whose userdata[0] is 0 (a scratch copy, a fresh MjData) is left alone.

The byte offsets of those pointer fields in mjData/mjModel are a property of the MuJoCo build;
they come from MuJoCo's own introspection (adaptive_mj.sim.mujoco_layout), are compiled in as
constants, and are part of the cache key, so another MuJoCo build gets its own compiled callback.

Compiling and caching. The callbacks are numba cfuncs with numba's on-disk cache
(``cache=True``). numba keys a cached function by its own code and closure values, not by the
code of the functions it calls, so each callback's closure carries `source_key`: a hash of the
source of every module whose functions it compiles in (laws, plant forms, plugins, this
package's stage code) and of those functions' closure values. Edit any of them and the next run
compiles afresh; otherwise a new process loads the machine code from the cache (numba also keys
by its version and the CPU). Set NUMBA_CACHE_DIR to move the cache.
"""
from __future__ import annotations

import hashlib
import inspect
import types as pytypes
from typing import TYPE_CHECKING, Any, Callable, Iterable, NamedTuple

import numpy as np

from adaptive_mj.numba_util import global_names

if TYPE_CHECKING:
    from adaptive_mj.plants.protocol import NativePlant

    # injected into the compiled functions' globals by context_functions (numba's carray, a
    # pointer intrinsic); declared here for the type checker only
    carray: Any
    iptr: Any

def mujoco_offsets() -> dict[str, int]:
    """{field: byte offset} of every mjData array pointer, every mjModel array pointer ("model."
    prefix) and of mjModel.opt.gravity (inline), for this process's MuJoCo (adaptive_mj.sim.mujoco_layout:
    MuJoCo's own introspection, behind a version check)."""
    from adaptive_mj.sim import mujoco_layout

    return mujoco_layout.offsets()


class Offsets(NamedTuple):
    """Byte offsets of the MjData (and MjModel: dof_armature, dof_damping, gravity, body_mass, actuator_gear,
    actuator_gainprm) fields the callback reads,
    by name (adaptive_mj.sim.native_context.mujoco_offsets), instead of slots of a tuple kept in step by hand."""

    userdata: int
    qpos: int
    qvel: int
    ctrl: int
    cdof: int
    xpos: int
    xmat: int
    subtree_com: int
    cinert: int
    dof_armature: int
    dof_damping: int
    gravity: int
    qfrc_applied: int
    M: int
    # the order-3 heave vehicle's y'' (plants.heave.HeavePlant.measure): its thrust state and forces
    act: int
    qfrc_passive: int
    qfrc_bias: int
    body_mass: int
    actuator_gear: int
    actuator_gainprm: int


#: the Offsets fields that name a field of MjModel (mujoco_offsets' "model." keys)
MUJOCO_FIELDS = {"dof_armature": "model.dof_armature", "dof_damping": "model.dof_damping", "gravity": "model.gravity",
                 "body_mass": "model.body_mass", "actuator_gear": "model.actuator_gear",
                 "actuator_gainprm": "model.actuator_gainprm"}


def offsets() -> Offsets:
    """The Offsets of this process's MuJoCo (mujoco_offsets, by field name)."""
    found = mujoco_offsets()
    return Offsets(**{name: found[MUJOCO_FIELDS.get(name, name)] for name in Offsets._fields})


def bind_context(data, context: np.ndarray) -> None:
    """Point data's callback at `context` (a (1,) structured array the caller keeps alive):
    userdata[0] holds its address (as the bits of an int64)."""
    if data.userdata.size < 1:
        raise ValueError("the model has no mjData.userdata slot for the native callback's context "
                         "(compile it through adaptive_mj.plants.mujoco_plant, which adds one)")
    data.userdata.view(np.int64)[0] = context.ctypes.data


def pointer_at(base, offset):
    """The pointer stored at base + offset (an mjData/mjModel pointer field), as an int64. Compiled
    into the callbacks (carray and iptr are injected by them)."""
    return carray(iptr(base + offset), 1)[0]  # noqa: F821 (injected)


def context_address(base, off_userdata):
    """The address of the context block the mjData at `base` points at (its userdata[0]), or 0
    when it has none (no userdata, or an MjData no native run owns: leave it alone)."""
    ud = pointer_at(base, off_userdata)
    if ud == 0:
        return 0
    return pointer_at(ud, 0)


def context_functions(numba, carray, iptr, tag: str) -> dict:
    """{"pointer_at", "context_address"} compiled for a callback variant (tag: numba_util.jit_tree)."""
    from adaptive_mj.numba_util import jit_tree

    inline = inlined(numba)
    at = jit_tree(pointer_at, inline, tag=tag, carray=carray, iptr=iptr)
    return {"pointer_at": at, "context_address": jit_tree(context_address, inline, tag=tag, pointer_at=at)}


def inlined(numba) -> Callable:
    """numba.njit for the functions a control callback calls: inlined into it (numba's inline="always",
    at numba's own IR level). Compiled apart, each call passes every array as a struct of 7 words and
    LLVM never sees across it; inlined, the 1-DOF callback's cost over bare stepping fell from 1.2 to
    0.7 µs per RK4 step (4 calls) on the heave vehicle. The same operations in the same order: results
    are unchanged bit for bit (tests/test_native.py)."""
    import functools

    return functools.partial(numba.njit, inline="always")


class ContextOwner:
    """What a native controller shares: it owns `self.context` for `self.plant`'s MjData while its
    run goes on (a context manager: the MjData is detached when the block ends), and steps the
    plant chunk by chunk with its compiled `callback`, `theta` (n_theta,) holding the estimates."""

    plant: NativePlant
    context: np.ndarray
    callback: Any  # the numba cfunc MuJoCo calls
    theta: np.ndarray
    max_rows: int  # the most physics steps one chunk takes (its buffers' rows)
    in_mujoco = True  # the plant steps in MuJoCo (mj_step calls `callback`); False: an analytic plant's compiled loop
    steps_apart = False  # a chunk is many steps: a MuJoCo warning after it is the chunk's (adaptive_mj.sim.driver)

    def chunk(self, rows: int, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Step `rows` physics steps; return (t, x, u, s, ref, theta_hat), each (rows, ...)."""
        raise NotImplementedError

    def advance(self, rows: int) -> None:
        """Step the plant `rows` physics steps with the compiled callback (or loop) installed
        (plant.controlled_natively): the chunk prepare() set up."""
        self.plant.step_native(rows)

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """chunk()'s first half: the buffers and the context set up for the next `rows` steps."""
        raise NotImplementedError

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """chunk()'s second half, after the plant stepped: the rows the callback recorded. partial: the first
        `rows` of a chunk MuJoCo cut short (rows_recorded), without the check that the whole chunk ran."""
        raise NotImplementedError

    def rows_recorded(self) -> int:
        """Rows the callback recorded in this chunk: the whole steps it completed, and the row of a step it began
        (stage 0 records the step's row) that MuJoCo then cut short: a NaN or huge acceleration makes MuJoCo warn,
        reset the data and step on without the callback finishing that step."""
        c = self.context[0]
        return int(c["row"]) + (1 if int(c["stage"]) != 0 else 0)

    def crash(self) -> tuple[int, str] | None:
        """(rows to keep, reason) where the plant crashed in the chunk just stepped (plants.quadrotor_kernel), else
        None."""
        return None

    def end_of_chunk(self) -> None:
        """After a whole chunk, before the loop asks the plant's termination(): what the plant must know of it."""
        return None

    def mass_rows(self, rows: int) -> np.ndarray | None:
        """(rows, m, m) the joint-space inertia at each step just taken, where the callback recorded it
        (the manipulator's, for V); None otherwise (1-DOF plants: V needs no M)."""
        return None

    def bind(self) -> None:
        """Point the plant's MjData at this run's context (the newest run on an MjData owns it); the
        plant holds the owner, so the context lives as long as the MjData can reach it."""
        from adaptive_mj.sim.native_step import projection_ready

        projection_ready(self.context)  # the projection compiled where this run has one (at its first bind)
        bind_context(self.plant.data, self.context)
        self.plant.native_owner = self

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        """The run is over: its MjData no longer points at the context (a later mj_step or mj_forward
        on it under a native callback changes nothing)."""
        unbind_context(self.plant.data)
        if self.plant.native_owner is self:
            self.plant.native_owner = None


def unbind_context(data) -> None:
    """Detach data from any context (userdata[0] = 0): the callback leaves it alone."""
    if data.userdata.size >= 1:
        data.userdata.view(np.int64)[0] = 0


def addr(array: np.ndarray) -> int:
    """The address of a C-contiguous float64/int64 array's first element (checked)."""
    if not array.flags.c_contiguous or array.dtype not in (np.float64, np.int64):
        raise TypeError(f"a buffer shared with compiled code must be C-contiguous float64/int64, got "
                        f"{array.dtype} (contiguous: {array.flags.c_contiguous})")
    return array.ctypes.data


def reached_functions(*fns: Callable) -> list[Callable]:
    """fns and every function they call through their globals, transitively, each once (source_key's inputs)."""
    todo, seen = list(fns), {id(fn) for fn in fns}
    for fn in todo:  # grows while it is walked
        for n in global_names(fn.__code__):
            v = fn.__globals__.get(n)
            if isinstance(v, pytypes.FunctionType) and id(v) not in seen:
                seen.add(id(v))
                todo.append(v)
    return todo


def source_key(*fns: Callable, extra: Iterable = ()) -> int:
    """A 60-bit key of the source of the modules defining fns and every function they call through their
    globals, transitively (reached_functions: an edit to any module a callback compiles in, however deep,
    changes the key), of the functions' closure values, and of `extra`."""
    h = hashlib.sha256()
    files: set[str] = set()
    for fn in reached_functions(*fns):
        try:
            files.add(inspect.getsourcefile(fn) or fn.__code__.co_filename)
        except TypeError:
            files.add(fn.__code__.co_filename)
        h.update(fn.__code__.co_code)
        h.update(repr([c.cell_contents for c in (fn.__closure__ or ())]).encode())
    for path in sorted(files):
        try:
            with open(path, "rb") as f:
                h.update(f.read())
        except OSError:
            h.update(path.encode())
    h.update(repr(list(extra)).encode())
    return int(h.hexdigest()[:15], 16) or 1


def unique_factory(factory: Callable, globals_: dict, key: int, *, what: str | None = None,
                   kind: str | None = None) -> Callable:
    """factory (a module-level function defining a cfunc named `callback`) with the given globals,
    its own name and its callback's qualified name made unique by `key`. numba names a compiled
    function's symbols, and its cache files, after the qualified name: two variants of one
    callback (two plant forms) loaded from the cache into one process would otherwise define the
    same symbol twice, which LLVM refuses (abort).

    The factory's `numba` global is compile_note.announcing's: a compile that is not a load from numba's disk
    cache is said on stderr, as `what` (e.g. "the 1-DOF control callback (plant form ...; sliding law)") of
    `kind` (e.g. "1-DOF callback": the last compile of one on this machine gives the estimate)."""
    from adaptive_mj.sim.compile_note import announcing

    tag = f"_{key:x}"
    code = factory.__code__
    if not any(isinstance(c, pytypes.CodeType) and c.co_name == "callback" for c in code.co_consts):
        raise TypeError(f"{factory.__qualname__} must define its compiled function as `callback` (unique_factory "
                        "names it apart per variant)")
    consts = tuple(c.replace(co_name=c.co_name + tag, co_qualname=code.co_name + tag + ".<locals>." + c.co_name + tag)
                   if isinstance(c, pytypes.CodeType) and c.co_name == "callback" else c for c in code.co_consts)
    code = code.replace(co_consts=consts, co_name=code.co_name + tag, co_qualname=code.co_qualname + tag)
    if "numba" in globals_:
        kind = kind or factory.__module__
        globals_ = {**globals_, "numba": announcing(globals_["numba"], what or f"the {kind} (variant {key:x})",
                                                    kind=kind, variant=f"{key:x}")}
    return pytypes.FunctionType(code, globals_, code.co_name)

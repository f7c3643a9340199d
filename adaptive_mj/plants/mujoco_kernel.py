"""What a MuJoCo plant kind declares beside its own code for the compiled control callback: its `MujocoKernel`.

The step's order is written once (adaptive_mj.sim.stage.control_stage); the one generic controller
(adaptive_mj.sim.native_mujoco) compiles it into MuJoCo's control callback with a kind's pieces and drives any
MuJoCo plant through its kind's declaration. Each kind declares (plants/one_dof_kernel.py: the 1-DOF MujocoPlant,
the lagged heave vehicle included; plants/manipulator_kernel.py: the multi-joint arms; plants/quadrotor_kernel.py:
the quadrotor):

    context        its own fields of the context record (after sim.native_step.STAGE_CONTEXT)
    supported      (plant, law) -> whether the compiled callback runs them
    variant        (plant, law) -> the KernelVariant compiled for them: its pieces (law_stage, apply_control,
                   record_row: plain Python functions compiled with injected globals: carray, fptr, iptr, the
                   pointer intrinsics, the stage functions), the functions of its cache key, how its compile is said
    setup          (plant, law, control, sensors, max_rows) -> KernelRun: the run's buffers, context values, law
                   gains record and row layout
    prepare        (controller, rows, noise, t, refs): the kind's part of a chunk's preparation (references,
                   noise, disturbance into its buffers)
    the controller hooks (crash, end_of_chunk, mass_rows): what the generic controller does differently for it:
                   termination (the quadrotor's crash), extra records (the arm's M(q)).

One row layout: every kind records a step's row in one flat float64 buffer (`rec`, rows × width) in the named
columns of `row_columns`: t, x, u, s, ref, θ̂, then the kind's extra record columns; one writer per kind's
record_row, one reader (sim.native_step.recorded_rows). The analytic chunk engine (sim.native_chunk) records the
same layout (record_columns).

Nothing here imports adaptive_mj.sim (plants is below sim): the compiled pieces reach what sim compiles in
through the globals it injects.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, NamedTuple

import numpy as np


class RecordColumns(NamedTuple):
    """Where each quantity of a step's row lies in a compiled loop's record buffer (first column of each; width:
    the row's length): t, x, u, s, ref, θ̂ (n_theta), then the kind's extra record columns. One definition for the
    compiled code that writes the rows and sim.native_step.recorded_rows that reads them."""

    t: int
    x: int
    u: int
    s: int
    ref: int
    theta: int
    extra: int
    width: int


def row_columns(nx, nu, ns, nref, nth, nextra):
    """The row layout of a kind whose row holds x (nx values), u (nu), s (ns), ref (nref), θ̂ (nth) and nextra
    columns of its own (compiled into the record writers too)."""
    x = 1
    u = x + nx
    s = u + nu
    ref = s + ns
    theta = ref + nref
    extra = theta + nth
    return RecordColumns(0, x, u, s, ref, theta, extra, extra + nextra)


def record_columns(n, nth):
    """The row layout of a plant of order n (scalar u and s) with n_theta parameters: the 1-DOF MuJoCo plants'
    and the analytic plants' (sim.native_chunk)."""
    return row_columns(n, 1, 1, n + 1, nth, 0)


class RowShapes(NamedTuple):
    """The shape of each quantity of one row (() a scalar), as the reader hands the rows back: x, u, s, ref, and
    the number of estimates and of the kind's extra columns."""

    x: tuple
    u: tuple
    s: tuple
    ref: tuple
    nth: int
    nextra: int = 0

    def columns(self) -> RecordColumns:
        size = lambda shape: int(np.prod(shape, dtype=np.int64))  # noqa: E731 (a short local helper)
        return row_columns(size(self.x), size(self.u), size(self.s), size(self.ref), self.nth, self.nextra)


@dataclass
class KernelRun:
    """What a kind's `setup` gives the generic controller for one run: buffers {name: array} (each a context field
    of its address; the stage's own, theta, rsum, prev, th, rate, ring, u_hold, delayed, rec, are the controller's),
    fields {name: value} of its own context, its law's gains record (a (1,) record array, or None where the law has
    none: the context's `gains` field holds its address), m (the control's width), the row's shapes, the reference
    order prepare's references are evaluated to, the width of s, and `state`: anything the kind's hooks keep."""

    buffers: dict[str, np.ndarray]
    fields: dict[str, Any]
    gains: np.ndarray | None
    m: int
    rows: RowShapes
    ref_order: int
    s_width: int
    state: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class KernelVariant:
    """One compiled variant of a kind's callback for a plant and law: mem_key (its key within the process),
    key_functions and key_extra (what its on-disk cache key hashes, beside the stage code sim compiles in),
    pieces(common, tag, inline) -> {"law_stage", "apply_control", "record_row"} compiled (common: the globals sim
    injects; tag: the variant's name suffix; inline: numba's njit that inlines), what and kind: how its compile is
    said, plugins: the user functions compiled in (a compile failure names them)."""

    mem_key: tuple
    key_functions: tuple
    key_extra: tuple
    pieces: Callable[[dict, str, Callable], dict[str, Any]]
    what: str
    kind: str
    plugins: tuple = ()


class Injected:
    """A name a kind's compiled pieces call that the generic controller injects into their globals (numba's carray,
    the pointer intrinsics, the stage functions, the law's compiled pieces: sim.native_step.compiled_callback): a
    module-level stand-in, so the pieces' source names it. Called unbound it says so; numba refuses to compile it, as
    it refused an undefined name."""

    def __init__(self, name: str):
        self.name = name

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        raise NotImplementedError(f"{self.name} is injected when the kind's callback is compiled "
                                  f"(adaptive_mj.sim.native_mujoco)")

    def __repr__(self) -> str:
        return f"Injected({self.name!r})"


# what sim.native_step.compiled_callback injects into every kind's pieces (its `common`)
carray = Injected("carray")  # numba.carray
fptr = Injected("fptr")  # an int64 address as a float64 pointer
iptr = Injected("iptr")  # an int64 address as an int64 pointer
pointer_at = Injected("pointer_at")  # the pointer stored at an address + offset (sim.native_context.pointer_at)
stage_estimate = Injected("stage_estimate")  # sim.stage.stage_estimate, compiled
sense = Injected("sense")  # sim.stage.sense, compiled


def _nothing(controller) -> None:
    return None


@dataclass(frozen=True)
class MujocoKernel:
    """A MuJoCo plant kind's kernel spec (see the module docstring); the generic controller
    (adaptive_mj.sim.native_mujoco) compiles and drives it.

    name: the kind's name (messages); plant_type() -> the class the callback drives; context: the kind's own
    context fields [(name, dtype[, shape])]; supported, variant, setup, prepare: see the module docstring;
    crash(controller) -> (rows to keep, reason) | None: termination found by the callback in the chunk just stepped;
    end_of_chunk(controller): what the plant must know after a whole chunk; mass_rows(controller, rows) -> (rows,
    m, m) | None: the joint-space inertia the callback recorded (extra record columns)."""

    name: str
    plant_type: Callable[[], type]
    context: tuple
    supported: Callable[[Any, Any], bool]
    variant: Callable[[Any, Any], KernelVariant]
    setup: Callable[..., KernelRun]
    prepare: Callable[..., None]
    crash: Callable[[Any], tuple[int, str] | None] = field(default=_nothing)
    end_of_chunk: Callable[[Any], None] = field(default=_nothing)
    mass_rows: Callable[[Any, int], np.ndarray | None] = field(default=lambda controller, rows: None)


def gains_record(record: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """A law's gains record as the callback reads it: a (1,) C-contiguous array of `dtype` exactly (the compiled
    code reads its fields at that dtype's offsets), checked."""
    if record.dtype != dtype or record.shape != (1,) or not record.flags.c_contiguous:
        raise TypeError(f"a law's native gains must be a (1,) record array of {dtype}, got {record.dtype} "
                        f"{record.shape}")
    return record

"""The one compiled controller of every MuJoCo plant kind: MuJoCo's control callback built from the kind's kernel
spec (plants.mujoco_kernel.MujocoKernel, declared beside the kind: plants/one_dof_kernel.py for the 1-DOF
MujocoPlant, plants/manipulator_kernel.py for the multi-joint arms, plants/quadrotor_kernel.py for the quadrotor),
and the controller that owns a run's context and steps the plant chunk by chunk.

The callback runs adaptive_mj.sim.stage.control_stage, the one definition of a control step's order that the Python
path (adaptive_mj.sim.loop.Controller) runs too, compiled (adaptive_mj.sim.native_step.compiled_callback) with the
kind's pieces (law_stage, apply_control, record_row). Physics advances with mj_step(m, d, nstep) in chunks, and
Python only works between chunks (events, noise, logging, divergence checks: adaptive_mj.sim.driver).

The controller does what every kind shares: the stage's buffers (the estimates, the delay line, the held control and
s), the context record (native_step.STAGE_CONTEXT, this module's MUJOCO_CONTEXT, then the kind's own fields), the
references at every stage time of a chunk, the rows in the one row layout (plants.mujoco_kernel.row_columns, read
by native_step.recorded_rows); the kind's hooks do the rest (its buffers, its part of a chunk's preparation, a
crash, the inertia it records). A plant dispatches here by declaration: its class names this module as its
compiled loop (protocol.Plant.compiled_loop) and its kernel spec (`mujoco_kernel`).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from adaptive_mj.laws.protocol import Law
from adaptive_mj.plants.mujoco_kernel import KernelVariant, MujocoKernel
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.sim import compile_note, native_step
from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_context import ContextOwner, addr, context_address, inlined, offsets, source_key

_i8 = np.int64
#: the context fields the generic controller fills for every kind, after STAGE_CONTEXT: the stage estimate's buffer,
#: the held s, the rows (the one row layout) and the law's gains record (addresses; gains 0 where the law has none)
MUJOCO_CONTEXT = [("th", _i8), ("s_hold", _i8), ("rec", _i8), ("gains", _i8)]
_compiled: dict = {}
_contexts: dict = {}


def kernel_context(kernel: MujocoKernel) -> np.dtype:
    """The context record of a kind: STAGE_CONTEXT, MUJOCO_CONTEXT, then the kind's own fields."""
    if kernel.name not in _contexts:
        _contexts[kernel.name] = native_step.context_dtype(MUJOCO_CONTEXT + list(kernel.context))
    return _contexts[kernel.name]


def compiled(kernel: MujocoKernel, variant: KernelVariant):
    """The cfunc of one kind's variant (in memory once per process, on disk across processes: its cache key hashes
    the source of every function compiled in, the kind's pieces and this module's context included)."""
    mem_key = (kernel.name,) + variant.mem_key
    if mem_key in _compiled:
        return _compiled[mem_key]
    import numba

    off = offsets()
    key = source_key(*variant.key_functions, native_step.callback_factory, stage_code.control_stage,
                     stage_code.stage_estimate, stage_code.end_stage, stage_code.sense, context_address,
                     kernel_context, extra=(off, numba.__version__) + tuple(variant.key_extra))
    dtype = kernel_context(kernel)

    def pieces(common: dict[str, Any], tag: str) -> dict[str, Any]:
        return variant.pieces(common, tag, inlined(numba))

    _compiled[mem_key] = compile_note.plugin_compiled(
        lambda: native_step.compiled_callback(dtype, off, key, pieces, what=variant.what, kind=variant.kind),
        variant.plugins, key)
    return _compiled[mem_key]


def supported(plant: Plant, law: Law) -> bool:
    """Whether the plant's kind's compiled callback runs this plant and law (its kernel spec's `supported`)."""
    kernel: MujocoKernel = plant.mujoco_kernel  # type: ignore[attr-defined]  # declared by every plant naming this module
    return kernel.supported(plant, law)


class MujocoController(ContextOwner):
    """Owns the context and buffers of one compiled run of a MuJoCo plant and steps it chunk by chunk.

    plant: a plant of a kind with a kernel spec (`plant.mujoco_kernel`); law: one the spec's `supported` accepts;
    control: the run's ControlTiming (mode, period in physics steps, delay); sensors: encoder quantisation and
    differentiated velocity (stage.Sensors) where the kind reads them (the arms)."""

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0, max_rows: int, *,
                 control: stage_code.ControlTiming | None = None, sensors: stage_code.Sensors | None = None):
        kernel: MujocoKernel | None = getattr(type(plant), "mujoco_kernel", None)
        if kernel is None or not isinstance(plant, kernel.plant_type()):
            raise TypeError(f"the compiled MuJoCo callback drives a plant whose kind declares its kernel spec "
                            f"(plants.mujoco_kernel.MujocoKernel), got a {type(plant).__name__}")
        self.kernel, self.plant, self.law, self.reference = kernel, plant, law, reference  # type: ignore[assignment]
        self.max_rows = int(max_rows)
        control = control if control is not None else stage_code.ControlTiming(period=plant.dt)
        run = kernel.setup(plant, law, control, sensors, self.max_rows)
        self.callback = compiled(kernel, kernel.variant(plant, law))
        nth, nst, m, d = len(law.names), plant.stages, run.m, control.delay
        self.run, self.nth, self.nst, self.m = run, nth, nst, m
        inc, weights = stage_code.TABLEAU[nst]
        self.stage_offsets = np.asarray(inc)  # RK4: c_i = a_i (see stage.TABLEAU)
        self.columns = run.rows.columns()
        self.theta = np.ascontiguousarray(np.array(theta_hat0, dtype=float).reshape(nth), dtype=np.float64)
        self.buffers = {  # everything the callback reaches by address: held here for the run's lifetime
            "theta": self.theta, "rsum": np.zeros(nth), "prev": np.zeros(nth), "th": np.zeros(nth),
            "rate": np.zeros(nth), "ring": np.zeros((d + 1, m)), "u_hold": np.zeros(m), "delayed": np.zeros(m),
            "s_hold": np.zeros(run.s_width), "rec": np.zeros(self.max_rows * self.columns.width), **run.buffers}
        self.gains = run.gains  # the law's record, held for the run's lifetime
        ctx = np.zeros(1, dtype=kernel_context(kernel))
        c = ctx[0]
        for name, buf in self.buffers.items():
            c[name] = addr(buf)
        c["nstages"], c["nth"], c["m"], c["h"], c["nbox"] = nst, nth, m, plant.dt, len(self.buffers["lower"])
        c["delay"], c["mode"], c["period_steps"], c["period"] = d, control.mode, control.steps, control.period
        c["inc"][:len(inc)], c["weights"][:len(weights)] = inc, weights
        if run.gains is not None:
            c["gains"] = run.gains.ctypes.data
        for name, value in run.fields.items():
            c[name] = value
        self.context = ctx
        self.bind()

    def chunk(self, rows: int, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        """Step `rows` physics steps; return (t, x, u, s, ref, theta_hat) rows, each (rows, ...): each row the state,
        reference and θ̂ at the step's start and the clamped control applied during it."""
        self.prepare(rows, noise)
        self.plant.step_native(rows)
        return self.finish(rows)

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """Set the buffers and the context up for the next `rows` physics steps (then the plant steps): the
        references at every stage time, then the kind's part (noise, disturbance, its own fields)."""
        if not 0 < rows <= self.max_rows:
            raise ValueError(f"rows must be in 1..{self.max_rows}, got {rows}")
        plant = self.plant
        t, refs = stage_code.stage_references(self.reference, plant.time, plant.dt, rows, self.stage_offsets,
                                              self.run.ref_order)
        self.kernel.prepare(self, rows, noise, t, refs)
        c = self.context[0]
        c["stage"], c["row"], c["rows"], c["t"] = 0, 0, rows, t[0]
        self.bind()

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """The rows the callback recorded over the `rows` steps just taken: (t, x, u, s, ref, theta_hat), shaped as
        the kind declares (partial: the first `rows` of a chunk MuJoCo cut short, ContextOwner.rows_recorded)."""
        return native_step.recorded_rows(self.context[0], self.buffers["rec"], self.columns, self.run.rows, rows,
                                         partial, "native callback")

    def extra_rows(self, rows: int) -> np.ndarray:
        """(rows, n_extra) the kind's extra record columns of the `rows` steps just taken."""
        col = self.columns
        return self.buffers["rec"][: rows * col.width].reshape(rows, col.width)[:, col.extra:col.width]

    def crash(self) -> tuple[int, str] | None:
        return self.kernel.crash(self)

    def end_of_chunk(self) -> None:
        self.kernel.end_of_chunk(self)

    def mass_rows(self, rows: int) -> np.ndarray | None:
        return self.kernel.mass_rows(self, rows)


#: what loop._native_controller takes of a compiled loop's module (protocol.Plant.compiled_loop)
Controller = MujocoController

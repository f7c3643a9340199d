"""The native closed loop for the quadrotor (adaptive_mj.plants.quadrotor): the flight laws' kernel
(adaptive_mj.laws.flight_kernel.flight_law: the geometric and the geometric adaptive law, their dead-zone and
robust modifications) compiled with numba into the C control callback, as the 1-DOF plants' and the arms' are
(adaptive_mj.sim.native, native_manipulator): MuJoCo calls it at every integrator stage and it runs
adaptive_mj.sim.stage.control_stage with this shape's pieces:
    _law_stage      at stage 0 the crash check on the state the last step left (plants.quadrotor.crash_check:
                    a crash stops the chunk's rows there); then x = [p; v; φ; Ω] measured from qpos/qvel
                    (plants.quadrotor.measure_into) plus the step's noise, the stage estimate, the law, the four
                    thrusts clamped into [0, T_max]
    _apply_control  ctrl of the four rotors
    _record_row     t, the true x (4, 3), the thrusts (4,), s (3,), the reference (5, 3), θ̂
The external force and torque of the events are held in xfrc_applied by the plant between chunks (events apply
only there). L1 augmentation's filters advance at each step's first stage from the last step's measured state and
thrusts (the Python path's step_ends, one step later and before anything reads them).
tests/test_native_flight.py shows the two paths give the same rows bit for bit.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from adaptive_mj.laws import flight_kernel
from adaptive_mj.laws.protocol import Law
from adaptive_mj.plants import quadrotor as quad
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.sim import native_step
from adaptive_mj.sim import stage as stage_code
from adaptive_mj.sim.native_context import ContextOwner, addr, context_address, inlined, offsets, source_key

if TYPE_CHECKING:
    from adaptive_mj.plants.quadrotor import QuadrotorPlant

    # injected by compiled(): numba's carray and the pointer intrinsics, the stage functions, the kernel
    carray: Any
    fptr: Any
    iptr: Any
    pointer_at: Any
    stage_estimate: Any
    flight_law: Any
    measure_into: Any
    crash_check: Any
    l1_update: Any

_i8, _f8 = np.int64, np.float64
CONTEXT = native_step.context_dtype([  # after stage.control_stage's fields (native_step.STAGE_CONTEXT)
    # settings
    ("maxrows", _i8), ("qadr", _i8), ("dadr", _i8), ("nq", _i8), ("nv", _i8), ("nu", _i8),
    # the crash check (plants.quadrotor.crash_check): its settings, the airborne flag, and a crash found (code > 0
    # at row crash_row, with its value, time and speed)
    ("cos_tilt", _f8), ("clearance", _f8), ("z0", _f8), ("airborne", _i8), ("crash_code", _i8), ("crash_row", _i8),
    ("crash_value", _f8), ("crash_t", _f8), ("crash_speed", _f8),
    # buffers (addresses)
    ("th", _i8), ("s_hold", _i8), ("ref", _i8), ("noise", _i8),
    ("rec_t", _i8), ("rec_x", _i8), ("rec_u", _i8), ("rec_s", _i8), ("rec_ref", _i8), ("rec_theta", _i8),
    ("x", _i8), ("act", _i8), ("lo", _i8), ("hi", _i8), ("P", _i8), ("G", _i8), ("Ainv", _i8), ("aug", _i8),
    ("R", _i8), ("F", _i8), ("tmp", _i8), ("u", _i8), ("s", _i8),
    # L1 augmentation's filters (P[P_L1] != 0): the predictor, the estimate, the last step's measured x and thrusts
    ("A", _i8), ("z_hat", _i8), ("sigma", _i8), ("x_prev", _i8), ("u_prev", _i8),
])
_compiled: dict = {}


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """This shape's law at a stage (adaptive_mj.sim.native_step; see the module docstring)."""
    base, mbase, off = io
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)  # noqa: F821 (injected)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.nv)  # noqa: F821 (injected)
    qa, da = ctx.qadr, ctx.dadr
    x = carray(fptr(ctx.x), (4, 3))  # noqa: F821 (injected)
    measure_into(qpos, qvel, qa, da, x)  # noqa: F821 (injected)
    noise = carray(fptr(ctx.noise), (ctx.maxrows, 4, 3))  # noqa: F821 (injected)
    for i in range(4):
        for j in range(3):
            x[i, j] = x[i, j] + noise[row, i, j]
    nth = ctx.nth
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)  # noqa: F821 (injected)
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)  # noqa: F821 (injected)
    P = carray(fptr(ctx.P), flight_kernel.P_SIZE)  # noqa: F821 (injected)
    tmp = carray(fptr(ctx.tmp), flight_kernel.TMP_SIZE)  # noqa: F821 (injected)
    if P[flight_kernel.P_L1] != 0.0 and stage == 0:  # L1: the last step's update (the Python path's step_ends)
        z_hat, x_prev = carray(fptr(ctx.z_hat), 6), carray(fptr(ctx.x_prev), (4, 3))  # noqa: F821 (injected)
        if ctx.step == 0:
            for i in range(3):
                z_hat[i] = x[1, i]
                z_hat[3 + i] = x[3, i]
        else:
            l1_update(x_prev, carray(fptr(ctx.u_prev), 4), th, P, carray(fptr(ctx.A), (4, 4)),  # noqa: F821
                      P[flight_kernel.P_AS], P[flight_kernel.P_WC], ctx.h, z_hat, carray(fptr(ctx.sigma), 6),  # noqa: F821
                      carray(fptr(ctx.aug), 6), carray(fptr(ctx.R), (3, 3)), tmp)  # noqa: F821
        for i in range(4):
            for j in range(3):
                x_prev[i, j] = x[i, j]
    r = carray(fptr(ctx.ref), (ctx.maxrows * ctx.nstages, 5, 3))[row * ctx.nstages + stage]  # noqa: F821
    u, s = carray(fptr(ctx.u), 4), carray(fptr(ctx.s), 3)  # noqa: F821 (injected)
    flight_law(x, r, th, carray(fptr(ctx.P), flight_kernel.P_SIZE), carray(fptr(ctx.G), (4, nth)),  # noqa: F821
               carray(fptr(ctx.Ainv), (4, 4)), carray(fptr(ctx.aug), 6), carray(fptr(ctx.R), (3, 3)),  # noqa: F821
               carray(fptr(ctx.F), 3), tmp, u, s, rate)  # noqa: F821 (injected)
    lo, hi = carray(fptr(ctx.lo), 4), carray(fptr(ctx.hi), 4)  # noqa: F821 (injected)
    u_hold, s_hold = carray(fptr(ctx.u_hold), 4), carray(fptr(ctx.s_hold), 3)  # noqa: F821 (injected)
    for i in range(4):
        u_hold[i] = min(max(u[i], lo[i]), hi[i])
    for i in range(3):
        s_hold[i] = s[i]


def _apply_control(ctx, io, row, u):
    """This shape's "apply": the four thrusts into their actuators' ctrl."""
    base, mbase, off = io
    ctrl = carray(fptr(pointer_at(base, off.ctrl)), ctx.nu)  # noqa: F821 (injected)
    act = carray(iptr(ctx.act), 4)  # noqa: F821 (injected)
    u_prev = carray(fptr(ctx.u_prev), 4)  # noqa: F821 (injected)
    for i in range(4):
        ctrl[act[i]] = u[i]
        if ctx.stage == 0:  # the step's applied thrusts, for L1's update at the next step
            u_prev[i] = u[i]


def _record_row(ctx, io, row, u, theta):
    """This shape's row: t, the true x (4, 3), the applied thrusts (4,), s (3,), the reference (5, 3), θ̂; first, at
    every step (sampled control too), the crash check on the state the last step left: a crash is noted with its
    row, and every later call is left alone (the loop keeps the rows before it, and checks them for divergence
    with this row's state)."""
    base, mbase, off = io
    maxrows, nth = ctx.maxrows, ctx.nth
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)  # noqa: F821 (injected)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.nv)  # noqa: F821 (injected)
    qa, da = ctx.qadr, ctx.dadr
    if ctx.crash_code == 0:
        code, value, airborne = crash_check(qpos[qa + 2], qpos[qa + 3], qpos[qa + 4], qpos[qa + 5],  # noqa: F821
                                            qpos[qa + 6], ctx.airborne != 0, ctx.z0, ctx.clearance, ctx.cos_tilt)
        ctx.airborne = 1 if airborne else 0
        if code != 0 and ctx.step > 0:
            ctx.crash_code, ctx.crash_row, ctx.crash_value, ctx.crash_t = code, row, value, ctx.t
            vx, vy, vz = qvel[da], qvel[da + 1], qvel[da + 2]
            ctx.crash_speed = (vx * vx + vy * vy + vz * vz) ** 0.5
            ctx.rows = row + 1  # this step's stages still run; every later call is left alone
    carray(fptr(ctx.rec_t), maxrows)[row] = ctx.t  # noqa: F821 (injected)
    rx = carray(fptr(ctx.rec_x), (maxrows, 4, 3))  # noqa: F821 (injected)
    measure_into(qpos, qvel, ctx.qadr, ctx.dadr, rx[row])  # noqa: F821 (injected)
    ru, rs = carray(fptr(ctx.rec_u), (maxrows, 4)), carray(fptr(ctx.rec_s), (maxrows, 3))  # noqa: F821
    rref = carray(fptr(ctx.rec_ref), (maxrows, 5, 3))  # noqa: F821 (injected)
    rth = carray(fptr(ctx.rec_theta), (maxrows, nth))  # noqa: F821 (injected)
    r = carray(fptr(ctx.ref), (maxrows * ctx.nstages, 5, 3))[row * ctx.nstages]  # noqa: F821 (injected)
    s_hold = carray(fptr(ctx.s_hold), 3)  # noqa: F821 (injected)
    for i in range(4):
        ru[row, i] = u[i]
    for i in range(3):
        rs[row, i] = s_hold[i]
    for k in range(5):
        for j in range(3):
            rref[row, k, j] = r[k, j]
    for i in range(nth):
        rth[row, i] = theta[i]


def compiled():
    """The control callback (a numba cfunc): in memory once per process, on disk across processes."""
    if "callback" in _compiled:
        return _compiled["callback"]
    import numba

    from adaptive_mj.numba_util import jit_tree

    off = offsets()
    key = source_key(native_step.callback_factory, stage_code.control_stage, _law_stage, _apply_control, _record_row,
                     flight_kernel.flight_law, flight_kernel.l1_update, quad.measure_into, quad.crash_check,
                     stage_code.stage_estimate, stage_code.end_stage, context_address,
                     extra=(off, numba.__version__, "flight"))

    def pieces(common: dict[str, Any], tag: str) -> dict[str, Any]:
        inline = inlined(numba)
        shape: dict[str, Any] = {"flight_law": jit_tree(flight_kernel.flight_law, numba.njit, tag=tag, inner=inline),
                                 "l1_update": jit_tree(flight_kernel.l1_update, numba.njit, tag=tag, inner=inline),
                                 "measure_into": jit_tree(quad.measure_into, inline, tag=tag),
                                 "crash_check": jit_tree(quad.crash_check, inline, tag=tag)}
        return {"law_stage": jit_tree(_law_stage, numba.njit, tag=tag, **common, **shape),
                "apply_control": jit_tree(_apply_control, inline, tag=tag, **common),
                "record_row": jit_tree(_record_row, inline, tag=tag, **common, **shape)}

    _compiled["callback"] = native_step.compiled_callback(
        CONTEXT, off, key, pieces, what="the quadrotor control callback (the flight laws and L1 filters)",
        kind="quadrotor callback")
    return _compiled["callback"]


def supported(plant: Plant, law: Law) -> bool:
    """Native path for the quadrotor: a QuadrotorPlant compiled with a userdata slot, a flight law the kernel
    computes (law.native: geometric, geometric_adaptive, l1_geometric), RK4 or a one-stage integrator."""
    from adaptive_mj.laws.flight import FlightLaw
    from adaptive_mj.plants.mujoco_plant import USERDATA_SLOTS
    from adaptive_mj.plants.quadrotor import QuadrotorPlant

    return (isinstance(plant, QuadrotorPlant) and isinstance(law, FlightLaw) and law.native
            and plant.stages in (1, 4) and plant.model.nuserdata >= USERDATA_SLOTS)


class NativeFlightController(ContextOwner):
    """Owns the context and buffers of one native quadrotor run (the interface of
    adaptive_mj.sim.native.NativeController)."""

    plant: QuadrotorPlant

    def __init__(self, plant: Plant, law: Law, reference, theta_hat0, max_rows: int, *,
                 control: stage_code.ControlTiming | None = None):
        from adaptive_mj.plants.quadrotor import QuadrotorPlant

        if not isinstance(plant, QuadrotorPlant):
            raise TypeError(f"the native flight callback drives a QuadrotorPlant, got a {type(plant).__name__}")
        self.plant, self.law, self.reference = plant, law, reference
        control = control if control is not None else stage_code.ControlTiming(period=plant.dt)
        self.callback = compiled()
        model = plant.model
        nth = len(law.names)
        self.nth, self.nst, self.max_rows = nth, plant.stages, int(max_rows)
        p = law.native_params()
        inc, weights = stage_code.TABLEAU[self.nst]
        self.stage_offsets = np.asarray(inc)
        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
        self.theta = f64(np.array(theta_hat0, dtype=float).reshape(nth))
        box = law.bounds
        lower, upper = box if box is not None else (np.full(nth, -np.inf), np.full(nth, np.inf))
        lo, hi = plant.ctrl_range
        rows, d = self.max_rows, control.delay
        self.buffers = {
            "theta": self.theta, "rsum": np.zeros(nth), "prev": np.zeros(nth), "th": np.zeros(nth),
            "rate": np.zeros(nth), "lower": f64(lower), "upper": f64(upper), "ring": np.zeros((d + 1, 4)),
            "u_hold": np.zeros(4), "s_hold": np.zeros(3), "delayed": np.zeros(4),
            "ref": np.zeros((rows * self.nst, 5, 3)), "noise": np.zeros((rows, 4, 3)), "rec_t": np.zeros(rows),
            "rec_x": np.zeros((rows, 4, 3)), "rec_u": np.zeros((rows, 4)), "rec_s": np.zeros((rows, 3)),
            "rec_ref": np.zeros((rows, 5, 3)), "rec_theta": np.zeros((rows, nth)), "x": np.zeros((4, 3)),
            "act": np.ascontiguousarray(plant.airframe.actuators, dtype=np.int64), "lo": f64(lo), "hi": f64(hi),
            "P": f64(p["P"]), "G": f64(p["G"]), "Ainv": f64(p["Ainv"]), "aug": np.zeros(6), "R": np.zeros((3, 3)),
            "F": np.zeros(3), "tmp": np.zeros(flight_kernel.TMP_SIZE), "u": np.zeros(4), "s": np.zeros(3),
            "A": f64(p["A"]), "z_hat": np.zeros(6), "sigma": np.zeros(6), "x_prev": np.zeros((4, 3)),
            "u_prev": np.zeros(4),
        }
        ctx = np.zeros(1, dtype=CONTEXT)
        c = ctx[0]
        for name, arr in self.buffers.items():
            c[name] = addr(arr)
        c["nstages"], c["nth"], c["m"], c["maxrows"] = self.nst, nth, 4, rows
        c["nbox"] = len(self.buffers["lower"])
        c["qadr"], c["dadr"], c["nq"], c["nv"], c["nu"] = plant.airframe.qpos, plant.airframe.qvel, model.nq, \
            model.nv, model.nu
        c["delay"], c["mode"], c["period_steps"], c["period"], c["h"] = d, control.mode, control.steps, \
            control.period, plant.dt
        c["inc"][:len(inc)], c["weights"][:len(weights)] = inc, weights
        c["cos_tilt"], c["clearance"], c["z0"] = plant.cos_tilt, plant.clearance, plant._z0
        c["airborne"] = int(plant._airborne)
        self.context = ctx
        self.bind()

    def chunk(self, rows: int, noise: np.ndarray | None) -> tuple[np.ndarray, ...]:
        self.prepare(rows, noise)
        self.plant.step_native(rows)
        return self.finish(rows)

    def prepare(self, rows: int, noise: np.ndarray | None) -> None:
        """The buffers and the context set up for the next `rows` physics steps."""
        if not 0 < rows <= self.max_rows:
            raise ValueError(f"rows must be in 1..{self.max_rows}, got {rows}")
        plant, nst, h = self.plant, self.nst, self.plant.dt
        t, refs = stage_code.stage_references(self.reference, plant.time, h, rows, self.stage_offsets, 4)
        b = self.buffers
        b["ref"][: rows * nst] = refs
        b["noise"][:rows] = 0.0 if noise is None else np.asarray(noise, dtype=float).reshape(rows, 4, 3)
        c = self.context[0]
        c["stage"], c["row"], c["rows"], c["t"] = 0, 0, rows, t[0]
        c["clearance"] = plant.clearance  # an event may have changed it (a payload released)
        self.bind()

    def finish(self, rows: int, *, partial: bool = False) -> tuple[np.ndarray, ...]:
        """The rows recorded over the `rows` steps just taken: (t, x (rows, 4, 3), u (rows, 4), s (rows, 3),
        ref (rows, 5, 3), θ̂ (rows, n_theta))."""
        c, b = self.context[0], self.buffers
        if not partial and (int(c["row"]) != rows or c["stage"] != 0):
            raise RuntimeError(f"native callback ran {int(c['row'])} steps (stage {int(c['stage'])}), expected {rows}")
        return (b["rec_t"][:rows].copy(), b["rec_x"][:rows].copy(), b["rec_u"][:rows].copy(),
                b["rec_s"][:rows].copy(), b["rec_ref"][:rows].copy(), b["rec_theta"][:rows].copy())

    def crash(self) -> tuple[int, str] | None:
        """(rows to keep, reason) of a crash the callback found in the chunk just stepped (the state a step left,
        checked at the next step's start; that step's row is recorded too, finish(keep + 1)), else None; the plant's
        termination() says the same from then on."""
        c = self.context[0]
        if int(c["crash_code"]) == 0:
            return None
        text = quad.crash_text(int(c["crash_code"]), float(c["crash_value"]), float(c["crash_t"]),
                               self.plant.crash_tilt, float(c["crash_speed"]))
        self.plant.crashed(text, airborne=True)
        return int(c["crash_row"]), text

    def end_of_chunk(self) -> None:
        """After a whole chunk: the plant checks the state its last step left (as the Python path does after every
        step), with the airborne flag the callback kept."""
        self.plant._airborne = bool(self.context[0]["airborne"])
        self.plant._check_crash()
        self.context[0]["airborne"] = int(self.plant._airborne)


#: what loop._native_controller takes of a compiled loop's module (protocol.Plant.compiled_loop)
Controller = NativeFlightController

"""The quadrotor's kernel (plants.quadrotor.QuadrotorPlant): the flight laws' kernel
(adaptive_mj.laws.flight_kernel.flight_law: the geometric and the geometric adaptive law, their dead-zone and
robust modifications) compiled with numba into the C control callback (the one generic controller,
adaptive_mj.sim.native_mujoco, builds and drives it from `KERNEL`, this kind's declaration): MuJoCo calls it at every
integrator stage and it runs adaptive_mj.sim.stage.control_stage with this kind's pieces:
    _law_stage      x = [p; v; φ; Ω] measured from qpos/qvel (plants.quadrotor.measure_into) plus the step's noise,
                    the stage estimate, the law, the four thrusts clamped into [0, T_max]
    _apply_control  ctrl of the four rotors, then RotorPy's rotor drag at the stage's state and thrusts into
                    qfrc_applied (plants.airframe.rotor_drag_into, as the Python path's callback applies it)
    _record_row     first, at every step, the crash check on the state the last step left (plants.quadrotor
                    .crash_check: a crash stops the chunk's rows there, the kind's termination); then t, the true x
                    (4, 3), the thrusts (4,), s (3,), the reference (5, 3), θ̂
The external force and torque of the events are held in xfrc_applied by the plant between chunks (events apply
only there). L1 augmentation's filters advance at each step's first stage from the last step's measured state and
thrusts (the Python path's step_ends, one step later and before anything reads them).
tests/test_native_flight.py shows the two paths give the same rows bit for bit. Nothing here imports
adaptive_mj.sim or numba at import time: `carray`, `fptr`, `iptr`, the pointer intrinsics, the stage functions and
the kernel's functions are globals the generic controller injects.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from adaptive_mj.laws import flight_kernel
from adaptive_mj.plants.mujoco_kernel import (Injected, KernelRun, KernelVariant, MujocoKernel, RowShapes, carray, fptr,
                                              iptr, pointer_at, row_columns, stage_estimate)

# the names the generic controller injects when it compiles this kind's pieces (plants.mujoco_kernel.Injected)
flight_law = Injected("flight_law")  # laws.flight_kernel.flight_law, compiled
measure_into = Injected("measure_into")  # plants.quadrotor.measure_into, compiled
crash_check = Injected("crash_check")  # plants.quadrotor.crash_check, compiled
l1_update = Injected("l1_update")  # laws.flight_kernel.l1_update, compiled
rotor_drag_into = Injected("rotor_drag_into")  # plants.airframe.rotor_drag_into, compiled

_i8, _f8 = np.int64, np.float64
#: this kind's context fields (after sim.native_step.STAGE_CONTEXT and the generic controller's own)
CONTEXT = (
    # settings
    ("maxrows", _i8), ("qadr", _i8), ("dadr", _i8), ("nq", _i8), ("nv", _i8), ("nu", _i8),
    # the rotor drag (plants.airframe.rotor_drag_into; drag_on 0: the model declares none): the body's id, the
    # MjData/MjModel sizes its arrays are read with
    ("drag_on", _i8), ("body", _i8), ("na", _i8), ("nbody", _i8), ("gain_w", _i8),
    # the crash check (plants.quadrotor.crash_check): its settings, the airborne flag, and a crash found (code > 0
    # at row crash_row, with its value, time and speed)
    ("cos_tilt", _f8), ("clearance", _f8), ("z0", _f8), ("airborne", _i8), ("crash_code", _i8), ("crash_row", _i8),
    ("crash_value", _f8), ("crash_t", _f8), ("crash_speed", _f8),
    # buffers (addresses)
    ("ref", _i8), ("noise", _i8),
    ("x", _i8), ("act", _i8), ("lo", _i8), ("hi", _i8), ("P", _i8), ("G", _i8), ("Ainv", _i8), ("aug", _i8),
    ("R", _i8), ("F", _i8), ("tmp", _i8), ("u", _i8), ("s", _i8),
    # L1 augmentation's filters (P[P_L1] != 0): the predictor, the estimate, the last step's measured x and thrusts
    ("A", _i8), ("z_hat", _i8), ("sigma", _i8), ("x_prev", _i8), ("u_prev", _i8),
    # the rotor drag's: each rotor's activation address, the hubs (4, 3), [k_eta, k_d, k_z], the wind (3,)
    ("actadr", _i8), ("rotors", _i8), ("drag", _i8), ("wind", _i8),
)


def _columns(nth):
    """The quadrotor's row layout (plants.mujoco_kernel.row_columns): t, x (4, 3), the thrusts (4,), s (3,), the
    reference (5, 3), θ̂ (nth,)."""
    return row_columns(12, 4, 3, 15, nth, 0)


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """This shape's law at a stage (adaptive_mj.sim.native_step; see the module docstring)."""
    base, mbase, off = io
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.nv)
    qa, da = ctx.qadr, ctx.dadr
    x = carray(fptr(ctx.x), (4, 3))
    measure_into(qpos, qvel, qa, da, x)
    noise = carray(fptr(ctx.noise), (ctx.maxrows, 4, 3))
    for i in range(4):
        for j in range(3):
            x[i, j] = x[i, j] + noise[row, i, j]
    nth = ctx.nth
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)
    P = carray(fptr(ctx.P), flight_kernel.P_SIZE)
    tmp = carray(fptr(ctx.tmp), flight_kernel.TMP_SIZE)
    if P[flight_kernel.P_L1] != 0.0 and stage == 0:  # L1: the last step's update (the Python path's step_ends)
        z_hat, x_prev = carray(fptr(ctx.z_hat), 6), carray(fptr(ctx.x_prev), (4, 3))
        if ctx.step == 0:
            for i in range(3):
                z_hat[i] = x[1, i]
                z_hat[3 + i] = x[3, i]
        else:
            l1_update(x_prev, carray(fptr(ctx.u_prev), 4), th, P, carray(fptr(ctx.A), (4, 4)),
                      P[flight_kernel.P_AS], P[flight_kernel.P_WC], ctx.h, z_hat, carray(fptr(ctx.sigma), 6),
                      carray(fptr(ctx.aug), 6), carray(fptr(ctx.R), (3, 3)), tmp)
        for i in range(4):
            for j in range(3):
                x_prev[i, j] = x[i, j]
    r = carray(fptr(ctx.ref), (ctx.maxrows * ctx.nstages, 5, 3))[row * ctx.nstages + stage]
    u, s = carray(fptr(ctx.u), 4), carray(fptr(ctx.s), 3)
    flight_law(x, r, th, carray(fptr(ctx.P), flight_kernel.P_SIZE), carray(fptr(ctx.G), (4, nth)),
               carray(fptr(ctx.Ainv), (4, 4)), carray(fptr(ctx.aug), 6), carray(fptr(ctx.R), (3, 3)),
               carray(fptr(ctx.F), 3), tmp, u, s, rate)
    lo, hi = carray(fptr(ctx.lo), 4), carray(fptr(ctx.hi), 4)
    u_hold, s_hold = carray(fptr(ctx.u_hold), 4), carray(fptr(ctx.s_hold), 3)
    for i in range(4):
        u_hold[i] = min(max(u[i], lo[i]), hi[i])
    for i in range(3):
        s_hold[i] = s[i]


def _apply_control(ctx, io, row, u):
    """This shape's "apply": the four thrusts into their actuators' ctrl; then the rotor drag at this stage into
    qfrc_applied (the Python path's QuadrotorPlant.apply_rotor_drag)."""
    base, mbase, off = io
    ctrl = carray(fptr(pointer_at(base, off.ctrl)), ctx.nu)
    act = carray(iptr(ctx.act), 4)
    u_prev = carray(fptr(ctx.u_prev), 4)
    for i in range(4):
        ctrl[act[i]] = u[i]
        if ctx.stage == 0:  # the step's applied thrusts, for L1's update at the next step
            u_prev[i] = u[i]
    if ctx.drag_on != 0:
        rotor_drag_into(carray(fptr(pointer_at(base, off.qvel)), ctx.nv), ctx.dadr,
                        carray(fptr(pointer_at(base, off.xmat)), ctx.nbody * 9)[ctx.body * 9:ctx.body * 9 + 9],
                        ctrl, carray(fptr(pointer_at(base, off.act)), max(ctx.na, 1)),
                        carray(fptr(pointer_at(mbase, off.actuator_gainprm)), (ctx.nu, ctx.gain_w)), act,
                        carray(iptr(ctx.actadr), 4), carray(fptr(ctx.lo), 4), carray(fptr(ctx.hi), 4),
                        carray(fptr(ctx.rotors), (4, 3)), carray(fptr(ctx.wind), 3), carray(fptr(ctx.drag), 3),
                        carray(fptr(pointer_at(base, off.qfrc_applied)), ctx.nv))



def _record_row(ctx, io, row, u, theta):
    """This shape's row in the record buffer's named columns (_columns): t, the true x (4, 3), the applied thrusts
    (4,), s (3,), the reference (5, 3), θ̂; first, at every step (sampled control too), the crash check on the state
    the last step left: a crash is noted with its row, and every later call is left alone (the loop keeps the rows
    before it, and checks them for divergence with this row's state)."""
    base, mbase, off = io
    maxrows, nth = ctx.maxrows, ctx.nth
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.nv)
    qa, da = ctx.qadr, ctx.dadr
    if ctx.crash_code == 0:
        code, value, airborne = crash_check(qpos[qa + 2], qpos[qa + 3], qpos[qa + 4], qpos[qa + 5],
                                            qpos[qa + 6], ctx.airborne != 0, ctx.z0, ctx.clearance, ctx.cos_tilt)
        ctx.airborne = 1 if airborne else 0
        if code != 0 and ctx.step > 0:
            ctx.crash_code, ctx.crash_row, ctx.crash_value, ctx.crash_t = code, row, value, ctx.t
            vx, vy, vz = qvel[da], qvel[da + 1], qvel[da + 2]
            ctx.crash_speed = (vx * vx + vy * vy + vz * vz) ** 0.5
            ctx.rows = row + 1  # this step's stages still run; every later call is left alone
    col = _columns(nth)
    first = ctx.rec + 8 * row * col.width  # the row's first column's address (8 bytes a column)
    rec = carray(fptr(first), col.width)
    rec[col.t] = ctx.t
    measure_into(qpos, qvel, ctx.qadr, ctx.dadr, carray(fptr(first + 8 * col.x), (4, 3)))
    r = carray(fptr(ctx.ref), (maxrows * ctx.nstages, 5, 3))[row * ctx.nstages]
    s_hold = carray(fptr(ctx.s_hold), 3)
    for i in range(4):
        rec[col.u + i] = u[i]
    for i in range(3):
        rec[col.s + i] = s_hold[i]
    for k in range(5):
        for j in range(3):
            rec[col.ref + 3 * k + j] = r[k, j]
    for i in range(nth):
        rec[col.theta + i] = theta[i]


def variant(plant, law) -> KernelVariant:
    """The one callback variant: the flight laws and L1 filters (their gains are run data, in P)."""
    from adaptive_mj.plants import airframe
    from adaptive_mj.plants import quadrotor as quad

    def pieces(common: dict[str, Any], tag: str, inline) -> dict[str, Any]:
        import numba

        from adaptive_mj.numba_util import jit_tree

        shape: dict[str, Any] = {"flight_law": jit_tree(flight_kernel.flight_law, numba.njit, tag=tag, inner=inline),
                                 "l1_update": jit_tree(flight_kernel.l1_update, numba.njit, tag=tag, inner=inline),
                                 "measure_into": jit_tree(quad.measure_into, inline, tag=tag),
                                 "crash_check": jit_tree(quad.crash_check, inline, tag=tag)}
        drag: dict[str, Any] = {"rotor_drag_into": jit_tree(airframe.rotor_drag_into, inline, tag=tag)}
        return {"law_stage": jit_tree(_law_stage, numba.njit, tag=tag, **common, **shape),
                "apply_control": jit_tree(_apply_control, inline, tag=tag, **common, **drag),
                "record_row": jit_tree(_record_row, inline, tag=tag, **common, **shape)}

    return KernelVariant(
        mem_key=("callback",),
        key_functions=(_law_stage, _apply_control, _record_row, _columns, flight_kernel.flight_law,
                       flight_kernel.l1_update, quad.measure_into, quad.crash_check, airframe.rotor_drag_into),
        key_extra=("flight",), pieces=pieces,
        what="the quadrotor control callback (the flight laws and L1 filters)", kind="quadrotor callback")


def supported(plant, law) -> bool:
    """Native path for the quadrotor: a QuadrotorPlant compiled with a userdata slot, a flight law the kernel
    computes (law.native: geometric, geometric_adaptive, l1_geometric), RK4 or a one-stage integrator."""
    from adaptive_mj.laws.flight import FlightLaw
    from adaptive_mj.plants.mujoco_plant import USERDATA_SLOTS
    from adaptive_mj.plants.quadrotor import QuadrotorPlant

    return (isinstance(plant, QuadrotorPlant) and isinstance(law, FlightLaw) and law.native
            and plant.stages in (1, 4) and plant.model.nuserdata >= USERDATA_SLOTS)


def setup(plant, law, control, sensors, max_rows: int) -> KernelRun:
    """The run's buffers (the law's arrays, the references, noise, work buffers, L1's filters) and context values
    (the airframe's addresses, the crash check's settings)."""
    model = plant.model
    nth = len(law.names)
    p = law.native_params()
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
    box = law.bounds
    lower, upper = box if box is not None else (np.full(nth, -np.inf), np.full(nth, np.inf))
    lo, hi = plant.ctrl_range
    rows, nst = max_rows, plant.stages
    buffers = {
        "lower": f64(lower), "upper": f64(upper),
        "ref": np.zeros((rows * nst, 5, 3)), "noise": np.zeros((rows, 4, 3)), "x": np.zeros((4, 3)),
        "act": np.ascontiguousarray(plant.airframe.actuators, dtype=np.int64), "lo": f64(lo), "hi": f64(hi),
        "P": f64(p["P"]), "G": f64(p["G"]), "Ainv": f64(p["Ainv"]), "aug": np.zeros(6), "R": np.zeros((3, 3)),
        "F": np.zeros(3), "tmp": np.zeros(flight_kernel.TMP_SIZE), "u": np.zeros(4), "s": np.zeros(3),
        "A": f64(p["A"]), "z_hat": np.zeros(6), "sigma": np.zeros(6), "x_prev": np.zeros((4, 3)),
        "u_prev": np.zeros(4),
        "actadr": np.ascontiguousarray(plant.airframe.act, dtype=np.int64),
        "rotors": f64(plant.airframe.rotors), "drag": f64(plant.airframe.drag), "wind": f64(model.opt.wind),
    }
    fields = {"maxrows": rows, "qadr": plant.airframe.qpos, "dadr": plant.airframe.qvel, "nq": model.nq,
              "nv": model.nv, "nu": model.nu, "cos_tilt": plant.cos_tilt, "clearance": plant.clearance,
              "z0": plant._z0, "airborne": int(plant._airborne), "drag_on": int(plant.airframe.has_drag),
              "body": plant.airframe.body, "na": model.na, "nbody": model.nbody,
              "gain_w": model.actuator_gainprm.shape[1]}
    return KernelRun(buffers, fields, None, m=4, rows=RowShapes((4, 3), (4,), (3,), (5, 3), nth), ref_order=4,
                     s_width=3)


def prepare(controller, rows: int, noise, t, refs) -> None:
    """The chunk's references and noise into the run's buffers, the wind and the crash check's clearance (an event
    may have changed them: a wind event, a payload released)."""
    plant, b = controller.plant, controller.buffers
    b["ref"][: rows * controller.nst] = refs
    b["noise"][:rows] = 0.0 if noise is None else np.asarray(noise, dtype=float).reshape(rows, 4, 3)
    b["wind"][:] = plant.model.opt.wind  # a wind event's, between chunks (the Python path reads opt.wind itself)
    controller.context[0]["clearance"] = plant.clearance


def crash(controller) -> tuple[int, str] | None:
    """(rows to keep, reason) of a crash the callback found in the chunk just stepped (the state a step left,
    checked at the next step's start; that step's row is recorded too, finish(keep + 1)), else None; the plant's
    termination() says the same from then on."""
    from adaptive_mj.plants import quadrotor as quad

    c = controller.context[0]
    if int(c["crash_code"]) == 0:
        return None
    text = quad.crash_text(int(c["crash_code"]), float(c["crash_value"]), float(c["crash_t"]),
                           controller.plant.crash_tilt, float(c["crash_speed"]))
    controller.plant.crashed(text, airborne=True)
    return int(c["crash_row"]), text


def end_of_chunk(controller) -> None:
    """After a whole chunk: the plant checks the state its last step left (as the Python path does after every
    step), with the airborne flag the callback kept."""
    plant, c = controller.plant, controller.context[0]
    plant._airborne = bool(c["airborne"])
    plant._check_crash()
    c["airborne"] = int(plant._airborne)


def _plant_type() -> type:
    from adaptive_mj.plants.quadrotor import QuadrotorPlant

    return QuadrotorPlant


#: the quadrotor's kernel spec (plants.quadrotor.QuadrotorPlant.mujoco_kernel)
KERNEL = MujocoKernel(name="quadrotor", plant_type=_plant_type, context=CONTEXT, supported=supported,
                      variant=variant, setup=setup, prepare=prepare, crash=crash, end_of_chunk=end_of_chunk)

"""The 1-DOF MuJoCo plants' kernel (plants.mujoco_plant.MujocoPlant: the heave vehicle, with its thruster lag of
order 3 too, the pendulum arm, the ship): the sliding law (`laws.sliding.sliding_law`, with composite adaptation
`laws.composite` in a variant of its own, or a law plugin's function) and the plant's regressor functions, compiled
with numba into the C control callback that MuJoCo calls without the GIL (the one generic controller,
adaptive_mj.sim.native_mujoco, builds and drives it from `KERNEL`, this kind's declaration).

At every call the callback runs adaptive_mj.sim.stage.control_stage, the step's order that the Python
controller (adaptive_mj.sim.loop.Controller) runs too, compiled (adaptive_mj.sim.native_step) with this module's
pieces: `_law_stage` (measure [q, q'] (+ noise), the stage estimate, the law on the plant's ModelForm, u
clamped), `_apply_control` (ctrl) and `_record_row` (the step's row). The heave vehicle with its thruster lag
(order 3, state [y, y', y'']) runs here too: `_acceleration` computes y'' from the thrust state and the forces
MuJoCo has just computed for the stage, the operations of plants.heave.HeavePlant.measure in its order.
The references at the stage times t_k + c_i h are evaluated in Python, vectorised, before each chunk (MuJoCo's
stage times are reproduced bit for bit).

Nothing is compiled in but the law, the plant's form and MuJoCo's struct layout, so the compiled callback is
cached on disk and reused by every process. tests/test_native.py shows the Python and native paths give the same
rows bit for bit. Nothing here imports adaptive_mj.sim or numba at import time: `carray`, `fptr`, the pointer
intrinsics, the stage functions and the law are globals the generic controller injects.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from adaptive_mj.laws.common import plugin_rate
from adaptive_mj.laws.composite import composite_rate, filter_gain, filter_step, stage_sums
from adaptive_mj.laws.plugin import PLUGIN_GAINS
from adaptive_mj.laws.sliding import SLIDING_GAINS, SlidingArrays, sliding_law_values
from adaptive_mj.plants.mujoco_kernel import (Injected, KernelRun, KernelVariant, MujocoKernel, RowShapes, carray, fptr,
                                              gains_record, pointer_at, record_columns, stage_estimate)

# the names the generic controller injects when it compiles this kind's pieces (plants.mujoco_kernel.Injected)
law = Injected("law")  # the law (_builtin_law, _composite_law or _plugin_law), compiled
user_law = Injected("user_law")  # a law plugin's function, compiled
gains_ptr = Injected("gains_ptr")  # an address as a pointer to the law's gains record
phi_fn = Injected("phi_fn")  # the plant form's φ, compiled
f_fn = Injected("f_fn")  # the plant form's f, compiled
h_fn = Injected("h_fn")  # the plant form's h, compiled
applied = Injected("applied")  # the law's `applied` (_composite_applied or _no_filters), compiled
acceleration = Injected("acceleration")  # _acceleration, compiled
applied_now = Injected("applied_now")  # _applied_now, compiled

_i8, _f8 = np.int64, np.float64
#: this kind's context fields (after sim.native_step.STAGE_CONTEXT and the generic controller's own)
CONTEXT = (
    # settings
    ("n", _i8), ("qadr", _i8), ("dadr", _i8), ("act", _i8), ("has_dist", _i8), ("lo", _f8), ("hi", _f8),
    # buffers (addresses)
    ("ref", _i8), ("noise", _i8), ("coeffs", _i8), ("gamma", _i8), ("theta0", _i8),
    ("params", _i8), ("xbuf", _i8), ("dist", _i8),
    # composite adaptation (laws.composite; the composite variant only): κ, the filters' gain 1 − e^(−λ_f h), and
    # buffers (n_theta + 1,): the filters z = [z_a, z_φ, z_τ], the pending step [y' at its start, φ̄, τ̄], and the
    # stage's [φ, f, h] (the law's, for the sums when the stage's control is applied)
    ("kappa", _f8), ("fgain", _f8), ("zf", _i8), ("fpend", _i8), ("fval", _i8),
    # order 3 (the heave vehicle with its thruster lag, plants.heave.HeavePlant.measure): y'' from the thrust state
    # act[act_adr] and the forces on the body `body`; gear_w, gain_w: the widths of MjModel's actuator_gear and
    # actuator_gainprm rows; applied_row: the external force the step's row reads, as the Python path's observe()
    # does before the step (the force the step before held)
    ("act_adr", _i8), ("body", _i8), ("gear_w", _i8), ("gain_w", _i8), ("applied_row", _f8),
)


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """This shape's law at a stage (adaptive_mj.sim.native_step): measure x = [q, q'] + the step's noise, the
    stage estimate θ̂_i, the law (the built-in sliding law or a plugin's) on the stage's reference, u clamped
    into [lo, hi] and held with s (u_hold, s_hold (1,)), the rate into ctx.rate."""
    base, mbase, off = io
    n, nth, nst = ctx.n, ctx.nth, ctx.nstages
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.qadr + 1)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.dadr + 1)
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)
    r0 = (row * nst + stage) * (n + 1)
    r = carray(fptr(ctx.ref), r0 + n + 1)[r0:r0 + n + 1]
    noise = carray(fptr(ctx.noise), (row + 1) * n)
    x = carray(fptr(ctx.xbuf), n)
    x[0] = qpos[ctx.qadr] + noise[row * n]
    x[1] = qvel[ctx.dadr] + noise[row * n + 1]
    if n == 3:  # y'' under the force this step applies (the Python path sets it before mj_step)
        x[2] = acceleration(ctx, base, mbase, off, applied_now(ctx, base, off, row)) + noise[row * n + 2]
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)
    u, s = law(x, r, th, ctx, carray(fptr(ctx.coeffs), n), carray(fptr(ctx.gamma), nth),
               carray(fptr(ctx.theta0), nth), lower, upper, carray(fptr(ctx.params), 1 << 30), rate)  # noqa: E501 (one carray per line)
    carray(fptr(ctx.u_hold), 1)[0] = min(max(u, ctx.lo), ctx.hi)
    carray(fptr(ctx.s_hold), 1)[0] = s


def _apply_control(ctx, io, row, u):
    """This shape's "apply" (adaptive_mj.sim.native_step): ctrl[act] = u, and with a disturbance the step's
    external force (force_offset + disturbance(t), prepared per chunk) into qfrc_applied, held over its stages;
    then the law's `applied` (the composite law's sums; nothing for the others)."""
    base, mbase, off = io
    applied(ctx, u)
    carray(fptr(pointer_at(base, off.ctrl)), ctx.act + 1)[ctx.act] = u[0]
    if ctx.has_dist != 0:
        qfrc = carray(fptr(pointer_at(base, off.qfrc_applied)), ctx.dadr + 1)
        qfrc[ctx.dadr] = carray(fptr(ctx.dist), row + 1)[row]


def _record_row(ctx, io, row, u, theta):
    """This shape's row (adaptive_mj.sim.native_step) in the record buffer's named columns (record_columns):
    t, true x = [q, q'], u, s, ref (n+1,), θ̂ at the step's start."""
    base, mbase, off = io
    n, nth = ctx.n, ctx.nth
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.qadr + 1)
    qvel = carray(fptr(pointer_at(base, off.qvel)), ctx.dadr + 1)
    r0 = row * ctx.nstages * (n + 1)
    r = carray(fptr(ctx.ref), r0 + n + 1)[r0:r0 + n + 1]
    col = record_columns(n, nth)
    rec = carray(fptr(ctx.rec), (row + 1) * col.width)
    o = row * col.width
    rec[o + col.t] = ctx.t
    rec[o + col.x] = qpos[ctx.qadr]
    rec[o + col.x + 1] = qvel[ctx.dadr]
    if n == 3:  # y'' as observe() reads it before the step: under the force the step before applied
        rec[o + col.x + 2] = acceleration(ctx, base, mbase, off, ctx.applied_row)
        ctx.applied_row = applied_now(ctx, base, off, row)
    rec[o + col.u] = u[0]
    rec[o + col.s] = carray(fptr(ctx.s_hold), 1)[0]
    for i in range(n + 1):
        rec[o + col.ref + i] = r[i]
    for j in range(nth):
        rec[o + col.theta + j] = theta[j]


def _applied_now(ctx, base, off, row):
    """[N] the external force on the joint over this step: the step's disturbance (prepared per chunk; the
    callback writes it into qfrc_applied in _apply_control, after the law's first stage) or the constant one
    (qfrc_applied as MujocoPlant.native_prestep left it)."""
    if ctx.has_dist != 0:
        return carray(fptr(ctx.dist), row + 1)[row]
    return carray(fptr(pointer_at(base, off.qfrc_applied)), ctx.dadr + 1)[ctx.dadr]


def _acceleration(ctx, base, mbase, off, applied):
    """y'' [m/s²] of the heave vehicle with its thruster lag, as plants.heave.HeavePlant.measure computes it, the
    same operations in the same order: (gear·gain·act + qfrc_passive − qfrc_bias + applied) / (mass + armature),
    the forces MuJoCo computed for this stage, `applied` the external force [N]."""
    a, dof, b = ctx.act, ctx.dadr, ctx.body
    gear = carray(fptr(pointer_at(mbase, off.actuator_gear)), (a + 1) * ctx.gear_w)[a * ctx.gear_w]
    gain = carray(fptr(pointer_at(mbase, off.actuator_gainprm)), (a + 1) * ctx.gain_w)[a * ctx.gain_w]
    act = carray(fptr(pointer_at(base, off.act)), ctx.act_adr + 1)[ctx.act_adr]
    passive = carray(fptr(pointer_at(base, off.qfrc_passive)), dof + 1)[dof]
    bias = carray(fptr(pointer_at(base, off.qfrc_bias)), dof + 1)[dof]
    mass = carray(fptr(pointer_at(mbase, off.body_mass)), b + 1)[b]
    armature = carray(fptr(pointer_at(mbase, off.dof_armature)), dof + 1)[dof]
    force = gear * gain * act + passive - bias + applied
    return force / (mass + armature)


def _builtin_law(x, r, th, ctx, coeffs, gamma, theta0, lower, upper, params, rate):
    """laws.sliding.sliding_law_values with the law's gains read by name from its SLIDING_GAINS record (at the
    context's `gains` address) and its arrays by name (the plant's functions are called here, as globals, so
    no function is passed as a value: numba could not cache that)."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]
    u, s, _ = sliding_law_values(x, r, th, gains, SlidingArrays(coeffs, gamma, theta0, lower, upper),
                                 phi_fn(x), f_fn(x), h_fn(x), rate)
    return u, s


def _composite_law(x, r, th, ctx, coeffs, gamma, theta0, lower, upper, params, rate):
    """laws.composite.CompositeSlidingLaw as the Python path runs it (loop.Controller: step_begins at stage 0,
    the law, step_ends): at each step's first stage the filters advance by the step before (laws.composite
    .filter_step; from the second step on) and the new step's pending sums start from y' measured now; then the
    sliding law (_builtin_law's), and from the second step on the composite correction of its rate
    (laws.composite.composite_rate). The stage's φ, f, h are kept in ctx.fval for _composite_applied."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]
    nz = ctx.nth + 1
    z, pending = carray(fptr(ctx.zf), nz), carray(fptr(ctx.fpend), nz)
    v = x[ctx.n - 1]
    if ctx.stage == 0:
        if ctx.step > 0:
            filter_step(z, pending, v, ctx.h, ctx.fgain, ctx.step == 1)
        for j in range(nz):
            pending[j] = 0.0
        pending[0] = v
    phi, f, h = phi_fn(x), f_fn(x), h_fn(x)
    fval = carray(fptr(ctx.fval), nz)
    n_p = phi.shape[0]
    for j in range(n_p):
        fval[j] = phi[j]
    fval[n_p] = f
    fval[n_p + 1] = h
    u, s, _ = sliding_law_values(x, r, th, gains, SlidingArrays(coeffs, gamma, theta0, lower, upper), phi, f, h,
                                 rate)
    if ctx.step > 0:
        composite_rate(z, th, ctx.kappa, gamma, theta0, lower, upper, rate)
    return u, s


def _composite_applied(ctx, u):
    """The composite law's `applied` (_apply_control): the stage's φ, f, h (ctx.fval) and its applied control u[0]
    into the step's pending sums with the stage's weight b_i (laws.composite.stage_sums)."""
    nz = ctx.nth + 1
    fval = carray(fptr(ctx.fval), nz)
    n_p = nz - 2
    stage_sums(carray(fptr(ctx.fpend), nz), ctx.weights[ctx.stage], fval[:n_p], fval[n_p], fval[n_p + 1],
               u[0])


def _no_filters(ctx, u):
    """The other laws' `applied` (_apply_control): nothing."""
    return None


def _plugin_law(x, r, th, ctx, coeffs, gamma, theta0, lower, upper, params, rate):
    """A law plugin's function (laws.plugin: law(x, ref, theta, phi, f, h, params, rate) -> (u, s)), then the
    shared modifications every plugin gets (laws.common.plugin_rate: a baseline's rate is zero, the
    dead-zone, the leakage and the projection), as PluginLaw does in Python; their scalars read by name from
    the law's PLUGIN_GAINS record (at the context's `gains` address)."""
    u, s = user_law(x, r, th, phi_fn(x), f_fn(x), h_fn(x), params, rate)
    shared = carray(gains_ptr(ctx.gains), 1)[0]
    s_abs = abs(s)
    signal = s_abs if shared.dz_on_s else abs(r[0] - x[0])
    plugin_rate(rate, th, s_abs, signal, shared.adapt, shared.dz_width, shared.sigma, shared.e_mod, theta0, gamma,
                lower, upper)
    return float(u), float(s)



def variant(plant, law) -> KernelVariant:
    """The callback variant for the plant's form and the law: the built-in sliding law, its composite variant
    (laws.composite, _composite_law) or a plugin's law function (adaptive_mj.laws.plugin), each compiled the same
    way (in memory per process, on disk across processes)."""
    p = law.native_params()
    plugin = p.get("plugin_law")
    composite = p.get("composite") is not None
    form = plant.form
    if composite and plugin is not None:
        raise ValueError("composite adaptation is a built-in sliding law's, not a plugin's")
    fns = (form.phi, form.f, form.h) + ((plugin,) if plugin is not None else ())
    mem_key = (composite,) + tuple((fn.__code__, tuple(c.cell_contents for c in (fn.__closure__ or ())))
                                   for fn in fns)

    def pieces(common: dict[str, Any], tag: str, inline) -> dict[str, Any]:
        """This shape's law_stage (the form's functions and the law inlined into it), apply_control and
        record_row."""
        import numba

        from adaptive_mj.numba_util import jit_tree, pointer

        forms: dict[str, Any] = {name: jit_tree(fn, inline, tag=tag)
                                 for name, fn in (("phi_fn", form.phi), ("f_fn", form.f), ("h_fn", form.h))}
        applied = jit_tree(_no_filters, inline, tag=tag)
        if composite:  # the sliding law with its filters (laws.composite), and their sums at each applied control
            # compiled apart, not inlined into the law: a cold compile of the variant 13-14 s instead of 16-17 s
            apart: dict[str, Any] = {name: jit_tree(fn, numba.njit, tag=tag, inner=inline)
                                     for name, fn in (("filter_step", filter_step), ("composite_rate", composite_rate),
                                                      ("stage_sums", stage_sums))}
            law = jit_tree(_composite_law, inline, tag=tag, carray=common["carray"], fptr=common["fptr"],
                           gains_ptr=pointer(numba.from_dtype(SLIDING_GAINS)), **forms, **apart)
            applied = jit_tree(_composite_applied, inline, tag=tag, carray=common["carray"], fptr=common["fptr"],
                               stage_sums=apart["stage_sums"])
        elif plugin is None:  # the law reads its gains through a pointer of its record's dtype (gains_ptr)
            law = jit_tree(_builtin_law, inline, tag=tag, carray=common["carray"],
                           gains_ptr=pointer(numba.from_dtype(SLIDING_GAINS)), **forms)
        else:
            law = jit_tree(_plugin_law, inline, tag=tag, user_law=jit_tree(plugin, inline, tag=tag),
                           carray=common["carray"], gains_ptr=pointer(numba.from_dtype(PLUGIN_GAINS)), **forms)
        third: dict[str, Any] = {"acceleration": jit_tree(_acceleration, inline, tag=tag, **common),  # order 3's y''
                                 "applied_now": jit_tree(_applied_now, inline, tag=tag, **common)}
        return {"law_stage": jit_tree(_law_stage, inline, tag=tag, law=law, **third, **common),
                "apply_control": jit_tree(_apply_control, inline, tag=tag, applied=applied, **common),
                "record_row": jit_tree(_record_row, inline, tag=tag, **third, **common,
                                       record_columns=jit_tree(record_columns, inline, tag=tag))}

    law_name = ("the sliding law with composite adaptation" if composite else "a sliding law" if plugin is None
                else f"law plugin {plugin.__module__}.{plugin.__qualname__}")
    return KernelVariant(
        mem_key=mem_key,
        key_functions=fns + (_law_stage, _apply_control, _record_row, _acceleration, _applied_now, _builtin_law,
                             _plugin_law, _composite_law, _composite_applied, _no_filters, sliding_law_values,
                             plugin_rate, record_columns),
        key_extra=(str(SLIDING_GAINS), str(PLUGIN_GAINS), "composite" if composite else "plain"),
        pieces=pieces,
        what=(f"the 1-DOF control callback (a plant form of order {form.order}, theta = {', '.join(form.names)}; "
              f"{law_name})"),
        kind="1-DOF callback", plugins=(plugin,) if plugin is not None else ())


def supported(plant, law) -> bool:
    """Native path: a 1-DOF MuJoCo plant (a MujocoPlant: the callback reads its joint and actuator
    addresses) of order 2 (its state is [q, q'], which the callback reads directly), or of order 3 where
    the plant says where its third state is read (MujocoPlant.native_third_state: the lagged heave
    vehicle), compiled with a userdata slot, a law the callback compiles (``law.native``: a sliding law, the sliding
    law with composite adaptation (laws.composite: its filters live in the context's buffers, the composite variant
    of the callback; continuous control only, as on the Python path) or a law plugin). A time-varying disturbance
    is evaluated per step in Python when a chunk is prepared and written into qfrc_applied by the callback."""
    from adaptive_mj.plants.mujoco_plant import USERDATA_SLOTS, MujocoPlant

    return (isinstance(plant, MujocoPlant)
            and (plant.order == 2 or plant.order == 3 and plant.native_third_state is not None) and law.native
            and plant.stages in (1, 4)
            and plant.model.nuserdata >= USERDATA_SLOTS)


def setup(plant, law, control, sensors, max_rows: int) -> KernelRun:
    """The run's buffers and context values: the law's arrays and gains, the joint's and actuator's addresses,
    the references', noise's and disturbance's buffers, the composite filters, order 3's addresses."""
    p = law.native_params()
    plugin = p.get("plugin_law")
    composite = p.get("composite")  # (κ, λ_f): the sliding law with composite adaptation (laws.composite)
    if composite is not None and control.sampled:
        raise ValueError("composite adaptation runs under continuous control only")
    gains = gains_record(p["gains"], SLIDING_GAINS if plugin is None else PLUGIN_GAINS)
    n, nth, nst = plant.form.order, len(law.names), plant.stages
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
    buffers = {
        "coeffs": f64(p["coeffs"]), "gamma": f64(p["gamma"]), "theta0": f64(p["theta0"]), "lower": f64(p["lower"]),
        "upper": f64(p["upper"]), "params": f64(p.get("plugin_params", np.zeros(1))),
        "ref": np.zeros(max_rows * nst * (n + 1)), "noise": np.zeros(max_rows * n), "xbuf": np.zeros(n),
        "dist": np.zeros(max_rows),
        "zf": np.zeros(nth + 1), "fpend": np.zeros(nth + 1), "fval": np.zeros(nth + 1),  # composite's filters
    }
    lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (-math.inf, math.inf)
    fields: dict[str, Any] = {"n": n, "lo": lo, "hi": hi, "qadr": plant._qadr, "dadr": plant._dadr,
                              "act": plant.actuator_id, "has_dist": int(plant.disturbance is not None)}
    if n == 3:  # y'' read as the plant's measure does (_acceleration)
        if plant.native_third_state is None:
            raise ValueError(f"the native callback reads the third state of the heave vehicle with its thruster "
                             f"lag only, not of a {type(plant).__name__}")
        fields["act_adr"], fields["body"] = plant.native_third_state
        fields["gear_w"], fields["gain_w"] = plant.model.actuator_gear.shape[1], plant.model.actuator_gainprm.shape[1]
    if composite is not None:  # κ and the filters' gain, as CompositeSlidingLaw.step_begins computes it
        fields["kappa"], fields["fgain"] = float(composite[0]), filter_gain(float(composite[1]), plant.dt)
    return KernelRun(buffers, fields, gains, m=1, rows=RowShapes((n,), (), (), (n + 1,), nth), ref_order=n,
                     s_width=1)


def prepare(controller, rows: int, noise, t, refs) -> None:
    """The chunk's references, noise and disturbance (the Python path's force per step, MujocoPlant.step, the
    same arithmetic) into the run's buffers, and the force the first row's y'' reads (_record_row)."""
    plant, b = controller.plant, controller.buffers
    n = plant.form.order
    b["ref"][: rows * controller.nst * (n + 1)] = refs.ravel()
    b["noise"][: rows * n] = 0.0 if noise is None else noise.ravel()
    if plant.disturbance is not None:
        dist = b["dist"]
        for k in range(rows):
            force = plant.force_offset
            force += plant.disturbance(float(t[k]))
            dist[k] = force
    controller.context[0]["applied_row"] = plant.data.qfrc_applied[plant._dadr]


def _plant_type() -> type:
    from adaptive_mj.plants.mujoco_plant import MujocoPlant

    return MujocoPlant


#: the 1-DOF MuJoCo plants' kernel spec (plants.mujoco_plant.MujocoPlant.mujoco_kernel)
KERNEL = MujocoKernel(name="1-DOF", plant_type=_plant_type, context=CONTEXT, supported=supported, variant=variant,
                      setup=setup, prepare=prepare)

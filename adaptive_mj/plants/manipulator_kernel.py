"""The multi-joint arms' kernel (plants.manipulator.ManipulatorPlant): the Slotine–Li law (and its baselines, or a
multi-joint law plugin) with the plant's regressor, compiled by numba into the C control callback that MuJoCo calls
at every stage of every physics step (the one generic controller, adaptive_mj.sim.native_mujoco, builds and drives
it from `KERNEL`, this kind's declaration).

At each stage the callback does what loop.Controller + SlotineLiLaw do in Python, with the
stage functions of adaptive_mj.sim.stage (the same source, compiled; sampled-data control
evaluates the law once per control period and holds it, as there):
measure x = [q; q̇] (+ noise), take the stage estimate θ̂_i = θ̂_k + h a_i k_{i-1},
evaluate reference_terms, then τ = Y θ̂ + τ_known and Yᵀ s on the live MjData (cdof, xpos,
xmat, subtree_com, cinert: MuJoCo has just computed them for this stage): by default by
Slotine–Li's O(n) recursions (regressor_kernel.rne_law_torque / rne_law_rate with
slotine_li_torque_output / slotine_li_rate_output, ctx.recursive; Y is never formed), else
(law.evaluation = "regressor", a law plugin) the regressor formed whole, the base map and
slotine_li_output (or the plugin's law); clamp τ, write ctrl = τ / gear, accumulate the
RK4-weighted rates, and after the last stage advance θ̂ once. The references at the stage times
are evaluated in Python, vectorised, before each chunk (MuJoCo's stage times are
reproduced bit for bit, each distinct time evaluated once). tests/test_native_manipulator.py
checks that the two paths give the same rows, bit for bit today, for the adaptive law,
both baselines, a base-parameter plant, saturation, dead-zones and noise, under RK4 and
Euler. (One known place where they could differ by an ulp: the dead-zone on the tracking
error compares ‖q̃‖, a plain sum here and np.linalg.norm in Python, with its width.)

Cost on the 6-joint UR5e with an unknown payload, RK4: about 1.6-1.7x a bare mj_step
(the Python path: ~60-80x); most of the difference is the regressor, see below.

The order of the step is not here: every compiled callback is adaptive_mj.sim.native_step's one
`control_stage`, into which this kind's three pieces are compiled: `_law_stage` (the regressor of a
kinematic tree read from MjData's kinematics, the law's point and output), `_apply_control` (τ / gear,
the disturbance torques) and `_record_row` (the row, and M(q) in the row's extra columns). Nothing here imports
adaptive_mj.sim or numba at import time: `carray`, `fptr`, `iptr`, the pointer intrinsics, the stage functions and
the law's pieces are globals the generic controller injects.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from adaptive_mj.laws.common import plugin_rate
from adaptive_mj.laws.plugin import PLUGIN_GAINS, joint_norm, tracking_error_norm
from adaptive_mj.laws.slotine_li import SLOTINE_LI_GAINS, SlotineLiArrays
from adaptive_mj.numba_util import jit_tree
from adaptive_mj.plants import regressor_kernel as rk
from adaptive_mj.plants.mujoco_kernel import (Injected, KernelRun, KernelVariant, MujocoKernel, RowShapes, carray, fptr,
                                              gains_record, iptr, pointer_at, row_columns, sense, stage_estimate)
from adaptive_mj.plants.regressor_kernel import rne_forward

# the names the generic controller injects when it compiles this kind's pieces (plants.mujoco_kernel.Injected)
regressor = Injected("regressor")  # _regressor, compiled
regressor_output = Injected("regressor_output")  # _regressor_output, compiled
law_torque = Injected("law_torque")  # regressor_kernel.rne_law_torque (or _no_law_torque), compiled
law_rate = Injected("law_rate")  # regressor_kernel.rne_law_rate (or _no_law_rate), compiled
law_recursive_output = Injected("law_recursive_output")  # _builtin_recursive_output (or _no_recursive_output), compiled
law_recursive_rate = Injected("law_recursive_rate")  # _builtin_recursive_rate (or _no_recursive_rate), compiled
torque_output = Injected("torque_output")  # laws.slotine_li.slotine_li_torque_output, compiled
rate_output = Injected("rate_output")  # laws.slotine_li.slotine_li_rate_output, compiled
ref_terms = Injected("ref_terms")  # laws.slotine_li.reference_terms, compiled
output = Injected("output")  # laws.slotine_li.slotine_li_output, compiled
law_point = Injected("law_point")  # _builtin_point or _plugin_point, compiled
law_output = Injected("law_output")  # _builtin_output or _plugin_output, compiled
user_point = Injected("user_point")  # a multi-joint law plugin's point, compiled
user_law = Injected("user_law")  # a multi-joint law plugin's law, compiled
gains_ptr = Injected("gains_ptr")  # an address as a pointer to the law's gains record
RNE_SCRATCH = rk.RNE_SCRATCH  # the regressor's scratch per body (injected with the same value)

_i8, _f8 = np.int64, np.float64
#: this kind's context fields (after sim.native_step.STAGE_CONTEXT and the generic controller's own): the run's
#: settings, and the addresses of its buffers and of the regressor's static arrays
CONTEXT = (
    # settings
    ("nv", _i8), ("nbody", _i8), ("nstd", _i8), ("nq", _i8), ("nu", _i8), ("maxrows", _i8), ("has_base", _i8),
    # the regressor's static arrays
    ("parent", _i8), ("dofadr", _i8), ("dofnum", _i8), ("rootid", _i8), ("body_col", _i8), ("body_known", _i8),
    ("col_arm", _i8), ("col_damp", _i8), ("need", _i8), ("bptr", _i8), ("bidx", _i8), ("bval", _i8),
    ("col_coul", _i8), ("coulomb_eps", _f8),  # the Coulomb friction columns tanh(q̇ / ε) (plant.friction_params)
    # plant and law constants
    ("qadr", _i8), ("act", _i8), ("gear", _i8), ("lo", _i8), ("hi", _i8), ("lam", _i8), ("kd", _i8),
    ("gamma", _i8), ("theta0", _i8),
    # work buffers
    ("x", _i8), ("s", _i8), ("qd_r", _i8), ("qdd_r", _i8), ("zero", _i8), ("u", _i8),
    ("y_std", _i8), ("y", _i8), ("tau_known", _i8), ("ref", _i8), ("noise", _i8), ("scratch", _i8),
    # sensors (stage.sense), disturbance torques and saturation-aware adaptation
    ("diff", _i8), ("has_dist", _i8), ("alpha", _f8), ("sense_period", _f8),
    ("quantum", _i8), ("q_prev", _i8), ("v_est", _i8), ("q_true", _i8), ("dist", _i8), ("sat_lo", _i8),
    ("sat_hi", _i8),
    # the size of MuJoCo's sparse M(q) (mjData.M), recorded at each step's start in the row's extra columns
    ("nM", _i8),
    # a multi-joint law plugin (laws.plugin.JointLawPlugin): its point's v and its params (nparams,)
    ("vpt", _i8), ("params", _i8), ("nparams", _i8),
    # Slotine–Li in O(n) (laws.slotine_li, evaluation "recursive"): 1 when on; π = B θ̂ (nstd,), Yᵀ s in the
    # standard parameters (nstd,), the s the rate takes (nv,)
    ("recursive", _i8), ("pi_std", _i8), ("rate_std", _i8), ("s_rate", _i8),
)

MODE_PD_GRAVITY = 2  # laws.slotine_li.Mode.PD_GRAVITY (the regressor at v = w = a = 0)


def _columns(nv, nth, nM):
    """The arm's row layout (plants.mujoco_kernel.row_columns): t, x = [q; q̇] (2, nv), τ (nv,), s (nv,), the
    reference (3, nv), θ̂ (nth,), then M(q) (nM,) as MuJoCo stores it (the extra record columns)."""
    return row_columns(2 * nv, nv, nv, 3 * nv, nth, nM)


# --- the regressor kernel, specialised -------------------------------------------
# regressor_kernel.regressor allocates its work arrays (about 60 small arrays per call
# with one unknown body) and builds each unit-parameter cinert with a generic 3x3
# product; it cost ~2.8 µs a call on the UR5e with an unknown payload, 4 calls a step
# under RK4, about as much as the physics. Here the same computation runs on scalars and
# one preallocated scratch buffer (cv, cw, ca: (nbody, 6) each), and the unit-parameter
# cinerts and forces are written out without their terms that are exactly zero (products
# with the unit vector's zeros, the h and m terms of an inertia unit): every remaining
# operation is the one regressor_kernel does, in the same order, and dropping a ±0 term
# from a sum or a factor 1.0 from a product changes no result, so Y and τ_known are the
# same numbers (at most the sign of an exact zero differs; inputs are finite).
# Columns that no base parameter reads are skipped. tests/test_native_manipulator.py
# checks equality against regressor_kernel on random states of several arms.


def _imul(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, x0, x1, x2, x3, x4, x5):
    """regressor_kernel._inert_mul on scalars."""
    return (I0 * x0 + I3 * x1 + I4 * x2 + (h1 * x5 - h2 * x4),
            I3 * x0 + I1 * x1 + I5 * x2 + (h2 * x3 - h0 * x5),
            I4 * x0 + I5 * x1 + I2 * x2 + (h0 * x4 - h1 * x3),
            m * x3 - (h1 * x2 - h2 * x1),
            m * x4 - (h2 * x0 - h0 * x2),
            m * x5 - (h0 * x1 - h1 * x0))


def _force(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, ca, cv, cw):
    """regressor_kernel._body_force on scalars: I ca + ½ [cv ×* (I cw) + cw ×* (I cv)]."""
    f0, f1, f2, f3, f4, f5 = _imul(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, ca[0], ca[1], ca[2], ca[3], ca[4], ca[5])
    for rep in range(2):
        if rep == 0:
            x, y = cw, cv
        else:
            x, y = cv, cw
        t0, t1, t2, t3, t4, t5 = _imul(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, x[0], x[1], x[2], x[3], x[4], x[5])
        w0, w1, w2, l0, l1, l2 = y[0], y[1], y[2], y[3], y[4], y[5]
        f0 += 0.5 * (w1 * t2 - w2 * t1 + l1 * t5 - l2 * t4)
        f1 += 0.5 * (w2 * t0 - w0 * t2 + l2 * t3 - l0 * t5)
        f2 += 0.5 * (w0 * t1 - w1 * t0 + l0 * t4 - l1 * t3)
        f3 += 0.5 * (w1 * t5 - w2 * t4)
        f4 += 0.5 * (w2 * t3 - w0 * t5)
        f5 += 0.5 * (w0 * t4 - w1 * t3)
    return f0, f1, f2, f3, f4, f5


def _force_rot(I0, I1, I2, I3, I4, I5, ca, cv, cw):
    """_force for a cinert with no first moment and no mass (h = m = 0): its terms in h and m
    are zeros, left out (the sums of the rest are the same numbers); the linear part is 0."""
    f0 = I0 * ca[0] + I3 * ca[1] + I4 * ca[2]
    f1 = I3 * ca[0] + I1 * ca[1] + I5 * ca[2]
    f2 = I4 * ca[0] + I5 * ca[1] + I2 * ca[2]
    for rep in range(2):
        if rep == 0:
            x, y = cw, cv
        else:
            x, y = cv, cw
        t0 = I0 * x[0] + I3 * x[1] + I4 * x[2]
        t1 = I3 * x[0] + I1 * x[1] + I5 * x[2]
        t2 = I4 * x[0] + I5 * x[1] + I2 * x[2]
        w0, w1, w2 = y[0], y[1], y[2]
        f0 += 0.5 * (w1 * t2 - w2 * t1)
        f1 += 0.5 * (w2 * t0 - w0 * t2)
        f2 += 0.5 * (w0 * t1 - w1 * t0)
    return f0, f1, f2


def _project(parent, dofadr, dofnum, cdof, b, f0, f1, f2, f3, f4, f5, Y, col):
    """Y[j, col] += cdof_j · f for every dof j on the path from body b to the world (regressor_kernel._project_col)."""
    x = b
    while x > 0:
        for j in range(dofadr[x], dofadr[x] + dofnum[x]):
            Y[j, col] += (cdof[j, 0] * f0 + cdof[j, 1] * f1 + cdof[j, 2] * f2
                          + cdof[j, 3] * f3 + cdof[j, 4] * f4 + cdof[j, 5] * f5)
        x = parent[x]


def _unit_column(parent, dofadr, dofnum, cdof, b, I0, I1, I2, I3, I4, I5, h0, h1, h2, m, ca, cv, cw, Y, col):
    f0, f1, f2, f3, f4, f5 = _force(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, ca, cv, cw)
    _project(parent, dofadr, dofnum, cdof, b, f0, f1, f2, f3, f4, f5, Y, col)


def _regressor(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp,  # noqa: C901 (a compiled kernel)
              dof_col_coul, arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity,
              v, w, a, Y, tau_known, scratch, need):
    """regressor_kernel.regressor (same arguments and numbers) with its work arrays in scratch (18 nbody).

    need (n_standard,): 0 for a column nobody reads (not in the base map), left at 0."""
    nbody = parent.shape[0]
    nv = v.shape[0]
    ncol = Y.shape[1]
    cv = scratch[0:6 * nbody].reshape((nbody, 6))
    cw = scratch[6 * nbody:12 * nbody].reshape((nbody, 6))
    ca = scratch[12 * nbody:18 * nbody].reshape((nbody, 6))
    for j in range(nv):
        tau_known[j] = 0.0
        for c in range(ncol):
            Y[j, c] = 0.0
    rne_forward(parent, dofadr, dofnum, cdof, gravity, v, w, a, scratch)  # cv, cw, ca: the O(n) law's own pass
    for b in range(1, nbody):
        col = body_col[b]
        if body_known[b] == 0 and col < 0:
            continue
        cab, cvb, cwb = ca[b], cv[b], cw[b]
        if body_known[b] != 0:
            ib = cinert[b]
            f0, f1, f2, f3, f4, f5 = _force(ib[0], ib[1], ib[2], ib[3], ib[4], ib[5], ib[6], ib[7], ib[8], ib[9],
                                            cab, cvb, cwb)
            x = b
            while x > 0:
                for j in range(dofadr[x], dofadr[x] + dofnum[x]):
                    tau_known[j] += (cdof[j, 0] * f0 + cdof[j, 1] * f1 + cdof[j, 2] * f2
                                     + cdof[j, 3] * f3 + cdof[j, 4] * f4 + cdof[j, 5] * f5)
                x = parent[x]
        if col >= 0:
            root = rootid[b]
            r0 = xpos[b, 0] - subtree_com[root, 0]
            r1 = xpos[b, 1] - subtree_com[root, 1]
            r2 = xpos[b, 2] - subtree_com[root, 2]
            X = xmat[b]
            rr = r0 * r0 + r1 * r1 + r2 * r2
            # m: cinert_of_params(e_0) without its zero terms
            if need[col] != 0:
                _unit_column(parent, dofadr, dofnum, cdof, b, (-r0) * r0 + rr, (-r1) * r1 + rr, (-r2) * r2 + rr,
                             (-r0) * r1, (-r0) * r2, (-r1) * r2, r0, r1, r2, 1.0, cab, cvb, cwb, Y, col)
            # m c_x, m c_y, m c_z: h = the body's axis in world coordinates
            for c in range(3):
                if need[col + 1 + c] == 0:
                    continue
                h0, h1, h2 = X[c], X[3 + c], X[6 + c]
                hr2 = 2.0 * (h0 * r0 + h1 * r1 + h2 * r2)
                _unit_column(parent, dofadr, dofnum, cdof, b,
                             -(h0 * r0) - r0 * h0 + hr2, -(h1 * r1) - r1 * h1 + hr2, -(h2 * r2) - r2 * h2 + hr2,
                             -(h0 * r1) - r0 * h1, -(h0 * r2) - r0 * h2, -(h1 * r2) - r1 * h2,
                             h0, h1, h2, 0.0, cab, cvb, cwb, Y, col + 1 + c)
            # Ixx, Ixy, Iyy, Ixz, Iyz, Izz: R E Rᵀ for the unit symmetric E
            for u in range(6):
                if need[col + 4 + u] == 0:
                    continue
                if u == 0:
                    pa, pb = 0, 0
                elif u == 1:
                    pa, pb = 0, 1
                elif u == 2:
                    pa, pb = 1, 1
                elif u == 3:
                    pa, pb = 0, 2
                elif u == 4:
                    pa, pb = 1, 2
                else:
                    pa, pb = 2, 2
                x0a, x1a, x2a = X[pa], X[3 + pa], X[6 + pa]
                if pa == pb:
                    i00, i11, i22 = x0a * x0a, x1a * x1a, x2a * x2a
                    i01, i02, i12 = x0a * x1a, x0a * x2a, x1a * x2a
                else:
                    x0b, x1b, x2b = X[pb], X[3 + pb], X[6 + pb]
                    i00, i11, i22 = x0b * x0a + x0a * x0b, x1b * x1a + x1a * x1b, x2b * x2a + x2a * x2b
                    i01, i02, i12 = x0b * x1a + x0a * x1b, x0b * x2a + x0a * x2b, x1b * x2a + x1a * x2b
                f0, f1, f2 = _force_rot(i00, i11, i22, i01, i02, i12, cab, cvb, cwb)
                x = b
                while x > 0:
                    for j in range(dofadr[x], dofadr[x] + dofnum[x]):
                        Y[j, col + 4 + u] += cdof[j, 0] * f0 + cdof[j, 1] * f1 + cdof[j, 2] * f2
                    x = parent[x]
    for j in range(nv):
        if dof_col_arm[j] >= 0:
            Y[j, dof_col_arm[j]] = a[j]
        else:
            tau_known[j] += arm_known[j] * a[j]
        if dof_col_damp[j] >= 0:
            Y[j, dof_col_damp[j]] = v[j]
        else:
            tau_known[j] += damp_known[j] * v[j]
        if dof_col_coul[j] >= 0:
            Y[j, dof_col_coul[j]] = math.tanh(v[j] / coulomb_eps)


_KERNEL = None


def kernel():
    """_regressor compiled with numba (once per process; the helpers it calls with it); called as
    regressor_kernel.regressor with two more arguments: scratch (18 nbody,) float64 and need
    (n_standard,) int64."""
    global _KERNEL
    if _KERNEL is None:
        import numba

        _KERNEL = jit_tree(_regressor, numba.njit)
    return _KERNEL


def _apply_control(ctx, io, row, u):
    """This shape's "apply" (adaptive_mj.sim.native_step): ctrl = τ / gear on each joint's actuator, and the
    step's disturbance torques into qfrc_applied, held over its stages."""
    base, mbase, off = io
    nv = ctx.nv
    ctrl = carray(fptr(pointer_at(base, off.ctrl)), ctx.nu)
    act, gear = carray(iptr(ctx.act), nv), carray(fptr(ctx.gear), nv)
    for j in range(nv):
        ctrl[act[j]] = u[j] / gear[j]
    if ctx.has_dist != 0:
        qfrc = carray(fptr(pointer_at(base, off.qfrc_applied)), nv)
        dist = carray(fptr(ctx.dist), (ctx.maxrows, nv))
        for j in range(nv):
            qfrc[j] = dist[row, j]



def _record_row(ctx, io, row, u, theta):
    """This shape's row (adaptive_mj.sim.native_step) in the record buffer's named columns (_columns): t, true
    x = [q; q̇], u, s, ref, θ̂ at the step's start, and M(q) as MuJoCo computed it for this stage (mj_forward at the
    step's start), for V = ½ sᵀMs + ...: copied, not recomputed per row in Python
    (plants.manipulator.ManipulatorPlant.full_mass)."""
    base, mbase, off = io
    nv, nth, maxrows, nst, nM = ctx.nv, ctx.nth, ctx.maxrows, ctx.nstages, ctx.nM
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)
    qvel = carray(fptr(pointer_at(base, off.qvel)), nv)
    qadr, s_hold = carray(iptr(ctx.qadr), nv), carray(fptr(ctx.s_hold), nv)
    r = carray(fptr(ctx.ref), (maxrows * nst, 3, nv))[row * nst]
    col = _columns(nv, nth, nM)
    rec = carray(fptr(ctx.rec), (maxrows, col.width))[row]
    rec[col.t] = ctx.t
    for j in range(nv):
        rec[col.x + j] = qpos[qadr[j]]
        rec[col.x + nv + j] = qvel[j]
        rec[col.u + j] = u[j]
        rec[col.s + j] = s_hold[j]
        for k in range(3):
            rec[col.ref + k * nv + j] = r[k, j]
    for i in range(nth):
        rec[col.theta + i] = theta[i]
    Md = carray(fptr(pointer_at(base, off.M)), nM)
    for k in range(nM):
        rec[col.extra + k] = Md[k]


def _law_stage(ctx, io, stage, row, theta, prev, lower, upper):
    """One evaluation of the Slotine–Li law at a stage: measure x (+ noise), the stage estimate, the
    regressor on the live MjData, τ clamped into u_hold (and s into s_hold), the rate into ctx.rate."""
    base, mbase, off = io
    nv, nb, nth, nstd = ctx.nv, ctx.nbody, ctx.nth, ctx.nstd
    qpos = carray(fptr(pointer_at(base, off.qpos)), ctx.nq)
    qvel = carray(fptr(pointer_at(base, off.qvel)), nv)
    r = carray(fptr(ctx.ref), (ctx.maxrows * ctx.nstages, 3, nv))[row * ctx.nstages + stage]
    off_cdof, off_xpos, off_xmat, off_subcom, off_cinert = off.cdof, off.xpos, off.xmat, off.subtree_com, off.cinert
    off_arm, off_damp, off_gravity = off.dof_armature, off.dof_damping, off.gravity
    th, rate = carray(fptr(ctx.th), nth), carray(fptr(ctx.rate), nth)
    x = carray(fptr(ctx.x), (2, nv))
    s, qd_r, qdd_r = carray(fptr(ctx.s), nv), carray(fptr(ctx.qd_r), nv), carray(fptr(ctx.qdd_r), nv)
    noise = carray(fptr(ctx.noise), (ctx.maxrows, 2, nv))
    qadr, q_true = carray(iptr(ctx.qadr), nv), carray(fptr(ctx.q_true), nv)
    for j in range(nv):
        q_true[j] = qpos[qadr[j]]
    sense(q_true, qvel, noise[row], carray(fptr(ctx.quantum), nv), ctx.diff != 0, stage == 0,
          ctx.step == 0, ctx.alpha, ctx.sense_period, carray(fptr(ctx.q_prev), nv),
          carray(fptr(ctx.v_est), nv), x)
    stage_estimate(theta, prev, ctx.inc[stage], ctx.h, lower, upper, th)
    v, w, a = law_point(ctx, x, r, s, qd_r, qdd_r)
    Y_std, tau_known = carray(fptr(ctx.y_std), (nv, nstd)), carray(fptr(ctx.tau_known), nv)
    cdof, xpos = carray(fptr(pointer_at(base, off_cdof)), (nv, 6)), carray(fptr(pointer_at(base, off_xpos)), (nb, 3))  # noqa: E501 (one carray per line)
    xmat, subcom = carray(fptr(pointer_at(base, off_xmat)), (nb, 9)), carray(fptr(pointer_at(base, off_subcom)), (nb, 3))  # noqa: E501 (one carray per line)
    cinert = carray(fptr(pointer_at(base, off_cinert)), (nb, 10))
    gravity = carray(fptr(mbase + off_gravity), 3)
    arm, damp = carray(fptr(pointer_at(mbase, off_arm)), nv), carray(fptr(pointer_at(mbase, off_damp)), nv)
    parent, dofadr = carray(iptr(ctx.parent), nb), carray(iptr(ctx.dofadr), nb)
    dofnum, rootid = carray(iptr(ctx.dofnum), nb), carray(iptr(ctx.rootid), nb)
    body_col, body_known = carray(iptr(ctx.body_col), nb), carray(iptr(ctx.body_known), nb)
    col_arm, col_damp = carray(iptr(ctx.col_arm), nv), carray(iptr(ctx.col_damp), nv)
    col_coul, eps = carray(iptr(ctx.col_coul), nv), ctx.coulomb_eps
    scratch, need = carray(fptr(ctx.scratch), RNE_SCRATCH * nb), carray(iptr(ctx.need), nstd)
    u = carray(fptr(ctx.u), nv)
    if ctx.recursive != 0:  # Slotine–Li in O(n): Y is never formed
        bptr, bidx = carray(iptr(ctx.bptr), nth + 1), carray(iptr(ctx.bidx), 1 << 30)
        bval = carray(fptr(ctx.bval), 1 << 30)
        law_torque(parent, dofadr, dofnum, rootid, body_col, body_known, col_arm, col_damp, col_coul, arm, damp,
                   eps, cdof, xpos, xmat, subcom, cinert, gravity, v, w, a, th, ctx.has_base, bptr, bidx, bval,
                   carray(fptr(ctx.pi_std), max(nstd, 1)), tau_known, scratch)
        s_rate = carray(fptr(ctx.s_rate), nv)
        adapting, s_norm = law_recursive_output(ctx, x, r, tau_known, s, u, s_rate, lower, upper)
        if adapting:
            law_rate(parent, dofadr, dofnum, rootid, body_col, col_arm, col_damp, col_coul, eps, cdof, xpos,
                     xmat, subcom, v, a, s_rate, ctx.has_base, bptr, bidx, bval,
                     carray(fptr(ctx.rate_std), max(nstd, 1)), rate, scratch)
        law_recursive_rate(ctx, th, rate, s_norm, adapting, lower, upper)
    else:
        regressor_output(ctx, x, r, v, w, a, th, s, u, rate, lower, upper, parent, dofadr, dofnum, rootid, body_col,
                         body_known, col_arm, col_damp, col_coul, arm, damp, eps, cdof, xpos, xmat, subcom, cinert,
                         gravity, Y_std, tau_known, scratch, need)
    lo, hi = carray(fptr(ctx.lo), nv), carray(fptr(ctx.hi), nv)
    u_hold, s_hold = carray(fptr(ctx.u_hold), nv), carray(fptr(ctx.s_hold), nv)
    for j in range(nv):
        v = u[j]
        if v < lo[j]:
            v = lo[j]
        if v > hi[j]:
            v = hi[j]
        u_hold[j] = v
        s_hold[j] = s[j]


def _regressor_output(ctx, x, r, v, w, a, th, s, u, rate, lower, upper, parent, dofadr, dofnum, rootid, body_col,
                      body_known, col_arm, col_damp, col_coul, arm, damp, eps, cdof, xpos, xmat, subcom, cinert,
                      gravity, Y_std, tau_known, scratch, need):
    """The regressor form: Y formed whole (the specialised kernel, then Y = Y_std B with a base map), then the
    law's output on it (Slotine–Li's slotine_li_output or a plugin's law)."""
    nv, nth = ctx.nv, ctx.nth
    regressor(parent, dofadr, dofnum, rootid, body_col, body_known, col_arm, col_damp, col_coul, arm, damp, eps,
              cdof, xpos, xmat, subcom, cinert, gravity, v, w, a, Y_std, tau_known, scratch, need)
    if ctx.has_base != 0:  # Y = Y_std B, B stored by columns as (pointer, row index, value)
        Y = carray(fptr(ctx.y), (nv, nth))
        bptr, bidx = carray(iptr(ctx.bptr), nth + 1), carray(iptr(ctx.bidx), 1 << 30)
        bval = carray(fptr(ctx.bval), 1 << 30)
        for j in range(nv):
            for c in range(nth):
                acc = 0.0
                for p in range(bptr[c], bptr[c + 1]):
                    acc += Y_std[j, bidx[p]] * bval[p]
                Y[j, c] = acc
    else:
        Y = Y_std
    law_output(ctx, x, r, Y, tau_known, th, s, u, rate, lower, upper)


def _builtin_point(ctx, x, r, s, qd_r, qdd_r):
    """Slotine–Li's point: s, q̇_r, q̈_r (reference_terms) and the regressor at (q̇, q̇_r, q̈_r); PD + gravity's at
    v = w = a = 0. Returns (v, w, a)."""
    nv = ctx.nv
    ref_terms(x, r, carray(fptr(ctx.lam), nv), s, qd_r, qdd_r)
    if carray(gains_ptr(ctx.gains), 1)[0].mode == MODE_PD_GRAVITY:
        zero = carray(fptr(ctx.zero), nv)
        return zero, zero, zero
    return x[1], qd_r, qdd_r


def _builtin_output(ctx, x, r, Y, tau_known, th, s, u, rate, lower, upper):
    """slotine_li_output with the law's gains read by name from its SLOTINE_LI_GAINS record (at the context's
    `gains` address) and its arrays by name (τ unclamped into u, the rate into rate)."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]
    e_norm = tracking_error_norm(x, r) if not gains.dz_on_s else 0.0
    arrays = SlotineLiArrays(carray(fptr(ctx.kd), ctx.nv), carray(fptr(ctx.gamma), ctx.nth),
                             carray(fptr(ctx.theta0), ctx.nth), lower, upper,
                             carray(fptr(ctx.sat_lo), ctx.nv), carray(fptr(ctx.sat_hi), ctx.nv))
    output(Y, tau_known, th, s, e_norm, gains, arrays, u, rate)


def _builtin_recursive_output(ctx, x, r, tau_model, s, u, s_rate, lower, upper):
    """slotine_li_torque_output (the O(n) form's τ and the s the rate takes), the gains read by name from the
    SLOTINE_LI_GAINS record, the arrays by name. Returns (adapting, ‖s‖)."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]
    e_norm = tracking_error_norm(x, r) if not gains.dz_on_s else 0.0
    arrays = SlotineLiArrays(carray(fptr(ctx.kd), ctx.nv), carray(fptr(ctx.gamma), ctx.nth),
                             carray(fptr(ctx.theta0), ctx.nth), lower, upper,
                             carray(fptr(ctx.sat_lo), ctx.nv), carray(fptr(ctx.sat_hi), ctx.nv))
    return torque_output(tau_model, s, e_norm, gains, arrays, u, s_rate)


def _builtin_recursive_rate(ctx, th, rate, s_norm, adapting, lower, upper):
    """slotine_li_rate_output: θ' = Γ⁻¹ Yᵀ s (or 0), then the modifications."""
    gains = carray(gains_ptr(ctx.gains), 1)[0]
    arrays = SlotineLiArrays(carray(fptr(ctx.kd), ctx.nv), carray(fptr(ctx.gamma), ctx.nth),
                             carray(fptr(ctx.theta0), ctx.nth), lower, upper,
                             carray(fptr(ctx.sat_lo), ctx.nv), carray(fptr(ctx.sat_hi), ctx.nv))
    rate_output(rate, th, s_norm, adapting, gains, arrays)


def _no_recursive_output(ctx, x, r, tau_model, s, u, s_rate, lower, upper):
    """A plugin law needs Y: the O(n) form is never on (ctx.recursive = 0)."""
    return False, 0.0


def _no_recursive_rate(ctx, th, rate, s_norm, adapting, lower, upper):
    """A plugin law needs Y: the O(n) form is never on (ctx.recursive = 0)."""
    return


def _no_law_torque(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp, dof_col_coul,
                   arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity, v, w, a, theta,
                   has_base, bptr, bidx, bval, pi, tau, scratch):
    """A plugin law's variant: the O(n) recursions (regressor_kernel.rne_law_torque) are never run (ctx.recursive
    = 0), so they are not compiled into it (about 40 % of the arm callback's compile)."""
    return


def _no_law_rate(parent, dofadr, dofnum, rootid, body_col, dof_col_arm, dof_col_damp, dof_col_coul, coulomb_eps,
                 cdof, xpos, xmat, subtree_com, v, a, s, has_base, bptr, bidx, bval, rate_std, rate, scratch):
    """A plugin law's variant: regressor_kernel.rne_law_rate is never run (ctx.recursive = 0; _no_law_torque)."""
    return


def _plugin_point(ctx, x, r, s, qd_r, qdd_r):
    """A JointLawPlugin's point(x, ref, params, v, w, a): where the regressor is evaluated. Returns (v, w, a)."""
    v = carray(fptr(ctx.vpt), ctx.nv)
    user_point(x, r, carray(fptr(ctx.params), ctx.nparams), v, qd_r, qdd_r)
    return v, qd_r, qdd_r


def _plugin_output(ctx, x, r, Y, tau_known, th, s, u, rate, lower, upper):
    """A JointLawPlugin's law(x, ref, theta, Y, tau_known, params, u, s, rate), then the shared modifications
    (laws.common.plugin_rate with ‖s‖ and ‖q̃‖), as laws.plugin.JointPluginLaw does in Python."""
    nth = ctx.nth
    user_law(x, r, th, Y, tau_known, carray(fptr(ctx.params), ctx.nparams), u, s, rate)
    shared = carray(gains_ptr(ctx.gains), 1)[0]
    s_abs = joint_norm(s)
    signal = s_abs if shared.dz_on_s else tracking_error_norm(x, r)
    plugin_rate(rate, th, s_abs, signal, shared.adapt, shared.dz_width, shared.sigma, shared.e_mod,
                carray(fptr(ctx.theta0), nth), carray(fptr(ctx.gamma), nth), lower, upper)



def plugin_functions(law):
    """(point, law) of a multi-joint law plugin for `variant`, or None for Slotine–Li and its baselines."""
    from adaptive_mj.laws.plugin import JointKernelLaw

    p = law.native_params() if isinstance(law, JointKernelLaw) else {}  # an installed plugin's or a built-in kind's
    return (p["plugin_point"], p["plugin_law"]) if "plugin_point" in p else None


def variant(plant, law) -> KernelVariant:
    """The callback variant for the law: Slotine–Li and its baselines, or (point, law) of a JointLawPlugin
    (laws.plugin) compiled the same way into the same step."""
    from adaptive_mj.laws.slotine_li import (reference_terms, slotine_li_output, slotine_li_rate_output,
                                             slotine_li_torque_output)

    plugin = plugin_functions(law)
    fns = () if plugin is None else tuple(plugin)
    mem_key = ("callback",) + tuple((fn.__code__, tuple(c.cell_contents for c in (fn.__closure__ or ())))
                                    for fn in fns)

    def pieces(common: dict[str, Any], tag: str, inline) -> dict[str, Any]:
        """This shape's law_stage (the regressor compiled apart, the law's point and output inlined into it),
        apply_control and record_row."""
        import numba

        from adaptive_mj.numba_util import pointer

        common = {**common, "MODE_PD_GRAVITY": MODE_PD_GRAVITY, "RNE_SCRATCH": rk.RNE_SCRATCH,
                  # the law reads its gains through a pointer of
                  "gains_ptr": pointer(numba.from_dtype(SLOTINE_LI_GAINS if plugin is None else PLUGIN_GAINS))}
        # Slotine–Li's O(n) recursions (ctx.recursive: a built-in law's evaluation "recursive"; a plugin needs Y)
        recursions: dict[str, Any] = {"law_torque": jit_tree(rk.rne_law_torque, numba.njit, tag=tag, inner=inline),
                                      "law_rate": jit_tree(rk.rne_law_rate, numba.njit, tag=tag, inner=inline)}
        if plugin is None:
            law_point = jit_tree(_builtin_point, inline, tag=tag,
                                 ref_terms=jit_tree(reference_terms, inline, tag=tag), **common)
            law_output = jit_tree(_builtin_output, inline, tag=tag,
                                  output=jit_tree(slotine_li_output, inline, tag=tag), **common)
            recursive_output = jit_tree(_builtin_recursive_output, inline, tag=tag,
                                        torque_output=jit_tree(slotine_li_torque_output, inline, tag=tag), **common)
            recursive_rate = jit_tree(_builtin_recursive_rate, inline, tag=tag,
                                      rate_output=jit_tree(slotine_li_rate_output, inline, tag=tag), **common)
        else:
            point, user = plugin
            law_point = jit_tree(_plugin_point, inline, tag=tag, user_point=jit_tree(point, inline, tag=tag),
                                 **common)
            law_output = jit_tree(_plugin_output, inline, tag=tag, user_law=jit_tree(user, inline, tag=tag),
                                  **common)
            recursive_output = jit_tree(_no_recursive_output, inline, tag=tag, **common)
            recursive_rate = jit_tree(_no_recursive_rate, inline, tag=tag, **common)
            recursions = {"law_torque": jit_tree(_no_law_torque, inline, tag=tag),
                          "law_rate": jit_tree(_no_law_rate, inline, tag=tag)}
        regressor_output = jit_tree(_regressor_output, numba.njit, tag=tag,
                                    regressor=jit_tree(_regressor, numba.njit, tag=tag, inner=inline),
                                    law_output=law_output, **common)
        return {"law_stage": jit_tree(_law_stage, numba.njit, tag=tag, regressor_output=regressor_output, **recursions,
                                      law_recursive_output=recursive_output, law_recursive_rate=recursive_rate,
                                      law_point=law_point, **common),
                "apply_control": jit_tree(_apply_control, inline, tag=tag, **common),
                "record_row": jit_tree(_record_row, inline, tag=tag, **common)}

    law_name = ("Slotine-Li or one of its baselines" if plugin is None
                else f"law plugin {fns[1].__module__}.{fns[1].__qualname__}")
    return KernelVariant(
        mem_key=mem_key,
        key_functions=fns + (_law_stage, _apply_control, _record_row, _regressor, reference_terms,
                             slotine_li_output, _builtin_point, _builtin_output, _regressor_output,
                             _builtin_recursive_output, _builtin_recursive_rate, _no_recursive_output,
                             _no_recursive_rate, _no_law_torque, _no_law_rate, slotine_li_torque_output,
                             slotine_li_rate_output, rk.rne_law_torque, rk.rne_law_rate, rk.rne_torque, rk.rne_rate,
                             rk.rne_forward, rk._force_add, rk._bilinear_grad, rk._cinert_scalars, rk._cross,
                             _plugin_point, _plugin_output, plugin_rate, _columns),
        key_extra=(str(SLOTINE_LI_GAINS), str(PLUGIN_GAINS)),
        pieces=pieces,
        what=f"the arm control callback (a kinematic tree's regressor; {law_name})", kind="arm callback",
        plugins=(fns[1], fns[0]) if plugin is not None else ())


def supported(plant, law) -> bool:
    """Native path for manipulators: a ManipulatorPlant (the callback reads its joint addresses and
    regressor arrays) compiled with a userdata slot, a Slotine–Li law (or baseline: the callback
    compiles slotine_li_output) using that plant's regressor, RK4 or a one-stage integrator."""
    from adaptive_mj.laws.plugin import JointKernelLaw
    from adaptive_mj.laws.slotine_li import SlotineLiLaw
    from adaptive_mj.plants.manipulator import ManipulatorPlant
    from adaptive_mj.plants.mujoco_plant import USERDATA_SLOTS

    if not (isinstance(plant, ManipulatorPlant) and isinstance(law, (SlotineLiLaw, JointKernelLaw)) and law.native):
        return False
    return (plant.stages in (1, 4) and law.regressor is plant.regressor
            and len(law.names) == len(plant.names) and int(law.m) == int(plant.m)
            and plant.model.nuserdata >= USERDATA_SLOTS)


def setup(plant, law, control, sensors, max_rows: int) -> KernelRun:
    """The run's buffers (the regressor's static arrays, the law's arrays, the work buffers) and context values."""
    from adaptive_mj.plants.manipulator import base_map_columns

    model, reg = plant.model, plant.regressor
    nv, nb = int(model.nv), int(model.nbody)
    nth, nstd = len(law.names), int(reg.n_standard)
    p = law.native_params()
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731 (a short local converter)
    i64 = lambda a: np.ascontiguousarray(a, dtype=np.int64)  # noqa: E731 (a short local converter)
    lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (np.full(nv, -np.inf), np.full(nv, np.inf))
    rows, nst = max_rows, plant.stages
    buf = {  # everything the callback reaches by address: held by the controller for the run's lifetime
        "parent": i64(reg.parent), "dofadr": i64(reg.dofadr), "dofnum": i64(reg.dofnum),
        "rootid": i64(reg.rootid), "body_col": i64(reg.body_col), "body_known": i64(reg.body_known),
        "col_arm": i64(reg.col_arm), "col_damp": i64(reg.col_damp), "col_coul": i64(reg.col_coul),
        "qadr": i64(plant._qadr), "act": i64(plant._act), "gear": f64(plant._gear),
        "lo": f64(np.broadcast_to(lo, (nv,))), "hi": f64(np.broadcast_to(hi, (nv,))),
        "lam": f64(p.get("lam", np.zeros(nv))), "kd": f64(p.get("kd", np.zeros(nv))), "gamma": f64(p["gamma"]),
        "theta0": f64(p["theta0"]), "lower": f64(p["lower"]), "upper": f64(p["upper"]),
        "x": np.zeros((2, nv)), "s": np.zeros(nv), "qd_r": np.zeros(nv), "qdd_r": np.zeros(nv),
        "zero": np.zeros(nv), "u": np.zeros(nv),
        "y_std": np.zeros((nv, nstd)), "y": np.zeros((nv, nth)), "tau_known": np.zeros(nv),
        "scratch": np.zeros(rk.RNE_SCRATCH * nb), "pi_std": np.zeros(max(nstd, 1)),
        "rate_std": np.zeros(max(nstd, 1)), "s_rate": np.zeros(nv),
        "ref": np.zeros((rows * nst, 3, nv)), "noise": np.zeros((rows, 2, nv)),
        "quantum": f64(sensors.quantum if sensors is not None else np.zeros(nv)), "q_prev": np.zeros(nv),
        "v_est": np.zeros(nv), "q_true": np.zeros(nv), "dist": np.zeros((rows, nv)),
        "sat_lo": f64(p.get("sat_lo", np.full(nv, -np.inf))), "sat_hi": f64(p.get("sat_hi", np.full(nv, np.inf))),
        "vpt": np.zeros(nv), "params": f64(p.get("plugin_params", np.zeros(1))),
    }
    B = reg.base_map
    if B is None and nstd != nth:
        raise ValueError(f"the law has {nth} parameters, the regressor {nstd}")
    buf.update(base_map_columns(B, nstd, nth))
    gains = gains_record(p["gains"], SLOTINE_LI_GAINS if "plugin_law" not in p else PLUGIN_GAINS)
    recursive = int(bool(p.get("recursive", False)))
    if recursive and "plugin_law" in p:  # its variant has no recursions compiled in (_no_law_torque)
        raise ValueError("a law plugin's arm callback evaluates the regressor whole, not Slotine-Li's recursions")
    sense_period = control.period if control.sampled else plant.dt
    fields = {"nv": nv, "nbody": nb, "nstd": nstd, "nq": model.nq, "nu": model.nu, "maxrows": rows, "nM": model.nM,
              "nparams": len(buf["params"]), "has_base": int(B is not None), "recursive": recursive,
              "coulomb_eps": reg.coulomb_eps, "sense_period": sense_period,
              "diff": int(sensors is not None and sensors.differentiated),
              "alpha": sensors.alpha(sense_period) if sensors is not None else 0.0,
              "has_dist": int(plant.joint_disturbance is not None)}
    return KernelRun(buf, fields, gains, m=nv, rows=RowShapes((2, nv), (nv,), (nv,), (3, nv), nth, int(model.nM)),
                     ref_order=2, s_width=nv)


def prepare(controller, rows: int, noise, t, refs) -> None:
    """The chunk's references, noise and disturbance torques into the run's buffers."""
    plant, b, m = controller.plant, controller.buffers, controller.m
    b["ref"][: rows * controller.nst] = refs
    b["noise"][:rows] = 0.0 if noise is None else np.asarray(noise, dtype=float).reshape(rows, 2, m)
    if plant.joint_disturbance is not None:
        b["dist"][:rows] = plant.joint_disturbance.rows(t)


def mass_rows(controller, rows: int) -> np.ndarray:
    """(rows, m, m) M(q) at the start of each of the `rows` steps just taken, as MuJoCo computed it in the step (the
    row's extra columns: the same numbers ManipulatorPlant.mass_matrices computes from the logged q, without its
    four MuJoCo calls per row)."""
    return controller.plant.full_mass(np.ascontiguousarray(controller.extra_rows(rows)))


def _plant_type() -> type:
    from adaptive_mj.plants.manipulator import ManipulatorPlant

    return ManipulatorPlant


#: the multi-joint arms' kernel spec (plants.manipulator.ManipulatorPlant.mujoco_kernel)
KERNEL = MujocoKernel(name="arm", plant_type=_plant_type, context=CONTEXT, supported=supported, variant=variant,
                      setup=setup, prepare=prepare, mass_rows=mass_rows)

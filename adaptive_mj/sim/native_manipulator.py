"""The native closed loop for manipulators: the Slotine–Li law (and its baselines) with
the plant's regressor kernel, compiled by numba into one C control callback that MuJoCo
calls at every stage of every physics step (adaptive_mj.sim.native does the same for the
1-DOF plants).

At each stage the callback does what loop._Controller + SlotineLiLaw do in Python:
measure x = [q; q̇] (+ noise), take the stage estimate θ̂_i = θ̂_k + h a_i k_{i-1},
evaluate reference_terms, the regressor on the live MjData (cdof, xpos, xmat,
subtree_com, cinert: MuJoCo has just computed them for this stage), the base map,
slotine_li_output, clamp τ, write ctrl = τ / gear, accumulate the RK4-weighted
rates, and after the last stage advance θ̂ once. The references at the stage times
are evaluated in Python, vectorised, before each chunk (MuJoCo's stage times are
reproduced bit for bit, each distinct time evaluated once). tests/test_native_manipulator.py
checks that the two paths give the same rows, bit for bit today, for the adaptive law,
both baselines, a base-parameter plant, saturation, dead-zones and noise, under RK4 and
Euler. (One known place where they could differ by an ulp: the dead-zone on the tracking
error compares ‖q̃‖, a plain sum here and np.linalg.norm in Python, with its width.)

Cost on the 6-joint UR5e with an unknown payload, RK4: about 1.6-1.7x a bare mj_step
(the Python path: ~60-80x); most of the difference is the regressor, see below.

Buffers are reached through module-level tables (_I: addresses and integers, _F:
scalars), so the callback is compiled once per process. Only one native run can be
active per process (MuJoCo's control callback is a process-wide global anyway).
The callback ignores calls for any other MjData, calls past the step's stages (an
extra mj_forward) and calls past the chunk's rows: ctrl is left as it is.
"""
from __future__ import annotations

import numpy as np

from adaptive_mj.sim.numba_util import pointer, with_globals as _with_globals

# --- the tables the callback reads -----------------------------------------------
# _I: int64 addresses of buffers and integer settings; _F: float settings.
(I_DATA, I_STAGE, I_ROW, I_ROWS, I_NST, I_NV, I_NBODY, I_NTH, I_NSTD, I_NQ, I_NU, I_MAXROWS,
 I_MODE, I_ADAPT, I_DZ_ON_S, I_HAS_BASE,
 # MjData / MjModel arrays (live)
 I_QPOS, I_QVEL, I_CTRL, I_CDOF, I_XPOS, I_XMAT, I_SUBCOM, I_CINERT, I_GRAVITY, I_ARM, I_DAMP,
 # regressor's static arrays
 I_PARENT, I_DOFADR, I_DOFNUM, I_ROOTID, I_BODYCOL, I_BODYKNOWN, I_COLARM, I_COLDAMP,
 # plant / law constants
 I_QADR, I_ACT, I_GEAR, I_LO, I_HI, I_LAM, I_KD, I_GAMMA, I_BPTR, I_BIDX, I_BVAL,
 # run state and work buffers
 I_THETA, I_RSUM, I_PREV, I_TH, I_X, I_S, I_QDR, I_QDDR, I_ZERO, I_U, I_RATE, I_YSTD, I_Y, I_TAUK,
 I_REF, I_NOISE, I_SCRATCH, I_NEED,
 # records (one row per physics step)
 I_RT, I_RX, I_RU, I_RS, I_RREF, I_RTH,
 # robust modifications: leakage prior, projection box
 I_THETA0, I_PLO, I_PHI, I_END) = range(74)
_I = np.zeros(I_END, dtype=np.int64)
F_H, F_T, F_DZW, F_INC, F_WEIGHTS, F_SIGMA, F_EMOD, F_END = 0, 1, 2, 4, 8, 12, 13, 14
_F = np.zeros(F_END)

MODE_PD_GRAVITY = 2  # laws.slotine_li.Mode.PD_GRAVITY (the regressor at v = w = a = 0)

_CALLBACK = None
_OWNER = None  # the controller whose buffers the tables point at




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


def _regressor(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp,
              arm_known, damp_known, cdof, xpos, xmat, subtree_com, cinert, gravity,
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
    for k in range(6):
        cv[0, k] = 0.0
        cw[0, k] = 0.0
        ca[0, k] = 0.0
    ca[0, 3] = -gravity[0]
    ca[0, 4] = -gravity[1]
    ca[0, 5] = -gravity[2]
    for b in range(1, nbody):
        p = parent[b]
        v0, v1, v2, v3, v4, v5 = cv[p, 0], cv[p, 1], cv[p, 2], cv[p, 3], cv[p, 4], cv[p, 5]
        w0, w1, w2, w3, w4, w5 = cw[p, 0], cw[p, 1], cw[p, 2], cw[p, 3], cw[p, 4], cw[p, 5]
        a0, a1, a2, a3, a4, a5 = ca[p, 0], ca[p, 1], ca[p, 2], ca[p, 3], ca[p, 4], ca[p, 5]
        for j in range(dofadr[b], dofadr[b] + dofnum[b]):
            c0, c1, c2, c3, c4, c5 = cdof[j, 0], cdof[j, 1], cdof[j, 2], cdof[j, 3], cdof[j, 4], cdof[j, 5]
            s = 0.5 * w[j]  # _cross_motion_add(cv, cdof_j, ½ w_j, ca)
            a0 += s * (v1 * c2 - v2 * c1)
            a1 += s * (v2 * c0 - v0 * c2)
            a2 += s * (v0 * c1 - v1 * c0)
            a3 += s * (v1 * c5 - v2 * c4 + v4 * c2 - v5 * c1)
            a4 += s * (v2 * c3 - v0 * c5 + v5 * c0 - v3 * c2)
            a5 += s * (v0 * c4 - v1 * c3 + v3 * c1 - v4 * c0)
            s = 0.5 * v[j]  # _cross_motion_add(cw, cdof_j, ½ v_j, ca)
            a0 += s * (w1 * c2 - w2 * c1)
            a1 += s * (w2 * c0 - w0 * c2)
            a2 += s * (w0 * c1 - w1 * c0)
            a3 += s * (w1 * c5 - w2 * c4 + w4 * c2 - w5 * c1)
            a4 += s * (w2 * c3 - w0 * c5 + w5 * c0 - w3 * c2)
            a5 += s * (w0 * c4 - w1 * c3 + w3 * c1 - w4 * c0)
            aj, vj, wj = a[j], v[j], w[j]
            a0 += c0 * aj
            a1 += c1 * aj
            a2 += c2 * aj
            a3 += c3 * aj
            a4 += c4 * aj
            a5 += c5 * aj
            v0 += c0 * vj
            v1 += c1 * vj
            v2 += c2 * vj
            v3 += c3 * vj
            v4 += c4 * vj
            v5 += c5 * vj
            w0 += c0 * wj
            w1 += c1 * wj
            w2 += c2 * wj
            w3 += c3 * wj
            w4 += c4 * wj
            w5 += c5 * wj
        cv[b, 0], cv[b, 1], cv[b, 2], cv[b, 3], cv[b, 4], cv[b, 5] = v0, v1, v2, v3, v4, v5
        cw[b, 0], cw[b, 1], cw[b, 2], cw[b, 3], cw[b, 4], cw[b, 5] = w0, w1, w2, w3, w4, w5
        ca[b, 0], ca[b, 1], ca[b, 2], ca[b, 3], ca[b, 4], ca[b, 5] = a0, a1, a2, a3, a4, a5
    for b in range(1, nbody):
        col = body_col[b]
        if body_known[b] == 0 and col < 0:
            continue
        cab, cvb, cwb = ca[b], cv[b], cw[b]
        if body_known[b] != 0:
            I = cinert[b]
            f0, f1, f2, f3, f4, f5 = _force(I[0], I[1], I[2], I[3], I[4], I[5], I[6], I[7], I[8], I[9],
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


_KERNEL = None


def kernel():
    """_regressor compiled with numba (once per process); called as regressor_kernel.regressor
    with two more arguments: scratch (18 nbody,) float64 and need (n_standard,) int64."""
    global _KERNEL
    if _KERNEL is not None:
        return _KERNEL
    import numba

    helpers = {"_imul": numba.njit(_imul), "_project": numba.njit(_project)}
    helpers["_force"] = numba.njit(_with_globals(_force, **helpers))
    helpers["_force_rot"] = numba.njit(_force_rot)
    helpers["_unit_column"] = numba.njit(_with_globals(_unit_column, **helpers))
    _KERNEL = numba.njit(_with_globals(_regressor, **helpers))
    return _KERNEL


def compiled():
    """The control callback (a numba cfunc), compiled once per process."""
    global _CALLBACK
    if _CALLBACK is not None:
        return _CALLBACK
    import numba
    from numba import carray, types
    from numba.extending import intrinsic

    from adaptive_mj.laws.common import clip_into, modify_rate
    from adaptive_mj.laws.slotine_li import reference_terms, slotine_li_output

    @intrinsic
    def address(typingctx, ptr):
        sig = types.int64(types.voidptr)

        def codegen(context, builder, signature, args):
            return builder.ptrtoint(args[0], context.get_value_type(types.int64))

        return sig, codegen

    fptr, iptr = pointer(types.float64), pointer(types.int64)
    i_addr, f_addr = _I.ctypes.data, _F.ctypes.data
    regressor = kernel()
    ref_terms = numba.njit(reference_terms)
    output = numba.njit(_with_globals(slotine_li_output, modify_rate=numba.njit(modify_rate)))
    clip = numba.njit(clip_into)

    @numba.cfunc(types.void(types.voidptr, types.voidptr), nogil=True)
    def callback(m, d):
        I = carray(iptr(i_addr), I_END)
        F = carray(fptr(f_addr), F_END)
        if address(d) != I[I_DATA]:  # another MjData (a scratch copy): not ours
            return
        stage, row, nst = I[I_STAGE], I[I_ROW], I[I_NST]
        if stage >= nst or row >= I[I_ROWS]:  # past the step's stages or the chunk: leave ctrl as it is
            return
        nv, nb, nth, nstd = I[I_NV], I[I_NBODY], I[I_NTH], I[I_NSTD]
        qpos, qvel, ctrl = carray(fptr(I[I_QPOS]), I[I_NQ]), carray(fptr(I[I_QVEL]), nv), \
            carray(fptr(I[I_CTRL]), I[I_NU])
        qadr, act = carray(iptr(I[I_QADR]), nv), carray(iptr(I[I_ACT]), nv)
        gear, lo, hi = carray(fptr(I[I_GEAR]), nv), carray(fptr(I[I_LO]), nv), carray(fptr(I[I_HI]), nv)
        theta, rsum, prev = carray(fptr(I[I_THETA]), nth), carray(fptr(I[I_RSUM]), nth), \
            carray(fptr(I[I_PREV]), nth)
        th, rate = carray(fptr(I[I_TH]), nth), carray(fptr(I[I_RATE]), nth)
        x = carray(fptr(I[I_X]), (2, nv))
        s, qd_r, qdd_r, u = carray(fptr(I[I_S]), nv), carray(fptr(I[I_QDR]), nv), carray(fptr(I[I_QDDR]), nv), \
            carray(fptr(I[I_U]), nv)
        maxrows = I[I_MAXROWS]
        noise = carray(fptr(I[I_NOISE]), (maxrows, 2, nv))
        refs = carray(fptr(I[I_REF]), (maxrows * nst, 3, nv))
        r = refs[row * nst + stage]
        h = F[F_H]

        for j in range(nv):
            x[0, j] = qpos[qadr[j]] + noise[row, 0, j]
            x[1, j] = qvel[j] + noise[row, 1, j]
        if stage == 0:
            for i in range(nth):
                th[i] = theta[i]
        else:
            c = h * F[F_INC + stage]
            for i in range(nth):
                th[i] = theta[i] + c * prev[i]
        theta0, plo, phi = carray(fptr(I[I_THETA0]), nth), carray(fptr(I[I_PLO]), nth), carray(fptr(I[I_PHI]), nth)
        clip(th, plo, phi)  # projection: the stage estimate stays in the box too
        ref_terms(x, r, carray(fptr(I[I_LAM]), nv), s, qd_r, qdd_r)

        Y_std, tau_known = carray(fptr(I[I_YSTD]), (nv, nstd)), carray(fptr(I[I_TAUK]), nv)
        cdof, xpos = carray(fptr(I[I_CDOF]), (nv, 6)), carray(fptr(I[I_XPOS]), (nb, 3))
        xmat, subcom = carray(fptr(I[I_XMAT]), (nb, 9)), carray(fptr(I[I_SUBCOM]), (nb, 3))
        cinert, gravity = carray(fptr(I[I_CINERT]), (nb, 10)), carray(fptr(I[I_GRAVITY]), 3)
        parent, dofadr = carray(iptr(I[I_PARENT]), nb), carray(iptr(I[I_DOFADR]), nb)
        dofnum, rootid = carray(iptr(I[I_DOFNUM]), nb), carray(iptr(I[I_ROOTID]), nb)
        body_col, body_known = carray(iptr(I[I_BODYCOL]), nb), carray(iptr(I[I_BODYKNOWN]), nb)
        col_arm, col_damp = carray(iptr(I[I_COLARM]), nv), carray(iptr(I[I_COLDAMP]), nv)
        arm, damp = carray(fptr(I[I_ARM]), nv), carray(fptr(I[I_DAMP]), nv)
        scratch, need = carray(fptr(I[I_SCRATCH]), 18 * nb), carray(iptr(I[I_NEED]), nstd)
        if I[I_MODE] == MODE_PD_GRAVITY:
            zero = carray(fptr(I[I_ZERO]), nv)
            regressor(parent, dofadr, dofnum, rootid, body_col, body_known, col_arm, col_damp, arm, damp,
                      cdof, xpos, xmat, subcom, cinert, gravity, zero, zero, zero, Y_std, tau_known, scratch, need)
        else:
            regressor(parent, dofadr, dofnum, rootid, body_col, body_known, col_arm, col_damp, arm, damp,
                      cdof, xpos, xmat, subcom, cinert, gravity, x[1], qd_r, qdd_r, Y_std, tau_known, scratch, need)
        if I[I_HAS_BASE] != 0:  # Y = Y_std B, B stored by columns as (pointer, row index, value)
            Y = carray(fptr(I[I_Y]), (nv, nth))
            bptr, bidx, bval = carray(iptr(I[I_BPTR]), nth + 1), carray(iptr(I[I_BIDX]), 1 << 30), \
                carray(fptr(I[I_BVAL]), 1 << 30)
            for j in range(nv):
                for c in range(nth):
                    acc = 0.0
                    for p in range(bptr[c], bptr[c + 1]):
                        acc += Y_std[j, bidx[p]] * bval[p]
                    Y[j, c] = acc
        else:
            Y = Y_std
        e_norm = 0.0
        if I[I_DZ_ON_S] == 0:
            for j in range(nv):
                e = r[0, j] - x[0, j]
                e_norm += e * e
            e_norm = np.sqrt(e_norm)
        output(Y, tau_known, th, s, carray(fptr(I[I_KD]), nv), carray(fptr(I[I_GAMMA]), nth), I[I_ADAPT] != 0,
               F[F_DZW], I[I_DZ_ON_S] != 0, e_norm, F[F_SIGMA], F[F_EMOD], theta0, plo, phi, u, rate)
        for j in range(nv):
            v = u[j]
            if v < lo[j]:
                v = lo[j]
            if v > hi[j]:
                v = hi[j]
            u[j] = v
            ctrl[act[j]] = v / gear[j]
        w = F[F_WEIGHTS + stage]
        for i in range(nth):
            rsum[i] += w * rate[i]
            prev[i] = rate[i]
        if stage == 0:  # the step's row: t, true x, u, s, ref, θ̂ at the step's start
            carray(fptr(I[I_RT]), maxrows)[row] = F[F_T]
            rx = carray(fptr(I[I_RX]), (maxrows, 2, nv))
            ru, rs = carray(fptr(I[I_RU]), (maxrows, nv)), carray(fptr(I[I_RS]), (maxrows, nv))
            rref, rth = carray(fptr(I[I_RREF]), (maxrows, 3, nv)), carray(fptr(I[I_RTH]), (maxrows, nth))
            for j in range(nv):
                rx[row, 0, j] = qpos[qadr[j]]
                rx[row, 1, j] = qvel[j]
                ru[row, j] = u[j]
                rs[row, j] = s[j]
                for k in range(3):
                    rref[row, k, j] = r[k, j]
            for i in range(nth):
                rth[row, i] = theta[i]
        stage += 1
        if stage == nst:  # end of the physics step: advance the estimates once
            for i in range(nth):
                theta[i] = theta[i] + h * rsum[i]
                rsum[i] = 0.0
            clip(theta, plo, phi)
            I[I_ROW] = row + 1
            F[F_T] = F[F_T] + h
            stage = 0
        I[I_STAGE] = stage

    _CALLBACK = callback
    return callback


def supported(plant, law) -> bool:
    """Native path for manipulators: a ManipulatorPlant (joint axis and regressor), a Slotine–Li
    law (or baseline) using that plant's regressor, RK4 or a one-stage integrator."""
    if not (hasattr(plant, "joint_shape") and hasattr(plant, "regressor") and hasattr(plant, "step_native")):
        return False
    if not hasattr(law, "native_params") or "mode" not in law.native_params():
        return False
    return (plant.stages in (1, 4) and getattr(law, "regressor", None) is plant.regressor
            and len(law.names) == len(plant.names) and int(law.m) == int(plant.m))


class NativeManipulatorController:
    """Owns the buffers of one native manipulator run and steps the plant chunk by chunk
    (the interface of adaptive_mj.sim.native.NativeController)."""

    def __init__(self, plant, law, reference, theta_hat0, max_rows: int, *, delay: int = 0):
        from adaptive_mj.sim.loop import TABLEAU

        if delay:
            raise ValueError("a control delay on a manipulator runs on the Python callback path (native=False)")

        self.plant, self.law, self.reference = plant, law, reference
        self.callback = compiled()
        model, data, reg = plant.model, plant.data, plant.regressor
        nv, nb = int(model.nv), int(model.nbody)
        nth, nstd = len(law.names), int(reg.n_standard)
        self.m, self.nth, self.nst, self.max_rows = nv, nth, plant.stages, int(max_rows)
        p = law.native_params()
        inc, weights = TABLEAU[self.nst]
        self.stage_offsets = np.asarray(inc)  # RK4: c_i = a_i (see loop.TABLEAU)

        f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
        i64 = lambda a: np.ascontiguousarray(a, dtype=np.int64)  # noqa: E731
        self.theta = f64(np.array(theta_hat0, dtype=float).reshape(nth))
        lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (np.full(nv, -np.inf), np.full(nv, np.inf))
        keep = {  # everything the callback reaches by address: held here for the run's lifetime
            I_PARENT: i64(reg.parent), I_DOFADR: i64(reg.dofadr), I_DOFNUM: i64(reg.dofnum),
            I_ROOTID: i64(reg.rootid), I_BODYCOL: i64(reg.body_col), I_BODYKNOWN: i64(reg.body_known),
            I_COLARM: i64(reg.col_arm), I_COLDAMP: i64(reg.col_damp),
            I_QADR: i64(plant._qadr), I_ACT: i64(plant._act), I_GEAR: f64(plant._gear),
            I_LO: f64(np.broadcast_to(lo, (nv,))), I_HI: f64(np.broadcast_to(hi, (nv,))),
            I_LAM: f64(p["lam"]), I_KD: f64(p["kd"]), I_GAMMA: f64(p["gamma"]),
            I_THETA: self.theta, I_RSUM: np.zeros(nth), I_PREV: np.zeros(nth), I_TH: np.zeros(nth),
            I_X: np.zeros((2, nv)), I_S: np.zeros(nv), I_QDR: np.zeros(nv), I_QDDR: np.zeros(nv),
            I_ZERO: np.zeros(nv), I_U: np.zeros(nv), I_RATE: np.zeros(nth), I_YSTD: np.zeros((nv, nstd)),
            I_Y: np.zeros((nv, nth)), I_TAUK: np.zeros(nv), I_SCRATCH: np.zeros(18 * nb),
            I_REF: np.zeros((self.max_rows * self.nst, 3, nv)), I_NOISE: np.zeros((self.max_rows, 2, nv)),
            I_RT: np.zeros(self.max_rows), I_RX: np.zeros((self.max_rows, 2, nv)),
            I_RU: np.zeros((self.max_rows, nv)), I_RS: np.zeros((self.max_rows, nv)),
            I_RREF: np.zeros((self.max_rows, 3, nv)), I_RTH: np.zeros((self.max_rows, nth)),
            I_THETA0: f64(p["theta0"]), I_PLO: f64(p["lower"]), I_PHI: f64(p["upper"]),
        }
        B = getattr(reg, "base_map", None)
        if B is not None:  # the base map by columns, its nonzero entries only (B is a column selection)
            B = np.asarray(B, dtype=float)
            if B.shape != (nstd, nth):
                raise ValueError(f"base map of shape {B.shape}, expected {(nstd, nth)}")
            rows_, vals, ptr = [], [], [0]
            for c in range(nth):
                nz = np.nonzero(B[:, c])[0]
                rows_ += nz.tolist()
                vals += B[nz, c].tolist()
                ptr.append(len(rows_))
            keep[I_BPTR], keep[I_BIDX], keep[I_BVAL] = i64(ptr), i64(rows_ or [0]), f64(vals or [0.0])
            keep[I_NEED] = i64(np.any(B != 0, axis=1))  # standard columns the base map reads
        elif nstd != nth:
            raise ValueError(f"the law has {nth} parameters, the regressor {nstd}")
        else:
            keep[I_NEED] = np.ones(max(nstd, 1), dtype=np.int64)
        self._keep = keep
        live = {I_QPOS: data.qpos, I_QVEL: data.qvel, I_CTRL: data.ctrl, I_CDOF: data.cdof, I_XPOS: data.xpos,
                I_XMAT: data.xmat, I_SUBCOM: data.subtree_com, I_CINERT: data.cinert,
                I_GRAVITY: model.opt.gravity, I_ARM: model.dof_armature, I_DAMP: model.dof_damping}
        for slot, arr in live.items():  # MuJoCo's own arrays (stable addresses; events edit them in place)
            if arr.dtype != np.float64 or not arr.flags.c_contiguous:
                raise TypeError(f"unexpected MuJoCo array layout for table slot {slot}")
        self._live = live
        it, ft = np.zeros(I_END, dtype=np.int64), np.zeros(F_END)
        for slot, arr in (*keep.items(), *live.items()):
            it[slot] = arr.ctypes.data
        it[I_DATA] = data._address
        it[I_NST], it[I_NV], it[I_NBODY], it[I_NTH], it[I_NSTD] = self.nst, nv, nb, nth, nstd
        it[I_NQ], it[I_NU], it[I_MAXROWS] = model.nq, model.nu, self.max_rows
        it[I_MODE], it[I_ADAPT] = int(p["mode"]), int(bool(p["adapt"]))
        it[I_DZ_ON_S], it[I_HAS_BASE] = int(bool(p["dz_on_s"])), int(B is not None)
        ft[F_H], ft[F_DZW], ft[F_SIGMA], ft[F_EMOD] = plant.dt, p["dz_width"], p["sigma"], p["e_mod"]
        ft[F_INC:F_INC + len(inc)] = inc
        ft[F_WEIGHTS:F_WEIGHTS + len(weights)] = weights
        self._tables = it, ft
        self._bind()

    def _bind(self) -> None:
        """Point the callback's tables at this controller's buffers (the newest controller owns them;
        an older one takes them back at its next chunk)."""
        global _OWNER
        _I[:], _F[:] = self._tables
        _OWNER = self

    def chunk(self, rows: int, noise: np.ndarray | None):
        """Step `rows` physics steps; return (t (rows,), x (rows, 2, m), u (rows, m), s (rows, m),
        ref (rows, 3, m), theta_hat (rows, n_params)): each row the state, reference and θ̂ at
        the step's start and the clamped τ applied during it."""
        if not 0 < rows <= self.max_rows:
            raise ValueError(f"rows must be in 1..{self.max_rows}, got {rows}")
        plant, m, nst, h = self.plant, self.m, self.nst, self.plant.dt
        t = np.empty(rows)
        t[0] = plant.time
        for i in range(1, rows):  # MuJoCo's own time accumulation, bit for bit
            t[i] = t[i - 1] + h
        stage_t = (t[:, None] + h * self.stage_offsets[None, :]).ravel()
        # Each distinct stage time once (RK4: stages 2 and 3 share t + h/2, and stage 4's t + h is
        # the next step's t, the same number): half the reference evaluations.
        if np.all(stage_t[1:] >= stage_t[:-1]):
            new = np.empty(stage_t.size, dtype=bool)
            new[0] = True
            np.not_equal(stage_t[1:], stage_t[:-1], out=new[1:])
            times, which = stage_t[new], np.cumsum(new) - 1
        else:
            times, which = np.unique(stage_t, return_inverse=True)
        refs = self.reference(times, 2)  # (3, len(times), m)
        self._keep[I_REF][: rows * nst] = np.moveaxis(refs, 1, 0)[which]
        buf = self._keep[I_NOISE]
        if noise is not None:
            buf[:rows] = np.asarray(noise, dtype=float).reshape(rows, 2, m)
        else:
            buf[:rows] = 0.0
        if _OWNER is not self:
            self._bind()
        _F[F_H], _F[F_T] = h, t[0]
        _I[I_STAGE], _I[I_ROW], _I[I_ROWS] = 0, 0, rows
        plant.step_native(rows)
        done = int(_I[I_ROW])
        if done != rows or _I[I_STAGE] != 0:
            raise RuntimeError(f"native callback ran {done} steps (stage {int(_I[I_STAGE])}), expected {rows}")
        k = self._keep
        return (k[I_RT][:rows].copy(), k[I_RX][:rows].copy(), k[I_RU][:rows].copy(), k[I_RS][:rows].copy(),
                k[I_RREF][:rows].copy(), k[I_RTH][:rows].copy())

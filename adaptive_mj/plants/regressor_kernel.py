"""The manipulator regressor Y(q, q̇, q̇_r, q̈_r) of a tree of hinge/slide joints, as
plain array code over MuJoCo's kinematic quantities (no mujoco import: the same
source runs in Python, under numba in Python, and inside the native callback).

For standard rigid-body parameters π (10 per body, see BODY_PARAM_NAMES) the
regressor satisfies, exactly,

    Y(q, v, w, a) π = M(q) a + C(q, v) w + g(q)          (+ joint terms, below)

with C the Christoffel form of the Coriolis/centrifugal matrix, so Ṁ - 2C is skew
and the Slotine–Li argument holds. It is MuJoCo's recursive Newton–Euler (mj_comVel
+ mj_rne) rewritten with three velocities:

  forward, body by body (parent before child), starting from the world
  with cacc = [0, 0, 0, -gravity]:
    for each dof j of body b (in order):
        cacc_b += cdof_j a_j + ½ [(cv_b × cdof_j) w_j + (cw_b × cdof_j) v_j]
        cv_b += cdof_j v_j,   cw_b += cdof_j w_j
  body force, linear in the body's 10 "cinert" numbers I:
        f_b(I) = I cacc_b + ½ [cv_b ×* (I cw_b) + cw_b ×* (I cv_b)]
  projection: τ_j = Σ_{b in the subtree of dof j's body} cdof_j · f_b.

With v = w this is MuJoCo's own RNE (the quadratic term c(v) = C(q, v) v), and the
bracket ½[...] is the polarization B(v, w) = ½[c(v + w) - c(v) - c(w)] of that
quadratic form, which is the Christoffel C(q, v) w.

All spatial quantities are MuJoCo's "c" frame: world axes, about the subtree centre
of mass of the tree's root (d.subtree_com[body_rootid]); 6-vectors are [angular;
linear]; cinert is [Ixx, Iyy, Izz, Ixy, Ixz, Iyz, m cx, m cy, m cz, m] about that point
in world axes. Body-frame parameters π_b map to cinert linearly (cinert_of_params).

Joint terms, one parameter each per dof: armature (column a_j), viscous damping
(column v_j, the measured velocity, so that the closed loop keeps V' = -sᵀ K_D s) and
Coulomb friction (column tanh(v_j / ε), the measured velocity again, smoothed with ε
[rad/s or m/s]). A known Coulomb term is not added to tau_known: MuJoCo's frictionloss
is a constraint force, not F tanh(v / ε), so without a Coulomb column it is unmodelled.
"""
from __future__ import annotations

import math

import numpy as np

#: The 10 standard inertial parameters of a body, in its own frame (Pinocchio's order):
#: mass [kg], first moment m·c [kg m], inertia about the body frame's origin [kg m²].
BODY_PARAM_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
JOINT_PARAM_NAMES = ("armature", "damping")
#: Joint friction parameters (plant.friction_params): viscous damping [N m s/rad or N s/m] and
#: Coulomb friction [N m or N], the amplitude of F tanh(q̇ / ε).
FRICTION_PARAM_NAMES = ("damping", "coulomb")
#: ε [rad/s or m/s] of the Coulomb column tanh(q̇ / ε) (plant.coulomb_smoothing): tanh reaches 0.995
#: at |q̇| = 3ε = 0.03 rad/s, a few per cent of the bundled references' joint speeds (0.2-1 rad/s),
#: so the column is F sign(q̇) wherever the joints move; a smaller ε only steepens the column's slope
#: 1/ε near q̇ = 0, which multiplies velocity noise into the torque.
DEFAULT_COULOMB_SMOOTHING = 0.01


def body_params(mass, ipos, inertia, iquat_mat) -> np.ndarray:
    """(10,) standard parameters of one body from MuJoCo's model fields.

    mass [kg]; ipos (3,) centre of mass in the body frame [m]; inertia (3,)
    principal moments about the centre of mass [kg m²]; iquat_mat (3, 3) rotation
    from the inertia frame to the body frame (mju_quat2Mat of body_iquat).
    """
    c = np.asarray(ipos, dtype=float)
    R = np.asarray(iquat_mat, dtype=float).reshape(3, 3)
    I_com = R @ np.diag(np.asarray(inertia, dtype=float)) @ R.T
    I_o = I_com + mass * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return np.array([mass, mass * c[0], mass * c[1], mass * c[2],
                     I_o[0, 0], I_o[0, 1], I_o[1, 1], I_o[0, 2], I_o[1, 2], I_o[2, 2]])


def cinert_of_params(p, xmat, r, out):
    """MuJoCo cinert (10,) of a body with parameters p (10,) (BODY_PARAM_NAMES order).

    xmat (9,) body orientation (row-major, body -> world); r (3,) body origin minus
    the reference point (subtree_com of the root) [m]. Linear in p:
      h = R h_b,  I_o = R I_b Rᵀ + m(|r|² E - r rᵀ) + 2 (h·r) E - (h rᵀ + r hᵀ).
    """
    m = p[0]
    hb0, hb1, hb2 = p[1], p[2], p[3]
    # R I_b R^T with I_b symmetric from (Ixx, Ixy, Iyy, Ixz, Iyz, Izz)
    Ib = np.empty((3, 3))
    Ib[0, 0] = p[4]
    Ib[0, 1] = p[5]
    Ib[1, 0] = p[5]
    Ib[1, 1] = p[6]
    Ib[0, 2] = p[7]
    Ib[2, 0] = p[7]
    Ib[1, 2] = p[8]
    Ib[2, 1] = p[8]
    Ib[2, 2] = p[9]
    RI = np.zeros((3, 3))
    for i in range(3):
        for k in range(3):
            acc = 0.0
            for j in range(3):
                acc += xmat[3 * i + j] * Ib[j, k]
            RI[i, k] = acc
    Iw = np.zeros((3, 3))
    for i in range(3):
        for k in range(3):
            acc = 0.0
            for j in range(3):
                acc += RI[i, j] * xmat[3 * k + j]
            Iw[i, k] = acc
    h = np.empty(3)
    for i in range(3):
        h[i] = xmat[3 * i] * hb0 + xmat[3 * i + 1] * hb1 + xmat[3 * i + 2] * hb2
    rr = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    hr = h[0] * r[0] + h[1] * r[1] + h[2] * r[2]
    for i in range(3):
        for k in range(3):
            Iw[i, k] += -m * r[i] * r[k] - h[i] * r[k] - r[i] * h[k]
        Iw[i, i] += m * rr + 2.0 * hr
    out[0] = Iw[0, 0]
    out[1] = Iw[1, 1]
    out[2] = Iw[2, 2]
    out[3] = Iw[0, 1]
    out[4] = Iw[0, 2]
    out[5] = Iw[1, 2]
    out[6] = m * r[0] + h[0]
    out[7] = m * r[1] + h[1]
    out[8] = m * r[2] + h[2]
    out[9] = m


def _inert_mul(inert, x, out):
    """out (6,) = spatial inertia I (cinert layout) times motion x (6,) [ang; lin]."""
    w0, w1, w2, l0, l1, l2 = x[0], x[1], x[2], x[3], x[4], x[5]
    h0, h1, h2, m = inert[6], inert[7], inert[8], inert[9]
    out[0] = inert[0] * w0 + inert[3] * w1 + inert[4] * w2 + (h1 * l2 - h2 * l1)
    out[1] = inert[3] * w0 + inert[1] * w1 + inert[5] * w2 + (h2 * l0 - h0 * l2)
    out[2] = inert[4] * w0 + inert[5] * w1 + inert[2] * w2 + (h0 * l1 - h1 * l0)
    out[3] = m * l0 - (h1 * w2 - h2 * w1)
    out[4] = m * l1 - (h2 * w0 - h0 * w2)
    out[5] = m * l2 - (h0 * w1 - h1 * w0)


def _cross_force_add(v, f, scale, out):
    """out += scale * (v ×* f): ang = ω × f_ang + v_lin × f_lin, lin = ω × f_lin."""
    w0, w1, w2, l0, l1, l2 = v[0], v[1], v[2], v[3], v[4], v[5]
    out[0] += scale * (w1 * f[2] - w2 * f[1] + l1 * f[5] - l2 * f[4])
    out[1] += scale * (w2 * f[0] - w0 * f[2] + l2 * f[3] - l0 * f[5])
    out[2] += scale * (w0 * f[1] - w1 * f[0] + l0 * f[4] - l1 * f[3])
    out[3] += scale * (w1 * f[5] - w2 * f[4])
    out[4] += scale * (w2 * f[3] - w0 * f[5])
    out[5] += scale * (w0 * f[4] - w1 * f[3])


def _cross_motion_add(v, c, scale, out):
    """out += scale * (v × c): ang = ω × c_ang, lin = ω × c_lin + v_lin × c_ang."""
    w0, w1, w2, l0, l1, l2 = v[0], v[1], v[2], v[3], v[4], v[5]
    out[0] += scale * (w1 * c[2] - w2 * c[1])
    out[1] += scale * (w2 * c[0] - w0 * c[2])
    out[2] += scale * (w0 * c[1] - w1 * c[0])
    out[3] += scale * (w1 * c[5] - w2 * c[4] + l1 * c[2] - l2 * c[1])
    out[4] += scale * (w2 * c[3] - w0 * c[5] + l2 * c[0] - l0 * c[2])
    out[5] += scale * (w0 * c[4] - w1 * c[3] + l0 * c[1] - l1 * c[0])


def _body_force(inert, ca, cv, cw, out):
    """out (6,) = I ca + ½ [cv ×* (I cw) + cw ×* (I cv)]."""
    tmp = np.empty(6)
    _inert_mul(inert, ca, out)
    _inert_mul(inert, cw, tmp)
    _cross_force_add(cv, tmp, 0.5, out)
    _inert_mul(inert, cv, tmp)
    _cross_force_add(cw, tmp, 0.5, out)


def regressor(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp,  # noqa: C901 (compiled kernel)
              dof_col_coul, arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity,
              v, w, a, Y, tau_known):
    """Fill Y (nv, n_params) and tau_known (nv,) at the state MuJoCo's kinematics describe.

    Model arrays (constant over a run):
      parent, dofadr, dofnum, rootid: (nbody,) MuJoCo body_parentid, body_dofadr,
        body_dofnum, body_rootid (bodies are ordered parent before child);
      body_col (nbody,): first column of the body's 10 parameters in Y, or -1 if the
        body is known; body_known (nbody,) 1 where the body's true cinert goes into
        tau_known;
      dof_col_arm, dof_col_damp (nv,): column of the dof's armature / damping
        parameter, or -1 if known; dof_col_coul (nv,): column of its Coulomb friction
        parameter, or -1 (not modelled); arm_known, damp_known (nv,) the known values
        [kg m² or kg; N m s/rad or N s/m]; coulomb_eps: ε > 0 of the Coulomb column
        tanh(v_j / ε) [rad/s or m/s].
    Data arrays (the current stage): cdof (nv, 6), xpos (nbody, 3), xmat (nbody, 9),
      subtree_com (nbody, 3), cinert (nbody, 10); gravity (3,) [m/s²].
    Signals: v (nv,) joint velocity q̇, w (nv,) reference velocity q̇_r, a (nv,)
      reference acceleration q̈_r.
    Output: Y π_unknown + tau_known = M a + C(q, v) w + g + armature·a + damping·v
      (+ coulomb·tanh(v / ε) for the dofs with a Coulomb column).
    """
    nbody = parent.shape[0]
    nv = v.shape[0]
    ncol = Y.shape[1]
    for j in range(nv):
        tau_known[j] = 0.0
        for c in range(ncol):
            Y[j, c] = 0.0
    cv = np.zeros((nbody, 6))
    cw = np.zeros((nbody, 6))
    ca = np.zeros((nbody, 6))
    ca[0, 3] = -gravity[0]
    ca[0, 4] = -gravity[1]
    ca[0, 5] = -gravity[2]
    for b in range(1, nbody):
        p = parent[b]
        for k in range(6):
            cv[b, k] = cv[p, k]
            cw[b, k] = cw[p, k]
            ca[b, k] = ca[p, k]
        for j in range(dofadr[b], dofadr[b] + dofnum[b]):
            _cross_motion_add(cv[b], cdof[j], 0.5 * w[j], ca[b])
            _cross_motion_add(cw[b], cdof[j], 0.5 * v[j], ca[b])
            for k in range(6):
                ca[b, k] += cdof[j, k] * a[j]
                cv[b, k] += cdof[j, k] * v[j]
                cw[b, k] += cdof[j, k] * w[j]
    f = np.empty(6)
    unit = np.zeros(10)
    cin = np.empty(10)
    r = np.empty(3)
    for b in range(1, nbody):
        if body_known[b] == 0 and body_col[b] < 0:
            continue
        if body_known[b] != 0:
            _body_force(cinert[b], ca[b], cv[b], cw[b], f)
            _project(parent, dofadr, dofnum, cdof, b, f, tau_known)
        col = body_col[b]
        if col >= 0:
            root = rootid[b]
            for k in range(3):
                r[k] = xpos[b, k] - subtree_com[root, k]
            for i in range(10):
                unit[i] = 1.0
                cinert_of_params(unit, xmat[b], r, cin)
                unit[i] = 0.0
                _body_force(cin, ca[b], cv[b], cw[b], f)
                _project_col(parent, dofadr, dofnum, cdof, b, f, Y, col + i)
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


def _project(parent, dofadr, dofnum, cdof, b, f, tau):
    """tau_j += cdof_j · f for every dof j on the path from body b to the world."""
    x = b
    while x > 0:
        for j in range(dofadr[x], dofadr[x] + dofnum[x]):
            tau[j] += (cdof[j, 0] * f[0] + cdof[j, 1] * f[1] + cdof[j, 2] * f[2]
                       + cdof[j, 3] * f[3] + cdof[j, 4] * f[4] + cdof[j, 5] * f[5])
        x = parent[x]


def _project_col(parent, dofadr, dofnum, cdof, b, f, Y, col):
    """Y[j, col] += cdof_j · f for every dof j on the path from body b to the world."""
    x = b
    while x > 0:
        for j in range(dofadr[x], dofadr[x] + dofnum[x]):
            Y[j, col] += (cdof[j, 0] * f[0] + cdof[j, 1] * f[1] + cdof[j, 2] * f[2]
                          + cdof[j, 3] * f[3] + cdof[j, 4] * f[4] + cdof[j, 5] * f[5])
        x = parent[x]


# --- Slotine–Li in O(n): τ = Y π̂ + τ_known and Yᵀ s without forming Y ---------------------------------
# Niemeyer & Slotine (IJRR 1991): Y π̂ is the recursive Newton–Euler of `regressor` with the bodies' cinert
# built from the estimates, and Yᵀ s is, per body, the gradient of ⟨w_b, f_b(I)⟩ in the body's parameters,
# with w_b = Σ_{dofs j on b's path to the world} cdof_j s_j. Both take one forward and one backward pass
# (docs/THEORY.md, "Slotine–Li in O(n)"). The forward pass and the body forces are `regressor`'s, so the
# numbers are Y π̂ and Yᵀ s up to the order of the sums (≤ 1e-10 relative, tests/test_slotine_li_rne.py).
#: the scratch rne_torque and rne_rate share, per body: cv, cw, ca (the forward pass), F (the subtree
#: forces), ws (the motion of s)
RNE_SCRATCH = 30


def rne_forward(parent, dofadr, dofnum, cdof, gravity, v, w, a, scratch):
    """The forward pass of `regressor` (cv, cw, ca per body, the same operations in the same order) into
    scratch (RNE_SCRATCH nbody,): cv at [0, 6 nbody), cw at [6 nbody, 12 nbody), ca at [12 nbody, 18 nbody)."""
    nbody = parent.shape[0]
    cv = scratch[0:6 * nbody].reshape((nbody, 6))
    cw = scratch[6 * nbody:12 * nbody].reshape((nbody, 6))
    ca = scratch[12 * nbody:18 * nbody].reshape((nbody, 6))
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
            s = 0.5 * w[j]  # ½ w_j (cv × cdof_j)
            a0 += s * (v1 * c2 - v2 * c1)
            a1 += s * (v2 * c0 - v0 * c2)
            a2 += s * (v0 * c1 - v1 * c0)
            a3 += s * (v1 * c5 - v2 * c4 + v4 * c2 - v5 * c1)
            a4 += s * (v2 * c3 - v0 * c5 + v5 * c0 - v3 * c2)
            a5 += s * (v0 * c4 - v1 * c3 + v3 * c1 - v4 * c0)
            s = 0.5 * v[j]  # ½ v_j (cw × cdof_j)
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


def _cinert_scalars(p, col, xmat, b, r0, r1, r2):
    """cinert_of_params(p[col:col + 10], xmat[b], r) as 10 scalars, without work arrays or views (the same
    formula; r = xpos_b - subtree_com of the root)."""
    X0, X1, X2, X3, X4 = xmat[b, 0], xmat[b, 1], xmat[b, 2], xmat[b, 3], xmat[b, 4]
    X5, X6, X7, X8 = xmat[b, 5], xmat[b, 6], xmat[b, 7], xmat[b, 8]
    m = p[col]
    hb0, hb1, hb2 = p[col + 1], p[col + 2], p[col + 3]
    B00, B01, B11, B02, B12, B22 = p[col + 4], p[col + 5], p[col + 6], p[col + 7], p[col + 8], p[col + 9]
    # R I_b (row i) then (R I_b) Rᵀ
    a00 = X0 * B00 + X1 * B01 + X2 * B02
    a01 = X0 * B01 + X1 * B11 + X2 * B12
    a02 = X0 * B02 + X1 * B12 + X2 * B22
    a10 = X3 * B00 + X4 * B01 + X5 * B02
    a11 = X3 * B01 + X4 * B11 + X5 * B12
    a12 = X3 * B02 + X4 * B12 + X5 * B22
    a20 = X6 * B00 + X7 * B01 + X8 * B02
    a21 = X6 * B01 + X7 * B11 + X8 * B12
    a22 = X6 * B02 + X7 * B12 + X8 * B22
    i00 = a00 * X0 + a01 * X1 + a02 * X2
    i11 = a10 * X3 + a11 * X4 + a12 * X5
    i22 = a20 * X6 + a21 * X7 + a22 * X8
    i01 = a00 * X3 + a01 * X4 + a02 * X5
    i02 = a00 * X6 + a01 * X7 + a02 * X8
    i12 = a10 * X6 + a11 * X7 + a12 * X8
    h0 = X0 * hb0 + X1 * hb1 + X2 * hb2
    h1 = X3 * hb0 + X4 * hb1 + X5 * hb2
    h2 = X6 * hb0 + X7 * hb1 + X8 * hb2
    rr = r0 * r0 + r1 * r1 + r2 * r2
    d = m * rr + 2.0 * (h0 * r0 + h1 * r1 + h2 * r2)
    return (i00 - m * r0 * r0 - 2.0 * h0 * r0 + d, i11 - m * r1 * r1 - 2.0 * h1 * r1 + d,
            i22 - m * r2 * r2 - 2.0 * h2 * r2 + d, i01 - m * r0 * r1 - h0 * r1 - r0 * h1,
            i02 - m * r0 * r2 - h0 * r2 - r0 * h2, i12 - m * r1 * r2 - h1 * r2 - r1 * h2,
            m * r0 + h0, m * r1 + h1, m * r2 + h2, m)


def _force_add(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, S, oa, ov, ow, oF):
    """S[oF:oF+6] += I ca + ½ [cv ×* (I cw) + cw ×* (I cv)] for the cinert I (10 scalars) (_body_force on
    scalars), ca, cv, cw at S[oa:oa+6], S[ov:ov+6], S[ow:ow+6] (offsets into one flat buffer: no array views)."""
    x0, x1, x2, x3, x4, x5 = S[oa], S[oa + 1], S[oa + 2], S[oa + 3], S[oa + 4], S[oa + 5]
    f0 = I0 * x0 + I3 * x1 + I4 * x2 + (h1 * x5 - h2 * x4)
    f1 = I3 * x0 + I1 * x1 + I5 * x2 + (h2 * x3 - h0 * x5)
    f2 = I4 * x0 + I5 * x1 + I2 * x2 + (h0 * x4 - h1 * x3)
    f3 = m * x3 - (h1 * x2 - h2 * x1)
    f4 = m * x4 - (h2 * x0 - h0 * x2)
    f5 = m * x5 - (h0 * x1 - h1 * x0)
    for rep in range(2):
        if rep == 0:
            ox, oy = ow, ov
        else:
            ox, oy = ov, ow
        x0, x1, x2, x3, x4, x5 = S[ox], S[ox + 1], S[ox + 2], S[ox + 3], S[ox + 4], S[ox + 5]
        t0 = I0 * x0 + I3 * x1 + I4 * x2 + (h1 * x5 - h2 * x4)
        t1 = I3 * x0 + I1 * x1 + I5 * x2 + (h2 * x3 - h0 * x5)
        t2 = I4 * x0 + I5 * x1 + I2 * x2 + (h0 * x4 - h1 * x3)
        t3 = m * x3 - (h1 * x2 - h2 * x1)
        t4 = m * x4 - (h2 * x0 - h0 * x2)
        t5 = m * x5 - (h0 * x1 - h1 * x0)
        w0, w1, w2, l0, l1, l2 = S[oy], S[oy + 1], S[oy + 2], S[oy + 3], S[oy + 4], S[oy + 5]
        f0 += 0.5 * (w1 * t2 - w2 * t1 + l1 * t5 - l2 * t4)
        f1 += 0.5 * (w2 * t0 - w0 * t2 + l2 * t3 - l0 * t5)
        f2 += 0.5 * (w0 * t1 - w1 * t0 + l0 * t4 - l1 * t3)
        f3 += 0.5 * (w1 * t5 - w2 * t4)
        f4 += 0.5 * (w2 * t3 - w0 * t5)
        f5 += 0.5 * (w0 * t4 - w1 * t3)
    S[oF] += f0
    S[oF + 1] += f1
    S[oF + 2] += f2
    S[oF + 3] += f3
    S[oF + 4] += f4
    S[oF + 5] += f5


def rne_torque(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp,  # noqa: C901 (compiled kernel)
               dof_col_coul, arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity,
               v, w, a, pi, tau, scratch):
    """tau (nv,) = Y(q, v, w, a) π + τ_known of `regressor` (same arguments up to gravity, then v, w, a), in O(n):
    the forward pass (rne_forward), each body's force f_b(I_b) with I_b its true cinert (a known body) or the
    cinert of its estimates π[body_col[b]:+10] (cinert_of_params), summed from the leaves to the root
    (F_b = f_b + Σ_children F_c) and projected on each dof, τ_j = cdof_j · F_b(j); then the joint terms.

    pi (n_standard,): the standard parameters (a base-parameter law passes B θ̂); scratch (RNE_SCRATCH nbody,):
    the forward pass stays there for rne_rate at the same state. Flat offsets into scratch, not array views
    (a view per body costs more than its force here)."""
    nbody = parent.shape[0]
    nv = v.shape[0]
    rne_forward(parent, dofadr, dofnum, cdof, gravity, v, w, a, scratch)
    S = scratch
    OV, OW, OA, OF = 0, 6 * nbody, 12 * nbody, 18 * nbody
    for k in range(6 * nbody):
        S[OF + k] = 0.0
    for b in range(nbody - 1, 0, -1):
        ob = 6 * b
        if body_known[b] != 0:
            _force_add(cinert[b, 0], cinert[b, 1], cinert[b, 2], cinert[b, 3], cinert[b, 4], cinert[b, 5],
                       cinert[b, 6], cinert[b, 7], cinert[b, 8], cinert[b, 9], S, OA + ob, OV + ob, OW + ob, OF + ob)
        col = body_col[b]
        if col >= 0:
            root = rootid[b]
            I0, I1, I2, I3, I4, I5, h0, h1, h2, m = _cinert_scalars(
                pi, col, xmat, b, xpos[b, 0] - subtree_com[root, 0], xpos[b, 1] - subtree_com[root, 1],
                xpos[b, 2] - subtree_com[root, 2])
            _force_add(I0, I1, I2, I3, I4, I5, h0, h1, h2, m, S, OA + ob, OV + ob, OW + ob, OF + ob)
        F0, F1, F2 = S[OF + ob], S[OF + ob + 1], S[OF + ob + 2]
        F3, F4, F5 = S[OF + ob + 3], S[OF + ob + 4], S[OF + ob + 5]
        for j in range(dofadr[b], dofadr[b] + dofnum[b]):
            tau[j] = (cdof[j, 0] * F0 + cdof[j, 1] * F1 + cdof[j, 2] * F2
                      + cdof[j, 3] * F3 + cdof[j, 4] * F4 + cdof[j, 5] * F5)
        p = parent[b]
        if p > 0:
            op = OF + 6 * p
            S[op] += F0
            S[op + 1] += F1
            S[op + 2] += F2
            S[op + 3] += F3
            S[op + 4] += F4
            S[op + 5] += F5
    for j in range(nv):
        if dof_col_arm[j] >= 0:
            tau[j] += pi[dof_col_arm[j]] * a[j]
        else:
            tau[j] += arm_known[j] * a[j]
        if dof_col_damp[j] >= 0:
            tau[j] += pi[dof_col_damp[j]] * v[j]
        else:
            tau[j] += damp_known[j] * v[j]
        if dof_col_coul[j] >= 0:
            tau[j] += pi[dof_col_coul[j]] * math.tanh(v[j] / coulomb_eps)


def _bilinear_grad(x0, x1, x2, x3, x4, x5, y0, y1, y2, y3, y4, y5):
    """The gradient (10 scalars) in the cinert numbers of xᵀ I y (I the spatial inertia of a cinert):
    xᵀ I y = x_angᵀ I_rot y_ang + h · (y_lin × x_ang + x_lin × y_ang) + m x_lin · y_lin; on (Ixx, Iyy, Izz)
    x_i y_i, on (Ixy, Ixz, Iyz) x_i y_k + x_k y_i."""
    return (x0 * y0, x1 * y1, x2 * y2, x0 * y1 + x1 * y0, x0 * y2 + x2 * y0, x1 * y2 + x2 * y1,
            (y4 * x2 - y5 * x1) + (x4 * y2 - x5 * y1), (y5 * x0 - y3 * x2) + (x5 * y0 - x3 * y2),
            (y3 * x1 - y4 * x0) + (x3 * y1 - x4 * y0), x3 * y3 + x4 * y4 + x5 * y5)


def _cross(w0, w1, w2, l0, l1, l2, u0, u1, u2, u3, u4, u5):
    """v × u (spatial motion cross product: ang = ω × u_ang, lin = ω × u_lin + v_lin × u_ang), 6 scalars."""
    return (w1 * u2 - w2 * u1, w2 * u0 - w0 * u2, w0 * u1 - w1 * u0,
            w1 * u5 - w2 * u4 + l1 * u2 - l2 * u1, w2 * u3 - w0 * u5 + l2 * u0 - l0 * u2,
            w0 * u4 - w1 * u3 + l0 * u1 - l1 * u0)


def rne_rate(parent, dofadr, dofnum, rootid, body_col, dof_col_arm, dof_col_damp, dof_col_coul, coulomb_eps,  # noqa: C901 (compiled kernel)
             cdof, xpos, xmat, subtree_com, v, a, s, rate, scratch):
    """rate (n_standard,) = Y(q, v, w, a)ᵀ s in O(n), after rne_torque at the same state (its forward pass in
    scratch). Forward: ws_b = ws_parent + Σ_{dofs j of b} cdof_j s_j, the motion the test velocities s give
    body b. Per unknown body: ⟨ws, f(I)⟩ = wsᵀ I ca − ½ (cv × ws)ᵀ I cw − ½ (cw × ws)ᵀ I cv (v ×* = −(v ×)ᵀ),
    its gradient G in the cinert numbers (_bilinear_grad), then in the body-frame parameters through
    cinert_of_params' map L: rate = Lᵀ G (the m, m·c and inertia parts below). Then the joint terms
    a_j s_j, v_j s_j, tanh(v_j / ε) s_j. Columns of known bodies and joints are not written."""
    nbody = parent.shape[0]
    nv = v.shape[0]
    S = scratch
    OV, OW, OA, OS = 0, 6 * nbody, 12 * nbody, 18 * nbody  # ws where rne_torque's F was
    for k in range(6):
        S[OS + k] = 0.0
    for b in range(1, nbody):
        ob, op = 6 * b, 6 * parent[b]
        z0, z1, z2 = S[OS + op], S[OS + op + 1], S[OS + op + 2]
        z3, z4, z5 = S[OS + op + 3], S[OS + op + 4], S[OS + op + 5]
        for j in range(dofadr[b], dofadr[b] + dofnum[b]):
            sj = s[j]
            z0 += cdof[j, 0] * sj
            z1 += cdof[j, 1] * sj
            z2 += cdof[j, 2] * sj
            z3 += cdof[j, 3] * sj
            z4 += cdof[j, 4] * sj
            z5 += cdof[j, 5] * sj
        S[OS + ob], S[OS + ob + 1], S[OS + ob + 2] = z0, z1, z2
        S[OS + ob + 3], S[OS + ob + 4], S[OS + ob + 5] = z3, z4, z5
        col = body_col[b]
        if col < 0:
            continue
        ov, ow, oa = OV + ob, OW + ob, OA + ob
        v0, v1, v2, v3, v4, v5 = S[ov], S[ov + 1], S[ov + 2], S[ov + 3], S[ov + 4], S[ov + 5]
        w0, w1, w2, w3, w4, w5 = S[ow], S[ow + 1], S[ow + 2], S[ow + 3], S[ow + 4], S[ow + 5]
        a0, a1, a2, a3, a4, a5 = S[oa], S[oa + 1], S[oa + 2], S[oa + 3], S[oa + 4], S[oa + 5]
        G0, G1, G2, G3, G4, G5, G6, G7, G8, G9 = _bilinear_grad(z0, z1, z2, z3, z4, z5, a0, a1, a2, a3, a4, a5)
        t0, t1, t2, t3, t4, t5 = _cross(v0, v1, v2, v3, v4, v5, z0, z1, z2, z3, z4, z5)  # cv × ws
        g0, g1, g2, g3, g4, g5, g6, g7, g8, g9 = _bilinear_grad(t0, t1, t2, t3, t4, t5, w0, w1, w2, w3, w4, w5)
        G0, G1, G2, G3, G4 = G0 - 0.5 * g0, G1 - 0.5 * g1, G2 - 0.5 * g2, G3 - 0.5 * g3, G4 - 0.5 * g4
        G5, G6, G7, G8, G9 = G5 - 0.5 * g5, G6 - 0.5 * g6, G7 - 0.5 * g7, G8 - 0.5 * g8, G9 - 0.5 * g9
        t0, t1, t2, t3, t4, t5 = _cross(w0, w1, w2, w3, w4, w5, z0, z1, z2, z3, z4, z5)  # cw × ws
        g0, g1, g2, g3, g4, g5, g6, g7, g8, g9 = _bilinear_grad(t0, t1, t2, t3, t4, t5, v0, v1, v2, v3, v4, v5)
        G0, G1, G2, G3, G4 = G0 - 0.5 * g0, G1 - 0.5 * g1, G2 - 0.5 * g2, G3 - 0.5 * g3, G4 - 0.5 * g4
        G5, G6, G7, G8, G9 = G5 - 0.5 * g5, G6 - 0.5 * g6, G7 - 0.5 * g7, G8 - 0.5 * g8, G9 - 0.5 * g9
        # G on the cinert (I_w 6, h_w 3, m): J = Gs : I_w + g_h · h_w' + g_m m with Gs symmetric (Gs_ii = G_i,
        # Gs_ik = G_(ik) / 2), I_w = R I_b Rᵀ + m (|r|² E − r rᵀ) + 2 (h·r) E − (h rᵀ + r hᵀ), h_w' = m r + h,
        # h = R h_b (cinert_of_params)
        root = rootid[b]
        r0 = xpos[b, 0] - subtree_com[root, 0]
        r1 = xpos[b, 1] - subtree_com[root, 1]
        r2 = xpos[b, 2] - subtree_com[root, 2]
        S00, S11, S22 = G0, G1, G2
        S01, S02, S12 = 0.5 * G3, 0.5 * G4, 0.5 * G5
        tr = S00 + S11 + S22
        Sr0 = S00 * r0 + S01 * r1 + S02 * r2
        Sr1 = S01 * r0 + S11 * r1 + S12 * r2
        Sr2 = S02 * r0 + S12 * r1 + S22 * r2
        rr = r0 * r0 + r1 * r1 + r2 * r2
        rate[col] = rr * tr - (r0 * Sr0 + r1 * Sr1 + r2 * Sr2) + (G6 * r0 + G7 * r1 + G8 * r2) + G9
        # the gradient in h (world), then h_b = Rᵀ h
        d0 = 2.0 * r0 * tr - 2.0 * Sr0 + G6
        d1 = 2.0 * r1 * tr - 2.0 * Sr1 + G7
        d2 = 2.0 * r2 * tr - 2.0 * Sr2 + G8
        for c in range(3):
            rate[col + 1 + c] = xmat[b, c] * d0 + xmat[b, 3 + c] * d1 + xmat[b, 6 + c] * d2
        # Gs : R I_b Rᵀ = (Rᵀ Gs R) : I_b, an off-diagonal I_b entry counted twice
        for u in range(6):
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
            xa0, xa1, xa2 = xmat[b, pa], xmat[b, 3 + pa], xmat[b, 6 + pa]
            xb0, xb1, xb2 = xmat[b, pb], xmat[b, 3 + pb], xmat[b, 6 + pb]
            q0 = S00 * xb0 + S01 * xb1 + S02 * xb2
            q1 = S01 * xb0 + S11 * xb1 + S12 * xb2
            q2 = S02 * xb0 + S12 * xb1 + S22 * xb2
            val = xa0 * q0 + xa1 * q1 + xa2 * q2
            rate[col + 4 + u] = val if pa == pb else 2.0 * val
    for j in range(nv):
        if dof_col_arm[j] >= 0:
            rate[dof_col_arm[j]] = a[j] * s[j]
        if dof_col_damp[j] >= 0:
            rate[dof_col_damp[j]] = v[j] * s[j]
        if dof_col_coul[j] >= 0:
            rate[dof_col_coul[j]] = math.tanh(v[j] / coulomb_eps) * s[j]


def rne_law_torque(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp, dof_col_coul,
                   arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity, v, w, a, theta,
                   has_base, bptr, bidx, bval, pi, tau, scratch):
    """rne_torque for a law's estimates θ (n_params,): the standard parameters π = B θ first when has_base (B by
    columns: column c's entries bval[p] in rows bidx[p], p in [bptr[c], bptr[c + 1])), else π = θ (pi unused).
    tau (nv,) = Y θ + τ_known, Y the law's regressor (Y_standard B with a base map)."""
    params = theta
    if has_base != 0:
        for i in range(pi.shape[0]):
            pi[i] = 0.0
        for c in range(theta.shape[0]):
            for p in range(bptr[c], bptr[c + 1]):
                pi[bidx[p]] += bval[p] * theta[c]
        params = pi
    # one call site: rne_torque is inlined into the compiled callback once, not once per branch (half the compile)
    rne_torque(parent, dofadr, dofnum, rootid, body_col, body_known, dof_col_arm, dof_col_damp, dof_col_coul,
               arm_known, damp_known, coulomb_eps, cdof, xpos, xmat, subtree_com, cinert, gravity, v, w, a, params,
               tau, scratch)


def rne_law_rate(parent, dofadr, dofnum, rootid, body_col, dof_col_arm, dof_col_damp, dof_col_coul, coulomb_eps,
                 cdof, xpos, xmat, subtree_com, v, a, s, has_base, bptr, bidx, bval, rate_std, rate, scratch):
    """rne_rate for a law: rate (n_params,) = Yᵀ s, Y the law's regressor (with a base map Bᵀ (Y_standardᵀ s),
    through rate_std (n_standard,)); after rne_law_torque at the same state."""
    # one call site, as in rne_law_torque: rne_rate compiled in once
    rne_rate(parent, dofadr, dofnum, rootid, body_col, dof_col_arm, dof_col_damp, dof_col_coul, coulomb_eps,
             cdof, xpos, xmat, subtree_com, v, a, s, rate_std if has_base != 0 else rate, scratch)
    if has_base != 0:
        for c in range(rate.shape[0]):
            acc = 0.0
            for p in range(bptr[c], bptr[c + 1]):
                acc += bval[p] * rate_std[bidx[p]]
            rate[c] = acc

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

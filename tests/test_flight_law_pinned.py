"""The flight laws' kernel (adaptive_mj.laws.flight_kernel, run as plain Python: no numba) pinned with independent
numbers (issue 54): the geometric law, the geometric adaptive law (with and without the inertia adapted) and L1
augmentation's thrust and moment terms against a reference written here from the papers' formulas with numpy,
scipy's rotation and a complex-step derivative for Ω_d (and finite differences of it for Ω̇_d), at non-zero states,
references, estimates and L1 estimates; the logged s by hand; the allocation's yaw-last rule by hand; L1's update
against the piecewise-constant adaptation law written out here. Edge cases by name: no force asked, a force along
the heading, a closed dead-zone, a rate at a box's edge, estimates the builder refuses.

The reference (Lee, Leok & McClamroch 2010; Goodarzi, Lee & Lee 2015's τ̂; Slotine & Li's attitude regressor for
the inertia; Hovakimyan & Cao's L1): with e_x = p − p_d, e_v = v − v_d, s = e_v + c e_x (per axis),
  geometric  F = −k_x e_x − k_v e_v + m̂ g e₃ + m̂ p̈_d
  adaptive   F = m̂ w − d̂ − k s,   w = p̈_d − c e_v + g e₃;   m̂' = −sᵀw/γ_m, d̂' = s/γ_d, τ̂' = (e_Ω + c_R e_R)/γ_τ
  f = F·Re₃;  R_d = [b₂ × b₃, b₂, b₃], b₃ = F/‖F‖, b₂ = b₃ × e₁/‖b₃ × e₁‖;  e_R = ½ vee(R_dᵀR − RᵀR_d)
  Ω_d = vee(R_dᵀṘ_d) along Ḟ = m̂ p⃛_d;  e_Ω = Ω − RᵀR_dΩ_d
  M = −k_R e_R − k_Ω e_Ω + Ω × ĴΩ − Ĵ(Ω × RᵀR_dΩ_d) − τ̂
  inertia adapted: s_R = e_Ω + c_R e_R, Ω_r = Ω − s_R, Ω̇_r = −Ω × RᵀR_dΩ_d + RᵀR_dΩ̇_d − c_R E e_Ω
             (E = ½(tr(RᵀR_d) I − RᵀR_d), Ω̇_d along F̈ = m̂ p⁽⁴⁾_d), M = ĴΩ̇_r + Ω_r × ĴΩ − k_Ω s_R − k_R e_R − τ̂,
             ĵ_k' = −s_Rᵀ(E_k Ω̇_r + Ω_r × E_k Ω)/γ_k for the six symmetric basis matrices E_k
  L1         f −= m̂ (a_v · Re₃), M −= Ĵ a_Ω  (a = the filtered C σ̂: aug)
  u = A⁻¹ [f, M]."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from adaptive_mj.laws import flight_kernel as fk

G_ACC = 9.81
E1, E3 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
# the hand allocation: hubs at (±1, ±1) m numbered (+,+), (+,−), (−,−), (−,+), yaw 0.5 m per N signed (+, −, +, −):
# rows [1 1 1 1], [y], [−x], [0.5 dir]; its rows are orthogonal, so A⁻¹ = Aᵀ diag(1/4, 1/4, 1/4, 1)
XY = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])
DIRS = np.array([1.0, -1.0, 1.0, -1.0])
A = np.vstack([np.ones(4), XY[:, 1], -XY[:, 0], 0.5 * DIRS])
AINV = A.T @ np.diag([0.25, 0.25, 0.25, 1.0])


def _inertia(th):
    """(3, 3) Ĵ [kg m²] from θ̂ (13,)'s Jxx, Jyy, Jzz, Jxy, Jxz, Jyz."""
    xx, yy, zz, xy, xz, yz = th[1:7]
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def _vee(S):
    """(3,) the vector of a skew (3, 3) matrix."""
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def _desired(F):
    """R_d of F (real or complex: norms as square roots of sums of squares, so a complex step differentiates it)."""
    b3 = F / np.sqrt(F @ F)
    c = np.cross(b3, E1)
    b2 = c / np.sqrt(c @ c)
    return np.column_stack([np.cross(b2, b3), b2, b3])


def _omega_d(F, F_dot):
    """Ω_d = vee(R_dᵀ dR_d/dt) for F moving at F_dot: dR_d/dt by a complex step (exact to rounding)."""
    eps = 1e-30
    dRd = np.imag(_desired(F + 1j * eps * F_dot)) / eps
    return _vee(_desired(F).T @ dRd)


def _params(mode, *, adapt=0.0, adapt_j=0.0, l1=0.0, dz_width=0.0, dz_on_s=1.0, sigma=0.0, emod=0.0,
            alloc=fk.ALLOC_EXACT_CLIP):
    """P (P_SIZE,): the law's numbers by the kernel's layout: k_R 7.8e-3 N m/rad, k_Ω 6.7e-4 N m s/rad, g 9.81 m/s²,
    a_s −5 1/s, w_c 5 rad/s, c_R 2.5 1/s, per-axis k_x [N/m], k_v [N s/m], c [1/s], k [N s/m], T_max [N]."""
    P = np.zeros(fk.P_SIZE)
    P[fk.P_MODE], P[fk.P_KR], P[fk.P_KW], P[fk.P_G] = mode, 7.8e-3, 6.7e-4, G_ACC
    P[fk.P_DZ_WIDTH], P[fk.P_DZ_ON_S], P[fk.P_SIGMA], P[fk.P_EMOD] = dz_width, dz_on_s, sigma, emod
    P[fk.P_ADAPT], P[fk.P_L1], P[fk.P_AS], P[fk.P_WC], P[fk.P_CR] = adapt, l1, -5.0, 5.0, 2.5
    P[fk.P_ADAPT_J] = adapt_j
    P[fk.P_KX:fk.P_KX + 3] = [0.195, 0.21, 0.45]
    P[fk.P_KV:fk.P_KV + 3] = [0.12, 0.13, 0.27]
    P[fk.P_C:fk.P_C + 3] = [1.6, 1.7, 1.8]
    P[fk.P_K:fk.P_K + 3] = [0.12, 0.11, 0.27]
    P[fk.P_ALLOC] = alloc
    P[fk.P_TMAX:fk.P_TMAX + 4] = [0.14375, 0.14, 0.15, 0.145]
    return P


GAMMA = np.array([3.0, 2e-7, 3e-7, 4e-7, 5e-7, 6e-7, 7e-7, 0.5, 0.6, 0.7, 8e-3, 9e-3, 1.1e-2])


def _gains(theta0=None, lower=None, upper=None):
    """G (4, 13): rows γ, θ₀, lower, upper."""
    return np.vstack([GAMMA, np.zeros(13) if theta0 is None else theta0,
                      np.full(13, -np.inf) if lower is None else lower,
                      np.full(13, np.inf) if upper is None else upper])


def _case(rng):
    """(x (4, 3), r (5, 3), θ̂ (13,)): a state off the reference (tilted, turning) [m, m/s, rad, rad/s], a reference
    with every derivative non-zero [m, m/s, ..., m/s⁴], estimates with products of inertia, a force [N] and a moment
    [N m]."""
    x = np.vstack([rng.normal(0, 0.2, 3) + [0, 0, 1], rng.normal(0, 0.5, 3), rng.normal(0, 0.3, 3),
                   rng.normal(0, 2.0, 3)])
    r = np.vstack([[0.1, -0.2, 1.1], rng.normal(0, 0.5, 3), rng.normal(0, 1.0, 3), rng.normal(0, 2.0, 3),
                   rng.normal(0, 4.0, 3)])
    th = np.array([0.035, 1.5e-5, 1.6e-5, 2.9e-5, 1e-6, -2e-6, 1.5e-6, 0.01, -0.02, 0.015, 1e-4, -2e-4, 3e-4])
    th[0] += rng.uniform(-0.005, 0.005)
    return x, r, th


def _run(x, r, th, P, G, aug=None, rate0=None):
    """(u (4,) [N], s (3,) [m/s], θ̂' (13,)) of flight_law with the hand allocation's inverse; scratch filled with
    NaN (a value read before it is written shows); aug (6,) [m/s², rad/s²] the L1 estimate (None: zeros)."""
    u, s = np.full(4, np.nan), np.full(3, np.nan)
    rate = np.full(13, np.nan) if rate0 is None else rate0
    fk.flight_law(x, r, th, P, G, AINV, np.zeros(6) if aug is None else aug, np.full((3, 3), np.nan),
                  np.full(3, np.nan), np.full(fk.TMP_SIZE, np.nan), u, s, rate)
    return u, s, rate


def _reference(x, r, th, P, G, aug):
    """(u (4,), s (3,), rate (13,)) by the module docstring's formulas."""
    p, v, phi, W = x
    R = Rotation.from_rotvec(phi).as_matrix()
    m, J, d, tau = th[0], _inertia(th), th[7:10], th[10:13]
    c, kx, kv, k = (P[i:i + 3] for i in (fk.P_C, fk.P_KX, fk.P_KV, fk.P_K))
    ex, ev = p - r[0], v - r[1]
    s = ev + c * ex
    adaptive = P[fk.P_MODE] == fk.MODE_ADAPTIVE
    w = r[2] - c * ev + G_ACC * E3
    F = m * w - d - k * s if adaptive else -kx * ex - kv * ev + m * G_ACC * E3 + m * r[2]
    f = F @ R[:, 2]
    if not np.sqrt(F @ F) > 1e-12:  # no force asked: R_d level (F taken as e₃, ‖F‖ = 1), f = 0 as asked
        F = E3.copy()
    Rd = _desired(F)
    eR = 0.5 * _vee(Rd.T @ R - R.T @ Rd)
    Wd = _omega_d(F, m * r[3])
    vb = R.T @ Rd @ Wd
    eW = W - vb
    kR, kW, cR = P[fk.P_KR], P[fk.P_KW], P[fk.P_CR]
    rate = np.zeros(13)
    signal = np.linalg.norm(s) if P[fk.P_DZ_ON_S] else np.linalg.norm(ex)
    adapting = adaptive and P[fk.P_ADAPT] != 0 and signal >= P[fk.P_DZ_WIDTH]
    if not (adaptive and P[fk.P_ADAPT_J]):
        M = -kR * eR - kW * eW + np.cross(W, J @ W) - J @ np.cross(W, vb) - tau
    else:
        def omega_d_at(t):  # F(t) = F + t m p⃛_d + t²/2 m p⁽⁴⁾_d
            return _omega_d(F + t * m * r[3] + 0.5 * t * t * m * r[4], m * r[3] + t * m * r[4])

        h = 1e-3  # the five-point derivative: error ~h⁴
        Wd_dot = (omega_d_at(-2 * h) - 8 * omega_d_at(-h) + 8 * omega_d_at(h) - omega_d_at(2 * h)) / (12 * h)
        Q = R.T @ Rd
        E = 0.5 * (np.trace(Q) * np.eye(3) - Q)
        sR = eW + cR * eR
        Wr = W - sR
        ar = -np.cross(W, vb) + Q @ Wd_dot - cR * E @ eW
        M = J @ ar + np.cross(Wr, J @ W) - kW * sR - kR * eR - tau
        if adapting:
            for kk, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))):
                Ek = np.zeros((3, 3))
                Ek[i, j] = Ek[j, i] = 1.0
                rate[1 + kk] = -sR @ (Ek @ ar + np.cross(Wr, Ek @ W)) / G[0, 1 + kk]
    if adapting:
        rate[0] = -(s @ w) / G[0, 0]
        rate[7:10] = s / G[0, 7:10]
        rate[10:13] = (eW + cR * eR) / G[0, 10:13]
    if adaptive and P[fk.P_ADAPT] != 0:
        rate -= (P[fk.P_SIGMA] + P[fk.P_EMOD] * np.linalg.norm(s)) * (th - G[1]) / G[0]
        rate[(th <= G[2]) & (rate < 0)] = 0.0
        rate[(th >= G[3]) & (rate > 0)] = 0.0
    if P[fk.P_L1]:
        f -= m * (aug[:3] @ R[:, 2])
        M = M - J @ aug[3:]
    return AINV @ np.concatenate([[f], M]), s, rate


AUG = np.array([0.3, -0.5, 0.8, 4.0, -6.0, 3.0])  # a non-zero L1 estimate [m/s², rad/s²]


@pytest.mark.parametrize("law", ["geometric", "adaptive", "adaptive_inertia", "adaptive_fixed",
                                 "l1_geometric", "l1_adaptive", "leaky", "fixed_leaky", "geometric_told_to_adapt"])
def test_the_kernel_is_the_papers_law(law):
    """u, s and θ̂' against the reference at ten random off-reference states (to 1e-9 relative, 1e-7 with the
    inertia adapted: Ω̇_d by finite differences)."""
    P = {"geometric": _params(fk.MODE_GEOMETRIC), "adaptive": _params(fk.MODE_ADAPTIVE, adapt=1.0),
         "adaptive_inertia": _params(fk.MODE_ADAPTIVE, adapt=1.0, adapt_j=1.0),
         "adaptive_fixed": _params(fk.MODE_ADAPTIVE),  # the adaptive law's force, not adapting (a baseline)
         "l1_geometric": _params(fk.MODE_GEOMETRIC, l1=1.0),
         "l1_adaptive": _params(fk.MODE_ADAPTIVE, adapt=1.0, adapt_j=1.0, l1=1.0),
         "leaky": _params(fk.MODE_ADAPTIVE, adapt=1.0, sigma=0.3, emod=0.7),
         # a law that does not adapt leaks nothing; the geometric law ignores the adaptive law's switches
         "fixed_leaky": _params(fk.MODE_ADAPTIVE, sigma=0.3, emod=0.7),
         "geometric_told_to_adapt": _params(fk.MODE_GEOMETRIC, adapt=1.0, adapt_j=1.0, sigma=0.3)}[law]
    G = _gains(theta0=np.linspace(0.01, 0.13, 13))
    rng = np.random.default_rng(54)
    tol = 1e-7 if P[fk.P_ADAPT_J] else 1e-9
    for _ in range(10):
        x, r, th = _case(rng)
        u, s, rate = _run(x, r, th, P, G, AUG)
        u_ref, s_ref, rate_ref = _reference(x, r, th, P, G, AUG)
        np.testing.assert_allclose(u, u_ref, rtol=tol, atol=1e-14)
        np.testing.assert_allclose(s, s_ref, rtol=1e-13)
        np.testing.assert_allclose(rate, rate_ref, rtol=tol, atol=1e-15)
        if P[fk.P_ADAPT] and P[fk.P_MODE] == fk.MODE_ADAPTIVE:
            assert np.all(rate[[0, 7, 8, 9, 10, 11, 12]] != 0.0)
        else:
            assert np.array_equal(rate, np.zeros(13))


def test_the_logged_s_by_hand():
    """s = e_v + c e_x per axis, c = (1.6, 1.7, 1.8): e_x = (0.1, −0.2, 0.05), e_v = (0.3, 0.1, −0.4) give
    s = (0.46, −0.24, −0.31) [m/s], in either law."""
    x = np.array([[1.1, 1.8, 3.05], [0.3, 0.1, -0.4], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    for mode in (fk.MODE_GEOMETRIC, fk.MODE_ADAPTIVE):
        _, s, _ = _run(x, r, th, _params(mode), _gains())
        np.testing.assert_allclose(s, [0.46, -0.24, -0.31], rtol=1e-14)


def test_the_l1_terms_at_hover_by_hand():
    """Level on the reference at hover with the true mass (F = m g e₃, f = m g = 0.2943 N, no moment): an L1
    estimate a_v = (0.3, −0.5, 0.8) m/s² takes m a_v·e₃ = 0.024 N off the thrust, a_Ω = (4, −6, 3) rad/s² takes
    J a_Ω = (5.72e-5, −8.58e-5, 8.58e-5) N m off the moment (J = diag(1.43e-5, 1.43e-5, 2.86e-5)): u = A⁻¹[0.2703,
    −5.72e-5, 8.58e-5, −8.58e-5]."""
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    for mode in (fk.MODE_GEOMETRIC, fk.MODE_ADAPTIVE):
        u, _, _ = _run(x, r, th, _params(mode, l1=1.0), _gains(), AUG)
        expected = AINV @ np.array([0.2943 - 0.024, -5.72e-5, 8.58e-5, -8.58e-5])
        np.testing.assert_allclose(u, expected, rtol=1e-12)
        u0, _, _ = _run(x, r, th, _params(mode), _gains(), AUG)  # no L1: the estimate is ignored
        np.testing.assert_allclose(u0, AINV @ np.array([0.2943, 0.0, 0.0, 0.0]), rtol=1e-12, atol=1e-17)


def test_the_l1_thrust_term_reads_the_body_z_axis():
    """Rolled 90° about x (body z = world −y), at rest: f = F·Re₃ = −F_y; the L1 thrust term is −m a_v·Re₃ =
    +m a_v,y = −0.015 N; and M −= J a_Ω with J's off-diagonal entries."""
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [math.pi / 2, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.zeros((5, 3))
    r[0] = [0.0, 0.0, 1.0]
    th = np.array([0.03, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3, 0, 0, 0, 0, 0, 0])
    P = _params(fk.MODE_GEOMETRIC, l1=1.0)
    P[fk.P_KR] = P[fk.P_KW] = 0.0  # no attitude feedback: M is the L1 term alone
    u, _, _ = _run(x, r, th, P, _gains(), AUG)
    # f = F·Re₃ with F = m g e₃ and Re₃ = (0, −1, 0): 0; the L1 term −m a_v·Re₃ = −0.03·(−0.5)(−1) = −0.015
    # J a_Ω = (1·4 + 0.1·(−6) + 0.2·3, 0.1·4 + 2·(−6) + 0.3·3, 0.2·4 + 0.3·(−6) + 3·3) = (4.0, −10.7, 8.0)
    np.testing.assert_allclose(A @ u, [-0.015, -4.0, 10.7, -8.0], rtol=1e-12, atol=1e-15)


def test_no_force_asked_flies_level():
    """A reference in free fall (p̈_d = −g e₃) on it: F = 0, so f = 0 and R_d = I (b₃ = e₃); at R = I, Ω = 0 the only
    moment is −τ̂."""
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, -G_ACC], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0, 0, 0, 1e-4, -2e-4, 3e-4])
    u, _, _ = _run(x, r, th, _params(fk.MODE_GEOMETRIC), _gains())
    np.testing.assert_allclose(A @ u, [0.0, -1e-4, 2e-4, -3e-4], rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("law", ["geometric", "adaptive_inertia"])
def test_no_force_asked_at_a_tilted_turning_state(law):
    """F = 0 exactly (the reference in free fall, on it; m̂ p̈_d cancels gravity) while tilted, turning and with a
    jerk and snap: f = 0 and R_d level (b₃d = e₃, ‖F‖ taken as 1 for Ω_d), against the reference."""
    P = _params(fk.MODE_GEOMETRIC) if law == "geometric" else _params(fk.MODE_ADAPTIVE, adapt=1.0, adapt_j=1.0)
    th = np.array([0.03, 1.5e-5, 1.6e-5, 2.9e-5, 1e-6, -2e-6, 1.5e-6, 0.0, 0.0, 0.0, 1e-4, -2e-4, 3e-4])
    x = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 0.1], [0.3, -0.2, 0.4], [1.0, -2.0, 0.5]])
    r = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 0.1], [0.0, 0.0, -G_ACC], [0.5, -1.0, 2.0], [3.0, 1.0, -2.0]])
    if law != "geometric":  # F = m̂ w − d̂ − k s with s = 0 and w = p̈_d + g e₃ = 0
        r[2] = [0.0, 0.0, -G_ACC]
    u, s, _ = _run(x, r, th, P, _gains())
    u_ref, _, _ = _reference(x, r, th, P, _gains(), np.zeros(6))
    assert s.tolist() == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(u, u_ref, rtol=1e-7, atol=1e-14)
    assert (A @ u)[0] == pytest.approx(0.0, abs=1e-15)


def test_a_force_along_the_heading_keeps_b2_on_e2():
    """F along e₁ (p̈_d = (5, 0, −g)): b₃ = e₁ leaves b₃ × e₁ = 0; b₂ = e₂ then, b₁ = e₂ × e₁ = −e₃, and at R = I
    e_R = ½ vee(R_dᵀ − R_d) = (0, −1, 0): M = (0, k_R, 0), f = F·e₃ = 0."""
    x = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [5.0, 0.0, -G_ACC], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    u, _, _ = _run(x, r, th, _params(fk.MODE_GEOMETRIC), _gains())
    np.testing.assert_allclose(A @ u, [0.0, 0.0, 7.8e-3, 0.0], rtol=1e-12, atol=1e-15)
    # with a jerk (0, 5, 0) m/s³: Ḟ = m (0, 5, 0), ḃ₃ = Ḟ/‖F‖ = (0, 1, 0) (‖F‖ = 5 m), ċ = ḃ₃ × e₁ = (0, 0, −1), and
    # with ‖b₃ × e₁‖ taken as 1: ḃ₂ = ċ − (b₂·ċ) b₂ = (0, 0, −1), ḃ₁ = ḃ₂ × b₃ + b₂ × ḃ₃ = (0, −1, 0);
    # Ω_d = (b₃·ḃ₂, b₁·ḃ₃, b₂·ḃ₁) = (0, 0, −1), R_d Ω_d = −b₃ = (−1, 0, 0): e_Ω = (1, 0, 0), M = (−k_Ω, k_R, 0)
    r[3] = [0.0, 5.0, 0.0]
    u, _, _ = _run(x, r, th, _params(fk.MODE_GEOMETRIC), _gains())
    np.testing.assert_allclose(A @ u, [0.0, -6.7e-4, 7.8e-3, 0.0], rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("p_y, p_dy", [(-0.5, -1.0), (1.5, 1.0)])
@pytest.mark.parametrize("on_s", [1.0, 0.0])
def test_a_closed_dead_zone_stops_every_rate_and_an_open_one_at_its_edge_adapts(on_s, p_y, p_dy):
    """The dead-zone on ‖s‖ (or on ‖e_x‖): below its width no estimate moves (rates exactly 0, the inertia's too);
    from the width on (exactly at it included) it adapts. Numbers exact in binary: p − p_d = (1.25, p_y, 1.5) −
    (1, p_dy, 1) = (0.25, 0.5, 0.5) (‖e_x‖ = 0.75), v = v_d (e_v = 0), c = 2 on every axis: s = (0.5, 1, 1),
    ‖s‖ = 1.5."""
    x = np.array([[1.25, p_y, 1.5], [0.3, -0.2, 0.1], [0.1, 0.0, 0.0], [0.5, 0.0, 0.0]])
    r = np.array([[1.0, p_dy, 1.0], [0.3, -0.2, 0.1], [0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.5, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    signal = 1.5 if on_s else 0.75
    for width, adapts in ((signal * (1 + 1e-12), False), (signal, True), (signal * (1 - 1e-12), True)):
        P = _params(fk.MODE_ADAPTIVE, adapt=1.0, adapt_j=1.0, dz_width=width, dz_on_s=on_s)
        P[fk.P_C:fk.P_C + 3] = 2.0
        _, s, rate = _run(x, r, th, P, _gains())
        assert s.tolist() == [0.5, 1.0, 1.0]
        if adapts:
            assert rate[0] != 0.0 and np.all(rate[1:4] != 0.0) and np.all(rate[10:13] != 0.0)
        else:
            assert np.array_equal(rate, np.zeros(13))


def test_the_box_stops_a_rate_that_leaves_it():
    """m̂ at its lower bound with m̂' < 0, d̂_x at its upper bound with d̂_x' > 0: both rates 0, the rest as they were.
    e_x = (0.2, 0, 0.1) m at rest, c = (1.6, ·, 1.8): s = (0.32, 0, 0.18) m/s, w = g e₃."""
    x = np.array([[0.2, 0.0, 1.1], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    r = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    th = np.array([0.03, 1.43e-5, 1.43e-5, 2.86e-5, 0, 0, 0, 0.01, 0, 0, 0, 0, 0])
    P = _params(fk.MODE_ADAPTIVE, adapt=1.0)
    _, _, free = _run(x, r, th, P, _gains())
    # s = (0.32, 0, 0.18), w = (0, 0, g): m̂' = −0.18 g/3 < 0, d̂_x' = 0.32/0.5 > 0
    assert free[0] == pytest.approx(-0.18 * G_ACC / 3.0, rel=1e-12) and free[7] == pytest.approx(0.64, rel=1e-12)
    lower, upper = np.full(13, -np.inf), np.full(13, np.inf)
    lower[0], upper[7] = 0.03, 0.01
    _, _, boxed = _run(x, r, th, P, _gains(lower=lower, upper=upper))
    assert boxed[0] == 0.0 and boxed[7] == 0.0
    np.testing.assert_array_equal(np.delete(boxed, [0, 7]), np.delete(free, [0, 7]))


def test_the_rates_are_written_afresh_each_call():
    """A rate array holding last call's numbers: a law that does not adapt leaves zeros in it."""
    x, r, th = _case(np.random.default_rng(1))
    for P in (_params(fk.MODE_GEOMETRIC), _params(fk.MODE_ADAPTIVE)):
        _, _, rate = _run(x, r, th, P, _gains(), rate0=np.full(13, 5.0))
        assert np.array_equal(rate, np.zeros(13))


# --- the rotation and the inertia -----------------------------------------------------------------------


def test_rodrigues_by_hand_and_against_scipy():
    R = np.full((3, 3), np.nan)
    fk.rodrigues(np.array([0.0, 0.0, math.pi / 2]), R)
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    fk.rodrigues(np.array([1e-13, -2e-13, 3e-13]), R)  # the first-order branch: I + φ^
    np.testing.assert_array_equal(R, [[1.0, -3e-13, -2e-13], [3e-13, 1.0, -1e-13], [2e-13, 1e-13, 1.0]])
    rng = np.random.default_rng(7)
    for _ in range(10):
        phi = rng.normal(0, 1.0, 3)
        fk.rodrigues(phi, R)
        np.testing.assert_allclose(R, Rotation.from_rotvec(phi).as_matrix(), atol=1e-14)


def test_the_inertia_times_a_vector_by_hand():
    th = np.array([0.0, 1.0, 2.0, 3.0, 0.1, 0.2, 0.3] + [0.0] * 6)
    out = np.full(3, np.nan)
    fk.inertia_times(th, np.array([1.0, -1.0, 2.0]), out)
    # [[1, .1, .2], [.1, 2, .3], [.2, .3, 3]] @ (1, −1, 2)
    np.testing.assert_allclose(out, [1.3, -1.3, 5.9], rtol=1e-14)


# --- the allocation -------------------------------------------------------------------------------------------


def _allocate(f, M, mode, tmax=2.0):
    """(4,) thrusts [N] of allocate with the hand allocation's inverse for f [N], M (3,) [N m], every T_max = tmax."""
    P = _params(fk.MODE_GEOMETRIC, alloc=mode)
    P[fk.P_TMAX:fk.P_TMAX + 4] = tmax
    u = np.full(4, np.nan)
    fk.allocate(AINV, f, *M, P, u)
    return u


def test_the_exact_inverse_when_it_fits_or_when_asked():
    """f = 4, M = (0, 0, 3): u_i = 1 + 1.5 dir_i = (2.5, −0.5, 2.5, −0.5), outside [0, 2]: kept as it is by the
    exact inverse (the loop clamps it), and a command that fits is the exact inverse under either mode."""
    np.testing.assert_allclose(_allocate(4.0, (0.0, 0.0, 3.0), fk.ALLOC_EXACT_CLIP), [2.5, -0.5, 2.5, -0.5])
    for mode in (fk.ALLOC_EXACT_CLIP, fk.ALLOC_YAW_LAST):
        # f = 4, M = (1, −0.5, 1): u = 1 + (y M0 − x M1)/4 + 0.5 dir M2 = (1.875, 0.375, 1.125, 0.625)... by hand:
        # rotor 1 (+,+,+): 1 + 0.25 + 0.125 + 0.5 = 1.875; 2 (+,−,−): 1 − 0.25 + 0.125 − 0.5 = 0.375;
        # 3 (−,−,+): 1 − 0.25 − 0.125 + 0.5 = 1.125; 4 (−,+,−): 1 + 0.25 − 0.125 − 0.5 = 0.625
        np.testing.assert_allclose(_allocate(4.0, (1.0, -0.5, 1.0), mode), [1.875, 0.375, 1.125, 0.625],
                                   rtol=1e-15)


def test_yaw_last_keeps_the_share_of_yaw_that_fits():
    """f = 4, M_z = 3 with T_max 2: a_i = 1, b_i = 1.5 dir_i; k = (2 − 1)/1.5 = 1/1.5 (b > 0) = −1/−1.5 (b < 0):
    u = 1 + dir_i = (2, 0, 2, 0); with a roll moment the limiting rotor sets k: f = 4, M = (1, 0, 3): a = (1.25,
    0.75, 0.75, 1.25), b = 1.5 dir: rotor 1 (2 − 1.25)/1.5 = 0.5, rotor 2 0.75/1.5 = 0.5, rotor 3 (2 − 0.75)/1.5,
    rotor 4 1.25/1.5: k = 0.5, u = a + 0.75 dir = (2, 0, 1.5, 0.5)."""
    np.testing.assert_allclose(_allocate(4.0, (0.0, 0.0, 3.0), fk.ALLOC_YAW_LAST), [2.0, 0.0, 2.0, 0.0],
                               atol=1e-15)
    np.testing.assert_allclose(_allocate(4.0, (1.0, 0.0, 3.0), fk.ALLOC_YAW_LAST), [2.0, 0.0, 1.5, 0.5],
                               atol=1e-15)
    # the rotors' own limits: rotor 3's T_max 1.7 makes its bound (1.7 − 0.75)/1.5 = 0.6333 > 0.5: k stays 0.5
    P = _params(fk.MODE_GEOMETRIC, alloc=fk.ALLOC_YAW_LAST)
    P[fk.P_TMAX:fk.P_TMAX + 4] = [1.85, 2.0, 2.0, 2.0]  # rotor 1's bound (1.85 − 1.25)/1.5 = 0.4
    u = np.full(4, np.nan)
    fk.allocate(AINV, 4.0, 1.0, 0.0, 3.0, P, u)
    np.testing.assert_allclose(u, [1.25 + 0.6, 0.75 - 0.6, 0.75 + 0.6, 1.25 - 0.6], atol=1e-15)


def test_yaw_last_with_a_rotor_already_outside_drops_the_yaw_and_no_yaw_keeps_it_all():
    """f = 10 (a_i = 2.5 > T_max 2) and M_z = 1: every bound is negative, floored to 0: k = 0, u = 2.5 each (the
    loop clamps them). f = 10 with no yaw: b = 0, k = 1: u = 2.5 each too."""
    np.testing.assert_allclose(_allocate(10.0, (0.0, 0.0, 1.0), fk.ALLOC_YAW_LAST), [2.5] * 4, rtol=1e-15)
    np.testing.assert_allclose(_allocate(10.0, (0.0, 0.0, 0.0), fk.ALLOC_YAW_LAST), [2.5] * 4, rtol=1e-15)
    # only a low rotor outside (below 0): f = 0.4, M_z = 1: a = 0.1, b = 0.5 dir: (2 − 0.1)/0.5 = 3.8 and
    # −0.1/−0.5 = 0.2: k = 0.2, u = 0.1 + 0.1 dir = (0.2, 0, 0.2, 0)
    np.testing.assert_allclose(_allocate(0.4, (0.0, 0.0, 1.0), fk.ALLOC_YAW_LAST), [0.2, 0.0, 0.2, 0.0],
                               atol=1e-15)


def _yaw_last_reference(Ainv, f, M, tmax):
    """The yaw-last rule solved by bisection rather than in closed form: the largest k in [0, 1] such that the yaw's
    share k pushes no rotor of u(k) = Ainv [f, M0, M1, 0] + k Ainv[:, 3] M2 past the limit it moves toward (a rotor
    the yaw raises stays at or below T_max_i, one it lowers at or above 0; one already past that limit: k = 0); the
    exact inverse where it fits in [0, T_max_i]. (This is the allocation's closed form; its docstring's looser
    "no rotor further outside than at k = 0" would let a rotor below 0 rise past T_max by as much.)"""
    a = Ainv[:, :3] @ np.array([f, M[0], M[1]])
    b = Ainv[:, 3] * M[2]
    exact = Ainv @ np.array([f, *M])
    if np.all((exact >= 0.0) & (exact <= tmax)):
        return exact

    def allowed(k):
        u = a + k * b
        return bool(np.all(((b <= 0) | (u <= tmax)) & ((b >= 0) | (u >= 0.0))))

    lo, hi = 0.0, 1.0
    if allowed(1.0):
        lo = 1.0
    elif allowed(0.0):
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid in (lo, hi):
                break
            lo, hi = (mid, hi) if allowed(mid) else (lo, mid)
    return a + lo * b


def test_yaw_last_against_the_rule_at_random_commands():
    """Random allocations (one with a rotor the yaw does not move: a zero in its yaw column), per-rotor limits and
    commands (a negative collective thrust among them): the closed form against the bisection, and the exact
    inverse under ALLOC_EXACT_CLIP. P's other entries hold numbers unlike any T_max (a limit read from the wrong
    slot shows)."""
    rng = np.random.default_rng(54)
    cases = 0
    for n in range(300):
        Ainv = rng.normal(0.0, 1.0, (4, 4))
        if n % 3 == 0:
            Ainv[rng.integers(4), 3] = 0.0
        tmax = rng.uniform(0.5, 2.0, 4)
        f, M = rng.normal(1.0, 1.5), rng.normal(0.0, 1.0, 3)
        P = _params(fk.MODE_GEOMETRIC, alloc=fk.ALLOC_YAW_LAST)
        P[:fk.P_TMAX] = np.where(P[:fk.P_TMAX] == fk.ALLOC_YAW_LAST, P[:fk.P_TMAX], 7.0 + np.arange(fk.P_TMAX))
        P[fk.P_TMAX:fk.P_TMAX + 4] = tmax
        u = np.full(4, np.nan)
        fk.allocate(Ainv, f, *M, P, u)
        np.testing.assert_allclose(u, _yaw_last_reference(Ainv, f, M, tmax), rtol=1e-9, atol=1e-12)
        P[fk.P_ALLOC] = fk.ALLOC_EXACT_CLIP
        fk.allocate(Ainv, f, *M, P, u)
        np.testing.assert_allclose(u, Ainv @ np.array([f, *M]), rtol=1e-12, atol=1e-15)
        cases += 0.0 < _k_of(Ainv, f, M, tmax) < 1.0
    assert cases > 30  # the yaw cut partly, often


def _k_of(Ainv, f, M, tmax):
    """The reference's yaw share k (dimensionless) for Ainv (4, 4), f [N], M (3,) [N m], tmax (4,) [N]."""
    a = Ainv[:, :3] @ np.array([f, M[0], M[1]])
    b = Ainv[:, 3] * M[2]
    u = _yaw_last_reference(Ainv, f, M, tmax)
    i = int(np.argmax(np.abs(b)))
    return (u[i] - a[i]) / b[i] if b[i] != 0 else 1.0


def test_yaw_last_with_every_rotor_below_zero_drops_the_yaw():
    """f = −0.4 (a_i = −0.1, below 0 for every rotor) and M_z = 0.1: the yaw would push half the rotors further
    below: k = 0, u = −0.1 each (the loop clamps them)."""
    np.testing.assert_allclose(_allocate(-0.4, (0.0, 0.0, 0.1), fk.ALLOC_YAW_LAST), [-0.1] * 4, rtol=1e-14)


def test_yaw_last_keeps_the_whole_yaw_where_it_only_lifts_a_rotor_below_zero():
    """f = 2, M = (1.2, 1.2, −0.1): a = (f + y M0 − x M1)/4 = (0.5, −0.1, 0.5, 1.1), b = 0.5 dir M2 = (−0.05, 0.05,
    −0.05, 0.05): rotor 2 is below 0 and the yaw lifts it (its bound (2 + 0.1)/0.05 = 42), the others' bounds are
    10, 42, 10 and (2 − 1.1)/0.05 = 18: k = 1, u = the exact inverse (0.45, −0.05, 0.45, 1.15), not a larger share."""
    np.testing.assert_allclose(_allocate(2.0, (1.2, 1.2, -0.1), fk.ALLOC_YAW_LAST), [0.45, -0.05, 0.45, 1.15],
                               rtol=1e-14)


def test_yaw_last_reads_each_rotor_s_own_limit():
    """T_max = (2, 1, 2, 2); f = 4, M = (−1, 0, −0.5): u = (0.5, 1.5, 1, 1), only rotor 2 outside, above its own 1 N
    (inside rotor 1's 2 N). a = (0.75, 1.25, 1.25, 0.75), b = −0.25 dir = (−0.25, 0.25, −0.25, 0.25): rotor 2's
    bound (1 − 1.25)/0.25 < 0: k = 0, u = a."""
    P = _params(fk.MODE_GEOMETRIC, alloc=fk.ALLOC_YAW_LAST)
    P[fk.P_TMAX:fk.P_TMAX + 4] = [2.0, 1.0, 2.0, 2.0]
    u = np.full(4, np.nan)
    fk.allocate(AINV, 4.0, -1.0, 0.0, -0.5, P, u)
    np.testing.assert_allclose(u, [0.75, 1.25, 1.25, 0.75], rtol=1e-15)


def test_yaw_last_with_a_rotor_the_yaw_does_not_move():
    """Rotor 1's yaw column 0 and its thrust a = 2.5 above T_max 2: the yaw cannot make it worse (its bound is 1);
    the others' bounds (1.9 each) leave the whole yaw: u = Ainv [f, M]."""
    Ainv = AINV.copy()
    Ainv[0, 3] = 0.0
    P = _params(fk.MODE_GEOMETRIC, alloc=fk.ALLOC_YAW_LAST)
    P[fk.P_TMAX:fk.P_TMAX + 4] = 2.0
    u = np.full(4, np.nan)
    # a = (2.5, 0.1, 0.1, 0.1)·... by hand: f = 2.8, M0 = 2.4, M1 = −2.4 give a = (f + y M0 − x M1)/4 =
    # (2.8 + 2.4 + 2.4, 2.8 − 2.4 + 2.4, 2.8 − 2.4 − 2.4, 2.8 + 2.4 − 2.4)/4 = (1.9, 0.7, −0.5, 0.7); M2 = 0.1:
    # b = 0.05 dir = (0 (rotor 1's column), −0.05, 0.05, −0.05): rotor 3 below 0 and moving up, rotors 2 and 4 inside
    # (bounds 0.7/0.05 = 14): k = 1
    fk.allocate(Ainv, 2.8, 2.4, -2.4, 0.1, P, u)
    np.testing.assert_allclose(u, [1.9, 0.65, -0.45, 0.65], rtol=1e-14)
    fk.allocate(Ainv, 4.0, 2.4, -2.4, 0.1, P, u)  # a = (2.2, 1.0, −0.2, 1.0): rotor 1 above, k = 1 still
    np.testing.assert_allclose(u, [2.2, 0.95, -0.15, 0.95], rtol=1e-14)


# --- L1's update ---------------------------------------------------------------------------------------------


def _l1_reference(x, u, th, a_s, w_c, h, z_hat, filt, A=A):
    """The piecewise-constant adaptation law (Hovakimyan & Cao 2010, §3.3) for ż = known + σ, the predictor
    ż_hat = known + σ̂ + a_s (ẑ − z): σ̂ = −Φ⁻¹ e^{a_s T} z̃ with Φ = (e^{a_s T} − 1)/a_s; the predictor advanced by
    one Euler step h; the low-pass C(s) = w_c/(s + w_c) discretised exactly: filt += (1 − e^{−w_c h})(σ̂ − filt).
    known = [f/m R e₃ − g e₃; J⁻¹(M − Ω × JΩ)], [f, M] = A u."""
    fM = A @ u
    R = Rotation.from_rotvec(x[2]).as_matrix()
    J = _inertia(th)
    W = x[3]
    known = np.concatenate([fM[0] / th[0] * R[:, 2] - G_ACC * E3, np.linalg.solve(J, fM[1:] - np.cross(W, J @ W))])
    z = np.concatenate([x[1], W])
    err = z_hat - z
    phi = (math.exp(a_s * h) - 1.0) / a_s
    sigma = -math.exp(a_s * h) * err / phi
    z_new = z_hat + h * (known + sigma + a_s * err)
    filt_new = filt + (1.0 - math.exp(-w_c * h)) * (sigma - filt)
    return z_new, sigma, filt_new


def test_the_l1_update_is_the_piecewise_constant_law():
    """At random states with a random allocation (distinct entries: each rotor's column and each row read)."""
    rng = np.random.default_rng(11)
    P = _params(fk.MODE_GEOMETRIC, l1=1.0)
    for _ in range(5):
        x, _, th = _case(rng)
        u = rng.uniform(0.05, 0.1, 4)
        A_l1 = np.vstack([rng.uniform(0.8, 1.2, 4), rng.normal(0.0, 0.05, (3, 4))])
        z_hat, filt = rng.normal(0, 0.5, 6), rng.normal(0, 0.5, 6)
        z_ref, s_ref, f_ref = _l1_reference(x, u, th, -5.0, 7.0, 0.002, z_hat, filt, A_l1)
        sigma = np.full(6, np.nan)
        fk.l1_update(x, u, th, P, A_l1, -5.0, 7.0, 0.002, z_hat, sigma, filt, np.full((3, 3), np.nan),
                     np.full(fk.TMP_SIZE, np.nan))
        np.testing.assert_allclose(z_hat, z_ref, rtol=1e-11, atol=1e-14)
        np.testing.assert_allclose(sigma, s_ref, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(filt, f_ref, rtol=1e-9, atol=1e-12)


def test_the_l1_update_by_hand_at_rest():
    """Level at rest, thrusts 0.1 N each (f = 0.4, M = 0), m̂ = 0.04 (known v̇ = 10 − 9.81 = 0.19 m/s² up), a
    predictor 0.01 m/s ahead in z (z̃_z = 0.01): σ̂_z = −a_s e^{a_s h}/(e^{a_s h} − 1) 0.01; ẑ_z = 0.01 + h (0.19 +
    σ̂_z − 5·0.01), every other entry 0; filt = (1 − e^{−w_c h}) σ̂."""
    x = np.zeros((4, 3))
    th = np.array([0.04, 1.0, 1.0, 1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
    z_hat, sigma, filt = np.array([0, 0, 0.01, 0, 0, 0]), np.zeros(6), np.zeros(6)
    fk.l1_update(x, np.full(4, 0.1), th, _params(fk.MODE_GEOMETRIC, l1=1.0), A, -5.0, 7.0, 0.002, z_hat, sigma,
                 filt, np.zeros((3, 3)), np.zeros(fk.TMP_SIZE))
    e = math.exp(-0.01)
    sg = 5.0 * e / (e - 1.0) * 0.01
    np.testing.assert_allclose(sigma, [0, 0, sg, 0, 0, 0], rtol=1e-13, atol=0)
    np.testing.assert_allclose(z_hat, [0, 0, 0.01 + 0.002 * (0.19 + sg - 0.05), 0, 0, 0], rtol=1e-13, atol=1e-17)
    np.testing.assert_allclose(filt, [0, 0, (1 - math.exp(-0.014)) * sg, 0, 0, 0], rtol=1e-13, atol=0)


@pytest.mark.parametrize("th0", [0.0, None])
def test_the_l1_update_with_estimates_the_builder_refuses_stays_finite(th0):
    """m̂ = 0, or Ĵ = 0 (singular): no division by zero (the builder refuses both: plants.quadrotor.estimate_problem)."""
    x, _, th = _case(np.random.default_rng(2))
    if th0 is None:
        th[1:7] = 0.0
    else:
        th[0] = th0
    z_hat, sigma, filt = np.zeros(6), np.zeros(6), np.zeros(6)
    fk.l1_update(x, np.full(4, 0.1), th, _params(fk.MODE_GEOMETRIC, l1=1.0), A, -5.0, 7.0, 0.002, z_hat, sigma,
                 filt, np.zeros((3, 3)), np.zeros(fk.TMP_SIZE))
    assert np.all(np.isfinite(z_hat)) and np.all(np.isfinite(sigma)) and np.all(np.isfinite(filt))

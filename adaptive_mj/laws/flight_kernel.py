"""The flight laws' arithmetic as plain scalar code over arrays (loops, math.*; no numpy call inside): what the
Python path runs (compiled by numba when it can be, else as it is) and the native callback compiles, so both give
the same bits. adaptive_mj.laws.geometric and laws.l1 write the same laws with numpy for reading;
tests/test_flight_laws.py checks the two agree to 1e-12.

flight_law(x, r, th, P, G, Ainv, aug, R, F, tmp, u, s, rate):
  x (4, 3)   [p; v; φ; Ω] measured (adaptive_mj.plants.quadrotor)
  r (5, 3)   [p_d; p_d'; p_d''; p_d'''; p_d''''] (rows 0 to 3 used; row 4 too with the inertia adapted)
  th (13,)   θ̂ = [m, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz, dx, dy, dz, tx, ty, tz]
  P          the law's numbers by index (the P_* constants below)
  G (4, 10)  rows γ (the adaptation stiffnesses: θ̂' = regressor·s/γ), θ₀, the projection's lower and upper bounds
             (laws.common.modify_rate: σ- and e-modification, the box's tangent cone)
  Ainv (4, 4)  the inverse of the airframe's allocation: thrusts = Ainv @ [f, M] (then `allocate`, P_ALLOC)
  aug (6,)   the L1 filtered estimate C σ̂ = [acceleration (3) m/s², angular acceleration (3) rad/s²] (zeros: none)
  u (4,)     out: the rotor thrusts [N], before the loop's clamp into [0, T_max]: the allocation's exact inverse,
             or under ALLOC_YAW_LAST with the yaw moment reduced where a rotor would leave [0, T_max] (`allocate`)
  s (3,)     out: s = e_v + c e_x [m/s] (c per axis)
  rate (13,) out: θ̂' (zero but for m, d and τ under the adaptive law, and Ĵ's six entries with law.adapt_inertia)
"""
from __future__ import annotations

import math

from adaptive_mj.laws.common import modify_rate

# P's layout: the law's numbers, one float64 array (the native callback reads it by address)
P_MODE, P_KR, P_KW, P_G = range(4)
P_DZ_WIDTH, P_DZ_ON_S, P_SIGMA, P_EMOD, P_ADAPT, P_L1, P_AS, P_WC, P_CR = range(4, 13)
P_ADAPT_J = 13  # the adaptive law adapts the inertia (law.adapt_inertia): the Slotine–Li attitude moment
# per axis x, y, z (three slots each, P[P_KX + i]): the position and velocity gains k_x, k_v [N/m, N s/m], the
# surface's slope c [1/s] (s = e_v + c e_x) and the adaptive law's gain k on s [N s/m]
P_KX, P_KV, P_C, P_K = 14, 17, 20, 23
# the allocation (`allocate`): its mode, and each rotor's upper thrust limit T_max [N] (four slots, P[P_TMAX + i])
P_ALLOC, P_TMAX = 26, 27
P_SIZE = 31
TMP_SIZE = 24  # the scratch tmp's length (flight_law, l1_update; the native callback's buffer)
MODE_GEOMETRIC, MODE_ADAPTIVE = 0.0, 1.0
ALLOC_EXACT_CLIP, ALLOC_YAW_LAST = 0.0, 1.0  # P[P_ALLOC]: laws.flight.ALLOCATIONS' "exact_clip", "yaw_last"


def rodrigues(phi, R):
    """R (3, 3) = exp(φ^) of the rotation vector φ (3,) [rad], in place."""
    a2 = phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2]
    angle = math.sqrt(a2)
    if angle < 1e-12:
        R[0, 0], R[0, 1], R[0, 2] = 1.0, -phi[2], phi[1]
        R[1, 0], R[1, 1], R[1, 2] = phi[2], 1.0, -phi[0]
        R[2, 0], R[2, 1], R[2, 2] = -phi[1], phi[0], 1.0
        return
    kx, ky, kz = phi[0] / angle, phi[1] / angle, phi[2] / angle
    sn, cs = math.sin(angle), 1.0 - math.cos(angle)
    R[0, 0] = 1.0 + cs * (kx * kx - 1.0)
    R[0, 1] = -sn * kz + cs * kx * ky
    R[0, 2] = sn * ky + cs * kx * kz
    R[1, 0] = sn * kz + cs * kx * ky
    R[1, 1] = 1.0 + cs * (ky * ky - 1.0)
    R[1, 2] = -sn * kx + cs * ky * kz
    R[2, 0] = -sn * ky + cs * kx * kz
    R[2, 1] = sn * kx + cs * ky * kz
    R[2, 2] = 1.0 + cs * (kz * kz - 1.0)


def inertia_times(th, w, out):
    """out (3,) = J w, J from θ̂'s [Jxx, Jyy, Jzz, Jxy, Jxz, Jyz] (th[1:7])."""
    xx, yy, zz, xy, xz, yz = th[1], th[2], th[3], th[4], th[5], th[6]
    out[0] = xx * w[0] + xy * w[1] + xz * w[2]
    out[1] = xy * w[0] + yy * w[1] + yz * w[2]
    out[2] = xz * w[0] + yz * w[1] + zz * w[2]


def inertia_regressor(th, a, Wr, W, jw, out):
    """out (3,) = Y(Ω, Ω_r, Ω̇_r) ĵ = Ĵ Ω̇_r + Ω_r × ĴΩ (linear in Ĵ's six entries th[1:7]); a = Ω̇_r, Wr = Ω_r,
    W = Ω (3,) each, jw (3,) scratch (left holding ĴΩ)."""
    inertia_times(th, W, jw)
    inertia_times(th, a, out)
    out[0] = out[0] + (Wr[1] * jw[2] - Wr[2] * jw[1])
    out[1] = out[1] + (Wr[2] * jw[0] - Wr[0] * jw[2])
    out[2] = out[2] + (Wr[0] * jw[1] - Wr[1] * jw[0])


def inertia_rate(s, a, Wr, W, gamma, rate):
    """Ĵ's rates ĵ' = −Yᵀ s/γ_j into rate[1:7] (gamma (13,): the stiffnesses, gamma[1:7] Ĵ's): with q = s × Ω_r
    (s·(Ω_r × v) = v·(s × Ω_r)), sᵀY e_k = sᵀE_k Ω̇_r + qᵀE_k Ω for E_k the symmetric basis matrix of entry k:
    (i, i) s_i a_i + q_i W_i, (i, j) s_i a_j + s_j a_i + q_i W_j + q_j W_i."""
    q0 = s[1] * Wr[2] - s[2] * Wr[1]
    q1 = s[2] * Wr[0] - s[0] * Wr[2]
    q2 = s[0] * Wr[1] - s[1] * Wr[0]
    rate[1] = -(s[0] * a[0] + q0 * W[0]) / gamma[1]
    rate[2] = -(s[1] * a[1] + q1 * W[1]) / gamma[2]
    rate[3] = -(s[2] * a[2] + q2 * W[2]) / gamma[3]
    rate[4] = -(s[0] * a[1] + s[1] * a[0] + q0 * W[1] + q1 * W[0]) / gamma[4]
    rate[5] = -(s[0] * a[2] + s[2] * a[0] + q0 * W[2] + q2 * W[0]) / gamma[5]
    rate[6] = -(s[1] * a[2] + s[2] * a[1] + q1 * W[2] + q2 * W[1]) / gamma[6]


def translation_rates(x, r, s, s_abs, w, P, G, rate) -> bool:
    """The adaptive law's m̂' = −sᵀw/γ_m and d̂' = s/γ_d into rate, when the dead-zone is open (on ‖s‖, or on
    ‖e_x‖); w (3,) the regressor p̈_d − λ e_v + g e₃. Returns whether it is open (the moment adapts with them)."""
    if P[P_DZ_ON_S] != 0.0:
        signal = s_abs
    else:
        e0, e1, e2 = x[0, 0] - r[0, 0], x[0, 1] - r[0, 1], x[0, 2] - r[0, 2]
        signal = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if signal < P[P_DZ_WIDTH]:
        return False
    sw = s[0] * w[0] + s[1] * w[1] + s[2] * w[2]
    rate[0] = -sw / G[0, 0]
    for i in range(3):
        rate[7 + i] = s[i] / G[0, 7 + i]
    return True


def flight_law(x, r, th, P, G, Ainv, aug, R, F, tmp, u, s, rate):
    """One evaluation (module docstring); R (3, 3), F (3,) and tmp (TMP_SIZE,) are scratch."""
    rodrigues(x[2], R)
    g = P[P_G]
    m = th[0]
    adaptive = P[P_MODE] == MODE_ADAPTIVE
    for i in range(3):  # the gains per axis: c, k, k_x, k_v of axis i
        c = P[P_C + i]
        ex = x[0, i] - r[0, i]
        ev = x[1, i] - r[1, i]
        s[i] = ev + c * ex
        if adaptive:  # F = m̂ w − d̂ − k s, w = a_d − c e_v + g e₃
            w = r[2, i] - c * ev + (g if i == 2 else 0.0)
            tmp[i] = w
            F[i] = m * w - th[7 + i] - P[P_K + i] * s[i]
        else:  # F = −k_x e_x − k_v e_v + m g e₃ + m a_d
            F[i] = -P[P_KX + i] * ex - P[P_KV + i] * ev + (m * g if i == 2 else 0.0) + m * r[2, i]
    for j in range(rate.shape[0]):
        rate[j] = 0.0
    s_abs = math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
    adapting = adaptive and P[P_ADAPT] != 0.0 and translation_rates(x, r, s, s_abs, tmp, P, G, rate)
    # the attitude loop: f = F·Re₃, R_d from F and b₁d = e₁, e_R = ½ vee(R_dᵀR − RᵀR_d), M = −k_R e_R − k_Ω Ω + Ω×JΩ
    f = F[0] * R[0, 2] + F[1] * R[1, 2] + F[2] * R[2, 2]
    nF = math.sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2])
    if not nF > 1e-12:  # no force asked (or a non-finite one): level, and let the run's own checks end it
        F[0], F[1], F[2], nF = 0.0, 0.0, 1.0, 1.0
    b30, b31, b32 = F[0] / nF, F[1] / nF, F[2] / nF
    # b₂d = b₃d × e₁ / ‖·‖ = (0, b32, −b31)/‖·‖ (b₃d along e₁ leaves the heading undefined: b₂d = e₂ then)
    n2 = math.sqrt(b32 * b32 + b31 * b31)
    if n2 > 1e-12:
        b20, b21, b22 = 0.0, b32 / n2, -b31 / n2
    else:
        b20, b21, b22, n2 = 0.0, 1.0, 0.0, 1.0
    b10, b11, b12 = b21 * b32 - b22 * b31, b22 * b30 - b20 * b32, b20 * b31 - b21 * b30
    # Rd columns b1, b2, b3; E = RdᵀR (3, 3) into tmp[3:12] row-major
    for a in range(3):
        da0 = b10 if a == 0 else (b20 if a == 1 else b30)
        da1 = b11 if a == 0 else (b21 if a == 1 else b31)
        da2 = b12 if a == 0 else (b22 if a == 1 else b32)
        for b in range(3):
            tmp[3 + 3 * a + b] = da0 * R[0, b] + da1 * R[1, b] + da2 * R[2, b]
    # e_R = ½ vee(E − Eᵀ): (E[2,1] − E[1,2], E[0,2] − E[2,0], E[1,0] − E[0,1]) / 2
    eR0 = 0.5 * (tmp[3 + 7] - tmp[3 + 5])
    eR1 = 0.5 * (tmp[3 + 2] - tmp[3 + 6])
    eR2 = 0.5 * (tmp[3 + 3] - tmp[3 + 1])
    # Ω_d = vee(R_dᵀṘ_d) with Ṙ_d from Ḟ ≈ m̂ p⃛_d (the reference's jerk; the feedback's own rate left out), Ω̇_d ≈ 0:
    # ḃ₃ = (Ḟ − (b₃·Ḟ) b₃)/‖F‖, ḃ₂ = (ċ − (b₂·ċ) b₂)/‖c‖ for c = b₃ × e₁, ḃ₁ = ḃ₂ × b₃ + b₂ × ḃ₃
    Fd0, Fd1, Fd2 = m * r[3, 0], m * r[3, 1], m * r[3, 2]
    bF = b30 * Fd0 + b31 * Fd1 + b32 * Fd2
    d30, d31, d32 = (Fd0 - bF * b30) / nF, (Fd1 - bF * b31) / nF, (Fd2 - bF * b32) / nF
    c1, c2 = d32, -d31  # ċ = ḃ₃ × e₁ = (0, ḃ₃z, −ḃ₃y)
    bc = b21 * c1 + b22 * c2
    d20, d21, d22 = 0.0, (c1 - bc * b21) / n2, (c2 - bc * b22) / n2
    d10 = (d21 * b32 - d22 * b31) + (b21 * d32 - b22 * d31)
    d11 = (d22 * b30 - d20 * b32) + (b22 * d30 - b20 * d32)
    d12 = (d20 * b31 - d21 * b30) + (b20 * d31 - b21 * d30)
    wd0 = b30 * d20 + b31 * d21 + b32 * d22  # b₃·ḃ₂
    wd1 = b10 * d30 + b11 * d31 + b12 * d32  # b₁·ḃ₃
    wd2 = b20 * d10 + b21 * d11 + b22 * d12  # b₂·ḃ₁
    o0 = b10 * wd0 + b20 * wd1 + b30 * wd2  # R_d Ω_d, world frame
    o1 = b11 * wd0 + b21 * wd1 + b31 * wd2
    o2 = b12 * wd0 + b22 * wd1 + b32 * wd2
    v0 = R[0, 0] * o0 + R[1, 0] * o1 + R[2, 0] * o2  # Rᵀ R_d Ω_d, body frame
    v1 = R[0, 1] * o0 + R[1, 1] * o1 + R[2, 1] * o2
    v2 = R[0, 2] * o0 + R[1, 2] * o1 + R[2, 2] * o2
    W = x[3]
    eW0, eW1, eW2 = W[0] - v0, W[1] - v1, W[2] - v2
    # M = −k_R e_R − k_Ω e_Ω + Ω × ĴΩ − Ĵ(Ω × RᵀR_dΩ_d) − τ̂ (Lee 2010 with Ω̇_d ≈ 0; τ̂ the law's constant moment:
    # Goodarzi, Lee & Lee 2015's Δ̂_R, adapted by the adaptive law, held by the baselines), unless the adaptive law
    # adapts the inertia (P_ADAPT_J)
    if not (adaptive and P[P_ADAPT_J] != 0.0):
        inertia_times(th, W, F)  # F now holds Ĵ Ω (F is no longer needed)
        M0 = -P[P_KR] * eR0 - P[P_KW] * eW0 + (W[1] * F[2] - W[2] * F[1]) - th[10]
        M1 = -P[P_KR] * eR1 - P[P_KW] * eW1 + (W[2] * F[0] - W[0] * F[2]) - th[11]
        M2 = -P[P_KR] * eR2 - P[P_KW] * eW2 + (W[0] * F[1] - W[1] * F[0]) - th[12]
        tmp[0], tmp[1], tmp[2] = W[1] * v2 - W[2] * v1, W[2] * v0 - W[0] * v2, W[0] * v1 - W[1] * v0
        inertia_times(th, tmp, F)  # Ĵ(Ω × RᵀR_dΩ_d)
        M0, M1, M2 = M0 - F[0], M1 - F[1], M2 - F[2]
    else:  # the Slotine–Li moment on SO(3) (docs/THEORY.md, "The inertia"): s_R = e_Ω + c_R e_R, Ω_r = Ω − s_R,
        # Ω̇_r = −Ω × RᵀR_dΩ_d + RᵀR_dΩ̇_d − c_R E e_Ω (E = ½(tr(RᵀR_d) I − RᵀR_d)), M = Y ĵ − k_Ω s_R − k_R e_R − τ̂
        # Ω̇_d from F̈ ≈ m̂ p⁽⁴⁾_d (the reference's snap) as Ω_d from Ḟ: b̈ = (c̈ − (ḃ·ċ + b·c̈) b − 2 (b·ċ) ḃ)/‖c‖
        # for b = c/‖c‖ (b₃ of F, b₂ of b₃ × e₁), b̈₁ = b̈₂ × b₃ + 2 ḃ₂ × ḃ₃ + b₂ × b̈₃,
        # Ω̇_d = (ḃ₃·ḃ₂ + b₃·b̈₂, ḃ₁·ḃ₃ + b₁·b̈₃, ḃ₂·ḃ₁ + b₂·b̈₁)
        Fs0, Fs1, Fs2 = m * r[4, 0], m * r[4, 1], m * r[4, 2]
        nn = (d30 * Fd0 + d31 * Fd1 + d32 * Fd2) + (b30 * Fs0 + b31 * Fs1 + b32 * Fs2)
        f30 = (Fs0 - nn * b30 - 2.0 * bF * d30) / nF
        f31 = (Fs1 - nn * b31 - 2.0 * bF * d31) / nF
        f32 = (Fs2 - nn * b32 - 2.0 * bF * d32) / nF
        g1, g2 = f32, -f31  # c̈ = b̈₃ × e₁
        nn = (d21 * c1 + d22 * c2) + (b21 * g1 + b22 * g2)
        f20, f21, f22 = 0.0, (g1 - nn * b21 - 2.0 * bc * d21) / n2, (g2 - nn * b22 - 2.0 * bc * d22) / n2
        f10 = (f21 * b32 - f22 * b31) + 2.0 * (d21 * d32 - d22 * d31) + (b21 * f32 - b22 * f31)
        f11 = (f22 * b30 - f20 * b32) + 2.0 * (d22 * d30 - d20 * d32) + (b22 * f30 - b20 * f32)
        f12 = (f20 * b31 - f21 * b30) + 2.0 * (d20 * d31 - d21 * d30) + (b20 * f31 - b21 * f30)
        a0 = (d30 * d20 + d31 * d21 + d32 * d22) + (b30 * f20 + b31 * f21 + b32 * f22)
        a1 = (d10 * d30 + d11 * d31 + d12 * d32) + (b10 * f30 + b11 * f31 + b12 * f32)
        a2 = (d20 * d10 + d21 * d11 + d22 * d12) + (b20 * f10 + b21 * f11 + b22 * f12)
        o0 = b10 * a0 + b20 * a1 + b30 * a2  # R_d Ω̇_d, world frame
        o1 = b11 * a0 + b21 * a1 + b31 * a2
        o2 = b12 * a0 + b22 * a1 + b32 * a2
        cR = P[P_CR]
        sR, Wr, ar, jw = tmp[12:15], tmp[15:18], tmp[18:21], tmp[21:24]
        sR[0], sR[1], sR[2] = eW0 + cR * eR0, eW1 + cR * eR1, eW2 + cR * eR2
        Wr[0], Wr[1], Wr[2] = W[0] - sR[0], W[1] - sR[1], W[2] - sR[2]
        tr = tmp[3] + tmp[7] + tmp[11]  # tr(R_dᵀR); (RᵀR_d)[i, j] = tmp[3 + 3 j + i]
        ar[0] = (-(W[1] * v2 - W[2] * v1) + (R[0, 0] * o0 + R[1, 0] * o1 + R[2, 0] * o2)
                 - cR * 0.5 * (tr * eW0 - (tmp[3] * eW0 + tmp[6] * eW1 + tmp[9] * eW2)))
        ar[1] = (-(W[2] * v0 - W[0] * v2) + (R[0, 1] * o0 + R[1, 1] * o1 + R[2, 1] * o2)
                 - cR * 0.5 * (tr * eW1 - (tmp[4] * eW0 + tmp[7] * eW1 + tmp[10] * eW2)))
        ar[2] = (-(W[0] * v1 - W[1] * v0) + (R[0, 2] * o0 + R[1, 2] * o1 + R[2, 2] * o2)
                 - cR * 0.5 * (tr * eW2 - (tmp[5] * eW0 + tmp[8] * eW1 + tmp[11] * eW2)))
        inertia_regressor(th, ar, Wr, W, jw, F)  # F now holds Y ĵ (F is no longer needed)
        M0 = F[0] - P[P_KW] * sR[0] - P[P_KR] * eR0 - th[10]
        M1 = F[1] - P[P_KW] * sR[1] - P[P_KR] * eR1 - th[11]
        M2 = F[2] - P[P_KW] * sR[2] - P[P_KR] * eR2 - th[12]
        if adapting:  # ĵ' = −Yᵀ s_R/γ_j
            inertia_rate(sR, ar, Wr, W, G[0], rate)
    if adaptive and P[P_ADAPT] != 0.0:
        if adapting:  # τ̂' = (e_Ω + c_R e_R)/γ_τ
            rate[10] = (eW0 + P[P_CR] * eR0) / G[0, 10]
            rate[11] = (eW1 + P[P_CR] * eR1) / G[0, 11]
            rate[12] = (eW2 + P[P_CR] * eR2) / G[0, 12]
        modify_rate(rate, th, s_abs, P[P_SIGMA], P[P_EMOD], G[1], G[0], G[2], G[3])
    if P[P_L1] != 0.0:  # L1: f_ad = −m (Cσ̂_v · Re₃), M_ad = −J Cσ̂_Ω
        f -= m * (aug[0] * R[0, 2] + aug[1] * R[1, 2] + aug[2] * R[2, 2])
        tmp[0], tmp[1], tmp[2] = aug[3], aug[4], aug[5]
        inertia_times(th, tmp, F)
        M0, M1, M2 = M0 - F[0], M1 - F[1], M2 - F[2]
    allocate(Ainv, f, M0, M1, M2, P, u)


def allocate(Ainv, f, M0, M1, M2, P, u):
    """u (4,) the rotor thrusts [N] for the collective thrust f [N] and body moments M0, M1, M2 [N m], Ainv (4, 4) the
    allocation's inverse, by the mode P[P_ALLOC]:

    ALLOC_EXACT_CLIP  u = Ainv [f, M], the exact inverse; the loop then clamps each rotor into [0, T_max] (what
                      RotorPy's vehicle does with its motor speeds), losing thrust, roll, pitch and yaw alike.
    ALLOC_YAW_LAST    the yaw moment gives way first (PX4's multicopter allocation with airmode off,
                      ControlAllocationSequentialDesaturation::mixAirmodeDisabled; Mueller & D'Andrea, ICRA 2014:
                      roll and pitch before yaw). Every rotor's thrust is affine in the share k of the yaw moment
                      kept, u_i(k) = a_i + k b_i (a_i = Ainv[i, :3] [f, M0, M1], b_i = Ainv[i, 3] M2); where the
                      exact inverse (k = 1) leaves a rotor outside [0, T_max_i], k is the largest in [0, 1] such that
                      no rotor that the yaw moment pushes up ends above T_max_i, nor one it pushes down below 0 (a
                      rotor already past that limit at k = 0 gives k = 0): per rotor in closed form,
                      k <= (T_max_i − a_i)/b_i for b_i > 0 and k <= −a_i/b_i for b_i < 0, each bound floored at 0.
                      With every a_i inside its box, the collective thrust and the roll and pitch moments are then
                      delivered exactly, and as much of the yaw moment as fits; what is left outside (thrust or
                      roll/pitch beyond the rotors even without yaw) the loop's clamp clips. Where the exact inverse
                      fits, u is its bits.
    Lower limit 0 (a rotor pushes only); T_max_i = P[P_TMAX + i] [N], the model's ctrlrange."""
    out = False
    for i in range(4):
        u[i] = Ainv[i, 0] * f + Ainv[i, 1] * M0 + Ainv[i, 2] * M1 + Ainv[i, 3] * M2
        if not (0.0 <= u[i] <= P[P_TMAX + i]):
            out = True
    if not out or P[P_ALLOC] != ALLOC_YAW_LAST:
        return
    k = 1.0
    for i in range(4):
        a = Ainv[i, 0] * f + Ainv[i, 1] * M0 + Ainv[i, 2] * M1
        b = Ainv[i, 3] * M2
        if b > 0.0:
            lim = (P[P_TMAX + i] - a) / b
        elif b < 0.0:
            lim = -a / b
        else:
            lim = 1.0
        lim = max(lim, 0.0)
        if lim < k:
            k = lim
    for i in range(4):
        u[i] = (Ainv[i, 0] * f + Ainv[i, 1] * M0 + Ainv[i, 2] * M1) + k * (Ainv[i, 3] * M2)


def l1_update(x, u, th, P, A, a_s, w_c, h, z_hat, sigma, filt, R, tmp):
    """One L1 step (laws.l1.step, written out): from the state x (4, 3) measured at a step's start and the thrusts
    u (4,) applied over it, advance the predictor ẑ (6,), the piecewise-constant estimate σ̂ (6,) and the filtered
    C σ̂ (6,) in place by h [s] (T_s = h). A (4, 4) the allocation ([f, M] = A u); tmp (TMP_SIZE,) scratch."""
    rodrigues(x[2], R)
    g, m = P[P_G], th[0]
    f = A[0, 0] * u[0] + A[0, 1] * u[1] + A[0, 2] * u[2] + A[0, 3] * u[3]
    for i in range(3):
        tmp[3 + i] = A[1 + i, 0] * u[0] + A[1 + i, 1] * u[1] + A[1 + i, 2] * u[2] + A[1 + i, 3] * u[3]
    W = x[3]
    # known angular acceleration J⁻¹(M − Ω×JΩ): J Ω into tmp[6:9], then solve J a = b by Cramer's rule
    inertia_times(th, W, tmp[6:9])
    b0 = tmp[3] - (W[1] * tmp[8] - W[2] * tmp[7])
    b1 = tmp[4] - (W[2] * tmp[6] - W[0] * tmp[8])
    b2 = tmp[5] - (W[0] * tmp[7] - W[1] * tmp[6])
    xx, yy, zz, xy, xz, yz = th[1], th[2], th[3], th[4], th[5], th[6]
    det = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz)
    if det == 0.0 or m == 0.0:  # the builder refuses such estimates (plants.quadrotor.estimate_problem)
        det, m = 1.0, 1.0
    k3 = ((yy * zz - yz * yz) * b0 - (xy * zz - xz * yz) * b1 + (xy * yz - xz * yy) * b2) / det
    k4 = (-(xy * zz - yz * xz) * b0 + (xx * zz - xz * xz) * b1 - (xx * yz - xz * xy) * b2) / det
    k5 = ((xy * yz - yy * xz) * b0 - (xx * yz - xy * xz) * b1 + (xx * yy - xy * xy) * b2) / det
    e = math.exp(a_s * h)
    gain = -(a_s / (e - 1.0)) * e
    alpha = 1.0 - math.exp(-w_c * h)
    for i in range(6):
        z = x[1, i] if i < 3 else W[i - 3]
        err = z_hat[i] - z
        sg = gain * err
        if i < 3:
            known = (f / m) * R[i, 2] - (g if i == 2 else 0.0)
        else:
            known = k3 if i == 3 else (k4 if i == 4 else k5)
        z_hat[i] = z_hat[i] + h * (known + sg + a_s * err)
        sigma[i] = sg
        filt[i] = filt[i] + alpha * (sg - filt[i])

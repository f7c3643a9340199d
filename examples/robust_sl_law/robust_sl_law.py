"""An adaptive-mj multi-joint law plugin: Slotine–Li with a boundary-layer robust term (a law that is not
Slotine–Li as bundled), on any arm adaptive-mj builds (plant.kind = "manipulator").

    s   = q̃' + λ q̃,   q̇_r = q̇_d + λ q̃,   q̈_r = q̈_d + λ q̃'            (q̃ = q_d − q)
    τ   = Y(q, q̇, q̇_r, q̈_r) π̂ + τ_known + K_D s + k_s sat(s / φ)       (sat per joint)
    π̂'  = Γ⁻¹ Yᵀ s

With V = ½ sᵀ M(q) s + ½ π̃ᵀ Γ π̃ (the bundled law's V), V' = −sᵀ K_D s − k_s sᵀ sat(s/φ) <= 0: the robust
term only adds dissipation, so the Lyapunov argument of Slotine–Li carries over and V is declared.

The functions are plain loops over arrays (no Python objects, no allocating numpy calls), so adaptive-mj
compiles them into MuJoCo's native control callback. params (the declared keys, in order):
[λ, K_D, k_s, φ, γ_1 … γ_n] (gamma is per parameter: n slots in the plant's parameter order).
"""
import numpy as np

from adaptive_mj.laws.plugin import JointLawPlugin, Param

GAMMA = 4  # where the per-parameter gamma starts in params


def point(x, ref, params, v, w, a):
    """The regressor's arguments: v = q̇, w = q̇_r, a = q̈_r."""
    lam = params[0]
    for j in range(x.shape[1]):
        v[j] = x[1, j]
        w[j] = ref[1, j] + lam * (ref[0, j] - x[0, j])
        a[j] = ref[2, j] + lam * (ref[1, j] - x[1, j])


def law(x, ref, theta, Y, tau_known, params, u, s, rate):
    lam, kd, ks, phi = params[0], params[1], params[2], params[3]
    m, n = Y.shape[0], Y.shape[1]
    for j in range(m):
        s[j] = (ref[1, j] - x[1, j]) + lam * (ref[0, j] - x[0, j])
        sat = s[j] / phi
        if sat > 1.0:
            sat = 1.0
        elif sat < -1.0:
            sat = -1.0
        acc = tau_known[j] + kd * s[j] + ks * sat
        for i in range(n):
            acc += Y[j, i] * theta[i]
        u[j] = acc
    for i in range(n):
        acc = 0.0
        for j in range(m):
            acc += Y[j, i] * s[j]
        rate[i] = acc / params[GAMMA + i]


def lyapunov(s, theta_hat, theta, params, M):
    """V = ½ sᵀ M s + ½ Σ γ_i π̃_i² per row: s (N, m), theta_hat / theta (N, n), M (N, m, m)."""
    n = theta_hat.shape[-1]
    gamma = params[GAMMA:GAMMA + n]
    return 0.5 * np.einsum("ni,nij,nj->n", s, M, s) + 0.5 * np.sum(gamma * (theta_hat - theta) ** 2, axis=-1)


LAW = JointLawPlugin(
    point=point,
    law=law,
    params=(Param("lambda", default=10.0, gt=0.0, unit="1/s", doc="surface slope λ (every joint)"),
            Param("kd", default=50.0, ge=0.0, unit="N m s/rad", doc="K_D (every joint)"),
            Param("ks", default=1.0, ge=0.0, unit="N m", doc="robust term's gain k_s"),
            Param("phi", default=0.05, gt=0.0, unit="rad/s", doc="boundary layer φ"),
            Param("gamma", default=0.2, gt=0.0, per_parameter=True,
                  doc="adaptation stiffness Γ (estimates move at Yᵀs/γ), a number or {parameter = number}")),
    lyapunov=lyapunov,
    gain="gamma",
    doc="Slotine-Li with a boundary-layer robust term k_s sat(s/phi)",
)

"""Geometric tracking control on SE(3) (Lee, Leok & McClamroch, "Geometric tracking control of a quadrotor UAV
on SE(3)", CDC 2010): the non-adaptive baseline of the flying plant (issue 33), as plain code over arrays.

With e₃ = (0, 0, 1), the position and velocity errors e_x = p − p_d, e_v = v − v_d [m, m/s] give the desired
force F = −k_x e_x − k_v e_v + m g e₃ + m a_d [N]; the collective thrust is f = F · R e₃; the desired body axes
are b₃d = F/‖F‖, b₂d = b₃d × b₁d/‖b₃d × b₁d‖ (b₁d the desired heading), R_d = [b₂d × b₃d, b₂d, b₃d]; the attitude
and rate errors e_R = ½ vee(R_dᵀR − RᵀR_d), e_Ω = Ω − RᵀR_d Ω_d, and the moments
M = −k_R e_R − k_Ω e_Ω + Ω × JΩ − J(Ω × RᵀR_dΩ_d) [N m], with Ω_d from the rate of F (`desired_rate`; the flight
laws pass Ḟ ≈ m̂ p⃛_d, the reference's jerk) and Ω̇_d = 0; without it (F_dot None) Ω_d = 0, as RotorPy's SE3Control,
which leaves an attitude lag on fast trajectories (the figure-eight's tail error 1.35 cm against 0.375 cm).

m [kg] and J (3, 3) [kg m²] are the law's *nominal* model: with an unknown payload they are wrong, and the
steady error that follows (e_z = Δm g / k_x at hover) is what the adaptive laws remove.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

E3 = np.array([0.0, 0.0, 1.0])


def hat(w: np.ndarray) -> np.ndarray:
    """(3, 3) the skew matrix of w (3,): hat(w) @ x = w × x."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def vee(S: np.ndarray) -> np.ndarray:
    """(3,) the vector of a skew matrix S (3, 3): vee(hat(w)) = w."""
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


class Gains(NamedTuple):
    """k_x [N/m], k_v [N s/m] (a number, or (3,) per axis x, y, z), k_R [N m/rad], k_Ω [N m s/rad]."""

    kx: float | np.ndarray
    kv: float | np.ndarray
    kR: float
    kW: float


class Command(NamedTuple):
    """f [N] the collective thrust, M (3,) [N m] the body moments, e_x (3,) [m] and e_R (3,) [rad] the errors."""

    f: float
    M: np.ndarray
    e_x: np.ndarray
    e_R: np.ndarray


def geometric(p: np.ndarray, v: np.ndarray, R: np.ndarray, W: np.ndarray, ref: np.ndarray, b1d: np.ndarray,
              gains: Gains, m: float, J: np.ndarray, g: float, tau: np.ndarray | None = None) -> Command:
    """The SE(3) controller (module docstring): state p, v (3,) world [m, m/s], R (3, 3) body-to-world, W (3,)
    body rate [rad/s]; ref (3, 3) rows [p_d, v_d, a_d] [m, m/s, m/s²], or (4, 3) with the jerk p⃛_d [m/s³] for Ω_d
    (Ḟ ≈ m p⃛_d); b1d (3,) the desired heading; nominal m [kg], J (3, 3) [kg m²]; gravity g [m/s²]; tau: attitude's."""
    e_x, e_v = p - ref[0], v - ref[1]
    F = -gains.kx * e_x - gains.kv * e_v + m * g * E3 + m * ref[2]
    F_dot = m * ref[3] if len(ref) > 3 else None
    return attitude(F, R, W, b1d, gains, J, F_dot, tau)._replace(e_x=e_x)


class MassGains(NamedTuple):
    """The translational adaptive law's gains: c [1/s] the surface slope, k [N s/m] the gain on s (each a number or
    (3,) per axis), gamma_m
    [kg² s/m² ... as m̂' = −γ_m sᵀw is in kg/s] the mass estimate's rate gain and gamma_d [N s/m ... Δ̂' = γ_Δ s in
    N/s] the disturbance force estimate's."""

    c: float | np.ndarray
    k: float | np.ndarray
    gamma_m: float
    gamma_d: float


class AdaptiveForce(NamedTuple):
    """F (3,) [N] the desired force, s (3,) [m/s] the surface, m_rate [kg/s] and d_rate (3,) [N/s] the estimates'
    rates."""

    F: np.ndarray
    s: np.ndarray
    m_rate: float
    d_rate: np.ndarray


def adaptive_force(p: np.ndarray, v: np.ndarray, ref: np.ndarray, m_hat: float, d_hat: np.ndarray,
                   gains: MassGains, g: float) -> AdaptiveForce:
    """The lecture's sliding adaptive law on the translational dynamics m p̈ = f R e₃ − m g e₃ + Δ, linear in the
    unknown mass m and disturbance force Δ: with e_x = p − p_d, e_v = v − v_d and s = e_v + c e_x (the lecture's
    s = ỹ' + λỹ with ỹ = −e_x), w = a_d − c e_v + g e₃ (ÿ_r plus gravity),

        F = m̂ w − Δ̂ − k s,    m̂' = −γ_m sᵀw,    Δ̂' = γ_Δ s,

    so that with V = ½ m sᵀs + ½ m̃²/γ_m + ½ ‖Δ̃‖²/γ_Δ and the thrust along F, V' = −k sᵀs (module docstring: the
    attitude follows F through the geometric controller's R_d). ref (3, 3) rows [p_d, v_d, a_d]."""
    e_x, e_v = p - ref[0], v - ref[1]
    s = e_v + gains.c * e_x
    w = ref[2] - gains.c * e_v + g * E3
    F = m_hat * w - d_hat - gains.k * s
    return AdaptiveForce(F, s, float(-gains.gamma_m * (s @ w)), gains.gamma_d * s)


def attitude(F: np.ndarray, R: np.ndarray, W: np.ndarray, b1d: np.ndarray, gains: Gains, J: np.ndarray,
             F_dot: np.ndarray | None = None, tau: np.ndarray | None = None) -> Command:
    """The geometric controller's attitude loop around a desired force F (3,) [N]: f = F·Re₃, R_d from F and b1d,
    e_Ω = Ω − RᵀR_dΩ_d, M = −k_R e_R − k_Ω e_Ω + Ω × JΩ − J(Ω × RᵀR_dΩ_d) − τ (Lee 2010 with Ω̇_d = 0). Ω_d is
    vee(R_dᵀṘ_d) with Ṙ_d from F_dot (3,) [N/s], the rate of F (None: Ω_d = 0, as RotorPy's SE3Control); tau (3,)
    [N m] a constant moment the law cancels (None: none). e_x is zero here (the force law owns it)."""
    f = float(F @ R[:, 2])
    Rd = desired_attitude(F, b1d)
    e_R = 0.5 * vee(Rd.T @ R - R.T @ Rd)
    v = R.T @ Rd @ (desired_rate(F, F_dot, b1d) if F_dot is not None else np.zeros(3))
    M = -gains.kR * e_R - gains.kW * (W - v) + np.cross(W, J @ W) - J @ np.cross(W, v)
    if tau is not None:
        M = M - tau
    return Command(f, M, np.zeros(3), e_R)


def desired_rate(F: np.ndarray, F_dot: np.ndarray, b1d: np.ndarray) -> np.ndarray:
    """(3,) Ω_d = vee(R_dᵀṘ_d) [rad/s] of desired_attitude(F, b1d) as F changes at F_dot (3,) (b1d constant)."""
    nF = np.linalg.norm(F)
    b3 = F / nF
    b3_dot = (F_dot - (b3 @ F_dot) * b3) / nF
    c = np.cross(b3, b1d)
    b2 = c / np.linalg.norm(c)
    c_dot = np.cross(b3_dot, b1d)
    b2_dot = (c_dot - (b2 @ c_dot) * b2) / np.linalg.norm(c)
    b1 = np.cross(b2, b3)
    b1_dot = np.cross(b2_dot, b3) + np.cross(b2, b3_dot)
    return np.array([b3 @ b2_dot, b1 @ b3_dot, b2 @ b1_dot])


def desired_attitude(F: np.ndarray, b1d: np.ndarray) -> np.ndarray:
    """(3, 3) R_d whose third axis is along F (3,) and whose first axis points as near b1d (3,) as it can."""
    b3 = F / np.linalg.norm(F)
    b2 = np.cross(b3, b1d)
    b2 /= np.linalg.norm(b2)
    return np.column_stack([np.cross(b2, b3), b2, b3])

"""Geometric tracking control on SE(3) (Lee, Leok & McClamroch, "Geometric tracking control of a quadrotor UAV
on SE(3)", CDC 2010): the non-adaptive baseline of the flying plant (issue 33), as plain code over arrays.

With e₃ = (0, 0, 1), the position and velocity errors e_x = p − p_d, e_v = v − v_d [m, m/s] give the desired
force F = −k_x e_x − k_v e_v + m g e₃ + m a_d [N]; the collective thrust is f = F · R e₃; the desired body axes
are b₃d = F/‖F‖, b₂d = b₃d × b₁d/‖b₃d × b₁d‖ (b₁d the desired heading), R_d = [b₂d × b₃d, b₂d, b₃d]; the attitude
and rate errors e_R = ½ vee(R_dᵀR − RᵀR_d), e_Ω = Ω − RᵀR_d Ω_d, and the moments
M = −k_R e_R − k_Ω e_Ω + Ω × JΩ [N m]. Here Ω_d = 0 and Ω̇_d = 0 (as RotorPy's SE3Control): the reference's jerk
is not used, which leaves a small attitude lag on fast trajectories.

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
    """k_x [N/m], k_v [N s/m], k_R [N m/rad], k_Ω [N m s/rad]."""

    kx: float
    kv: float
    kR: float
    kW: float


class Command(NamedTuple):
    """f [N] the collective thrust, M (3,) [N m] the body moments, e_x (3,) [m] and e_R (3,) [rad] the errors."""

    f: float
    M: np.ndarray
    e_x: np.ndarray
    e_R: np.ndarray


def geometric(p: np.ndarray, v: np.ndarray, R: np.ndarray, W: np.ndarray, ref: np.ndarray, b1d: np.ndarray,
              gains: Gains, m: float, J: np.ndarray, g: float) -> Command:
    """The SE(3) controller (module docstring): state p, v (3,) world [m, m/s], R (3, 3) body-to-world, W (3,)
    body rate [rad/s]; ref (3, 3) rows [p_d, v_d, a_d] [m, m/s, m/s²]; b1d (3,) the desired heading; nominal m [kg],
    J (3, 3) [kg m²]; gravity g [m/s²]."""
    e_x, e_v = p - ref[0], v - ref[1]
    F = -gains.kx * e_x - gains.kv * e_v + m * g * E3 + m * ref[2]
    f = float(F @ R[:, 2])
    b3 = F / np.linalg.norm(F)
    b2 = np.cross(b3, b1d)
    b2 /= np.linalg.norm(b2)
    Rd = np.column_stack([np.cross(b2, b3), b2, b3])
    e_R = 0.5 * vee(Rd.T @ R - R.T @ Rd)
    M = -gains.kR * e_R - gains.kW * W + np.cross(W, J @ W)
    return Command(f, M, e_x, e_R)

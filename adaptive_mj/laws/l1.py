"""L1 adaptive augmentation of the geometric controller (Wu et al. 2023, "L1Quad: L1 adaptive augmentation of
geometric control for agile quadrotors"), the flying plant's fast-adaptation law (issue 33), as plain code over
arrays: a state predictor, piecewise-constant adaptation and a low-pass filter that decouples the adaptation's
speed from the loop's robustness.

On the velocity and body rate z = [v; Ω] (6,) [m/s, rad/s] the known model with the law's nominal mass m [kg] and
inertia J (3, 3) [kg m²] is

    v' = (f/m) R e₃ − g e₃,    Ω' = J⁻¹ (M − Ω × JΩ),

and everything else (a payload's mass and inertia, wind, a weak rotor) is a lumped uncertainty σ (6,) in
acceleration units [m/s², rad/s²]. With A_s = a_s I (a_s < 0) [1/s]:

    predictor     ẑ' = known(ẑ-free terms at the measured z, f, M) + σ̂ + A_s (ẑ − z)
    adaptation    σ̂ = −Φ⁻¹ e^{A_s T_s} (ẑ − z) at every sample T_s, Φ = A_s⁻¹ (e^{A_s T_s} − I) (piecewise constant)
    control       f_ad = −m (C σ̂_v) · R e₃,   M_ad = −J (C σ̂_Ω),   C a first-order low-pass of cut-off ω_c [rad/s]

added to the baseline's f and M. The x, y components of σ̂_v are unmatched by the thrust (it acts along R e₃):
only their projection on R e₃ is cancelled, as in L1Quad.

With σ̂ held over each sample, the prediction error after a sample is z̃ = −Φσ for a constant σ, so the estimate
settles at σ̂ = e^{a_s T_s} σ: a bias of a_s T_s (1 % at a_s = −5 1/s, T_s = 2 ms) that the baseline's position
loop must carry (tests/test_geometric.py measures it: 5 mm at hover with a 10 g payload on the 30 g vehicle).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

E3 = np.array([0.0, 0.0, 1.0])


class L1Gains(NamedTuple):
    """a_s [1/s] < 0 the predictor's pole; T_s [s] the adaptation's sample time; w_c [rad/s] the low-pass filter's
    cut-off (the same on the six channels)."""

    a_s: float
    T_s: float
    w_c: float


class L1State(NamedTuple):
    """z_hat (6,) the predicted [v; Ω]; sigma (6,) the adaptation's estimate σ̂; filtered (6,) C σ̂."""

    z_hat: np.ndarray
    sigma: np.ndarray
    filtered: np.ndarray

    @classmethod
    def start(cls, v: np.ndarray, W: np.ndarray) -> "L1State":
        """The predictor at the measured state, σ̂ = 0."""
        return cls(np.concatenate([v, W]), np.zeros(6), np.zeros(6))


def augmentation(state: L1State, R: np.ndarray, m: float, J: np.ndarray) -> tuple[float, np.ndarray]:
    """(f_ad [N], M_ad (3,) [N m]): the filtered estimate cancelled on the matched channels."""
    c = state.filtered
    return float(-m * (c[:3] @ R[:, 2])), -J @ c[3:]


def step(state: L1State, v: np.ndarray, W: np.ndarray, R: np.ndarray, f: float, M: np.ndarray, m: float,
         J: np.ndarray, g: float, gains: L1Gains, h: float) -> L1State:
    """Advance the predictor, the adaptation and the filter by h [s] (h = T_s: one adaptation per step) from the
    measured v, W, R and the total command f [N], M (3,) [N m] applied over the step (explicit Euler)."""
    z = np.concatenate([v, W])
    err = state.z_hat - z
    e = math.exp(gains.a_s * gains.T_s)
    sigma = -(gains.a_s / (e - 1.0)) * e * err  # −Φ⁻¹ e^{A_s T_s} z̃, A_s = a_s I
    known = np.concatenate([(f / m) * R[:, 2] - g * E3, np.linalg.solve(J, M - np.cross(W, J @ W))])
    z_hat = state.z_hat + h * (known + sigma + gains.a_s * err)
    alpha = 1.0 - math.exp(-gains.w_c * h)  # the first-order low-pass, exact for σ̂ held over the step
    filtered = state.filtered + alpha * (sigma - state.filtered)
    return L1State(z_hat, sigma, filtered)

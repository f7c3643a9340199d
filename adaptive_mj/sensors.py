"""What the law measures of an arm's state x = [q; q̇] (2, m) (`Sensors`, `sense`):
    q_m  = Δ round((q + n_q) / Δ)                    (encoder of Δ = 2π / counts rad; no rounding
                                                     without counts), n ~ N(0, σ²) drawn once per step
    q̇_m  = q̇ + n_q̇                                  (velocity = "measured"), or
    v_k  = α v_{k-1} + (1 - α) (q_m,k - q_m,k-1) / T  (velocity = "differentiated": a finite
           α = exp(-2π f_c T)                         difference through a first-order low-pass of
                                                     cut-off f_c, discretised exactly for the held
                                                     difference; T the sampling period)
The velocity estimate is updated once per sample (at the first stage of each physics step under
continuous control, once per control period under sampled-data control) and held between samples;
it starts at the initial state's velocity (the filter settled before the run). Positions are
measured at every stage the law runs at.

Plain array code (no mujoco, no numba): adaptive_mj.sim.stage runs `sense` in the Python
controller, and the compiled manipulator callback runs the same source compiled by numba.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Sensors", "sense", "surface_noise_std"]


@dataclass(frozen=True)
class Sensors:
    """An arm's sensors (see the module docstring). quantum: (m,) encoder resolution [rad or m per
    count], 0 where a joint is not quantised; differentiated: q̇ from positions instead of measured;
    cutoff_hz: the estimator's low-pass cut-off f_c [Hz] (inf: the plain difference)."""

    quantum: np.ndarray
    differentiated: bool = False
    cutoff_hz: float = math.inf

    def alpha(self, period: float) -> float:
        """The low-pass's α = exp(-2π f_c T) for sampling period T [s] (0 without a cut-off)."""
        return 0.0 if math.isinf(self.cutoff_hz) else math.exp(-2.0 * math.pi * self.cutoff_hz * period)

    @property
    def ideal(self) -> bool:
        """No quantisation and measured velocity: the law sees x + noise."""
        return not self.differentiated and not bool(np.any(self.quantum > 0))

    def describe(self) -> dict:
        """For a log's header and a trajectory's meta."""
        return {"encoder_quantum": [float(v) for v in self.quantum],
                "velocity": "differentiated" if self.differentiated else "measured",
                "velocity_cutoff_hz": None if math.isinf(self.cutoff_hz) else float(self.cutoff_hz)}


def sense(q, dq, noise, quantum, differentiated, update, first, alpha, period, q_prev, v_est, out):
    """out (2, m) = what the law sees of q, q̇ (m,) (true, at this stage) with this step's noise
    (2, m), per the module docstring. update: this call is a sample (the velocity estimate v_est
    (m,) advances, q_prev (m,) is the last sample's measured q); first: the run's first sample
    (v_est starts at the true q̇, q_prev at q_m)."""
    for j in range(out.shape[1]):
        y = q[j] + noise[0, j]
        if quantum[j] > 0.0:
            y = np.floor(y / quantum[j] + 0.5) * quantum[j]
        out[0, j] = y
        if differentiated:
            if update:
                if first:
                    v_est[j] = dq[j]
                else:
                    v_est[j] = alpha * v_est[j] + (1.0 - alpha) * ((y - q_prev[j]) / period)
                q_prev[j] = y
            out[1, j] = v_est[j]
        else:
            out[1, j] = dq[j] + noise[1, j]


def surface_noise_std(lam, sigma_q, sigma_dq, sensors: Sensors | None, period: float) -> np.ndarray:
    """(m,) standard deviation of the noise in s_j = q̃'_j + λ_j q̃_j from white measurement noise:
    lam, sigma_q, sigma_dq (m,) [1/s, rad, rad/s]; period T [s] of the velocity estimate.

    Encoders add their rounding as uniform noise, Δ²/12 (dithered by the noise: valid while
    σ_q ≳ Δ/2). Measured velocity: σ_s² = σ_q̇² + λ² σ_q². Differentiated: the position noise n
    enters s as -(λ n_k + g Σ_i h_i n_(k-i)), g = (1 - α)/T and h the impulse response of
    (1 - z⁻¹)/(1 - α z⁻¹) (h_0 = 1, h_i = α^(i-1)(α - 1)), so
        σ_s² = σ_q² [(λ + g)² + g² (1 - α)/(1 + α)]."""
    lam = np.asarray(lam, dtype=float)
    var_q = np.asarray(sigma_q, dtype=float) ** 2
    if sensors is not None:
        var_q = var_q + np.asarray(sensors.quantum, dtype=float) ** 2 / 12.0
    if sensors is None or not sensors.differentiated:
        return np.sqrt(np.asarray(sigma_dq, dtype=float) ** 2 + lam**2 * var_q)
    alpha = sensors.alpha(period)
    g = (1.0 - alpha) / period
    return np.sqrt(var_q * ((lam + g) ** 2 + g**2 * (1.0 - alpha) / (1.0 + alpha)))

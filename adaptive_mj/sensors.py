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

__all__ = ["Sensors", "sense"]


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

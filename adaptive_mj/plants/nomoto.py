"""The Nomoto/Norrbin steering model and its fit to recorded rudder-step responses (numpy only).

    T r' + r + alpha r³ = K (delta + delta_b),     r = psi' [rad/s]

K [1/s] rudder gain, T [s] time constant, alpha [s²] Norrbin's nonlinear yaw damping,
delta_b [rad] a rudder bias (the rudder angle a constant yaw moment takes to hold a course).
Divided by K it is the lecture's plant of order 2 in psi (adaptive_mj.form.ModelForm):

    (T/K) psi'' = -(1/K) psi' - (alpha/K) psi'³ + delta_b + delta

so d = T/K [s²], p = (1/K [s], alpha/K [s³], delta_b [rad]), phi(x) = [-psi', -psi'³, 1], h = 1.

`fit` finds (K, T, alpha, delta_b) by output-error least squares: the model is driven by the
recorded rudder angles and its yaw rate compared with the recorded one, over several steps at
once (MuJoCo's own minimiser, mujoco.minimize.least_squares, a pure-numpy Levenberg-Marquardt).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptive_mj.form import ModelForm

PARAM_NAMES = ("K", "T", "alpha", "delta_b")
THETA_NAMES = ("T_over_K", "one_over_K", "alpha_over_K", "rudder_bias")


@dataclass(frozen=True)
class NomotoFit:
    """Fitted K [1/s], T [s], alpha [s²], delta_b [rad]; rms [rad/s]: the yaw-rate residual's RMS
    over every recorded sample; peak [rad/s]: the largest recorded |r| (the residual's scale)."""

    K: float
    T: float
    alpha: float
    delta_b: float
    rms: float
    peak: float

    @property
    def theta(self) -> np.ndarray:
        """(4,) the lecture's theta = [T/K, 1/K, alpha/K, delta_b] (THETA_NAMES)."""
        return np.array([self.T / self.K, 1.0 / self.K, self.alpha / self.K, self.delta_b])


def nomoto_form() -> ModelForm:
    """(T/K) psi'' = -(1/K) psi' - (alpha/K) psi'³ + delta_b + delta: the autopilot's regressor."""

    def phi(x):
        r = x[1]
        return np.array([-r, -r * r * r, 1.0])

    return ModelForm(order=2, p_names=THETA_NAMES[1:], phi=phi, d_name=THETA_NAMES[0])


def from_theta(theta) -> tuple[float, float, float, float]:
    """(K, T, alpha, delta_b) of theta = [T/K, 1/K, alpha/K, delta_b] (nan where 1/K = 0)."""
    d, a, b, c = (float(v) for v in theta)
    K = 1.0 / a if a != 0 else float("nan")
    return K, d * K, b * K, c


def simulate(params: np.ndarray, delta: np.ndarray, h: float, r0: np.ndarray | None = None) -> np.ndarray:
    """Yaw rates of the Nomoto model, classic RK4 with the rudder angle linear between samples.

    params: (4, P) columns [K, T, alpha, delta_b] (P parameter sets at once, or (4,) for one);
    delta: (R, N) rudder angle [rad] of R runs at times 0, h, ..., (N-1) h; r0: (R,) yaw rates at
    t = 0 [rad/s] (zeros). Returns r: (P, R, N) [rad/s] at the same times ((R, N) for one set)."""
    p = np.asarray(params, dtype=float)
    single = p.ndim == 1
    p = p.reshape(4, -1)
    K, T, al, b = (p[i][:, None] for i in range(4))
    delta = np.asarray(delta, dtype=float)
    R, N = delta.shape
    r = np.zeros((p.shape[1], R)) if r0 is None else np.tile(np.asarray(r0, dtype=float), (p.shape[1], 1))
    out = np.empty((p.shape[1], R, N))
    out[:, :, 0] = r

    def f(r, d):
        return (K * (d + b) - r - al * r * r * r) / T

    for i in range(N - 1):
        d0, d1 = delta[:, i], delta[:, i + 1]
        dm = 0.5 * (d0 + d1)
        k1 = f(r, d0)
        k2 = f(r + 0.5 * h * k1, dm)
        k3 = f(r + 0.5 * h * k2, dm)
        k4 = f(r + h * k3, d1)
        r = r + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[:, :, i + 1] = r
    return out[0] if single else out


def fit(delta: np.ndarray, r: np.ndarray, h: float, *, r0: np.ndarray | None = None) -> NomotoFit:
    """Least-squares (K, T, alpha, delta_b) of recorded runs.

    delta, r: (R, N) rudder angle [rad] and yaw rate [rad/s] of R runs sampled every h [s].
    Starts from the equation-error solution (r' by finite differences, linear in the
    parameters), then minimises the output error sum (r_model - r)² over every sample."""
    delta, r = np.asarray(delta, dtype=float), np.asarray(r, dtype=float)
    try:
        with np.errstate(all="ignore"):
            x0 = _equation_error(delta, r, h)
    except np.linalg.LinAlgError:  # degenerate data: a fit that the caller's checks refuse
        nan = float("nan")
        return NomotoFit(K=nan, T=nan, alpha=nan, delta_b=nan, rms=nan, peak=float(np.max(np.abs(r))))

    def residual(P):
        return (simulate(P, delta, h, r0) - r[None]).reshape(P.shape[1], -1).T

    from mujoco import minimize

    with np.errstate(all="ignore"):  # a diverging trial point is the minimiser's to reject, not a warning
        x, _ = minimize.least_squares(x0, residual, verbose=0, max_iter=60)
        res = residual(x.reshape(4, 1))[:, 0]
    return NomotoFit(K=float(x[0]), T=float(x[1]), alpha=float(x[2]), delta_b=float(x[3]),
                     rms=float(np.sqrt(np.mean(res**2))), peak=float(np.max(np.abs(r))))


def _equation_error(delta: np.ndarray, r: np.ndarray, h: float) -> np.ndarray:
    """[K, T, alpha, delta_b] from r = -T r' - alpha r³ + K delta + K delta_b (linear least squares),
    r' by central differences; T and K kept positive for the start of the output-error fit."""
    rd = np.gradient(r, h, axis=1)
    A = np.stack([delta.ravel(), np.ones(delta.size), -rd.ravel(), -(r**3).ravel()], axis=1)
    (K, Kb, T, al), *_ = np.linalg.lstsq(A, r.ravel(), rcond=None)
    K, T = max(float(K), 1e-3), max(float(T), 1e-2)
    return np.array([K, T, float(al), float(Kb) / K])

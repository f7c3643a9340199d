"""Sliding-surface adaptive control of order n (lecture 7), and two baselines.

Plant (see adaptive_mj.form.ModelForm):   d y^(n) = f(x) + phi(x) p + h(x) u
Tracking error ỹ = y_d - y, and

    s      = (d/dt + lambda)^(n-1) ỹ
           = sum_{i=0}^{n-1} C(n-1, i) lambda^(n-1-i) ỹ^(i)
    ṡ_r    = ((d/dt + lambda)^(n-1) - (d/dt)^(n-1)) ỹ' + y_d^(n)
           = y_d^(n) + sum_{i=0}^{n-2} C(n-1, i) lambda^(n-1-i) ỹ^(i+1)
    u      = h^-1 (d̂ ṡ_r - f - phi p̂ + k s)
    p̂'     = -phi^T s / gamma_p,      d̂' = ṡ_r s / gamma_d

so that with V = ½ d s² + ½ sum_i gamma_i θ̃_i²  (θ̃ = θ̂ - θ),  V' = -k s².
(ṡ = ṡ_r - y^(n), hence d ṡ = -d̃ ṡ_r + phi p̃ - k s.)

gamma may be a scalar (the lecture) or one value per entry of theta.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.common import DeadZone, LawStep, as_gamma


def surface_coefficients(order: int, lam: float) -> np.ndarray:
    """(order,) coefficients c_i = C(n-1, i) lam^(n-1-i), so s = c . [ỹ, ỹ', ..., ỹ^(n-1)]."""
    n = order
    return np.array([math.comb(n - 1, i) * lam ** (n - 1 - i) for i in range(n)])


def sliding_terms(coeffs: np.ndarray, x: np.ndarray, ref: np.ndarray) -> tuple[float, float, float]:
    """(s, ṡ_r, ỹ) for state x (n,) and reference ref (n+1,)."""
    n = coeffs.shape[0]
    e = ref[:n] - x
    s = float(coeffs @ e)
    s_r_dot = float(ref[n] + coeffs[:-1] @ e[1:])
    return s, s_r_dot, float(e[0])


def _check_gains(form: ModelForm, lam: float, k: float) -> None:
    if form.d_name is None:
        raise ValueError("sliding laws need a form with an unknown leading coefficient d")
    if not (math.isfinite(lam) and lam > 0):
        raise ValueError(f"lambda must be finite and > 0, got {lam}")
    if not (math.isfinite(k) and k >= 0):
        raise ValueError(f"k must be finite and >= 0, got {k}")


def _certainty_equivalent(form, x, s, s_r_dot, theta, k) -> float:
    """h^-1 (d̂ ṡ_r - f - phi p̂ + k s)."""
    return (theta[0] * s_r_dot - form.f(x) - float(form.phi(x) @ theta[1:]) + k * s) / form.h(x)


class SlidingAdaptiveLaw:
    """The lecture's adaptive sliding law of order n = form.order, optionally with a dead-zone.

    lam: lambda [1/s] of the surface; k: gain on s [u per unit of s];
    gamma: scalar or (n_theta,) adaptation "stiffness" (estimates move at 1/gamma);
    dead_zone: None, or a DeadZone (default test |s| < eps, the lecture's formula).
    """

    def __init__(self, form: ModelForm, *, lam: float, k: float, gamma, dead_zone: DeadZone | None = None):
        _check_gains(form, lam, k)
        self.form = form
        self.order = form.order
        self.names = form.names
        self.lam = float(lam)
        self.k = float(k)
        self.gamma = as_gamma(gamma, len(self.names))
        self.dead_zone = dead_zone
        self._coeffs = surface_coefficients(form.order, self.lam)

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        form = self.form
        s, s_r_dot, y_tilde = sliding_terms(self._coeffs, x, ref)
        u = _certainty_equivalent(form, x, s, s_r_dot, theta_hat, self.k)
        if self.dead_zone is None or self.dead_zone.adapting(s, y_tilde):
            rate = np.empty(len(self.names))
            rate[0] = s_r_dot * s
            rate[1:] = -form.phi(x) * s
            rate /= self.gamma
        else:
            rate = np.zeros(len(self.names))
        return LawStep(u, rate, s, s_r_dot)

    def lyapunov(self, s, theta_hat, theta) -> np.ndarray:
        """V = ½ d s² + ½ sum_i gamma_i (θ̂_i - θ_i)².  s: (N,), theta*: (N, n_theta)."""
        s = np.asarray(s, dtype=float)
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        d = np.asarray(theta, dtype=float)[..., 0]
        return 0.5 * d * s**2 + 0.5 * np.sum(self.gamma * err**2, axis=-1)


class FixedNominalLaw:
    """Baseline: the same control structure with theta_hat held at its initial (nominal) value."""

    def __init__(self, form: ModelForm, *, lam: float, k: float):
        _check_gains(form, lam, k)
        self.form = form
        self.order = form.order
        self.names = form.names
        self.lam = float(lam)
        self.k = float(k)
        self._coeffs = surface_coefficients(form.order, self.lam)

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        s, s_r_dot, _ = sliding_terms(self._coeffs, x, ref)
        u = _certainty_equivalent(self.form, x, s, s_r_dot, theta_hat, self.k)
        return LawStep(u, np.zeros(len(self.names)), s, s_r_dot)

    def lyapunov(self, s, theta_hat, theta) -> np.ndarray:
        """No adaptation, so only the tracking part: V = ½ d s²."""
        d = np.asarray(theta, dtype=float)[..., 0]
        return 0.5 * d * np.asarray(s, dtype=float) ** 2


class RobustSlidingLaw(FixedNominalLaw):
    """Baseline: robust sliding control with a boundary layer, nominal parameters fixed.

    u = h^-1 (d̂ ṡ_r - f - phi p̂ + k s + K sat(s / Phi))
    K: switching gain [u units] (should exceed the model-error bound);
    boundary_layer: Phi > 0 [units of s]; sat(z) = clip(z, -1, 1).
    """

    def __init__(self, form: ModelForm, *, lam: float, k: float, K: float, boundary_layer: float):
        super().__init__(form, lam=lam, k=k)
        if not (math.isfinite(K) and K >= 0):
            raise ValueError(f"K must be finite and >= 0, got {K}")
        if not (math.isfinite(boundary_layer) and boundary_layer > 0):
            raise ValueError(f"boundary_layer must be finite and > 0, got {boundary_layer}")
        self.K = float(K)
        self.boundary_layer = float(boundary_layer)

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        step = super().__call__(t, x, ref, theta_hat)
        sat = min(1.0, max(-1.0, step.s / self.boundary_layer))
        return step._replace(u=step.u + self.K * sat / self.form.h(x))

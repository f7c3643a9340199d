"""Composite adaptation (Slotine and Li): the sliding law's tracking-error update plus
the prediction error of a filtered regressor. No acceleration is measured.

The plant  d y^(n) = f(x) + φ(x)ᵀp + h(x) u  is linear in θ = [d; p]:

    Y θ = τ,    Y = [y^(n), −φᵀ],    τ = f + h u.

Per physics step k this holds exactly in the integrator's own terms: the step moves
y^(n-1) by h Σ_i b_i y^(n)(stage i) (b_i: the RK4 weights, or 1 for Euler), so with
a_k = (y^(n-1)_{k+1} − y^(n-1)_k) / h (the velocity change over the step, not a
measured acceleration), φ̄_k = Σ_i b_i φ(x_i) and τ̄_k = Σ_i b_i (f(x_i) + h(x_i) u_i)
over the stages the controller saw,

    d a_k − φ̄_kᵀ p = τ̄_k          (the ideal plant, to round-off).

Each of a, φ̄, τ̄ is passed through the same discrete first-order low-pass filter
z ← z + (1 − e^(−λ_f h)) (input − z) (the zero-order-hold W(s) = λ_f / (s + λ_f)),
which keeps the identity: Y_f = [z_a, −z_φ], τ_f = z_τ, Y_f θ = τ_f. The prediction
error is e = Y_f θ̂ − τ_f = Y_f θ̃ and the update is

    θ̂' = (sliding law's θ̂') − κ Γ⁻¹ Y_fᵀ e,

so that V = ½ d s² + ½ θ̃ᵀΓθ̃ has V' = −k s² − κ (Y_f θ̃)² ≤ 0 in the ideal case: the
estimates move along every direction the filtered regressor has excited, not only
while s is large. The filters start at the first step's values.

This law keeps filter state between calls (``has_filters``, laws.protocol), so it runs on the
Python callback path: loop.Controller resets it, calls step_begins(x) with the measured state at
the start of each step and step_ends(stage states, stage controls, weights, h) at its end.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.common import DeadZone, LawStep, Modification, modify_rate
from adaptive_mj.laws.sliding import SlidingAdaptiveLaw


class CompositeSlidingLaw(SlidingAdaptiveLaw):
    """The sliding adaptive law of order n with composite adaptation.

    kappa: κ > 0, weight of the prediction error [gamma-units / (unit of τ)² / s];
    filter_rate: λ_f > 0 [1/s]. The other arguments as SlidingAdaptiveLaw.
    """

    native = False  # filter state between calls: the Python callback path
    has_filters = True  # the loop calls reset, step_begins and step_ends (laws.protocol)

    def __init__(self, form: ModelForm, *, lam: float, k: float, gamma, kappa: float, filter_rate: float,
                 dead_zone: DeadZone | None = None, modification: Modification | None = None):
        super().__init__(form, lam=lam, k=k, gamma=gamma, dead_zone=dead_zone, modification=modification)
        for name, v in (("composite gain", kappa), ("composite filter", filter_rate)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v}")
        self.kappa = float(kappa)
        self.filter_rate = float(filter_rate)
        self._z: np.ndarray | None = None  # [z_a, z_φ (n_p), z_τ]
        # (y^(n-1) at the step's start, φ̄, τ̄, h) of the step just done
        self._pending: tuple[float, np.ndarray, float, float] | None = None

    def reset(self) -> None:
        """Forget the filters (a new run)."""
        self._z = None
        self._pending = None

    def step_ends(self, xs, us, weights, h: float) -> None:
        """After a physics step: xs, us the measured stage states (n,) and applied controls the
        controller saw, weights the integrator's b_i, h the step [s]."""
        form = self.form
        phi_bar = sum(w * np.asarray(form.phi(x), dtype=float) for w, x in zip(weights, xs, strict=True))
        tau_bar = sum(w * (form.f(x) + form.h(x) * u) for w, x, u in zip(weights, xs, us, strict=True))
        self._pending = (float(xs[0][self.order - 1]), phi_bar, float(tau_bar), float(h))

    def step_begins(self, x: np.ndarray) -> None:
        """At the start of a physics step, with its measured state x (n,): the previous step's
        a = Δy^(n-1)/h is now known, and the filters advance by one step."""
        if self._pending is None:
            return
        y0, phi_bar, tau_bar, h = self._pending
        self._pending = None
        inp = np.concatenate(([(float(x[self.order - 1]) - y0) / h], phi_bar, [tau_bar]))
        if self._z is None:
            self._z = inp
        else:
            self._z = self._z + (1.0 - math.exp(-self.filter_rate * h)) * (inp - self._z)

    def prediction(self, theta_hat: np.ndarray) -> tuple[np.ndarray, float]:
        """(Y_f (n_theta,), e = Y_f θ̂ − τ_f); zeros before the first step is known."""
        if self._z is None:
            return np.zeros(len(self.names)), 0.0
        z = self._z
        Yf = np.concatenate(([z[0]], -z[1:-1]))
        return Yf, float(Yf @ theta_hat - z[-1])

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        step = super().__call__(t, x, ref, theta_hat)
        if self._z is None:
            return step
        Yf, e = self.prediction(theta_hat)
        rate = step.theta_hat_dot - self.kappa * Yf * e / self.gamma
        _, _, theta0, lower, upper = self.modification.arrays(len(self.names), gamma=self.gamma)
        modify_rate(rate, theta_hat, 0.0, 0.0, 0.0, theta0, self.gamma, lower, upper)  # projection again
        return step._replace(theta_hat_dot=rate)

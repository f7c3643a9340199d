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

The arithmetic is written once, as plain array functions that numba compiles (the style of
laws.sliding.sliding_law_values): `stage_sums` (φ̄, τ̄ with the integrator's weights, one stage at a
time), `filter_gain` and `filter_step` (the filters' advance by one step), `composite_rate` (the
prediction e = Y_f θ̂ − τ_f and the rate correction −κ Y_f e / γ, then the projection again). The
filter state is two arrays: z = [z_a, z_φ (n_p), z_τ] and the pending step [y^(n-1) at its start,
φ̄ (n_p), τ̄], both (n_p + 2,).

This law keeps filter state between calls (``has_filters``, laws.protocol). On the Python callback
path loop.Controller resets it, calls step_begins(x) with the measured state at the start of each
step and step_ends(stage states, stage controls, weights, h) at its end. It is also ``native``: the
compiled 1-DOF callback (adaptive_mj.plants.one_dof_kernel, its composite variant) keeps z and the pending step
in its buffers, adds each stage to the sums when it applies the stage's control and advances the
filters at each step's first stage, calling the same functions: the same rows bit for bit
(tests/test_native.py). Continuous control only (the loop refuses sampled-data control with filters).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.common import DeadZone, LawStep, Modification, modify_rate
from adaptive_mj.laws.sliding import SlidingAdaptiveLaw


def filter_gain(filter_rate: float, h: float) -> float:
    """1 − e^(−λ_f h): the gain of the zero-order-hold filter W(s) = λ_f / (s + λ_f) over a step h [s]."""
    return 1.0 - math.exp(-filter_rate * h)


def stage_sums(pending, w, phi, f, h, u):
    """One stage into the step's sums, in place: pending[1:1+n_p] += w φ(x_i), pending[1+n_p] += w (f(x_i) +
    h(x_i) u_i). pending (n_p + 2,) = [y^(n-1) at the step's start, φ̄, τ̄], the sums zero before the first
    stage (so the sums are the same floats as Python's sum(), which starts from 0); w: the stage's b_i; phi
    (n_p,), f, h: the form at the stage's measured state; u: the control applied over the stage."""
    n_p = phi.shape[0]
    for j in range(n_p):
        pending[1 + j] += w * phi[j]
    pending[1 + n_p] += w * (f + h * u)


def filter_step(z, pending, v, h, gain, first):
    """The filters advance by the step just done, in place: its input [a, φ̄, τ̄] with a = (v − pending[0]) / h
    (v: y^(n-1) measured at the next step's start) into z (n_p + 2,) = [z_a, z_φ, z_τ]: z = input at the first
    step (first), else z ← z + gain (input − z) (gain: filter_gain)."""
    a = (v - pending[0]) / h
    if first:
        z[0] = a
        for j in range(1, z.shape[0]):
            z[j] = pending[j]
    else:
        z[0] = z[0] + gain * (a - z[0])
        for j in range(1, z.shape[0]):
            z[j] = z[j] + gain * (pending[j] - z[j])


def prediction_error(z, theta):
    """e = Y_f θ̂ − τ_f with Y_f = [z_a, −z_φ] (z (n_theta + 1,) = [z_a, z_φ, z_τ]), summed in θ's order."""
    n = theta.shape[0]
    e = 0.0
    for j in range(n):
        e += (z[0] if j == 0 else -z[j]) * theta[j]
    return e - z[n]


def composite_rate(z, theta, kappa, gamma, theta0, lower, upper, rate):
    """The composite correction of the sliding law's rate (n_theta,), in place: rate_j −= κ Y_f,j e / γ_j
    (e: prediction_error), then the projection's tangent cone again (common.modify_rate without leakage: the
    sliding law applied the leakage already). Returns e."""
    e = prediction_error(z, theta)
    for j in range(theta.shape[0]):
        rate[j] = rate[j] - kappa * (z[0] if j == 0 else -z[j]) * e / gamma[j]
    modify_rate(rate, theta, 0.0, 0.0, 0.0, theta0, gamma, lower, upper)
    return e


class CompositeSlidingLaw(SlidingAdaptiveLaw):
    """The sliding adaptive law of order n with composite adaptation.

    kappa: κ > 0, weight of the prediction error [gamma-units / (unit of τ)² / s];
    filter_rate: λ_f > 0 [1/s]. The other arguments as SlidingAdaptiveLaw.
    """

    native = True  # adaptive_mj.plants.one_dof_kernel compiles it (continuous control, a 1-DOF MuJoCo plant)
    has_filters = True  # the Python path: the loop calls reset, step_begins and step_ends (laws.protocol)

    def __init__(self, form: ModelForm, *, lam: float, k: float, gamma, kappa: float, filter_rate: float,
                 dead_zone: DeadZone | None = None, modification: Modification | None = None):
        super().__init__(form, lam=lam, k=k, gamma=gamma, dead_zone=dead_zone, modification=modification)
        for name, v in (("composite gain", kappa), ("composite filter", filter_rate)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be finite and > 0, got {v}")
        self.kappa = float(kappa)
        self.filter_rate = float(filter_rate)
        self.reset()

    def reset(self) -> None:
        """Forget the filters (a new run)."""
        size = len(self.names) + 1  # n_p + 2
        self._z = np.zeros(size)  # [z_a, z_φ (n_p), z_τ]
        self._pending = np.zeros(size)  # [y^(n-1) at the step's start, φ̄, τ̄] of the step just done
        self._h = 0.0
        self._has_pending = False  # a step is done whose input the filters have not taken
        self._filtered = False  # the filters hold a value (from the second step on)

    def native_params(self) -> dict[str, Any]:
        """The sliding law's (SlidingAdaptiveLaw.native_params) and "composite": (κ, λ_f)."""
        return {**super().native_params(), "composite": (self.kappa, self.filter_rate)}

    def chunk_kernel(self, order: int) -> None:
        """None: the analytic chunk engine has no filters (the Python path runs it there)."""
        return None

    def step_ends(self, xs, us, weights, h: float) -> None:
        """After a physics step: xs, us the measured stage states (n,) and applied controls the
        controller saw, weights the integrator's b_i, h the step [s]."""
        form, pending = self.form, self._pending
        pending[:] = 0.0
        pending[0] = float(xs[0][self.order - 1])
        for w, x, u in zip(weights, xs, us, strict=True):
            stage_sums(pending, float(w), np.asarray(form.phi(x), dtype=float), float(form.f(x)), float(form.h(x)),
                       float(u))
        self._h = float(h)
        self._has_pending = True

    def step_begins(self, x: np.ndarray) -> None:
        """At the start of a physics step, with its measured state x (n,): the previous step's
        a = Δy^(n-1)/h is now known, and the filters advance by one step."""
        if not self._has_pending:
            return
        h = self._h
        filter_step(self._z, self._pending, float(x[self.order - 1]), h, filter_gain(self.filter_rate, h),
                    not self._filtered)
        self._has_pending = False
        self._filtered = True

    def prediction(self, theta_hat: np.ndarray) -> tuple[np.ndarray, float]:
        """(Y_f (n_theta,), e = Y_f θ̂ − τ_f); zeros before the first step is known."""
        if not self._filtered:
            return np.zeros(len(self.names)), 0.0
        z = self._z
        Yf = np.concatenate(([z[0]], -z[1:-1]))
        return Yf, float(prediction_error(z, np.asarray(theta_hat, dtype=float)))

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        step = super().__call__(t, x, ref, theta_hat)
        if not self._filtered:
            return step
        arrays = self._fixed[1] if self._fixed is not None else self.arrays()
        rate = np.array(step.theta_hat_dot, dtype=float)
        composite_rate(self._z, np.asarray(theta_hat, dtype=float), self.kappa, arrays.gamma, arrays.theta0,
                       arrays.lower, arrays.upper, rate)
        return step._replace(theta_hat_dot=rate)

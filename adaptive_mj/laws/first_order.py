"""Adaptive control of a first-order system (lecture 7, first part).

    x' = f(x) + phi(x) p + u,          x̃ = x_d - x
    u  = x_d' - f(x) - phi(x) p̂ + k x̃
    p̂' = -phi(x)^T x̃ / gamma
    V  = ½ x̃² + ½ gamma p̃^T p̃,   p̃ = p̂ - p,    V' = -k x̃²

With a common.Modification: p̂' -= (σ + ν|x̃|)(p̂ - p₀)/gamma, projected onto a box.

This is the n = 1 sliding law with d = 1 known and s = x̃; it is kept as its
own class because it is the lecture's first example, written in its notation. Its arithmetic is
`first_order_values`, plain loops that the Python class calls and the analytic twin's compiled loop
(adaptive_mj.sim.native_chunk) compiles.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.keys import Table
from adaptive_mj.laws.common import (NO_MODIFICATION, DeadZone, Gains, LawStep, Modification, as_gamma,
                                     dead_zone_open, modify_rate, record_dtype)
from adaptive_mj.laws.kernel import LawKernel, f64, f_fn, form_arrays, form_law_arrays, h_fn, phi_fn
from adaptive_mj.laws.kinds import BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import Box, Law, SurfaceFeedback
from adaptive_mj.laws.sliding import model_law_keys, read_model_law
from adaptive_mj.specs import LawSpec, PlantSpec


@dataclass(frozen=True)
class FirstOrderGains(Gains):
    """The first-order law's scalars, by name: what `first_order_values` reads of them (the compiled loop reads
    the same names as fields of a FIRST_ORDER_GAINS record, `record()`, through its address).

    k: gain on x̃ [u per unit of x]; dead_zone: adaptation stops while |x̃| < dz_width (False: it never stops);
    sigma, e_mod: the leakage (common.modify_rate)."""

    k: float
    dz_width: float
    sigma: float
    e_mod: float
    dead_zone: bool


FIRST_ORDER_GAINS = record_dtype(FirstOrderGains)


def first_order_values(x, ref, theta, gains, gamma, theta0, lower, upper, phi, f, h, rate):
    """One evaluation of the lecture's first-order law at x (1,) on ref (2,) = [x_d, x_d'] with θ̂ theta (n_p,),
    the form's values phi (n_p,), f, h at x; gains: FirstOrderGains (or its record); gamma, theta0, lower, upper
    (n_p,): the adaptation gains, the leakage's prior and the projection's box. Writes θ̂' into rate (n_p,) and
    returns (u, x̃):

        x̃ = x_d - x,   u = (x_d' - f - φ·θ̂ + k x̃) / h,   θ̂' = -φ x̃ / γ  [- (σ + ν|x̃|)(θ̂ - θ₀)/γ, projected]

    Plain loops (φ·θ̂ summed from 0, as numpy's dot of a short vector sums it), so numba compiles it."""
    x_tilde = ref[0] - x[0]
    dot = 0.0
    for j in range(phi.shape[0]):
        dot += phi[j] * theta[j]
    u = (ref[1] - f - dot + gains.k * x_tilde) / h
    if not gains.dead_zone or dead_zone_open(x_tilde, gains.dz_width):
        for j in range(phi.shape[0]):
            rate[j] = -phi[j] * x_tilde / gamma[j]
    else:
        for j in range(phi.shape[0]):
            rate[j] = 0.0
    modify_rate(rate, theta, abs(x_tilde), gains.sigma, gains.e_mod, theta0, gamma, lower, upper)
    return u, x_tilde


def first_order_kernel(x, r, th, g, a, lower, upper, rate):
    """The lecture's first-order law as the chunk engine compiles it (laws.kernel's signature: first_order_values
    with φ, f, h of the law's form); g a FIRST_ORDER_GAINS record, a = [zeros (n), Γ, θ₀] (laws.kernel
    .form_arrays)."""
    _, gamma, theta0, _ = form_arrays(a, x.shape[0], th.shape[0])
    return first_order_values(x, r, th, g, gamma, theta0, lower, upper, phi_fn(x), f_fn(x), h_fn(x), rate)


class FirstOrderAdaptiveLaw(Law):
    """form: order-1 ModelForm with d_name=None (h is honoured; the lecture has h = 1).

    k: gain on x̃ [u per unit of x]; gamma: scalar or (n_p,); dead_zone: None or a
    DeadZone on |x̃|; modification: σ/e-modification and projection, or None.
    """

    def __init__(self, form: ModelForm, *, k: float, gamma, dead_zone: DeadZone | None = None,
                 modification: Modification | None = None):
        if form.order != 1 or form.d_name is not None:
            raise ValueError("FirstOrderAdaptiveLaw needs an order-1 form with d known (d_name=None)")
        if not (math.isfinite(k) and k >= 0):
            raise ValueError(f"k must be finite and >= 0, got {k}")
        self.form = form
        self.order = 1
        self.names = form.names
        self.k = float(k)
        self.gamma = as_gamma(gamma, len(self.names))
        self.dead_zone = dead_zone
        self.modification = modification or NO_MODIFICATION
        sigma, e_mod, self._theta0, self._lower, self._upper = self.modification.arrays(len(self.names))
        self.gains = FirstOrderGains(self.k, dead_zone.width if dead_zone is not None else 0.0, sigma, e_mod,
                                     dead_zone is not None)

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) of the projection, or None (common.Modification.box)."""
        return self.modification.box(len(self.names))

    def feedback(self) -> SurfaceFeedback:
        """k on s = x̃ (no surface: λ None, nothing added to the loop's fastest mode)."""
        return SurfaceFeedback(k=self.k, lam=None, effective=self.k, surface_rate=0.0, keys="law.k")

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        form = self.form
        rate = np.empty(len(self.names))
        u, x_tilde = first_order_values(x, ref, theta_hat, self.gains, self.gamma, self._theta0, self._lower,
                                        self._upper, form.phi(x), form.f(x), form.h(x), rate)
        return LawStep(float(u), rate, float(x_tilde), float(ref[1]))

    def native_arrays(self) -> dict[str, Any]:
        """What the analytic chunk engine (adaptive_mj.sim.native_chunk) takes of this law, by name: "gains", the
        FIRST_ORDER_GAINS record, and the arrays gamma, theta0, lower, upper (n_p,)."""
        return {"gains": self.gains.record(), "gamma": self.gamma, "theta0": self._theta0, "lower": self._lower,
                "upper": self._upper}

    def chunk_kernel(self, order: int) -> LawKernel | None:
        """Its compiled form (laws.kernel: first_order_kernel over `native_arrays`) on a plant of its form's
        order; None on another."""
        if self.form.order != order:
            return None
        p = self.native_arrays()
        return LawKernel(first_order_kernel, FIRST_ORDER_GAINS, p["gains"],
                         form_law_arrays(np.zeros(self.order), p["gamma"], p["theta0"]), f64(p["lower"]),
                         f64(p["upper"]), self.form, what="the first-order law")

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """V = ½ x̃² + ½ sum_i gamma_i p̃_i²."""
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        return 0.5 * np.asarray(s, dtype=float) ** 2 + 0.5 * np.sum(self.gamma * err**2, axis=-1)


# --- the law kind: its keys (law.*; those of the sliding laws without law.lambda), and its builder -------
def _read(t: Table, kind: str, plant: PlantSpec, order: int) -> LawSpec:
    return read_model_law(t, kind, plant, order, adaptive=True, surface=False)


def _build(ctx: BuildContext) -> Law:
    form = ctx.model_form()
    return FirstOrderAdaptiveLaw(form, k=ctx.law.k, gamma=ctx.gamma(form.names), dead_zone=ctx.dead_zone(),
                                 modification=ctx.modification)


#: this law kind, registered (adaptive_mj.laws.kinds): law.kind = "first_order_adaptive", exactly on
#: plant.kind = "first_order" (which takes no other built-in law)
KIND = register(LawKind(
    "first_order_adaptive", frozenset({Form.MODEL}), True,
    "the lecture's first-order adaptive law (plant.kind = 'first_order' only)",
    keys=model_law_keys(adaptive=True, surface=False), read=_read, build=_build, plant_kinds=frozenset({"first_order"}),
    module=__name__, example=("lecture_first_order", ())))

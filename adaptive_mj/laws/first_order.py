"""Adaptive control of a first-order system (lecture 7, first part).

    x' = f(x) + phi(x) p + u,          x̃ = x_d - x
    u  = x_d' - f(x) - phi(x) p̂ + k x̃
    p̂' = -phi(x)^T x̃ / gamma
    V  = ½ x̃² + ½ gamma p̃^T p̃,   p̃ = p̂ - p,    V' = -k x̃²

With a common.Modification: p̂' -= (σ + ν|x̃|)(p̂ - p₀)/gamma, projected onto a box.

This is the n = 1 sliding law with d = 1 known and s = x̃; it is kept as its
own class because it is the lecture's first example, written in its notation.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.keys import Table
from adaptive_mj.laws.common import NO_MODIFICATION, DeadZone, LawStep, Modification, as_gamma, modify_rate
from adaptive_mj.laws.kinds import BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import Box, Law, SurfaceFeedback
from adaptive_mj.laws.sliding import model_law_keys, read_model_law
from adaptive_mj.specs import LawSpec, PlantSpec


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
        self._mod = self.modification.arrays(len(self.names))

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) of the projection, or None (common.Modification.box)."""
        return self.modification.box(len(self.names))

    def feedback(self) -> SurfaceFeedback:
        """k on s = x̃ (no surface: λ None, nothing added to the loop's fastest mode)."""
        return SurfaceFeedback(k=self.k, lam=None, effective=self.k, surface_rate=0.0, keys="law.k")

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        form = self.form
        x_tilde = float(ref[0] - x[0])
        phi = form.phi(x)
        u = (ref[1] - form.f(x) - float(phi @ theta_hat) + self.k * x_tilde) / form.h(x)
        if self.dead_zone is None or self.dead_zone.adapting(x_tilde, x_tilde):
            rate = -phi * x_tilde / self.gamma
        else:
            rate = np.zeros(len(self.names))
        sigma, e_mod, theta0, lower, upper = self._mod
        modify_rate(rate, theta_hat, abs(x_tilde), sigma, e_mod, theta0, self.gamma, lower, upper)
        return LawStep(u, rate, x_tilde, float(ref[1]))

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

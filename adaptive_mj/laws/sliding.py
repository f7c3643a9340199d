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
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.form import ModelForm
from adaptive_mj.keys import Key, Table
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws.common import (NO_MODIFICATION, DeadZone, DeadZoneOn, LawStep, Modification, as_gamma,
                                     Gains, dead_zone_open, modify_rate, record_dtype)
from adaptive_mj.laws.kernel import LawKernel, f64, f_fn, form_arrays, form_law_arrays, h_fn, phi_fn
from adaptive_mj.laws.kinds import BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import Box, Law, SurfaceFeedback
from adaptive_mj.specs import LawSpec, PlantSpec


def surface_coefficients(order: int, lam: float) -> np.ndarray:
    """(order,) coefficients c_i = C(n-1, i) lam^(n-1-i), so s = c . [ỹ, ỹ', ..., ỹ^(n-1)]."""
    n = order
    return np.array([math.comb(n - 1, i) * lam ** (n - 1 - i) for i in range(n)])


def surface_noise_std(order: int, lam: float, std) -> float:
    """σ_s: the standard deviation that independent measurement noise of std (n,) [per state
    component] gives s = Σ c_i ỹ^(i): √(Σ c_i² σ_i²) (n = 2: √(σ_y'² + λ² σ_y²))."""
    return float(np.sqrt(np.sum((surface_coefficients(order, lam) * np.asarray(std, dtype=float)) ** 2)))


def sliding_terms(coeffs: np.ndarray, x: np.ndarray, ref: np.ndarray) -> tuple[float, float, float]:
    """(s, ṡ_r, ỹ) for state x (n,) and reference ref (n+1,).

    s = sum_i c_i ỹ^(i);  ṡ_r = y_d^(n) + sum_{i>=1} c_{i-1} ỹ^(i).
    Written as scalar loops so the same code also compiles with numba
    (adaptive_mj.plants.one_dof_kernel) for MuJoCo's native control callback.
    """
    n: int = coeffs.shape[0]
    s = 0.0
    s_r_dot = ref[n]
    for i in range(n):
        e_i = ref[i] - x[i]
        s += coeffs[i] * e_i
        if i > 0:
            s_r_dot += coeffs[i - 1] * e_i
    return s, s_r_dot, ref[0] - x[0]


@dataclass(frozen=True)
class SlidingGains(Gains):
    """The sliding laws' scalar gains and switches, by name: what `sliding_law_values` reads of them.

    k: gain on s [u per unit of s]; dz_width: the dead-zone's width [unit of its signal] (0: none), on |s|
    when dz_on_s, else on |ỹ| (common.dead_zone_open); K, boundary_layer: the robust term K sat(s/Φ)
    (K = 0: none); sigma, e_mod: the leakage (common.modify_rate); sat_lo, sat_hi: the actuator's limits
    [u] for saturation-aware adaptation, which is on when freeze; adapt: the estimates move (False for the
    baselines). The Python path passes this object; the compiled callback (adaptive_mj.plants.one_dof_kernel) reads
    the same names as fields of a SLIDING_GAINS record (`record()`), through its address."""

    k: float
    dz_width: float
    K: float
    boundary_layer: float
    sigma: float
    e_mod: float
    sat_lo: float
    sat_hi: float
    adapt: bool
    dz_on_s: bool
    freeze: bool


SLIDING_GAINS = record_dtype(SlidingGains)


class SlidingArrays(NamedTuple):
    """The sliding laws' arrays, by name (a NamedTuple: numba passes it to compiled code as it is).

    coeffs (n,): the surface's coefficients (surface_coefficients); gamma (n_theta,): the adaptation
    gains; theta0 (n_theta,): the prior the leakage pulls toward; lower, upper (n_theta,): the projection's
    box (±inf where free)."""

    coeffs: np.ndarray
    gamma: np.ndarray
    theta0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray


def sliding_law(x, ref, theta, gains: SlidingGains, arrays: SlidingArrays, form: ModelForm, rate):
    """One evaluation of the sliding laws (adaptive, fixed nominal, robust), as plain array code.

    x (n,), ref (n+1,), theta (n_theta,) = [d̂, p̂...]; gains: the scalar gains and switches
    (SlidingGains: k on s; adapt: estimates move (False for the baselines); the dead-zone: adaptation off
    while |s| (dz_on_s) or |ỹ| < dz_width (common.dead_zone_open); K, boundary_layer: the robust term
    K sat(s/Phi) (K = 0: none); sigma, e_mod: the leakage toward theta0 (common.modify_rate); freeze:
    saturation-aware adaptation, no adaptation while u lies outside the actuator's [sat_lo, sat_hi] (the
    1-DOF case of Slotine–Li's per-joint rule)); arrays: coeffs (n,) surface coefficients, gamma (n_theta,)
    adaptation gains, theta0, and the projection's box lower, upper (SlidingArrays); form: the plant's
    ModelForm (phi, f, h evaluated at x). Writes θ̂' into rate (n_theta,) and returns (u, s, ṡ_r):

        u = h^-1 (d̂ ṡ_r - f - phi p̂ + k s [+ K sat(s/Phi)])
        d̂' = ṡ_r s / gamma_d,   p̂' = -phi^T s / gamma_p   [- (σ + ν|s|)(θ̂ - θ₀)/γ, projected]

    The Python laws below call it; adaptive_mj.plants.one_dof_kernel compiles sliding_law_values, its body.
    """
    return sliding_law_values(x, ref, theta, gains, arrays, form.phi(x), form.f(x), form.h(x), rate)


def sliding_law_values(x, ref, theta, gains, arrays, phi, f, h, rate):
    """sliding_law with the regressor's values at x: phi (n_p,), f, h (floats), not the form's functions
    (the compiled callback evaluates the plant's functions itself and calls this, with gains a
    SLIDING_GAINS record: the same names, read as fields)."""
    s, s_r_dot, y_tilde = sliding_terms(arrays.coeffs, x, ref)
    acc = theta[0] * s_r_dot - f + gains.k * s
    for j in range(phi.shape[0]):
        acc -= phi[j] * theta[j + 1]
    if gains.K > 0.0:
        z = s / gains.boundary_layer
        acc += gains.K * min(1.0, max(-1.0, z))
    u = acc / h
    signal = s if gains.dz_on_s else y_tilde
    gamma = arrays.gamma
    if gains.adapt and dead_zone_open(signal, gains.dz_width) and not (gains.freeze and (u < gains.sat_lo or
                                                                                          u > gains.sat_hi)):
        rate[0] = s_r_dot * s / gamma[0]
        for j in range(phi.shape[0]):
            rate[j + 1] = -phi[j] * s / gamma[j + 1]
    else:
        for j in range(rate.shape[0]):
            rate[j] = 0.0
    if gains.adapt:  # leakage acts inside the dead-zone too; projection always
        modify_rate(rate, theta, abs(s), gains.sigma, gains.e_mod, arrays.theta0, gamma, arrays.lower, arrays.upper)
    return u, s, s_r_dot


def _check_gains(form: ModelForm, lam: float, k: float) -> None:
    if form.d_name is None:
        raise ValueError("sliding laws need a form with an unknown leading coefficient d")
    if not (math.isfinite(lam) and lam > 0):
        raise ValueError(f"lambda must be finite and > 0, got {lam}")
    if not (math.isfinite(k) and k >= 0):
        raise ValueError(f"k must be finite and >= 0, got {k}")


def sliding_kernel(x, r, th, g, a, lower, upper, rate):
    """A sliding law as the chunk engine compiles it (laws.kernel's signature: sliding_law_values with φ, f, h of
    the law's form); g a SLIDING_GAINS record, a = [the surface's coefficients (n), Γ, θ₀] (laws.kernel
    .form_arrays)."""
    coeffs, gamma, theta0, _ = form_arrays(a, x.shape[0], th.shape[0])
    u, s, _ = sliding_law_values(x, r, th, g, SlidingArrays(coeffs, gamma, theta0, lower, upper), phi_fn(x),
                                 f_fn(x), h_fn(x), rate)
    return u, s


class _SlidingBase(Law):
    """What the three sliding laws share: the surface, and the call into `sliding_law`."""

    adapt = True
    native = True  # adaptive_mj.plants.one_dof_kernel compiles sliding_law

    def __init__(self, form: ModelForm, *, lam: float, k: float):
        _check_gains(form, lam, k)
        self.form = form
        self.order = form.order
        self.names = form.names
        self.lam = float(lam)
        self.k = float(k)
        self._coeffs = surface_coefficients(form.order, self.lam)
        self.gamma = np.ones(len(self.names))
        self.dead_zone: DeadZone | None = None
        self.K = 0.0
        self.boundary_layer = 1.0
        self.modification = NO_MODIFICATION
        self.saturation: tuple[float, float] | None = None  # (lo, hi) [control units]: saturation-aware adaptation
        self._fixed: tuple[SlidingGains, SlidingArrays] | None = None

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) of the projection, or None (common.Modification.box)."""
        return self.modification.box(len(self.names))

    def gains(self) -> SlidingGains:
        """The law's scalar gains and switches, by name (what sliding_law reads of them)."""
        dz = self.dead_zone
        sigma, e_mod, _, _, _ = self.modification.arrays(len(self.names))
        return SlidingGains(k=self.k, dz_width=0.0 if dz is None else dz.width, K=self.K,
                            boundary_layer=self.boundary_layer, sigma=sigma, e_mod=e_mod,
                            sat_lo=-math.inf if self.saturation is None else float(self.saturation[0]),
                            sat_hi=math.inf if self.saturation is None else float(self.saturation[1]),
                            adapt=self.adapt, dz_on_s=dz is None or dz.on is DeadZoneOn.S,
                            freeze=self.saturation is not None)

    def arrays(self) -> SlidingArrays:
        """The law's arrays, by name (what sliding_law reads of them)."""
        _, _, theta0, lower, upper = self.modification.arrays(len(self.names))
        return SlidingArrays(coeffs=self._coeffs, gamma=self.gamma, theta0=theta0, lower=lower, upper=upper)

    def native_params(self) -> dict[str, Any]:
        """What the native (numba) callback takes: "gains", the SLIDING_GAINS record of `gains()` (read by
        name through its address), and the arrays of `arrays()` by their names."""
        return {"gains": self.gains().record(), **self.arrays()._asdict()}

    def chunk_kernel(self, order: int) -> LawKernel | None:
        """Its compiled form (laws.kernel: sliding_kernel over `native_params`) on a plant of its form's order;
        None on another, or when its `native` is off."""
        if not self.native or self.form.order != order:
            return None
        p = self.native_params()
        return LawKernel(sliding_kernel, SLIDING_GAINS, p["gains"],
                         form_law_arrays(f64(p["coeffs"]).reshape(-1)[:self.order], p["gamma"], p["theta0"]),
                         f64(p["lower"]), f64(p["upper"]), self.form, what="a sliding law")

    def feedback(self) -> SurfaceFeedback:
        """k on s, λ, and the gain of the linearised velocity feedback k + K/Φ (robust sliding) with the
        (n - 1) λ the surface adds to the loop's fastest mode (the pre-flight check)."""
        effective = self.k + (self.K / self.boundary_layer if self.K > 0 else 0.0)
        keys = "law.k" + (" (+ law.K / law.boundary_layer)" if self.K > 0 else "")
        return SurfaceFeedback(k=self.k, lam=self.lam, effective=effective, surface_rate=(self.order - 1) * self.lam,
                               keys=keys)

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        if self._fixed is None:  # the gains, once (they are fixed after construction)
            self._fixed = (self.gains(), self.arrays())
        rate = np.empty(len(self.names))
        u, s, s_r_dot = sliding_law(x, ref, theta_hat, *self._fixed, self.form, rate)
        return LawStep(u, rate, s, s_r_dot)


class SlidingAdaptiveLaw(_SlidingBase):
    """The lecture's adaptive sliding law of order n = form.order, optionally with a dead-zone.

    lam: lambda [1/s] of the surface; k: gain on s [u per unit of s];
    gamma: scalar or (n_theta,) adaptation "stiffness" (estimates move at 1/gamma);
    dead_zone: None, or a DeadZone (default test |s| < eps, the lecture's formula);
    modification: σ/e-modification and projection (common.Modification), or None;
    saturation: the actuator's (lo, hi) for saturation-aware adaptation (no adaptation while the law's
    u is outside it), or None (the lecture's law).
    """

    def __init__(self, form: ModelForm, *, lam: float, k: float, gamma, dead_zone: DeadZone | None = None,
                 modification: Modification | None = None, saturation: tuple[float, float] | None = None):
        super().__init__(form, lam=lam, k=k)
        self.gamma = as_gamma(gamma, len(self.names))
        self.dead_zone = dead_zone
        self.modification = modification or NO_MODIFICATION
        self.saturation = None if saturation is None else (float(saturation[0]), float(saturation[1]))

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """V = ½ d s² + ½ sum_i gamma_i (θ̂_i - θ_i)².  s: (N,), theta*: (N, n_theta)."""
        s = np.asarray(s, dtype=float)
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        d = np.asarray(theta, dtype=float)[..., 0]
        return 0.5 * d * s**2 + 0.5 * np.sum(self.gamma * err**2, axis=-1)


class FixedNominalLaw(_SlidingBase):
    """Baseline: the same control structure with theta_hat held at its initial (nominal) value."""

    adapt = False

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
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


# --- the law kinds: their keys (law.*), read from a scenario, and their builders ----------------------
LAMBDA = Key("lambda", "number", unit="1/s", bounds="> 0", required=True,
             doc="λ of the surface s = (d/dt + λ)^(n−1) ỹ")
K_GAIN = Key("k", "number", unit="u per unit of s", bounds=">= 0", required=True, doc="gain on s")
SWITCHING = (Key("K", "number", unit="u", bounds=">= 0", required=True, doc="switching gain of u = … + K sat(s/Φ)"),
             Key("boundary_layer", "number", unit="unit of s", bounds="> 0", required=True,
                 doc="Φ, the boundary layer's width"))


def model_law_keys(*, adaptive: bool, surface: bool = True, switching: bool = False) -> tuple[Key, ...]:
    """The keys `read_model_law` reads, in its order (adaptive: law.gamma is required; surface: law.lambda;
    switching: law.K and law.boundary_layer)."""
    gamma = shared.GAMMA_REQUIRED if adaptive else shared.GAMMA
    return (shared.KIND, shared.ORDER, *((LAMBDA,) if surface else ()), K_GAIN, gamma, shared.DEAD_ZONE,
            shared.INITIAL_ESTIMATES, shared.NOMINAL, *(SWITCHING if switching else ()), *shared.ROBUST,
            shared.SATURATION)


def read_model_law(t: Table, kind: str, plant: PlantSpec, order: int, *, adaptive: bool, surface: bool = True,
                   switching: bool = False, composite: bool = False) -> LawSpec:
    """The [law] keys of a law of the model form (a sliding law; surface=False: the first-order law): adaptive,
    law.gamma is required and the robust modifications are kept; else law.nominal or law.initial_estimates is;
    switching: law.K and law.boundary_layer (required); composite: law.composite and law.saturation = "freeze"
    are taken."""
    law_order = shared.read_order(t, plant, order)
    lam = t.number("lambda", gt=0) if surface else None
    k = t.number("k", ge=0)
    gamma = shared.read_gamma(t)
    if adaptive:
        shared.required(t, gamma, "law.gamma", kind)
    dead_zone = shared.read_dead_zone(t)
    initial = shared.read_estimates(t, "initial_estimates")
    nominal = shared.read_estimates(t, "nominal")
    if not adaptive and nominal is None and initial is None:
        raise ScenarioError(f"{t.where}: law.nominal (or law.initial_estimates) is required for law.kind = {kind!r}")
    K = t.number("K", None, ge=0) if switching else None
    phi = t.number("boundary_layer", None, gt=0) if switching else None
    if switching and (K is None or phi is None):
        raise ScenarioError(f"{t.where}: law.K and law.boundary_layer are required for law.kind = {kind!r}")
    robust = shared.read_robust(t, kind, adaptive=adaptive, composite=composite, presets=())
    saturation = shared.read_saturation(t)
    if saturation != "ignore" and (not composite or robust.composite_gain is not None):
        raise t.fail("saturation", "'ignore' except for law.kind = 'sliding_adaptive' (without law.composite)",
                     saturation)
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=lam, k=k, gamma=gamma, dead_zone=dead_zone,
                   initial_estimates=initial, nominal=nominal, K=K, boundary_layer=phi, robust=robust,
                   saturation=saturation)


def _read_sliding_adaptive(t: Table, kind: str, plant: PlantSpec, order: int) -> LawSpec:
    return read_model_law(t, kind, plant, order, adaptive=True, composite=True)


def _read_fixed_nominal(t: Table, kind: str, plant: PlantSpec, order: int) -> LawSpec:
    return read_model_law(t, kind, plant, order, adaptive=False)


def _read_robust_sliding(t: Table, kind: str, plant: PlantSpec, order: int) -> LawSpec:
    return read_model_law(t, kind, plant, order, adaptive=False, switching=True)


def _build_sliding_adaptive(ctx: BuildContext) -> Law:
    """SlidingAdaptiveLaw, or with law.composite the CompositeSlidingLaw (adaptive_mj.laws.composite)."""
    L, form = ctx.law, ctx.model_form()
    assert L.lam is not None  # law.lambda is required for this law kind (read_model_law)
    if L.robust.composite_gain is not None:
        from adaptive_mj.laws.composite import CompositeSlidingLaw

        assert L.robust.composite_filter is not None  # law.composite gives gain and filter together
        return CompositeSlidingLaw(form, lam=L.lam, k=L.k, gamma=ctx.gamma(form.names),
                                   kappa=L.robust.composite_gain, filter_rate=L.robust.composite_filter,
                                   dead_zone=ctx.dead_zone(), modification=ctx.modification)
    return SlidingAdaptiveLaw(form, lam=L.lam, k=L.k, gamma=ctx.gamma(form.names), dead_zone=ctx.dead_zone(),
                              modification=ctx.modification,
                              saturation=ctx.saturation() if L.saturation == "freeze" else None)


def _build_fixed_nominal(ctx: BuildContext) -> Law:
    assert ctx.law.lam is not None  # law.lambda is required for this law kind (read_model_law)
    return FixedNominalLaw(ctx.model_form(), lam=ctx.law.lam, k=ctx.law.k)


def _build_robust_sliding(ctx: BuildContext) -> Law:
    L = ctx.law
    # law.lambda, law.K and law.boundary_layer are required for this law kind (read_model_law)
    assert L.lam is not None and L.K is not None and L.boundary_layer is not None
    return RobustSlidingLaw(ctx.model_form(), lam=L.lam, k=L.k, K=L.K, boundary_layer=L.boundary_layer)


#: these law kinds, registered (adaptive_mj.laws.kinds): law.kind = "sliding_adaptive", "fixed_nominal",
#: "robust_sliding"
SLIDING_ADAPTIVE = register(LawKind(
    "sliding_adaptive", frozenset({Form.MODEL}), True,
    "the lecture's sliding-surface adaptive law of order n (with its modifications)",
    keys=model_law_keys(adaptive=True), read=_read_sliding_adaptive, build=_build_sliding_adaptive, module=__name__,
    example=("heave_tracking", ())))
FIXED_NOMINAL = register(LawKind(
    "fixed_nominal", frozenset({Form.MODEL}), False,
    "the sliding law with the estimates frozen at law.nominal (baseline)",
    keys=model_law_keys(adaptive=False), read=_read_fixed_nominal, build=_build_fixed_nominal, module=__name__,
    example=("heave_tracking", ("law.kind='fixed_nominal'",))))
ROBUST_SLIDING = register(LawKind(
    "robust_sliding", frozenset({Form.MODEL}), False,
    "sliding control with a boundary layer, K sat(s/phi), no adaptation (baseline)",
    keys=model_law_keys(adaptive=False, switching=True), read=_read_robust_sliding, build=_build_robust_sliding,
    module=__name__,
    example=("heave_tracking", ("law.kind='robust_sliding'", "law.K=10.0", "law.boundary_layer=0.05"))))

"""Direct model-reference adaptive control (MRAC) of a plant of relative degree one in its
control input, with the Lyapunov rule and, for contrast, the MIT rule (docs/THEORY.md, "MRAC").

The plant, in the law's coordinates (x = [y, y', ..., y^(n-1)], n = 1 or 2):

    y^(n) = aᵀx + wᵀψ(x) + b u          a (n,), w and b unknown, sign(b) known;
                                         ψ: the matched nonlinear terms, or none

the reference model, a stable polynomial s^n + α_{n-1} s^{n-1} + ... + α_0 and a gain β:

    y_m^(n) = -αᵀx_m + β r               x_m = [y_m, ..., y_m^(n-1)]

The reference supplies x_m and y_m^(n) (ref = [y_m, ..., y_m^(n)], reference.kind =
"reference_model" filters a command r through this model in closed form); the law recovers
r = (y_m^(n) + αᵀx_m) / β. The control and the gains (θ̂ = [k_x (n), k_r, k_ψ (len ψ)]):

    u = θ̂ᵀω,   ω = [x; r; ψ(x)]
    e = x - x_m,  s = eᵀP b_n  (n = 1: s = e; n = 2: AᵀP + PA = -I, A the model's companion matrix)
    Lyapunov rule:  θ̂' = -γ sign(b) ω s
    MIT rule:       θ̂' = -γ sign(b) ω_f e₁,  ω_f = α_0/(p + α_0) ω (n = 1): the sensitivity
                    ∂e/∂θ̂ approximated by the filtered regressor (a filter state of the law)

The ideal gains θ* = [-(α + a)/b, β/b, -w/b] make the closed loop the reference model, and
e' = A e + b_n b θ̃ᵀω (θ̃ = θ̂ - θ*). With V = eᵀPe·c + |b| θ̃ᵀΓ⁻¹θ̃ (n = 1: V = ½e² + |b|/(2γ)θ̃²)
the Lyapunov rule gives V' = -α_0 e² ≤ 0 (n = 1); the MIT rule has no such V.

The gains γ here are adaptation *rates* (the textbooks' Γ), unlike the lecture laws' stiffnesses
(1/γ): Nguyen's γ = 2 and 2.9 and Rohrs' γ = 1 are written as published. The modifications
(laws.common.Modification) are applied with Γ: θ̂' -= (σ + ν|s|) Γ (θ̂ - θ₀), projection the same.

Plain array code; no mujoco. The law's arithmetic is mrac_regressor and mrac_values, plain loops that MracLaw
calls in Python and adaptive_mj.sim.native_chunk compiles: on the linear plant (adaptive_mj.plants.linear) the
Lyapunov rule runs compiled, bit for bit the Python path's rows, and so it does with matched terms ψ (the
wing-rock plant, the stirred tank: mrac_psi_kernel, the plant's ψ compiled in); the MIT rule (its filter) runs on
the Python path.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from adaptive_mj.keys import Key, Table
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws.common import (NO_MODIFICATION, DeadZone, DeadZoneOn, Gains, LawStep, Modification, as_gamma,
                                     dead_zone_open, modify_rate, record_dtype)
from adaptive_mj.laws.kernel import LawKernel, f64, psi_fn
from adaptive_mj.laws.kinds import BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import Box, Law
from adaptive_mj.specs import LawSpec, MracSpec, PlantSpec


class Rule(enum.Enum):
    LYAPUNOV = "lyapunov"
    MIT = "mit"


def gain_names(order: int, psi_names: tuple[str, ...] = ()) -> tuple[str, ...]:
    """θ names: ("k_y", "k_r") for n = 1; ("k_x1", "k_x2", "k_r", "k_<ψ name>"...) for n = 2."""
    state = ("k_y",) if order == 1 else tuple(f"k_x{i + 1}" for i in range(order))
    return state + ("k_r",) + tuple(f"k_{p}" for p in psi_names)


def ideal_gains(a, b: float, w, alpha, beta: float) -> np.ndarray:
    """θ* = [-(α + a)/b, β/b, -w/b]: the gains that make the plant y^(n) = aᵀx + wᵀψ + b u the
    reference model. a, alpha (n,); w (len ψ,); b, beta scalars."""
    a, alpha, w = (np.asarray(v, dtype=float).reshape(-1) for v in (a, alpha, w))
    return np.concatenate([-(alpha + a) / b, [beta / b], -w / b])


def lyapunov_matrix(alpha) -> np.ndarray:
    """P (n, n) with AᵀP + PA = -I for the companion matrix A of s^n + α_{n-1}s^{n-1} + ... + α_0
    (solved through the Kronecker form: plain numpy)."""
    alpha = np.asarray(alpha, dtype=float)
    n = alpha.shape[0]
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1, :] = -alpha
    eye = np.eye(n)
    K = np.kron(eye, A.T) + np.kron(A.T, eye)
    P = np.linalg.solve(K, -eye.reshape(-1)).reshape(n, n)
    return 0.5 * (P + P.T)


_NO_PSI = np.zeros(0)


@dataclass
class MracGains(Gains):
    """The MRAC law's scalars, by name (common.record_dtype: the compiled analytic loop reads them as a record).
    beta: the reference model's gain on r; sign_b: ±1; always: no dead-zone (adapt whatever s is, NaN too);
    dz_width: the dead-zone's width [unit of y]; dz_on_s: the dead-zone on |s| (else on |e_1|);
    sigma [1/s], e_mod [1/(s · unit of y)]: the leakage (common.modify_rate)."""

    beta: float
    sign_b: float
    always: bool
    dz_width: float
    dz_on_s: bool
    sigma: float
    e_mod: float


MRAC_GAINS = record_dtype(MracGains)


def mrac_regressor(x, ref, alpha, beta, psi, omega):
    """ω = [x_1..x_n; r; ψ] into omega (n_theta,) in place, and r = (y_m^(n) + αᵀx_m) / β returned [unit of r].
    x: (≥ n,) the measured state; ref: (n+1,) [y_m, ..., y_m^(n)]; alpha: (n,); psi: (len ψ,) ψ(x), evaluated
    by the caller. Plain loops (αᵀx_m summed from 0 in order, as numpy's dot of a few entries does, bit for
    bit): MracLaw calls it in Python, adaptive_mj.sim.native_chunk compiled."""
    n = alpha.shape[0]
    acc = 0.0
    for i in range(n):
        acc += alpha[i] * ref[i]
    r = (ref[n] + acc) / beta
    for i in range(n):
        omega[i] = x[i]
    omega[n] = r
    for j in range(psi.shape[0]):
        omega[n + 1 + j] = psi[j]
    return r


def mrac_values(x, ref, theta, omega, omega_f, pb, gamma, inv_gamma, sign_b, mit, always, dz_width, dz_on_s,
                sigma, e_mod, theta0, lower, upper, rate):
    """One evaluation of the law (module docstring): returns (u, s) and writes θ̂' into rate (n_theta,).

    u = θ̂ᵀω; e = x - x_m; s = eᵀP b_n (pb (n,)); Lyapunov rule: rate = -sign_b Γ ω s; MIT rule (mit): rate =
    -sign_b Γ ω_f e_1 (omega_f (n_theta,), the filtered regressor). Adaptation is on while `always` (no
    dead-zone) or dead_zone_open(s, or e_1 without dz_on_s, dz_width); then the leakage and the projection's
    tangent cone (common.modify_rate with 1/Γ = inv_gamma as the stiffness). theta: (n_theta,) the stage estimate;
    gamma: (n_theta,) rates; theta0, lower, upper: (n_theta,) the modification's arrays. Plain loops, every dot
    summed from 0 in order (numpy's dot of a few entries gives the same bits): MracLaw calls it in Python and
    adaptive_mj.sim.native_chunk compiles it."""
    n = pb.shape[0]
    u = 0.0
    for i in range(theta.shape[0]):
        u += theta[i] * omega[i]
    s = 0.0
    for i in range(n):
        s += (x[i] - ref[i]) * pb[i]
    e0 = x[0] - ref[0]
    signal = e0 if mit else s
    if always or dead_zone_open(s if dz_on_s else e0, dz_width):
        for i in range(rate.shape[0]):
            rate[i] = -sign_b * gamma[i] * (omega_f[i] if mit else omega[i]) * signal
    else:
        for i in range(rate.shape[0]):
            rate[i] = 0.0
    modify_rate(rate, theta, abs(s), sigma, e_mod, theta0, inv_gamma, lower, upper)
    return u, s


def mrac_kernel(x, r, th, g, a, lower, upper, rate):
    """MRAC with the Lyapunov rule and no ψ as the chunk engine compiles it (laws.kernel's signature; MracLaw's
    arithmetic: mrac_regressor, mrac_values); g an MRAC_GAINS record; a = [α (n), P b_n (n), Γ, 1/Γ, θ₀, ω
    (scratch), zeros (n_theta each)]; s as the law logs it, -eᵀP b_n."""
    n, nth = x.shape[0], th.shape[0]
    alpha, pb = a[0:n], a[n:2 * n]
    o = 2 * n
    gamma, inv_gamma, theta0 = a[o:o + nth], a[o + nth:o + 2 * nth], a[o + 2 * nth:o + 3 * nth]
    omega, dummy = a[o + 3 * nth:o + 4 * nth], a[o + 4 * nth:o + 5 * nth]
    mrac_regressor(x, r, alpha, g.beta, dummy[:0], omega)
    u, s = mrac_values(x, r, th, omega, dummy, pb, gamma, inv_gamma, g.sign_b, False, g.always, g.dz_width,
                       g.dz_on_s, g.sigma, g.e_mod, theta0, lower, upper, rate)
    return u, -s


def mrac_psi_kernel(x, r, th, g, a, lower, upper, rate):
    """mrac_kernel with the plant's matched nonlinear terms ψ(x) in the regressor (ω = [x; r; ψ(x)]; psi_fn: the
    law's ψ, bound per variant, plain array code): MRAC on the wing-rock plant and the stirred tank, compiled."""
    n, nth = x.shape[0], th.shape[0]
    alpha, pb = a[0:n], a[n:2 * n]
    o = 2 * n
    gamma, inv_gamma, theta0 = a[o:o + nth], a[o + nth:o + 2 * nth], a[o + 2 * nth:o + 3 * nth]
    omega, dummy = a[o + 3 * nth:o + 4 * nth], a[o + 4 * nth:o + 5 * nth]
    mrac_regressor(x, r, alpha, g.beta, psi_fn(x), omega)
    u, s = mrac_values(x, r, th, omega, dummy, pb, gamma, inv_gamma, g.sign_b, False, g.always, g.dz_width,
                       g.dz_on_s, g.sigma, g.e_mod, theta0, lower, upper, rate)
    return u, -s


class MracLaw(Law):
    """Direct MRAC (see the module docstring).

    order: n (1 or 2); alpha: (n,) the reference model's polynomial [α_0, ..., α_{n-1}] [1/s^k];
    beta: its gain on r; gamma: (n_theta,) or scalar adaptation rates; sign_b: ±1; rule: Rule;
    psi: x -> (n_psi,) matched nonlinear terms and psi_names; b_abs: |b| of the plant (only for V,
    like every law's V uses the true θ); dead_zone on |s|; modification: σ/e-mod and projection.
    """

    def __init__(self, *, order: int, alpha, beta: float, gamma, sign_b: float = 1.0, rule: Rule = Rule.LYAPUNOV,
                 psi: Callable[[np.ndarray], np.ndarray] | None = None, psi_names: tuple[str, ...] = (),
                 b_abs: float = math.nan, dead_zone: DeadZone | None = None,
                 modification: Modification | None = None):
        if order not in (1, 2):
            raise ValueError(f"MRAC is written for order 1 or 2, got {order}")
        self.alpha = np.asarray(alpha, dtype=float).reshape(-1)
        if self.alpha.shape != (order,) or not np.all(np.isfinite(self.alpha)) or np.any(self.alpha <= 0):
            raise ValueError(f"the reference model needs {order} coefficients > 0 (a stable polynomial), "
                             f"got {self.alpha.tolist()}")
        if not (math.isfinite(beta) and beta != 0):
            raise ValueError(f"the reference model's gain must be finite and non-zero, got {beta}")
        if sign_b not in (1.0, -1.0):
            raise ValueError(f"sign_b must be 1 or -1, got {sign_b}")
        self.order = order
        self.names = gain_names(order, tuple(psi_names))
        self.beta, self.sign_b, self.rule = float(beta), float(sign_b), Rule(rule)
        if self.rule is Rule.MIT and order != 1:
            raise ValueError("the MIT rule is written for order 1 (its sensitivity filter is α_0/(p + α_0))")
        self.psi, self.psi_names = psi, tuple(psi_names)
        self.gamma = as_gamma(gamma, len(self.names))
        self.b_abs = float(b_abs)
        self.dead_zone = dead_zone
        self.modification = modification or NO_MODIFICATION
        self._mod = self.modification.arrays(len(self.names))
        # the modifications divide by a stiffness: Γ is a rate here, so 1/Γ is passed to them
        self._inv_gamma = 1.0 / self.gamma
        # the scalars mrac_values takes, made once: the Python path reads them here, the compiled loop as a record
        self._scalars = MracGains(beta=self.beta, sign_b=self.sign_b, always=dead_zone is None,
                                  dz_width=0.0 if dead_zone is None else dead_zone.width,
                                  dz_on_s=dead_zone is None or dead_zone.on is DeadZoneOn.S,
                                  sigma=self._mod[0], e_mod=self._mod[1])
        self.pb = np.array([1.0]) if order == 1 else lyapunov_matrix(self.alpha)[:, -1]  # P b_n
        self.has_filters = self.rule is Rule.MIT
        self.omega_f = np.zeros(len(self.names))  # MIT: the filtered regressor, at the step's start
        self._stage_omegas: list[np.ndarray] = []

    @property
    def bounds(self) -> Box | None:
        return self.modification.box(len(self.names))

    def regressor(self, x, ref) -> tuple[np.ndarray, float]:
        """(ω, r): ω = [x; r; ψ(x)] (n_theta,), r recovered from the reference model."""
        omega = np.empty(len(self.names))
        psi = np.asarray(self.psi(x), dtype=float) if self.psi is not None else _NO_PSI
        r = mrac_regressor(np.asarray(x, dtype=float), np.asarray(ref, dtype=float), self.alpha, self.beta, psi, omega)
        return omega, r

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        omega, _ = self.regressor(x, ref)
        mit = self.rule is Rule.MIT
        if mit:
            self._stage_omegas.append(omega)
        rate = np.empty(len(self.names))
        _, _, theta0, lower, upper = self._mod
        g = self._scalars
        u, s = mrac_values(np.asarray(x, dtype=float), np.asarray(ref, dtype=float), theta_hat, omega, self.omega_f,
                           self.pb, self.gamma, self._inv_gamma, g.sign_b, mit, g.always, g.dz_width, g.dz_on_s,
                           g.sigma, g.e_mod, theta0, lower, upper, rate)
        return LawStep(u, rate, -s, float(ref[self.order]))

    def native_arrays(self) -> dict[str, Any]:
        """What the analytic chunk engine (adaptive_mj.sim.native_chunk) takes of this law, by name: its
        scalars as one MRAC_GAINS record ("gains") and its arrays: alpha (n,), pb (n,), gamma and 1/gamma,
        theta0, lower, upper (n_theta,). The Lyapunov rule without ψ only (`compiled_form`)."""
        _, _, theta0, lower, upper = self._mod
        return {"gains": self._scalars.record(), "alpha": self.alpha, "pb": self.pb, "gamma": self.gamma,
                "inv_gamma": self._inv_gamma,
                "theta0": theta0, "lower": lower, "upper": upper}

    def chunk_kernel(self, order: int) -> LawKernel | None:
        """Its compiled form (laws.kernel: mrac_kernel over `native_arrays`) where it has one (`compiled_form`);
        None otherwise (the Python path). MRAC reads no model form: any plant order."""
        if not self.compiled_form:
            return None
        p = self.native_arrays()
        arrays = np.concatenate([f64(p[k]) for k in ("alpha", "pb", "gamma", "inv_gamma", "theta0")]
                                + [np.zeros(2 * len(self.names))])
        if self.psi is not None:  # its matched terms compiled in (their function: plain array code)
            return LawKernel(mrac_psi_kernel, MRAC_GAINS, p["gains"], arrays, f64(p["lower"]), f64(p["upper"]),
                             what="MRAC, the Lyapunov rule, matched terms " + ", ".join(self.psi_names),
                             psi=self.psi)
        return LawKernel(mrac_kernel, MRAC_GAINS, p["gains"], arrays, f64(p["lower"]), f64(p["upper"]),
                         what="MRAC, the Lyapunov rule")

    @property
    def compiled_form(self) -> bool:
        """Whether the compiled analytic loop runs this law: the Lyapunov rule (the MIT rule's filter is stepped in
        Python), no physically consistent projection; matched nonlinear terms ψ are compiled in (the plant's ψ
        function is plain array code: mrac_psi_kernel)."""
        return self.rule is Rule.LYAPUNOV and not self.modification.bodies

    # --- the MIT rule's sensitivity filter (loop: law.has_filters) -----------------------------
    def reset(self) -> None:
        self.omega_f = np.zeros(len(self.names))
        self._stage_omegas = []

    def step_begins(self, x) -> None:
        self._stage_omegas = []

    def step_ends(self, xs, us, weights, h: float) -> None:
        """ω_f' = α_0 (ω - ω_f) over the step, ω held at the integrator-weighted mean of its stages:
        ω_f ← e^{-α_0 h} ω_f + (1 - e^{-α_0 h}) Σ b_i ω_i (exact for that held input)."""
        if not self._stage_omegas:
            return
        mean = sum(w * o for w, o in zip(weights, self._stage_omegas, strict=True))
        decay = math.exp(-self.alpha[0] * h)
        self.omega_f = decay * self.omega_f + (1.0 - decay) * mean

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """n = 1, Lyapunov rule: V = ½ e² + |b|/2 Σ θ̃_i²/γ_i (s logged as -e). Otherwise NaN: the
        MIT rule has no Lyapunov function, and for n = 2 V needs the whole e, not s."""
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        s = np.asarray(s, dtype=float)
        if self.order != 1 or self.rule is not Rule.LYAPUNOV:
            return np.full(s.shape[:1] if s.ndim else (), math.nan)
        return 0.5 * s**2 + 0.5 * self.b_abs * np.sum(err**2 / self.gamma, axis=-1)


# --- the law kind: its keys (law.*), read from a scenario, and its builder -----------------------------
OWN_KEYS = (
    Key("model", "array of n numbers", unit="1/s^k", bounds="> 0", required=True,
        doc="the reference model's polynomial [α_0, …, α_{n−1}] of s^n + … + α_0"),
    Key("model_gain", "number", bounds="!= 0", doc="β in y_m^(n) + … + α_0 y_m = β r (default α_0: unit DC gain)"),
    Key("rule", "string", default="lyapunov", bounds="one of 'lyapunov', 'mit'", doc="the update ('mit': n = 1)"),
)


def _read(t: Table, kind: str, plant: PlantSpec, order: int) -> LawSpec:
    """law.model, law.model_gain, law.rule, law.gamma (rates, required), law.dead_zone, law.initial_estimates and
    the robust modifications (no law.nominal: MRAC has no baseline)."""
    law_order = shared.read_order(t, plant, order)
    alpha = t.numbers("model", length=order)
    if any(a <= 0 for a in alpha):
        raise t.fail("model", f"{order} coefficient(s) > 0 (a stable reference model)", list(alpha))
    beta = t.number("model_gain", alpha[0])
    if beta == 0:
        raise t.fail("model_gain", "non-zero", beta)
    rule = t.string("rule", "lyapunov", choices=tuple(r.value for r in Rule))
    if rule == "mit" and order != 1:
        raise t.fail("rule", "'lyapunov' for a law of order 2 (the MIT rule is written for order 1)", rule)
    gamma = shared.read_gamma(t)
    shared.required(t, gamma, "law.gamma", kind)
    dead_zone = shared.read_dead_zone(t)
    initial = shared.read_estimates(t, "initial_estimates")
    robust = shared.read_robust(t, kind, adaptive=True, composite=False, presets=())
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=gamma, dead_zone=dead_zone,
                   initial_estimates=initial, nominal=None, K=None, boundary_layer=None, robust=robust,
                   mrac=MracSpec(alpha=alpha, beta=beta, rule=rule))


def _build(ctx: BuildContext) -> Law:
    """MracLaw on the plant's MRAC state form: the sign and size of its b, its matched nonlinear terms."""
    M, plant = ctx.law.mrac, ctx.mrac_state()
    assert M is not None  # set for law.kind = 'mrac' (_read)
    return MracLaw(order=plant.order, alpha=M.alpha, beta=M.beta, gamma=ctx.gamma(plant.names),
                   sign_b=1.0 if plant.b > 0 else -1.0, rule=Rule(M.rule), psi=plant.psi, psi_names=plant.psi_names,
                   b_abs=abs(plant.b), dead_zone=ctx.dead_zone(), modification=ctx.modification)


#: this law kind, registered (adaptive_mj.laws.kinds): law.kind = "mrac"
KIND = register(LawKind(
    "mrac", frozenset({Form.MRAC_STATE}), True, "model-reference adaptive control (Lyapunov rule or the MIT rule)",
    keys=(shared.KIND, shared.ORDER, *OWN_KEYS, shared.GAMMA_REQUIRED, shared.DEAD_ZONE, shared.INITIAL_ESTIMATES,
          *shared.ROBUST),
    read=_read, build=_build, module=__name__, filters_key="law.rule = 'mit'",
    example=("mrac_time_delay", ())))

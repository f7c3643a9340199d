"""The Slotine–Li adaptive law for an m-joint manipulator, and two baselines.

Plant:  M(q) q̈ + C(q, q̇) q̇ + g(q) + D q̇ = τ,  linear in the parameters π:
        Y(q, q̇, q̇_r, q̈_r) π + τ_known = M q̈_r + C q̇_r + g + D q̇   (C: Christoffel form)

With q̃ = q_d - q (the project's sign for tracking errors), per joint

    s    = q̃' + Λ q̃,         q̇_r = q̇_d + Λ q̃,       q̈_r = q̈_d + Λ q̃'
    τ    = Y π̂ + τ_known + K_D s
    π̂'   = Γ⁻¹ Yᵀ s            (π̃ = π̂ - π)

Then M ṡ + C s + K_D s = -Y π̃, and V = ½ sᵀ M(q) s + ½ π̃ᵀ Γ π̃ has V' = -sᵀ K_D s
(Ṁ - 2C skew). Λ, K_D are scalar or per joint; Γ scalar or per parameter. The
dead-zone stops adaptation while |s| (Euclidean norm) or |q̃| is below its width.
With a common.Modification: π̂' -= (σ + ν‖s‖) Γ⁻¹ (π̂ - π₀), projected onto a box
(per parameter: e.g. masses >= 0; docs/THEORY.md).

Baselines, the same τ with π̂ held at a nominal π_0:
  computed torque:        τ = Y(q, q̇, q̇_r, q̈_r) π_0 + τ_known + K_D s
  PD + gravity:           τ = g_0(q) + K_D s  (Y at q̇ = q̇_r = q̈_r = 0)

The plant hands the law its regressor: ``regressor(v, w, a) -> (Y (m, n_params),
τ_known (m,))`` evaluated at the current configuration, like φ(x) for the 1-DOF laws.
No mujoco here.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.keys import Key, Table, joint_values
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws.common import (NO_MODIFICATION, DeadZone, DeadZoneOn, LawStep, Modification, as_gamma,
                                     Gains, dead_zone_open, modify_rate, record_dtype)
from adaptive_mj.laws.kinds import BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import Box, JointFeedback, Law
from adaptive_mj.specs import LawSpec, PlantSpec


#: law.evaluation: how τ = Y π̂ and Yᵀ s are evaluated (SlotineLiLaw's evaluation)
EVALUATIONS = ("recursive", "regressor")


class Mode(enum.IntEnum):
    ADAPTIVE = 0
    COMPUTED_TORQUE = 1
    PD_GRAVITY = 2


def reference_terms(x, ref, lam, s, qd_r, qdd_r):
    """Fill s, q̇_r, q̈_r (m,) from x (2, m) = [q; q̇] and ref (3, m) = [q_d; q̇_d; q̈_d]."""
    m = s.shape[0]
    for j in range(m):
        e = ref[0, j] - x[0, j]
        de = ref[1, j] - x[1, j]
        s[j] = de + lam[j] * e
        qd_r[j] = ref[1, j] + lam[j] * e
        qdd_r[j] = ref[2, j] + lam[j] * de


@dataclass(frozen=True)
class SlotineLiGains(Gains):
    """Slotine–Li's scalar gains and switches, by name: what `slotine_li_output` (and the compiled callback's
    point, adaptive_mj.plants.manipulator_kernel) read of them.

    mode: Mode (ADAPTIVE, COMPUTED_TORQUE, PD_GRAVITY: where the regressor is evaluated); adapt: the estimates
    move (ADAPTIVE only); dz_width: the dead-zone's width [rad/s on ‖s‖, rad on ‖q̃‖] (0: none), on ‖s‖ when
    dz_on_s, else on ‖q̃‖; sigma, e_mod: the leakage (common.modify_rate); freeze: saturation-aware adaptation.
    The Python path passes this object; the compiled callback reads the same names as fields of a
    SLOTINE_LI_GAINS record (`record()`), through its address."""

    mode: int
    adapt: bool
    dz_width: float
    dz_on_s: bool
    sigma: float
    e_mod: float
    freeze: bool


SLOTINE_LI_GAINS = record_dtype(SlotineLiGains)


class SlotineLiArrays(NamedTuple):
    """Slotine–Li's arrays, by name (a NamedTuple: numba passes it to compiled code as it is). kd (m,): K_D
    [N m s/rad]; gamma (n_params,): Γ; theta0, lower, upper (n_params,): the leakage's prior and the
    projection's box (±inf where free); sat_lo, sat_hi (m,): the torque limits [N m] of saturation-aware
    adaptation (±inf when off)."""

    kd: np.ndarray
    gamma: np.ndarray
    theta0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    sat_lo: np.ndarray
    sat_hi: np.ndarray


def slotine_li_output(Y, tau_known, theta, s, e_norm, gains, arrays, u, rate):
    """τ = Y θ + τ_known + K_D s into u (m,) (unclamped); θ' = Γ⁻¹ Yᵀ s into rate (unless not gains.adapt,
    or the dead-zone signal ‖s‖ (gains.dz_on_s) or ‖q̃‖ = e_norm is below gains.dz_width:
    common.dead_zone_open), then the modifications (common.modify_rate with |s| = ‖s‖) when adapting.
    gains.freeze (saturation-aware adaptation): a joint whose τ_j lies outside its limits [sat_lo_j, sat_hi_j]
    gives no s_j to the rate (θ' = Γ⁻¹ Σ_{j unsaturated} Y_jᵀ s_j). Y (m, n_params), tau_known (m,), theta
    (n_params,), s (m,); gains: SlotineLiGains (or its record); arrays: SlotineLiArrays."""
    m, n = Y.shape[0], Y.shape[1]
    kd, gamma, lo, hi = arrays.kd, arrays.gamma, arrays.sat_lo, arrays.sat_hi
    s_norm = 0.0
    for j in range(m):
        acc = tau_known[j] + kd[j] * s[j]
        for i in range(n):
            acc += Y[j, i] * theta[i]
        u[j] = acc
        s_norm += s[j] * s[j]
    s_norm = math.sqrt(s_norm)
    signal = s_norm if gains.dz_on_s else e_norm
    if gains.adapt and dead_zone_open(signal, gains.dz_width):  # signal >= 0: abs() changes nothing
        for i in range(n):
            acc = 0.0
            for j in range(m):
                if gains.freeze and (u[j] < lo[j] or u[j] > hi[j]):
                    continue
                acc += Y[j, i] * s[j]
            rate[i] = acc / gamma[i]
    else:
        for i in range(n):
            rate[i] = 0.0
    if gains.adapt:
        modify_rate(rate, theta, s_norm, gains.sigma, gains.e_mod, arrays.theta0, gamma, arrays.lower, arrays.upper)


def slotine_li_torque_output(tau_model, s, e_norm, gains, arrays, u, s_rate):
    """The O(n) form's first half (the regressor's tau_model = Y θ + τ_known computed by the plant's recursion,
    regressor_kernel.rne_law_torque): u = tau_model + K_D s (unclamped) into u (m,), and s_rate (m,): the s the
    rate takes, s_j, or 0 for a joint whose u_j lies outside [sat_lo_j, sat_hi_j] under gains.freeze (as
    slotine_li_output leaves its Y_jᵀ s_j out). Returns (adapting, ‖s‖): adapting when gains.adapt and the
    dead-zone is open (common.dead_zone_open on ‖s‖ or e_norm = ‖q̃‖); then the caller evaluates
    rate = Yᵀ s_rate (regressor_kernel.rne_law_rate) and slotine_li_rate_output finishes it."""
    m = s.shape[0]
    kd, lo, hi = arrays.kd, arrays.sat_lo, arrays.sat_hi
    s_norm = 0.0
    for j in range(m):
        u[j] = tau_model[j] + kd[j] * s[j]
        s_norm += s[j] * s[j]
    s_norm = math.sqrt(s_norm)
    signal = s_norm if gains.dz_on_s else e_norm
    adapting = gains.adapt and dead_zone_open(signal, gains.dz_width)
    for j in range(m):
        if gains.freeze and (u[j] < lo[j] or u[j] > hi[j]):
            s_rate[j] = 0.0
        else:
            s_rate[j] = s[j]
    return adapting, s_norm


def slotine_li_rate_output(rate, theta, s_norm, adapting, gains, arrays):
    """The O(n) form's second half: rate (n_params,) holds Yᵀ s_rate when adapting; θ' = Γ⁻¹ Yᵀ s_rate, or 0 when
    not adapting, then the modifications (common.modify_rate) when gains.adapt, as slotine_li_output."""
    gamma = arrays.gamma
    for i in range(rate.shape[0]):
        if adapting:
            rate[i] = rate[i] / gamma[i]
        else:
            rate[i] = 0.0
    if gains.adapt:
        modify_rate(rate, theta, s_norm, gains.sigma, gains.e_mod, arrays.theta0, gamma, arrays.lower, arrays.upper)


def _per_joint(value, m: int, what: str) -> np.ndarray:
    v = np.broadcast_to(np.asarray(value, dtype=float), (m,)).copy()
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError(f"{what} must be finite and >= 0 (scalar or one per joint), got {value}")
    return v


class SlotineLiLaw(Law):
    """Slotine–Li adaptive control (mode ADAPTIVE) or a fixed-parameter baseline.

    regressor: the plant's regressor(v, w, a) -> (Y, τ_known).
    names: parameter names (n_params,); m: joints.
    lam: Λ [1/s], kd: K_D [N m s/rad], scalar or (m,); gamma: Γ, scalar or (n_params,)
    (estimates move at 1/γ); dead_zone: None or a DeadZone on ‖s‖ (or ‖q̃‖);
    modification: σ/e-modification and projection (common.Modification), or None.
    saturation: (lo, hi) (m,) torque limits [N m or N] for saturation-aware adaptation (a saturated
    joint's s_j is left out of the rate, slotine_li_output's freeze), or None (the lecture's law).
    evaluation: "recursive" (default): τ = Y π̂ + τ_known and Yᵀ s by the plant's O(n) recursions (the
    regressor's torque(v, w, a, θ) and rate(v, a, s, out), regressor_kernel.rne_law_torque / rne_law_rate),
    Y never formed; "regressor": Y formed whole (slotine_li_output), as before the O(n) form (a log that
    does not record its law.evaluation re-simulates with it, runs.verify). A regressor without torque/rate (a
    plain callable) is evaluated whole.
    """

    order = 2
    native = True  # adaptive_mj.plants.manipulator_kernel compiles slotine_li_output

    def __init__(self, regressor, names, m: int, *, lam, kd, gamma=1.0, dead_zone: DeadZone | None = None,
                 mode: Mode = Mode.ADAPTIVE, modification: Modification | None = None,
                 saturation: tuple[np.ndarray, np.ndarray] | None = None, evaluation: str = "recursive"):
        if evaluation not in EVALUATIONS:
            raise ValueError(f"evaluation must be one of {EVALUATIONS}, got {evaluation!r}")
        self.regressor = regressor
        self.evaluation = evaluation
        self.recursive = (evaluation == "recursive" and hasattr(regressor, "torque")
                          and hasattr(regressor, "rate"))
        self.names = tuple(names)
        self.m = int(m)
        self.mode = Mode(mode)
        self.lam = _per_joint(lam, self.m, "lambda")
        if np.any(self.lam <= 0):
            raise ValueError(f"lambda must be > 0, got {lam}")
        self.kd = _per_joint(kd, self.m, "kd")
        self.gamma = as_gamma(gamma, len(self.names))
        self.dead_zone = dead_zone
        self.adapt = self.mode is Mode.ADAPTIVE
        self._zero = np.zeros(self.m)
        self._dz_width = 0.0 if dead_zone is None else dead_zone.width  # the dead-zone, once (not per call)
        self._dz_on_s = dead_zone is None or dead_zone.on is DeadZoneOn.S
        self.modification = modification or NO_MODIFICATION
        self._mod = self.modification.arrays(len(self.names), gamma=self.gamma)
        self.freeze = saturation is not None
        lo, hi = saturation if saturation is not None else (-np.inf, np.inf)
        self.lo = np.broadcast_to(np.asarray(lo, dtype=float), (self.m,)).copy()
        self.hi = np.broadcast_to(np.asarray(hi, dtype=float), (self.m,)).copy()
        self._gains, self._arrays = self.gains(), self.arrays()  # once: the Python path reads them by name

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) of the projection, or None (common.Modification.box)."""
        return self.modification.box(len(self.names), self.gamma)

    def gains(self) -> SlotineLiGains:
        """The law's scalar gains and switches, by name."""
        sigma, e_mod = self._mod[0], self._mod[1]
        return SlotineLiGains(mode=int(self.mode), adapt=self.adapt, dz_width=self._dz_width, dz_on_s=self._dz_on_s,
                              sigma=sigma, e_mod=e_mod, freeze=self.freeze)

    def arrays(self) -> SlotineLiArrays:
        """The law's arrays, by name."""
        theta0, lower, upper = self._mod[2], self._mod[3], self._mod[4]
        return SlotineLiArrays(kd=self.kd, gamma=self.gamma, theta0=theta0, lower=lower, upper=upper, sat_lo=self.lo,
                               sat_hi=self.hi)

    def native_params(self) -> dict[str, Any]:
        """What adaptive_mj.plants.manipulator_kernel needs: "gains" (the SLOTINE_LI_GAINS record of `gains()`), Λ and
        the arrays by name."""
        return {"gains": self.gains().record(), "lam": self.lam, "recursive": self.recursive,
                **self.arrays()._asdict()}

    def feedback(self) -> JointFeedback:
        """K_D and Λ (every mode: the baselines close the same feedback on s)."""
        return JointFeedback(kd=self.kd, lam=self.lam)

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        m = self.m
        s, qd_r, qdd_r = np.empty(m), np.empty(m), np.empty(m)
        reference_terms(x, ref, self.lam, s, qd_r, qdd_r)
        if self.mode is Mode.PD_GRAVITY:
            v, w, a = self._zero, self._zero, self._zero
        else:
            v, w, a = x[1], qd_r, qdd_r
        u, rate = np.empty(m), np.empty(len(self.names))
        e_norm = float(np.linalg.norm(ref[0] - x[0]))
        if self.recursive:  # O(n): Y π̂ and Yᵀ s by the plant's recursions (the native callback's numbers)
            tau_model = self.regressor.torque(v, w, a, theta_hat)
            s_rate = np.empty(m)
            adapting, s_norm = slotine_li_torque_output(tau_model, s, e_norm, self._gains, self._arrays, u, s_rate)
            if adapting:
                self.regressor.rate(v, a, s_rate, rate)
            slotine_li_rate_output(rate, theta_hat, s_norm, adapting, self._gains, self._arrays)
        else:
            Y, tau_known = self.regressor(v, w, a)
            slotine_li_output(Y, tau_known, theta_hat, s, e_norm, self._gains, self._arrays, u, rate)
        return LawStep(u, rate, s, qdd_r)

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """V = ½ sᵀ M s + ½ Σ γ_i π̃_i² (baselines: ½ sᵀ M s).  s: (N, m), M: (N, m, m) (required)."""
        if M is None:
            raise ValueError("the Slotine–Li V needs M, the plant's mass matrices at the rows")
        s = np.asarray(s, dtype=float)
        V = 0.5 * np.einsum("ni,nij,nj->n", s, M, s)
        if self.adapt:
            err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
            V = V + 0.5 * np.sum(self.gamma * err**2, axis=-1)
        return V


# --- the law kinds: their keys (law.*), read from a scenario, and their builders ----------------------
OWN_KEYS = (
    Key("lambda", "number or table {joint = number}", unit="1/s", bounds="> 0", required=True,
        doc="Λ of s = q̃' + Λ q̃, one for every joint or a table giving every joint"),
    Key("kd", "number or table {joint = number}", unit="N m s/rad (N s/m on a slide)", bounds="> 0", required=True,
        doc="K_D of τ = … + K_D s, one for every joint or a table giving every joint"),
    Key("evaluation", "string", default="recursive", bounds="one of 'recursive', 'regressor'",
        doc="how Y π̂ and Yᵀ s are evaluated: 'recursive' (O(n) Newton–Euler recursions, Y never formed) or "
            "'regressor' (Y formed whole, as before the O(n) form); the same law to rounding"),
)


def _keys(adaptive: bool) -> tuple[Key, ...]:
    """The keys `_read` reads (law.gamma is required when adapting)."""
    return (shared.KIND, *OWN_KEYS, shared.GAMMA_REQUIRED if adaptive else shared.GAMMA, shared.DEAD_ZONE,
            shared.INITIAL_ESTIMATES, shared.NOMINAL, *shared.ROBUST, shared.SATURATION)


def _reader(adaptive: bool) -> Callable[[Table, str, PlantSpec, int], LawSpec]:
    """The key reader of the adaptive kind or of a baseline (`_read`)."""
    return lambda t, kind, plant, order: _read(t, kind, adaptive=adaptive)


def _read(t: Table, kind: str, *, adaptive: bool) -> LawSpec:
    """law.lambda and law.kd (a number, or a table by joint), law.gamma (required when adapting), law.dead_zone,
    the estimates (a baseline needs law.nominal or law.initial_estimates), the robust modifications (projection
    may be "consistent" or "nonnegative", law_keys.RIGID_BODY_PROJECTIONS) and law.saturation ("freeze" when
    adapting). The law is of order 2 (law.order is not a key of these kinds)."""
    lam = joint_values(t, "lambda", arrays=False)
    kd = joint_values(t, "kd", arrays=False)
    for key, value in (("lambda", lam), ("kd", kd)):
        for j, v in (value.items() if isinstance(value, dict) else [("", value)]):
            if not v > 0:
                raise t.fail(key + (f".{j}" if j else ""), "> 0", v)
    gamma = shared.read_gamma(t)
    if adaptive:
        shared.required(t, gamma, "law.gamma", kind)
    dead_zone = shared.read_dead_zone(t)
    initial = shared.read_estimates(t, "initial_estimates")
    nominal = shared.read_estimates(t, "nominal")
    if not adaptive and nominal is None and initial is None:
        raise ScenarioError(f"{t.where}: law.nominal (or law.initial_estimates) is required for law.kind = {kind!r}")
    robust = shared.read_robust(t, kind, adaptive=adaptive, composite=False, presets=shared.RIGID_BODY_PROJECTIONS)
    saturation = shared.read_saturation(t)
    if saturation != "ignore" and not adaptive:
        raise t.fail("saturation", "'ignore' for a law without adaptation", saturation)
    evaluation = t.string("evaluation", "recursive", choices=EVALUATIONS)
    t.finish()
    return LawSpec(kind=kind, order=2, lam=None if isinstance(lam, dict) else lam, k=0.0, gamma=gamma,
                   dead_zone=dead_zone, initial_estimates=initial, nominal=nominal, K=None, boundary_layer=None,
                   kd=kd, lam_joints=lam if isinstance(lam, dict) else None, robust=robust, saturation=saturation,
                   params={"evaluation": evaluation})


def _builder(mode: Mode) -> Callable[[BuildContext], Law]:
    """The builder of the kind of `mode`: SlotineLiLaw on the plant's regressor, Λ and K_D per joint."""

    def build(ctx: BuildContext) -> Law:
        L, arm = ctx.law, ctx.rigid_body()
        lam_value = L.lam_joints if L.lam_joints is not None else L.lam
        # law.lambda (a number, or lam_joints) and law.kd are required for these kinds (_read)
        assert lam_value is not None and L.kd is not None
        return SlotineLiLaw(arm.regressor, arm.names, arm.m, lam=ctx.per_joint("law.lambda", lam_value),
                            kd=ctx.per_joint("law.kd", L.kd),
                            gamma=ctx.gamma(arm.names) if L.gamma is not None else 1.0,
                            dead_zone=ctx.dead_zone(), mode=mode,
                            modification=ctx.modification if mode is Mode.ADAPTIVE else None,
                            saturation=ctx.saturation() if L.saturation == "freeze" else None,
                            evaluation=(L.params or {}).get("evaluation", "recursive"))

    return build


def _kind(name: str, mode: Mode, doc: str) -> LawKind:
    adaptive = mode is Mode.ADAPTIVE
    example = ("ur5e_identification", () if adaptive else (f"law.kind='{name}'", "law.nominal='model'"))
    return register(LawKind(name, frozenset({Form.RIGID_BODY}), adaptive, doc, keys=_keys(adaptive),
                            read=_reader(adaptive), build=_builder(mode), module=__name__, example=example))


#: these law kinds, registered (adaptive_mj.laws.kinds): law.kind = "slotine_li" and its two baselines
SLOTINE_LI = _kind("slotine_li", Mode.ADAPTIVE, "Slotine-Li adaptive control of a manipulator, tau = Y pi_hat + K_D s")
COMPUTED_TORQUE = _kind("computed_torque", Mode.COMPUTED_TORQUE,
                        "computed torque at the nominal parameters (baseline)")
PD_GRAVITY = _kind("pd_gravity", Mode.PD_GRAVITY, "PD plus gravity compensation at the nominal parameters (baseline)")

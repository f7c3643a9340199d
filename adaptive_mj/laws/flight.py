"""The flight laws as law kinds of Form.AIRFRAME (adaptive_mj.laws.kinds): the SE(3) geometric controller, its
adaptive form (the lecture's sliding adaptive law on the translational dynamics: mass and a disturbance force),
and L1 adaptive augmentation, each evaluated on the loop's state x (4, 3) = [p; v; φ; Ω] and reference (5, 3) =
[p_d, p_d', p_d'', p_d''', p_d''''] (adaptive_mj.plants.quadrotor), returning the four rotor thrusts [N] through
the airframe's allocation (law.allocation: "yaw_last", by default, gives up yaw before thrust, roll and pitch where
a rotor would saturate; "exact_clip" inverts exactly; flight_kernel.allocate), then the loop clamps them into
[0, T_max] (the applied thrusts are logged).

θ (13,) = [m, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz, dx, dy, dz, tx, ty, tz] as the plant names it: a law's nominal model is
θ̂; the adaptive law moves m̂, d̂ and the moment τ̂ (Goodarzi, Lee & Lee 2015's Δ̂_R; the inertia stays at its
estimate unless law.adapt_inertia: then Ĵ too, by the Slotine–Li law on SO(3)), the others hold it. Every law
feeds the desired body rate Ω_d forward from the reference's jerk (Lee 2010's e_Ω = Ω − RᵀR_dΩ_d, with Ω̇_d = 0;
with law.adapt_inertia Ω̇_d from its snap).

The position gains are per axis x, y, z (law.kx, law.kv, law.lambda and law.k: one number for every axis, or three),
RotorPy's by default: its SE3Control's kp_pos = (6.5, 6.5, 15) 1/s² and kd_pos = (4, 4, 9) 1/s times the 0.03 kg
Crazyflie (rotorpy/controllers/quadrotor_control.py at 9b760b8), so z is stiffer than x and y.

The sliding variable logged as s (3,) [m/s] is the translational surface s = e_v + c e_x (c = k_x/k_v per axis for
the geometric baseline and L1, law.lambda for the adaptive law), with V = ½ m sᵀs (+ ½ m̃²/γ_m + ½ ‖d̃‖²/γ_d when
adapting): the translational Lyapunov function the adaptive law's proof uses (docs/THEORY.md, "The quadrotor").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from adaptive_mj.keys import Key
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws import flight_kernel as fk
from adaptive_mj.laws import geometric as geo
from adaptive_mj.laws.common import NO_MODIFICATION, DeadZone, LawStep, Modification
from adaptive_mj.laws.kinds import AirframeView, BuildContext, Form, LawKind, register
from adaptive_mj.laws.protocol import AirframeFeedback
from adaptive_mj.specs import LawSpec

E1 = np.array([1.0, 0.0, 0.0])  # the desired heading b₁d: yaw held at 0 (the references carry no yaw)
M_INDEX, J_SLICE, D_SLICE, T_SLICE = 0, slice(1, 7), slice(7, 10), slice(10, 13)


def rotation(phi: np.ndarray) -> np.ndarray:
    """(3, 3) R = exp(φ^) of the rotation vector φ (3,) [rad]: flight_kernel.rodrigues, the kernel's own."""
    R = np.empty((3, 3))
    fk.rodrigues(np.asarray(phi, dtype=float), R)
    return R


def inertia_matrix(theta: np.ndarray) -> np.ndarray:
    """(3, 3) J [kg m²] of θ's [Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]."""
    xx, yy, zz, xy, xz, yz = theta[J_SLICE]
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


_KERNELS: dict[str, object] = {}


def kernel(name: str):
    """flight_kernel's `flight_law` or `l1_update` compiled by numba (with the plain functions it calls; cached on
    disk), or the plain Python function where numba is missing: the same arithmetic either way (the native
    callback compiles the same source)."""
    if name not in _KERNELS:
        fn = getattr(fk, name)
        try:
            import functools

            import numba

            from adaptive_mj.numba_util import jit_tree

            _KERNELS[name] = jit_tree(fn, functools.partial(numba.njit, cache=True), tag="_flight")
        except ImportError:  # pragma: no cover - numba is a dependency; a bare checkout still runs, slowly
            _KERNELS[name] = fn
    return _KERNELS[name]


@dataclass
class FlightLaw:
    """What the three flight laws share (see the module docstring): the airframe, the law's numbers P and arrays G
    (adaptive_mj.laws.flight_kernel), evaluated by flight_kernel.flight_law. order 4; names: the plant's θ names."""

    airframe: AirframeView
    gains: geo.Gains
    c: np.ndarray  # (3,) [1/s] the surface's slope per axis
    names: tuple[str, ...] = ()
    order: int = 4
    has_filters: bool = False
    installed = None
    native: bool = True
    adapt: bool = False
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    gamma: np.ndarray = field(default_factory=lambda: np.ones(13))
    c_R: float = 0.0
    mode: float = fk.MODE_GEOMETRIC
    k: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) [N s/m] the adaptive law's gain on s per axis
    adapt_inertia: bool = False
    dead_zone: DeadZone | None = None
    modification: Modification | None = None
    l1: bool = False
    allocation: str = "yaw_last"  # ALLOCATIONS: how thrust and moments become rotor thrusts (flight_kernel.allocate)

    def __post_init__(self):
        self.names = tuple(self.airframe.names)
        n = len(self.names)
        P = np.zeros(fk.P_SIZE)
        P[fk.P_MODE], P[fk.P_G] = self.mode, self.airframe.gravity
        P[fk.P_KR], P[fk.P_KW] = self.gains.kR, self.gains.kW
        for at, v in ((fk.P_KX, self.gains.kx), (fk.P_KV, self.gains.kv), (fk.P_C, self.c), (fk.P_K, self.k)):
            P[at:at + 3] = np.broadcast_to(np.asarray(v, dtype=float), (3,))
        dz = self.dead_zone
        P[fk.P_DZ_WIDTH] = dz.width if dz is not None else 0.0
        P[fk.P_DZ_ON_S] = 1.0 if dz is None or dz.on.value == "s" else 0.0
        P[fk.P_ADAPT], P[fk.P_L1], P[fk.P_CR] = float(self.adapt), float(self.l1), self.c_R
        P[fk.P_ADAPT_J] = float(self.adapt_inertia)
        P[fk.P_ALLOC] = ALLOCATIONS[self.allocation]
        P[fk.P_TMAX:fk.P_TMAX + 4] = np.asarray(self.airframe.thrust_max, dtype=float)
        G = np.zeros((4, n))
        G[0] = self.gamma
        mod = self.modification
        sigma, e_mod, G[1], G[2], G[3] = (mod if mod is not None else NO_MODIFICATION).arrays(n)
        P[fk.P_SIGMA], P[fk.P_EMOD] = sigma, e_mod
        if mod is not None:
            self.bounds = mod.box(n)
        self.P, self.G = P, G
        self.Ainv = np.ascontiguousarray(np.linalg.inv(self.airframe.allocation))
        self.aug = np.zeros(6)
        self._scratch = (np.zeros((3, 3)), np.zeros(3), np.zeros(fk.TMP_SIZE))

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        u, s, rate = np.empty(4), np.empty(3), np.empty(len(self.names))
        R, F, tmp = self._scratch
        kernel("flight_law")(np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(ref, dtype=float),
                             np.ascontiguousarray(theta_hat, dtype=float), self.P, self.G, self.Ainv, self.aug,
                             R, F, tmp, u, s, rate)
        return LawStep(u, rate, s, np.array(ref[2]))

    def lyapunov(self, s, theta_hat, theta, *, M=None) -> np.ndarray:
        """(N,) V = ½ sᵀ M s (M = m I from the plant) + ½ Σ γᵢ θ̃ᵢ² over the mass and force estimates, and the
        inertia's with law.adapt_inertia (γ: the stiffnesses, θ̂' = regressor·s/γ); the attitude's own terms
        (½ s_RᵀJs_R, k_R Ψ) and the moment estimate's are not in it (docs/THEORY.md)."""
        s = np.asarray(s, dtype=float)
        kinetic = 0.5 * np.einsum("ni,nij,nj->n", s, M, s) if M is not None else 0.5 * np.einsum("ni,ni->n", s, s)
        if not self.adapt:
            return kinetic
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        moving = np.zeros(len(self.names), dtype=bool)
        moving[M_INDEX] = moving[D_SLICE] = True
        if self.adapt_inertia:
            moving[J_SLICE] = True
        return kinetic + 0.5 * np.sum(np.where(moving, self.gamma, 0.0) * np.where(moving, err, 0.0) ** 2, axis=1)

    def reset(self) -> None:
        return None

    def step_begins(self, x) -> None:
        return None

    def step_ends(self, xs, us, weights, h) -> None:
        return None

    def native_params(self) -> dict:
        """What the compiled callback takes: P, G, the allocation and its inverse
        (adaptive_mj.plants.quadrotor_kernel)."""
        return {"P": self.P, "G": self.G, "Ainv": self.Ainv, "A": self.airframe.allocation}

    def feedback(self) -> AirframeFeedback:
        """The attitude loop's gains, for the pre-flight check (adaptive_mj.sim.preflight)."""
        return AirframeFeedback(self.gains.kR, self.gains.kW)


@dataclass
class GeometricLaw(FlightLaw):
    """Lee, Leok & McClamroch (2010) at the nominal θ̂ (adaptive_mj.laws.geometric.geometric, written out in
    flight_kernel.flight_law)."""


@dataclass
class GeometricAdaptiveLaw(FlightLaw):
    """The sliding adaptive law on the translational dynamics (adaptive_mj.laws.geometric.adaptive_force) with the
    geometric attitude loop: m̂' = −sᵀw/γ_m, d̂' = s/γ_d (the project's γ is a stiffness: rate = regressor · s / γ),
    through the dead-zone and the robust modifications (σ, e-modification on ‖s‖, projection). With adapt_inertia
    the attitude loop is the Slotine–Li law on SO(3) instead: M = Y ĵ − k_Ω s_R − k_R e_R − τ̂, ĵ' = −Yᵀs_R/γ_j
    (flight_kernel.inertia_regressor, inertia_rate; docs/THEORY.md, "The inertia")."""

    mode: float = fk.MODE_ADAPTIVE
    adapt: bool = True


@dataclass
class L1GeometricLaw(FlightLaw):
    """The geometric controller plus L1 augmentation (adaptive_mj.laws.l1; flight_kernel.l1_update): the predictor,
    the piecewise-constant adaptation and the low-pass filter advance once per physics step (step_ends, from the
    state measured at the step's start and the thrusts applied over it: T_s = the physics step), so the
    augmentation is held over each step's stages. Continuous control only (its filters integrate per step). The
    compiled callback makes the same update at the next step's first stage, before the law runs
    (adaptive_mj.plants.quadrotor_kernel)."""

    a_s: float = -5.0
    w_c: float = 5.0
    has_filters: bool = True
    l1: bool = True

    def __post_init__(self):
        super().__post_init__()
        self.P[fk.P_AS], self.P[fk.P_WC] = self.a_s, self.w_c
        self.z_hat: np.ndarray | None = None
        self.sigma = np.zeros(6)
        self._theta: np.ndarray | None = None
        self._l1_scratch = (np.zeros((3, 3)), np.zeros(fk.TMP_SIZE))

    def reset(self) -> None:
        self.z_hat = None
        self.sigma[:] = 0.0
        self.aug[:] = 0.0

    def step_begins(self, x) -> None:
        if self.z_hat is None:
            self.z_hat = np.concatenate([x[1], x[3]]).astype(float)

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        self._theta = np.array(theta_hat, dtype=float)
        return super().__call__(t, x, ref, theta_hat)

    def step_ends(self, xs, us, weights, h) -> None:
        """One L1 update over the step: the predictor from the step's first measured state and applied thrusts."""
        assert self.z_hat is not None and self._theta is not None
        R, tmp = self._l1_scratch
        kernel("l1_update")(np.ascontiguousarray(xs[0], dtype=float), np.ascontiguousarray(us[0], dtype=float),
                            self._theta, self.P, np.ascontiguousarray(self.airframe.allocation), self.a_s, self.w_c, h,
                            self.z_hat, self.sigma, self.aug, R, tmp)


# --- the law kinds: keys, readers, builders -----------------------------------------------
#: law.allocation -> P[P_ALLOC] (flight_kernel.allocate). "yaw_last" is the default: the flight stacks in use give yaw
#: the lowest priority when a rotor saturates (PX4's ControlAllocationSequentialDesaturation with airmode off, its
#: default: roll and pitch desaturated first, yaw mixed into what is left; ArduPilot's AP_MotorsMatrix
#: output_armed_stabilizing limits yaw to the headroom roll and pitch leave), as Mueller & D'Andrea (ICRA 2014) give
#: up yaw to keep flying. RotorPy (and AdaptiveQuadBench on it) inverts exactly and clips the motor speeds:
#: "exact_clip", this project's allocation before issue 52.
ALLOCATIONS = {"exact_clip": fk.ALLOC_EXACT_CLIP, "yaw_last": fk.ALLOC_YAW_LAST}
GAMMA_J_DEFAULT = 1e4  # measured on the lemniscate: docs/THEORY.md, "The inertia"
# RotorPy's SE3Control position gains (kp_pos = (6.5, 6.5, 15) 1/s², kd_pos = (4, 4, 9) 1/s; quadrotor_control.py at
# 9b760b8) times its Crazyflie's 0.03 kg: per axis x, y, z
KX_DEFAULT = (0.195, 0.195, 0.45)  # [N/m]
KV_DEFAULT = (0.12, 0.12, 0.27)  # [N s/m]
KX = Key("kx", "number or array [x, y, z]", "N/m", KX_DEFAULT, "> 0",
         "position gain k_x per axis (geometric, l1_geometric; one number: every axis)")
KV = Key("kv", "number or array [x, y, z]", "N s/m", KV_DEFAULT, "> 0",
         "velocity gain k_v per axis (geometric, l1_geometric; one number: every axis)")
KR = Key("kR", "number", "N m/rad", 7.8e-3, "> 0", "attitude gain k_R")
KW = Key("kW", "number", "N m s/rad", 6.7e-4, "> 0", "body-rate gain k_Omega")
# the adaptive law's k s = k e_v + k c e_x matches the geometric law's k_v e_v + k_x e_x: c = k_x/k_v, k = k_v per axis
LAMBDA = Key("lambda", "number or array [x, y, z]", "1/s",
             tuple(x / v for x, v in zip(KX_DEFAULT, KV_DEFAULT, strict=True)), "> 0",
             "the surface's slope c per axis: s = e_v + c e_x (one number: every axis)")
K = Key("k", "number or array [x, y, z]", "N s/m", KV_DEFAULT, "> 0",
        "the gain on s per axis in the force law F = m_hat w - d_hat - k s (one number: every axis)")
GAMMA_M = Key("gamma_m", "number", "m² kg⁻¹ s⁻²", 100.0, "> 0",
              "the mass estimate's adaptation stiffness (rate = -s.w / gamma_m)")
GAMMA_D = Key("gamma_d", "number", "m/N", 20.0, "> 0",
              "the disturbance force estimate's adaptation stiffness (rate = s / gamma_d)")
GAMMA_T = Key("gamma_t", "number", "rad/(N m)", 200.0, "> 0",
              "the moment estimate's adaptation stiffness (rate = (Omega + c_r e_R) / gamma_t)")
ADAPT_INERTIA = Key("adapt_inertia", "boolean", "", False, "",
                    "geometric_adaptive: adapt the inertia J_hat too (the Slotine-Li attitude law on SO(3))")
GAMMA_J = Key("gamma_j", "number", "rad² kg⁻¹ m⁻² s⁻²", GAMMA_J_DEFAULT, "> 0",
              "the inertia estimate's adaptation stiffness (rate = -Y^T s_R / gamma_j), with adapt_inertia")
C_R = Key("c_r", "number", "1/s", 5.0, "> 0", "the attitude surface's slope: s_R = Omega + c_r e_R")
A_S = Key("a_s", "number", "1/s", -5.0, "< 0", "the L1 state predictor's pole")
W_C = Key("w_c", "number", "rad/s", 5.0, "> 0", "the L1 low-pass filter's cut-off")
ALLOCATION = Key("allocation", "string", "", "yaw_last", "one of 'yaw_last', 'exact_clip'",
                 "how thrust and moments become rotor thrusts where a rotor would saturate: 'yaw_last' reduces the "
                 "yaw moment to keep the thrust, roll and pitch (PX4, ArduPilot); 'exact_clip' inverts exactly and "
                 "clips each rotor (RotorPy)")

ATTITUDE_KEYS = (KR, KW)

#: the position gains' defaults before issue 52 (one number on every axis: RotorPy's x/y gains reused on z). A log
#: written then is re-simulated with them (adaptive_mj.runs.verify), for the keys its scenario left to the default.
FORMER_DEFAULTS = {"kx": 0.195, "kv": 0.12, "lambda": 1.625, "k": 0.12}


def former_gain_overrides(kind: str, set_keys: set[str]) -> list[str]:
    """The --set expressions that give law kind `kind` (a flight law's) the position gains it had by default before
    issue 52, for its keys not in set_keys (the keys its scenario or overrides set); [] for any other kind."""
    own = {"geometric": GEOMETRIC_OWN, "l1_geometric": L1_OWN, "geometric_adaptive": ADAPTIVE_OWN}.get(kind, ())
    return [f"law.{key.name}={FORMER_DEFAULTS[key.name]!r}" for key in own
            if key.name in FORMER_DEFAULTS and key.name not in set_keys]


def _read(own: tuple[Key, ...], *, adaptive: bool):
    def read(t, kind: str, plant, order: int) -> LawSpec:
        params = {}
        for key in own:
            if key.type == "boolean":
                params[key.name] = t.boolean(key.name, key.default)
            elif key is ALLOCATION:
                params[key.name] = t.string(key.name, key.default, choices=tuple(ALLOCATIONS))
            elif key in PER_AXIS:
                params[key.name] = _per_axis(t, key)
            elif key.name == "a_s":  # the predictor's pole: < 0
                params[key.name] = t.number(key.name, key.default)
                if not params[key.name] < 0:
                    raise t.fail(key.name, "< 0 (a stable predictor)", params[key.name])
            else:
                params[key.name] = t.number(key.name, key.default, gt=0)
        dead_zone = shared.read_dead_zone(t) if adaptive else None
        initial = shared.read_estimates(t, "initial_estimates")
        nominal = shared.read_estimates(t, "nominal")
        robust = shared.read_robust(t, kind, adaptive=adaptive, composite=False, presets=())
        t.finish()
        # LawSpec's scalar λ and k: the largest axis' (what sizes the dead-zone's noise in ‖s‖, and the studies')
        lam = max(params["lambda"]) if "lambda" in params else None
        return LawSpec(kind=kind, order=4, lam=lam, k=float(max(params.get("k", (0.0,)))), gamma=None,
                       dead_zone=dead_zone, initial_estimates=initial, nominal=nominal, K=None, boundary_layer=None,
                       robust=robust, params=params)

    return read


PER_AXIS = (KX, KV, LAMBDA, K)


def _per_axis(t, key: Key) -> tuple[float, float, float]:
    """A per-axis gain: one number (every axis) or three (x, y, z), each > 0; absent: the key's default."""
    v = t.data.get(key.name)
    if isinstance(v, (list, tuple)):
        vals = t.numbers(key.name, None)
        if vals is None or len(vals) != 3:
            raise t.fail(key.name, "a number or 3 numbers (x, y, z)", v)
    else:
        one = t.number(key.name, None)
        if one is None:  # absent: the key's default
            return tuple(key.default)
        vals = (one,) * 3
    for a in vals:
        if not (math.isfinite(a) and a > 0):
            raise t.fail(key.name, "> 0 on every axis", list(vals))
    return (float(vals[0]), float(vals[1]), float(vals[2]))


def _gains(p: dict) -> geo.Gains:
    return geo.Gains(np.array(p.get("kx", KX.default), dtype=float), np.array(p.get("kv", KV.default), dtype=float),
                     p["kR"], p["kW"])


def _slope(gains: geo.Gains) -> np.ndarray:
    """(3,) c = k_x/k_v per axis [1/s]."""
    return np.asarray(gains.kx, dtype=float) / np.asarray(gains.kv, dtype=float)


def _build_geometric(ctx: BuildContext):
    p = ctx.law.params or {}
    gains = _gains(p)
    return GeometricLaw(ctx.airframe(), gains, _slope(gains), allocation=p.get("allocation", ALLOCATION.default))


def _build_adaptive(ctx: BuildContext):
    p = ctx.law.params or {}
    af = ctx.airframe()
    # a held estimate is infinitely stiff: no rate, and the σ- and e-modification's leak (θ̂ − θ₀)/γ leaves it
    # alone (with γ = 1 it pulled a held Ĵ toward θ₀, zeros unless law.theta0 was given)
    gamma = np.full(len(af.names), np.inf)
    gamma[M_INDEX], gamma[D_SLICE], gamma[T_SLICE] = p["gamma_m"], p["gamma_d"], p["gamma_t"]
    inertia = bool(p["adapt_inertia"])
    if inertia:
        gamma[J_SLICE] = p["gamma_j"]
    return GeometricAdaptiveLaw(af, _gains(p), np.array(p["lambda"], dtype=float), gamma=gamma,
                                k=np.array(p["k"], dtype=float), dead_zone=ctx.dead_zone(),
                                modification=ctx.modification, c_R=p["c_r"], adapt_inertia=inertia,
                                allocation=p.get("allocation", ALLOCATION.default))


def _build_l1(ctx: BuildContext):
    p = ctx.law.params or {}
    gains = _gains(p)
    return L1GeometricLaw(ctx.airframe(), gains, _slope(gains), a_s=p["a_s"], w_c=p["w_c"],
                          allocation=p.get("allocation", ALLOCATION.default))


def _keys(own: tuple[Key, ...], adaptive: bool) -> tuple[Key, ...]:
    return (shared.KIND, *own, *((shared.DEAD_ZONE,) if adaptive else ()), shared.INITIAL_ESTIMATES, shared.NOMINAL,
            *shared.ROBUST)


GEOMETRIC_OWN = (KX, KV, KR, KW, ALLOCATION)
ADAPTIVE_OWN = (LAMBDA, K, GAMMA_M, GAMMA_D, GAMMA_T, C_R, KR, KW, ADAPT_INERTIA, GAMMA_J, ALLOCATION)
L1_OWN = (KX, KV, KR, KW, A_S, W_C, ALLOCATION)

#: these law kinds, registered (adaptive_mj.laws.kinds): law.kind = "geometric", "geometric_adaptive", "l1_geometric"
GEOMETRIC = register(LawKind(
    "geometric", frozenset({Form.AIRFRAME}), False,
    "geometric tracking control on SE(3) at the nominal mass and inertia (Lee, Leok & McClamroch 2010; baseline)",
    keys=_keys(GEOMETRIC_OWN, False), read=_read(GEOMETRIC_OWN, adaptive=False), build=_build_geometric,
    module=__name__, example=("quadrotor_hover_payload", ("law.kind='geometric'",))))
GEOMETRIC_ADAPTIVE = register(LawKind(
    "geometric_adaptive", frozenset({Form.AIRFRAME}), True,
    "the sliding adaptive law on the translational dynamics (mass, disturbance force) with the geometric attitude loop",
    keys=_keys(ADAPTIVE_OWN, True), read=_read(ADAPTIVE_OWN, adaptive=True), build=_build_adaptive,
    module=__name__, example=("quadrotor_hover_payload", ())))
L1_GEOMETRIC = register(LawKind(
    "l1_geometric", frozenset({Form.AIRFRAME}), True,
    "L1 adaptive augmentation of the geometric controller (predictor, piecewise-constant adaptation, low-pass; L1Quad)",
    keys=_keys(L1_OWN, False), read=_read(L1_OWN, adaptive=False), build=_build_l1,
    module=__name__, example=("quadrotor_hover_payload", ("law.kind='l1_geometric'",)),
    filters_key="law.kind = 'l1_geometric' (its predictor and filter)"))

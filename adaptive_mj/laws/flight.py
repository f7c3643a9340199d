"""The flight laws as law kinds of Form.AIRFRAME (adaptive_mj.laws.kinds): the SE(3) geometric controller, its
adaptive form (the lecture's sliding adaptive law on the translational dynamics: mass and a disturbance force),
and L1 adaptive augmentation, each evaluated on the loop's state x (4, 3) = [p; v; φ; Ω] and reference (5, 3) =
[p_d, p_d', p_d'', p_d''', p_d''''] (adaptive_mj.plants.quadrotor), returning the four rotor thrusts [N] through
the airframe's allocation, unclipped (the loop clamps them into [0, T_max]: the applied thrusts are logged).

θ (10,) = [m, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz, dx, dy, dz] as the plant names it: a law's nominal model is θ̂; the
adaptive law moves m̂ and d̂ (the inertia stays at its estimate), the others hold it.

The sliding variable logged as s (3,) [m/s] is the translational surface s = e_v + c e_x (c = k_x/k_v for the
geometric baseline and L1, law.lambda for the adaptive law), with V = ½ m sᵀs (+ ½ m̃²/γ_m + ½ ‖d̃‖²/γ_d when
adapting): the translational Lyapunov function the adaptive law's proof uses (docs/THEORY.md, "The quadrotor").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from adaptive_mj.keys import Key
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws import geometric as geo
from adaptive_mj.laws import l1
from adaptive_mj.laws.common import DeadZone, LawStep, Modification, dead_zone_open, modify_rate
from adaptive_mj.laws.kinds import AirframeView, BuildContext, Form, LawKind, register
from adaptive_mj.specs import LawSpec

E1 = np.array([1.0, 0.0, 0.0])  # the desired heading b₁d: yaw held at 0 (the references carry no yaw)
M_INDEX, J_SLICE, D_SLICE = 0, slice(1, 7), slice(7, 10)


def rotation(phi: np.ndarray) -> np.ndarray:
    """(3, 3) R = exp(φ^) (Rodrigues) of the rotation vector φ (3,) [rad]."""
    angle = math.sqrt(float(phi @ phi))
    if angle < 1e-12:
        return np.eye(3) + geo.hat(phi)
    K = geo.hat(phi / angle)
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def inertia_matrix(theta: np.ndarray) -> np.ndarray:
    """(3, 3) J [kg m²] of θ's [Jxx, Jyy, Jzz, Jxy, Jxz, Jyz]."""
    xx, yy, zz, xy, xz, yz = theta[J_SLICE]
    return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])


def thrusts(airframe: AirframeView, f: float, M: np.ndarray) -> np.ndarray:
    """(4,) rotor thrusts [N] giving collective thrust f [N] and moments M (3,) [N m] (the allocation's inverse,
    unclipped)."""
    return np.linalg.solve(airframe.allocation, np.concatenate([[f], M]))


@dataclass
class FlightLaw:
    """What the three flight laws share: the airframe, the attitude gains, the surface's slope c and the Lyapunov
    function. order 4; names: the plant's θ names."""

    airframe: AirframeView
    gains: geo.Gains
    c: float
    names: tuple[str, ...] = ()
    order: int = 4
    has_filters: bool = False
    installed = None
    native: bool = False
    adapt: bool = False
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    gamma: np.ndarray = field(default_factory=lambda: np.ones(10))

    def __post_init__(self):
        self.names = tuple(self.airframe.names)

    def lyapunov(self, s, theta_hat, theta, *, M=None) -> np.ndarray:
        """(N,) V = ½ sᵀ M s (M = m I from the plant) + ½ Σ θ̃ᵢ²/γᵢ over the estimates that move."""
        s = np.asarray(s, dtype=float)
        kinetic = 0.5 * np.einsum("ni,nij,nj->n", s, M, s) if M is not None else 0.5 * np.einsum("ni,ni->n", s, s)
        if not self.adapt:
            return kinetic
        err = np.asarray(theta_hat, dtype=float) - np.asarray(theta, dtype=float)
        moving = np.zeros(len(self.names), dtype=bool)
        moving[M_INDEX] = moving[D_SLICE] = True
        return kinetic + 0.5 * np.sum(np.where(moving, err**2 / self.gamma, 0.0), axis=1)

    def reset(self) -> None:
        return None

    def step_begins(self, x) -> None:
        return None

    def step_ends(self, xs, us, weights, h) -> None:
        return None

    def native_params(self):
        raise TypeError(f"{type(self).__name__} has no compiled form")

    def feedback(self):
        return None

    def _command(self, F: np.ndarray, R: np.ndarray, W: np.ndarray, J: np.ndarray) -> geo.Command:
        return geo.attitude(F, R, W, E1, self.gains, J)


@dataclass
class GeometricLaw(FlightLaw):
    """Lee, Leok & McClamroch (2010) at the nominal θ̂ (adaptive_mj.laws.geometric.geometric)."""

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        R = rotation(x[2])
        m = float(theta_hat[M_INDEX])
        cmd = geo.geometric(x[0], x[1], R, x[3], ref[:3], E1, self.gains, m, inertia_matrix(theta_hat),
                            self.airframe.gravity)
        s = (x[1] - ref[1]) + self.c * (x[0] - ref[0])
        return LawStep(thrusts(self.airframe, cmd.f, cmd.M), np.zeros(len(self.names)), s, ref[2])


@dataclass
class GeometricAdaptiveLaw(FlightLaw):
    """The sliding adaptive law on the translational dynamics (adaptive_mj.laws.geometric.adaptive_force) with the
    geometric attitude loop: m̂' = −sᵀw/γ_m, d̂' = s/γ_d (the project's γ is a stiffness: rate = regressor · s / γ),
    through the dead-zone and the robust modifications (σ, e-modification on ‖s‖, projection)."""

    k: float = 0.1
    dead_zone: DeadZone | None = None
    modification: Modification | None = None
    adapt: bool = True

    def __post_init__(self):
        super().__post_init__()
        mod = self.modification
        self._mod = mod.arrays(len(self.names)) if mod is not None else None
        self.bounds = mod.box(len(self.names)) if mod is not None else None

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        g = self.airframe.gravity
        m_hat, d_hat = float(theta_hat[M_INDEX]), theta_hat[D_SLICE]
        e_x, e_v = x[0] - ref[0], x[1] - ref[1]
        s = e_v + self.c * e_x
        w = ref[2] - self.c * e_v + g * geo.E3
        F = m_hat * w - d_hat - self.k * s
        cmd = self._command(F, rotation(x[2]), x[3], inertia_matrix(theta_hat))
        rate = np.zeros(len(self.names))
        dz = self.dead_zone
        if dz is None or dead_zone_open(float(np.linalg.norm(s) if dz.on.value == "s" else np.linalg.norm(e_x)),
                                        dz.width):
            rate[M_INDEX] = -float(s @ w) / self.gamma[M_INDEX]
            rate[D_SLICE] = s / self.gamma[D_SLICE]
        if self._mod is not None:
            sigma, e_mod, theta0, lower, upper = self._mod
            modify_rate(rate, theta_hat, float(np.linalg.norm(s)), sigma, e_mod, theta0, self.gamma, lower, upper)
        return LawStep(thrusts(self.airframe, cmd.f, cmd.M), rate, s, ref[2])


@dataclass
class L1GeometricLaw(FlightLaw):
    """The geometric controller plus L1 augmentation (adaptive_mj.laws.l1): the predictor, the piecewise-constant
    adaptation and the low-pass filter advance once per physics step (step_ends, from the state measured at the
    step's start and the thrusts applied over it: T_s = the physics step), so the augmentation is held over each
    step's stages. Continuous control only (its filters integrate per step)."""

    a_s: float = -5.0
    w_c: float = 5.0
    has_filters: bool = True

    def __post_init__(self):
        super().__post_init__()
        self.state: l1.L1State | None = None
        self._theta: np.ndarray | None = None

    def reset(self) -> None:
        self.state = None

    def step_begins(self, x) -> None:
        if self.state is None:
            self.state = l1.L1State.start(np.array(x[1]), np.array(x[3]))
        self._x0 = np.array(x)

    def __call__(self, t, x, ref, theta_hat) -> LawStep:
        R = rotation(x[2])
        m, J = float(theta_hat[M_INDEX]), inertia_matrix(theta_hat)
        self._theta = theta_hat
        cmd = geo.geometric(x[0], x[1], R, x[3], ref[:3], E1, self.gains, m, J, self.airframe.gravity)
        f, M = cmd.f, cmd.M
        if self.state is not None:
            f_ad, M_ad = l1.augmentation(self.state, R, m, J)
            f, M = f + f_ad, M + M_ad
        s = (x[1] - ref[1]) + self.c * (x[0] - ref[0])
        return LawStep(thrusts(self.airframe, f, M), np.zeros(len(self.names)), s, ref[2])

    def step_ends(self, xs, us, weights, h) -> None:
        """One L1 update over the step: the predictor from the step's first measured state and applied thrusts."""
        assert self.state is not None and self._theta is not None
        x0 = xs[0]
        fm = self.airframe.allocation @ np.asarray(us[0], dtype=float)
        th = self._theta
        gains = l1.L1Gains(self.a_s, h, self.w_c)
        self.state = l1.step(self.state, x0[1], x0[3], rotation(x0[2]), float(fm[0]), fm[1:], float(th[M_INDEX]),
                             inertia_matrix(th), self.airframe.gravity, gains, h)


# --- the law kinds: keys, readers, builders -----------------------------------------------
KX = Key("kx", "number", "N/m", 0.195, "> 0", "position gain k_x (geometric, l1_geometric)")
KV = Key("kv", "number", "N s/m", 0.12, "> 0", "velocity gain k_v (geometric, l1_geometric)")
KR = Key("kR", "number", "N m/rad", 7.8e-3, "> 0", "attitude gain k_R")
KW = Key("kW", "number", "N m s/rad", 6.7e-4, "> 0", "body-rate gain k_Omega")
LAMBDA = Key("lambda", "number", "1/s", 1.625, "> 0", "the surface's slope c: s = e_v + c e_x")
K = Key("k", "number", "N s/m", 0.12, "> 0", "the gain on s in the force law F = m_hat w - d_hat - k s")
GAMMA_M = Key("gamma_m", "number", "m² kg⁻¹ s⁻²", 800.0, "> 0",
              "the mass estimate's adaptation stiffness (rate = -s.w / gamma_m)")
GAMMA_D = Key("gamma_d", "number", "m/N", 1000.0, "> 0",
              "the disturbance force estimate's adaptation stiffness (rate = s / gamma_d)")
A_S = Key("a_s", "number", "1/s", -5.0, "< 0", "the L1 state predictor's pole")
W_C = Key("w_c", "number", "rad/s", 5.0, "> 0", "the L1 low-pass filter's cut-off")

ATTITUDE_KEYS = (KR, KW)


def _read(own: tuple[Key, ...], *, adaptive: bool):
    def read(t, kind: str, plant, order: int) -> LawSpec:
        params = {}
        for key in own:
            if key.name == "a_s":
                params[key.name] = t.number(key.name, key.default, lt=0)
            else:
                params[key.name] = t.number(key.name, key.default, gt=0)
        dead_zone = shared.read_dead_zone(t) if adaptive else None
        initial = shared.read_estimates(t, "initial_estimates")
        nominal = shared.read_estimates(t, "nominal")
        robust = shared.read_robust(t, kind, adaptive=adaptive, composite=False, presets=())
        t.finish()
        return LawSpec(kind=kind, order=4, lam=params.get("lambda"), k=float(params.get("k", 0.0)), gamma=None,
                       dead_zone=dead_zone, initial_estimates=initial, nominal=nominal, K=None, boundary_layer=None,
                       robust=robust, params=params)

    return read


def _gains(p: dict) -> geo.Gains:
    return geo.Gains(p.get("kx", KX.default), p.get("kv", KV.default), p["kR"], p["kW"])


def _build_geometric(ctx: BuildContext):
    p = ctx.law.params or {}
    return GeometricLaw(ctx.airframe(), _gains(p), p["kx"] / p["kv"])


def _build_adaptive(ctx: BuildContext):
    p = ctx.law.params or {}
    af = ctx.airframe()
    gamma = np.ones(len(af.names))
    gamma[M_INDEX], gamma[D_SLICE] = p["gamma_m"], p["gamma_d"]
    return GeometricAdaptiveLaw(af, _gains(p), p["lambda"], gamma=gamma, k=p["k"], dead_zone=ctx.dead_zone(),
                                modification=ctx.modification)


def _build_l1(ctx: BuildContext):
    p = ctx.law.params or {}
    return L1GeometricLaw(ctx.airframe(), _gains(p), p["kx"] / p["kv"], a_s=p["a_s"], w_c=p["w_c"])


def _keys(own: tuple[Key, ...], adaptive: bool) -> tuple[Key, ...]:
    return (shared.KIND, *own, *((shared.DEAD_ZONE,) if adaptive else ()), shared.INITIAL_ESTIMATES, shared.NOMINAL,
            *shared.ROBUST)


GEOMETRIC_OWN = (KX, KV, KR, KW)
ADAPTIVE_OWN = (LAMBDA, K, GAMMA_M, GAMMA_D, KR, KW)
L1_OWN = (KX, KV, KR, KW, A_S, W_C)

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
    module=__name__, example=("quadrotor_hover_payload", ("law.kind='l1_geometric'",))))

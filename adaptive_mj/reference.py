"""Desired trajectories y_d(t) with their time derivatives.

A reference is called as ``ref(t, order)`` and returns the array
``[y_d, y_d', ..., y_d^(order)]`` of shape (order+1,) for scalar t, or
(order+1, len(t)) for an array of times. Units follow the plant's output
(m for the heave vehicle, rad for the arm); derivatives are per second^k.

All derivatives are exact (closed form). Note the lecture's slip: for
y_d = cos t it sets ddy_d = cos t; the correct value, used here, is -cos t.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _harmonic(t, amplitude, omega, phase, order, base):
    """Derivatives 0..order of amplitude*base(omega*t + phase), base in {np.cos, np.sin}.

    Exact cycle: cos -> -sin -> -cos -> sin (and sin -> cos -> -sin -> -cos),
    times omega^k.
    """
    arg = omega * np.asarray(t, dtype=float) + phase
    c, s = np.cos(arg), np.sin(arg)
    cycle = (c, -s, -c, s) if base is np.cos else (s, c, -s, -c)
    return np.array([amplitude * omega**k * cycle[k % 4] for k in range(order + 1)])


@dataclass(frozen=True)
class Constant:
    """y_d = value (a setpoint: not persistently exciting)."""

    value: float = 0.0

    def __call__(self, t, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros((order + 1,) + t.shape)
        out[0] = self.value
        return out


@dataclass(frozen=True)
class _Harmonic:
    """y_d = offset + amplitude*base(omega*t + phase), base = cos or sin.  omega [rad/s], phase [rad]."""

    amplitude: float = 1.0
    omega: float = 1.0
    phase: float = 0.0
    offset: float = 0.0
    _base = staticmethod(np.cos)

    def __call__(self, t, order: int) -> np.ndarray:
        out = _harmonic(t, self.amplitude, self.omega, self.phase, order, self._base)
        out[0] += self.offset
        return out


@dataclass(frozen=True)
class Cosine(_Harmonic):
    """y_d = offset + amplitude*cos(omega*t + phase).  omega [rad/s], phase [rad]."""

    _base = staticmethod(np.cos)


@dataclass(frozen=True)
class Sine(_Harmonic):
    """y_d = offset + amplitude*sin(omega*t + phase).  omega [rad/s], phase [rad]."""

    _base = staticmethod(np.sin)


@dataclass(frozen=True)
class SumOfSines:
    """y_d = offset + sum_i amplitudes[i]*sin(omegas[i]*t + phases[i]).

    With at least as many distinct frequencies as half the number of unknown
    parameters this is persistently exciting for the regressors used here.
    """

    amplitudes: tuple[float, ...] = (0.5, 0.3, 0.2)
    omegas: tuple[float, ...] = (0.7, 1.9, 3.1)
    phases: tuple[float, ...] = (0.0, 0.0, 0.0)
    offset: float = 0.0

    def __post_init__(self):
        if not (len(self.amplitudes) == len(self.omegas) == len(self.phases)):
            raise ValueError("SumOfSines: amplitudes, omegas and phases must have the same length")

    def __call__(self, t, order: int) -> np.ndarray:
        out = sum(
            _harmonic(t, a, w, p, order, np.sin)
            for a, w, p in zip(self.amplitudes, self.omegas, self.phases, strict=True)
        )
        out = np.array(out, dtype=float)
        out[0] += self.offset
        return out


def _smoothstep_poly(smoothness: int) -> np.polynomial.Polynomial:
    """Polynomial S on [0, 1]: S(0)=0, S(1)=1, derivatives 1..smoothness vanish at both ends.

    S'(x) is proportional to x^m (1-x)^m with m = smoothness.
    """
    m = smoothness
    P = np.polynomial.Polynomial
    dS = P([0, 1]) ** m * P([1, -1]) ** m
    S = dS.integ()
    return S / S(1.0)


_SMOOTHSTEP = _smoothstep_poly(4)  # C^4: enough for laws up to order n = 4


@dataclass(frozen=True)
class SmoothStep:
    """Setpoint change from `start` to `end` beginning at t0 [s], lasting rise_time [s].

    The blend is a degree-9 polynomial whose first four derivatives vanish at
    both ends, so y_d is C^4 (continuous derivatives for laws up to n = 4).
    """

    start: float = 0.0
    end: float = 1.0
    t0: float = 1.0
    rise_time: float = 2.0

    def __call__(self, t, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        x = np.clip((t - self.t0) / self.rise_time, 0.0, 1.0)
        inside = (t > self.t0) & (t < self.t0 + self.rise_time)
        out = np.zeros((order + 1,) + t.shape)
        S = _SMOOTHSTEP
        span = self.end - self.start
        out[0] = self.start + span * S(x)
        for k in range(1, order + 1):
            S = S.deriv()
            out[k] = np.where(inside, span * S(x) / self.rise_time**k, 0.0)
        return out


@dataclass(frozen=True)
class ModelResponse:
    """y_m: the response of MRAC's reference model y_m^(n) + α_{n-1} y_m^(n-1) + ... + α_0 y_m = β r,
    started at rest (y_m and its n-1 derivatives 0 at t = 0), to the command
    r(t) = offset + sum_i amplitudes[i]*sin(omegas[i]*t + phases[i]); exact, closed form.

    alpha: (n,) [α_0, ..., α_{n-1}], the polynomial's roots distinct and in the left half-plane;
    beta: gain. y_m = steady state (β r through G(s) = β / (s^n + ...), each sine by G(jω)) plus the
    free response Σ c_j e^{λ_j t} that brings it to rest at t = 0; derivative k of each term is
    exact ((jω)^k, λ_j^k), so every order asked for is exact."""

    alpha: tuple[float, ...]
    beta: float
    offset: float = 0.0
    amplitudes: tuple[float, ...] = ()
    omegas: tuple[float, ...] = ()
    phases: tuple[float, ...] = ()
    _gains: tuple = field(default=(), init=False, repr=False, compare=False)  # G(jω) per sine (__post_init__)
    _free: tuple = field(default=(), init=False, repr=False, compare=False)  # (λ, c): the free response's terms

    def __post_init__(self):
        if not (len(self.amplitudes) == len(self.omegas) == len(self.phases)):
            raise ValueError("ModelResponse: amplitudes, omegas and phases must have the same length")
        lam = self.poles()
        if np.any(lam.real >= 0) or len(np.unique(np.round(lam, 12))) != len(lam):
            raise ValueError(f"ModelResponse: the reference model's poles must be distinct and stable, got {lam}")
        # what every call would compute again from the same numbers (the same floats: a cache, not a change):
        # G(jω) of each sine, the poles λ and the free response's coefficients c
        object.__setattr__(self, "_gains", tuple(self._gain(1j * w) for w in self.omegas))
        n = len(self.alpha)
        vander = np.array([lam**k for k in range(n)])
        c = np.linalg.solve(vander, -np.array([self._steady(0.0, k) for k in range(n)], dtype=complex))
        object.__setattr__(self, "_free", (lam, c))

    def poles(self) -> np.ndarray:
        """λ (n,): roots of s^n + α_{n-1} s^{n-1} + ... + α_0."""
        return np.roots(np.concatenate([[1.0], np.asarray(self.alpha, dtype=float)[::-1]]))

    def _gain(self, s):
        """G(s) = β / (s^n + α_{n-1} s^{n-1} + ... + α_0)."""
        return self.beta / np.polyval(np.concatenate([[1.0], np.asarray(self.alpha, dtype=float)[::-1]]), s)

    def _steady(self, t, k: int):
        """k-th derivative of the steady-state response at t."""
        out = np.zeros(np.shape(t)) + (self.beta * self.offset / self.alpha[0] if k == 0 else 0.0)
        for a, w, p, g in zip(self.amplitudes, self.omegas, self.phases, self._gains, strict=True):
            out = out + a * np.imag((1j * w) ** k * g * np.exp(1j * (w * np.asarray(t) + p)))
        return out

    def __call__(self, t, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        lam, c = self._free  # the free response Σ c_j e^{λ_j t}: Σ c_j λ_j^k = -steady^(k)(0), k < n
        out = np.empty((order + 1,) + t.shape)
        for k in range(order + 1):
            free = sum(cj * lj**k * np.exp(lj * t) for cj, lj in zip(c, lam, strict=True))
            out[k] = self._steady(t, k) + np.real(free)
        return out

    def scalar_rows(self, t, order: int) -> np.ndarray:
        """(order+1, T): [y_m, ..., y_m^(order)] at each of the times t (T,) [s], bit for bit what T calls
        `self(float(t_i), order)` give, in one vectorised pass (the compiled analytic loop's references,
        adaptive_mj.sim.native_chunk). An array call of __call__ is not that: numpy multiplies complex
        arrays with fused multiply-adds, complex scalars without, so here every complex product is written
        out in real arrays as numpy's scalar arithmetic computes it ((a+bi)(c+di) = (ac - bd) + (ad + bc)i,
        a complex times a real component by component); the constants (1jω)^k G(jω) and c_j λ_j^k are the
        scalar path's own numbers, and np.exp gives the same bits on arrays as on scalars (tested:
        tests/test_native_analytic.py)."""
        t = np.ascontiguousarray(t, dtype=float).reshape(-1)
        lam, c = self._free
        out = np.empty((order + 1,) + t.shape)
        for k in range(order + 1):
            # _steady(t, k), its arithmetic in the scalar path's order
            steady = np.zeros(t.shape) + (self.beta * self.offset / self.alpha[0] if k == 0 else 0.0)
            for a, w, p, g in zip(self.amplitudes, self.omegas, self.phases, self._gains, strict=True):
                K = (1j * w) ** k * g
                E = np.exp(1j * (w * t + p))
                steady = steady + a * (K.real * E.imag + K.imag * E.real)  # imag(K E)
            # free = sum(c_j λ_j^k e^{λ_j t}): Python's sum from 0, a complex scalar times a real or complex array
            re: np.ndarray | int = 0
            for cj, lj in zip(c, lam, strict=True):
                Kj = cj * lj**k
                Ej = np.exp(lj * t)
                if np.iscomplexobj(Ej):
                    term_re = Kj.real * Ej.real - Kj.imag * Ej.imag
                else:
                    term_re = Kj.real * Ej
                re = re + term_re
            out[k] = steady + re
        return out


# --------------------------------------------------------------------------
# Joint-space references for an arm of m joints.
#
# Called as ``ref(t, order)``; return shape ``(order+1,) + np.shape(t) + (m,)``:
# (order+1, m) for a scalar t, (order+1, T, m) for t of shape (T,). Row k holds
# the k-th time derivative [rad/s^k, or m/s^k for slide joints], exact.
# Times are evaluated as one flat array whatever the shape of t, so a scalar
# call gives bit for bit the same numbers as the matching entry of an array call.
# --------------------------------------------------------------------------


def _check_order(cls: str, order, max_order: int | None = None) -> int:
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 0:
        raise ValueError(f"{cls}: order must be a non-negative integer, got {order!r}")
    if max_order is not None and order > max_order:
        raise ValueError(
            f"{cls}: order must be at most {max_order} (derivatives beyond "
            f"{max_order} are not continuous), got {order}")
    return int(order)


def _float_tuple(cls: str, field: str, value, length: int | None = None) -> tuple[float, ...]:
    """`value` as a tuple of finite floats (optionally of a given length), else ValueError naming `field`."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{cls}: {field} must be a sequence of numbers, got {value!r}") from None
    if arr.ndim != 1:
        raise ValueError(f"{cls}: {field} must be a flat sequence of numbers, got shape {arr.shape}")
    if length is not None and arr.shape[0] != length:
        raise ValueError(f"{cls}: {field} must have length {length}, got length {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{cls}: {field} must be finite, got {value!r}")
    return tuple(float(v) for v in arr)


def _flat_times(t) -> tuple[np.ndarray, tuple[int, ...]]:
    t = np.asarray(t, dtype=float)
    return np.ascontiguousarray(t.reshape(-1)), t.shape


@dataclass(frozen=True)
class JointSumOfSines:
    """Per joint i: q_d,i(t) = center[i] + sum_k amplitudes[i][k]*sin(omegas[i][k]*t + phases[i][k]).

    center: m positions [rad or m]; amplitudes, omegas [rad/s], phases [rad]:
    m tuples each (joint i may have its own number of terms, the same in all
    three). phases=None means all zeros. Sequences are stored as tuples.
    """

    center: tuple[float, ...]
    amplitudes: tuple[tuple[float, ...], ...]
    omegas: tuple[tuple[float, ...], ...]
    phases: tuple[tuple[float, ...], ...] | None = None

    def __post_init__(self):
        cls = type(self).__name__
        center = _float_tuple(cls, "center", self.center)
        m = len(center)
        if m == 0:
            raise ValueError(f"{cls}: center must have at least one joint, got length 0")

        def per_joint(field, value, lengths=None):
            try:
                n = len(value)
            except TypeError:
                raise ValueError(f"{cls}: {field} must be a sequence of {m} per-joint sequences "
                                 f"(one per entry of center), got {value!r}") from None
            if isinstance(value, (str, bytes)) or n != m:
                raise ValueError(f"{cls}: {field} must have {m} per-joint sequences "
                                 f"(one per entry of center), got {n}")
            return tuple(
                _float_tuple(cls, f"{field}[{i}]", row, None if lengths is None else lengths[i])
                for i, row in enumerate(value))

        amplitudes = per_joint("amplitudes", self.amplitudes)
        lengths = [len(a) for a in amplitudes]
        omegas = per_joint("omegas", self.omegas, lengths)
        phases = (tuple((0.0,) * n for n in lengths) if self.phases is None
                  else per_joint("phases", self.phases, lengths))
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "amplitudes", amplitudes)
        object.__setattr__(self, "omegas", omegas)
        object.__setattr__(self, "phases", phases)

    @property
    def m(self) -> int:
        """Number of joints."""
        return len(self.center)

    def __call__(self, t, order: int) -> np.ndarray:
        order = _check_order(type(self).__name__, order)
        tf, shape = _flat_times(t)
        out = np.zeros((order + 1, tf.size, self.m))
        phases = self.phases
        assert phases is not None  # __post_init__ stores zeros for None
        for i in range(self.m):
            joint = sum(
                (_harmonic(tf, a, w, p, order, np.sin)
                 for a, w, p in zip(self.amplitudes[i], self.omegas[i], phases[i], strict=True)),
                np.zeros((order + 1, tf.size)))
            joint[0] += self.center[i]
            out[:, :, i] = joint
        return out.reshape((order + 1,) + shape + (self.m,))


@dataclass(frozen=True)
class JointWaypoints:
    """Point-to-point moves through waypoints, each move a C^4 smooth step.

    waypoints: K >= 2 poses of m joints [rad or m]; durations: K-1 positive
    move times [s]. The arm rests at waypoints[0] until t0 [s], moves from
    waypoints[j] to waypoints[j+1] during durations[j] along the degree-9
    polynomial _SMOOTHSTEP (first four derivatives zero at both ends), and
    rests at waypoints[-1] afterwards. Every move starts and ends at rest, so
    consecutive moves join C^4; derivatives are exact up to order 4.

    cycle=True repeats the moves forever after t0 with period sum(durations);
    it requires waypoints[-1] == waypoints[0].
    """

    waypoints: tuple[tuple[float, ...], ...]
    durations: tuple[float, ...]
    t0: float = 0.0
    cycle: bool = False

    MAX_ORDER = 4  # class constant (not a field): _SMOOTHSTEP is C^4

    def __post_init__(self):
        cls = type(self).__name__
        try:
            K = len(self.waypoints)
        except TypeError:
            raise ValueError(f"{cls}: waypoints must be a sequence of poses, got {self.waypoints!r}") from None
        if K < 2:
            raise ValueError(f"{cls}: waypoints must hold at least 2 poses, got {K}")
        first = _float_tuple(cls, "waypoints[0]", self.waypoints[0])
        m = len(first)
        if m == 0:
            raise ValueError(f"{cls}: waypoints[0] must have at least one joint, got length 0")
        waypoints = (first,) + tuple(
            _float_tuple(cls, f"waypoints[{j}]", w, m) for j, w in enumerate(self.waypoints) if j > 0)
        try:
            nd = len(self.durations)
        except TypeError:
            raise ValueError(f"{cls}: durations must be a sequence of {K - 1} move times, "
                             f"got {self.durations!r}") from None
        if nd != K - 1:
            raise ValueError(f"{cls}: durations must have {K - 1} entries (one per move between "
                             f"{K} waypoints), got {nd}")
        durations = _float_tuple(cls, "durations", self.durations, K - 1)
        if not all(d > 0.0 for d in durations):
            raise ValueError(f"{cls}: durations must all be positive, got {durations}")
        t0 = float(self.t0)
        if not np.isfinite(t0):
            raise ValueError(f"{cls}: t0 must be finite, got {self.t0!r}")
        if not isinstance(self.cycle, (bool, np.bool_)):
            raise ValueError(f"{cls}: cycle must be a bool, got {self.cycle!r}")
        if self.cycle and waypoints[-1] != waypoints[0]:
            raise ValueError(f"{cls}: cycle=True needs waypoints[-1] == waypoints[0], "
                             f"got {waypoints[-1]} and {waypoints[0]}")
        object.__setattr__(self, "waypoints", waypoints)
        object.__setattr__(self, "durations", durations)
        object.__setattr__(self, "t0", t0)
        object.__setattr__(self, "cycle", bool(self.cycle))

    @property
    def m(self) -> int:
        """Number of joints."""
        return len(self.waypoints[0])

    @property
    def period(self) -> float:
        """Total time of one pass through the moves, sum(durations) [s]."""
        return float(np.cumsum(self.durations)[-1])

    def __call__(self, t, order: int) -> np.ndarray:
        order = _check_order(type(self).__name__, order, self.MAX_ORDER)
        tf, shape = _flat_times(t)
        wp = np.array(self.waypoints)                        # (K, m)
        d = np.array(self.durations)                         # (K-1,)
        # absolute move starts: t = t0 + durations[0] hits starts[1] exactly
        cum = np.cumsum(d)
        starts = self.t0 + np.concatenate(([0.0], cum))
        if self.cycle:  # later passes fold back into the first (fmod is exact)
            tf = np.where(tf >= starts[-1], self.t0 + np.fmod(tf - self.t0, cum[-1]), tf)
        # move index j and its local coordinate x (in [0, 1] during the move)
        j = np.clip(np.searchsorted(starts, tf, side="right") - 1, 0, len(d) - 1)
        x = (tf - starts[j]) / d[j]
        before, after = x <= 0.0, x >= 1.0
        inside = ~(before | after)
        x = np.clip(x, 0.0, 1.0)
        span = wp[j + 1] - wp[j]                             # (N, m)
        out = np.zeros((order + 1, tf.size, wp.shape[1]))
        # at rest exactly at the move's start or end pose outside (0, 1)
        out[0] = np.where(before[:, None], wp[j], np.where(after[:, None], wp[j + 1],
                                                             wp[j] + span * _SMOOTHSTEP(x)[:, None]))
        S = _SMOOTHSTEP
        for k in range(1, order + 1):
            S = S.deriv()
            rate = S(x) / d[j] ** k
            out[k] = np.where(inside[:, None], span * rate[:, None], 0.0)
        return out.reshape((order + 1,) + shape + (wp.shape[1],))


@dataclass(frozen=True)
class Waypoints:
    """A 1-DOF output through set-points, each move a C^4 smooth step (JointWaypoints of one joint):
    rests at waypoints[0] until t0 [s], moves to waypoints[j+1] during durations[j] [s], rests at the
    last. A repeated value holds it (e.g. a ship's course changes: [0, 0.17, 0.17, -0.17] rad)."""

    waypoints: tuple[float, ...]
    durations: tuple[float, ...]
    t0: float = 0.0
    joint: JointWaypoints | None = field(init=False, repr=False, compare=False, default=None)

    def __post_init__(self):
        object.__setattr__(self, "joint", JointWaypoints(waypoints=tuple((float(w),) for w in self.waypoints),
                                                         durations=tuple(self.durations), t0=self.t0))

    def __call__(self, t, order: int) -> np.ndarray:
        assert self.joint is not None  # set in __post_init__
        return self.joint(t, order)[..., 0]


@dataclass(frozen=True)
class Flight:
    """A flying body's position reference p_d(t) (3,) [m]: a climb from `start` to `center` (a C⁴ SmoothStep
    from t = 0 over rise_time [s]; none when start is None), plus a figure-eight (lemniscate of Gerono) about
    `center` in the horizontal plane, x = A sin(ω t), y = (A/2) sin(2 ω t), from t0 [s] on (A = amplitude [m],
    ω = omega [rad/s]; A = 0: hover). Called as ref(t, order) -> (order+1, 3) for scalar t, (order+1, N, 3) for
    an array of N times: [p_d, p_d', ..., p_d^(order)] per axis x, y, z; every derivative exact.

    The figure-eight starts at its centre moving at (A ω, A ω, 0): a run that starts on the reference at t0 = 0
    starts with that velocity (simulation.initial_state = "reference")."""

    center: tuple[float, float, float] = (0.0, 0.0, 1.0)
    amplitude: float = 0.0
    omega: float = 1.0
    start: tuple[float, float, float] | None = None
    rise_time: float = 2.0
    t0: float = 0.0

    def __post_init__(self):
        if len(tuple(self.center)) != 3 or (self.start is not None and len(tuple(self.start)) != 3):
            raise ValueError("center and start are positions (x, y, z) [m]")
        if not self.omega > 0 or not self.rise_time > 0 or self.amplitude < 0:
            raise ValueError("omega and rise_time must be > 0, amplitude >= 0")

    def __call__(self, t, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.zeros((order + 1,) + t.shape + (3,))
        out[0] = self.center
        if self.start is not None:  # the climb: one blend S(τ), τ = t/rise_time, for the three axes
            span = np.asarray(self.center, dtype=float) - np.asarray(self.start, dtype=float)
            x = np.clip(t / self.rise_time, 0.0, 1.0)
            inside = (t > 0.0) & (t < self.rise_time)
            derivs = _smoothstep_derivatives(order)
            out[0] = np.asarray(self.start, dtype=float) + np.multiply.outer(derivs[0](x), span)
            for k in range(1, order + 1):
                out[k] = np.multiply.outer(np.where(inside, derivs[k](x) / self.rise_time**k, 0.0), span)
        if self.amplitude > 0:
            moving = (t >= self.t0).astype(float)
            tau = t - self.t0
            out[..., 0] += moving * _harmonic(tau, self.amplitude, self.omega, 0.0, order, np.sin)
            out[..., 1] += moving * _harmonic(tau, 0.5 * self.amplitude, 2.0 * self.omega, 0.0, order, np.sin)
        return out


_DERIVATIVES: list = []


def _smoothstep_derivatives(order: int) -> list:
    """[S, S', ..., S^(order)] of the C⁴ blend (computed once)."""
    while len(_DERIVATIVES) <= order:
        _DERIVATIVES.append(_SMOOTHSTEP if not _DERIVATIVES else _DERIVATIVES[-1].deriv())
    return _DERIVATIVES


@dataclass(frozen=True)
class MotionPrimitive:
    """A flying body's position reference p_d(t) (3,) [m]: AdaptiveQuadBench's random motion primitive
    (valmik/AdaptiveQuadBench, aqb/config/randomization_config.py, create_trajectories: RotorPy's RapidTrajectory,
    Mueller, Hehn & D'Andrea, "A computationally efficient motion primitive for quadrocopter trajectory
    generation", IEEE T-RO 31(6), 2015). It starts at rest at `center` [m] (zero velocity and acceleration) and
    reaches center + position [m] with velocity [m/s] and acceleration [m/s²] (each (3,), world frame) at
    t = duration [s]: per axis the quintic minimising the integral of the squared jerk between those ends,

        p(t) = γ t³/6 + β t⁴/24 + α t⁵/120, with (Δp, Δv, Δa) = (position, velocity, acceleration), T = duration:
        α = (60 T² Δa − 360 T Δv + 720 Δp)/T⁵,  β = (−24 T³ Δa + 168 T² Δv − 360 T Δp)/T⁵,
        γ = (3 T⁴ Δa − 24 T³ Δv + 60 T² Δp)/T⁵.

    Before t = 0 it rests at center; after `duration` it goes on at the end's acceleration (p(T) + v(T) τ + a(T) τ²/2,
    τ = t − T: continuous up to the acceleration; AdaptiveQuadBench's runs end at T). Called as ref(t, order) ->
    (order+1, 3) for scalar t, (order+1, N, 3) for N times; every derivative exact."""

    center: tuple[float, float, float] = (0.0, 0.0, 1.0)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    acceleration: tuple[float, float, float] = (0.0, 0.0, 0.0)
    duration: float = 5.0

    def __post_init__(self):
        for name in ("center", "position", "velocity", "acceleration"):
            if len(tuple(getattr(self, name))) != 3:
                raise ValueError(f"{name} is a vector (x, y, z)")
        if not self.duration > 0:
            raise ValueError("duration must be > 0")

    def coefficients(self) -> np.ndarray:
        """(6, 3): the quintic's coefficients c_k of t^k per axis (c_0 = center, c_1 = c_2 = 0)."""
        T = float(self.duration)
        dp, dv, da = (np.asarray(v, dtype=float) for v in (self.position, self.velocity, self.acceleration))
        alpha = (60 * T**2 * da - 360 * T * dv + 720 * dp) / T**5
        beta = (-24 * T**3 * da + 168 * T**2 * dv - 360 * T * dp) / T**5
        gamma = (3 * T**4 * da - 24 * T**3 * dv + 60 * T**2 * dp) / T**5
        c = np.zeros((6, 3))
        c[0] = self.center
        c[3], c[4], c[5] = gamma / 6.0, beta / 24.0, alpha / 120.0
        return c

    def __call__(self, t, order: int) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        T = float(self.duration)
        c = self.coefficients()
        polys = [np.polynomial.Polynomial(c[:, i]) for i in range(3)]
        s = np.clip(t, 0.0, T)  # on the primitive (and at rest before it)
        out = np.zeros((order + 1,) + t.shape + (3,))
        for i, p in enumerate(polys):
            d = [p.deriv(k) if k else p for k in range(3)]  # p, p', p'' at T: the extension past it
            end = [float(q(T)) for q in d]
            tau = np.maximum(t - T, 0.0)
            after = t > T
            for k in range(order + 1):
                on = (p.deriv(k) if k else p)(s)
                if k:
                    on = np.where(t < 0.0, 0.0, on)
                ext = ([end[0] + end[1] * tau + 0.5 * end[2] * tau**2, end[1] + end[2] * tau,
                        np.full(t.shape, end[2])][k] if k < 3 else np.zeros(t.shape))
                out[k, ..., i] = np.where(after, ext, on)
        return out

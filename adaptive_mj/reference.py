"""Desired trajectories y_d(t) with their time derivatives.

A reference is called as ``ref(t, order)`` and returns the array
``[y_d, y_d', ..., y_d^(order)]`` of shape (order+1,) for scalar t, or
(order+1, len(t)) for an array of times. Units follow the plant's output
(m for the heave vehicle, rad for the arm); derivatives are per second^k.

All derivatives are exact (closed form). Note the lecture's slip: for
y_d = cos t it sets ddy_d = cos t; the correct value, used here, is -cos t.
"""
from __future__ import annotations

from dataclasses import dataclass

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
            for a, w, p in zip(self.amplitudes, self.omegas, self.phases)
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

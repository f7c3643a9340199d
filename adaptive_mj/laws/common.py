"""Pieces shared by the laws: the step result, the dead-zone, gain checks, the records of their
compiled gains."""
from __future__ import annotations

import dataclasses
import enum
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from adaptive_mj.laws.pseudo_inertia import body_record, project_bodies


class LawStep(NamedTuple):
    """One evaluation of a law.

    u: control before saturation [N or N*m]; theta_hat_dot: (n_theta,)
    estimate derivative [units of theta / s]; s: sliding variable
    [units of y^(n-1)]; s_r_dot: reference derivative of s. On a plant of m
    joints u, s and s_r_dot (there q̈_r) are (m,) arrays.
    """

    u: float | np.ndarray
    theta_hat_dot: np.ndarray
    s: float | np.ndarray
    s_r_dot: float | np.ndarray


_RECORD_TYPES = {"float": np.float64, "bool": np.bool_, "int": np.int64}


def record_dtype(cls: type) -> np.dtype:
    """The numpy structured dtype of a dataclass of scalars (fields annotated float, bool or int), one
    field per dataclass field, by name and in its order. A law's gains dataclass is the contract by name
    between the law and its compiled code: the Python path reads the dataclass's attributes, the compiled
    callback the same names as fields of a record of this dtype (adaptive_mj.plants.one_dof_kernel reads it through
    its address)."""
    out = []
    for f in dataclasses.fields(cls):
        kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
        if kind not in _RECORD_TYPES:
            raise TypeError(f"{cls.__name__}.{f.name}: a record field is a float, bool or int, not {kind!r}")
        out.append((f.name, _RECORD_TYPES[kind]))
    return np.dtype(out, align=True)


def as_record(gains: Any, dtype: np.dtype) -> np.ndarray:
    """(1,) array of `dtype` (record_dtype of gains' class) holding gains' values, field by field (a float
    is stored as the float64 it is: the compiled code reads the same bits the Python path uses)."""
    out = np.zeros(1, dtype=dtype)
    for name in dtype.names or ():
        out[name] = getattr(gains, name)
    return out


class Gains:
    """Base of a law's gains dataclass (fields of float, bool or int): `record()` is its values as the (1,) record
    of `record_dtype` of its class, which the compiled callbacks read by name through its address."""

    def record(self) -> np.ndarray:
        """(1,) record_dtype(type(self)) array of these values (the dtype made once per class)."""
        cls = type(self)
        if cls not in _DTYPES:
            _DTYPES[cls] = record_dtype(cls)
        return as_record(self, _DTYPES[cls])


_DTYPES: dict[type, np.dtype] = {}


def dead_zone_open(signal: float, width: float) -> bool:
    """The dead-zone of every law: adaptation is on while |signal| >= width (off while
    |signal| < width; width 0 never stops it). signal: s for the 1-DOF laws with the
    lecture's formula (DeadZoneOn.S), ‖s‖ (Euclidean norm) for Slotine–Li, ỹ = y_d - y
    (‖q̃‖ for Slotine–Li, x̃ for the first-order law) with the lecture's code
    (DeadZoneOn.TRACKING_ERROR). A NaN signal never adapts.

    The one place the boundary is decided: DeadZone.adapting, laws.sliding.sliding_law,
    laws.slotine_li.slotine_li_output and the first-order law call it (the laws as a
    module global, so that adaptive_mj.sim.native_mujoco compiles it with them: plain scalar
    code, numba nopython)."""
    return abs(signal) >= width


class DeadZoneOn(enum.Enum):
    """Which signal switches adaptation off when it is small."""

    S = "s"  # the lecture's formula: adapt only while |s| >= eps
    TRACKING_ERROR = "tracking_error"  # the lecture's code: adapt only while |y_d - y| >= eps


@dataclass(frozen=True)
class DeadZone:
    """Adaptation is off while |signal| < width.  width: same unit as the signal."""

    width: float
    on: DeadZoneOn = DeadZoneOn.S

    def __post_init__(self):
        if not (np.isfinite(self.width) and self.width >= 0):
            raise ValueError(f"dead-zone width must be finite and >= 0, got {self.width}")

    def adapting(self, s: float, y_tilde: float) -> bool:
        return dead_zone_open(s if self.on is DeadZoneOn.S else y_tilde, self.width)


def as_gamma(gamma, n_theta: int) -> np.ndarray:
    """Scalar or per-parameter adaptation gain -> (n_theta,) array, all > 0."""
    g = np.broadcast_to(np.asarray(gamma, dtype=float), (n_theta,)).copy()
    if not np.all(np.isfinite(g)) or np.any(g <= 0):
        raise ValueError(f"gamma must be finite and > 0, got {gamma}")
    return g


@dataclass(frozen=True)
class Modification:
    """Robust modifications of an adaptive law's estimate rate (docs/THEORY.md, "Robust adaptation").

    With Γ⁻¹ = 1/gamma (the project's gains are adaptation "stiffnesses") and θ₀ a prior:
      sigma:  σ-modification, θ̂' = (law's θ̂') − σ Γ⁻¹ (θ̂ − θ₀)            σ [gamma-units / s]
      e_mod:  e-modification, θ̂' = (law's θ̂') − ν |s| Γ⁻¹ (θ̂ − θ₀)        ν [gamma-units / (s · unit of s)]
      lower, upper: (n_theta,) box of the parameter projection (±inf where free): the rate
        is cut where it would leave the box, and every estimate (each RK4 stage's and each
        step's) is clipped into it, so θ̂ never leaves [lower, upper].
      theta0: (n_theta,) the prior θ₀ the leakage pulls toward.
      bodies: the indices in θ̂ of each rigid body's m whose ten parameters are kept physically consistent
        (law.projection = "consistent", adaptive_mj.laws.pseudo_inertia): after the box's clip, every stage's
        and step's estimate of each such body is projected, in the metric of Γ, onto {π : J(π) ⪰ 0}. The
        arrays the loop clips with (`box`, `arrays`) then carry that projection's record after their first
        n_theta entries (pseudo_inertia.body_record, built from the law's Γ).
    For the manipulator law |s| is the Euclidean norm ‖s‖.
    """

    sigma: float = 0.0
    e_mod: float = 0.0
    theta0: np.ndarray | None = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    bodies: tuple[int, ...] = ()

    def __post_init__(self):
        for name in ("sigma", "e_mod"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
        if self.lower is not None and self.upper is not None:
            lo, hi = np.asarray(self.lower, dtype=float), np.asarray(self.upper, dtype=float)
            if lo.shape != hi.shape or np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
                raise ValueError(f"projection bounds must satisfy lower <= upper, got {lo} and {hi}")

    @property
    def leaks(self) -> bool:
        return self.sigma > 0.0 or self.e_mod > 0.0

    def box(self, n_theta: int, gamma=None) -> tuple[np.ndarray, np.ndarray] | None:
        """(lower, upper) of the projection, or None without one: a law's `bounds`, into which the loop clips
        (clip_into) every stage's and step's estimate; each (n_theta,), or with `bodies` (n_theta + record,)
        (see `arrays`; gamma: the law's Γ, (n_theta,) or a scalar)."""
        if self.lower is None and self.upper is None and not self.bodies:
            return None
        return self.arrays(n_theta, gamma=gamma)[3:]

    def arrays(self, n_theta: int, theta_hat0=None, *,
               gamma=None) -> tuple[float, float, np.ndarray, np.ndarray, np.ndarray]:
        """(sigma, e_mod, theta0, lower, upper) as the compiled laws take them: θ₀ defaults to
        theta_hat0 (else zeros), the box to (-inf, inf). With `bodies`, lower and upper each go on past
        n_theta with the physically consistent projection's record (pseudo_inertia.body_record of the
        bodies and the law's Γ = gamma; None: ones); every loop over the box stops at n_theta."""
        th0 = self.theta0 if self.theta0 is not None else theta_hat0
        th0 = np.zeros(n_theta) if th0 is None else np.array(th0, dtype=float).reshape(n_theta)
        lo = np.full(n_theta, -np.inf) if self.lower is None else np.array(self.lower, dtype=float).reshape(n_theta)
        hi = np.full(n_theta, np.inf) if self.upper is None else np.array(self.upper, dtype=float).reshape(n_theta)
        if self.bodies:
            g = np.broadcast_to(np.asarray(1.0 if gamma is None else gamma, dtype=float), (n_theta,))
            record = body_record(self.bodies, g)
            lo, hi = np.concatenate((lo, record)), np.concatenate((hi, record))
        return float(self.sigma), float(self.e_mod), th0, lo, hi


NO_MODIFICATION = Modification()


def modify_rate(rate, theta, s_abs, sigma, e_mod, theta0, gamma, lower, upper):
    """Apply leakage and projection to an estimate rate, in place (plain loops: numba compiles it).

    rate_i -= (σ + ν |s|) (θ̂_i − θ₀_i) / γ_i;  then rate_i = 0 where θ̂_i <= lower_i and
    rate_i < 0, or θ̂_i >= upper_i and rate_i > 0 (the box's tangent cone)."""
    leak = sigma + e_mod * s_abs
    for i in range(rate.shape[0]):
        if leak != 0.0:
            rate[i] -= leak * (theta[i] - theta0[i]) / gamma[i]
        if theta[i] <= lower[i] and rate[i] < 0.0:
            rate[i] = 0.0
        elif theta[i] >= upper[i] and rate[i] > 0.0:
            rate[i] = 0.0


def clip_into(theta, lower, upper):
    """Clip θ̂ into [lower, upper] in place (a no-op with infinite bounds); where lower goes on past n_theta (a
    Modification with `bodies`), then each of those bodies projected onto its physically consistent set
    (pseudo_inertia.project_bodies, the record at lower[n_theta:])."""
    n = theta.shape[0]
    for i in range(n):
        if theta[i] < lower[i]:
            theta[i] = lower[i]
        elif theta[i] > upper[i]:
            theta[i] = upper[i]
    if lower.shape[0] > n:
        project_bodies(theta, lower, n)


def plugin_rate(rate, theta, s_abs, signal, adapt, dz_width, sigma, e_mod, theta0, gamma, lower, upper):
    """What every law plugin's estimate rate goes through after the plugin wrote it (in place; plain loops,
    compiled with the plugin): zero when the law does not adapt (a baseline) or the dead-zone is closed
    (dead_zone_open(signal, dz_width); signal |s| or ‖s‖, or |ỹ| / ‖q̃‖), then the leakage and the
    projection's tangent cone (modify_rate with |s| = s_abs and Γ = gamma). With no dead-zone, no leakage
    and no box this changes nothing."""
    if not adapt or not dead_zone_open(signal, dz_width):
        for i in range(rate.shape[0]):
            rate[i] = 0.0
    if adapt:
        modify_rate(rate, theta, s_abs, sigma, e_mod, theta0, gamma, lower, upper)

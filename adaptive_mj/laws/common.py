"""Pieces shared by the laws: the step result, the dead-zone, gain checks."""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class LawStep(NamedTuple):
    """One evaluation of a law.

    u: control before saturation [N or N*m]; theta_hat_dot: (n_theta,)
    estimate derivative [units of theta / s]; s: sliding variable
    [units of y^(n-1)]; s_r_dot: reference derivative of s.
    """

    u: float
    theta_hat_dot: np.ndarray
    s: float
    s_r_dot: float


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
        signal = s if self.on is DeadZoneOn.S else y_tilde
        return abs(signal) >= self.width


def as_gamma(gamma, n_theta: int) -> np.ndarray:
    """Scalar or per-parameter adaptation gain -> (n_theta,) array, all > 0."""
    g = np.broadcast_to(np.asarray(gamma, dtype=float), (n_theta,)).copy()
    if not np.all(np.isfinite(g)) or np.any(g <= 0):
        raise ValueError(f"gamma must be finite and > 0, got {gamma}")
    return g

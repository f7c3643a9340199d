"""Results are data: a run is a Trajectory of arrays (live or replayed)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Trajectory:
    """One run, sampled at the start of every recorded physics step.

    t: (N,) time [s]
    x: (N, n) true plant state [y, y', ..., y^(n-1)] (y in m or rad)
    u: (N,) applied control (after saturation) held over the step [N or N*m]
    s: (N,) sliding variable; for the first-order law s = x̃
    ref: (N, n+1) reference [y_d, ..., y_d^(n)]
    theta_hat: (N, n_theta) estimates; theta: (N, n_theta) true values
    V: (N,) the law's Lyapunov function
    names: parameter names, len n_theta
    status: "ok", "diverged", "interrupted", "failed" or "truncated"
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    s: np.ndarray
    ref: np.ndarray
    theta_hat: np.ndarray
    theta: np.ndarray
    V: np.ndarray
    names: tuple[str, ...]
    status: str = "ok"
    reason: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def q(self) -> np.ndarray:
        """(N,) output y [m or rad]."""
        return self.x[:, 0]

    @property
    def qd(self) -> np.ndarray:
        """(N,) output rate y' (n >= 2), else the reference-free finite difference of y."""
        if self.x.shape[1] >= 2:
            return self.x[:, 1]
        return np.gradient(self.x[:, 0], self.t) if len(self.t) > 1 else np.zeros(len(self.t))

    @property
    def y_tilde(self) -> np.ndarray:
        """(N,) tracking error y_d - y."""
        return self.ref[:, 0] - self.x[:, 0]

    @property
    def theta_tilde(self) -> np.ndarray:
        """(N, n_theta) estimate error θ̂ - θ."""
        return self.theta_hat - self.theta

    def __len__(self) -> int:
        return len(self.t)

"""Results are data: a run is a Trajectory of arrays (live or replayed)."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Status(enum.StrEnum):
    """A run's verdict (and a study row's outcome), a closed set. A StrEnum: equal to its text, which is what
    logs, JSON summaries and CSV rows hold, so older logs and rows compare as before.

    OK: completed and met its [success] criteria; FAILED: completed (or stopped by an error) without them;
    DIVERGED: stopped at a non-finite or out-of-bound value or a MuJoCo instability (reason says which);
    INTERRUPTED: stopped by a signal or by reset/close; TRUNCATED: a log never closed (replay recovered its
    rows); ERROR / REFUSED: a study row whose run could not start / whose pre-flight check refused it."""

    OK = "ok"
    FAILED = "failed"
    DIVERGED = "diverged"
    INTERRUPTED = "interrupted"
    TRUNCATED = "truncated"
    ERROR = "error"
    REFUSED = "refused"


@dataclass(frozen=True)
class Trajectory:
    """One run, sampled at the start of every recorded physics step.

    t: (N,) time [s]
    x: (N, n) true plant state [y, y', ..., y^(n-1)] (y in m or rad); for a plant of
       m joints (N, n, m): [q; q̇] per joint, the joints last
    u: (N,) applied control (after saturation) held over the step [N or N*m]; (N, m)
       joint torques for m joints
    s: (N,) sliding variable (for the first-order law s = x̃); (N, m) for m joints
    ref: (N, n+1) reference [y_d, ..., y_d^(n)]; (N, n+1, m) for m joints
    theta_hat: (N, n_theta) estimates; theta: (N, n_theta) true values
    V: (N,) the law's Lyapunov function
    names: parameter names, len n_theta
    joint_names: () for a 1-DOF plant (scalar y and u), else the m joint names
    control_names: the k actuators' names where they are not one per joint (a quadrotor's 4 rotors on its 3
       position axes: u is then (N, k)); () when u has one entry per joint (`actuators`)
    status: a Status: OK, DIVERGED, INTERRUPTED, FAILED or TRUNCATED
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
    status: Status = Status.OK
    reason: str = ""
    joint_names: tuple[str, ...] = ()
    meta: dict = field(default_factory=dict)
    control_names: tuple[str, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "status", Status(self.status))  # a log's text "ok" becomes Status.OK

    @property
    def m(self) -> int:
        """Number of joints (1 for the 1-DOF plants)."""
        return max(1, len(self.joint_names))

    @property
    def actuators(self) -> tuple[str, ...]:
        """The names of u's entries: control_names, else the joint names (() on a 1-DOF plant)."""
        return self.control_names or self.joint_names

    @property
    def q(self) -> np.ndarray:
        """(N,) output y [m or rad]; (N, m) for m joints."""
        return self.x[:, 0]

    @property
    def joint_errors(self) -> np.ndarray:
        """(N, m) tracking error per joint (m = 1 for the 1-DOF plants)."""
        y = self.y_tilde
        return y[:, None] if y.ndim == 1 else y

    @property
    def qd(self) -> np.ndarray:
        """(N,) output rate y' (n >= 2), else the reference-free finite difference of y; (N, m) for m joints."""
        if self.x.shape[1] >= 2:
            return self.x[:, 1]
        return np.gradient(self.x[:, 0], self.t, axis=0) if len(self.t) > 1 else np.zeros_like(self.x[:, 0])

    @property
    def y_tilde(self) -> np.ndarray:
        """(N,) tracking error y_d - y; (N, m) for m joints."""
        return self.ref[:, 0] - self.x[:, 0]

    @property
    def theta_tilde(self) -> np.ndarray:
        """(N, n_theta) estimate error θ̂ - θ."""
        return self.theta_hat - self.theta

    def __len__(self) -> int:
        return len(self.t)

"""Results are data: a run is a Trajectory of arrays (live or replayed)."""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np


class Status(enum.StrEnum):
    """A run's verdict (and a study row's outcome), a closed set: every way a run ends is one of these. A StrEnum:
    equal to its text, which is what logs, JSON summaries and CSV rows hold, so older logs and rows compare as before.

    OK: completed and met its [success] criteria; FAILED: completed (or stopped by an error) without them;
    CRASHED: the vehicle hit the ground or tipped over (a quadrotor: plants.quadrotor.crash_check), the run cut
    short there, its reason saying when and how ("crashed at t = … s: …"; before log format 9 such a run closed as
    FAILED with that reason, which replay reads as CRASHED: `ending`); DIVERGED: stopped at a non-finite or
    out-of-bound value or a MuJoCo instability (reason says which); INTERRUPTED: stopped by a signal or by
    reset/close; TRUNCATED: a log never closed (replay recovered its rows); NOT_RUN: a study's row that was not
    run, its reason saying why. ERROR / REFUSED: a study row whose run could not start / whose pre-flight check
    refused it (kept as they are, so older rows read as before: both are rows not run, for those two reasons).

    A run *completed* (ran to its end, every row there) when it is OK or FAILED; every other ending is a failure
    of the run whatever its figures (CLI exit codes and studies count CRASHED as they count FAILED)."""

    OK = "ok"
    FAILED = "failed"
    CRASHED = "crashed"
    DIVERGED = "diverged"
    INTERRUPTED = "interrupted"
    TRUNCATED = "truncated"
    NOT_RUN = "not run"
    ERROR = "error"
    REFUSED = "refused"


#: How a crash's reason begins (plants.quadrotor.crash_text): "crashed at t = … s: …". Logs before format 9 closed a
#: crash as "failed" with such a reason; `ending` reads them as CRASHED.
CRASH_REASON_PREFIX = "crashed at"


def ending(status: str, reason: str) -> Status:
    """The Status of a run that ended with `status` and `reason`, as this version names it: a "failed" run whose
    reason is a crash's (CRASH_REASON_PREFIX, as logs and rows written before Status.CRASHED have it) is CRASHED;
    any other status is itself."""
    if status == Status.FAILED and str(reason).startswith(CRASH_REASON_PREFIX):
        return Status.CRASHED
    return Status(status)


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
    status: a Status: OK, FAILED, CRASHED, DIVERGED, INTERRUPTED or TRUNCATED
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

"""A run's outcome as a study judges it: RunOutcome, a typed view of one JobResult (its status, its summary's
figures and its analyses), and `passes`, the one predicate every study's pass or fail goes through (the breaking
points of the stress study, the scorecard and the control-rate section by a tail bound; the quadrotor's flight
margins by a position-error bound; the bench's quadrotor tasks).

A run passes when it completed (status "ok" or "failed": it ran to its end, so its figures are the whole run's;
the scenario's own [success] verdict does not enter), so did not crash, diverge, or stop interrupted, refused or
in error, and each bound given holds. A crash fails whatever its figures: the tail of a run cut short is not the
tail of the run.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from adaptive_mj.study.job import JobResult
from adaptive_mj.trajectory import Status, ending

#: Endings of a run that ran to its end, every row there: judged by their figures, whatever the scenario's verdict.
COMPLETED = (Status.OK, Status.FAILED)

#: The summary metrics that hold the tail RMS tracking error, in the order read: the 1-DOF one [m or rad] (on a
#: plant with joints the RMS over every joint's error), then the RMS of the joint error norm |q̃| [rad or m].
TAIL_METRICS = ("rms_tracking_error_tail", "rms_tracking_error_norm_tail")


def _finite_or_inf(value: float | None) -> float:
    """A summary's or an analysis's figure as a float, inf where it is absent (None) or not finite."""
    v = math.inf if value is None else float(value)
    return v if math.isfinite(v) else math.inf


@dataclass(frozen=True)
class RunOutcome:
    """One run's ending and the figures studies judge it by.

    status: its Status (a "failed" run whose reason is a crash's, as older rows have it, reads as CRASHED:
    trajectory.ending); reason: why it ended so ("" for an ok run; a run that never ran: its error);
    summary: the run's summary (None when it did not run or was stopped before one); extras: the analyses its job
    asked for (study.job.EXTRAS: name -> result)."""

    status: Status
    reason: str = ""
    summary: dict | None = None
    extras: dict = field(default_factory=dict)

    @classmethod
    def of(cls, result: JobResult) -> RunOutcome:
        """The outcome of a study's run."""
        reason = result.error if result.summary is None else str(result.summary.get("reason") or "")
        return cls(ending(result.status, reason), reason, result.summary, result.extras)

    @property
    def completed(self) -> bool:
        """It ran to its end (status ok or failed, its summary there): not crashed, diverged, interrupted, refused
        or in error."""
        return self.status in COMPLETED and self.summary is not None

    @property
    def crashed(self) -> bool:
        """Its vehicle hit the ground or tipped over (a quadrotor), cutting the run short."""
        return self.status == Status.CRASHED

    @property
    def tail_error(self) -> float:
        """The tail RMS tracking error [m or rad] (TAIL_METRICS: the 1-DOF one, else the joint-norm one); inf when
        the run did not complete or the figure is absent or not finite."""
        if not self.completed:
            return math.inf
        metrics = (self.summary or {}).get("metrics") or {}
        return _finite_or_inf(next((metrics[k] for k in TAIL_METRICS if metrics.get(k) is not None), None))

    @property
    def max_position_error(self) -> float:
        """The largest position error ‖p_d − p‖ over the run [m] (the flight_metrics analysis, a quadrotor's); inf
        where the run has no such analysis or its figure is not finite."""
        return _finite_or_inf((self.extras.get("flight_metrics") or {}).get("max_error"))

    @property
    def predicted_unstable(self) -> bool:
        """The run's pre-flight check found its loop past the stability limit (its summary's `preflight`)."""
        pre = (self.summary or {}).get("preflight") or {}
        return bool(pre.get("checked")) and pre.get("ok") is False


def passes(result: JobResult, *, tail_bound: float | None = None, max_error: float | None = None) -> bool:
    """Whether a study's run passes: it completed (so did not crash) and each bound given holds: its tail RMS
    tracking error at most tail_bound [m or rad] (RunOutcome.tail_error), its largest position error at most
    max_error [m] (RunOutcome.max_position_error). None: that bound is not asked."""
    run = RunOutcome.of(result)
    return (run.completed and not run.crashed
            and (tail_bound is None or run.tail_error <= tail_bound)
            and (max_error is None or run.max_position_error <= max_error))

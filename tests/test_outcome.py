"""A study's run as one typed outcome (study.job.RunOutcome) and the one predicate every study judges it by
(`passes`): completed (ok or failed) and not crashed, each bound given held; a run's every ending a Status."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from adaptive_mj.study.job import JobResult, RunOutcome, RunSpec, as_expected, passes
from adaptive_mj.trajectory import Status, ending

JOB = RunSpec(Path("x.toml"))
CRASH = "crashed at t = 0.744 s: hit the ground at 1.63 m/s (its centre 0.0313 m up)"


def _result(status: str, reason: str = "", *, tail=0.01, norm=None, max_error=None, preflight=None,
            summary: bool = True, expect: str = "ok") -> RunOutcome:
    metrics = {"rms_tracking_error_tail": tail}
    if norm is not None:
        metrics["rms_tracking_error_norm_tail"] = norm
    s = {"status": status, "reason": reason, "metrics": metrics, **({"preflight": preflight} if preflight else {})}
    extras = {} if max_error is None else {"flight_metrics": {"max_error": max_error}}
    return RunOutcome(RunSpec(JOB.scenario, expect=expect), status, s if summary else None, extras,
                     error="" if summary else "the log could not be written")


@pytest.mark.parametrize("status, completed", [(Status.OK, True), (Status.FAILED, True), (Status.CRASHED, False),
                                               (Status.DIVERGED, False), (Status.INTERRUPTED, False)])
def test_only_a_run_that_ran_to_its_end_passes(status, completed):
    r = _result(status, CRASH if status == Status.CRASHED else "")
    run = r
    assert run.completed is completed and run.crashed is (status == Status.CRASHED)
    assert passes(r) is completed and passes(r, tail_bound=0.02) is completed
    assert run.tail_error == (0.01 if completed else math.inf)


def test_a_run_that_never_ran_fails_and_says_why():
    for status in (Status.ERROR, Status.REFUSED, Status.NOT_RUN):
        r = _result(status, summary=False)
        run = r
        assert not run.completed and not passes(r) and run.reason == "the log could not be written"
        assert run.tail_error == math.inf and run.max_position_error == math.inf and not run.predicted_unstable


def test_an_older_row_s_crash_reads_as_crashed():
    """Before Status.CRASHED a crash was "failed" with a crash's reason: the same outcome, failing whatever its tail."""
    assert ending("failed", CRASH) == Status.CRASHED and ending("failed", "tail RMS 0.3 > 0.02") == Status.FAILED
    assert ending("diverged", CRASH) == Status.DIVERGED
    r = _result(Status.FAILED, CRASH, tail=1e-6)
    assert r.status == Status.CRASHED and r.crashed
    assert not passes(r, tail_bound=1.0)


def test_the_tail_bound_reads_the_1dof_tail_else_the_joint_norm_one():
    assert passes(_result(Status.OK, tail=0.02), tail_bound=0.02)
    assert not passes(_result(Status.OK, tail=0.021), tail_bound=0.02)
    assert _result(Status.OK, tail=None, norm=0.03).tail_error == 0.03  # absent (null): the norm's
    assert _result(Status.OK, tail=None).tail_error == math.inf  # neither: no tail, a failure
    assert not passes(_result(Status.OK, tail=None), tail_bound=1.0)
    assert passes(_result(Status.OK, tail=None))  # no bound asked: completed is enough


def test_the_position_error_bound_reads_the_flight_metrics():
    assert passes(_result(Status.FAILED, max_error=0.99), max_error=1.0)  # failed by its scenario: still judged
    assert not passes(_result(Status.OK, max_error=1.01), max_error=1.0)
    assert not passes(_result(Status.OK), max_error=1.0)  # no flight_metrics analysis: inf
    assert not passes(_result(Status.CRASHED, CRASH, max_error=0.1), max_error=1.0)
    both = _result(Status.OK, tail=0.05, max_error=0.5)
    assert passes(both, tail_bound=0.1, max_error=1.0) and not passes(both, tail_bound=0.01, max_error=1.0)


def test_the_pre_flight_prediction():
    assert _result(Status.OK, preflight={"checked": True, "ok": False}).predicted_unstable
    assert not _result(Status.OK, preflight={"checked": True, "ok": True}).predicted_unstable
    assert not _result(Status.OK, preflight={"checked": False, "ok": False}).predicted_unstable


def test_a_run_meant_to_fail_that_crashed_ended_as_expected():
    assert as_expected(_result(Status.CRASHED, CRASH, expect="fail")) is True
    assert as_expected(_result(Status.CRASHED, CRASH, expect="ok")) is False
    assert as_expected(_result(Status.CRASHED, CRASH, expect="measured")) is None


def test_a_run_s_spec_and_outcome_keep_their_names_from_before_0_2_0():
    """Job and JobResult (the names before 0.2.0) are RunSpec and RunOutcome: a plugin's or a script's import still
    works, and an outcome made with the old status text of a crash reads as crashed."""
    from adaptive_mj.study.job import Job

    assert Job is RunSpec and JobResult is RunOutcome
    old = JobResult(Job(Path("x.toml")), "failed", {"status": "failed", "reason": CRASH, "metrics": {}})
    assert old.status is Status.CRASHED and old.crashed and old.reason == CRASH and old.spec is old.job

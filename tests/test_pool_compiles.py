"""A study's workers compile, overlapped with runs (issue 51: a cold bench took one core to compile while the other
waited): the parent loads only what numba's cache holds (parallel._prewarm), and a scenario file whose controller
is not there is compiled by its first run, in a worker, while its other runs wait and the other workers run other
files' runs (parallel._Held)."""
from __future__ import annotations

import json
import os
import time
from collections import deque
from pathlib import Path

import pytest

from adaptive_mj.study import parallel
from adaptive_mj.study.job import RunOutcome, RunSpec

FIRST_S, OTHER_S = 0.8, 0.1  # [s] a file's first run (its compile) and each other run, in the fake worker


def _fake_run(job: RunSpec) -> RunOutcome:
    """A run that takes FIRST_S for seed 0 (as a run that compiles) and OTHER_S otherwise, and writes when it ran
    (and in which process) to its `log` path: module level, so that the pool can send it to its forked workers."""
    t0 = time.monotonic()
    time.sleep(FIRST_S if job.seed == 0 else OTHER_S)
    assert job.log is not None
    job.log.write_text(json.dumps({"start": t0, "end": time.monotonic(), "pid": os.getpid()}))
    return RunOutcome(job, "ok", None)


def _jobs(tmp_path: Path) -> list[RunSpec]:
    return [RunSpec(Path(f"{name}.toml"), seed=k, log=tmp_path / f"{name}{k}.json") for name in ("a", "b")
            for k in range(3)]


def _times(tmp_path: Path, jobs: list[RunSpec]) -> dict[str, dict]:
    return {f"{j.scenario.stem}{j.seed}": json.loads(j.log.read_text()) for j in jobs}  # type: ignore[union-attr]


@pytest.mark.parametrize("unknown", [False, True])
def test_a_file_s_runs_wait_for_its_first_run_s_compile_while_another_file_runs(tmp_path, monkeypatch, unknown):
    """Six runs of two files (a0 a1 a2 b0 b1 b2) on two workers, with nothing in the parent's cache: a0 and b0
    (each compiling its file's controller) run side by side, a1 and a2 start only after a0 ended, b1 and b2 after
    b0; every run is yielded once. Where the parent knows nothing (fork missing, or a test that turns the head
    start off: _prewarm gives None) they go in order, a1 beside a0."""
    monkeypatch.setattr(parallel, "_run_in_pool_worker", _fake_run)
    monkeypatch.setattr(parallel, "_prewarm", (lambda jobs, n_jobs=1: lambda job: job.scenario) if not unknown else
                        (lambda jobs, n_jobs=1: None))
    jobs = _jobs(tmp_path)
    got = sorted(i for i, _ in parallel._iter_local_pool(jobs, 2))
    assert got == list(range(6))
    t = _times(tmp_path, jobs)
    if not unknown:
        assert t["b0"]["start"] < t["a0"]["end"] and t["a0"]["start"] < t["b0"]["end"]  # side by side
        assert t["a0"]["pid"] != t["b0"]["pid"]
        for k in (1, 2):
            assert t[f"a{k}"]["start"] >= t["a0"]["end"], k
            assert t[f"b{k}"]["start"] >= t["b0"]["end"], k
    else:
        assert t["a1"]["start"] < t["a0"]["end"]  # nothing held back


def test_held_runs_keep_their_order_and_go_back_when_the_pool_breaks():
    """_Held by hand, each file standing for its controller (c's loaded): the first run of a controller still to
    compile compiles it, its later runs wait (in order) and come first once it is back; a run put back goes before
    the runs that wait for it; a broken pool (release) frees every controller, so its next run compiles it; a spare
    run for an idle worker, and its return frees its controller."""
    jobs = [RunSpec(Path(n)) for n in ("a", "a", "b", "a", "c", "b")]
    held = parallel._Held(deque(range(6)), jobs, lambda job: None if job.scenario == Path("c") else job.scenario)
    assert held.next() == 0  # a's compiler
    assert held.next() == 2  # b's compiler; 1 waits
    assert held.next() == 4  # c is ready; 3 and 5 wait
    assert held.next() is None and bool(held)
    held.finished(0)  # a compiled: 1 and 3 first, in order
    assert [held.next(), held.next()] == [1, 3]
    held.put_back(2)  # b's compiler not submitted (the pool broke): first again, then b's waiting run
    assert [held.next(), held.next()] == [2, None]
    held.release()  # the pool broke while 2 compiled: 5 is back, and compiles b
    assert held.next() == 5 and held.next() is None and not held.order
    held.finished(4)  # a ready file's run: nothing changes
    assert held.compiler == {Path("b"): 5}
    more = parallel._Held(deque(range(4)), [RunSpec(Path(n)) for n in ("a", "a", "a", "b")], lambda job: job.scenario)
    assert [more.next(), more.next(), more.next()] == [0, 3, None]
    assert more.spare() == 1  # for a worker that would idle: a's first waiting run
    more.finished(1)  # a spare run of a came back: a is compiled (it waited for the compile), 2 goes next
    assert more.next() == 2 and more.compiler == {Path("b"): 3}
    assert more.spare() is None and not more

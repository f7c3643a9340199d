"""numba_util.cache_lock: one process at a time compiles or loads a function of numba's disk cache (numba's cache is
not safe for processes that save the same function at once: numba issue 4807). Reentrant in a process; a forked
child waits for its parent's hold (it opens a file description of its own: one shared with the parent would let
both hold the lock at once); released on exit from the block."""
from __future__ import annotations

import multiprocessing as mp
import time

import pytest

from adaptive_mj import numba_util
from adaptive_mj.numba_util import cache_lock, cache_lock_path, first_call_locked

fcntl = pytest.importorskip("fcntl")


def _take(queue) -> None:
    with cache_lock():
        queue.put(time.monotonic())


def test_a_forked_child_waits_for_the_parents_hold_and_nesting_does_not_deadlock(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert cache_lock_path().startswith(str(tmp_path))
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    with cache_lock():
        with cache_lock():  # reentrant: a compile inside a compile (a callback and the functions it calls)
            child = ctx.Process(target=_take, args=(queue,))
            child.start()  # forked while this process holds the lock
            time.sleep(0.5)
            released = time.monotonic()
    taken = queue.get(timeout=30)
    child.join(30)
    assert child.exitcode == 0
    assert taken >= released  # the child got the lock only after the parent let it go


def test_the_lock_is_free_after_the_block_and_held_inside_it(tmp_path, monkeypatch):
    import os

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))

    def free() -> bool:  # another open file description tries it without waiting
        fd = os.open(cache_lock_path(), os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(fd, fcntl.LOCK_UN)
            return True
        except BlockingIOError:
            return False
        finally:
            os.close(fd)

    with cache_lock():
        assert not free()
    assert free()
    with pytest.raises(ZeroDivisionError), cache_lock():
        1 / 0
    assert free() and numba_util._CACHE_LOCK["depth"] == 0


def test_first_call_locked_calls_under_the_lock_once(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    depths = []

    def fn(x):
        depths.append(numba_util._CACHE_LOCK["depth"])
        return 2 * x

    assert first_call_locked(fn, 3) == 6 and first_call_locked(fn, 4) == 8
    assert depths == [1, 0]

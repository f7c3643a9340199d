"""adaptive_mj.study.beside: work in a forked process beside the parent's (the bench's analyses beside its study)."""
import os

import pytest

from adaptive_mj.errors import AdaptiveMJError
from adaptive_mj.study.beside import Beside, can_fork

needs_fork = pytest.mark.skipif(not can_fork(), reason="fork is not available (or threads run) here")


@needs_fork
def test_value_from_the_child_which_sees_the_parents_memory():
    unpicklable = lambda: os.getpid()  # noqa: E731 (a closure the child inherits: nothing is pickled on the way in)
    parent = os.getpid()
    b = Beside(lambda: (unpicklable(), [1.5, {"a": 2}]))
    assert b.forked
    pid, payload = b.result()
    assert pid != parent and payload == [1.5, {"a": 2}]


@needs_fork
def test_the_childs_exception_is_raised_in_the_parent_with_its_type_and_text():
    def fails():
        raise AdaptiveMJError("section 3: no rows")

    with pytest.raises(AdaptiveMJError, match="section 3: no rows") as info:
        Beside(fails).result()
    assert any("beside the study" in note for note in getattr(info.value, "__notes__", []))


@needs_fork
def test_any_other_exception_is_a_runtime_error_naming_its_class():
    with pytest.raises(RuntimeError, match=r"ZeroDivisionError: division by zero"):
        Beside(lambda: 1 / 0).result()


@needs_fork
def test_a_child_that_dies_is_a_clear_error_not_a_hang():
    with pytest.raises(RuntimeError, match="ended without a result"):
        Beside(lambda: os._exit(3)).result()


def test_fork_false_runs_in_the_parent_when_asked():
    calls = []
    b = Beside(lambda: calls.append(os.getpid()) or "done", fork=False)
    assert not b.forked and calls == []
    assert b.result() == "done" and calls == [os.getpid()]


@needs_fork
def test_cancel_ends_the_child():
    import time

    b = Beside(lambda: time.sleep(60))
    proc = b._proc
    b.cancel()
    assert not proc.is_alive()

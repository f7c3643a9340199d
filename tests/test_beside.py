"""adaptive_mj.study.beside: work in a forked process beside the parent's (the bench's analyses beside its study)."""
import os

import pytest

from adaptive_mj.errors import AdaptiveMJError
from adaptive_mj.study.beside import Beside, can_fork


@pytest.fixture
def forkable():
    """Skips the test unless a child can be forked now. Checked when the test runs, not when the module is imported:
    an earlier test in this process (a Ray session, say) may have left threads running, and Beside then runs fn in
    this process, where the dying child's os._exit would end the test worker itself (pytest-xdist: "node down")."""
    if not can_fork():
        pytest.skip("fork is not available, or other threads run in this process now")


needs_fork = pytest.mark.usefixtures("forkable")


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


def test_with_other_threads_running_the_fork_tests_skip_instead_of_ending_the_process():
    """This file's fork tests in a process where another thread runs (as after a Ray session in the same test worker):
    each skips when it runs, none runs the dying child's os._exit in the process itself (which ended a test worker:
    pytest-xdist's "node down", then a hung run)."""
    import subprocess
    import sys

    code = ("import sys, threading, pytest; e = threading.Event(); "
            "threading.Thread(target=e.wait, daemon=True).start(); "
            f"rc = pytest.main(['-q', '-p', 'no:cacheprovider', '-k', 'not other_threads and not with_its_parent', "
            f"{__file__!r}]); "
            "e.set(); sys.exit(rc)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "1 passed, 5 skipped" in r.stdout, r.stdout[-2000:]


def test_the_child_dies_with_its_parent():
    """A parent killed outright (SIGKILL: no handler of its runs, as at a test's timeout) leaves no child computing on:
    the child sees it within beside.PARENT_POLL_S and exits."""
    import subprocess
    import sys

    from test_signals import alive, assert_gone

    code = ("import time\nfrom adaptive_mj.study.beside import Beside\n"
            "b = Beside(lambda: time.sleep(600), fork=True)\nprint(b._proc.pid, flush=True)\ntime.sleep(600)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        child = int(proc.stdout.readline())
        assert alive(child)
    finally:
        proc.kill()
        proc.wait(timeout=60)
    assert_gone({child}, timeout=5.0)

"""Work done in a forked process beside the parent's own: the bench's section analyses and figures (CPU in one
process) while its breaking-point study keeps the worker processes busy, so no core waits for the other.

The child is forked, so it inherits the parent's memory: the runs' results and the sections' analysis closures
are not copied on the way in. It runs fn(), sends its return value back through a pipe (or its exception's class,
text and traceback), and exits.
Where fork is missing, or other threads run in the parent (a fork copies their locks as they stand: a Ray
session's threads, say), fn() runs in the parent when `result` is asked, as it would without this module.
The child dies with its parent: a parent killed outright (SIGKILL, a test's timeout) leaves no child computing on
(it sees it within PARENT_POLL_S, as a study's workers do) nor one blocked sending a result no one reads.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import signal
import threading
import time
import traceback
from typing import Any, Callable, Generic, TypeVar

T = TypeVar("T")

#: [s] how often the child looks whether its parent is still there
PARENT_POLL_S = 0.2


def can_fork() -> bool:
    """Whether a child can be forked safely now: fork exists and the parent runs no other thread."""
    return "fork" in mp.get_all_start_methods() and threading.active_count() == 1


class Beside(Generic[T]):
    """fn() started in a forked child now (see the module docstring); `result()` waits for its value and raises
    what it raised (adaptive_mj.errors' classes as themselves, any other as a RuntimeError naming it). `cancel()`
    ends the child (a stop signal in the parent). fork=False: fn() runs in the parent, when result() is asked."""

    def __init__(self, fn: Callable[[], T], *, fork: bool | None = None):
        self._fn = fn
        self._proc: Any = None
        if fork is None:
            fork = can_fork()
        if not fork:
            return
        ctx = mp.get_context("fork")
        self._recv, send = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=_child, args=(fn, send, self._recv, os.getpid()), daemon=True)
        self._proc.start()
        send.close()  # the child's end: the parent reads EOF if the child dies before sending

    @property
    def forked(self) -> bool:
        return self._proc is not None

    def result(self) -> T:
        if self._proc is None:
            return self._fn()
        try:
            ok, payload = self._recv.recv()
        except EOFError:
            self._proc.join()
            raise RuntimeError(f"the process running {getattr(self._fn, '__name__', 'the work')} beside the study "
                               f"ended without a result (exit code {self._proc.exitcode})") from None
        except BaseException:  # a stop signal while waiting: the child goes too
            self.cancel()
            raise
        finally:
            self._recv.close()
        self._proc.join()
        self._proc = None
        if ok:
            return payload
        raise _raised(*payload)

    def cancel(self, grace: float = 5.0) -> None:
        """End the child: SIGTERM, and SIGKILL if it has not exited `grace` s later [s]."""
        if self._proc is not None and self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(grace)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
        self._proc = None


def _child(fn: Callable[[], Any], send, recv, parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent takes a stop signal and ends this process
    recv.close()  # the parent's end, inherited: once the parent is gone, a send fails instead of filling the pipe
    threading.Thread(target=_exit_with, args=(parent,), name="adaptive-mj parent watch", daemon=True).start()
    try:
        value = (True, fn())
    except BaseException as exc:  # told to the parent as text (its class by name), which raises it again
        value = (False, (type(exc).__module__, type(exc).__qualname__, str(exc), traceback.format_exc()))
    send.send(value)
    send.close()


def _exit_with(parent: int) -> None:
    """The child's daemon thread: once the parent is gone (this process now belongs to init or a subreaper), end."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(128 + signal.SIGTERM)


def _raised(module: str, name: str, text: str, trace: str) -> BaseException:
    """The child's exception for the parent to raise: one of adaptive_mj.errors' own classes again (a user's
    mistake stays a one-line error), anything else a RuntimeError naming its class; the child's traceback in a
    note."""
    from adaptive_mj import errors

    cls = getattr(errors, name, None) if module == errors.__name__ else None
    exc: BaseException
    if isinstance(cls, type) and issubclass(cls, errors.AdaptiveMJError):
        exc = cls(text)
    else:
        exc = RuntimeError(f"{name}: {text}")
    exc.add_note(f"(raised in the process beside the study)\n{trace}")
    return exc

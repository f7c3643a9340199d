"""SIGINT and SIGTERM as a clean stop.

Inside `stop_on_signals()` (each CLI command; SIGTERM in each bench/sweep worker,
see adaptive_mj.study.parallel) the first of these signals raises errors.Interrupted in
the main thread, where the run is going: loop.run hands the recorder every whole
row and runner.execute closes the log with status "interrupted". Later signals are
ignored, so that closing is never cut short.

A log write runs inside `deferred()`: a signal that comes during it is raised when
the write is done, so a log never holds half a block. `armed()` marks where the
signal may be raised at all (a worker between runs only takes note: see
`requested`).
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Iterable, TypedDict

from adaptive_mj.errors import Interrupted


class _State(TypedDict):
    signum: int | None  # the signal that asked this process to stop
    raised: bool  # errors.Interrupted has been raised for it
    armed: int  # depth of armed() blocks
    deferring: int  # depth of deferred() blocks


# This process's signal state (signal handlers are per process and run in its main thread).
_state: _State = {"signum": None, "raised": False, "armed": 0, "deferring": 0}


def requested() -> int | None:
    """The signal that asked this process to stop, or None."""
    return _state["signum"]


def _raise_if_due() -> None:
    if _state["signum"] is not None and not _state["raised"] and _state["armed"] and not _state["deferring"]:
        _state["raised"] = True
        raise Interrupted(_state["signum"])


def _handler(signum, frame) -> None:
    if _state["signum"] is None:  # a second signal while stopping changes nothing
        _state["signum"] = signum
        _raise_if_due()


@contextmanager
def deferred():
    """A block that a stop signal does not cut: the signal is raised when the block ends."""
    _state["deferring"] += 1
    try:
        yield
    finally:
        _state["deferring"] -= 1
    _raise_if_due()


@contextmanager
def armed():
    """A block where a stop signal raises errors.Interrupted (at once if one came already)."""
    _state["armed"] += 1
    try:
        _raise_if_due()
        yield
    finally:
        _state["armed"] -= 1


def install(signals: Iterable[int]) -> dict:
    """Route `signals` to the stop handler (main thread only); returns the previous handlers."""
    _state.update({"signum": None, "raised": False})
    return {sig: signal.signal(sig, _handler) for sig in signals}


@contextmanager
def stop_on_signals(signals: Iterable[int] = (signal.SIGINT, signal.SIGTERM)):
    """While the block runs, the first of `signals` raises errors.Interrupted (see the module
    docstring); the previous handlers come back afterwards. Outside the main thread, a no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = install(signals)
    try:
        with armed():
            yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)
        _state.update({"signum": None, "raised": False})

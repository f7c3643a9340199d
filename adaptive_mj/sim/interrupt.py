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

Python runs a signal handler at the next bytecode of the main thread, wherever that
is: inside a weakref callback or a `__del__` (numba's compiler runs thousands while it
compiles), an exception the handler raises is printed as "Exception ignored" and
dropped, and the process would go on as if no signal had come (a bench ran to its end,
a worker ran its run to the end while its parent waited). `install` hooks
`sys.unraisablehook`: an Interrupted dropped that way is delivered again, by the same
signal sent to the main thread REDELIVER_S later, until it lands in code that can raise.
Where Python wraps it instead (raised in a class body's `__set_name__`, it becomes a
RuntimeError whose cause it is), `stop_behind` finds it: a run that such an exception
ends is closed as "interrupted", and code that goes on after an ordinary error
(`except Exception`) calls `reraise_stop` first.
"""
from __future__ import annotations

import signal
import sys
import threading
import time
from contextlib import contextmanager
from typing import Callable, Iterable, TypedDict

from adaptive_mj.errors import Interrupted


class _State(TypedDict):
    signum: int | None  # the signal that asked this process to stop
    raised: bool  # errors.Interrupted has been raised for it
    armed: int  # depth of armed() blocks
    deferring: int  # depth of deferred() blocks


# This process's signal state (signal handlers are per process and run in its main thread).
_state: _State = {"signum": None, "raised": False, "armed": 0, "deferring": 0}

#: [s] how long after an Interrupted was dropped (raised inside a weakref callback or a __del__) its signal comes again
REDELIVER_S = 0.01

# unarmed(signum): what a process does with a stop signal that comes outside an armed() block (install's argument)
_unarmed: list[Callable[[int], None]] = []


def requested() -> int | None:
    """The signal that asked this process to stop, or None."""
    return _state["signum"]


def _raise_if_due() -> None:
    if _state["signum"] is not None and not _state["raised"] and _state["armed"] and not _state["deferring"]:
        _state["raised"] = True
        raise Interrupted(_state["signum"])


def stop_behind(exc: BaseException | None) -> Interrupted | None:
    """The Interrupted behind `exc`: exc itself, or one in its chain of causes and contexts (a stop signal whose
    exception Python wrapped, or one during which another error was raised); else, when a stop signal came before
    `exc` was raised, that signal's (exc is its consequence: numba's "no compiled object yet" after a compile the
    signal cut short); None when no stop signal came."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Interrupted):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    if _state["signum"] is not None:
        _state["raised"] = True  # this is its delivery: not again
        return Interrupted(_state["signum"])
    return None


def stop_or(exc: BaseException) -> BaseException:
    """The Interrupted behind `exc` (stop_behind) where there is one, else exc: what a run's except block closes the
    log by and raises (`raise stop from exc` when it is not exc itself)."""
    stop = stop_behind(exc)
    return exc if stop is None else stop


def reraise_stop(exc: BaseException) -> None:
    """Raise the Interrupted behind `exc` (stop_behind) where there is one: for `except Exception` blocks that would
    otherwise go on as after an ordinary error."""
    stop = stop_behind(exc)
    if stop is not None:
        raise stop from exc


def _handler(signum, frame) -> None:
    if _state["signum"] is None:  # a second signal while stopping changes nothing (the first was raised already)
        _state["signum"] = signum
    if not _in_hook(frame):  # raised inside the hook, it would be dropped too: the next delivery raises it
        _raise_if_due()
    if not _state["armed"] and _unarmed:
        _unarmed[0](signum)


def _redeliver_dropped(unraisable) -> None:
    """sys.unraisablehook: an Interrupted raised where Python can only drop it (a weakref callback, a __del__, a
    ctypes callback) is due again: its signal is sent to the main thread REDELIVER_S from now (not from here: the
    handler would run inside this hook, where it would be dropped as well). Anything else goes to the previous hook."""
    if isinstance(unraisable.exc_value, Interrupted) and _state["raised"] and _state["signum"] is not None:
        _state["raised"] = False
        timer = threading.Timer(REDELIVER_S, _deliver_again, (_state["signum"],))
        timer.daemon = True
        timer.start()
        return
    _previous_unraisablehook(unraisable)


#: deliveries at most of one dropped stop (REDELIVER_S apart): one that lands while the hook still runs is skipped
REDELIVER_TRIES = 100


def _in_hook(frame) -> bool:
    """Whether `frame` (where a signal handler interrupted the main thread) runs inside _redeliver_dropped."""
    while frame is not None:
        if frame.f_code is _redeliver_dropped.__code__:
            return True
        frame = frame.f_back
    return False


def _deliver_again(signum: int) -> None:
    """The signal again, to the main thread, every REDELIVER_S while it is still due (not raised since, nor the
    stop over, nor the block that raises it left): a delivery that lands while _redeliver_dropped is still
    starting this thread (seen under load) is not raised there, and the next one raises it in the main code."""
    for _ in range(REDELIVER_TRIES):
        if not (_state["signum"] == signum and not _state["raised"] and _state["armed"]):
            return
        signal.pthread_kill(threading.main_thread().ident or 0, signum)  # the main thread has an ident once started
        time.sleep(REDELIVER_S)


_previous_unraisablehook = sys.unraisablehook


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


def install(signals: Iterable[int], *, unarmed: Callable[[int], None] | None = None) -> dict:
    """Route `signals` to the stop handler (main thread only), and an Interrupted dropped by Python to its second
    delivery (sys.unraisablehook, see the module docstring); returns the previous handlers.

    unarmed(signum): called when one of `signals` comes outside an armed() block (a worker between runs:
    adaptive_mj.study.parallel ends itself there when its parent is gone)."""
    global _previous_unraisablehook
    _state.update({"signum": None, "raised": False})
    _unarmed[:] = [unarmed] if unarmed is not None else []
    if sys.unraisablehook is not _redeliver_dropped:
        _previous_unraisablehook = sys.unraisablehook
        sys.unraisablehook = _redeliver_dropped
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
        sys.unraisablehook = _previous_unraisablehook
        _unarmed.clear()
        _state.update({"signum": None, "raised": False})

"""A run's notes and warnings, the Python way: the "adaptive_mj" logger.

A note (INFO: a model edit made for the run, the integrator kept) or a warning (WARNING: a pre-flight figure)
goes through logging. From Python it goes where the application's logging sends it, nowhere by default
(`logging.basicConfig()` shows them; `run_scenario` is silent otherwise); the command line shows every one on
stderr (show_on_stderr). Nothing else of adaptive_mj is imported here.
"""
from __future__ import annotations

import logging
import sys

#: the logger of a run's notes (INFO) and warnings (WARNING)
log = logging.getLogger("adaptive_mj")
log.addHandler(logging.NullHandler())


def say(line: str, level: int = logging.INFO) -> None:
    """A run's note (INFO) or warning (WARNING), one line, through the "adaptive_mj" logger."""
    log.log(level, line)


class LineHandler(logging.Handler):
    """The command line's handler of the "adaptive_mj" logger: each record one whole line on the stderr of the
    moment, in one write, flushed (a study's worker processes share the stream, and print's two writes, the text
    and then the newline, let another worker's line land between them: two lines merged)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
            sys.stderr.flush()
        except Exception:  # noqa: BLE001 (logging's contract: a handler reports its own failure)
            self.handleError(record)


def show_on_stderr() -> None:
    """The command line's wiring: the run's notes and warnings on stderr (LineHandler at INFO), once."""
    if not any(isinstance(h, LineHandler) for h in log.handlers):
        log.addHandler(LineHandler())
    log.setLevel(logging.INFO)
    log.propagate = False

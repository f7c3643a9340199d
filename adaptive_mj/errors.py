"""The project's error family. Every user-facing failure is one of these.

Messages name the place (file, key), what was expected and what came, e.g.
``scenarios/x.toml: law.gamma must be > 0, got -1``.
"""


class AdaptiveMJError(Exception):
    """Base class: anything the command line reports as a one-line error."""


class ScenarioError(AdaptiveMJError, ValueError):
    """A scenario file or override is invalid (exit code 2)."""


class ModelError(AdaptiveMJError, ValueError):
    """An MJCF model is missing, fails to compile, or lacks what a plant needs."""


class LogFormatError(AdaptiveMJError, ValueError):
    """A file is not a readable adaptive-mj MCAP log."""


class SimulationDiverged(AdaptiveMJError, RuntimeError):
    """A run produced a non-finite or out-of-bound value, or MuJoCo flagged instability."""

    def __init__(self, reason: str, *, t: float):
        super().__init__(f"diverged at t={t:.6g} s: {reason}")
        self.reason = reason
        self.t = t

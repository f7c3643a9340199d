"""The project's error family. Every user-facing failure is one of these.

Messages name the place (file, key), what was expected and what came, e.g.
``scenarios/x.toml: law.gamma must be > 0, got -1``.

A run that diverges is not an exception: divergence is decided per step (adaptive_mj.sim.driver.first_divergence) and
ends the run as data, a Trajectory with status Status.DIVERGED and the reason (adaptive_mj.trajectory).
"""


class AdaptiveMJError(Exception):
    """Base class: anything the command line reports as a one-line error."""


class ScenarioError(AdaptiveMJError, ValueError):
    """A scenario file or override is invalid (exit code 2)."""


class ModelError(AdaptiveMJError, ValueError):
    """An MJCF model is missing, fails to compile, or lacks what a plant needs."""


class PreflightRefused(ScenarioError):
    """The pre-flight check found the run's loop unstable by construction and the scenario (or
    `run --strict`, or a study) asked to refuse such a run (exit code 2; a study row "refused")."""


class LogFormatError(AdaptiveMJError, ValueError):
    """A file is not a readable adaptive-mj MCAP log."""


class PluginError(AdaptiveMJError, RuntimeError):
    """A plugin's own code raised (a law plugin's function): one line naming the plugin, where it comes from
    and what it raised; the run's log is closed as "failed" with that reason."""


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived; the run in progress stops cleanly, its log closed with
    status "interrupted". adaptive_mj.sim.interrupt's handler raises it for both signals (in the
    CLI, and for SIGTERM in bench/sweep workers); loop.run turns a plain KeyboardInterrupt
    into one.

    signum: the signal (2 = SIGINT); trajectory: the rows simulated before it (set by
    loop.run); summary: that run's summary (set by runner.execute once the log is closed);
    note: what was left behind, for the one-line message (set by the command); trajectories: for a
    batch of runs (sim.batch.run_batch), each run's rows or ended trajectory (None: not started);
    finished: how many of a batch's runs had ended before it (their logs closed with their verdicts).
    """

    def __init__(self, signum: int = 2, trajectory=None):
        super().__init__(signum)
        self.signum = signum
        self.trajectory = trajectory
        self.summary: dict | None = None
        self.note = ""
        self.trajectories: list | None = None
        self.finished = 0

    @property
    def signal_name(self) -> str:
        import signal

        try:
            return signal.Signals(self.signum).name
        except ValueError:
            return f"signal {self.signum}"

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for SIGINT, 143 for SIGTERM (the shell's convention)."""
        return 128 + self.signum

    def __str__(self) -> str:
        return f"interrupted by {self.signal_name}"

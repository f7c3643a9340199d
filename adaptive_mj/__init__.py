"""adaptive-mj: the lecture's adaptive laws on MuJoCo physics."""
from importlib.metadata import PackageNotFoundError, version as _version

from adaptive_mj.sim.loop import Event, run
from adaptive_mj.trajectory import Trajectory

try:
    # one source for the version: pyproject.toml's [project] version, read from the installed metadata
    # (written into every log's header as version.adaptive_mj); CHANGELOG.md says what each one changed
    __version__ = _version("adaptive-mj")
except PackageNotFoundError:  # imported from a source tree that pip never installed (PYTHONPATH=...)
    __version__ = "0+unknown"
__all__ = ["run", "run_scenario", "score", "Event", "Trajectory", "__version__"]


def __getattr__(name: str):
    """adaptive_mj.run_scenario and adaptive_mj.score (adaptive_mj.study.api), imported when first used."""
    if name in ("run_scenario", "score"):
        import importlib

        # by name, when called: the study layer sits above everything this package's modules import
        return getattr(importlib.import_module("adaptive_mj.study.api"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

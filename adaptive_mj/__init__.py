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
__all__ = ["run", "Event", "Trajectory", "__version__"]

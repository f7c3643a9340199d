"""Clean virtual environments for the tests that must not depend on what is installed in the interpreter
running them (a user who followed docs/ADDING_A_LAW.md has the example `emod` plugin there).

A clean environment is made with `venv --without-pip`; its third-party dependencies (mujoco, numba, ...)
come read-only from this test environment through a .pth file naming a folder of links, so nothing is
downloaded. That folder links every top-level entry of this environment's site-packages except
adaptive-mj itself and every distribution that registers an adaptive-mj plugin (entry-point groups
adaptive_mj.laws, adaptive_mj.plants): the clean environment holds exactly what its test installs.
"""
from __future__ import annotations

import subprocess
import sys
import sysconfig
from importlib.metadata import distributions
from pathlib import Path, PurePosixPath

PLUGIN_GROUPS = ("adaptive_mj.laws", "adaptive_mj.plants")


def _own_entries(dist) -> set[str]:
    """The top-level names a distribution installed into its site-packages (its modules, packages,
    .pth files and its .dist-info folder)."""
    names = {PurePosixPath(str(f)).parts[0] for f in (dist.files or ())}
    return {n for n in names if n not in ("..", "__pycache__")}


def shared_site_packages(dest: Path, *, sources: list[str] | None = None) -> Path:
    """`dest`, made to hold links to the entries of `sources` (default: this interpreter's purelib and
    platlib) but adaptive-mj's and the plugins' (see the module's doc); .pth files are left out too."""
    dest.mkdir(parents=True, exist_ok=True)
    paths = sysconfig.get_paths()
    for src in dict.fromkeys(sources or [paths["purelib"], paths["platlib"]]):
        hidden: set[str] = set()
        for dist in distributions(path=[src]):
            name = (dist.metadata["Name"] or "").lower().replace("_", "-")
            if name == "adaptive-mj" or any(ep.group in PLUGIN_GROUPS for ep in dist.entry_points):
                hidden |= _own_entries(dist)
        for entry in sorted(Path(src).iterdir()):
            if entry.name in hidden or entry.suffix == ".pth" or entry.name == "__pycache__":
                continue
            if not (dest / entry.name).exists():
                (dest / entry.name).symlink_to(entry)
    return dest


def make_venv(root: Path) -> Path:
    """A new virtual environment at `root` with no pip and no adaptive-mj, seeing this environment's
    third-party dependencies only (shared_site_packages); returns its python."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root)], check=True, timeout=300)
    python = root / "bin" / "python"
    purelib = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  check=True, capture_output=True, text=True).stdout.strip())
    shared = shared_site_packages(root / "shared_dependencies")
    (purelib / "_shared_dependencies.pth").write_text(f"{shared}\n")
    return python


def pip_install(python: Path, *args: str) -> None:
    """This environment's pip installing into the clean environment of `python`, offline."""
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", "--no-index",
                    *args], check=True, timeout=600, capture_output=True)

"""adaptive-mj as a package a researcher installs anywhere (issue 22): the wheel built from this tree holds
the bundled models, payloads and scenarios (package data, found through importlib.resources), and the
command it installs works from any folder, writing logs/ there; pyproject.toml's compatible ranges admit the
exact versions of constraints.txt; the version has one source."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from importlib.metadata import version
from pathlib import Path

import pytest
from clean_env import make_venv, pip_install
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
# what a wheel is built from (tracked files; .venv, logs and caches stay behind)
SOURCES = ("adaptive_mj", "models", "scenarios", "pyproject.toml", "README.md", "LICENSE")


def constraint_pins() -> dict[str, str]:
    """constraints.txt as {canonical name: exact version}."""
    pins = {}
    for line in (REPO / "constraints.txt").read_text().splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, sep, ver = line.partition("==")
            assert sep and ver and not re.search(r"[<>=!~,;\[ ]", ver), f"not an exact pin: {line!r}"
            pins[canonicalize_name(name)] = ver
    return pins


def declared_requirements() -> list[Requirement]:
    project = PYPROJECT["project"]
    extras = [r for group in project["optional-dependencies"].values() for r in group]
    return [Requirement(r) for r in project["dependencies"] + extras]


def test_the_ranges_admit_every_pin_of_the_constraints_file():
    pins = constraint_pins()
    assert len(pins) > 40  # the whole environment, transitive dependencies included
    for req in declared_requirements():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is in pyproject.toml but not pinned in constraints.txt"
        assert req.specifier.contains(pins[name], prereleases=True), \
            f"constraints.txt pins {req.name}=={pins[name]}, outside pyproject.toml's {req}"
        if name != "mujoco":  # ranges, not pins: one version admitted is a pin in disguise
            assert not any(s.operator in ("==", "===") for s in req.specifier), f"{req} is pinned in pyproject.toml"
    (mujoco,) = [r for r in declared_requirements() if r.name == "mujoco"]
    assert str(mujoco.specifier) == "==3.17.0"  # dm-control 1.0.50 breaks on mujoco 4.0.0 (pyproject says why)


def test_the_readme_commands_and_ci_install_the_constraints():
    readme = (REPO / "README.md").read_text()
    for marker in ("<!-- main-command -->", "<!-- test-command -->"):
        block = readme.split(marker, 1)[1].split("```", 2)[1]
        assert "pip install" in block and "-c constraints.txt" in block, (marker, block)
    assert "README.md" in (REPO / ".ci" / "run").read_text()  # CI runs the README's test command


def test_the_version_has_one_source():
    import adaptive_mj

    assert adaptive_mj.__version__ == version("adaptive-mj") == PYPROJECT["project"]["version"], \
        "the installed metadata is older than pyproject.toml: run pip install -c constraints.txt -e '.[test]' again"
    assert re.search(rf"^## {re.escape(adaptive_mj.__version__)} ", (REPO / "CHANGELOG.md").read_text(), re.M)
    typed = re.compile(r"__version__\s*=\s*['\"]\d+\.\d")  # a version literal, e.g. __version__ = "0.1.0"
    sources = [p for p in (REPO / "adaptive_mj").rglob("*.py") if typed.search(p.read_text())]
    assert sources == [], f"a version typed in the code: {sources}"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel of this tree, built offline (no index, no build isolation: the test environment's
    setuptools) from a copy, so the build's own files never land in the checkout."""
    src = tmp_path_factory.mktemp("src")
    for name in SOURCES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name, symlinks=True, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(path, src / name)
    dist = tmp_path_factory.mktemp("dist")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-index", "--no-build-isolation",
                    "-w", str(dist), str(src)], check=True, timeout=300, capture_output=True)
    (found,) = dist.glob("adaptive_mj-*.whl")
    return found


def test_the_wheel_holds_every_bundled_file_and_the_license(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    bundled = [p for folder in ("models", "scenarios") for p in (REPO / folder).rglob("*") if p.is_file()]
    assert len(bundled) >= 18
    for p in bundled:
        assert f"adaptive_mj/data/{p.relative_to(REPO).as_posix()}" in names, f"{p.relative_to(REPO)} not in the wheel"
    dist_info = f"adaptive_mj-{PYPROJECT['project']['version']}.dist-info"
    assert f"{dist_info}/licenses/LICENSE" in names
    metadata = zipfile.ZipFile(wheel).read(f"{dist_info}/METADATA").decode()
    assert "License-Expression: Apache-2.0" in metadata and "Requires-Dist: mujoco==3.17.0" in metadata


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """A fresh virtual environment with the wheel installed (not editable, nothing from the checkout).
    Third-party dependencies are shared read-only from the test environment (tests/clean_env.py: not its
    own adaptive-mj, an editable install, nor any plugin), so nothing is downloaded."""
    root = tmp_path_factory.mktemp("wheel_env")
    pip_install(make_venv(root), str(wheel))
    return root


def command(root: Path, cwd: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """The installed `adaptive-mj` run in `cwd`, with no hint of the checkout (no PYTHONPATH, no ADAPTIVE_MJ_LOGS)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "ADAPTIVE_MJ_LOGS")}
    env["MUJOCO_GL"] = os.environ.get("MUJOCO_GL", "egl")
    return subprocess.run([str(root / "bin" / "adaptive-mj"), *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


# Every run of `bench --quick` loaded and built (stepped by none) in the installed package: each scenario, model and
# payload file it reads is found there; prints the number of runs and of scenario files
CHECK_BENCH_FILES = """
from pathlib import Path
import adaptive_mj
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import check
from adaptive_mj.study.bench_catalogue import catalogue
jobs = [j for s in catalogue(quick=True, logs=Path("logs")) for j in s.jobs]
package = Path(adaptive_mj.__file__).parent
assert all(j.scenario.is_relative_to(package) for j in jobs), [j.scenario for j in jobs]
sources = {}
for j in jobs:
    check(sc.load(j.scenario, overrides=list(j.overrides), seed=j.seed), sources)
print(len(jobs), len({j.scenario for j in jobs}))
"""


def test_the_installed_command_works_from_any_folder(installed, tmp_path):
    """list, run, replay --verify and bench --quick (one section: the wheel is tested, not the bench, which
    tests/test_docs.py runs in full) from a new folder: the bundled scenarios and models come from the installed
    package, and logs/ is created in that folder; every run of the whole `bench --quick` finds its files there."""
    where = subprocess.run([str(installed / "bin" / "python"), "-c", "import adaptive_mj, adaptive_mj.data as d; "
                            "print(adaptive_mj.__file__); print(d.MODELS); print(adaptive_mj.__version__)"],
                           cwd=tmp_path, capture_output=True, text=True, check=True,
                           env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"}).stdout.split()
    assert all(Path(p).is_relative_to(installed) for p in where[:2]), where  # not the checkout
    assert where[2] == PYPROJECT["project"]["version"]

    r = command(installed, tmp_path, "list")
    assert r.returncode == 0, r.stderr
    listed = {line.split()[0] for line in r.stdout.splitlines() if line.strip()}
    assert {p.stem for p in (REPO / "scenarios").glob("*.toml")} <= listed

    # the 1-DOF arm with a bundled payload attached (models/payloads/sphere.xml)
    r = command(installed, tmp_path, "run", "arm_payload_swap", "--set", "simulation.duration=2", "--set", "events=[]")
    assert r.returncode == 0, r.stderr
    (log,) = (tmp_path / "logs").glob("arm_payload_swap-*.mcap")  # ./logs, made by the command
    r = command(installed, tmp_path, "replay", str(log.relative_to(tmp_path)), "--verify")
    assert r.returncode == 0 and "verify: bit-identical" in r.stdout, r.stdout + r.stderr

    r = command(installed, tmp_path, "bench", "--quick", "--only", "first_order", "--jobs", "2")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    (report,) = (tmp_path / "logs").glob("bench-*/report.md")
    assert str(report.relative_to(tmp_path)) in r.stdout
    assert "## 1. Adaptive control of a first-order system" in report.read_text()

    r = subprocess.run([str(installed / "bin" / "python"), "-c", CHECK_BENCH_FILES], cwd=tmp_path, capture_output=True,
                       text=True, timeout=300, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    assert r.returncode == 0, r.stderr[-2000:]
    runs, files = map(int, r.stdout.split())
    assert runs > 200 and files >= 20  # the whole quick catalogue (241 runs, 30 scenario files when written)

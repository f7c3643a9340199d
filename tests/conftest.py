"""Shared fixtures for the adaptive-mj test suite.

Conventions used throughout:
  * every MuJoCo model is compiled *before* any control callback is installed
    (MuJoCo refuses to compile while a Python callback is installed);
  * the autouse fixture below fails a test that leaves mjcb_control installed,
    so one broken test cannot poison the compiles of the next ones;
"""
from __future__ import annotations

import os

# A cold numba cache makes a run say what it compiles on stderr (adaptive_mj.sim.compile_note); whether a variant
# is cached depends on which test ran first, and many tests read a run's stderr line by line. Off here (in this
# process and every process a test starts); tests/test_compile_note.py turns them on where it tests them.
os.environ["ADAPTIVE_MJ_COMPILE_NOTES"] = "0"

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import heave
from adaptive_mj.plants.mujoco_plant import compile_xml_path

# Gains named in the issue (lecture 7 laws on the MuJoCo heave vehicle and arm).
HEAVE_GAINS = dict(lam=5.0, k=200.0, gamma=[0.0025, 0.002, 0.5])
ARM_GAINS = dict(lam=10.0, k=5.0, gamma=[0.16, 0.07, 0.025, 0.075])


@pytest.fixture(autouse=True)
def _no_leaked_control_callback():
    """Every test starts and ends with no MuJoCo control callback installed (and ends with no timer callback)."""
    before = mujoco.get_mjcb_control()
    if before is not None:  # repair so later tests can still compile, then complain
        mujoco.set_mjcb_control(None)
        pytest.fail(f"mjcb_control was left installed before this test: {before!r}")
    yield
    after = mujoco.get_mjcb_control()
    if after is not None:
        mujoco.set_mjcb_control(None)
        pytest.fail(f"this test left mjcb_control installed: {after!r}")
    timer = mujoco.get_mjcb_time()  # plants.mujoco_plant.compiled_control turns MuJoCo's timers off while it steps
    if timer is not None:
        mujoco.set_mjcb_time(None)
        pytest.fail(f"this test left mjcb_time installed: {timer!r}")


@pytest.fixture
def notes_on_stderr():
    """The "adaptive_mj" logger's notes and warnings on stderr, as the command line shows them (adaptive_mj.notes:
    from Python they go where logging sends them, nowhere by default); the logger as it was afterwards."""
    from adaptive_mj import notes

    handlers, level, propagate = list(notes.log.handlers), notes.log.level, notes.log.propagate
    notes.show_on_stderr()
    yield
    notes.log.handlers[:] = handlers
    notes.log.setLevel(level)
    notes.log.propagate = propagate


@pytest.fixture
def heave_gains() -> dict:
    return dict(HEAVE_GAINS)


@pytest.fixture
def arm_gains() -> dict:
    return dict(ARM_GAINS)


@pytest.fixture
def make_heave():
    """Factory: a fresh MuJoCo heave plant; model options are set *before* the
    plant is built (the plant reads the integrator when it is constructed).

    make_heave(viscosity=None, integrator=None, x0=None) -> HeavePlant
    """

    def _make(*, viscosity: float | None = None, integrator=None, x0=None):
        model = compile_xml_path(heave.MODEL_PATH)
        if viscosity is not None:
            model.opt.viscosity = viscosity
        if integrator is not None:
            model.opt.integrator = integrator
        plant = heave.HeavePlant(model)
        if x0 is not None:
            plant.set_state(x0)
        return plant

    return _make


@pytest.fixture
def tail_rms():
    """tail_rms(traj, seconds, t_end=None): RMS of the tracking error y_d - y over
    the last `seconds` before t_end (default: the end of the run)."""

    def _tail(traj, seconds: float, t_end: float | None = None) -> float:
        dt = traj.meta["dt"]
        end = traj.t[-1] + dt if t_end is None else t_end
        sel = (traj.t >= end - seconds - 0.5 * dt) & (traj.t < end - 0.5 * dt)
        assert sel.sum() >= int(round(seconds / dt)) - 1, "window not fully inside the run"
        return float(np.sqrt(np.mean(traj.y_tilde[sel] ** 2)))

    return _tail


# The order in which pytest-xdist hands the test files to its workers (`-n auto --dist loadfile`: one file at a time
# to whichever worker has run out of work). xdist's own order is by the number of tests in a file, so a file of a
# few long tests (the README's commands, the wheel's venv, every bundled scenario run twice) came last and left one
# worker running it alone for minutes while the other had finished. The longest files, measured on a fresh clone
# (an empty numba cache), go first here, longest first; every other file follows in xdist's order (most tests
# first). Only the order changes: every test runs as before, and a file still runs whole on one worker.
LONG_FILES = ("test_run_scenario.py", "test_ray.py", "test_docs.py", "test_plugin.py", "test_score.py", "test_sweep.py",
              "test_native.py", "test_analytic_kernel.py", "test_native_manipulator.py", "test_native_twin.py",
              "test_arm_conditions.py", "test_compile_note.py", "test_packaging.py", "test_twin.py",
              "test_score_verify.py", "test_quadrotor_studies.py", "test_verdict.py", "test_build_cache.py",
              "test_bench.py")


def pytest_configure(config):
    if hasattr(config.option, "loadscopereorder"):  # pytest-xdist is there: keep the order given below
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
    counts: dict[str, int] = {}
    for item in items:
        counts[str(item.path)] = counts.get(str(item.path), 0) + 1
    first = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: (first.get(item.path.name, len(first)), -counts[str(item.path)], str(item.path)))

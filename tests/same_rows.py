"""A test helper shared by the compiled loops' tests (tests/test_native_twin.py, tests/test_native_analytic.py): a
scenario run on its compiled loop and on the Python path (simulation.python_callback), and every row compared bit
for bit (np.array_equal, not allclose)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.runs.runner import execute

FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")


def run_scenario(path: Path, overrides, *, python: bool):
    """The scenario at `path` with `overrides`, run on the Python path (python) or as it chooses; its trajectory."""
    scn = sc.load(path, overrides=list(overrides) + (["simulation.python_callback=true"] if python else []))
    return execute(scn).trajectory


def same_rows(path: Path, overrides, *, native: bool = True):
    """The compiled and Python runs of a scenario: every row equal bit for bit, status and reason equal; the
    compiled one took the compiled loop (native) or fell back to the Python path. Returns the compiled run's
    trajectory."""
    compiled, python = run_scenario(path, overrides, python=False), run_scenario(path, overrides, python=True)
    assert python.meta["native"] is False
    assert compiled.meta["native"] is native
    for field in FIELDS:
        a, b = getattr(compiled, field), getattr(python, field)
        assert a.shape == b.shape, field
        assert np.array_equal(a, b, equal_nan=True), field
    assert (compiled.status, compiled.reason) == (python.status, python.reason)
    return compiled

"""Many runs at once: job.py says what one run is (RunSpec, RunOutcome, Backend, run_job),
parallel.py runs jobs in worker processes (or, for --backend ray, hands them to
ray_backend.py, which runs each as a Ray task), sweep.py runs a scenario over a grid
of overrides and seeds, bench.py runs the catalogue of the lecture's phenomena
(bench_catalogue.py, assembled from one module per report section in sections/) and
writes the report, with the analyses beyond the summary metrics in analysis.py.

From Python (api.py): ``adaptive_mj.study.sweep(scenario, grid=..., seeds=...)``, ``.breaking_point``,
``.stress`` and ``.bench`` run a study and return a Study (result.py). Those four names are also the
modules that hold each command's code (``from adaptive_mj.study import sweep; sweep.parse_grid``), so
each of those modules is callable: calling it calls the function of the same name in api.py.
"""
from __future__ import annotations

import importlib
import sys
import types

from adaptive_mj.study.result import Study, Table

__all__ = ["Study", "Table", "bench", "breaking_point", "stress", "sweep"]


class CallableModule(types.ModuleType):
    """A study command's module that can be called like its API function (adaptive_mj.study.api)."""

    def __call__(self, *args, **kwargs):
        # looked up when called, by name: the command modules sit below api.py in the study's layers
        # (pyproject.toml [tool.importlinter]) and never import it; only a call made from outside reaches it
        api = importlib.import_module("adaptive_mj.study.api")
        return getattr(api, self.__name__.rsplit(".", 1)[1])(*args, **kwargs)


def callable_module(name: str) -> None:
    """Make the module `name` (one of sweep, breaking_point, stress, bench) callable (CallableModule)."""
    sys.modules[name].__class__ = CallableModule


COMMANDS = ("sweep", "breaking_point", "stress", "bench")


def __getattr__(name: str):
    """adaptive_mj.study.sweep (and the other commands) before anything imported that module."""
    if name in COMMANDS:
        return importlib.import_module(f"adaptive_mj.study.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

"""adaptive-mj warmup: compile, before a bench, every compiled callback and chunk stepper its runs take, in parallel
processes, so that the bench (and any run of the same plants and laws) loads them from numba's disk cache.

What the bench needs is found by doing what it does: each distinct (scenario, overrides) of its catalogue (and, for
the full bench, of its breaking-point study, at each stressor's two ends) is set up and run for WARM_STEPS physics
steps, the path a bench run takes (adaptive_mj.runs.runner.start, adaptive_mj.sim.loop.run). A run whose variant is
in the cache loads it in a fraction of a second; one that is not compiles it, saying so on stderr with its time
(adaptive_mj.sim.compile_note). Two processes that need the same variant compile it once (compile_note's lock);
the runs are ordered so that the processes start on different scenario files.
"""
from __future__ import annotations

import contextlib
import io
import multiprocessing as mp
import sys
import tempfile
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor
from concurrent.futures import wait as wait_for
from dataclasses import dataclass, field
from pathlib import Path

WARM_STEPS = 2  # physics steps per run: the first chunk compiles (or loads) everything the run's path takes

Spec = tuple[Path, tuple[str, ...]]


@dataclass
class Warmup:
    """What a warmup did: the runs it set up, the variants it compiled ((what, seconds), in order), the runs that
    could not be set up (scenario, overrides, the error's line), and its wall time [s]."""

    runs: int
    jobs: int
    quick: bool
    compiled: list[tuple[str, float]] = field(default_factory=list)
    errors: list[tuple[str, str]] = field(default_factory=list)
    seconds: float = 0.0

    def text(self) -> str:
        total = sum(s for _, s in self.compiled)
        head = (f"warmup: the {'quick ' if self.quick else ''}bench's {self.runs} distinct runs set up on {self.jobs} "
                f"process{'es' if self.jobs > 1 else ''} in {self.seconds:.1f} s: ")
        if self.compiled:
            head += (f"{len(self.compiled)} variant{'s' if len(self.compiled) > 1 else ''} compiled ({total:.1f} s "
                     "of compiling), the rest loaded from numba's cache")
        else:
            head += "nothing to compile, every variant was in numba's cache"
        lines = [head] + [f"  could not set up {what}: {err}" for what, err in self.errors]
        return "\n".join(lines)


def bench_specs(*, quick: bool) -> list[Spec]:
    """Every distinct (scenario, overrides) the bench runs (quick: `bench --quick`'s): its catalogue's jobs, and for
    the full bench its breaking-point study's searches at each stressor's two ends."""
    from adaptive_mj.study.bench_catalogue import catalogue

    with tempfile.TemporaryDirectory() as logs:  # the jobs name their logs; nothing is written there
        specs = [(Path(job.scenario), tuple(job.overrides)) for s in catalogue(quick=quick, logs=Path(logs))
                 for job in s.jobs]
    if not quick:
        from adaptive_mj.study.stress import BENCH_SETTINGS, study

        for search in study(composite=False, duration=BENCH_SETTINGS["duration"],
                            plant_laws=BENCH_SETTINGS["plant_laws"], plant_names=BENCH_SETTINGS["plant_names"]):
            st = search.stressor
            for v in (st.lo, st.hi):
                specs.append((Path(search.scenario), (*search.overrides, *st.overrides(v))))
    return _spread(list(dict.fromkeys(specs)))


def _spread(specs: list[Spec]) -> list[Spec]:
    """specs reordered round-robin over their scenario files (the first of each file, then the second, ...): the
    processes start on different plants and laws, so they compile different variants side by side."""
    groups: dict[Path, list[Spec]] = {}
    for spec in specs:
        groups.setdefault(spec[0], []).append(spec)
    out: list[Spec] = []
    for i in range(max((len(g) for g in groups.values()), default=0)):
        out.extend(g[i] for g in groups.values() if i < len(g))
    return out


def warm_one(spec: Spec, wait: bool = True) -> tuple[list[tuple[str, float]], str | None]:
    """Set one (scenario, overrides) up and run it WARM_STEPS physics steps, as a bench run would (no log): the
    variants this compiled ((what, seconds)) and the error's line where it could not be set up; BUSY where wait is
    False and another process compiles the variant it needs (compile_note.VariantBusy)."""
    from adaptive_mj.setup.scenario import load
    from adaptive_mj.sim import compile_note
    from adaptive_mj.sim.loop import run
    from adaptive_mj.runs.runner import start

    before = len(compile_note.COMPILED)
    scenario, overrides = spec
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(
                compile_note.CompileLines(sys.stderr, plugin_notes=True)), compile_note.waiting(wait):
            st = start(load(scenario, overrides=list(overrides)))
            plant = st.setup.plant
            run(plant, st.setup.law, st.setup.reference, sink=None,
                **{**st.kwargs, "duration": WARM_STEPS * plant.dt, "events": ()})
    except compile_note.VariantBusy:
        return compile_note.COMPILED[before:], BUSY
    except Exception as exc:  # noqa: BLE001 (a run the bench would report as an error; the warmup goes on)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        return compile_note.COMPILED[before:], f"{type(exc).__name__}: {first[:200]}"
    return compile_note.COMPILED[before:], None


BUSY = "busy"  # warm_one's answer where another process compiles the variant (it is tried again later, waiting)


def warmup(*, quick: bool = False, jobs: int = 1, specs: list[Spec] | None = None) -> Warmup:
    """Compile what the bench needs (quick: `bench --quick`'s runs; specs: these (scenario, overrides) instead) on
    `jobs` processes; each variant compiled is said on stderr with its time as it is done. A run whose variant
    another process is compiling is put back at the end of the queue (the process takes the next run), and waits
    for that compile when its turn comes again."""
    specs = bench_specs(quick=quick) if specs is None else specs
    result = Warmup(runs=len(specs), jobs=jobs, quick=quick)
    t0 = time.perf_counter()
    outcomes: dict[int, tuple[list[tuple[str, float]], str | None]] = {}
    if jobs <= 1:
        outcomes = {i: warm_one(spec) for i, spec in enumerate(specs)}
    else:
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context(method)) as pool:
            queue = deque((i, False) for i in range(len(specs)))
            running: dict = {}
            while queue or running:
                while queue and len(running) < jobs:
                    i, wait = queue.popleft()
                    running[pool.submit(warm_one, specs[i], wait)] = (i, wait)
                done, _ = wait_for(running, return_when=FIRST_COMPLETED)
                for future in done:
                    i, _ = running.pop(future)
                    compiled, error = future.result()
                    if error == BUSY:
                        queue.append((i, True))
                    outcomes[i] = (outcomes.get(i, ([], None))[0] + compiled, error)
    for i, (scenario, overrides) in enumerate(specs):
        compiled, error = outcomes[i]
        result.compiled.extend(compiled)
        if error is not None:
            result.errors.append((f"{scenario.name} {' '.join(overrides)}".strip(), error))
    result.seconds = time.perf_counter() - t0
    return result

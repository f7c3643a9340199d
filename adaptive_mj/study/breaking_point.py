"""Breaking points: raise one stressor until a law fails, by bisection over runs.

A run *fails* when it diverges (or cannot run) or when its tail RMS tracking error
exceeds a stated bound. Every probe is run, whatever the law: the pre-flight check's
prediction is recorded beside the outcome (Evaluation.predicted), never taken for it.
A stress value *passes* when every seed passes. For one
(scenario, law, stressor) the search

  1. runs every seed at the low end and at the high end of the range;
  2. if the low end fails, the margin is "below the range"; if the high end passes,
     it is "at least the high end";
  3. otherwise bisects (geometrically when the range spans a decade or more and the
     low end is > 0, linearly otherwise, to whole numbers for integer stressors and to
     whole multiples of `step` for a stressor with a step, e.g. control.period in
     physics steps) for a fixed number of steps, keeping the largest passing value
     `margin` and the smallest failing value `first_fail`; the resolution is
     first_fail − margin.

Across seeds, at the margin: the mean tail error and its CVaR at 10 % (the mean of the
worst ⌈10 %⌉ of seeds: with 5 seeds, the worst one); at first_fail: the failure rate.

Searches for many (scenario, law, stressor) triples run in lockstep: every bisection
level of every search is one batch of parallel runs (adaptive_mj.study.parallel), so
the study takes (2 + steps) batches whatever its size. Every run's MCAP log is kept.

Screening (`screen=True`, the stress study's): a value is run on its first seed alone, and on
the others only if that one passed. A value whose first seed fails fails whatever the others
do, so the bisection takes the same path to the same margin and first_fail, and the margin's
seeds (all of which passed) are all run; at the end each search's first_fail is completed on its
other seeds, so its failure rate is over every seed as before. What is skipped: the other seeds
of the failing values the bisection passed on the way (2 batches per level instead of 1, and
one more at the end).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from adaptive_mj.plants import kinds
# what a search raises, below the study layer (each plant kind declares its own stressors); studies import it here
from adaptive_mj.plants.study_spec import Stressor, whole_steps
from adaptive_mj.study import callable_module
from adaptive_mj.study.parallel import Backend, RunSpec, RunOutcome, run_jobs
from adaptive_mj.study.job import RECORD_PREFLIGHT, passes

CVAR_LEVEL = 0.10  # the worst 10 % of seeds
# [m], [rad]: the stress study's failure bound on the tail RMS error (the 6-joint arm: RMS over its joints)
#: the stress study's plants by name -> their plant kinds: each kind that declares its row (PlantKind.stress)
STRESS_PLANT_KIND = {k.stress.name: k.name for k in kinds.built_in().values() if k.stress is not None}


def kind_number(kind: str, field: str) -> float:
    """A number plant kind `kind` declares for studies (PlantKind.tail_bound, .nominal_noise); one line if it
    declares none."""
    value = getattr(kinds.built_in()[kind], field)
    if value is None:
        raise ValueError(f"plant kind {kind!r} declares no {field} (the stress study needs it: plants/kinds.py)")
    return float(value)


TAIL_BOUND = {name: kind_number(kind, "tail_bound") for name, kind in STRESS_PLANT_KIND.items()}  # each kind's own


@dataclass(frozen=True)
class Search:
    """One breaking-point search: scenario file, fixed overrides (the law), the stressor, and what passes.

    A run passes when it completed without a crash and its tail RMS error is at most tail_bound (study.job's
    `passes`), or, with `run_passes`, when that says so (the quadrotor's AdaptiveQuadBench criterion:
    adaptive_mj.study.flight).
    rule "all": a value passes when every seed passes, so `margin` is the largest value where all did and
    `first_fail` the smallest where one did not (a breaking point); rule "any": a value passes when any seed
    does, so `first_fail` is the smallest value at which every seed fails (AdaptiveQuadBench's when2fail) and
    `margin` the largest below it where one seed still passed. extras: the analyses each run's job computes
    (adaptive_mj.study.job.EXTRAS), for `run_passes` to read."""

    scenario: Path
    label: str  # e.g. "heave/sigma"
    overrides: tuple[str, ...]
    stressor: Stressor
    tail_bound: float  # [m or rad] tail RMS above this is a failure
    seed: int = 0  # the first seed: the search runs seeds seed .. seed + seeds - 1 (the scorecard: one each)
    rule: str = "all"
    run_passes: Callable[[RunOutcome], bool] | None = None
    extras: tuple[str, ...] = ()

    def __post_init__(self):
        if self.rule not in RULES:
            raise ValueError(f"Search.rule must be one of {RULES}, got {self.rule!r}")

    def judged(self, result: RunOutcome) -> float:
        """One run as this search judges it: its tail RMS error when it passes, inf when it fails."""
        tail = result.tail_error
        if self.run_passes is None:
            return tail if passes(result, tail_bound=self.tail_bound) else math.inf
        if not self.run_passes(result):
            return math.inf
        return tail if math.isfinite(tail) else 0.0  # passed by its own criterion, with no tail to show

    def value_passes(self, ev: "Evaluation") -> bool:
        """Whether a value passes by this search's rule (every seed, or any seed)."""
        ok = [math.isfinite(t) for t in ev.tails]
        return all(ok) if self.rule == "all" else any(ok)


#: A value passes when every seed passes ("all": a margin) or when any does ("any": AdaptiveQuadBench's when2fail).
RULES = ("all", "any")


@dataclass
class Evaluation:
    value: float
    tails: list[float]  # per seed, inf for a run that diverged or failed
    statuses: list[str]
    raw: list[float] = field(default_factory=list)  # per seed, the tail error even beyond the bound
    predicted: list[bool] = field(default_factory=list)  # per seed, the pre-flight check found the loop unstable
    specs: list[RunSpec] = field(default_factory=list)  # per seed, the run as it was made (its overrides, its log)

    @property
    def passes(self) -> bool:
        return all(np.isfinite(self.tails))

    def failure_rate(self) -> float:
        return float(np.mean([not np.isfinite(x) for x in self.tails]))


@dataclass
class Margin:
    search: Search
    margin: float | None  # largest passing value (None: the low end fails)
    first_fail: float | None  # smallest failing value (None: the high end passes)
    evaluations: list[Evaluation] = field(default_factory=list)
    screened_out: int = 0  # runs not made by screening: a value's other seeds once its first had failed

    @property
    def resolution(self) -> float | None:
        if self.margin is None or self.first_fail is None:
            return None
        return self.first_fail - self.margin

    def at(self, value: float | None) -> Evaluation | None:
        return next((e for e in self.evaluations if value is not None and e.value == value), None)

    def stats(self) -> dict:
        """Mean and CVaR(10 %) of the tail error over seeds at the margin; failure rate at first_fail."""
        ok, bad = self.at(self.margin), self.at(self.first_fail)
        out = {"margin": self.margin, "first_fail": self.first_fail, "resolution": self.resolution,
               "tail_mean": None, "tail_cvar10": None, "failure_rate_beyond": None}
        if ok is not None:
            t = np.sort(np.asarray(ok.tails))[::-1]
            out["tail_mean"] = float(np.mean(t))
            out["tail_cvar10"] = float(np.mean(t[:max(1, math.ceil(CVAR_LEVEL * len(t)))]))
        if bad is not None:
            out["failure_rate_beyond"] = bad.failure_rate()
        return out


def _file_name(text: str) -> str:
    """A label as a plain file name: letters, digits and - _ . kept, anything else one "_"."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "x"


def _mid(lo: float, hi: float, st: Stressor) -> float:
    if lo > 0 and hi / lo >= 10.0:
        v = math.sqrt(lo * hi)
    else:
        v = 0.5 * (lo + hi)
    if st.integer:
        v = float(round(v))
        if v <= lo:
            v = lo + 1
        if v >= hi:
            v = hi - 1
    elif st.step > 0:  # whole steps strictly between lo and hi
        n_lo, n_hi = round(lo / st.step), round(hi / st.step)
        v = whole_steps(min(max(round(v / st.step), n_lo + 1), n_hi - 1) * st.step, st.step)
    return v


def _midpoints(searches: Sequence[Search], brackets: list[tuple[float, float] | None]) -> list[tuple[int, float]]:
    """(search index, value to try next) for each search still bracketed; an integer (or stepped)
    search whose bracket is down to neighbouring values is done (its bracket set to None)."""
    wanted = []
    for i, br in enumerate(brackets):
        if br is None:
            continue
        lo, hi = br
        st = searches[i].stressor
        if (st.integer and hi - lo <= 1) or (st.step > 0 and st.steps_between(lo, hi) <= 1):
            brackets[i] = None
            continue
        wanted.append((i, _mid(lo, hi, st)))
    return wanted


class _Batches:
    """The runs of search_all's batches: each (search, value) on its seeds, the Evaluations kept in `margins`."""

    def __init__(self, searches: Sequence[Search], margins: list[Margin], *, seeds: int, logs: Path, n_jobs: int,
                 backend: Backend | None, on_done: Callable[[RunOutcome], None] | None, keep_trajectory: bool,
                 screen: bool):
        self.searches, self.margins, self.seeds, self.logs = searches, margins, seeds, logs
        self.n_jobs, self.backend, self.on_done, self.keep_trajectory = n_jobs, backend, on_done, keep_trajectory
        self.screen = screen and seeds > 1
        self.done: dict[Path, RunOutcome] = {}  # by log: searches of one label and stressor share their runs

    def jobs_for(self, i: int, value: float, which: range) -> list[RunSpec]:
        s = self.searches[i]
        safe = _file_name(s.label.replace("/", "-"))
        text = str(int(value)) if s.stressor.integer else f"{value:.6g}"
        return [RunSpec(s.scenario, overrides=(RECORD_PREFLIGHT, *s.overrides, *s.stressor.overrides(value)), seed=k,
                    log=self.logs / safe / f"{_file_name(s.stressor.name)}={text}-seed{k}.mcap",
                    tag=f"{s.label} {s.stressor.name}={text} seed {k}", keep_trajectory=self.keep_trajectory,
                    extras=s.extras, expect="measured")  # a probe of a margin: its verdict is the measurement
                for k in which]

    def run(self, batch: list[tuple[int, float, range]]) -> list[list[RunOutcome]]:
        """The results of each (search, value, seeds) of one batch of parallel runs, in order; a run another
        search of the same label and stressor has made (a margin's and a when2fail's) is not made again."""
        jobs = [job for i, v, which in batch for job in self.jobs_for(i, v, which)]
        fresh = list({job.log: job for job in jobs if job.log not in self.done}.values())
        made = run_jobs(fresh, n_jobs=self.n_jobs, on_done=self.on_done, backend=self.backend) if fresh else []
        self.done.update((job.log, r) for job, r in zip(fresh, made, strict=True))  # type: ignore[misc]
        results = [self.done[job.log] for job in jobs]  # type: ignore[index]
        out, start = [], 0
        for _, _, which in batch:
            out.append(results[start:start + len(which)])
            start += len(which)
        return out

    def seeds_of(self, i: int, first: int = 0) -> range:
        """Search i's seeds from its `first`-th on."""
        return range(self.searches[i].seed + first, self.searches[i].seed + self.seeds)

    def evaluate(self, wanted: list[tuple[int, float]]) -> list[Evaluation]:
        """Each (search, value) of `wanted` run (screened: the first seed, then the others where it passed)."""
        if self.screen:
            chunks = self.run([(i, v, self.seeds_of(i)[:1]) for i, v in wanted])
            go_on = [n for n, ((i, _), c) in enumerate(zip(wanted, chunks, strict=True))
                     if self.searches[i].rule != "all" or math.isfinite(self.searches[i].judged(c[0]))]
            for n in set(range(len(wanted))) - set(go_on):
                self.margins[wanted[n][0]].screened_out += self.seeds - 1
            rest = self.run([(wanted[n][0], wanted[n][1], self.seeds_of(wanted[n][0], 1)) for n in go_on])
            for n, more in zip(go_on, rest, strict=True):
                chunks[n] = chunks[n] + more
        else:
            chunks = self.run([(i, v, self.seeds_of(i)) for i, v in wanted])
        out = []
        for (i, v), chunk in zip(wanted, chunks, strict=True):
            runs = [r for r in chunk]
            ev = Evaluation(v, [self.searches[i].judged(r) for r in chunk], [r.status for r in chunk],
                            [o.tail_error for o in runs], [o.predicted_unstable for o in runs], [o.job for o in runs])
            self.margins[i].evaluations.append(ev)
            out.append(ev)
        return out

    def complete_first_fails(self) -> None:
        """Screened: each search's first_fail run on its other seeds too (its failure rate over every seed)."""
        if not self.screen:
            return
        short = [(i, ev) for i, m in enumerate(self.margins) if (ev := m.at(m.first_fail)) is not None
                 and len(ev.tails) < self.seeds]
        rest = self.run([(i, ev.value, self.seeds_of(i, len(ev.tails))) for i, ev in short])
        for (i, ev), more in zip(short, rest, strict=True):
            self.margins[i].screened_out -= len(more)  # run after all
            ev.tails += [self.searches[i].judged(r) for r in more]
            ev.statuses += [r.status for r in more]
            runs = [r for r in more]
            ev.raw += [o.tail_error for o in runs]
            ev.predicted += [o.predicted_unstable for o in runs]
            ev.specs += [o.job for o in runs]


def search_all(searches: Sequence[Search], *, seeds: int, steps: int, logs: Path, n_jobs: int = 1,
               backend: Backend | None = None, on_batch: Callable[[int, int], None] | None = None,
               on_done: Callable[[RunOutcome], None] | None = None, keep_trajectory: bool = True,
               screen: bool = False) -> list[Margin]:
    """Run every search to its margin, in lockstep batches (see the module docstring).

    seeds: seeds 0..seeds-1 per stress value; steps: bisection steps after the two ends;
    logs: every run's MCAP log goes to logs/<label>/<stressor>=<value>-seed<k>.mcap;
    keep_trajectory: whether each run sends its decimated rows back (False: the summary only);
    screen: run a value's other seeds only where its first passed (the module docstring: the same margins,
    first_fail and statistics, fewer runs; a failing value on the way keeps its first seed's run only)."""
    margins = [Margin(s, None, None) for s in searches]
    brackets: list[tuple[float, float] | None] = [None] * len(searches)
    batches = _Batches(searches, margins, seeds=seeds, logs=logs, n_jobs=n_jobs, backend=backend, on_done=on_done,
                       keep_trajectory=keep_trajectory, screen=screen)
    total = 2 + steps
    ends = [(i, s.stressor.lo) for i, s in enumerate(searches)] + [(i, s.stressor.hi) for i, s in enumerate(searches)]
    evs = batches.evaluate(ends)
    if on_batch:
        on_batch(1, total)
    n = len(searches)
    for i in range(n):
        low, high = evs[i], evs[n + i]
        if not searches[i].value_passes(low):
            margins[i].first_fail = low.value
        elif searches[i].value_passes(high):
            margins[i].margin = high.value
        else:
            margins[i].margin, margins[i].first_fail = low.value, high.value
            brackets[i] = (low.value, high.value)
    for step in range(steps):
        wanted = _midpoints(searches, brackets)
        if not wanted:
            break
        for (i, v), ev in zip(wanted, batches.evaluate(wanted), strict=True):
            bracket = brackets[i]
            assert bracket is not None  # _midpoints wants values of bracketed searches only
            lo, hi = bracket
            if searches[i].value_passes(ev):
                brackets[i] = (v, hi)
                margins[i].margin = v
            else:
                brackets[i] = (lo, v)
                margins[i].first_fail = v
        if on_batch:
            on_batch(2 + step, total)
    batches.complete_first_fails()
    return margins


def margin_text(m: Margin) -> str:
    """The margin as a table cell: value ± resolution, or a bound."""
    st = m.search.stressor
    unit = f" {st.unit}" if st.unit else ""
    if m.margin is None:
        return f"< {st.lo:g}{unit}"
    if m.first_fail is None:
        return f"≥ {st.hi:g}{unit}"
    return f"{m.margin:.3g}{unit} (next {m.first_fail:.3g})"


callable_module(__name__)  # adaptive_mj.study.breaking_point(...) calls adaptive_mj.study.api.breaking_point(...)

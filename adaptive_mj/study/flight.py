"""The quadrotor's measurements (issue 33): each flight law on each task, and how much of each disturbance and of
a control delay it takes before the vehicle fails, after AdaptiveQuadBench (arXiv 2510.03471; its code at
github.com/valmik/AdaptiveQuadBench, ee7df29): a disturbance's *when2fail* is the smallest intensity at which every
seed fails (their success rate reaching 0 %), its *margin* the largest at which every seed succeeds; the *delay
margin* is the margin of a control delay (theirs: a sweep from 0 to 0.5 s in 0.01 s steps).

What fails a run is a named rule (RULES; `margins`, `grid_results` take rule=):
  "ours" (the default): the run crashes or diverges, its position error ‖p_d − p‖ exceeds MAX_ERROR = 1 m at any
         time, or it misses the quadrotor's stability criteria (its tail saturated, its body rate oscillating:
         success.tail_saturation, success.oscillation; issue 52). The 1 m bound is AdaptiveQuadBench's, but from
         its delay test only (aqb/utils/delay_analysis.py: "unstable" when the largest position error exceeds
         position_threshold = 1.0 m); here it applies to every disturbance.
  "aqb": AdaptiveQuadBench's own success rule for its disturbance trials: the RMS of ‖p_d − p‖ over the run below
         AQB_RMS_BOUND = 5 m (aqb/experiments/experiment_runner.py, `(df['pos_tracking_error'] < 5).mean()`, the
         error being parallel_data_collection.compute_cost's sqrt(mean ‖x − x_des‖²) over the trajectory), with
         no crash check. Here a crash ends the run, so a crashed run's RMS covers the rows before it.

The disturbances are the quadrotor kind's (adaptive_mj.plants.quadrotor.DISTURBANCES, which its breaking-point row
raises too); the delay is this study's (DELAY). The runs: the bundled lemniscate (A = 0.5 m, ω = 1 rad/s at 1 m)
without its payload, RUN_SECONDS long (their 5 s), with small measurement noise (NOISE, a seed per run), the
disturbance from t = 0 (a rotor's loss from 1 s).
A run the pre-flight check finds unstable by construction (adaptive_mj.sim.preflight: the attitude loop with a
control delay past its linearised limit) is run like any other and judged by its outcome, as in every study
(job.RECORD_PREFLIGHT). Two searches per (law, disturbance): by
bisection (`margins`: lo and hi, then `steps` rounds, every search's runs in one parallel batch per round) or on
a fixed grid (`grid_jobs`, `grid_results`: one batch; the bench's section). Every run is logged (MCAP) under the
folder given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from adaptive_mj.plants.quadrotor import DISTURBANCES, Disturbance
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.breaking_point import Stressor
from adaptive_mj.study.job import RECORD_PREFLIGHT
from adaptive_mj.study.job import COMPLETED, passes
from adaptive_mj.study.parallel import Backend, RunSpec, RunOutcome
from adaptive_mj.study.result import Table
from adaptive_mj.trajectory import Status

LAWS = ("geometric", "geometric_adaptive", "l1_geometric")
LAW_LABEL = {"geometric": "geometric (Lee 2010)", "geometric_adaptive": "geometric adaptive (m̂, d̂, τ̂)",
             "l1_geometric": "L1 geometric"}
MAX_ERROR = 1.0  # [m] the rule "ours": the largest position error (AdaptiveQuadBench's delay test's bound)
AQB_RMS_BOUND = 5.0  # [m] the rule "aqb": AdaptiveQuadBench's bound on the RMS position error of a trial
RUN_SECONDS = 5.0  # [s] AdaptiveQuadBench's run length
TASK = "quadrotor_lemniscate"
DT = 0.002  # [s] the scenario's physics step: a delay is a whole number of them
NOISE = "noise={std={p=0.001, v=0.01, phi=0.001, omega=0.01}}"
BASE = ("plant.payload='none'", f"simulation.duration={RUN_SECONDS!r}", "log.rate_hz=20", NOISE)


DELAY = Disturbance("delay", "s", lambda v: [f"simulation.control_delay={int(round(v / DT))}"], 0.0, 0.5, step=DT,
                    doc="a control delay (whole physics steps of 2 ms)")


def succeeded(r: RunOutcome) -> bool:
    """The rule "ours" (module docstring): the run completed without a crash, its position error stayed within
    MAX_ERROR (a run its scenario's own [success] tail bound calls failed still succeeds here) and it met its
    stability criteria (not saturated over its tail, not oscillating): study.job's `passes` with that bound, named
    for the searches' run_passes."""
    return passes(r, max_error=MAX_ERROR)


def aqb_succeeded(r: RunOutcome) -> bool:
    """The rule "aqb" (module docstring): the RMS position error over the run [m] (the flight_metrics analysis'
    rms_error) below AQB_RMS_BOUND, whether or not the run crashed; a run without that figure (not run, refused, in
    error) or with a non-finite one fails."""
    if r.status not in (*COMPLETED, Status.CRASHED):
        return False
    rms = (r.extras.get("flight_metrics") or {}).get("rms_error")
    return rms is not None and math.isfinite(rms) and rms < AQB_RMS_BOUND


#: the named failure rules of the searches: rule name -> run_passes (RunOutcome -> success)
RULES: dict[str, Callable[[RunOutcome], bool]] = {"ours": succeeded, "aqb": aqb_succeeded}


def rule_of(name: str) -> Callable[[RunOutcome], bool]:
    """RULES[name], or a ValueError naming the rules."""
    if name not in RULES:
        raise ValueError(f"unknown failure rule {name!r}; expected one of {', '.join(RULES)}")
    return RULES[name]


@dataclass
class Search:
    """One (law, disturbance) search: its evaluations {intensity: [success per seed]}."""

    law: str
    disturbance: Disturbance
    evaluations: dict[float, list[bool]] = field(default_factory=dict)

    def margin(self) -> tuple[float | None, float | None]:
        """(largest intensity with every seed succeeding, the smallest above it where some failed) (None: none)."""
        ok = [v for v, s in self.evaluations.items() if all(s)]
        lo = max(ok) if ok else None
        above = [v for v, s in self.evaluations.items() if not all(s) and (lo is None or v > lo)]
        return lo, (min(above) if above else None)

    def when2fail(self) -> tuple[float | None, float | None]:
        """(the largest intensity below it where some seed succeeded, the smallest with every seed failing)."""
        dead = [v for v, s in self.evaluations.items() if not any(s)]
        hi = min(dead) if dead else None
        below = [v for v, s in self.evaluations.items() if any(s) and (hi is None or v < hi)]
        return (max(below) if below else None), hi

    def success_rate(self, v: float) -> float:
        return float(np.mean(self.evaluations[v]))


def _jobs(s: Search, v: float, seeds: int, logs: Path, extra: Sequence[str]) -> list[RunSpec]:
    d = s.disturbance
    name = f"{s.law}-{d.name.replace(' ', '_')}={v:.6g}"
    return [RunSpec(sc.SCENARIOS_DIR / f"{TASK}.toml",
                overrides=(RECORD_PREFLIGHT, *BASE, *extra, f"law={s.law}", *d.overrides(v)),
                seed=k, log=logs / f"{name}-seed{k}.mcap", tag=f"{name} seed {k}", extras=("flight_metrics",),
                keep_trajectory=False, expect="measured")  # a probe of a margin: its verdict is the measurement
            for k in range(seeds)]


def searches(laws: Sequence[str] = LAWS, disturbances: Sequence[Disturbance] = (*DISTURBANCES, DELAY)) -> list[Search]:
    return [Search(law, d) for d in disturbances for law in laws]


def stressor(d: Disturbance) -> Stressor:
    """A disturbance as the breaking-point search's stressor (its intensities, range and step)."""
    return d.stressor()


def margins(found: list[Search], *, seeds: int, steps: int, logs: Path, n_jobs: int = 1,
            backend: Backend | None = None, extra: Sequence[str] = (), rule: str = "ours") -> list[Search]:
    """Bisect every search's margin and when2fail (module docstring) with the breaking-point search
    (adaptive_mj.study.breaking_point.search_all, the one bisection of every study): per (law, disturbance) a
    search of rule "all" (the margin) and one of rule "any" (when2fail: its first_fail), both judging a run by
    the failure rule RULES[rule] and sharing the runs they both ask for; the range's ends, then `steps` rounds.
    Each Search's evaluations are then every intensity tried, with each seed's success."""
    from adaptive_mj.study.breaking_point import Search as Probe, search_all

    judge = rule_of(rule)
    task = sc.SCENARIOS_DIR / f"{TASK}.toml"
    probes = [Probe(task, s.law, (*BASE, *extra, f"law={s.law}"), stressor(s.disturbance), math.inf, rule=kind,
                    run_passes=judge, extras=("flight_metrics",))
              for s in found for kind in ("all", "any")]
    done = search_all(probes, seeds=seeds, steps=steps, logs=logs, n_jobs=n_jobs, backend=backend,
                      keep_trajectory=False)
    for n, s in enumerate(found):
        for m in done[2 * n:2 * n + 2]:
            for ev in m.evaluations:
                s.evaluations[ev.value] = [math.isfinite(t) for t in ev.tails]
    return found


def grid(d: Disturbance, levels: int) -> list[float]:
    """`levels` intensities over [lo, hi]: geometric where the range spans a decade and starts above 0, else even
    (the delay: on its step)."""
    if d.step > 0:
        return sorted({round(v / d.step) * d.step for v in np.linspace(d.lo, d.hi, levels)})
    if d.lo > 0 and d.hi / d.lo >= 10:
        return [float(v) for v in np.geomspace(d.lo, d.hi, levels)]
    return [float(v) for v in np.linspace(d.lo, d.hi, levels)]


def grid_jobs(found: list[Search], levels: int, seeds: int, logs: Path, extra: Sequence[str] = ()) -> list[RunSpec]:
    """Every search's runs on its grid (one batch: the bench's section)."""
    return [j for s in found for v in grid(s.disturbance, levels) for j in _jobs(s, v, seeds, logs, extra)]


def grid_results(found: list[Search], levels: int, seeds: int, results: dict[str, RunOutcome], *,
                 rule: str = "ours") -> list[Search]:
    """Fill every search's evaluations from its grid runs' results (by tag), each judged by RULES[rule]."""
    succeeded = rule_of(rule)
    for s in found:
        for v in grid(s.disturbance, levels):
            name = f"{s.law}-{s.disturbance.name.replace(' ', '_')}={v:.6g}"
            s.evaluations[v] = [succeeded(results[f"{name} seed {k}"]) if f"{name} seed {k}" in results else False
                                for k in range(seeds)]
    return found


def bracket_text(d: Disturbance, lo: float | None, hi: float | None, *, upper: bool) -> str:
    """A margin (upper False: the largest passing value, its bracket up to the first failure) or a when2fail (upper
    True: the smallest all-failing value, down to the last success) as a table cell with its resolution."""
    if upper:
        if hi is None:
            return f"> {d.text(d.hi)}"
        return f"{d.text(hi)} (≥ {d.text(lo)})" if lo is not None else f"≤ {d.text(hi)}"
    if lo is None:
        return f"< {d.text(d.lo)}"
    return f"{d.text(lo)} (< {d.text(hi)})" if hi is not None else f"≥ {d.text(lo)}"


def table(found: list[Search], laws: Sequence[str] = LAWS) -> Table:
    """Per disturbance, each law's margin (every seed succeeds) and when2fail (every seed fails), each with the
    nearest evaluated value on its other side (the resolution); its to_markdown() is the report's table."""
    by = {(s.law, s.disturbance.name): s for s in found}
    rows = []
    for name in dict.fromkeys(s.disturbance.name for s in found):
        row: dict[str, str] = {"disturbance": name}
        for law in laws:
            s = by[(law, name)]
            row[LAW_LABEL.get(law, law)] = (f"margin {bracket_text(s.disturbance, *s.margin(), upper=False)}; "
                                            f"when2fail {bracket_text(s.disturbance, *s.when2fail(), upper=True)}")
        rows.append(row)
    return Table.of(rows, ["disturbance", *(LAW_LABEL.get(law, law) for law in laws)])


def as_rows(found: list[Search]) -> list[dict]:
    """JSON-ready rows: law, disturbance, unit, margin and when2fail brackets, every evaluation's success rate."""
    out = []
    for s in found:
        (m_lo, m_hi), (w_lo, w_hi) = s.margin(), s.when2fail()
        out.append({"law": s.law, "disturbance": s.disturbance.name, "unit": s.disturbance.unit,
                    "margin": m_lo, "margin_first_fail": m_hi, "when2fail": w_hi, "when2fail_last_success": w_lo,
                    "success_rate": {repr(v): s.success_rate(v) for v in sorted(s.evaluations)}})
    return out

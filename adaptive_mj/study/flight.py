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
         no crash check. Its bisection runs fly as AdaptiveQuadBench's go on (RULE_RUNS: no tilt ends a run, the
         task AQB_RULE_HEIGHT up, out of the ground's reach); a run that still ends early (diverged) is judged on
         the rows before its end. The protocol's trials (protocol_jobs) keep the 80 deg crash check (AQB.ours).

Each search flies one airframe (VEHICLES, Search.airframe): the bundled Crazyflie on its lemniscate at the laws'
default gains (RotorPy's), or AdaptiveQuadBench's 0.826 kg vehicle on its lemniscate (quadrotor_aqb_lemniscate) at
AdaptiveQuadBench's gains (PROTOCOL_GAINS). The disturbances are the quadrotor kind's (adaptive_mj.plants.quadrotor.
DISTURBANCES, which its breaking-point row raises too), declared on the Crazyflie; on another airframe each range is
scaled by the ratio of one quantity of the two compiled models (SCALES, VehicleSize: the weight, the spare lift, one
rotor's roll authority). The delay is this study's (DELAY); AdaptiveQuadBench's own delay test (AQBDelayTest,
AQB_DELAY_TEST: 10 ms steps up to 0.5 s until a trajectory's largest error passes 1 m, over a hover, a circle and 3
rapid trajectories per seed) is `delay_test`, judged by DELAY_RULES. The runs: the airframe's lemniscate (A = 0.5
m, ω = 1 rad/s at 1 m) without a payload, RUN_SECONDS long (their 5 s), with small measurement noise (NOISE, a seed
per run), the disturbance from t = 0 (a rotor's loss from 1 s).
A run the pre-flight check finds unstable by construction (adaptive_mj.sim.preflight: the attitude loop with a
control delay past its linearised limit) is run like any other and judged by its outcome, as in every study
(job.RECORD_PREFLIGHT). Two searches per (law, disturbance): by
bisection (`margins`: lo and hi, then `steps` rounds, every search's runs in one parallel batch per round) or on
a fixed grid (`grid_jobs`, `grid_results`: one batch; the bench's section). Every run is logged (MCAP) under the
folder given.

AdaptiveQuadBench's protocol itself (issue 52, item 5): its randomisation ranges declared once (AQB, an AQBProtocol:
every figure cited to its file and lines at ee7df29, and what this suite does differently, AQB.ours); a seeded
sampler (draw_task: a numpy Generator per seed draws a random motion primitive's goal and the disturbance's
direction, switch times, rotor factors and payload offset) whose TaskDraw.overrides() set up the scenario
PROTOCOL_TASK (AdaptiveQuadBench's vehicle on a 5 s motion primitive); protocol_jobs / protocol_results run and
judge its trials per law, axis (AXES) and intensity (protocol_levels: 0 to 10 by 1), success_curves and
plot_success_curves give the share of seeds that succeed at each intensity, as its paper plots them, and
protocol_output is the study's output (format PROTOCOL_FORMAT) with the ranges recorded (AQB.record()).
benchmarks/aqb_protocol.py runs it.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
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


#: [m] the height of the rule "aqb"'s runs (RULE_RUNS): a free fall from rest over the whole run, ½ g T², does not
#: reach the ground plane (AdaptiveQuadBench has none)
AQB_RULE_HEIGHT = math.ceil(0.5 * 9.81 * RUN_SECONDS ** 2)
#: what each failure rule's bisection runs add (margins_by_rule): the rule "aqb" flies its runs as AdaptiveQuadBench's
#: RotorPy runs go on, no tilt ending one (plant.crash_tilt = 180 deg) and the task AQB_RULE_HEIGHT up, so a vehicle
#: that is lost flies on and its RMS error grows, where with the 80 deg crash check, or the ground 1 m below, its run
#: ends with the rows before it well within 5 m (measured: every law on both airframes then "passed" the top of
#: every range). Rules with the same overrides share their runs.
RULE_RUNS: dict[str, tuple[str, ...]] = {
    "ours": (), "aqb": ("plant.crash_tilt=180.0", f"reference.center=[0.0, 0.0, {float(AQB_RULE_HEIGHT)!r}]")}


def rule_of(name: str) -> Callable[[RunOutcome], bool]:
    """RULES[name], or a ValueError naming the rules."""
    if name not in RULES:
        raise ValueError(f"unknown failure rule {name!r}; expected one of {', '.join(RULES)}")
    return RULES[name]


@dataclass
class Search:
    """One (law, disturbance) search on one airframe (VEHICLES): its evaluations {intensity: [success per seed]}."""

    law: str
    disturbance: Disturbance
    evaluations: dict[float, list[bool]] = field(default_factory=dict)
    airframe: str = "crazyflie"  # a key of VEHICLES: the vehicle, its task and its gains

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


def _label(s: Search) -> str:
    """The search's runs' label: the law (the Crazyflie: the names of issue 33), else airframe-law."""
    return s.law if s.airframe == "crazyflie" else f"{s.airframe}-{s.law}"


def _name(s: Search, v: float) -> str:
    return f"{_label(s)}-{s.disturbance.name.replace(' ', '_')}={v:.6g}"


def _jobs(s: Search, v: float, seeds: int, logs: Path, extra: Sequence[str]) -> list[RunSpec]:
    d, vehicle = s.disturbance, VEHICLES[s.airframe]
    name = _name(s, v)
    return [RunSpec(vehicle.task,
                overrides=(RECORD_PREFLIGHT, *BASE, *extra, *vehicle.law(s.law), *d.overrides(v)),
                seed=k, log=logs / f"{name}-seed{k}.mcap", tag=f"{name} seed {k}", extras=("flight_metrics",),
                keep_trajectory=False, expect="measured")  # a probe of a margin: its verdict is the measurement
            for k in range(seeds)]


def searches(laws: Sequence[str] = LAWS, disturbances: Sequence[Disturbance] | None = None, *,
             airframe: str = "crazyflie") -> list[Search]:
    """Per disturbance and law a Search on `airframe` (a key of VEHICLES); disturbances: by default the
    airframe's (Vehicle.disturbances: the Crazyflie's DISTURBANCES scaled to the vehicle) and the delay DELAY."""
    if airframe not in VEHICLES:
        raise ValueError(f"unknown airframe {airframe!r}; expected one of {', '.join(VEHICLES)}")
    if disturbances is None:
        disturbances = (*VEHICLES[airframe].disturbances(), DELAY)
    return [Search(law, d, airframe=airframe) for d in disturbances for law in laws]


def stressor(d: Disturbance) -> Stressor:
    """A disturbance as the breaking-point search's stressor (its intensities, range and step)."""
    return d.stressor()


def margins(found: list[Search], *, seeds: int, steps: int, logs: Path, n_jobs: int = 1,
            backend: Backend | None = None, extra: Sequence[str] = (), rule: str = "ours") -> list[Search]:
    """Bisect every search's margin and when2fail (module docstring) with the breaking-point search
    (adaptive_mj.study.breaking_point.search_all, the one bisection of every study): per (law, disturbance) a
    search of rule "all" (the margin) and one of rule "any" (when2fail: its first_fail), both judging a run by
    the failure rule RULES[rule] and sharing the runs they both ask for; the range's ends, then `steps` rounds.
    Each Search's evaluations are then every intensity tried, with each seed's success. Each search runs on its
    airframe's task at its gains (VEHICLES[s.airframe])."""
    return margins_by_rule(found, rules=(rule,), seeds=seeds, steps=steps, logs=logs, n_jobs=n_jobs,
                           backend=backend, extra=extra)[rule]


def margins_by_rule(found: list[Search], *, rules: Sequence[str], seeds: int, steps: int, logs: Path,
                    n_jobs: int = 1, backend: Backend | None = None,
                    extra: Sequence[str] = ()) -> dict[str, list[Search]]:
    """`margins` under each failure rule of `rules` at once: {rule: a copy of `found` with its evaluations}. Each
    rule's runs add its RULE_RUNS; the bisections run in lockstep, and rules with the same RULE_RUNS share every run
    they both ask for (one run per label, intensity and seed)."""
    from dataclasses import replace as copy

    from adaptive_mj.study.breaking_point import Search as Probe, search_all

    judges = {rule: rule_of(rule) for rule in rules}
    out = {rule: [copy(s, evaluations={}) for s in found] for rule in rules}

    def label(s: Search, rule: str) -> str:  # runs of other overrides go under another label
        return _label(s) + (f"-{rule}-runs" if RULE_RUNS[rule] else "")

    probes = [Probe(VEHICLES[s.airframe].task, label(s, rule),
                    (*BASE, *RULE_RUNS[rule], *extra, *VEHICLES[s.airframe].law(s.law)),
                    stressor(s.disturbance), math.inf, rule=kind, run_passes=judge, extras=("flight_metrics",))
              for rule, judge in judges.items() for s in found for kind in ("all", "any")]
    done = search_all(probes, seeds=seeds, steps=steps, logs=logs, n_jobs=n_jobs, backend=backend,
                      keep_trajectory=False)
    for r, rule in enumerate(rules):
        for n, s in enumerate(out[rule]):
            first = 2 * (r * len(found) + n)
            for m in done[first:first + 2]:
                for ev in m.evaluations:
                    s.evaluations[ev.value] = [math.isfinite(t) for t in ev.tails]
    return out


def grid(d: Disturbance, levels: int) -> list[float]:
    """`levels` intensities over [lo, hi]: geometric where the range spans a decade and starts above 0, else even
    (the delay: on its step)."""
    if d.step > 0:
        return sorted({round(v / d.step) * d.step for v in np.linspace(d.lo, d.hi, levels)})
    if d.lo > 0 and d.hi / d.lo >= 10:
        return [float(v) for v in np.geomspace(d.lo, d.hi, levels)]
    return [float(v) for v in np.linspace(d.lo, d.hi, levels)]


def grid_jobs(found: list[Search], levels: int, seeds: int, logs: Path, extra: Sequence[str] = ()) -> list[RunSpec]:
    """Every search's runs on its grid (one batch: the bench's section), as the rule "ours" flies them (for the rule
    "aqb" as its bisection flies them, add RULE_RUNS["aqb"] to `extra`)."""
    return [j for s in found for v in grid(s.disturbance, levels) for j in _jobs(s, v, seeds, logs, extra)]


def grid_results(found: list[Search], levels: int, seeds: int, results: dict[str, RunOutcome], *,
                 rule: str = "ours") -> list[Search]:
    """Fill every search's evaluations from its grid runs' results (by tag), each judged by RULES[rule]."""
    succeeded = rule_of(rule)
    for s in found:
        for v in grid(s.disturbance, levels):
            name = _name(s, v)
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
    nearest evaluated value on its other side (the resolution); its to_markdown() is the report's table. Searches
    on more than one airframe: a row per airframe and disturbance, with an airframe column."""
    by = {(s.airframe, s.law, s.disturbance.name): s for s in found}
    frames = list(dict.fromkeys(s.airframe for s in found))
    rows = []
    for frame, name in dict.fromkeys((s.airframe, s.disturbance.name) for s in found):
        row: dict[str, str] = {"airframe": frame} if len(frames) > 1 else {}
        row["disturbance"] = name
        for law in laws:
            s = by[(frame, law, name)]
            row[LAW_LABEL.get(law, law)] = (f"margin {bracket_text(s.disturbance, *s.margin(), upper=False)}; "
                                            f"when2fail {bracket_text(s.disturbance, *s.when2fail(), upper=True)}")
        rows.append(row)
    head = ["airframe"] if len(frames) > 1 else []
    return Table.of(rows, [*head, "disturbance", *(LAW_LABEL.get(law, law) for law in laws)])


def as_rows(found: list[Search]) -> list[dict]:
    """JSON-ready rows: airframe, law, disturbance, unit, its range searched [lo, hi], margin and when2fail
    brackets, every evaluation's success rate."""
    out = []
    for s in found:
        (m_lo, m_hi), (w_lo, w_hi) = s.margin(), s.when2fail()
        out.append({"airframe": s.airframe, "law": s.law, "disturbance": s.disturbance.name,
                    "unit": s.disturbance.unit, "range": [s.disturbance.lo, s.disturbance.hi],
                    "margin": m_lo, "margin_first_fail": m_hi, "when2fail": w_hi, "when2fail_last_success": w_lo,
                    "success_rate": {repr(v): s.success_rate(v) for v in sorted(s.evaluations)}})
    return out


# --------------------------------------------------------------------------------------------------------------------
# AdaptiveQuadBench's protocol (issue 52, item 5): its randomisation ranges, declared once, and a seeded sampler that
# turns (seed, axis, intensity) into a task of the scenario PROTOCOL_TASK

#: where every range below is read: github.com/valmik/AdaptiveQuadBench at this commit
AQB_COMMIT = "ee7df29"
AQB_RANDOMIZATION = "aqb/config/randomization_config.py"


@dataclass(frozen=True)
class Cited:
    """One figure of AdaptiveQuadBench's protocol: its value (a number, or (lo, hi) for a range), its unit, the
    file and lines at AQB_COMMIT it is read from, and what it is."""

    value: float | tuple[float, float]
    unit: str
    source: str
    doc: str

    @property
    def range(self) -> tuple[float, float]:
        """(lo, hi) of a range (a ValueError for a single number)."""
        if not isinstance(self.value, tuple):
            raise ValueError(f"{self.doc}: a number, not a range")
        return self.value

    @property
    def number(self) -> float:
        """A single number's value (a ValueError for a range)."""
        if isinstance(self.value, tuple):
            raise ValueError(f"{self.doc}: a range, not a number")
        return float(self.value)

    def record(self) -> dict:
        v = self.value
        return {"value": list(v) if isinstance(v, tuple) else v, "unit": self.unit,
                "source": f"valmik/AdaptiveQuadBench@{AQB_COMMIT}:{self.source}", "doc": self.doc}


def _r(lines: str) -> str:
    return f"{AQB_RANDOMIZATION}:{lines}"


@dataclass(frozen=True)
class AQBProtocol:
    """AdaptiveQuadBench's randomisation of a trial (valmik/AdaptiveQuadBench at ee7df29), every figure cited to its
    file and lines; the one declaration the sampler (draw_task) reads and the study's output records (record()).
    An axis's intensity I is AdaptiveQuadBench's (when2fail raises it from 0 in steps of 1 up to 10): wind I m/s,
    force (I, I, I) N, torque (I, I, I) N m, every rotor's efficiency 1 + U(−c, c) with c = min(I, cap), a payload
    of min(I, cap) times the vehicle's mass. What we do differently is in `ours`."""

    vehicle_mass: Cited = Cited(0.826, "kg", "aqb/quad_param/quadrotor.py:7", "the vehicle's mass ('mass')")
    arm_length: Cited = Cited(0.166, "m", "aqb/quad_param/quadrotor.py:3,14", "the arm d ('arm_length')")
    # the random motion primitive (create_trajectories): from rest at the origin, goal drawn per axis
    trajectory_position: Cited = Cited((-2.0, 2.0), "m", _r("79,224"), "goal position, U(lo, hi) per axis")
    trajectory_velocity: Cited = Cited((-2.0, 2.0), "m/s", _r("80,225"), "goal velocity, U(lo, hi) per axis")
    trajectory_acceleration: Cited = Cited((-2.0, 2.0), "m/s²", _r("81,226"), "goal acceleration, U(lo, hi) per axis")
    trajectory_time: Cited = Cited(5.0, "s", _r("82,231"), "the primitive's duration (and the run's)")
    # the axes
    wind_speed: Cited = Cited(1.0, "m/s per unit intensity", _r("152-155,254"), "the mean wind's speed: I")
    wind_direction: Cited = Cited((-1.0, 1.0), "", _r("255-256"),
                                  "U(lo, hi) per axis, normalised: the mean wind's direction")
    wind_sigma: Cited = Cited((30.0, 60.0), "", _r("77,258"),
                              "DrydenGust's sig_wind per axis, U(lo, hi): the gust's turbulence (not modelled here)")
    force: Cited = Cited(1.0, "N per unit intensity", _r("157-160,318"),
                         "each world axis's force: U(I, I) = I, i.e. (F, F, F)")
    torque: Cited = Cited(1.0, "N m per unit intensity", _r("162-165,320"),
                          "each world axis's torque: U(I, I) = I, i.e. (τ, τ, τ)")
    rotor_efficiency_cap: Cited = Cited(0.6, "", _r("172-176,276"),
                                        "each rotor's efficiency 1 + U(−c, c), c = min(I, cap)")
    payload_mass_cap: Cited = Cited(2.0, "× vehicle mass", _r("178-181,303-304"),
                                    "the payload's mass min(I, cap) times the vehicle's")
    payload_offset: Cited = Cited((-0.2, 0.2), "× arm length", _r("78,306-307"),
                                  "the payload's centre of mass, U(lo, hi) per body axis times the arm")
    toggles: Cited = Cited((1.0, 4.0), "", _r("347"), "how many times the force, torque or payload is switched")
    toggle_window: Cited = Cited((0.5, 4.5), "s", _r("323,356"),
                                 "each switch time U(lo, hi): min_toggle_interval to t_final − min_toggle_interval")
    toggle_gap: Cited = Cited(0.5, "s", _r("323,358"),
                              "the least time between switches (a time drawn closer is redrawn, at most 100 tries; "
                              "after 100 failures no more switches)")
    intensity_step: Cited = Cited(1.0, "", "aqb/experiments/config_manager.py:61", "when2fail's intensity step")
    max_intensity: Cited = Cited(10.0, "", "aqb/experiments/config_manager.py:59", "when2fail's largest intensity")
    success_rms: Cited = Cited(AQB_RMS_BOUND, "m", "aqb/experiments/experiment_runner.py:277",
                               "a trial succeeds when its RMS position error is below this (no crash check)")

    #: what this suite does where AdaptiveQuadBench differs or cannot be followed (recorded beside the figures)
    ours: tuple[str, ...] = (
        "wind: a steady wind of AdaptiveQuadBench's mean speed and direction (plant.wind, felt through RotorPy's rotor "
        "drag); its Dryden turbulence (rotorpy DrydenGust, sig_wind) is not modelled, so wind_sigma is recorded and "
        "not applied",
        "switching: off at t = 0, on at the first switch time, off at the next and so on, the payload switched with "
        "the force and torque, as the simulate() of the RotorPy fork AdaptiveQuadBench pins (its submodule "
        "Dz298/rotorpy; force_on = False at the start, payload attached while force or torque is on)",
        "the payload: a point mass on the vehicle (event payload_point), its weight acting through MuJoCo's dynamics "
        "rather than as the fork's constant world-frame torque r × m g",
        "the trajectory starts at rest 5 m up (reference.center of the task), not at the origin: AdaptiveQuadBench has "
        "no ground, and a primitive within its ranges dips at most 4.40 m below its start",
        "seeds: a numpy Generator per seed (not the global numpy seed), the trajectory and the disturbance's "
        "direction and timing drawn from two streams of it, the same at every intensity (AdaptiveQuadBench keeps the "
        "trajectories and redraws the disturbance at each intensity); so numbers differ from AdaptiveQuadBench's draws",
        "a run ends at a crash (a tilt past plant.crash_tilt, or the ground), where AdaptiveQuadBench's ends only past "
        "20 m/s or 100 rad/s (its RotorPy fork's safety_exit; it has no ground) and its cost ignores how it ended: "
        "under the rule 'aqb' the RMS covers the rows before the end, so a vehicle lost early passes (every crashed "
        "trial of the torque axis at 1 and 5 N m did, 10 seeds, the geometric law); the rule 'ours' fails it",
    )

    def record(self) -> dict:
        """Every figure with its unit, source and meaning, and `ours`: JSON-ready, for the study's output."""
        from dataclasses import fields

        out: dict = {f.name: getattr(self, f.name).record() for f in fields(self) if f.name != "ours"}
        out["ours"] = list(self.ours)
        return out


AQB = AQBProtocol()
#: the protocol's task: AdaptiveQuadBench's vehicle on a motion primitive, each law at AdaptiveQuadBench's gains
PROTOCOL_TASK = "quadrotor_aqb_random"
#: each flight law at AdaptiveQuadBench's geometric gains (aqb/controller/geometric_control.py at ee7df29,
#: GeoControl.__init__'s last self.k: k_x = (5, 5, 10) N/m, k_v = (4, 4, 8) N s/m, k_R = 0.3 N m/rad, k_W = 0.03
#: N m s/rad; the adaptive law's surface lambda = k_x/k_v, k = k_v), as overrides of PROTOCOL_TASK (whose own law is
#: the adaptive one at these gains): a law swap, then its gains
_AQB_GEOMETRIC = ("law.kx=[5.0, 5.0, 10.0]", "law.kv=[4.0, 4.0, 8.0]", "law.kR=0.3", "law.kW=0.03")
PROTOCOL_GAINS: dict[str, tuple[str, ...]] = {
    "geometric": ("law=geometric", *_AQB_GEOMETRIC), "l1_geometric": ("law=l1_geometric", *_AQB_GEOMETRIC),
    "geometric_adaptive": ("law=geometric_adaptive", "law.lambda=[1.25, 1.25, 1.25]", "law.k=[4.0, 4.0, 8.0]",
                           "law.kR=0.3", "law.kW=0.03")}
#: AdaptiveQuadBench's disturbance axes, each with its intensity's unit
AXES = {"wind": "m/s", "force": "N", "torque": "N m", "rotor_efficiency": "", "payload": "× vehicle mass"}


# --------------------------------------------------------------------------------------------------------------------
# The flight study on both airframes (issue 52, item 5): the Crazyflie's task and AdaptiveQuadBench's vehicle's, each
# at its own gains, the disturbances' ranges scaled from the Crazyflie's by the compiled models

#: what each disturbance's range scales with from the Crazyflie's (plants.quadrotor.DISTURBANCES, declared on the
#: bundled Crazyflie) to another airframe: the ratio of this quantity of the two compiled models (VehicleSize);
#: None: the same range on every airframe
SCALES: dict[str, str | None] = {"wind": None, "force": "weight", "torque": "roll authority", "payload": "spare lift",
                                 "rotor loss": None}


@dataclass(frozen=True)
class VehicleSize:
    """The quantities a disturbance's range scales with (SCALES), from a compiled model (the task's plant without a
    payload): weight m g [N]; spare lift (Σ T_max − m g)/g [kg], the payload the rotors could just hold; roll
    authority max_i T_max,i |y_i| [N m], the largest torque one rotor puts about the body's x axis."""

    mass: float  # [kg]
    weight: float  # [N]
    spare_lift: float  # [kg]
    roll_authority: float  # [N m]

    def of(self, quantity: str) -> float:
        return {"weight": self.weight, "spare lift": self.spare_lift, "roll authority": self.roll_authority}[quantity]


#: the unit of each scaled quantity
SCALE_UNITS = {"weight": "N", "spare lift": "kg", "roll authority": "N m"}


@dataclass(frozen=True)
class Vehicle:
    """One airframe of the flight study: name (a key of VEHICLES), scenario (its task: a file under scenarios/,
    whose plant.model is the vehicle; run without its payload, BASE), gains: per law the overrides that swap the
    law in at this vehicle's gains (None: `law=NAME` at the law's defaults, RotorPy's Crazyflie gains)."""

    name: str
    scenario: str
    gains: dict[str, tuple[str, ...]] | None = None
    doc: str = ""

    @property
    def task(self) -> Path:
        return sc.SCENARIOS_DIR / f"{self.scenario}.toml"

    def law(self, law: str) -> tuple[str, ...]:
        """The overrides that fly `law` on this vehicle (a law swap, then its gains)."""
        return (f"law={law}",) if self.gains is None else self.gains[law]

    def size(self) -> VehicleSize:
        """The vehicle's VehicleSize, from its task's compiled model without a payload."""
        return _size(str(sc.load(self.task, overrides=("plant.payload='none'",)).plant.model))

    def disturbances(self) -> tuple[Disturbance, ...]:
        """plants.quadrotor.DISTURBANCES with each range scaled by SCALES from the Crazyflie's compiled model to
        this vehicle's (the Crazyflie's: unchanged)."""
        base = VEHICLES["crazyflie"]
        if self.name == base.name:
            return DISTURBANCES
        mine, ref = self.size(), base.size()
        out = []
        for d in DISTURBANCES:
            q = SCALES[d.name]
            if q is None:
                out.append(d)
                continue
            r = mine.of(q) / ref.of(q)
            out.append(replace(d, lo=d.lo * r, hi=d.hi * r,
                               doc=f"the Crazyflie's range ({d.lo:.3g} to {d.hi:.3g} {d.unit}) × {r:.4g}, the ratio "
                                   f"of the vehicles' {q} ({mine.of(q):.4g} to {ref.of(q):.4g} {SCALE_UNITS[q]})"))
        return tuple(out)


@functools.cache
def _size(model: str) -> VehicleSize:
    """VehicleSize of the quadrotor MJCF at `model` (a path), compiled."""
    from adaptive_mj.plants import quadrotor

    plant = quadrotor.load(model)
    frame, g = plant.airframe, float(-plant.model.opt.gravity[2])
    return VehicleSize(mass=frame.mass, weight=frame.mass * g,
                       spare_lift=(float(frame.thrust_max.sum()) - frame.mass * g) / g,
                       roll_authority=float(np.max(frame.thrust_max * np.abs(frame.rotors[:, 1]))))


#: the flight study's airframes: the bundled Crazyflie on its lemniscate at RotorPy's gains (the laws' defaults),
#: and AdaptiveQuadBench's 0.826 kg vehicle on its lemniscate at AdaptiveQuadBench's gains (PROTOCOL_GAINS)
VEHICLES: dict[str, Vehicle] = {
    "crazyflie": Vehicle("crazyflie", TASK, None, "RotorPy's Crazyflie 2.x (models/quadrotor.xml, 30 g)"),
    "aqb": Vehicle("aqb", "quadrotor_aqb_lemniscate", PROTOCOL_GAINS,
                   "AdaptiveQuadBench's quadrotor (models/quadrotor_aqb.xml, 0.826 kg) at its geometric gains"),
}


# --------------------------------------------------------------------------------------------------------------------
# AdaptiveQuadBench's delay test, as it defines it (aqb/experiments/experiment_runner.py:311-352 at ee7df29, calling
# aqb/utils/delay_analysis.py's compute_delay_margin and generate_random_trajectories)

_RUNNER = "aqb/experiments/experiment_runner.py"
_DELAY = "aqb/utils/delay_analysis.py"


@dataclass(frozen=True)
class AQBDelayTest:
    """AdaptiveQuadBench's delay test, every figure cited at AQB_COMMIT: per controller and trajectory, the control
    delay is raised from `start` by `step` until a 5 s run's largest position error exceeds `bound` (no crash
    check: RotorPy runs on with terminate=False); the trajectory's delay margin is that delay less one step (`stop`
    if none fails). Its trajectories: a hover, a circle, and rapid (motion-primitive) ones whose goals widen with a
    difficulty (i + 1)/(n − 2). What this suite does differently is in `ours`."""

    start: Cited = Cited(0.0, "s", f"{_RUNNER}:347", "the first delay (initial_delay)")
    step: Cited = Cited(0.01, "s", f"{_RUNNER}:349", "the delay's step (delay_step)")
    stop: Cited = Cited(0.5, "s", f"{_RUNNER}:348", "the largest delay tried (max_delay)")
    duration: Cited = Cited(5.0, "s", f"{_RUNNER}:350", "each run's length (test_duration)")
    bound: Cited = Cited(1.0, "m", f"{_RUNNER}:351; {_DELAY}:205-220",
                         "unstable when max_t ‖x − x_des‖ exceeds this (position_threshold)")
    trajectories: Cited = Cited(5.0, "", f"{_RUNNER}:321-322; {_DELAY}:89-98",
                                "how many trajectories: a hover, a circle and n − 2 rapid ones")
    circle_radius: Cited = Cited(2.0, "m", f"{_DELAY}:94", "CircularTraj(center=(−2, 0, 0), radius=2)")
    circle_frequency: Cited = Cited(0.2, "Hz", "rotorpy/trajectories/circular_traj.py:12 (spencerfolk/rotorpy)",
                                    "CircularTraj's default freq (AdaptiveQuadBench passes none)")
    rapid_position: Cited = Cited((2.0, 2.0), "m", f"{_DELAY}:110-112",
                                  "goal position U(−r, r) per axis, r = lo + hi·difficulty, z made positive")
    rapid_velocity: Cited = Cited((1.0, 2.0), "m/s", f"{_DELAY}:115-116",
                                  "goal velocity U(−r, r), r = lo + hi·difficulty")
    rapid_acceleration: Cited = Cited((0.5, 1.5), "m/s²", f"{_DELAY}:119-120",
                                      "goal acceleration U(−r, r), r = lo + hi·difficulty")
    sim_rate: Cited = Cited(100.0, "Hz", f"{_DELAY}:182", "RotorPy's simulation (and control) rate")

    ours: tuple[str, ...] = (
        "the delay: whole physics steps of 2 ms (simulation.control_delay), 10 ms = 5 steps; AdaptiveQuadBench "
        "simulates and controls at 100 Hz, so its 10 ms step is one control period",
        "the circle: a lemniscate (x = A sin ωt, y = (A/2) sin 2ωt) of A = the circle's radius at ω = 2π·0.2 rad/s: "
        "this suite's references have no circle",
        "the trajectories start at rest 5 m up (as PROTOCOL_TASK; AdaptiveQuadBench has no ground), on the reference",
        "the rapid trajectories' goals: drawn per seed from a numpy Generator (AdaptiveQuadBench: the global numpy "
        "state), the same at every delay",
        "each run starts afresh (AdaptiveQuadBench reuses one controller object across the delays of a trajectory, "
        "so an adaptive law carries its estimates over)",
        "no tilt ends a run (plant.crash_tilt = DELAY_TEST_CRASH_TILT = 180 deg), as RotorPy's runs go on "
        "(terminate=False): a vehicle that tumbles flies on and its error grows past the bound, where a crash at the "
        "default 80 deg would end the run with the rows before it within 1 m (measured: every law on the Crazyflie "
        "'passed' 0.3 s of delay so). A run still ends at the ground (5 m below the start) or if it diverges, and "
        "is judged over the rows before; the rule 'ours' here sees no tilt crash, only its error and stability",
    )

    def levels(self) -> list[float]:
        """The delays tried [s]: start, start + step, ... up to stop (0, 0.01, ..., 0.5)."""
        lo, step, hi = self.start.number, self.step.number, self.stop.number
        return [round(lo + k * step, 12) for k in range(int(math.floor((hi - lo) / step + 1e-9)) + 1)]

    def rapid_goals(self, seed: int) -> list[tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]]:
        """The n − 2 rapid trajectories' goals (position [m], velocity [m/s], acceleration [m/s²], each (3,)) of
        seed `seed`: the i-th at difficulty (i + 1)/(n − 2), each range ±(lo + hi·difficulty) per axis, the goal's
        z made positive, drawn from numpy's Generator for the seed."""
        rng = np.random.default_rng(np.random.SeedSequence(seed))
        n = int(self.trajectories.number) - 2
        out = []
        for i in range(n):
            d = (i + 1) / n
            p, v, a = ((r.range[0] + r.range[1] * d) for r in (self.rapid_position, self.rapid_velocity,
                                                                self.rapid_acceleration))
            pos, vel, acc = rng.uniform(-p, p, size=3), rng.uniform(-v, v, size=3), rng.uniform(-a, a, size=3)
            pos[2] = abs(pos[2])
            out.append(tuple(tuple(float(x) for x in g) for g in (pos, vel, acc)))
        return out  # type: ignore[return-value]

    def references(self, seed: int, center: Sequence[float] = (0.0, 0.0, 5.0)) -> list[tuple[str, str]]:
        """(name, the `reference={...}` override) of each of the test's trajectories for seed `seed`, starting at
        `center` [m]: hover, circle (a lemniscate: `ours`), rapid1 .. rapid(n − 2)."""
        c = [float(x) for x in center]
        omega = 2 * math.pi * self.circle_frequency.number
        out = [("hover", f"reference={{kind='hover', center={c!r}}}"),
               ("circle", f"reference={{kind='lemniscate', center={c!r}, amplitude={self.circle_radius.number!r}, "
                          f"omega={omega!r}}}")]
        dur = self.duration.number
        for i, (p, v, a) in enumerate(self.rapid_goals(seed)):
            out.append((f"rapid{i + 1}", f"reference={{kind='motion_primitive', center={c!r}, position={list(p)!r}, "
                                         f"velocity={list(v)!r}, acceleration={list(a)!r}, duration={dur!r}}}"))
        return out

    def record(self) -> dict:
        from dataclasses import fields

        out: dict = {f.name: getattr(self, f.name).record() for f in fields(self) if f.name != "ours"}
        out["ours"] = list(self.ours)
        return out


AQB_DELAY_TEST = AQBDelayTest()

#: the delay test's axis (a Disturbance for Search, table and as_rows): a control delay [s] in AQB_DELAY_TEST's steps
AQB_DELAY = Disturbance("delay (AQB test)", "s",
                        lambda v: [f"simulation.control_delay={int(round(v / DT))}"], AQB_DELAY_TEST.start.number,
                        AQB_DELAY_TEST.stop.number, step=AQB_DELAY_TEST.step.number,
                        doc="AdaptiveQuadBench's delay test: raised by 10 ms until a trajectory's largest position "
                            "error passes 1 m, over a hover, a circle and 3 rapid trajectories per seed")


def aqb_delay_succeeded(r: RunOutcome) -> bool:
    """AdaptiveQuadBench's delay test's rule: the largest position error over the run [m] (flight_metrics'
    max_error) at most AQB_DELAY_TEST.bound, whether or not the run crashed (its rows before the end); a run
    without that figure, or with a non-finite one, fails."""
    if r.status not in (*COMPLETED, Status.CRASHED):
        return False
    e = (r.extras.get("flight_metrics") or {}).get("max_error")
    return e is not None and math.isfinite(e) and e <= AQB_DELAY_TEST.bound.number


#: the delay test's failure rules, by the names of RULES: "aqb" its own bound (no crash check), "ours" as RULES
DELAY_RULES: dict[str, Callable[[RunOutcome], bool]] = {"aqb": aqb_delay_succeeded, "ours": succeeded}


#: [deg] the delay test's runs' plant.crash_tilt: no tilt ends them (AQBDelayTest.ours)
DELAY_TEST_CRASH_TILT = 180.0


def _delay_name(airframe: str, law: str, traj: str, v: float) -> str:
    return f"{airframe}-{law}-aqbdelay-{traj}={v:.6g}"


def delay_jobs(airframe: str, law: str, v: float, seeds: Sequence[int], logs: Path, extra: Sequence[str] = (),
               test: AQBDelayTest = AQB_DELAY_TEST) -> list[RunSpec]:
    """The delay test's runs of `law` on `airframe`'s task at delay v [s]: per seed k, each of the test's
    trajectories (test.references(k)), test.duration long, without a payload, no tilt ending the run
    (DELAY_TEST_CRASH_TILT), noise seed k."""
    vehicle = VEHICLES[airframe]
    base = ("plant.payload='none'", f"plant.crash_tilt={DELAY_TEST_CRASH_TILT!r}",
            f"simulation.duration={test.duration.number!r}", "log.rate_hz=20", NOISE)
    return [RunSpec(vehicle.task, overrides=(RECORD_PREFLIGHT, *base, *extra, *vehicle.law(law), ref,
                                             *AQB_DELAY.overrides(v)),
                    seed=k, log=logs / f"{_delay_name(airframe, law, name, v)}-seed{k}.mcap",
                    tag=f"{_delay_name(airframe, law, name, v)} seed {k}", extras=("flight_metrics",),
                    keep_trajectory=False, expect="measured")
            for k in seeds for name, ref in test.references(k)]


def scan_results(levels: Sequence[float], outcomes: dict[float, list[RunOutcome | None]],
                 judge: Callable[[RunOutcome], bool]) -> dict[float, list[bool]]:
    """AdaptiveQuadBench's scan, judged: outcomes {delay: [run per (seed, trajectory), None where not run]} ->
    {delay: [success]}: a column succeeds at a delay when `judge` passes its run there and at every delay below
    (the scan stops at a trajectory's first instability: every delay above it fails)."""
    n = len(outcomes[levels[0]])
    alive = [True] * n
    out: dict[float, list[bool]] = {}
    for v in levels:
        row = outcomes.get(v, [None] * n)
        alive = [a and r is not None and judge(r) for a, r in zip(alive, row, strict=True)]
        out[float(v)] = list(alive)
    return out


def scan_margins(s: Search, step: float) -> list[float]:
    """Each column's (seed, trajectory's) delay margin as AdaptiveQuadBench gives it (compute_delay_margin): the
    first delay that failed less one step, or the largest delay tried where none failed [s]."""
    levels = sorted(s.evaluations)
    cols = len(s.evaluations[levels[0]])
    out = []
    for j in range(cols):
        first = next((v for v in levels if not s.evaluations[v][j]), None)
        out.append(levels[-1] if first is None else round(first - step, 12))
    return out


def delay_test(laws: Sequence[str] = LAWS, *, airframe: str, seeds: int, logs: Path, n_jobs: int = 1,
               backend: Backend | None = None, extra: Sequence[str] = (), rules: Sequence[str] = ("aqb", "ours"),
               test: AQBDelayTest = AQB_DELAY_TEST) -> dict[str, list[Search]]:
    """AdaptiveQuadBench's delay test (AQBDelayTest) of each law on `airframe`: the delay raised through
    test.levels(), each level one batch of the runs (law, seed, trajectory) still passing under some rule of
    `rules` (DELAY_RULES); {rule: a Search per law on the axis AQB_DELAY, its evaluations {delay: [success per
    (seed, trajectory)]} after scan_results}. Its margin is the largest delay every trajectory of every seed
    passed, its when2fail the smallest at which all had failed; scan_margins gives each trajectory's."""
    from adaptive_mj.study.parallel import run_jobs

    judges = [DELAY_RULES[r] for r in rules]
    levels = test.levels()
    runs: dict[str, dict[float, list[RunOutcome | None]]] = {law: {} for law in laws}
    alive = {law: None for law in laws}  # type: dict[str, list[bool] | None]
    for v in levels:
        batch: list[tuple[str, list[RunSpec]]] = []
        for law in laws:
            jobs = delay_jobs(airframe, law, v, range(seeds), logs, extra, test)
            keep = alive[law] or [True] * len(jobs)
            batch.append((law, [j for j, a in zip(jobs, keep, strict=True) if a]))
        flat = [j for _, js in batch for j in js]
        if not flat:
            break
        done = iter(run_jobs(flat, n_jobs=n_jobs, backend=backend))
        for law, _ in batch:
            keep = alive[law] or [True] * (seeds * int(test.trajectories.number))
            row = [next(done) if a else None for a in keep]
            runs[law][v] = row
            alive[law] = [a and r is not None and any(j(r) for j in judges) for a, r in zip(keep, row, strict=True)]
    out: dict[str, list[Search]] = {}
    for rule, judge in zip(rules, judges, strict=True):
        out[rule] = []
        for law in laws:
            s = Search(law, AQB_DELAY, airframe=airframe)
            tried = [v for v in levels if v in runs[law]]
            s.evaluations = scan_results(tried, runs[law], judge)
            out[rule].append(s)
    return out


@dataclass(frozen=True)
class TaskDraw:
    """One seed's task on one axis at one intensity (draw_task): the motion primitive's goal (3,) each, relative
    to its start [m, m/s, m/s²]; the switch times [s]; the wind's direction (3,) (unit); the four rotors'
    efficiency factors (4,); the payload's mass [kg] and offset (3,) [m]. Only what the axis uses is applied."""

    seed: int
    axis: str
    intensity: float
    position: tuple[float, float, float]
    velocity: tuple[float, float, float]
    acceleration: tuple[float, float, float]
    toggles: tuple[float, ...]
    wind_direction: tuple[float, float, float]
    rotor_factors: tuple[float, float, float, float]
    payload_mass: float
    payload_offset: tuple[float, float, float]

    def overrides(self, protocol: AQBProtocol = AQB, *, until: float | None = None) -> tuple[str, ...]:
        """The scenario overrides (--set expressions) of this task on PROTOCOL_TASK: the reference's goal, and the
        axis's disturbance at this intensity; until: a shorter run's duration [s], the switches after it left out."""
        out = [f"reference.position={list(self.position)!r}", f"reference.velocity={list(self.velocity)!r}",
               f"reference.acceleration={list(self.acceleration)!r}"]
        i = self.intensity
        events: list[str] = []
        if self.axis == "wind":
            out.append(f"plant.wind={[i * protocol.wind_speed.number * d for d in self.wind_direction]!r}")
        elif self.axis in ("force", "torque"):
            per = i * getattr(protocol, self.axis).number
            for k, t in enumerate(self.toggles):
                v = per if k % 2 == 0 else -per  # on at the odd switches (from off at t = 0)
                events.append(f"{{t={t!r}, kind='external_force', {self.axis}=[{v!r}, {v!r}, {v!r}]}}")
        elif self.axis == "rotor_efficiency":
            events += [f"{{t=0.0, kind='rotor_efficiency', rotor={r + 1}, value={f!r}}}"
                       for r, f in enumerate(self.rotor_factors)]
        elif self.axis == "payload":
            out.append("plant.payload='quad_box'")
            off = list(self.payload_offset)
            events.append(f"{{t=0.0, kind='payload_point', value=0.0, offset={off!r}}}")
            events += [f"{{t={t!r}, kind='payload_point', value={self.payload_mass if k % 2 == 0 else 0.0!r}, "
                       f"offset={off!r}}}" for k, t in enumerate(self.toggles)]
        if until is not None:
            events = [e for e in events if float(e[3:e.index(",")]) <= until]
        if events:
            out.append(f"events=[{', '.join(events)}]")
        return tuple(out)

    def as_dict(self) -> dict:
        from dataclasses import asdict

        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


def _toggle_times(rng: np.random.Generator, p: AQBProtocol) -> tuple[float, ...]:
    """AdaptiveQuadBench's create_disturbance_toggle_times with our generator: 1 to 4 switch times in the window, at
    least the gap apart (a candidate too close is redrawn, at most 100 times; then no more switches), sorted."""
    lo_n, hi_n = p.toggles.range
    w_lo, w_hi = p.toggle_window.range
    gap = p.toggle_gap.number
    times: list[float] = []
    for _ in range(int(rng.integers(int(lo_n), int(hi_n) + 1))):
        for _ in range(100):
            c = float(rng.uniform(w_lo, w_hi))
            if not times or min(abs(c - t) for t in times) >= gap:
                times.append(c)
                break
        else:
            break
    return tuple(sorted(times))


def draw_task(seed: int, axis: str, intensity: float, protocol: AQBProtocol = AQB) -> TaskDraw:
    """Seed `seed`'s task on `axis` (AXES) at `intensity` (AdaptiveQuadBench's I, >= 0), drawn from the ranges of
    `protocol`: the motion primitive's goal from one stream of numpy's Generator for the seed, the disturbance's
    direction, switch times, rotor factors and payload offset from another. Both streams depend on the seed only,
    so a seed's trajectory and the disturbance's direction and timing are the same at every intensity and on every
    axis; the intensity scales the magnitude (rotor efficiency: c = min(I, cap) times a factor drawn in [−1, 1];
    payload mass: min(I, cap) times the vehicle's mass). Same seed, same draw."""
    if axis not in AXES:
        raise ValueError(f"unknown axis {axis!r}; expected one of {', '.join(AXES)}")
    if not intensity >= 0:
        raise ValueError("intensity must be >= 0")
    traj, dist = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    p = protocol
    goal = [tuple(float(x) for x in traj.uniform(*r.range, size=3))
            for r in (p.trajectory_position, p.trajectory_velocity, p.trajectory_acceleration)]
    toggles = _toggle_times(dist, p)
    d = dist.uniform(*p.wind_direction.range, size=3)
    direction = tuple(float(x) for x in d / np.linalg.norm(d))
    c = min(float(intensity), p.rotor_efficiency_cap.number)
    factors = tuple(float(1.0 + c * u) for u in dist.uniform(-1.0, 1.0, size=4))
    ratio = min(float(intensity), p.payload_mass_cap.number)
    offset = tuple(float(x) * p.arm_length.number for x in dist.uniform(*p.payload_offset.range, size=3))
    return TaskDraw(seed, axis, float(intensity), goal[0], goal[1], goal[2], toggles, direction,  # type: ignore[arg-type]
                    factors, ratio * p.vehicle_mass.number, offset)  # type: ignore[arg-type]


#: the format of protocol_output's object (a new key or a changed meaning bumps it; readers check it). 2: each row
#: (as_rows) names its airframe ("aqb") and the range searched
PROTOCOL_FORMAT = 2


def protocol_levels(protocol: AQBProtocol = AQB) -> list[float]:
    """AdaptiveQuadBench's when2fail intensities: 0 to max_intensity in steps of intensity_step (0, 1, ..., 10)."""
    step, top = protocol.intensity_step.number, protocol.max_intensity.number
    return [round(k * step, 12) for k in range(int(math.floor(top / step + 1e-9)) + 1)]


def _protocol_name(law: str, axis: str, v: float) -> str:
    return f"aqb-{law}-{axis}={v:.6g}"


def protocol_jobs(laws: Sequence[str], axes: Sequence[str], levels: Sequence[float], seeds: int, logs: Path,
                  extra: Sequence[str] = (), protocol: AQBProtocol = AQB) -> list[RunSpec]:
    """AdaptiveQuadBench's trials on PROTOCOL_TASK (one batch): per law, axis, intensity and seed k the task
    draw_task(k, axis, intensity) draws, the law at AdaptiveQuadBench's gains (PROTOCOL_GAINS), logged at 20 Hz
    under logs; `extra` overrides go after the gains (e.g. a shorter simulation.duration for tests)."""
    return [RunSpec(sc.SCENARIOS_DIR / f"{PROTOCOL_TASK}.toml",
                    overrides=(RECORD_PREFLIGHT, "log.rate_hz=20", *PROTOCOL_GAINS[law], *extra,
                               *draw_task(k, axis, v, protocol).overrides(protocol)),
                    seed=k, log=logs / f"{_protocol_name(law, axis, v)}-seed{k}.mcap",
                    tag=f"{_protocol_name(law, axis, v)} seed {k}", extras=("flight_metrics",), keep_trajectory=False,
                    expect="measured")
            for law in laws for axis in axes for v in levels for k in range(seeds)]


def protocol_axis(axis: str, levels: Sequence[float]) -> Disturbance:
    """An axis of AdaptiveQuadBench's protocol as a Disturbance (for Search, table and as_rows): its unit and the
    range of the levels run; its overrides are draw_task's, per seed, so this one has none."""
    return Disturbance(axis, AXES[axis], lambda v: [], float(min(levels)), float(max(levels)),
                       doc=f"AdaptiveQuadBench's {axis} axis (study.flight.AQB)")


def protocol_results(laws: Sequence[str], axes: Sequence[str], levels: Sequence[float], seeds: int,
                     results: dict[str, RunOutcome], *, rule: str = "aqb") -> list[Search]:
    """Per (law, axis) a Search whose evaluations are each intensity's per-seed success by RULES[rule], read from
    the protocol_jobs' results by tag (a missing run fails)."""
    judge = rule_of(rule)
    found = []
    for axis in axes:
        d = protocol_axis(axis, levels)
        for law in laws:
            s = Search(law, d, airframe="aqb")
            for v in levels:
                tags = [f"{_protocol_name(law, axis, v)} seed {k}" for k in range(seeds)]
                s.evaluations[float(v)] = [judge(results[t]) if t in results else False for t in tags]
            found.append(s)
    return found


def success_curves(found: Sequence[Search]) -> list[dict]:
    """AdaptiveQuadBench's plot as data: per (law, axis), the intensities (ascending) and at each the share of
    seeds that succeeded (0 to 1), with the number of seeds."""
    return [{"law": s.law, "axis": s.disturbance.name, "unit": s.disturbance.unit,
             "intensity": sorted(s.evaluations), "success_rate": [s.success_rate(v) for v in sorted(s.evaluations)],
             "seeds": len(next(iter(s.evaluations.values()))) if s.evaluations else 0} for s in found]


def plot_success_curves(curves: Sequence[dict], path: Path, *, title: str = "") -> Path:
    """The success-rate curves (success_curves) as a PNG at path: a panel per axis, a line per law, success [%]
    against intensity, as AdaptiveQuadBench's paper plots when2fail."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes = list(dict.fromkeys(c["axis"] for c in curves))
    fig, panels = plt.subplots(1, len(axes), figsize=(3.6 * len(axes), 3.2), squeeze=False, constrained_layout=True)
    for ax, name in zip(panels[0], axes, strict=True):
        for c in (c for c in curves if c["axis"] == name):
            ax.plot(c["intensity"], [100 * r for r in c["success_rate"]], marker="o", ms=3,
                    label=LAW_LABEL.get(c["law"], c["law"]))
        unit = next(c["unit"] for c in curves if c["axis"] == name)
        ax.set_xlabel(f"intensity [{unit}]" if unit else "intensity")
        ax.set_ylabel("success [%]")
        ax.set_ylim(-5, 105)
        ax.set_title(name, fontsize=9)
    panels[0][0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def protocol_output(by_rule: dict[str, list[Search]], *, seeds: int, levels: Sequence[float],
                    protocol: AQBProtocol = AQB) -> dict:
    """The protocol study's output (JSON-ready; format PROTOCOL_FORMAT): the randomisation it drew from
    (protocol.record(), every range with its source), the task, the seeds and levels, and per failure rule its
    rows (as_rows) and success-rate curves (success_curves)."""
    return {"format": PROTOCOL_FORMAT, "protocol": "AdaptiveQuadBench", "task": PROTOCOL_TASK,
            "randomization": protocol.record(), "seeds": seeds, "levels": list(levels),
            "rules": {rule: {"rows": as_rows(found), "curves": success_curves(found)}
                      for rule, found in by_rule.items()}}


def protocol_text(protocol: AQBProtocol = AQB) -> str:
    """The randomisation as a markdown list (each figure, its unit and source), then where this suite differs."""
    from dataclasses import fields

    lines = []
    for f in fields(protocol):
        if f.name == "ours":
            continue
        r = getattr(protocol, f.name).record()
        v = r["value"]
        lines.append(f"- {f.name}: {v if not isinstance(v, list) else tuple(v)} {r['unit']} — {r['doc']} "
                     f"(`{r['source']}`)")
    return "\n".join(lines + [f"- ours: {o}" for o in protocol.ours])

"""The breaking-point study: every law × stressor × plant, margins by bisection over
seeded runs (adaptive_mj.study.breaking_point), written as its own report
(`adaptive-mj stress`) and as a section of the full bench.

Plants (each starts on its reference with the estimates at the truth, so the laws are
compared on robustness, not on their first transient, under a nominal sensor noise so
that seeds differ):
  heave: heave_tracking (y_d = cos t), σ_y = 0.5 mm, σ_y' = 5 mm/s;
  arm:   arm_payload_swap without its swap (a sum of sines), σ_y = 0.5 mrad, σ_y' = 5 mrad/s.
  ur5e:  ur5e_identification (the 6-joint arm on its exciting sum of sines), σ_q = 0.1 mrad,
         σ_q' = 1 mrad/s on every joint.
  quadrotor: quadrotor_lemniscate (the figure-eight with its 10 g payload), σ_p = 1 mm, σ_v = 1 cm/s.
Failure: divergence, a crash, or tail RMS ỹ above the plant's bound (TAIL_BOUND).

Laws and stressors: each plant kind declares its own beside its keys (PlantKind.stress: StressPlant.laws and
.stressors, functions of the row's plants.study_spec.StudyContext, every number from the compiled model): on heave
and the 1-DOF arm the lecture's sliding law and its modifications and baselines (plants.sliding_study) with a
thruster lag (heave) or a payload ratio (arm); on the 6-joint arm Slotine–Li's (plants.manipulator.study_laws,
.study_stressors); on the quadrotor the geometric laws under AdaptiveQuadBench's disturbances
(plants.quadrotor.study_laws, .study_stressors). The study adds the stressors of every plant: a control delay of
whole physics steps, and the control period T of sampled-data control: control.mode = 'sampled', control.period =
n·dt, searched over whole physics steps n from 1 to PERIOD_MAX (or the run's duration), reported in seconds. A law
with filters integrated per step (composite adaptation, L1) runs under continuous control only: n/a for the control
period.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence, TypedDict

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.study.job import SUMMARY_LOG_RATE_HZ  # noqa: F401 (the bench reads it here)
from adaptive_mj.study import callable_module
from adaptive_mj.plants import kinds
from adaptive_mj.plants.study_spec import StudyContext
from adaptive_mj.report.metrics import TAIL_FRACTION
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.breaking_point import (STRESS_PLANT_KIND, TAIL_BOUND, Margin, Search, Stressor, kind_number,
                                             margin_text, search_all)
from adaptive_mj.study.result import Study, Table

# TAIL_BOUND (breaking_point, shared with the bench): [m], [rad]: tail RMS above this is a failure
# σ_y [m], [rad]; σ_y' = 10 σ_y [per s]: each kind's own
NOMINAL_NOISE = {name: kind_number(kind, "nominal_noise") for name, kind in STRESS_PLANT_KIND.items()}
DURATION = 20.0  # s per run (its tail: report.metrics.TAIL_FRACTION, the last 25 %)


class BenchSettings(TypedDict):
    """run_study's keyword arguments that BENCH_SETTINGS sets."""

    seeds: int
    steps: int
    duration: float
    plant_laws: dict[str, tuple[str, ...]]
    plant_names: tuple[str, ...]


# the full bench's reduced study: 5 s runs, and on the 6-joint arm four laws (the full study: eight); not the
# quadrotor, whose margins the bench measures in its own section (adaptive_mj.study.sections.quadrotor_flight)
BENCH_SETTINGS: BenchSettings = {"seeds": 5, "steps": 2, "duration": 5.0,
                                 "plant_laws": {"ur5e": ("adaptive", "dead_zone", "sigma", "computed_torque")},
                                 "plant_names": ("heave", "arm", "ur5e")}
PERIOD_MAX = 1.0  # s: the control period stressor's high end (heave: 2d/k = 0.37 s; the 1-DOF arm: 2J/k = 0.085 s)
PERIOD = "control period"  # the control period stressor's name


@dataclass(frozen=True)
class Plant:
    """A row of the study: its name, its scenario (a bundled scenario's name, or the path of a user's scenario
    file, `score --scenario`), the overrides of its every run, its plant kind and, for a user's scenario, the
    score's tasks derived from it (adaptive_mj.study.score_suite.Task; empty: the suite's TASKS of its name)."""

    name: str
    scenario: str
    base: tuple[str, ...]
    kind: str = ""  # "": STRESS_PLANT_KIND[name]
    tasks: tuple = ()


def scenario_path(scenario: str) -> Path:
    """A bundled scenario's file by its name, or the scenario file a path names (ending in .toml)."""
    return Path(scenario) if scenario.endswith(".toml") else sc.SCENARIOS_DIR / f"{scenario}.toml"


def _kind(p: Plant) -> kinds.PlantKind:
    """The plant kind of row p."""
    return kinds.built_in()[p.kind or STRESS_PLANT_KIND[p.name]]


def tail_bound(p: Plant) -> float:
    """[output unit] Row p's failure bound on the tail RMS error: its plant kind's (PlantKind.tail_bound)."""
    return kind_number(_kind(p).name, "tail_bound")


def nominal_noise(p: Plant) -> float:
    """[output unit] Row p's nominal measurement noise σ_y: its plant kind's (PlantKind.nominal_noise)."""
    return kind_number(_kind(p).name, "nominal_noise")


def _row(p: Plant) -> kinds.StressPlant:
    """What p's plant kind declares for the study (PlantKind.stress)."""
    row = _kind(p).stress
    assert row is not None  # the study's plants are the kinds that declare one (STRESS_PLANT_KIND)
    return row


def plants(duration: float = DURATION) -> list[Plant]:
    """The study's plants: each plant kind that declares its row (PlantKind.stress), in the registry's order, on
    its scenario for `duration` [s] with its own overrides, the estimates at the truth and its nominal noise."""
    out = []
    for name, kind in STRESS_PLANT_KIND.items():
        row = kinds.built_in()[kind].stress
        assert row is not None  # STRESS_PLANT_KIND holds the kinds that declare one
        out.append(Plant(name, row.scenario, _base(kinds.built_in()[kind], duration), kind))
    return out


def _base(kind: kinds.PlantKind, duration: float) -> tuple[str, ...]:
    """The overrides of every stress run on a plant of `kind` (it declares a study row): `duration` [s], the row's
    own overrides, the estimates at the truth and the kind's nominal noise σ_y (10 σ_y on the rate)."""
    row = kind.stress
    assert row is not None
    sig, (y, y_dot) = kind_number(kind.name, "nominal_noise"), row.noise_signals
    return (f"simulation.duration={duration}", *row.overrides, "law.initial_estimates='model'",
            f"noise.std={{{y}={sig!r}, {y_dot}={10 * sig!r}}}")


def user_plant(path: Path, duration: float = DURATION, *, tasks: tuple = ()) -> Plant:
    """A row for a user's scenario file (`score --scenario`): its plant kind's study row (PlantKind.stress: the
    overrides of a stress run, the signals the nominal noise is on) applied to this scenario, named after the
    file. One line when the file cannot be loaded or its plant kind declares no study row."""
    scn = sc.load(path)
    study_row(path, scn.plant.kind)
    kind = kinds.built_in()[scn.plant.kind]
    return Plant(Path(path).stem, str(path), _base(kind, duration), kind.name, tasks)


def study_row(path: Path, kind_name: str) -> kinds.StressPlant:
    """What plant kind `kind_name` (of the scenario file at `path`) declares for the studies (PlantKind.stress);
    one line naming the file when it declares nothing."""
    kind = kinds.built_in().get(kind_name)
    if kind is None or kind.stress is None:
        scored = sorted(k.name for k in kinds.built_in().values() if k.stress is not None)
        raise ScenarioError(f"{path}: plant.kind {kind_name!r} declares no study row (PlantKind.stress: its "
                            f"laws, stressors and failure bound); expected a scenario of one of {', '.join(scored)}")
    return kind.stress


def continuous_only(p: Plant, overrides: tuple[str, ...]) -> bool:
    """Whether the law of these overrides on p has filters integrated in the stage states (composite adaptation,
    L1's predictor and filter): sampled-data control does not apply to it, so neither does the control period."""
    from adaptive_mj.setup.build import build

    if overrides not in _FILTERS:
        scn = sc.load(scenario_path(p.scenario), overrides=[*p.base, *overrides])
        law = build(scn).law
        _FILTERS[overrides] = bool(getattr(law, "has_filters", False))
    return _FILTERS[overrides]


_FILTERS: dict[tuple[str, ...], bool] = {}


def _setup(p: Plant):
    from adaptive_mj.setup.build import build

    scn = sc.load(scenario_path(p.scenario), overrides=list(p.base))
    return scn, build(scn)


def context(p: Plant) -> StudyContext:
    """What row p's law and stressor sets read (plants.study_spec.StudyContext), from its scenario with its
    overrides and the compiled model."""
    scn, s = _setup(p)
    kind, row = _kind(p), _row(p)
    dt = scn.simulation.timestep
    if dt is None:  # the model's own timestep
        dt = float(s.plant.dt)
    return StudyContext(p.name, p.scenario, kind.output_unit, kind.control_unit, row.disturbance, row.composite,
                        tuple(s.law.names), np.asarray(s.law.gamma), scn.law.lam, s.plant.true_theta(), dt,
                        nominal_noise(p), scn.plant.payload_mass, s.plant)


def laws(p: Plant, *, composite: bool, ctx: StudyContext | None = None) -> list[tuple[str, list[str]]]:
    """(law label, overrides) for plant p: what its plant kind declares (StressPlant.laws), every number derived
    from the scenario and its model (ctx: context(p), when the caller has it)."""
    return _row(p).laws(ctx or context(p), composite)


def stressors(p: Plant, duration: float = DURATION, *, ctx: StudyContext | None = None) -> list[Stressor]:
    """Plant p's stressors for runs of `duration` [s]: its plant kind's own (StressPlant.stressors), then those of
    every plant: a control delay of 0 to 200 whole physics steps and the control period from one physics step to
    PERIOD_MAX or the run's duration (ctx: context(p), when the caller has it)."""
    ctx = ctx or context(p)
    return [*_row(p).stressors(ctx, duration),
            Stressor("delay", lambda v: [f"simulation.control_delay={int(v)}"], 0, 200, integer=True, unit="steps"),
            Stressor.control_period(ctx.dt, min(PERIOD_MAX, duration), ctx.dt, name=PERIOD)]


def with_law(p: Plant, entries: list[tuple[str, list[str]]], law: str | None, sets: tuple[str, ...] = (),
             gains: dict[str, list[str]] | None = None) -> list[tuple[str, list[str]]]:
    """The plant's laws with law kind `law` (a built-in kind or an installed plugin) after them, swapped in
    (setup.scenario.law_swap) with its gains for the plant's kind (`gains`: plant kind -> --set expressions, as
    score --gains reads them) and its --set keys, when it serves a form of the plant's kind; the label is the
    kind's name ("NAME (yours)" when a built-in label has it)."""
    if law is None:
        return entries
    from adaptive_mj.laws.kinds import all_kinds, serving

    k = _kind(p)
    if law not in serving(k.name, k.forms, {law: all_kinds()[law]}):
        return entries
    label = f"{law} (yours)" if any(name == law for name, _ in entries) else law
    return [*entries, (label, [sc.law_swap(law), *(gains or {}).get(k.name, []), *sets])]


def study(*, composite: bool, duration: float = DURATION, plant_laws: Mapping[str, tuple[str, ...]] | None = None,
          law: str | None = None, sets: tuple[str, ...] = (),
          gains: dict[str, list[str]] | None = None, plant_names: tuple[str, ...] | None = None,
          extra: tuple[str, ...] = ()) -> list[Search]:
    """Every plant × law × stressor search; plant_names: the plants to include (None: all); extra: overrides of
    every run after the plant's (e.g. the log's rate); plant_laws: plant name -> the built-in laws to include on
    it (a plant not named, or None: all its laws);
    law: a law kind added on the plants it serves, with its gains and --set keys `sets` (with_law); one line when
    it serves none of them."""
    out = []
    served = False
    for p in plants(duration):
        if plant_names is not None and p.name not in plant_names:
            continue
        path = scenario_path(p.scenario)
        ctx = context(p)
        own = laws(p, composite=composite, ctx=ctx)
        entries = with_law(p, own, law, sets, gains)
        served = served or (law is not None and len(entries) > len(own))
        kept = (plant_laws or {}).get(p.name)
        conditions = stressors(p, duration, ctx=ctx)
        for name, over in entries:
            if kept is not None and name not in kept and not (law and name.startswith(law)):
                continue
            for st in conditions:
                if st.name == PERIOD and continuous_only(p, tuple(over)):  # n/a: its filters integrate per step
                    continue
                out.append(Search(path, f"{p.name}/{name}", (*p.base, *extra, *over), st, tail_bound(p)))
    if law is not None and not served:
        raise ScenarioError(f"--law: {law!r} serves none of the study's plants ({', '.join(STRESS_PLANT_KIND)})")
    return out


def table(margins: list[Margin], *, seeds: int) -> Table:
    """One row per plant/law, one column per stressor: margin (next failing value), and below it, at the margin
    over the seeds, mean / CVaR10 % of the tail error and the failure rate at the next value; n/a: the stressor
    does not apply (its to_markdown() is the report's table)."""
    stressor_names = list(dict.fromkeys(m.search.stressor.name for m in margins))
    by = {(m.search.label, m.search.stressor.name): m for m in margins}
    rows = []
    for label in dict.fromkeys(m.search.label for m in margins):
        row = {"plant / law": label}
        for name in stressor_names:
            margin = by.get((label, name))
            row[name] = "n/a" if margin is None else _cell(margin)
        rows.append(row)
    return Table.of(rows, ["plant / law", *stressor_names])


def _cell(margin: Margin) -> str:
    """A margin as the stress table shows it: its bracket, then the tail mean / CVaR10 and failure rate beyond."""
    st = margin.stats()
    extra = []
    if st["tail_mean"] is not None:
        extra.append(f"tail {st['tail_mean']:.2g}/{st['tail_cvar10']:.2g}")
    if st["failure_rate_beyond"] is not None:
        extra.append(f"fail {100 * st['failure_rate_beyond']:.0f} %")
    return margin_text(margin) + ("<br>" + ", ".join(extra) if extra else "")


def unseparated_text(margins: Sequence[Margin], *, steps: int) -> str:
    """One sentence naming, per plant and stressor, the laws this study's resolution cannot tell apart: two or more
    laws whose searches ended in the same bracket (margin, next failing value) with a gap left open (a bracket
    closed to neighbouring values is as fine as the stressor goes; a search that failed at the range's low end or
    passed at its high end is ended by the range). "" when there is none. steps: the study's bisection steps (the
    sentence says how to get more)."""
    groups: dict[tuple[str, str, float, float], list[str]] = {}
    for m in margins:
        plant, _, law = m.search.label.partition("/")
        st = m.search.stressor
        if m.margin is None or m.first_fail is None:
            continue  # failed at the low end or passed at the high end: the range, not the resolution, ends it
        if (st.integer and m.first_fail - m.margin <= 1) or (st.step > 0 and st.steps_between(m.margin,
                                                                                             m.first_fail) <= 1):
            continue  # closed as far as the stressor goes (breaking_point's own stop): a real tie
        groups.setdefault((plant, m.search.stressor.name, m.margin, m.first_fail), []).append(law or plant)
    ties = [(key, laws) for key, laws in groups.items() if len(laws) > 1]
    if not ties:
        return ""
    parts = [f"{plant} {name} {margin_text_of(lo, hi)}: {', '.join(laws)}" for (plant, name, lo, hi), laws in ties]
    return (f"**Not told apart at this resolution** ({steps} bisection steps; the same bracket, which their "
            f"margins may lie anywhere in): " + "; ".join(parts) + ". `adaptive-mj stress --steps N` with a larger N "
            "(each step halves a bracket) separates them or shows a tie.")


def margin_text_of(margin: float, first_fail: float) -> str:
    """A bracket in words: "[margin, first_fail)"."""
    return f"[{margin:g}, {first_fail:g})"


def preflight_text(margins: Sequence[Margin]) -> str:
    """One sentence: how many of the study's runs the pre-flight check predicted unstable, and how many of those
    failed when run (every probe is run, whatever the law: job.RECORD_PREFLIGHT)."""
    predicted = [(p, math.isfinite(t)) for m in margins for e in m.evaluations
                 for p, t in zip(e.predicted, e.tails, strict=True) if p]
    skipped = sum(m.screened_out for m in margins)
    screened = (f" Screening left out {skipped} runs (a value's other seeds once its first had failed: the value "
                "fails either way), by the same rule for every law." if skipped else "")
    if not predicted:
        return ("The pre-flight check predicted none of the runs unstable; every probe was run and judged by its "
                "outcome, whatever the law." + screened)
    failed = sum(not passed for _, passed in predicted)
    return (f"The pre-flight check predicted {len(predicted)} of the runs unstable (a law that declares its feedback "
            f"is checked); they were run like the others, whatever the law, and {failed} of them failed."
            + screened)


def _bounds_text(searches: list[Search] | None = None) -> str:
    """Each plant's failure bound in words: "0.01 m (heave), 0.05 rad (arm) or ..." (PlantKind.tail_bound, its
    output unit and StressPlant.label), of the plants among `searches` (None: all)."""
    parts = []
    shown = None if searches is None else {s.label.split("/")[0] for s in searches}
    for name, kind in STRESS_PLANT_KIND.items():
        if shown is not None and name not in shown:
            continue
        k = kinds.built_in()[kind]
        assert k.stress is not None  # STRESS_PLANT_KIND holds the kinds that declare one
        parts.append(f"{TAIL_BOUND[name]:g} {k.output_unit} ({k.stress.label or name})")
    return ", ".join(parts[:-1]) + " or " + parts[-1] if len(parts) > 1 else "".join(parts)


def run_study(out: Path, *, seeds: int, steps: int, composite: bool, n_jobs: int,
              duration: float = DURATION, backend=None,
              plant_laws: Mapping[str, tuple[str, ...]] | None = None, law: str | None = None,
              sets: tuple[str, ...] = (), gains: dict[str, list[str]] | None = None,
              plant_names: tuple[str, ...] | None = None,
              log_rate_hz: float | None = None) -> tuple[list[Margin], str, float]:
    """Run the study (on `backend`: a parallel.Backend, default n_jobs local processes); returns the
    margins, the report text and the wall time [s]."""
    import sys

    from adaptive_mj.study.parallel import progress_printer

    extra = () if log_rate_hz is None else (f"log.rate_hz={log_rate_hz!r}",)
    searches = study(composite=composite, duration=duration, plant_laws=plant_laws, law=law, sets=sets, gains=gains,
                     plant_names=plant_names, extra=extra)
    t0 = time.perf_counter()
    at_most = len(searches) * seeds * (2 + steps)  # bisection stops early where a bracket closes

    def batch(k, total):
        print(f"\nstress: batch {k}/{total} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)

    margins = search_all(searches, seeds=seeds, steps=steps, logs=out / "logs", n_jobs=n_jobs, backend=backend,
                         on_batch=batch, on_done=progress_printer(at_most, label="runs (at most)"), screen=True)
    wall = time.perf_counter() - t0
    runs = sum(len(e.tails) for m in margins for e in m.evaluations)
    screened = ("" if seeds == 1 else " (a value's other seeds run where its first passed: a value fails when "
                "any seed fails; the first failing value runs on every seed)")
    untold = unseparated_text(margins, steps=steps)  # the laws this resolution cannot tell apart, if any
    text = (f"{len(searches)} breaking-point searches (plant × law × stressor), {seeds} seeds per value{screened}, "
            f"the two ends and {steps} bisection steps: {runs} runs of {duration:g} s in {wall:.0f} s. "
            f"A run fails when it diverges, crashes or its tail RMS ỹ exceeds {_bounds_text(searches)}; the tail "
            "is the last "
            f"{100 * TAIL_FRACTION:g} % of a run; "
            "a value passes when every seed passes. Each cell: the margin (the "
            "largest value that passed) and, in brackets, the smallest that failed: their gap is the resolution; "
            "then, over the seeds at the margin, the mean / CVaR at 10 % (the worst seed of "
            f"{seeds}) of the tail error, and the failure rate at the failing value. n/a: the stressor does not "
            "apply to that plant. Every run's log is in `logs/`"
            + ("" if log_rate_hz is None else f" (its summary and a row every {1 / log_rate_hz:g} s; the margins "
               "come from the full-rate rows)") + ". " + preflight_text(margins) + "\n\n"
            + table(margins, seeds=seeds).to_markdown()
            + ("\n\n" + untold if untold else ""))
    return margins, text, wall


def run_stress(*, seeds: int, steps: int, duration: float, composite: bool, out: Path | None, backend,
               law: str | None = None, sets: tuple[str, ...] = (),
               plant_names: tuple[str, ...] | None = None) -> Study:
    """The study with options adaptive_mj.study.api.stress has checked: report.md, report.html and
    margins.csv in `out` (default a new logs/stress-...)."""
    from adaptive_mj.report.html import write_html
    from adaptive_mj.runs.runner import new_output_dir
    from adaptive_mj.study.parallel import session

    out = new_output_dir(out, "stress")
    with session(backend):
        margins, text, wall = run_study(out, seeds=seeds, steps=steps, composite=composite,
                                        n_jobs=backend.jobs, duration=duration, backend=backend, law=law, sets=sets,
                                        plant_names=plant_names)
    report = "# adaptive-mj breaking points\n\n" + text + "\n"
    (out / "report.md").write_text(report, encoding="utf-8")
    html = write_html(out / "report.md")  # report.html: the same text, for a browser
    rows = [{"plant_law": m.search.label, "stressor": m.search.stressor.name, "unit": m.search.stressor.unit,
             "lo": m.search.stressor.lo, "hi": m.search.stressor.hi, **m.stats()} for m in margins]
    Table.of(rows).to_csv(out / "margins.csv")
    return Study("stress", out, 0, out / "report.md", html,
                 text + f"\n\nreport: {out / 'report.md'}  ({wall:.0f} s)\nhtml: {html}",
                 info={"seconds": wall}, load_rows=lambda: rows,
                 plotter=lambda path=None: plot_margins(rows, path or out / "margins.png"))


def margin_position(row: dict) -> float:
    """Where a margin lies in its stressor's range: 0 = the low end already fails, 1 = the high end still
    passes; in between on the bisection's own scale (geometric over a decade or more from > 0, else linear)."""
    lo, hi, margin = row["lo"], row["hi"], row["margin"]
    if margin is None:
        return 0.0
    if row["first_fail"] is None:
        return 1.0
    if lo > 0 and hi / lo >= 10:
        return float(math.log(margin / lo) / math.log(hi / lo))
    return float((margin - lo) / (hi - lo))


def plot_margins(rows: list[dict], path: Path) -> Path:
    """A plant/law × stressor grid: each cell coloured by where its margin lies in the stressor's range
    (margin_position) and labelled with the margin in the stressor's unit; n/a cells left white."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    laws = list(dict.fromkeys(r["plant_law"] for r in rows))
    stressors = list(dict.fromkeys(r["stressor"] for r in rows))
    grid = np.full((len(laws), len(stressors)), np.nan)
    fig, ax = plt.subplots(figsize=(1.3 * len(stressors) + 2.5, 0.42 * len(laws) + 1.6), constrained_layout=True)
    for r in rows:
        i, j = laws.index(r["plant_law"]), stressors.index(r["stressor"])
        grid[i, j] = margin_position(r)
        text = "< lo" if r["margin"] is None else f"{r['margin']:.3g}" + ("+" if r["first_fail"] is None else "")
        ax.text(j, i, text, ha="center", va="center", fontsize=7)
    image = ax.imshow(grid, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
    units = {name: " or ".join(dict.fromkeys(r["unit"] for r in rows if r["stressor"] == name and r["unit"]))
             for name in stressors}  # a stressor's unit per plant: noise σ_y in m (heave) or rad (arms)
    ax.set_xticks(range(len(stressors)), [f"{n} [{units[n]}]" if units[n] else n for n in stressors],
                  rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(len(laws)), laws, fontsize=8)
    fig.colorbar(image, ax=ax, label="margin's place in the range searched [-] (0: fails at its low end, "
                                     "1: passes at its high end)", shrink=0.8)
    ax.set_title("breaking points: the largest value that passed (+: the high end passed)", fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


callable_module(__name__)  # adaptive_mj.study.stress(...) calls adaptive_mj.study.api.stress(...)

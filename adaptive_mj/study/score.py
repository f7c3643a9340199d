"""`adaptive-mj score`: a law ranked against the baselines on every plant kind it serves (the suite:
adaptive_mj.study.score_suite), written as scorecard.json, scorecard.md and scorecard.html with a figure per
criterion group, and every run's log.

The law under test runs as `law=NAME` (the scenario's [law] table swapped for the law's, adaptive_mj.setup.
scenario.law_swap) plus its gains for the plant (`--gains FILE.toml`: a table per plant kind) and `--set law.*`.
The baselines are the breaking-point study's laws on that plant (adaptive_mj.study.stress.laws): on the 1-DOF
plants the lecture's law, its dead-zone, σ-, e-modification and projection, the fixed-parameter and robust
sliding baselines; on the UR5e Slotine–Li, its modifications, computed torque and PD + gravity. Those given the
true parameters (the fixed ones) are marked oracles: a reference, not a competitor.
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import platform
import time
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence, TypeGuard

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.plants import kinds
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import score_suite as suite
from adaptive_mj.study import stress
from adaptive_mj.study.breaking_point import Margin, Search, _file_name, search_all
from adaptive_mj.study.job import RECORD_PREFLIGHT, RunSpec, RunOutcome
from adaptive_mj.study.job import passes
from adaptive_mj.study.sweep import to_toml
from adaptive_mj.study.stats import CONFIDENCE, RANKING, Estimate, cvar, estimate, paired_ranks, separated_pairs
from adaptive_mj.trajectory import Status

CARD_FORMAT = "adaptive-mj scorecard"
MARGIN_LOG_RATE_HZ = 1.0  # the margin runs' logs: the summary and a row per second (full_logs: the scenario's own)
COST_SECONDS = 1.0  # s simulated per compute-cost timing (the best of COST_REPS)
COST_REPS = 3
ORACLE_KINDS = ("fixed_nominal", "robust_sliding", "computed_torque", "pd_gravity", "geometric")
# keys of the law under test that would change a task, not the law: refused in --gains and --set
TASK_KEYS = ("kind", "initial_estimates", "nominal", "order")


@dataclass(frozen=True)
class Entry:
    """A law on a plant: its label on the card, its overrides, whether it is the law under test, and whether it
    is given the true parameters (an oracle baseline)."""

    label: str
    overrides: tuple[str, ...]
    tested: bool = False
    oracle: bool = False


def read_gains(path: Path | None) -> dict[str, list[str]]:
    """--gains FILE.toml: a table per plant kind ([heave], [arm], [manipulator]) of law keys -> the --set
    expressions per plant kind. Anything else is refused in one line naming the file and the key."""
    if path is None:
        return {}
    import tomllib

    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"{path}: --gains file not found")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    scored = {kinds.built_in()[k].name for k in stress.STRESS_PLANT_KIND.values()}
    out = {}
    for key, table in doc.items():
        if key not in scored:
            raise ScenarioError(f"{path}: key {key!r}: expected a table named after a scored plant kind "
                                f"({', '.join(sorted(scored))}), got {key!r}")
        if not isinstance(table, dict):
            raise ScenarioError(f"{path}: key {key!r}: expected a table of law keys, got {type(table).__name__}")
        for k in table:
            if k in TASK_KEYS:
                raise ScenarioError(f"{path}: key {key}.{k}: the suite sets law.{k} for every law alike (the task, "
                                    "not the law); expected the law's own gains, got it set")
        out[key] = [f"law.{k}={to_toml(v)}" for k, v in table.items()]
    return out


def _truth_half(p: stress.Plant) -> str:
    """Half the true θ (from the compiled model) as a law.initial_estimates table."""
    _, s = stress._setup(p)
    return "{" + ", ".join(f"{json.dumps(n)}={0.5 * float(v)!r}" for n, v in
                           zip(s.law.names, s.plant.true_theta(), strict=True)) + "}"


def task_overrides(p: stress.Plant, task: suite.Task, duration: float) -> tuple[str, ...]:
    """The overrides of `task` on plant row p for a run of `duration` [s], its templates filled from the model."""
    values: dict[str, str] = {"half": repr(0.5 * duration)}
    text = " ".join(task.overrides)
    if "{theta_half}" in text:
        values["theta_half"] = _truth_half(p)
    if "{payload_x4}" in text:
        m0 = sc.load(stress.scenario_path(task.scenario)).plant.payload_mass
        if m0 is None:
            raise ScenarioError(f"{task.scenario}: the change task needs plant.payload_mass")
        values["payload_x4"] = repr(4.0 * float(m0))
    out = [f"simulation.duration={duration!r}"]
    if task.noise_scale > 0:
        y, y_dot = _kind(p).stress.noise_signals  # type: ignore[union-attr]
        sig = task.noise_scale * stress.nominal_noise(p)
        out.append(f"noise.std={{{y}={sig!r}, {y_dot}={10 * sig!r}}}")
    out += [o.format(**values) for o in task.overrides]
    return tuple(out)


def _kind(p: stress.Plant) -> kinds.PlantKind:
    return stress._kind(p)


@functools.cache
def draws(p: stress.Plant, task: suite.Task, seed: int) -> tuple[tuple[str, ...], dict[str, Any]]:
    """What seed `seed` draws of `task` on plant row p (ScoreTask.draws): the overrides that apply the draw, and
    the drawn values by key. The generator is seeded by the suite's version, the plant, the task and the seed
    alone, so every law meets the same draw on that seed (a paired comparison), on every machine."""
    if not task.draws:
        return (), {}
    rng = np.random.default_rng([suite.SUITE_VERSION, zlib.crc32(p.name.encode()), zlib.crc32(task.name.encode()),
                                 seed])
    path = stress.scenario_path(task.scenario)
    scn = sc.load(path)
    over: list[str] = []
    values: dict[str, Any] = {}
    for d in task.draws:
        if d.key == "law.initial_estimates":  # on the scenario's own truth, so inside any box set about it
            from adaptive_mj.setup.build import build

            s = build(scn)
            value: Any = {n: float(v) * float(rng.uniform(d.lo, d.hi))
                          for n, v in zip(s.law.names, s.plant.true_theta(), strict=True)}
        else:
            value = _drawn(_base_value(scn, d.key, task), d, rng)
        values[d.key] = value
        over.append(f"{d.key}={to_toml(value)}")
    return tuple(over), values


def _base_value(scn: Any, key: str, task: suite.Task) -> Any:
    """The value of a drawn key in the task's scenario, as loaded (defaults filled): reference.* from its
    [reference] table, plant.* from its [plant] table; one line when it has none."""
    section, _, name = key.partition(".")
    table = {"reference": scn.reference.params, "plant": vars(scn.plant)}.get(section, {})
    value = table.get(name)
    if value is None:
        raise ScenarioError(f"{task.scenario}: the score's task {task.name!r} draws {key}, and the scenario has none "
                            "(expected a number, or numbers in a list or table)")
    return value


def _drawn(value: Any, d: kinds.Draw, rng: np.random.Generator) -> Any:
    """`value` (a number, a list or tuple of numbers, or a table of them) with draw d applied: each number times a
    factor (or plus an offset, d.add) from U[d.lo, d.hi], one for them all or one each (d.each)."""
    one = float(rng.uniform(d.lo, d.hi))

    def apply(v: Any) -> Any:
        if isinstance(v, dict):
            return {k: apply(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [apply(x) for x in v]
        r = float(rng.uniform(d.lo, d.hi)) if d.each else one
        return float(v) + r if d.add else float(v) * r

    return apply(value)


def tasks_of(p: stress.Plant) -> tuple[suite.Task, ...]:
    """Plant row p's tasks: those derived from a user's scenario (score --scenario), else the suite's."""
    return p.tasks or suite.TASKS[p.name]


def scenario_row(path: Path, duration: float) -> stress.Plant:
    """A user's scenario file as a scored plant row (stress.user_plant) with the suite's three tasks derived from
    it, as the suite's own tasks are built:
      tracking  the scenario as given (its own estimates and noise);
      change    from the estimates at the truth, under the nominal noise, its payload's mass times four at half
                the run (plant.payload_mass; a scenario without a payload: one line);
      hold      its reference held at its value at t = 0 as its plant kind declares (StressPlant.hold: a constant,
                every joint at its start, a hover at the start) under the nominal noise, from the estimates at the
                truth: any change of the estimates is drift."""
    from adaptive_mj.setup.build import build

    path = Path(path)
    scn = sc.load(path)
    if scn.plant.payload_mass is None:
        raise ScenarioError(f"{path}: score's change task multiplies the payload's mass: expected plant.payload and "
                            "plant.payload_mass, got none")
    setup = build(scn)
    start = np.asarray(setup.reference(0.0, 0), dtype=float)[0]  # y_d(0): (m,) on joints or axes, a float else
    row = stress.study_row(path, scn.plant.kind)
    held = row.hold(setup.plant, start)
    tasks = (suite.Task("tracking", str(path), (), noise_scale=0.0),
             suite.Task("change", str(path), ("law.initial_estimates='model'",
                                              "events=[{{t={half}, kind='payload_mass', value={payload_x4}}}]"),
                        extras=("change_response",)),
             suite.Task("hold", str(path), ("law.initial_estimates='model'", "events=[]", held),
                        extras=("estimate_drift",)))
    return stress.user_plant(path, duration, tasks=tasks)


def serves(law: str, p: stress.Plant) -> bool:
    """Whether law kind `law` serves a form plant row p's kind offers (adaptive_mj.laws.kinds.serving)."""
    from adaptive_mj.laws.kinds import all_kinds, serving

    k = _kind(p)
    return law in serving(k.name, k.forms, {law: all_kinds()[law]})


def law_kind_checked(law: str) -> None:
    """One line when `law` is no law kind (built in or installed), naming the close ones."""
    from adaptive_mj.laws.kinds import all_kinds

    names = all_kinds()
    if law not in names:
        import difflib

        close = difflib.get_close_matches(law, list(names), n=1)
        raise ScenarioError(f"score: {law!r} is not a law kind (built in or installed: `adaptive-mj list --laws`)"
                            + (f"; did you mean {close[0]!r}?" if close else ""))


def entries(p: stress.Plant, law: str | None, label: str, gains: Sequence[str], sets: Sequence[str],
            against: Sequence[str] | None) -> list[Entry]:
    """The law under test (first, when `law`) and the baselines on plant row p (`against`: only those)."""
    base = [Entry(name, tuple(over), oracle=any(f"law.kind='{k}'" in over for k in ORACLE_KINDS)
                  or any(o.startswith("law.theta0=") for o in over))
            for name, over in stress.laws(p, composite=False)]
    if against is not None:
        base = [e for e in base if e.label in against]
    out = []
    if law is not None:
        out.append(Entry(label, (sc.law_swap(law), *gains, *sets), tested=True))
    return out + base


def baseline_names(p: stress.Plant) -> list[str]:
    return [name for name, _ in stress.laws(p, composite=False)]


# ---------------------------------------------------------------- one seed's figures


def _param_error(summary: dict | None) -> float:
    """‖θ̂ − θ‖ / ‖θ‖ at the end of the run (the whole parameter vector, so that a parameter near zero does not
    blow the figure up); NaN without estimates."""
    final = (summary or {}).get("final") or {}
    est, true = final.get("theta_hat") or {}, final.get("theta") or {}
    if not true:
        return math.nan
    th = np.array([true[n] for n in true], dtype=float)
    eh = np.array([est.get(n, math.nan) for n in true], dtype=float)
    scale = float(np.linalg.norm(th))
    return float(np.linalg.norm(eh - th) / (scale if scale > 0 else 1.0))


def _completed(r: RunOutcome | None) -> TypeGuard[RunOutcome]:
    """Whether a run finished (ok or failed by its criteria; not crashed, diverged, refused or in error):
    study.job's `passes` with no bound (None: a task not run)."""
    return r is not None and passes(r)


def seed_figures(runs: dict[str, RunOutcome], bound: float, limits: tuple[float, float],
                 durations: dict[str, float]) -> dict:
    """The criteria (score_suite.CRITERIA) of one law on one plant for one seed, from its task runs (task name ->
    RunOutcome): a dict criterion -> value, plus "success" (0 or 1) and "performance"."""
    tr, ch, hold = runs.get("tracking"), runs.get("change"), runs.get("hold")
    ok = _completed(ch) and all(r is not None and passes(r, tail_bound=bound) for r in (tr, hold))
    out: dict[str, float] = {c.name: math.nan for c in suite.CRITERIA}
    if _completed(tr):
        m = (tr.summary or {})["metrics"]
        out["tail_error"] = tr.tail_error
        out["control_rms"] = float(m["control_rms"])
        out["control_tv_rate"] = float(m["control_total_variation"]) / durations["tracking"]
        out["param_error"] = _param_error(tr.summary)
    if _completed(ch) and ch.extras.get("change_response"):
        resp = ch.extras["change_response"]
        out["peak_after_change"] = float(resp["peak_error_after"])
        env = np.asarray(resp["envelope"], dtype=float)
        above = np.nonzero(env >= bound)[0]
        left = durations["change"] - resp["event_time"]
        out["recovery_time"] = 0.0 if above.size == 0 else min(left, float(above[-1] + 1) * resp["window"])
        if env.size and env[-1] >= bound:
            out["recovery_time"] = left
    if _completed(hold):
        out["drift_rate"] = abs(float(hold.extras.get("estimate_drift", math.nan)))
    out["success"] = 1.0 if ok else 0.0
    out["performance"] = performance(out, normalisers(bound, limits, durations))
    return out


def performance(figs: dict, norm: dict) -> float:
    """S of one seed from its criteria (a value that is not finite counted at its worst) and its "success" (0 or
    1), with the plant's normalisers `norm` (normalisers); the drift is judged with identification
    (score_suite.JUDGED_TOGETHER: a still estimate earns nothing when it is still because the law does not adapt,
    its term at least the parameter error's)."""
    part = {c.name: 1.0 if not math.isfinite(figs[c.name]) else min(1.0, max(0.0, figs[c.name] / norm[c.name]))
            for c in suite.CRITERIA}
    for name, with_ in suite.JUDGED_TOGETHER.items():
        part[name] = max(part[name], part[with_])
    return figs["success"] * (1.0 - sum(c.weight * part[c.name] for c in suite.CRITERIA))


def normalisers(bound: float, limits: tuple[float, float], durations: dict[str, float]) -> dict[str, float]:
    """n_i of each criterion on a plant (score_suite.CRITERIA's rules): bound the failure bound [output unit],
    limits (RMS, sum) of the actuators' limits [control unit], durations [s] per task."""
    rms_limit, sum_limit = limits
    return {"tail_error": bound, "peak_after_change": 10.0 * bound, "recovery_time": 0.5 * durations["change"],
            "control_rms": rms_limit, "control_tv_rate": 100.0 * sum_limit, "param_error": 1.0, "drift_rate": 1.0}


def actuator_limits(p: stress.Plant) -> tuple[float, float]:
    """(RMS, sum) over the actuators of the larger |limit| of each [control unit], from the compiled model."""
    _, s = stress._setup(p)
    lo, hi = (np.atleast_1d(np.asarray(x, dtype=float)) for x in s.plant.ctrl_range)
    lim = np.maximum(np.abs(lo), np.abs(hi))
    return float(np.sqrt(np.mean(lim**2))), float(np.sum(lim))


# ---------------------------------------------------------------- compute cost


def compute_ratio(p: stress.Plant, entry: Entry, task: suite.Task, *, seconds: float = COST_SECONDS) -> float:
    """The law's closed loop per physics step against bare mj_step on the same model, on the tracking task as it
    runs (its noise, sensors, control timing; no log), the best of COST_REPS timings of `seconds` simulated each,
    after one run that compiles."""
    import contextlib
    import io

    import mujoco

    from adaptive_mj.setup.build import build
    from adaptive_mj.sim.loop import run
    from adaptive_mj.runs.runner import start

    path = stress.scenario_path(task.scenario)
    over = [*task_overrides(p, task, seconds), *draws(p, task, 0)[0], *entry.overrides]  # seed 0's task

    def timed(sec: float) -> tuple[float, float]:
        scn = sc.load(path, overrides=[*over, f"simulation.duration={sec!r}"])
        with contextlib.redirect_stderr(io.StringIO()):  # its notes and pre-flight lines: the task runs said them
            st = start(scn)
        steps = max(1, round(sec / st.setup.plant.dt))
        t0 = time.perf_counter()
        run(st.setup.plant, st.setup.law, st.setup.reference, **st.kwargs)
        loop = (time.perf_counter() - t0) / steps
        st.setup.plant.release()
        bare: Any = build(scn).plant  # a MuJoCo plant: its model and data
        m, d = bare.model, bare.data
        t0 = time.perf_counter()
        mujoco.mj_step(m, d, nstep=steps)
        return loop, (time.perf_counter() - t0) / steps

    timed(0.01)  # compiles (or loads the cache)
    best = [timed(seconds) for _ in range(COST_REPS)]
    return float(min(b[0] for b in best) / min(b[1] for b in best))


# ---------------------------------------------------------------- the card's run specs (score --verify)


def _file(path: Path, hashes: dict[Path, str]) -> dict:
    path = Path(path).resolve()
    if path not in hashes:
        hashes[path] = hashlib.sha256(path.read_bytes()).hexdigest()
    return {"scenario": str(path), "sha256": hashes[path]}


def _relative(log: Path | None, out: Path) -> str | None:
    return None if log is None else os.path.relpath(Path(log).resolve(), Path(out).resolve())


def record_specs(out: Path, jobs: Sequence[RunSpec], keys: Sequence[tuple[str, str, str, int]],
                 margins: Sequence[Margin]) -> dict:
    """scorecard.json's "specs" (adaptive_mj.study.score_verify re-runs them): its task runs (task_jobs' RunSpecs
    and their (plant, law, task, seed)) grouped by law and seed, and its searches with their probes (Margin, one
    seed each), each run's scenario file (absolute path, sha256), overrides, seed and log (relative to the card's
    folder `out`)."""
    hashes: dict[Path, str] = {}
    tasks: dict[tuple[str, str, int], dict] = {}
    for job, (pn, lb, tn, k) in zip(jobs, keys, strict=True):
        unit = tasks.setdefault((pn, lb, k), {"plant": pn, "law": lb, "seed": k, "runs": []})
        unit["runs"].append({"task": tn, **_file(job.scenario, hashes), "overrides": list(job.overrides),
                             "seed": job.seed, "extras": list(job.extras), "log": _relative(job.log, out)})
    searches = []
    for m in margins:
        s = m.search
        plant, law = s.label.split("/", 1)
        probes = [{"value": ev.value, "overrides": list(spec.overrides), "seed": spec.seed,
                   "log": _relative(spec.log, out), "passes": math.isfinite(tail), "tail": raw, "status": str(st)}
                  for ev in m.evaluations
                  for spec, tail, raw, st in zip(ev.specs, ev.tails, ev.raw, ev.statuses, strict=True)]
        searches.append({"plant": plant, "law": law, "stressor": s.stressor.name, "seed": s.seed,
                         **_file(s.scenario, hashes), "overrides": list(s.overrides), "tail_bound": s.tail_bound,
                         "probes": probes})
    return {"logs": "relative to the card's folder", "tasks": list(tasks.values()), "searches": searches}


def relocate_specs(specs: dict, source: Path, out: Path, labels: dict[tuple[str, str], str | None]) -> dict:
    """A card's specs as a merged card in folder `out` holds them: logs relative to `out` (from `source`, the folder
    of the card they come from), each law under its merged label (labels: (plant, label) -> the merged card's
    label, None: a copy the merged card does not keep)."""
    def moved(log: str | None) -> str | None:
        return None if log is None else os.path.relpath((Path(source) / log).resolve(), Path(out).resolve())

    out_specs: dict[str, Any] = {"logs": specs.get("logs"), "tasks": [], "searches": []}
    for kind in ("tasks", "searches"):
        for unit in specs.get(kind, []):
            label = labels.get((unit["plant"], unit["law"]), unit["law"])
            if label is None:
                continue
            unit = json.loads(json.dumps(unit))
            unit["law"] = label
            for run in unit.get("runs", []) + unit.get("probes", []):
                run["log"] = moved(run["log"])
            out_specs[kind].append(unit)
    return out_specs


# ---------------------------------------------------------------- the card


@dataclass
class Scorecard:
    """A scorecard (scorecard.json's content as `data`), its folder, and the text printed."""

    data: dict
    out: Path | None
    text: str = ""
    exit_code: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def plants(self) -> list[str]:
        return list(self.data["plants"])

    def laws(self, plant: str) -> list[str]:
        return list(self.data["plants"][plant]["laws"])

    def figure(self, plant: str, law: str, name: str) -> Estimate:
        """A criterion ("tail_error", ...), "performance", "robustness" or "success" of `law` on `plant`."""
        return Estimate.from_dict(self.data["plants"][plant]["laws"][law]["figures"][name])

    def rank(self, plant: str, law: str, score: str = "performance") -> int:
        return int(self.data["plants"][plant]["laws"][law]["rank"][score])

    def margin(self, plant: str, law: str, stressor: str) -> Estimate:
        return Estimate.from_dict(self.data["plants"][plant]["laws"][law]["stressors"][stressor]["margin"])


def _versions(law: str | None) -> dict:
    import mujoco

    from adaptive_mj import __version__

    out: dict[str, Any] = {"adaptive_mj": __version__, "mujoco": mujoco.__version__,
                           "python": platform.python_version()}
    if law is not None:
        from adaptive_mj.laws.plugin import installed

        inst = installed().get(law)
        if inst is not None:
            out["law_plugin"] = {"name": law, "distribution": inst.distribution, "version": inst.version,
                                 "source_sha256": inst.source_sha256}
    return out


def stressor_text(p: stress.Plant, duration: float) -> list[dict]:
    return [{"name": st.name, "unit": st.unit, "lo": st.lo, "hi": st.hi} for st in stress.stressors(p, duration)]


def card_hash(duration: float) -> str:
    """The suite's definitions hash with every scored plant's stressors (names, units, ranges), failure bound and
    nominal noise, whichever plants a card covers (so cards of different plants merge), hashed together."""
    import hashlib

    rows = {p.name: {"stressors": stressor_text(p, duration), "tail_bound": stress.tail_bound(p),
                     "nominal_noise": stress.nominal_noise(p)} for p in stress.plants(duration)}
    text = suite.definitions_hash() + json.dumps(rows, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def criteria_spread(plant: dict) -> dict[str, dict]:
    """Per criterion, the range of min(1, cᵢ/nᵢ) (its place on its normaliser's scale, 1 at the cap) over the
    adaptive laws on the plant (every law but the oracle baselines, †), from each law's mean; saturated: every
    adaptive law at the cap, so the criterion separates none of them (the normalisers are chosen so that no
    bundled plant has one)."""
    norm = plant["normalisers"]
    laws = [e for e in plant["laws"].values() if not e.get("oracle")]
    out = {}
    for c in suite.CRITERIA:
        means = [e["figures"][c.name]["mean"] for e in laws]
        parts = [1.0 if m is None or not math.isfinite(m) else min(1.0, max(0.0, m / norm[c.name])) for m in means]
        if parts:
            out[c.name] = {"lo": min(parts), "hi": max(parts), "saturated": min(parts) >= 1.0}
    return out


def rank_laws(plant: dict) -> None:
    """Each law's ranks on the plant's performance and robustness by paired comparison over the seeds
    (adaptive_mj.study.stats.paired_ranks, on each figure's per-seed "values"; null: no value), in place; the rule
    in plant["ranking"] and how many pairs of laws separate per score in plant["separated_pairs"]."""
    labels = list(plant["laws"])
    counts: dict[str, int] = {}
    for score in ("performance", "robustness"):
        values = [[math.nan if v is None else float(v) for v in plant["laws"][lb]["figures"][score]["values"]]
                  for lb in labels]
        for lb, r in zip(labels, paired_ranks(values), strict=True):
            plant["laws"][lb].setdefault("rank", {})[score] = r
        counts[score] = separated_pairs(values)
    plant["ranking"] = RANKING
    plant["separated_pairs"] = {**counts, "pairs": len(labels) * (len(labels) - 1) // 2}


@dataclass
class Plan:
    """What a score runs: the suite's settings, seeds, the plant rows and each one's entries (law under test
    first)."""

    settings: suite.Settings
    seeds: int
    rows: list[stress.Plant]
    entries: dict[str, list[Entry]]
    gains: dict[str, list[str]]


def _rows(law: str | None, plants: Sequence[str] | None, duration: float,
          scenarios: Sequence[Path] = ()) -> list[stress.Plant]:
    """The scored plant rows: those named in `plants` (all when None; none when only `scenarios` are given) and
    the users' scenario files `scenarios` (scenario_row), those `law` serves."""
    rows = [p for p in stress.plants(duration) if p.name in suite.TASKS]  # the kinds that declare score tasks
    if scenarios and plants is None:
        plants = ()
    if plants is not None:
        unknown = [n for n in plants if n not in {p.name for p in rows}]
        if unknown:
            raise ScenarioError(f"--plants: {unknown[0]!r} is not a scored plant (expected one of "
                                f"{', '.join(p.name for p in rows)})")
        rows = [p for p in rows if p.name in plants]
    for path in scenarios:
        row = scenario_row(path, duration)
        if row.name in {p.name for p in rows}:
            raise ScenarioError(f"--scenario {path}: a plant named {row.name!r} is scored already; expected one file "
                                "name per plant")
        rows.append(row)
    if law is not None:
        chosen = [p for p in rows if serves(law, p)]
        if not chosen:
            raise ScenarioError(f"score: law {law!r} serves none of the scored plants "
                                f"({', '.join(p.name for p in rows)})")
        rows = chosen
    return rows


def plan(law: str | None, *, label: str | None, sets: Sequence[str], gains: Path | None,
         against: Sequence[str] | None, suite_name: str, seeds: int | None, plants: Sequence[str] | None,
         scenarios: Sequence[Path] = ()) -> Plan:
    """The runs' plan, every option checked, and the law built once on each plant (a missing gain: one line)."""
    settings = suite.SUITES[suite_name]
    if law is not None:
        law_kind_checked(law)
    gain_sets = read_gains(gains)
    rows = _rows(law, plants, settings.stress_duration, scenarios)
    served = {_kind(p).name for p in _rows(law, None, settings.stress_duration)} if law is not None else set()
    for kind in gain_sets:
        if kind not in served:
            raise ScenarioError(f"{gains}: key {kind!r}: law {law!r} does not run on that plant kind (it serves "
                                f"{', '.join(sorted(served)) or 'none'}); expected only tables of those")
    if against is not None:
        known = {n for p in rows for n in baseline_names(p)}
        bad = [a for a in against if a not in known]
        if bad:
            raise ScenarioError(f"--against: {bad[0]!r} is no baseline (the baselines: {', '.join(sorted(known))})")
    by_plant: dict[str, list[Entry]] = {}
    for p in rows:
        lab = label or law or ""
        if law is not None and lab in baseline_names(p):
            lab = f"{law} (under test)"
        by_plant[p.name] = entries(p, law, lab, gain_sets.get(_kind(p).name, []), sets, against)
        if law is not None:
            _check_builds(p, law, by_plant[p.name][0])
    return Plan(settings, settings.seeds if seeds is None else seeds, rows, by_plant, gain_sets)


def _check_builds(p: stress.Plant, law: str, e: Entry) -> None:
    """The law under test built on p's tracking task, or one line naming the plant and the --gains table."""
    from adaptive_mj.setup.build import build

    t = tasks_of(p)[0]
    try:
        build(sc.load(stress.scenario_path(t.scenario), overrides=[*task_overrides(p, t, 0.01), *e.overrides]))
    except ScenarioError as exc:
        raise ScenarioError(f"score: law {law!r} on plant {p.name} ({_kind(p).name}): {exc} (give its gains in a "
                            f"[{_kind(p).name}] table of --gains FILE.toml, or --set law.KEY=V)") from None


def task_jobs(pl: Plan, out: Path) -> tuple[list[RunSpec], list[tuple[str, str, str, int]]]:
    """Every plant × law × task × seed as a RunSpec, and its (plant, label, task, seed)."""
    jobs, keys = [], []
    for p in pl.rows:
        for e in pl.entries[p.name]:
            for task in tasks_of(p):
                over = task_overrides(p, task, pl.settings.duration(task.name))
                for k in range(pl.seeds):
                    jobs.append(RunSpec(stress.scenario_path(task.scenario),
                                    overrides=(RECORD_PREFLIGHT, *over, *draws(p, task, k)[0], *e.overrides), seed=k,
                                    log=out / "logs" / "tasks" / p.name / _file_name(e.label)
                                    / f"{task.name}-seed{k}.mcap",
                                    tag=f"{p.name}/{e.label} {task.name} seed {k}", extras=task.extras,
                                    keep_trajectory=False))
                    keys.append((p.name, e.label, task.name, k))
    return jobs, keys


#: Why a search is not run (the card's "not run"): the one rule, the same for every law
NOT_RUN_WHY = {stress.PERIOD: "a law with filters integrated per step (composite adaptation, L1) runs under "
                              "continuous control only: the control period does not apply to it (n/a, not in its R)"}


def _not_applicable(p: stress.Plant, e: Entry, st) -> bool:
    """Whether stressor `st` does not apply to law entry e on row p (its reason: NOT_RUN_WHY[st.name])."""
    return st.name == stress.PERIOD and stress.continuous_only(p, e.overrides)


def not_run(pl: Plan) -> list[dict]:
    """The searches the card does not run: plant, law, stressor, how many seeds, status "not run" (Status.NOT_RUN)
    and why (NOT_RUN_WHY)."""
    return [{"plant": p.name, "law": e.label, "stressor": st.name, "seeds": pl.seeds, "status": str(Status.NOT_RUN),
             "why": NOT_RUN_WHY[st.name]}
            for p in pl.rows for e in pl.entries[p.name] for st in stress.stressors(p, pl.settings.stress_duration)
            if _not_applicable(p, e, st)]


def searches(pl: Plan, *, full_logs: bool) -> list[Search]:
    """Every plant × law × stressor × seed as a breaking-point search of its own (one seed each), but those
    `not_run` lists."""
    out = []
    log_rate = () if full_logs else (f"log.rate_hz={MARGIN_LOG_RATE_HZ!r}",)
    for p in pl.rows:
        path = stress.scenario_path(p.scenario)
        for e in pl.entries[p.name]:
            for st in stress.stressors(p, pl.settings.stress_duration):
                if _not_applicable(p, e, st):
                    continue  # n/a: not_run
                for k in range(pl.seeds):
                    out.append(Search(path, f"{p.name}/{e.label}", (*p.base, *log_rate, *margin_draws(p, k),
                                                                    *e.overrides), st, stress.tail_bound(p), seed=k))
    return out


def margin_draws(p: stress.Plant, seed: int) -> tuple[str, ...]:
    """What seed `seed`'s margin runs on plant row p draw: its tracking task's draw (draws), on the row's own
    scenario where the task runs that scenario, but for the initial estimates (a margin run starts from the truth);
    nothing where the task runs another scenario."""
    task = next((t for t in tasks_of(p) if t.name == "tracking"), None)
    if task is None or stress.scenario_path(task.scenario) != stress.scenario_path(p.scenario):
        return ()
    return tuple(o for o in draws(p, task, seed)[0] if not o.startswith("law.initial_estimates="))


def stressor_figures(ms: list, st) -> tuple[dict, list[float]]:
    """One law's margins on one stressor (a Margin per seed, in seed order): the card's entry and each seed's
    margin position (stress.margin_position)."""
    pos = [stress.margin_position({"margin": m.margin, "first_fail": m.first_fail, "lo": st.lo, "hi": st.hi})
           for m in ms]
    at_margin = [m.at(m.margin) for m in ms]
    tails = [ev.raw[0] for ev in at_margin if ev is not None and ev.raw]
    at_hi = [m.at(st.hi) for m in ms]
    fails_hi = [not ev.passes for ev in at_hi if ev is not None]
    return {"unit": st.unit, "margins": [m.margin for m in ms], "first_fails": [m.first_fail for m in ms],
            "margin": estimate([st.lo if m.margin is None else m.margin for m in ms], lowest=st.lo,
                               highest=st.hi).as_dict(),
            "position": estimate(pos, lowest=0.0, highest=1.0).as_dict(),
            "tail_mean_at_margin": float(np.mean(tails)) if tails else None,
            "tail_cvar10_at_margin": cvar(tails) if tails else None,
            "failure_rate_at_hi": float(np.mean(fails_hi)) if fails_hi else None}, pos


#: the figures a law's task runs give, per seed (seed_figures), and robustness from its margins
TASK_FIGURES = (*(c.name for c in suite.CRITERIA), "success", "performance")


def figure(name: str, values: list[float]) -> dict:
    """A figure on the card: its Estimate over the seeds' `values` (in the figure's domain: 0 to 1 for the scores and
    success, from 0 for a criterion) and the values themselves."""
    return {**estimate(values, lowest=0.0, highest=1.0 if name in ("success", "performance", "robustness")
                       else math.inf).as_dict(), "values": values}


def law_figures(per_seed: list[dict], margins: dict[str, list], stressors: Sequence, seeds: int) -> tuple[dict, dict]:
    """A law's figures on a plant and its stressors' entries: per_seed, each seed's task figures (seed_figures, in
    seed order); margins, stressor name -> its Margin per seed (in seed order; none: the stressor does not apply
    to the law, n/a and not in its R); stressors: the plant's (each with name, unit, lo, hi)."""
    figures = {name: figure(name, [f[name] for f in per_seed]) for name in TASK_FIGURES}
    st_out, cols = {}, []
    for st in stressors:
        ms = margins.get(st.name)
        if not ms:
            continue
        st_out[st.name], pos = stressor_figures(ms, st)
        cols.append(pos)
    robust = np.asarray(cols, dtype=float).mean(axis=0) if cols else np.full(seeds, math.nan)
    figures["robustness"] = figure("robustness", robust.tolist())
    return figures, st_out


def plant_card(pl: Plan, p: stress.Plant, task_runs: dict, margins: list, cost_of: dict) -> dict:
    """The card's entry for plant row p: its units, bound, normalisers, stressors, and every law's figures."""
    k = _kind(p)
    durations = dict(pl.settings.durations)
    bound, limits = stress.tail_bound(p), actuator_limits(p)
    plant: dict[str, Any] = {"kind": k.name, "output_unit": k.output_unit, "control_unit": k.control_unit,
                             "tail_bound": bound, "normalisers": normalisers(bound, limits, durations),
                             "stressors": stressor_text(p, pl.settings.stress_duration), "laws": {},
                             # each task's distribution (ScoreTask.draws) and what every seed drew of it
                             "draws": {t.name: {"distribution": [asdict(d) for d in t.draws],
                                                "seeds": [draws(p, t, k)[1] for k in range(pl.seeds)]}
                                       for t in tasks_of(p) if t.draws}}
    by_search: dict[tuple[str, str], list] = {}
    for m in margins:
        by_search.setdefault((m.search.label, m.search.stressor.name), []).append(m)
    stressors = stress.stressors(p, pl.settings.stress_duration)
    for e in pl.entries[p.name]:
        per_seed = [seed_figures(task_runs.get((p.name, e.label, s), {}), bound, limits, durations)
                    for s in range(pl.seeds)]
        ms = {st.name: sorted(by_search.get((f"{p.name}/{e.label}", st.name), []), key=lambda m: m.search.seed)
              for st in stressors}
        figures, st_out = law_figures(per_seed, ms, stressors, pl.seeds)
        plant["laws"][e.label] = {"tested": e.tested, "oracle": e.oracle, "overrides": list(e.overrides),
                                  "figures": figures, "stressors": st_out, "compute_ratio": cost_of.get((p.name,
                                                                                                        e.label))}
    if p.tasks:  # a user's scenario: the file and the tasks derived from it, so that the card can be re-run
        import hashlib

        path = stress.scenario_path(p.scenario)
        plant["scenario"] = {"file": str(path), "sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
                             "tasks": [asdict(t) for t in p.tasks]}
    rank_laws(plant)
    plant["criteria_spread"] = criteria_spread(plant)
    return plant


def run_score(law: str | None, *, label: str | None = None, sets: Sequence[str] = (), gains: Path | None = None,
              against: Sequence[str] | None = None, suite_name: str = "quick", seeds: int | None = None,
              plants: Sequence[str] | None = None, out: Path | None = None, backend=None, full_logs: bool = False,
              cost: bool = True, on_progress: Callable[[str], None] | None = None,
              scenarios: Sequence[Path] = ()) -> Scorecard:
    """Run the suite for `law` (None: the baselines alone) and write the card into `out` (checked options: see
    adaptive_mj.study.api.score)."""
    import sys

    from adaptive_mj.runs.runner import new_output_dir
    from adaptive_mj.study.job import Backend
    from adaptive_mj.study.parallel import progress_printer, run_jobs, session
    from adaptive_mj.study.score_card import write_card

    backend = backend or Backend()
    say = on_progress or (lambda text: print(text, file=sys.stderr))
    pl = plan(law, label=label, sets=sets, gains=gains, against=against, suite_name=suite_name, seeds=seeds,
              plants=plants, scenarios=scenarios)
    out = new_output_dir(out, "score")
    t0 = time.perf_counter()
    jobs, keys = task_jobs(pl, out)
    found = searches(pl, full_logs=full_logs)
    at_most = len(found) * (2 + pl.settings.steps)
    say(f"score: {len(jobs)} task runs and {len(found)} breaking-point searches (plant × law × stressor × seed, "
        f"at most {at_most} runs) on {', '.join(p.name for p in pl.rows)}, {pl.seeds} seeds")
    with session(backend):
        results = run_jobs(jobs, n_jobs=backend.jobs, backend=backend,
                           on_done=progress_printer(len(jobs), label="task runs"))
        margins = search_all(found, seeds=1, steps=pl.settings.steps, logs=out / "logs" / "margins",
                             n_jobs=backend.jobs, backend=backend,
                             on_done=progress_printer(at_most, label="margin runs (at most)"), keep_trajectory=False)
    task_runs: dict[tuple[str, str, int], dict[str, RunOutcome]] = {}
    for (pn, lb, tn, k), r in zip(keys, results, strict=True):
        task_runs.setdefault((pn, lb, k), {})[tn] = r
    cost_of: dict[tuple[str, str], float] = {}
    for p in pl.rows if cost else ():  # per-step compute cost, in this process
        for e in pl.entries[p.name]:
            try:
                cost_of[(p.name, e.label)] = compute_ratio(p, e, tasks_of(p)[0])
            except Exception as exc:  # noqa: BLE001 (a law that cannot run has its runs' errors on the card)
                say(f"score: {p.name}/{e.label}: no compute-cost timing: {type(exc).__name__}: {exc}")
    errors = [r for r in results if r.status == "error"]
    s = pl.settings
    data: dict[str, Any] = {
        "format": CARD_FORMAT,
        "suite": {"version": suite.SUITE_VERSION, "name": s.name, "hash": card_hash(s.stress_duration),
                  "seeds": pl.seeds, "steps": s.steps, "stress_duration": s.stress_duration,
                  "durations": dict(s.durations), "confidence": CONFIDENCE},
        "versions": _versions(law),
        "law": None if law is None else {"name": law, "label": pl.entries[pl.rows[0].name][0].label,
                                         "sets": list(sets), "gains": pl.gains},
        "plants": {p.name: plant_card(pl, p, task_runs, margins, cost_of) for p in pl.rows},
        "errors": len(errors),
        "runs": {"tasks": len(jobs), "margins": sum(len(ev.tails) for m in margins for ev in m.evaluations),
                 "not_run": not_run(pl),
                 "predicted_unstable": sum(p for m in margins for ev in m.evaluations for p in ev.predicted)},
        "specs": record_specs(out, jobs, keys, margins),
    }
    data["wall_seconds"] = time.perf_counter() - t0
    card = Scorecard(data, out, exit_code=1 if errors else 0)
    write_card(card)
    if errors:
        card.notes.append(f"score: {len(errors)} task runs could not be set up (status 'error'), e.g. "
                          f"{errors[0].job.tag}: {errors[0].error}")
    return card


CARD_KEYS: dict[str, type | tuple[type, ...]] = {"suite": dict, "versions": (dict, list), "plants": dict}


def read_card(path: Path) -> dict:
    """A scorecard.json (or the folder holding one), its format and top-level keys checked in one line each."""
    path = Path(path)
    if path.is_dir():
        path = path / "scorecard.json"
    if not path.is_file():
        raise ScenarioError(f"{path}: no such scorecard file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: not a scorecard (not JSON: {exc})") from None
    if not isinstance(data, dict):
        raise ScenarioError(f"{path}: expected a scorecard (a JSON object), got {type(data).__name__}")
    if data.get("format") != CARD_FORMAT:
        raise ScenarioError(f"{path}: key 'format': expected {CARD_FORMAT!r}, got {data.get('format')!r}")
    for key, kind in CARD_KEYS.items():
        if not isinstance(data.get(key), kind):
            raise ScenarioError(f"{path}: key {key!r}: expected a JSON {'object' if kind is dict else 'value'}, "
                                f"got {type(data.get(key)).__name__}")
    for key in ("version", "hash", "name", "seeds"):
        if key not in data["suite"]:
            raise ScenarioError(f"{path}: key 'suite.{key}': missing")
    data["path"] = str(path)
    return data


def merge(paths: Sequence[Path], out: Path | None) -> Scorecard:
    """Cards of one suite (version, hash, name and seeds) joined plant by plant into one leaderboard. A law in
    several cards with the same figures (a baseline) is kept once; with other figures, each copy is named after its
    card ("dead_zone [card 2]")."""
    from adaptive_mj.runs.runner import new_output_dir
    from adaptive_mj.study.score_card import write_card, write_leaderboard

    if len(paths) < 2:
        raise ScenarioError(f"--merge needs two or more scorecard.json files, got {len(paths)}")
    cards = [read_card(Path(p)) for p in paths]
    first = cards[0]
    for data in cards[1:]:
        for key in ("version", "hash", "name", "seeds"):
            if data["suite"].get(key) != first["suite"].get(key):
                raise ScenarioError(f"{data['path']}: key 'suite.{key}': expected {first['suite'].get(key)!r} (as in "
                                    f"{first['path']}), got {data['suite'].get(key)!r}; cards of another suite "
                                    "cannot share a leaderboard")
    out = new_output_dir(out, "score-merged")
    merged = json.loads(json.dumps({k: v for k, v in first.items() if k != "path"}))
    merged["law"] = [c["law"] for c in cards if c.get("law") is not None]
    merged["merged_from"] = [c["path"] for c in cards]
    merged["versions"] = [c["versions"] for c in cards]
    merged["wall_seconds"] = None
    runs = [c.get("runs") or {} for c in cards]  # every card's runs (older cards: no not_run, no predictions)
    merged["runs"] = {"tasks": sum(r.get("tasks", 0) for r in runs), "margins": sum(r.get("margins", 0) for r in runs),
                      "not_run": [n for r in runs for n in r.get("not_run", [])],
                      "predicted_unstable": sum(r.get("predicted_unstable", 0) for r in runs)}
    labels: list[dict[tuple[str, str], str | None]] = [{}]  # per card: (plant, label) -> its label here, or None
    for n, data in enumerate(cards[1:], start=2):
        labels.append({})
        for pn, plant in data["plants"].items():
            target = merged["plants"].setdefault(pn, {**json.loads(json.dumps(plant)), "laws": {}})
            for lb, entry in plant["laws"].items():
                have = target["laws"].get(lb)
                if have is None:
                    target["laws"][lb] = entry
                elif have["figures"] != entry["figures"]:
                    target["laws"][f"{lb} [card {n}]"] = entry
                    labels[-1][(pn, lb)] = f"{lb} [card {n}]"
                else:  # the same law with the same figures: kept once, with the runs of the card that has it first
                    labels[-1][(pn, lb)] = None
    merged.pop("specs", None)
    if all(isinstance(c.get("specs"), dict) for c in cards):  # older cards: the merged card cannot be re-run
        parts = [relocate_specs(c["specs"], Path(c["path"]).parent, out, lab)
                 for c, lab in zip(cards, labels, strict=True)]
        merged["specs"] = {"logs": "relative to the card's folder",
                           "tasks": [u for p in parts for u in p["tasks"]],
                           "searches": [u for p in parts for u in p["searches"]]}
    for plant in merged["plants"].values():
        rank_laws(plant)
        plant["criteria_spread"] = criteria_spread(plant)
    card = Scorecard(merged, out)
    write_card(card)
    card.text += f"\nleaderboard: {write_leaderboard(card, cards)}"
    return card

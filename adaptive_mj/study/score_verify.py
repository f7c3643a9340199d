"""`adaptive-mj score --verify CARD.json [--sample N]`: a scorecard's runs re-run from the specs scorecard.json
records ("specs", written by score.record_specs and, for a merged card, score.relocate_specs), and the card checked
against what they give and against its own per-seed values.

The card records two kinds of run records, each a unit the card's per-seed figures come from:
  tasks     a law's seed on a plant: its task runs (tracking, change, hold), each with its scenario file (path and
            sha256), overrides, seed, analyses and log; the seed's figures come from the three together
            (score.seed_figures);
  searches  one seed's breaking-point search of a law on a plant under one stressor: its scenario file, its fixed
            overrides, the failure bound, and its probes in the order run (value, overrides, log, pass or fail, tail
            RMS error), from which the seed's margin comes.
Log paths are relative to the card's folder (a merged card's: to its own folder); scenario paths are absolute.

--verify then
  1. re-runs a sample of the records (all by default; else N picked by a generator seeded with the hash of the
     card's specs, so the same card picks the same N) from their recorded specs, into a temporary folder: each run
     must log the same rows bit for bit as the card's log, a seed's task runs must give the card's per-seed values
     of every figure, and a search must make the same probes with the same pass or fail and tail, and end at the
     card's margin and first failure for that seed;
  2. recomputes every law's figures from the card's own per-seed values (each seed's S from its criteria and
     success, the Estimates, R from the recorded probes' margins, the stressors' entries, the ranks) with the
     functions that wrote the card (score.performance, score.law_figures, score.rank_laws) and compares them with
     what the card holds: a card edited by hand fails.
"""
from __future__ import annotations

import hashlib
import json
import math
import random
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.study import stress
from adaptive_mj.study.breaking_point import Evaluation, Margin, Search, search_all
from adaptive_mj.study.job import RunOutcome, RunSpec
from adaptive_mj.study.score import (TASK_FIGURES, actuator_limits, law_figures, performance, rank_laws, read_card,
                                     scenario_row, seed_figures)

#: the trajectory fields compared bit for bit between a re-run's log and the card's (runs.verify's)
LOG_FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")
OLD_CARD = "written before specs were recorded: re-score it"


# ---------------------------------------------------------------- checking


@dataclass
class Verification:
    """What `score --verify` found: the card, the records it re-ran (`picked`, as "plant/law tasks seed k" or
    "plant/law stressor seed k"), the problems (one line each; none: the card agrees), the text printed and the
    exit code (0 all agree, 1 a problem)."""

    card: Path
    picked: list[str]
    problems: list[str] = field(default_factory=list)
    total: int = 0
    wall_seconds: float = 0.0
    notes: list[str] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        return 1 if self.problems else 0

    @property
    def text(self) -> str:
        head = (f"verify: {self.card}: re-ran {len(self.picked)} of {self.total} run records "
                f"({self.wall_seconds:.0f} s)" + ("" if len(self.picked) == self.total else
                                                   ": " + (", ".join(self.picked) or "none")))
        if not self.problems:
            return head + "\nverify: the card agrees with its runs and with its own per-seed values"
        return "\n".join([head, *(f"verify: MISMATCH: {p}" for p in self.problems)])


def _num(v: Any) -> Any:
    """A number as the card writes it (not finite: null), so that values compare after the JSON round trip."""
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _num(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_num(x) for x in v]
    return v


def _first_diff(card: Any, other: Any, where: str) -> tuple[str, Any, Any] | None:
    """The first place (a dotted key) where `card` and `other` (both as the card writes numbers) differ."""
    if isinstance(card, dict) and isinstance(other, dict):  # a figure's per-seed values before its Estimate
        for k in sorted(card, key=lambda k: k != "values") + [k for k in other if k not in card]:
            if k not in card or k not in other:
                return f"{where}.{k}", card.get(k, "(missing)"), other.get(k, "(missing)")
            d = _first_diff(card[k], other[k], f"{where}.{k}")
            if d:
                return d
        return None
    if isinstance(card, list) and isinstance(other, list) and len(card) == len(other):
        for i, (a, b) in enumerate(zip(card, other, strict=True)):
            d = _first_diff(a, b, f"{where}[{i}]")
            if d:
                return d
        return None
    same = card == other and type(card) is type(other) or (
        isinstance(card, (int, float)) and isinstance(other, (int, float)) and not isinstance(card, bool)
        and not isinstance(other, bool) and card == other)
    return None if same else (where, card, other)


def _said(d: tuple[str, Any, Any], what: str = "re-computed") -> str:
    return f"{d[0]}: card {d[1]!r}, {what} {d[2]!r}"


def read(path: Path) -> dict:
    """The card at `path` (a scorecard.json or its folder), with its specs, or one line (exit 2)."""
    data = read_card(Path(path))
    specs = data.get("specs")
    if not isinstance(specs, dict) or not isinstance(specs.get("tasks"), list) \
            or not isinstance(specs.get("searches"), list):
        raise ScenarioError(f"{data['path']}: key 'specs': expected the card's run specs, got "
                            f"{type(specs).__name__ if specs is not None else 'none'}: the card was {OLD_CARD}")
    return data


def picked_units(data: dict, sample: int | None) -> list[tuple[str, dict]]:
    """The records to re-run: all (sample None), or `sample` of them picked by a generator seeded with the hash of
    the card's specs (the same card, the same pick), in the card's order."""
    units = [("tasks", u) for u in data["specs"]["tasks"]] + [("searches", u) for u in data["specs"]["searches"]]
    if sample is None or sample >= len(units):
        return units
    digest = hashlib.sha256(json.dumps(data["specs"], sort_keys=True).encode()).hexdigest()
    chosen = sorted(random.Random(int(digest[:16], 16)).sample(range(len(units)), sample))
    return [units[i] for i in chosen]


def unit_name(kind: str, unit: dict) -> str:
    what = "tasks" if kind == "tasks" else unit["stressor"]
    return f"{unit['plant']}/{unit['law']} {what} seed {unit['seed']}"


def _rows(data: dict) -> dict[str, stress.Plant]:
    """The card's plant rows by name: the suite's, or a user's scenario file (score.scenario_row)."""
    duration = float(data["suite"]["stress_duration"])
    suite_rows = {p.name: p for p in stress.plants(duration)}
    out = {}
    for pn, plant in data["plants"].items():
        if "scenario" in plant:
            out[pn] = scenario_row(Path(plant["scenario"]["file"]), duration)
        elif pn in suite_rows:
            out[pn] = suite_rows[pn]
        else:
            raise ScenarioError(f"{data['path']}: key 'plants.{pn}': expected a scored plant or a scenario file, got "
                                "neither")
    return out


def _scenario_checked(data: dict, run: dict) -> Path:
    """A recorded scenario file, its sha256 checked (a file changed since: one line)."""
    path = Path(run["scenario"])
    if not path.is_file():
        raise ScenarioError(f"{data['path']}: scenario file {path} not found (key 'specs': the card's runs need it)")
    got = hashlib.sha256(path.read_bytes()).hexdigest()
    if got != run["sha256"]:
        raise ScenarioError(f"{data['path']}: scenario file {path}: expected sha256 {run['sha256'][:16]}… as the card "
                            f"recorded, got {got[:16]}…: the file changed since the card was written")
    return path


def same_log(card_log: Path, new_log: Path | None) -> str:
    """"" when the two logs hold the same rows bit for bit, else what differs first."""
    from adaptive_mj.log.replay import read_log

    if new_log is None or not Path(new_log).is_file():
        return "the re-run wrote no log"
    if not card_log.is_file():
        return f"the card's log {card_log} is missing"
    a, b = read_log(card_log).trajectory, read_log(new_log).trajectory
    if len(a) != len(b):
        return f"log rows: card {len(a)}, re-run {len(b)}"
    for name in LOG_FIELDS:
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        if x.shape != y.shape:
            return f"log field {name}: card shape {x.shape}, re-run {y.shape}"
        if not np.array_equal(x, y, equal_nan=True):
            bad = tuple(np.argwhere((x != y) & ~(np.isnan(x) & np.isnan(y)))[0])
            return f"log field {name} at row {bad[0]} (t={float(a.t[bad[0]])!r} s): card {x[bad]!r}, re-run {y[bad]!r}"
    return ""


def _rerun_tasks(data: dict, units: list[dict], rows: dict, tmp: Path, backend) -> list[str]:
    """Each task record's runs re-run: its logs bit for bit and its seed's figures as the card has them."""
    from adaptive_mj.study.parallel import run_jobs

    card_dir = Path(data["path"]).parent
    jobs, where = [], []
    for n, unit in enumerate(units):
        for run in unit["runs"]:
            jobs.append(RunSpec(_scenario_checked(data, run), overrides=tuple(run["overrides"]), seed=run["seed"],
                                log=tmp / "tasks" / str(n) / f"{run['task']}.mcap", tag=unit_name("tasks", unit),
                                extras=tuple(run["extras"]), keep_trajectory=False))
            where.append((n, run))
    results = run_jobs(jobs, n_jobs=backend.jobs, backend=backend) if jobs else []
    by_unit: dict[int, dict[str, RunOutcome]] = {}
    problems: dict[int, str] = {}
    for (n, run), r in zip(where, results, strict=True):
        by_unit.setdefault(n, {})[run["task"]] = r
        differ = same_log(card_dir / run["log"], r.job.log) if run["log"] else ""
        if differ and n not in problems:
            problems[n] = f"{unit_name('tasks', units[n])}: {run['task']} run: {differ}"
    durations = {k: float(v) for k, v in data["suite"]["durations"].items()}
    limits = {pn: actuator_limits(p) for pn, p in rows.items()}
    for n, unit in enumerate(units):
        if n in problems:
            continue
        plant = data["plants"][unit["plant"]]
        law = plant["laws"].get(unit["law"])
        if law is None:
            problems[n] = f"{unit_name('tasks', unit)}: the card has no law {unit['law']!r} on {unit['plant']}"
            continue
        got = _num(seed_figures(by_unit[n], float(plant["tail_bound"]), limits[unit["plant"]], durations))
        for name, value in got.items():
            card_value = law["figures"][name]["values"][unit["seed"]]
            d = _first_diff(card_value, value, f"figure {name!r}")
            if d:
                problems[n] = f"{unit_name('tasks', unit)}: {_said(d, 're-run')}"
                break
    return [problems[n] for n in sorted(problems)]


def _rerun_searches(data: dict, units: list[dict], rows: dict, tmp: Path, backend) -> list[str]:
    """Each search record re-run (breaking_point.search_all, one seed): the same probes with the same verdict, tail
    and log, and the card's margin and first failure for that seed."""
    card_dir = Path(data["path"]).parent
    duration = float(data["suite"]["stress_duration"])
    searches = []
    for unit in units:
        st = {s.name: s for s in stress.stressors(rows[unit["plant"]], duration)}.get(unit["stressor"])
        if st is None:
            raise ScenarioError(f"{data['path']}: key 'specs': plant {unit['plant']} has no stressor "
                                f"{unit['stressor']!r}")
        searches.append(Search(_scenario_checked(data, unit), f"{unit['plant']}/{unit['law']}",
                               tuple(unit["overrides"]), st, float(unit["tail_bound"]), seed=int(unit["seed"])))
    margins = search_all(searches, seeds=1, steps=int(data["suite"]["steps"]), logs=tmp / "margins",
                         n_jobs=backend.jobs, backend=backend, keep_trajectory=False) if searches else []
    problems = []
    for unit, m in zip(units, margins, strict=True):
        name = unit_name("searches", unit)
        new: list[dict[str, Any]] = [{"value": ev.value, "overrides": list(spec.overrides),
                                      "passes": math.isfinite(tail), "tail": raw, "log": spec.log}
                                     for ev in m.evaluations
               for spec, tail, raw in zip(ev.specs, ev.tails, ev.raw, strict=True)]
        card = unit["probes"]
        if len(new) != len(card):
            problems.append(f"{name}: probes: card {len(card)}, re-run {len(new)}")
            continue
        for i, (a, b) in enumerate(zip(card, new, strict=True)):
            d = _first_diff(_num({k: a[k] for k in ("value", "overrides", "passes", "tail")}),
                            _num({k: b[k] for k in ("value", "overrides", "passes", "tail")}), f"probe {i}")
            differ = _said(d, "re-run") if d else same_log(card_dir / a["log"], b["log"]) if a["log"] else ""
            if differ:
                problems.append(f"{name}: {differ}")
                break
        else:
            entry = data["plants"][unit["plant"]]["laws"].get(unit["law"], {}).get("stressors", {}).get(
                unit["stressor"], {})
            k = int(unit["seed"])
            for key, value in (("margins", m.margin), ("first_fails", m.first_fail)):
                have = (entry.get(key) or [None] * (k + 1))[k] if entry else "(missing)"
                d = _first_diff(_num(have), _num(value), f"{unit['stressor']} {key[:-1]}")
                if d:
                    problems.append(f"{name}: {_said(d, 're-run')}")
                    break
    return problems


def _margins_of(data: dict, plant_name: str, label: str, law: dict, seeds: int) -> dict[str, list[Margin]]:
    """A law's margins per stressor as the card holds them: each seed's margin and first failure, with its recorded
    probes as the evaluations score.stressor_figures reads."""
    probes: dict[tuple[str, int], list[dict]] = {}
    for unit in data["specs"]["searches"]:
        if unit["plant"] == plant_name and unit["law"] == label:
            probes[(unit["stressor"], int(unit["seed"]))] = unit["probes"]
    out = {}
    for st_name, entry in law["stressors"].items():
        ms = []
        for k in range(seeds):
            evs = [Evaluation(float(p["value"]), [float(p["tail"]) if p["passes"] else math.inf], [p["status"]],
                              [math.nan if p["tail"] is None else float(p["tail"])])
                   for p in probes.get((st_name, k), [])]
            ms.append(Margin(None, entry["margins"][k], entry["first_fails"][k], evs))  # type: ignore[arg-type]
        out[st_name] = ms
    return out


def recomputed(data: dict) -> list[str]:
    """Every law's figures, stressors and ranks recomputed from the card's own per-seed values and recorded probes,
    compared with what the card holds: a problem per plant and law that differs (its first difference)."""
    seeds = int(data["suite"]["seeds"])
    problems = []
    for pn, plant in data["plants"].items():
        stressors = [SimpleNamespace(**s) for s in plant["stressors"]]
        again: dict[str, dict] = {"laws": {}}
        for lb, law in plant["laws"].items():
            per_seed = [{name: math.nan if law["figures"][name]["values"][k] is None
                         else float(law["figures"][name]["values"][k]) for name in TASK_FIGURES}
                        for k in range(seeds)]
            for f in per_seed:
                f["performance"] = performance(f, plant["normalisers"])
            figures, st_out = law_figures(per_seed, _margins_of(data, pn, lb, law, seeds), stressors, seeds)
            d = (_first_diff(_num(law["figures"]), _num(figures), "figure")
                 or _first_diff(_num(law["stressors"]), _num(st_out), "stressors"))
            if d:
                problems.append(f"{pn}/{lb}: {_said(d)} from the card's per-seed values")
            again["laws"][lb] = {"figures": _num(figures)}
        if problems:
            continue
        rank_laws(again)
        for lb, law in plant["laws"].items():
            d = _first_diff(law.get("rank"), again["laws"][lb]["rank"], "rank")
            if d:
                problems.append(f"{pn}/{lb}: {_said(d)} from the card's figures")
    return problems


def verify(path: Path, *, sample: int | None = None, backend=None) -> Verification:
    """Re-run `sample` of the card's run records (None: all) and check the card (the module docstring)."""
    import time

    from adaptive_mj.study.job import Backend
    from adaptive_mj.study.parallel import session

    t0 = time.perf_counter()
    data = read(path)
    backend = backend or Backend()
    units = picked_units(data, sample)
    result = Verification(Path(data["path"]), [unit_name(k, u) for k, u in units],
                          total=len(data["specs"]["tasks"]) + len(data["specs"]["searches"]))
    result.problems = recomputed(data)
    if units:
        rows = _rows(data)
        with tempfile.TemporaryDirectory(prefix="adaptive-mj-verify-") as tmp, session(backend):
            result.problems += _rerun_tasks(data, [u for k, u in units if k == "tasks"], rows, Path(tmp), backend)
            result.problems += _rerun_searches(data, [u for k, u in units if k == "searches"], rows, Path(tmp),
                                               backend)
    result.wall_seconds = time.perf_counter() - t0
    return result

"""The studies from Python: sweep, breaking_point, stress and bench, each returning a Study
(adaptive_mj.study.result): its rows as a list of dicts, a pandas-free table, the output folder,
report.md / report.html, and .plot().

    from adaptive_mj import study

    s = study.sweep("heave_tracking", grid={"law.k": [100, 200]}, seeds=2, out="logs/k")
    s.table["rms_tracking_error_tail"]; s.rows[0]["status"]; s.plot(); s.out / "report.html"

`adaptive-mj sweep | stress | bench` parse their command line and call these (adaptive_mj.cli), so
this module is the one place their options are checked (and Backend.checked, for where the runs
go): bad input raises adaptive_mj.errors.ScenarioError naming the option as the command line spells
it, before any folder is made or any run starts. A run that diverges or fails is a row of the
result (Study.exit_code 1), not an exception.

Every argument after the scenario is keyword-only. `backend`: "local" (worker processes on this
machine, `jobs` of them, default every core; engine "batch": mujoco.batch in this process) or "ray"
(`address`, `ray_logs`, `retries`: see docs/GUIDE.md "Studies that outgrow one machine").
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

from adaptive_mj.errors import ScenarioError
from adaptive_mj.study.job import Backend
from adaptive_mj.study.result import Study, Table

__all__ = ["Study", "Table", "bench", "breaking_point", "run_scenario", "score", "stress", "sweep"]

GridSpec = Mapping[str, Any] | Sequence[str]
#: a run's overrides: {key: value} with Python values (a number, a string, a bool, a list, a dict: written as the
#: TOML value a scenario file would hold), or --set expressions "KEY=VALUE" as the command line takes them
Overrides = Mapping[str, Any] | Sequence[str] | str


def count(option: str, value: Any, lowest: int) -> int:
    """An integer option >= lowest, or one line naming it."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lowest:
        raise ScenarioError(f"{option} must be an integer >= {lowest}, got {value}")
    return value


def positive(option: str, value: Any, unit: str = "") -> float:
    """A finite number > 0, or one line naming it (and its unit)."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    if not ok:
        raise ScenarioError(f"{option} must be > 0{f' [{unit}]' if unit else ''}, got {value}")
    return float(value)


def where(backend: str | Backend = "local", *, jobs: int | None = None, address: str | None = None,
          ray_logs: str = "bytes", retries: int = 3, engine: str = "process") -> Backend:
    """The Backend the options ask for (a Backend given as `backend` is used as it is)."""
    if isinstance(backend, Backend):
        return backend
    return Backend.checked(backend, jobs=jobs, address=address, logs=ray_logs, retries=retries, engine=engine)


def scenario_path(scenario: str | Path) -> Path:
    """A scenario file, or the name of a bundled one (heave_tracking, heave_tracking.toml); a name that is
    neither raises one line with the closest bundled name."""
    from adaptive_mj.setup.scenario import SCENARIOS_DIR

    arg = str(scenario)
    path = Path(arg)
    if not path.exists() and "/" not in arg:
        bundled = SCENARIOS_DIR / (arg if arg.endswith(".toml") else f"{arg}.toml")
        if bundled.exists():
            return bundled
        if arg.endswith(".toml"):  # a file name: the loader says it is not found
            return path
        import difflib

        names = sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
        close = difflib.get_close_matches(Path(arg).stem, names, n=1, cutoff=0.6)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ScenarioError(f"{arg}: no such scenario file, nor a bundled scenario ({hint}`adaptive-mj list` shows "
                            "the bundled ones)")
    return path


def grid_expressions(grid: GridSpec) -> list[str]:
    """--grid expressions from {key: [values]} (TOML values), {key: "LO:HI:N"} or ["KEY=LO:HI:N", ...]."""
    from adaptive_mj.study.sweep import to_toml

    if isinstance(grid, str):
        return [grid]
    if isinstance(grid, Mapping):
        out = []
        for key, values in grid.items():
            if isinstance(values, str):
                out.append(f"{key}={values}")
            elif isinstance(values, Sequence) and not isinstance(values, (bytes, bytearray)):
                out.append(f"{key}=" + ",".join(to_toml(v) for v in values))
            else:
                raise ScenarioError(f"grid[{key!r}]: expected a list of values or 'LO:HI:N', got {values!r}")
        return out
    return [str(expr) for expr in grid]


def overrides_of(option: str, value: Any) -> list[str]:
    """--set expressions from Overrides: {key: value} (each value as TOML: setup.scenario's loader reads it back
    as that value) or KEY=VALUE strings; one line naming the option otherwise."""
    if isinstance(value, Mapping):
        from adaptive_mj.study.sweep import to_toml

        bad = [k for k in value if not isinstance(k, str) or not k]
        if bad:
            raise ScenarioError(f"{option}: expected scenario keys (e.g. 'law.k') as the dict's keys, got {bad[0]!r}")
        return [f"{key}={to_toml(v)}" for key, v in value.items()]
    return _strings(option, value)


def _strings(option: str, value: Any) -> list[str]:
    if isinstance(value, str):
        return [value]
    if not isinstance(value, Sequence) or not all(isinstance(v, str) for v in value):
        raise ScenarioError(f"{option}: expected KEY=VALUE strings, got {value!r}")
    return list(value)


def sweep(scenario: str | Path, *, grid: GridSpec, seeds: int = 1, overrides: Overrides = (),
          metrics: Sequence[str] = (), out: str | Path | None = None, resume: str | Path | None = None,
          logs: str = "all", backend: str | Backend = "local", jobs: int | None = None,
          address: str | None = None, ray_logs: str = "bytes", retries: int = 3,
          engine: str = "process", law: str | None = None) -> Study:
    """Run `scenario` over a grid of keys × seeds 0..seeds-1 (`adaptive-mj sweep`).

    law: swap the scenario's law for this kind (its defaults plus the law.* overrides; setup.scenario.law_swap),
    as a grid axis law.kind = [a, b] does per point.

    grid: {key: [values]} or {key: "LO:HI:N"} or ["KEY=LO:HI:N", "KEY=V1,V2"] (a key dotted, law.k, or
    bare, payload_mass); overrides: {key: value} or --set expressions (Overrides); metrics: the columns
    summarised and plotted (default rms_tracking_error_tail); out: a new or empty folder (default a new logs/sweep-...);
    resume: finish the study in that folder (the same arguments); logs: "all" (an MCAP log per run) or
    "summary" (the rows only). Returns the Study: one row per run (its grid values, seed, status,
    reason, every metric, log)."""
    from adaptive_mj.study.sweep import run_sweep

    seeds = count("--seeds", seeds, 1)
    if logs not in ("all", "summary"):
        raise ScenarioError(f"--logs must be 'all' or 'summary', got {logs!r}")
    backend_ = where(backend, jobs=jobs, address=address, ray_logs=ray_logs, retries=retries, engine=engine)
    if resume is not None and out is not None:
        raise ScenarioError(f"sweep --resume {resume} writes into that folder; -o {out} cannot be combined with it")
    if logs == "summary" and resume is not None:
        raise ScenarioError("--logs summary writes no logs, and --resume and --breaking-point read the runs' logs "
                            "back; leave out --logs summary")
    return run_sweep(scenario_path(scenario), grid=grid_expressions(grid), seeds=seeds,
                     overrides=with_law(law, overrides_of("--set", overrides)), metrics=_strings("--metric", metrics),
                     out=None if out is None else Path(out), resume=None if resume is None else Path(resume),
                     logs=logs, backend=backend_)


def with_law(law: str | None, overrides: list[str]) -> list[str]:
    """The overrides with `--law NAME` as its swap in front (setup.scenario.law_swap)."""
    if law is None:
        return overrides
    from adaptive_mj.setup.scenario import law_swap

    name: object = law  # any value a Python caller passed
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"--law must be a law kind's name (adaptive-mj list --laws), got {law!r}")
    return [law_swap(law), *overrides]


def breaking_point(scenario: str | Path, *, key: str, lo: float | None = None, hi: float | None = None,
                   tail_bound: float, seeds: int = 1, steps: int = 5, overrides: Overrides = (),
                   out: str | Path | None = None, backend: str | Backend = "local", jobs: int | None = None,
                   address: str | None = None, ray_logs: str = "bytes", retries: int = 3,
                   engine: str = "process") -> Study:
    """Bisect one scenario key for the largest value at which every seed passes (no divergence, tail RMS
    tracking error <= tail_bound, in the scenario's output unit) (`adaptive-mj sweep --breaking-point`).

    key: "KEY=LO:HI", or KEY with lo and hi (integers when both are ints: whole numbers are tried);
    control.period is searched in whole physics steps under sampled-data control. Returns the Study:
    one row per value tried (value, passes, statuses, tail_max); info holds the margin, first_fail,
    resolution and the tail statistics at the margin."""
    from adaptive_mj.study.sweep import run_breaking_point

    if lo is not None or hi is not None:
        if lo is None or hi is None or "=" in key:
            raise ScenarioError(f"--breaking-point: give key='KEY=LO:HI', or key='KEY' with both lo and hi "
                                f"(got key={key!r}, lo={lo!r}, hi={hi!r})")
        key = f"{key}={lo!r}:{hi!r}"
    bound: object = tail_bound  # any value a Python caller passed
    if bound is None or not isinstance(bound, (int, float)) or not bound > 0:
        raise ScenarioError(f"--breaking-point needs --tail-bound B > 0 (the tail RMS tracking error above which "
                            f"a run fails, in the scenario's output unit), got {tail_bound}")
    seeds = count("--seeds", seeds, 1)
    steps = count("--steps", steps, 0)
    backend_ = where(backend, jobs=jobs, address=address, ray_logs=ray_logs, retries=retries, engine=engine)
    return run_breaking_point(scenario_path(scenario), point=key, tail_bound=float(tail_bound), seeds=seeds,
                              steps=steps, overrides=overrides_of("--set", overrides),
                              out=None if out is None else Path(out), backend=backend_)


def stress(*, seeds: int = 5, steps: int = 4, duration: float = 20.0, composite: bool = False,
           out: str | Path | None = None, backend: str | Backend = "local", jobs: int | None = None,
           address: str | None = None, ray_logs: str = "bytes", retries: int = 3,
           engine: str = "process", law: str | None = None, set: Overrides = (),  # noqa: A002
           plants: str | Sequence[str] | None = None) -> Study:
    """The breaking-point study, every plant × law × stressor (`adaptive-mj stress`): `seeds` per value,
    `steps` bisection steps, runs of `duration` s; composite: also composite adaptation; law: also this law
    kind (built in or a plugin) on every plant it serves, with its `set` keys (law.KEY=V); plants: only these
    ("heave,quadrotor" or a list; None: all). Returns the Study: one row per plant/law × stressor (margin,
    first_fail, resolution, tail statistics), as margins.csv."""
    from adaptive_mj.study.breaking_point import STRESS_PLANT_KIND
    from adaptive_mj.study.stress import run_stress

    sets = _law_sets(law, set)
    names = _names("--plants", plants)
    if names is not None:
        unknown = [n for n in names if n not in STRESS_PLANT_KIND]
        if unknown:
            raise ScenarioError(f"--plants: {unknown[0]!r} is not a plant of the study (expected one of "
                                f"{', '.join(STRESS_PLANT_KIND)})")

    seeds, steps = count("--seeds", seeds, 1), count("--steps", steps, 0)
    duration = positive("--duration", duration, "s")
    backend_ = where(backend, jobs=jobs, address=address, ray_logs=ray_logs, retries=retries, engine=engine)
    return run_stress(seeds=seeds, steps=steps, duration=duration, composite=bool(composite),
                      out=None if out is None else Path(out), backend=backend_, law=law, sets=tuple(sets),
                      plant_names=None if names is None else tuple(names))


def _law_sets(law: str | None, sets: Overrides) -> list[str]:
    """A law kind's name checked (one line naming the close ones) and its --set law.KEY=V expressions ({key:
    value} or the expressions: Overrides)."""
    items = overrides_of("--set", sets)
    if law is None:
        if items:
            raise ScenarioError("--set needs --law (the built-in laws keep their own keys)")
        return []
    name: object = law  # any value a Python caller passed
    if not isinstance(name, str) or not name:
        raise ScenarioError(f"--law must be a law kind's name (adaptive-mj list --laws), got {law!r}")
    from adaptive_mj.study.score import law_kind_checked

    law_kind_checked(law)
    from adaptive_mj.study.score import TASK_KEYS

    for expr in items:
        text: object = expr
        if not isinstance(text, str) or not expr.startswith("law.") or "=" not in expr:
            raise ScenarioError(f"--set: only the law's own keys, law.KEY=VALUE, got {expr!r}")
        key = expr.split("=", 1)[0].strip()[len("law."):]
        if key in TASK_KEYS:
            raise ScenarioError(f"--set: law.{key} is the study's, set alike for every law (the task, not the law); "
                                f"expected one of the law's own keys, got {expr!r}")
    return items


def bench(*, quick: bool = False, scenarios: Sequence[str | Path] = (), out: str | Path | None = None,
          backend: str | Backend = "local", jobs: int | None = None, address: str | None = None,
          ray_logs: str = "bytes", retries: int = 3, engine: str = "process", law: str | None = None,
          gains: str | Path | None = None, set: Overrides = (),  # noqa: A002
          full_logs: bool = False, only: str | Sequence[str] | None = None,
          results: str | Path | None = None) -> Study:
    """The benchmark catalogue (`adaptive-mj bench`): results: a file to write the measured-results page to
    (docs/RESULTS.md in the repository; bench.results_page, also `results.md` in the output folder); quick:
    shorter runs, no breaking-point study; full_logs: the breaking-point study's runs log every row (default: their
    summary and a row per second);
    scenarios: your own scenario files (or bundled names), each in a section of its own; law: a law kind
    (built in or a plugin, its keys per plant kind in `gains` and `set`) scored against the baselines in a
    section of its own (score's quick suite) and added to the breaking-point study; only: the catalogue's
    sections to run, by key ("a,b" or a sequence; bench.section_keys(); "breaking_points" is the full bench's study),
    default all of them. Returns the Study: one row per run of the report's main table (section, run, status,
    tail, u_rms, u_tv, key)."""
    from adaptive_mj.study.bench import BREAKING_POINTS, run_bench, section_keys

    sets = _law_sets(law, set)
    keys = _names("--only", only)
    if keys is not None:
        known = section_keys()
        wrong = [k for k in keys if k not in known]
        if wrong:
            raise ScenarioError(f"--only {wrong[0]!r}: not a section of the bench (sections: {', '.join(known)})")
        if quick and BREAKING_POINTS in keys:
            raise ScenarioError(f"--only {BREAKING_POINTS}: bench --quick runs no breaking-point study")

    backend_ = where(backend, jobs=jobs, address=address, ray_logs=ray_logs, retries=retries, engine=engine)
    paths = [scenario_path(p) for p in ([scenarios] if isinstance(scenarios, (str, Path)) else scenarios)]
    return run_bench(quick=bool(quick), scenarios=paths, out=None if out is None else Path(out), backend=backend_,
                     law=law, gains=None if gains is None else Path(gains), sets=tuple(sets),
                     full_logs=bool(full_logs), only=None if keys is None else tuple(dict.fromkeys(keys)),
                     results=None if results is None else Path(results))


def run_scenario(scenario: str | Path, *, set: Overrides = (), seed: int | None = None,  # noqa: A002
                 law: str | None = None, log: str | Path | bool = False, python_callback: bool = False):
    """One scenario run as `adaptive-mj run` runs it, from Python: a scenario file or a bundled scenario's name,
    `set` its overrides ({key: value} or --set KEY=VALUE expressions: Overrides), `seed` the noise seed, `law` a
    law kind swapped in (`run --law`),
    `log` a log file to write (True: a new file under logs/, as `run` names it; False: none). Returns a
    adaptive_mj.runs.runner.RunResult: .trajectory, .summary, .status (the same verdict as `run`, [success]
    applied), .log_path. Bad input raises adaptive_mj.errors.ScenarioError (one line)."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.runs.runner import execute, reserve_log_path

    sets = overrides_of("set", set)
    if seed is not None:
        seed = count("seed", seed, 0)
    overrides = [*with_law(law, sets), *(["simulation.python_callback=true"] if python_callback else [])]
    scn = sc.load(scenario_path(scenario), overrides=overrides, seed=seed)
    path = None
    if log is True:
        path = reserve_log_path(scn)
    elif log:
        path = reserve_log_path(scn, out=Path(log), force=True)
    return execute(scn, log_path=path)


def _names(option: str, value: Any) -> list[str] | None:
    """A list of names from "a,b" or a sequence of strings (None stays None)."""
    if value is None:
        return None
    items = value.split(",") if isinstance(value, str) else list(value)
    if not items or not all(isinstance(x, str) and x.strip() for x in items):
        raise ScenarioError(f"{option} must be names separated by commas, got {value!r}")
    return [x.strip() for x in items]


def _scenario_file(path: str | Path) -> Path:
    """--scenario FILE.toml of `score`: a scenario file that exists, or one line."""
    path = Path(path)
    if path.suffix != ".toml" or not path.is_file():
        raise ScenarioError(f"--scenario {path}: expected a scenario file (.toml), got "
                            + ("no such file" if not path.exists() else "another kind of file"))
    return path.resolve()


def score(law: str | None = None, *, set: Overrides = (), gains: str | Path | None = None,  # noqa: A002
          against: str | Sequence[str] | None = None, suite: str = "quick", seeds: int | None = None,
          plants: str | Sequence[str] | None = None, label: str | None = None, out: str | Path | None = None,
          full_logs: bool = False, cost: bool = True, merge: Sequence[str | Path] = (),
          backend: str | Backend = "local", jobs: int | None = None, address: str | None = None,
          ray_logs: str = "bytes", retries: int = 3, engine: str = "process",
          scenarios: Sequence[str | Path] = (), verify: str | Path | None = None, sample: int | None = None):
    """A law scored against the baselines on every plant kind it serves (`adaptive-mj score`): the suite of
    adaptive_mj.study.score_suite (`suite` "quick" or "full"), `seeds` per figure (default the suite's), the law's
    gains per plant kind from `gains` (a TOML file, a table per plant kind) and `set` (law.KEY=V), against every
    baseline or those named in `against`, on every plant it serves or those named in `plants`, or on the users'
    scenario files `scenarios` (each a plant of its own: tracking the scenario as given, a payload change and a
    hold derived from it, the stressors of its plant kind; with `plants` too, both). merge: instead,
    join these scorecard.json files (one suite version) into one leaderboard (and leaderboard.html). Returns a
    adaptive_mj.study.score.Scorecard (its data is scorecard.json; .figure(plant, law, name), .rank(...)).
    verify: instead, re-run `sample` of this card's run records (None: all) and check the card against them and
    against its own per-seed values (adaptive_mj.study.score_verify); returns its Verification (.problems,
    .exit_code: 0 the card agrees, 1 it does not)."""
    from adaptive_mj.study import score as sc_
    from adaptive_mj.study.score_suite import SUITES

    if verify is not None or sample is not None:
        from adaptive_mj.study import score_verify

        if verify is None:
            raise ScenarioError("score: --sample needs --verify CARD.json")
        if law is not None or merge:
            raise ScenarioError("score: --verify re-runs a card: give no LAW and no --merge with it")
        return score_verify.verify(Path(verify), sample=None if sample is None else count("--sample", sample, 0),
                                   backend=where(backend, jobs=jobs, address=address, ray_logs=ray_logs,
                                                 retries=retries, engine=engine))
    if merge:
        return sc_.merge([Path(p) for p in merge], None if out is None else Path(out))
    sets = _law_sets(law, set)
    if suite not in SUITES:
        raise ScenarioError(f"--suite must be one of {', '.join(SUITES)}, got {suite!r}")
    if seeds is not None:
        seeds = count("--seeds", seeds, 2)
    backend_ = where(backend, jobs=jobs, address=address, ray_logs=ray_logs, retries=retries, engine=engine)
    return sc_.run_score(law, label=label, sets=sets, gains=None if gains is None else Path(gains),
                         against=_names("--against", against), suite_name=suite, seeds=seeds,
                         plants=_names("--plants", plants), out=None if out is None else Path(out),
                         backend=backend_, full_logs=bool(full_logs), cost=bool(cost),
                         scenarios=[_scenario_file(s) for s in scenarios])

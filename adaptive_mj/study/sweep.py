"""`adaptive-mj sweep`: one scenario over a grid of keys × seeds, in parallel.

    --grid exprs ──► parse_grid (one axis each) ──► grid_points ──► each point validated (scenario.load)
                 ──► one RunSpec per point × seed, each logging to DIR/logs/ ──► parallel.iter_results
                 ──► a row per run as it finishes, appended to DIR/rows.jsonl (the driver keeps only the
                     few columns the summary table and plot need)
                 ──► DIR/sweep.csv, DIR/sweep.json in the planned order, DIR/sweep.png, a table on stdout

A grid axis is ``KEY=LO:HI:N`` (N values linearly spaced from LO to HI, both
included; N = 1 gives LO) or ``KEY=V1,V2,...`` (TOML values). KEY is a dotted
scenario key (``law.k``, ``noise.std.y``) or a bare key (``payload_mass``)
that names exactly one key of the scenario or one documented key of a section.
Bad input raises ScenarioError before anything runs (exit 2); a run that
diverges or fails is recorded and the others go on (exit 1).
"""
from __future__ import annotations

import csv
import difflib
import itertools
import json
import math
import re
import sys
import time
import tomllib
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from adaptive_mj.study import callable_module
from adaptive_mj.setup import scenario as sc
from adaptive_mj.errors import AdaptiveMJError, ScenarioError
from adaptive_mj.report.html import write_html
from adaptive_mj.report.metrics import TAIL_FRACTION, clean_json, metrics as run_metrics
from adaptive_mj.study.parallel import (Backend, RunSpec, RunOutcome, iter_results, progress_printer, session,
                                       stopping_with)
from adaptive_mj.study.job import RECORD_PREFLIGHT
from adaptive_mj.study.result import Study, Table
from adaptive_mj.trajectory import Status, Trajectory

EXIT_OK, EXIT_FAILED = 0, 1
DEFAULT_METRIC = "rms_tracking_error_tail"
LOG_SPAN = 100.0  # a plotted quantity spanning more than this ratio (2 decades) gets a log axis

# The keys of each section (docs/SCENARIOS.md), so that a bare grid key can name a key the scenario
# file leaves at its default, e.g. viscosity -> plant.viscosity; tests/test_sweep.py checks that the
# validator reads every one. The reference keys depend on reference.kind: the validator's own table.
DOCUMENTED_KEYS: dict[str, tuple[str, ...]] = {
    "plant": ("kind", "backend", "model", "joint", "actuator", "payload", "payload_mass", "site", "theta",
              "g", "density", "viscosity", "ctrl_range", "thruster_time_constant", "regressor",
              "unknown", "joint_params", "base_parameters", "servo_to_torque", "forcerange",
              "damping", "frictionloss", "actuator_lag", "friction_params", "coulomb_smoothing"),
    "simulation": ("integrator", "timestep", "duration", "initial_state", "state_bound", "control_delay",
                   "python_callback"),
    "law": ("kind", "order", "lambda", "k", "gamma", "dead_zone.width", "dead_zone.on",
            "dead_zone.width_in_noise_std", "initial_estimates", "nominal", "K", "boundary_layer", "kd",
            "sigma", "e_modification", "theta0", "projection", "composite.gain", "composite.filter"),
    "noise": ("std",) + tuple(f"std.{signal}" for signal in sc.STATE_SIGNALS) + ("seed",),
    "disturbance": ("kind", "magnitude", "t0", "omega", "phase"),
    "log": ("rate_hz",),
    "control": ("mode", "period", "hold"),
}
TOP_LEVEL = ("schema_version", "name", "description", "reference", "events") + tuple(DOCUMENTED_KEYS)
_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")

_OUTPUT_METRICS = ("rms_tracking_error", "rms_tracking_error_tail", "max_abs_tracking_error_tail")
#: a sweep row's column: each estimate's final error over its true value, p̂/p − 1 [-] (None when p = 0)
RELATIVE = "param_error_relative_final"
_CONTROL_METRICS = ("control_rms", "control_total_variation")
_KEY_UNITS = {"plant.payload_mass": "kg", "plant.density": "kg/m³", "plant.viscosity": "Pa·s",
              "plant.thruster_time_constant": "s", "simulation.duration": "s", "simulation.timestep": "s",
              "law.lambda": "1/s", "reference.omega": "rad/s", "disturbance.omega": "rad/s"}


# --------------------------------------------------------------------------
# grid expressions
def _expected(expr: str) -> ScenarioError:
    return ScenarioError(f"--grid {expr!r}: expected KEY=LO:HI:N or KEY=V1,V2,...")


def _split_top_level(raw: str, sep: str) -> list[str]:
    """raw split at `sep` outside quotes, [arrays] and {inline tables}; parts stripped."""
    parts, depth, quote, start = [], 0, "", 0
    for i, ch in enumerate(raw):
        if quote:
            if ch == quote and raw[i - 1] != "\\":
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == sep and depth == 0:
            parts.append(raw[start:i].strip())
            start = i + 1
    parts.append(raw[start:].strip())
    return parts


def _paths(node: dict, prefix: str = "") -> list[str]:
    """Every dotted key of a parsed document, tables and their entries (not inside arrays)."""
    out = []
    for name, value in node.items():
        path = f"{prefix}{name}"
        out.append(path)
        if isinstance(value, dict):
            out += _paths(value, f"{path}.")
    return out


def known_keys(doc: dict) -> list[str]:
    """The keys a grid may name: those in the document and the documented keys of its sections."""
    keys = _paths(doc)
    keys += [f"{section}.{key}" for section, names in DOCUMENTED_KEYS.items() for key in names]
    ref = doc.get("reference")
    kind = ref.get("kind") if isinstance(ref, dict) else None
    defaults = sc._REFERENCE_KEYS.get(kind, {}) if kind is not None else {}  # the keys of that kind, with defaults
    keys += [f"reference.{key}" for key in ("kind", *defaults)]
    return list(dict.fromkeys(keys))


def resolve_key(key: str, doc: dict, *, expr: str) -> str:
    """A dotted key from a section (used as is), or the one known key that ends with `key`."""
    if not _KEY.match(key):
        raise ScenarioError(f"--grid {expr!r}: key {key!r} must be a dotted scenario key like law.k "
                            "or a bare key like payload_mass")
    if key.split(".")[0] in TOP_LEVEL or key.split(".")[0] in doc:
        return key
    known = known_keys(doc)
    matches = [k for k in known if k.endswith(f".{key}")]
    if len(matches) == 1:
        return matches[0]
    if matches:
        raise ScenarioError(f"--grid {expr!r}: {key!r} is ambiguous: it could be {', '.join(matches)}; "
                            "write the dotted key")
    by_name = {k.rsplit(".", 1)[-1]: k for k in reversed(known)}
    close = [by_name[n] for n in difflib.get_close_matches(key.rsplit(".", 1)[-1], list(by_name), n=3)]
    hint = f" (candidates: {', '.join(close)})" if close else " (write a dotted key like law.k)"
    raise ScenarioError(f"--grid {expr!r}: no scenario key named {key!r}{hint}")


def _number(text: str, *, expr: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ScenarioError(f"--grid {expr!r}: {what} must be a finite number, got {text!r} "
                            "(expected KEY=LO:HI:N)")
    return value


def _linear(raw: str, *, expr: str) -> list[float]:
    parts = _split_top_level(raw, ":")
    if len(parts) != 3:
        raise _expected(expr)
    lo = _number(parts[0], expr=expr, what="LO")
    hi = _number(parts[1], expr=expr, what="HI")
    try:
        n = int(parts[2])
    except ValueError:
        n = 0
    if n < 1:
        raise ScenarioError(f"--grid {expr!r}: N must be an integer >= 1, got {parts[2]!r} (expected KEY=LO:HI:N)")
    return [float(v) for v in np.linspace(lo, hi, n)]


def _explicit(raw: str, *, expr: str) -> list[Any]:
    if not raw:
        raise ScenarioError(f"--grid {expr!r}: empty value list (expected KEY=V1,V2,...)")
    items = _split_top_level(raw, ",")
    for i, item in enumerate(items):
        if not item:
            raise ScenarioError(f"--grid {expr!r}: value {i + 1} is empty (expected KEY=V1,V2,...)")
    return [sc.parse_value(item, what=f"--grid {expr!r}") for item in items]


def parse_grid(expr: str, doc: dict) -> tuple[str, list[Any]]:
    """One --grid expression -> (dotted key, its values).

    doc: the scenario's parsed TOML (after --set overrides), used to resolve bare keys.
    """
    if "=" not in expr:
        raise _expected(expr)
    key, raw = (part.strip() for part in expr.split("=", 1))
    if not key:
        raise _expected(expr)
    key = resolve_key(key, doc, expr=expr)
    if len(_split_top_level(raw, ":")) > 1:
        return key, _linear(raw, expr=expr)
    return key, _explicit(raw, expr=expr)


def scoped_axes(axes: Sequence[tuple[str, Sequence[Any]]]) -> dict[str, str]:
    """{axis key: the law kind it belongs to} for the law-scoped axes, `law.<kind>.<key>` where <kind> is a value of
    a law.kind axis (scenario._scoped_law_keys: such a key reaches only that law's runs)."""
    kinds = {str(v) for key, values in axes if key == "law.kind" for v in values}
    return {key: key.split(".")[1] for key, _ in axes
            if key.startswith("law.") and key.count(".") >= 2 and key.split(".")[1] in kinds}


def grid_points(axes: Sequence[tuple[str, Sequence[Any]]]) -> list[dict[str, Any]]:
    """The product of the axes, first axis slowest: [{key: value, ...}, ...]. A law-scoped axis (scoped_axes:
    `--grid law.kind=a,b --grid law.b.K=0,5,20`) expands only under its own law: at another law's points its value
    is None (not applied, shown as "-"), and the points that would repeat one another are left out (law a runs
    once, not three times)."""
    keys = [key for key, _ in axes]
    points = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*(values for _, values in axes))]
    scoped = scoped_axes(axes)
    if not scoped:
        return points
    out, seen = [], set()
    for point in points:
        kept = {k: (None if k in scoped and scoped[k] != str(point["law.kind"]) else v) for k, v in point.items()}
        signature = json.dumps([repr(v) for v in kept.values()])
        if signature not in seen:
            seen.add(signature)
            out.append(kept)
    return out


# --------------------------------------------------------------------------
# values as TOML text (overrides) and as short labels (file names, tables)
def to_toml(value: Any) -> str:
    """A TOML value's text: to_toml(v) parsed back gives v."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(to_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k if _KEY.match(k) and '.' not in k else json.dumps(k)} = {to_toml(v)}"
                               for k, v in value.items()) + "}"
    return str(value)  # TOML dates and times print as TOML


def label(value: Any) -> str:
    """A short readable text for a grid value: 4 significant digits for floats; "-" for a law-scoped axis at
    another law's point (None: grid_points)."""
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, str):
        return value
    return to_toml(value)


def short_names(keys: Sequence[str]) -> dict[str, str]:
    """key without its section (law.gamma.J -> gamma.J), or the whole key where two axes would clash."""
    last = [k.split(".", 1)[-1] for k in keys]
    return {k: (n if last.count(n) == 1 else k) for k, n in zip(keys, last, strict=True)}


def run_name(index: int, point: dict[str, Any], seed: int, *, names: dict[str, str], width: int = 4) -> str:
    """E.g. 0007-payload_mass=1.36-seed2 (characters unsafe in file names become _)."""
    parts = [f"{names[k]}={label(v)}" for k, v in point.items() if v is not None]
    text = re.sub(r"[^A-Za-z0-9._=+-]+", "_", "-".join(parts))[:80]
    return f"{index:0{width}d}-{text}-seed{seed}"


# --------------------------------------------------------------------------
# results -> rows -> files
def scalar_metric_names() -> list[str]:
    """The metric names of a summary's "metrics", param_error_final left to its entries."""
    empty = Trajectory(t=np.zeros(0), x=np.zeros((0, 1)), u=np.zeros(0), s=np.zeros(0), ref=np.zeros((0, 2)),
                       theta_hat=np.zeros((0, 0)), theta=np.zeros((0, 0)), V=np.zeros(0), names=())
    return [k for k, v in run_metrics(empty).items() if not isinstance(v, dict)]


def flat_metrics(summary: dict | None) -> dict[str, Any]:
    """A summary's metrics with tables flattened: param_error_final.J, ...; and each parameter's error
    relative to its true value, param_error_relative_final.J = (p̂ − p)/|p| (None where p = 0)."""
    out: dict[str, Any] = {}
    for name, value in (summary or {}).get("metrics", {}).items():
        if isinstance(value, dict):
            out.update({f"{name}.{k}": v for k, v in value.items()})
        else:
            out[name] = value
    true = ((summary or {}).get("final") or {}).get("theta") or {}
    for name, err in ((summary or {}).get("metrics", {}).get("param_error_final") or {}).items():
        if name not in true:  # a summary without the final values (none in the tests' stand-ins)
            continue
        p = true[name]
        ok = isinstance(err, (int, float)) and isinstance(p, (int, float)) and p != 0
        out[f"{RELATIVE}.{name}"] = err / abs(p) if ok else None
    return out


def rows(results: Sequence[tuple[dict[str, Any], RunOutcome]], *, root: Path) -> list[dict[str, Any]]:
    """One row per run: its name (the job's tag), grid values, seed, status, reason (why it diverged or
    failed), the summary's metrics flattened, log (relative to root; "" if the run wrote none)."""
    out = []
    for point, result in results:
        summary = result.summary
        reason = result.error if result.status == Status.ERROR else (summary or {}).get("reason", "")
        log = result.job.log
        row = {"run": result.job.tag, **point, "seed": result.job.seed, "status": result.status, "reason": reason}
        row.update(flat_metrics(summary))
        row["log"] = log.relative_to(root).as_posix() if log is not None and log.is_file() else ""
        out.append(row)
    return out


@dataclass(frozen=True)
class PointStats:
    """One grid point's metric over its seeds: mean, min, max, and n_ok of n runs. basis: the runs the numbers
    are of: "ok" (the seeds whose run is ok), or "failed" where no ok seed has a value and some run that
    completed but missed its [success] criteria does (status failed: its metrics are whole; a diverged run's
    are not; a crashed run's count too, FAILED_BASIS); n_basis: how many runs that is (0: NaN, no run has a value)."""

    point: dict[str, Any]
    mean: float
    lo: float
    hi: float
    n_ok: int
    n: int
    basis: str = "ok"
    n_basis: int = 0

    @property
    def failed_only(self) -> bool:
        """The numbers are those of runs that failed their [success] criteria (no ok run has one)."""
        return self.basis == Status.FAILED and self.n_basis > 0

    def shown(self, fmt: str = ".4g") -> str:
        """The mean as a table shows it: "n/a" without a value, "(failed)" after one from failed runs only."""
        if math.isnan(self.mean):
            return "n/a"
        return f"{self.mean:{fmt}}" + (" (failed)" if self.failed_only else "")


def _values(rows: Sequence[dict[str, Any]], metric: str) -> np.ndarray:
    vals = np.array([r.get(metric) for r in rows if _is_number(r.get(metric))], dtype=float)
    return vals[np.isfinite(vals)]


#: The runs a point's metric falls back to where no ok seed has it (basis "failed"): those that failed their
#: [success] criteria, and, as before the crash had a status of its own, those that crashed (their metrics cover
#: the rows up to the crash).
FAILED_BASIS = (Status.FAILED, Status.CRASHED)


def point_stats(table: Sequence[dict[str, Any]], keys: Sequence[str], metric: str) -> list[PointStats]:
    """The metric per grid point, over the seeds whose run is ok; where none of those has a value, over the
    runs that failed their [success] criteria (basis "failed": they ran to the end, so their metrics are
    what sweep.csv holds); NaN where neither has one."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for row in table:
        groups.setdefault(to_toml([row[k] for k in keys]), []).append(row)
    out = []
    for group in groups.values():
        ok = [r for r in group if r["status"] == Status.OK]
        basis, vals = "ok", _values(ok, metric)
        if not vals.size:
            failed = _values([r for r in group if r["status"] in FAILED_BASIS], metric)
            if failed.size:
                basis, vals = str(Status.FAILED.value), failed
        mean, lo, hi = (float(vals.mean()), float(vals.min()), float(vals.max())) if vals.size else (math.nan,) * 3
        out.append(PointStats({k: group[0][k] for k in keys}, mean, lo, hi, len(ok), len(group), basis, int(vals.size)))
    return out


def metric_label(metric: str, plant_kind: str) -> str:
    """The metric name with its unit where known (tracking errors in the plant's output unit)."""
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    if metric.startswith(f"{RELATIVE}."):
        return f"{metric} [-] (p̂/p − 1)"
    if metric.startswith("param_error_final."):
        unit = units.param_unit(plant_kind, metric.split(".", 1)[1])
    elif metric in _OUTPUT_METRICS:
        unit = units.output_unit(plant_kind)
    elif metric in _CONTROL_METRICS:
        unit = units.control_unit(plant_kind)
    else:
        unit = {"saturation_fraction": "-"}.get(metric, "")
    if unit == "-" and metric != "saturation_fraction":  # the first-order example: dimensionless
        unit = ""
    return f"{metric} [{unit}]" if unit else metric


def key_label(key: str, plant_kind: str) -> str:
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    y_unit = units.output_unit(plant_kind)
    y_unit = "" if y_unit == "-" else y_unit
    unit = _KEY_UNITS.get(key) or {"noise.std.y": y_unit, "noise.std.y_dot": y_unit and f"{y_unit}/s"}.get(key, "")
    return f"{key} [{unit}]" if unit else key


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _spans_decades(values: Sequence[float]) -> bool:
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=float)
    return v.size > 1 and bool(np.all(v > 0)) and v.max() / v.min() > LOG_SPAN


def plot_sweep(table: Sequence[dict[str, Any]], keys: Sequence[str], metrics: Sequence[str], path: Path, *,
               plant_kind: str = "", title: str = "") -> Path:
    """One panel per metric against the first grid key; one line per value of the other keys.

    Each point is the mean over the seeds whose run is ok, the band their min–max;
    an x in the line's colour at the bottom marks a grid point where some run was not ok.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.transforms import blended_transform_factory

    x_key, others = keys[0], list(keys[1:])
    numeric_x = all(_is_number(r[x_key]) for r in table)
    x_ticks = {to_toml(r[x_key]): label(r[x_key]) for r in table}  # categorical axis: value -> tick label
    position = list(x_ticks).index

    def x_of(st: PointStats) -> Any:
        return st.point[x_key] if numeric_x else position(to_toml(st.point[x_key]))

    seeds = len({r["seed"] for r in table})
    fig, axes = plt.subplots(len(metrics), 1, figsize=(8, 3.6 * len(metrics) + 0.6), sharex=True,
                             constrained_layout=True, squeeze=False)
    for ax, metric in zip(axes[:, 0], metrics, strict=True):
        stats = point_stats(table, keys, metric)
        series: dict[str, list[PointStats]] = {}
        for st in stats:
            series.setdefault(", ".join(label(st.point[k]) for k in others), []).append(st)
        for i, (name, sts) in enumerate(series.items()):
            sts = sorted(sts, key=x_of)
            # categories: each series a little apart, so that markers at one category do not hide each other
            dodge = 0.0 if numeric_x else (i - (len(series) - 1) / 2) * min(0.3 / len(series), 0.1)
            xs = [x_of(st) + dodge for st in sts]
            mean = np.array([st.mean for st in sts])
            lo, hi = np.array([st.lo for st in sts]), np.array([st.hi for st in sts])
            color = f"C{i % 10}"
            # a categorical axis (law kinds, names): markers only, no line through the categories as if continuous
            ax.plot(xs, mean, "o-" if numeric_x else "o", color=color, lw=1.5, ms=4 if numeric_x else 6,
                    label=name or "mean")
            failed = [(x, st.mean) for x, st in zip(xs, sts, strict=True) if st.failed_only]
            if failed:  # no ok run there: the failed runs' numbers, drawn hollow
                ax.plot(*zip(*failed, strict=True), "o", color=color, ms=9, mfc="white", mew=1.5, zorder=3)
            if seeds > 1 and numeric_x:
                ax.fill_between(xs, lo, hi, color=color, alpha=0.2, lw=0)
            elif seeds > 1:  # the min-max band of a category as an error bar at its marker
                ax.errorbar(xs, mean, yerr=[np.maximum(mean - lo, 0), np.maximum(hi - mean, 0)], fmt="none",
                            ecolor=color, elinewidth=1.5, capsize=4, alpha=0.6)
            bad = [x_of(st) + dodge for st in sts if st.n_ok < st.n]
            if bad:
                ax.plot(bad, [0.03] * len(bad), "x", color=color, ms=9, mew=2.5, clip_on=False,
                        transform=blended_transform_factory(ax.transData, ax.transAxes))
        bad = [st for st in stats if st.n_ok < st.n]
        if bad:
            ax.plot([], [], "x", color="grey", ms=9, mew=2.5, label="some run not ok")
        if any(st.failed_only for st in stats):
            ax.plot([], [], "o", color="grey", ms=9, mfc="white", mew=1.5,
                    label="no run ok: the runs that failed their [success] criteria")
        plotted = [v for st in stats for v in (st.mean, st.lo, st.hi)]
        if _spans_decades(plotted):
            ax.set_yscale("log")
        ax.set_ylabel(metric_label(metric, plant_kind))
        ax.grid(alpha=0.3)
        ax.grid(alpha=0.1, which="minor")
        if len(series) > 1 or bad:
            ax.legend(title=", ".join(key_label(k, plant_kind) for k in others) or None, fontsize=8, title_fontsize=8,
                      loc="best", ncol=2 if len(series) > 6 else 1)
    ax = axes[-1, 0]
    if numeric_x and _spans_decades([float(r[x_key]) for r in table]):
        ax.set_xscale("log")
    if not numeric_x:
        ax.set_xticks(range(len(x_ticks)), list(x_ticks.values()))
    ax.set_xlabel(key_label(x_key, plant_kind))
    n_ok = sum(r["status"] == Status.OK for r in table)
    spread = f"mean over {seeds} seeds, band min–max" if seeds > 1 else "1 seed"
    failed_shown = any(st.failed_only for m in metrics for st in point_stats(table, keys, m))
    text = f"{spread}; {n_ok}/{len(table)} runs ok" + (
        (" (failed runs drawn hollow where no run is ok)" if failed_shown else " (the others left out)")
        if n_ok < len(table) else "")
    axes[0, 0].set_title(f"{title}: {text}" if title else text, fontsize=10)
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def summary_table(table: Sequence[dict[str, Any]], keys: Sequence[str], metrics: Sequence[str]) -> str:
    """Text: one line per grid point with its values, each metric's mean over ok seeds (over the runs that failed
    their [success] criteria where no ok seed has one, marked "(failed)"), and ok/total."""
    names = short_names(keys)
    stats = {m: point_stats(table, keys, m) for m in metrics}
    head = [names[k] for k in keys] + [f"mean {m}" for m in metrics] + ["ok/total"]
    lines = []
    for i, st in enumerate(stats[metrics[0]]):
        cells = [label(st.point[k]) for k in keys]
        cells += [stats[m][i].shown() for m in metrics]
        lines.append(cells + [f"{st.n_ok}/{st.n}"])
    widths = [max(len(r[c]) for r in [head, *lines]) for c in range(len(head))]
    return "\n".join("  ".join(cell.rjust(w) for cell, w in zip(r, widths, strict=True)) for r in [head, *lines])


# --------------------------------------------------------------------------
# the command
def _document(path: Path, overrides: Sequence[str]) -> tuple[dict, sc.Scenario]:
    """The scenario as parsed TOML after the overrides (for key resolution), and validated."""
    scn = sc.load(path, overrides=list(overrides))
    doc = tomllib.loads(scn.text)
    for expr in overrides:
        sc.apply_override(doc, expr, where=str(path))
    return doc, scn


def _axes(exprs: Sequence[str], doc: dict) -> list[tuple[str, list[Any]]]:
    if not exprs:
        raise ScenarioError("sweep needs at least one --grid KEY=LO:HI:N or KEY=V1,V2,...")
    axes: list[tuple[str, list[Any]]] = []
    for expr in exprs:
        key, values = parse_grid(expr, doc)
        if key == "noise.seed":
            raise ScenarioError(f"--grid {expr!r}: noise.seed is set per run; use --seeds N for seeds 0..N-1")
        if key in (k for k, _ in axes):
            raise ScenarioError(f"--grid {expr!r}: {key} is already a grid axis")
        axes.append((key, values))
    return axes


def _metrics(requested: Sequence[str]) -> list[str]:
    names = [n.strip() for item in requested for n in item.split(",") if n.strip()] or [DEFAULT_METRIC]
    known = scalar_metric_names()
    for name in names:
        if name not in known and not name.startswith(("param_error_final.", f"{RELATIVE}.")):
            raise ScenarioError(f"--metric {name!r}: expected one of {', '.join(known)} "
                                f"or param_error_final.<parameter> or {RELATIVE}.<parameter>")
    return list(dict.fromkeys(names))


def _grid_overrides(point: dict[str, Any]) -> list[str]:
    """A grid point as overrides; a law.kind axis swaps the whole law (scenario.law_swap: that law's
    defaults plus the --set law.* keys), so laws with other keys can share a sweep; a law-scoped axis at another
    law's point (None: grid_points) gives none."""
    return [sc.law_swap(str(value)) if key == "law.kind" else f"{key}={to_toml(value)}"
            for key, value in point.items() if value is not None]


def _validate_points(path: Path, overrides: Sequence[str], points: Sequence[dict[str, Any]]) -> None:
    """Every grid point as a scenario, and built (its model, payload files, names and keyframes;
    adaptive_mj.setup.build.check), before any point runs."""
    from adaptive_mj.setup.build import check

    sources: dict = {}  # points that share a [plant] section compose its model once
    for point in points:
        try:
            check(sc.load(path, overrides=[*overrides, *_grid_overrides(point)]), sources)
        except AdaptiveMJError as exc:
            where = ", ".join(f"{k}={label(v)}" for k, v in point.items())
            raise ScenarioError(f"grid point {where}: {exc}") from None


def plan(path: Path, points: Sequence[dict[str, Any]], *, seeds: int, overrides: Sequence[str],
         logs: Path | None) -> list[tuple[dict[str, Any], RunSpec]]:
    """(grid point, RunSpec) for every point × seed 0..seeds-1, seeds fastest; each job logs to logs/<name>.mcap
    (logs None: no log, the summary row only)."""
    names = short_names(list(points[0]))
    width = max(4, len(str(len(points) * seeds - 1)))
    planned = []
    for p, point in enumerate(points):
        for seed in range(seeds):
            name = run_name(p * seeds + seed, point, seed, names=names, width=width)
            job = RunSpec(path, overrides=(RECORD_PREFLIGHT, *overrides, *_grid_overrides(point)), seed=seed,
                      log=None if logs is None else logs / f"{name}.mcap",
                      tag=name, keep_trajectory=False)
            planned.append((point, job))
    return planned


def parse_breaking_point(expr: str, doc: dict) -> tuple[str, float, float, bool]:
    """--breaking-point KEY=LO:HI -> (dotted key, lo, hi, integer: both ends written as integers)."""
    if "=" not in expr:
        raise ScenarioError(f"--breaking-point {expr!r}: expected KEY=LO:HI")
    key, raw = (part.strip() for part in expr.split("=", 1))
    key = resolve_key(key, doc, expr=expr)
    parts = raw.split(":")
    if len(parts) != 2:
        raise ScenarioError(f"--breaking-point {expr!r}: expected KEY=LO:HI, got {raw!r}")
    lo, hi = (_number(x, expr=expr, what=w) for x, w in zip(parts, ("LO", "HI"), strict=True))
    if not lo < hi:
        raise ScenarioError(f"--breaking-point {expr!r}: LO must be < HI, got {lo:g} and {hi:g}")
    integer = all(re.fullmatch(r"[+-]?\d+", x.strip()) for x in parts)
    return key, lo, hi, integer


def sweep_notes(base, keys: Sequence[str], seeds: int) -> list[str]:
    """What a sweep's grid will not do that its user may expect: seeds that change nothing (no
    noise anywhere in the grid), and a payload mass that an event overrides mid-run."""
    notes = []
    disturbance = getattr(base, "disturbance", None)
    noisy = (any(v > 0 for v in (base.noise.std or {}).values()) or any(k.startswith("noise.std") for k in keys)
             or getattr(disturbance, "kind", None) == "noise"  # band-limited noise drawn from the seed
             or any(k.startswith("disturbance") for k in keys))
    if seeds > 1 and not noisy:
        notes.append(f"--seeds {seeds} on a scenario without noise (noise.std is empty): the seed changes nothing, "
                     f"so the {seeds} runs of each point are identical; set noise.std (--set or --grid) or use "
                     "--seeds 1")
    if "plant.payload_mass" in keys:
        from adaptive_mj.plants.kinds import event_kind

        for i, e in enumerate(base.events):
            kind = event_kind(e.kind)  # its declaration says which keys it overrides (EventKind.overrides)
            if kind is not None and "plant.payload_mass" in kind.overrides:
                what = kind.sets(e) if kind.sets is not None else f"{e.value:g}"
                notes.append(f"plant.payload_mass sets the payload's initial mass only: events[{i}] still sets it "
                             f"to {what} at t = {e.t:g} s in every run (override `events` to change or remove it)")
    return notes


def where_text(backend: Backend | None, runs: int) -> str:
    """Where the runs go, for the opening line: "on Ray (ADDR, logs as bytes)" or "in N processes"."""
    if backend is not None and backend.kind == "ray":
        return f"on Ray ({backend.address or 'started here'}, logs as {backend.logs})"
    jobs = backend.jobs if backend is not None else 1
    n = min(jobs, max(1, runs))
    return f"in {n} process{'es' if n > 1 else ''}"


def run_breaking_point(path: Path, *, point: str, tail_bound: float, seeds: int, steps: int,
                       overrides: Sequence[str], out: Path | None, backend: Backend) -> Study:
    """`sweep --breaking-point KEY=LO:HI --tail-bound B` (adaptive_mj.study.api.breaking_point, which checks
    the options): the largest value of KEY at which every seed passes (no divergence, tail RMS error <= B),
    by bisection (adaptive_mj.study.breaking_point).
    KEY = control.period: LO, HI and every value tried are rounded to whole physics steps of the
    scenario's timestep, each run under control.mode = 'sampled'."""
    from adaptive_mj.runs.runner import new_output_dir
    from adaptive_mj.study.breaking_point import Search, Stressor, margin_text, search_all

    doc, base = _document(path, overrides)
    key, lo, hi, integer = parse_breaking_point(point, doc)
    step = None
    if key == "control.period":  # whole physics steps, under sampled-data control
        step = _timestep(base)
        stressor = Stressor.control_period(lo, hi, step)
        if not stressor.lo < stressor.hi:
            raise ScenarioError(f"--breaking-point {point!r}: LO and HI round to the same whole "
                                f"number of physics steps ({stressor.lo:g} s, timestep {step:g} s)")
        if (stressor.lo, stressor.hi) != (lo, hi):
            print(f"sweep: note: control.period rounded to whole physics steps of {step:g} s: "
                  f"[{stressor.lo:g}, {stressor.hi:g}] s", file=sys.stderr)
        lo, hi, integer = stressor.lo, stressor.hi, False
    else:
        stressor = Stressor.key(key, lo, hi, integer=integer)
    from adaptive_mj.setup.build import check

    for v in (lo, hi):  # both ends must make a valid scenario, built, before anything runs
        try:
            check(sc.load(path, overrides=[*overrides, *stressor.overrides(v)]))
        except AdaptiveMJError as exc:
            raise ScenarioError(f"--breaking-point {key}={v:g}: {exc}") from None
    for note in sweep_notes(base, [key], seeds):
        print(f"sweep: note: {note}", file=sys.stderr)
    out = new_output_dir(out, f"breaking-point-{base.name}")
    search = Search(path, base.name, tuple(overrides), stressor, float(tail_bound))
    print(f"breaking point of {key} in [{lo:g}, {hi:g}] for {base.name}: {seeds} seed(s), "
          f"{steps} bisection step(s) {where_text(backend, backend.jobs)} -> {out}", file=sys.stderr)
    with session(backend):  # several batches, one Ray session
        (m,) = search_all([search], seeds=seeds, steps=steps, logs=out / "logs", n_jobs=backend.jobs,
                          backend=backend, on_done=progress_printer(seeds * (2 + steps), label="runs"))
    stats = m.stats()
    record = {"scenario": str(path), "key": key, "lo": lo, "hi": hi, "integer": integer, "step": step,
              "seeds": seeds,
              "steps": steps, "tail_bound": tail_bound, "overrides": list(overrides), **stats,
              "evaluations": [{"value": e.value, "passes": e.passes, "statuses": e.statuses,
                               "tail": [x if math.isfinite(x) else None for x in e.raw],
                               "predicted_unstable": e.predicted} for e in m.evaluations]}
    (out / "breaking_point.json").write_text(json.dumps(clean_json(record), indent=1), encoding="utf-8")
    text = (f"{key}: margin {margin_text(m)}"
            + (f", resolution {m.resolution:.3g}" if m.resolution is not None else "")
            + (f"; at the margin over {seeds} seed(s): tail error mean {stats['tail_mean']:.3g}, CVaR10% "
               f"{stats['tail_cvar10']:.3g}" if stats["tail_mean"] is not None else "")
            + (f"; failure rate at {m.first_fail:g}: {100 * stats['failure_rate_beyond']:.0f} %"
               if stats["failure_rate_beyond"] is not None else ""))
    evaluations = [{"value": e["value"], "passes": e["passes"], "statuses": ", ".join(e["statuses"]),
                    "tail_max": max((x for x in e["tail"] if x is not None), default=None)}
                   for e in clean_json(record)["evaluations"]]
    evaluations.sort(key=lambda e: e["value"])
    unit = metric_label(DEFAULT_METRIC, base.plant.kind)[len(DEFAULT_METRIC):].strip(" []")
    plot_path = out / "breaking_point.png"
    plot_breaking_point(record, plot_path, unit=unit, title=base.name)
    md = (f"# Breaking point of {key} for {base.name}\n\n"
          f"Bisection of `{key}` in [{lo:g}, {hi:g}] on `{path.name}` ({seeds} seed(s), {steps} bisection step(s)"
          + (f", overrides {', '.join(f'`{o}`' for o in overrides)}" if overrides else "")
          + f"): a run fails when it diverges or its tail RMS tracking error (over the last "
          f"{100 * TAIL_FRACTION:g} % of the run) exceeds {tail_bound:g}{' ' + unit if unit else ''}; a value "
          f"passes when every seed passes.\n\n**{text}.**\n\n"
          + Table.of(evaluations).to_markdown()
          + "\n\n![breaking point](breaking_point.png)\n\nEvery value's runs are in `breaking_point.json`, their "
          "logs in `logs/`.\n")
    (out / "report.md").write_text(md, encoding="utf-8")
    html = write_html(out / "report.md")
    return Study("breaking_point", out, EXIT_OK, out / "report.md", html, f"\n{text}\noutput: {out}",
                 info=clean_json({k: v for k, v in record.items() if k != "evaluations"}),
                 load_rows=lambda: evaluations,
                 plotter=lambda path=None: plot_breaking_point(record, path or plot_path, unit=unit, title=base.name))


def plot_breaking_point(record: dict, path: Path, *, unit: str = "", title: str = "") -> Path:
    """Each seed's tail RMS error at each value tried (a cross where the run diverged, failed or could not
    run), the bound as a labelled line, the margin and the first failing value as vertical lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
    bound = record["tail_bound"]
    ys = []
    for e in record["evaluations"]:
        for x, status in zip(e["tail"], e["statuses"], strict=True):
            if x is not None and status == Status.OK:
                ax.plot(e["value"], x, "o", color="C0", ms=4)
                ys.append(x)
            else:
                ax.plot(e["value"], bound, "x", color="C3", ms=8, mew=2)
    ax.axhline(bound, color="C3", ls="--", lw=1, label=f"bound {bound:g}{' ' + unit if unit else ''}")
    if record.get("margin") is not None:
        ax.axvline(record["margin"], color="C2", lw=1, label=f"margin {record['margin']:g}")
    if record.get("first_fail") is not None:
        ax.axvline(record["first_fail"], color="C1", lw=1, ls=":", label=f"first failing {record['first_fail']:g}")
    ax.plot([], [], "x", color="C3", ms=8, mew=2, label="run not ok (drawn at the bound)")
    values = [e["value"] for e in record["evaluations"]]
    if _spans_decades(values):
        ax.set_xscale("log")
    if _spans_decades(ys + [bound]):
        ax.set_yscale("log")
    ax.set_xlabel(record["key"])
    ax.set_ylabel(f"tail RMS tracking error{f' [{unit}]' if unit else ''}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{title}: breaking point of {record['key']}" if title else record["key"], fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return Path(path)


def _timestep(base) -> float:
    """The scenario's physics timestep [s]: simulation.timestep, or the model's own."""
    if base.simulation.timestep is not None:
        return float(base.simulation.timestep)
    from adaptive_mj.setup.build import build

    return float(build(base).plant.dt)


MANIFEST = "manifest.json"  # the study's inputs, written before any run
MANIFEST_FORMAT = 1


def check_manifest(out: Path, manifest: dict) -> None:
    """--resume DIR: DIR holds a study started with the same scenario, grid, seeds and overrides."""
    path = out / MANIFEST
    if not path.is_file():
        raise ScenarioError(f"sweep --resume {out}: no {MANIFEST} there (not a sweep folder, or one from before "
                            "resumable sweeps)")
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ScenarioError(f"sweep --resume {out}: {MANIFEST} cannot be read ({exc})") from None
    if not isinstance(old, dict) or not all(key in old for key in manifest):
        got = (f"an object without {', '.join(k for k in manifest if k not in old)}" if isinstance(old, dict)
               else "a JSON " + {list: "array", str: "string", int: "number", float: "number", bool: "boolean",
                                    type(None): "null"}.get(type(old), type(old).__name__))
        raise ScenarioError(f"sweep --resume {out}: {MANIFEST} is not a sweep manifest (expected an object with "
                            f"{', '.join(manifest)}; got {got}); resume only a folder that sweep wrote")
    for key in ("scenario_text", "grid", "seeds", "overrides"):
        if old.get(key) != manifest[key]:
            shown = "the scenario file's text" if key == "scenario_text" else f"{key} {old.get(key)!r}"
            now = "" if key == "scenario_text" else f", this command has {manifest[key]!r}"
            raise ScenarioError(f"sweep --resume {out}: the study was started with {shown}{now}; resume it with the "
                                "same scenario, --grid, --seeds and --set, or start a new folder")


def finished_results(jobs: Sequence[RunSpec]) -> Iterator[tuple[int, RunOutcome]]:
    """(index, result) for each job whose log is complete (closed with a summary: ok, failed, crashed
    or diverged), read back from the log; a missing, truncated or interrupted log (or one a dead Ray
    worker left as NAME.partial) is removed so that its run starts afresh."""
    from adaptive_mj.errors import LogFormatError
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.study.ray_backend import partial_path

    for i, job in enumerate(jobs):
        if job.log is None:
            continue
        partial_path(job.log).unlink(missing_ok=True)
        if not job.log.is_file():
            continue
        try:
            logged = read_log(job.log)
        except LogFormatError:
            logged = None
        ended = (Status.OK, Status.DIVERGED, Status.FAILED, Status.CRASHED)
        if logged is not None and logged.summary is not None and logged.status in ended:
            yield i, RunOutcome(job, logged.status, logged.summary)
        else:
            job.log.unlink()


ROWS_STREAM = "rows.jsonl"  # one line per finished run, written as it arrives: {"index": i, "row": {...}}


class _RowStream:
    """rows.jsonl open for writing: one line per finished run, flushed at most every FLUSH_EVERY seconds
    (a flush per run cost the driver ~0.1 ms a run; nothing reads the stream before it is closed, and
    --resume rebuilds it from the logs)."""

    FLUSH_EVERY = 1.0  # [s]

    def __init__(self, file):
        self.file, self.flushed_at = file, time.monotonic()

    def append(self, index: int, row: dict[str, Any]) -> None:
        self.file.write(json.dumps(clean_json({"index": index, "row": row}), ensure_ascii=False, default=str) + "\n")
        now = time.monotonic()
        if now - self.flushed_at >= self.FLUSH_EVERY:
            self.file.flush()
            self.flushed_at = now


def write_tables(stream_path: Path, n: int, inputs: dict[str, Any], out: Path, *,
                 keep: Sequence[str]) -> tuple[list[dict[str, Any]], list[str]]:
    """sweep.csv and sweep.json in the planned order, from the rows streamed to `stream_path` in the
    order they finished (one line per run index 0..n-1), holding one row at a time plus each line's
    offset. Numbers as Python writes them (exact floats); NaN, inf and missing values as empty cells
    (JSON null); tables as TOML; returns the rows cut to the columns in `keep` (+ run, status, reason) for the summary,
    and every column's name."""
    offsets: dict[int, int] = {}
    with open(stream_path, "rb") as f:
        pos = 0
        for line in f:
            offsets[json.loads(line)["index"]] = pos
            pos += len(line)
    missing = [i for i in range(n) if i not in offsets]
    if missing:
        raise AssertionError(f"{stream_path}: no row for run(s) {missing[:5]}")

    def ordered():
        with open(stream_path, "rb") as f:
            for i in range(n):
                f.seek(offsets[i])
                yield json.loads(f.readline())["row"]

    cols: dict[str, None] = {}
    counts: dict[str, int] = {}
    for row in ordered():
        cols.update(dict.fromkeys(k for k in row if k != "log"))
        counts[row["status"]] = counts.get(row["status"], 0) + 1
    fieldnames = [*cols, "log"]
    short = []
    with open(out / "sweep.csv", "w", newline="", encoding="utf-8") as fc, \
            open(out / "sweep.json", "w", encoding="utf-8") as fj:
        writer = csv.DictWriter(fc, fieldnames=fieldnames)
        writer.writeheader()
        head = json.dumps(clean_json({"inputs": inputs, "counts": counts}), indent=1, ensure_ascii=False, default=str)
        fj.write(head[:-2] + ',\n "rows": [')
        for i, row in enumerate(ordered()):
            writer.writerow({k: "" if v is None else v if isinstance(v, (str, int, float)) else to_toml(v)
                             for k, v in row.items()})
            fj.write(("," if i else "") + "\n  " + json.dumps(row, ensure_ascii=False))
            short.append({k: row[k] for k in ("run", "status", "reason", *keep) if k in row})
        fj.write("\n ]\n}\n")
    return short, fieldnames


def run_sweep(path: Path, *, grid: Sequence[str], seeds: int, overrides: Sequence[str], metrics: Sequence[str],
              out: Path | None, resume: Path | None, logs: str, backend: Backend) -> Study:
    """The sweep (see the module docstring) with options that adaptive_mj.study.api.sweep has checked."""
    from adaptive_mj.runs.runner import new_output_dir

    doc, base = _document(path, overrides)
    axes = _axes(grid, doc)
    keys = [key for key, _ in axes]
    metrics = _metrics(metrics)
    points = grid_points(axes)
    _validate_points(path, overrides, points)

    for note in sweep_notes(base, keys, seeds):
        print(f"sweep: note: {note}", file=sys.stderr)
    manifest = {"format": MANIFEST_FORMAT, "scenario": str(path), "scenario_text": base.text, "grid": list(grid),
                "seeds": seeds, "overrides": list(overrides)}
    if resume is not None:
        out = Path(resume)
        check_manifest(out, manifest)
    else:
        out = new_output_dir(out, f"sweep-{base.name}")
        (out / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")  # first: a study
        # killed at any point can be resumed
    planned = plan(path, points, seeds=seeds, overrides=overrides, logs=None if logs == "summary" else out / "logs")
    total = len(planned)
    stream_path = out / ROWS_STREAM
    finished: set[int] = set()
    with open(stream_path, "w", encoding="utf-8") as file:  # rows as they arrive (bounded driver memory)
        stream = _RowStream(file)
        if resume is not None:
            for i, result in finished_results([job for _, job in planned]):
                stream.append(i, rows([(planned[i][0], result)], root=out)[0])
                finished.add(i)
        todo = [i for i in range(total) if i not in finished]
        if backend.kind == "local":
            backend = replace(backend, jobs=min(backend.jobs, max(1, len(todo))))
        where = where_text(backend, len(todo))
        print(f"sweep: {len(points)} grid point(s) x {seeds} seed(s) = {total} runs of {base.name} "
              + (f"({len(finished)} already finished, {len(todo)} to run) " if resume is not None else "")
              + f"{where} -> {out}", file=sys.stderr)
        progress = progress_printer(len(todo), label="runs")
        if todo:
            gen = iter_results([planned[i][1] for i in todo], backend, on_retry=progress.retried)
            with stopping_with(gen, len(todo), lambda: progress.n):
                for k, result in gen:
                    i = todo[k]
                    progress(result)
                    stream.append(i, rows([(planned[i][0], result)], root=out)[0])
        del todo, finished

    inputs = {"scenario": str(path), "scenario_name": base.name,
              "grid": [{"expr": expr, "key": key, "values": values}
                       for expr, (key, values) in zip(grid, axes, strict=True)],
              "overrides": list(overrides), "seeds": seeds, "metrics": metrics,
              "backend": backend.kind, "created_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    table, present = write_tables(stream_path, total, inputs, out, keep=[*keys, "seed", *metrics])
    plot_sweep(table, keys, metrics, out / "sweep.png", plant_kind=base.plant.kind, title=base.name)

    notes = []
    for name in metrics:
        if name not in present:
            have = [c for c in present if c.startswith("param_error_final.")]
            notes.append(f"--metric {name!r}: no run has this metric (have: {', '.join(sorted(have)) or 'none'})")
    not_ok = [r for r in table if r["status"] != Status.OK]
    notes += [f"  {row['run']}: {row['status']}: {row['reason']}" for row in not_ok[:5]]
    if len(not_ok) > 5:
        notes.append(f"  ... and {len(not_ok) - 5} more (see sweep.csv)")
    counts = {status: sum(r["status"] == status for r in table) for status in dict.fromkeys(r["status"] for r in table)}
    (out / "report.md").write_text(sweep_report(inputs, table, keys, metrics, plant_kind=base.plant.kind, where=where,
                                                logs=logs), encoding="utf-8")
    html = write_html(out / "report.md")
    text = (summary_table(table, keys, metrics) + f"\nreport: {html}\n"
            + f"{total - len(not_ok)}/{total} runs ok; output: {out}")

    def load_rows() -> list[dict[str, Any]]:
        return json.loads((out / "sweep.json").read_text(encoding="utf-8"))["rows"]

    def plotter(path: Path | None = None, *, metrics: Sequence[str] = tuple(metrics)) -> Path:
        return plot_sweep(table, keys, _metrics(metrics), path or out / "sweep.png", plant_kind=base.plant.kind,
                          title=base.name)

    return Study("sweep", out, EXIT_OK if not not_ok else EXIT_FAILED, out / "report.md", html, text, tuple(notes),
                 info={"keys": keys, "metrics": metrics, "counts": counts, "inputs": inputs},
                 load_rows=load_rows, columns=tuple(present), plotter=plotter)


def sweep_report(inputs: dict[str, Any], table: Sequence[dict[str, Any]], keys: Sequence[str],
                 metrics: Sequence[str], *, plant_kind: str, where: str, logs: str) -> str:
    """report.md of a sweep: what ran, each grid point's metrics (mean over the ok seeds), the figure, the
    runs that were not ok."""
    total = len(table)
    n_ok = sum(r["status"] == Status.OK for r in table)
    grid = "; ".join(f"`{g['key']}` = " + ", ".join(label(v) for v in g["values"]) for g in inputs["grid"])
    stats = {m: point_stats(table, keys, m) for m in metrics}
    points = [{**{key_label(k, plant_kind): label(st.point[k]) for k in keys},
               **{f"mean {metric_label(m, plant_kind)}": (stats[m][i].shown(".6g") if stats[m][i].failed_only
                                                          else stats[m][i].mean) for m in metrics},
               "ok/total": f"{st.n_ok}/{st.n}"} for i, st in enumerate(stats[metrics[0]])]
    not_ok = [r for r in table if r["status"] != Status.OK]
    text = (f"# Sweep of {inputs['scenario_name']}\n\n"
            f"{total} runs of `{Path(inputs['scenario']).name}` {where}, created {inputs['created_utc']}: the grid "
            f"{grid} × {inputs['seeds']} seed(s) (0..{inputs['seeds'] - 1})"
            + (f", with {', '.join(f'`{o}`' for o in inputs['overrides'])}" if inputs["overrides"] else "")
            + f". {n_ok} of {total} runs ok. Each metric is the mean over the seeds whose run is ok"
            f" (tail: the last {100 * TAIL_FRACTION:g} % of the run); where no seed's run is ok, over the runs that"
            " ran to the end but failed their [success] criteria, marked (failed).\n\n"
            + Table.of(points).to_markdown() + "\n\n![sweep](sweep.png)\n\n")
    if not_ok:
        text += "Runs that were not ok:\n\n" + "\n".join(
            f"- `{r['run']}`: {r['status']}" + (f" ({r['reason']})" if r["reason"] else "") for r in not_ok[:50])
        text += (f"\n- ... and {len(not_ok) - 50} more (see `sweep.csv`)" if len(not_ok) > 50 else "") + "\n\n"
    text += ("Every run's row (all metrics) is in `sweep.csv` and `sweep.json`"
             + (", its MCAP log in `logs/`." if logs != "summary" else " (no logs: `--logs summary`).") + "\n")
    return text


callable_module(__name__)  # adaptive_mj.study.sweep(...) calls adaptive_mj.study.api.sweep(...)

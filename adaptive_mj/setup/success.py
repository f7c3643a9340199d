"""A run's verdict: the scenario's [success] criteria made concrete for its plant and reference
before the run (`criteria`), and a finished run's summary judged against them (`judge`).

A run that completes is "ok" only when every criterion holds; otherwise "failed", with a reason
that names each criterion missed and the measured value. A run that diverges stays "diverged"
(its own, earlier verdict). Defaults and their derivation: docs/SCENARIOS.md, "Verdict".
"""
from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Hashable
from dataclasses import dataclass, field
from typing import TypeGuard

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.setup.scenario import Scenario

REFERENCE_SAMPLES = 2001  # reference evaluations over [0, duration] for its half-range


@dataclass(frozen=True)
class Criteria:
    """tail_rms: (m,) bound per joint on the tail RMS tracking error [m or rad] (m = 1 for a 1-DOF
    plant); tail_rule: how it was set (said in the summary); param_error: name -> bound on the final
    |θ̂ - θ| / |θ|; saturation: the largest fraction of the run an actuator may spend at its limit;
    tail_saturation: the largest fraction of the tail's rows with any actuator at a limit (1: not judged);
    oscillation [rad/s]: the largest sustained oscillation of the body rate over the tail (inf: not judged)."""

    tail_rms: tuple[float, ...]
    tail_rule: str
    param_error: dict[str, float] = field(default_factory=dict)
    saturation: float = 1.0
    physical: bool = False
    tail_saturation: float = 1.0
    oscillation: float = math.inf

    def describe(self) -> dict:
        """The criteria as JSON-ready data (the summary's "success"; an unjudged oscillation bound is null)."""
        return {"tail_rms": list(self.tail_rms), "tail_rule": self.tail_rule,
                "param_error": dict(self.param_error), "saturation": self.saturation, "physical": self.physical,
                "tail_saturation": self.tail_saturation, "oscillation": self.oscillation}


def reference_rows(reference, ts: np.ndarray, order: int) -> np.ndarray:
    """(order + 1, N, m) y_d and its derivatives 1..order at the times ts (N,) [s] (m = 1 for a 1-DOF plant): one
    vectorised call of the reference (the bundled kinds take an array of t; every bundled joint reference gives each
    time the numbers a scalar call gives, MRAC's model response may differ in the last bit), else one call per
    time."""
    n = len(ts)
    try:
        r = np.asarray(reference(ts, order), dtype=float)
        if r.shape[:2] == (order + 1, n):
            return r.reshape(order + 1, n, -1)
    except (TypeError, ValueError):
        pass
    rows = [reference(t, order) for t in ts]
    return np.array([[np.atleast_1d(np.asarray(r[k], dtype=float)) for r in rows] for k in range(order + 1)])


def reference_positions(reference, ts: np.ndarray, order: int) -> np.ndarray:
    """(N, m) y_d at the times ts (N,) [s], m = 1 for a 1-DOF plant (reference_rows' first row)."""
    return reference_rows(reference, ts, order)[0]


def sampled_rows(reference, duration: float, samples: int, order: int) -> np.ndarray:
    """(order + 1, samples, m) reference_rows at `samples` evenly spaced times over [0, duration] [s]. Kept per
    (reference, duration, samples, order) when the reference is a frozen dataclass (every bundled kind: equal
    fields, equal values), as a study's runs share one; a copy each time. A 6-joint reference's 2001 samples
    cost ~1 ms a run otherwise."""
    if _frozen_dataclass(reference):
        try:
            return _sampled(reference, float(duration), samples, order).copy()
        except TypeError:  # a field numpy holds (unhashable): evaluated every time
            pass
    return reference_rows(reference, np.linspace(0.0, duration, samples), order)


def sampled_positions(reference, duration: float, samples: int, order: int) -> np.ndarray:
    """(samples, m) y_d at `samples` evenly spaced times over [0, duration] [s] (sampled_rows' first row)."""
    return sampled_rows(reference, duration, samples, order)[0]


def _frozen_dataclass(value: object) -> TypeGuard[Hashable]:
    """A frozen dataclass: hashed by its fields (which may still fail to hash: a numpy array). Every
    dataclass has __dataclass_params__; typeshed's DataclassInstance does not declare it."""
    return dataclasses.is_dataclass(value) and value.__dataclass_params__.frozen  # type: ignore[union-attr]  # undeclared


@functools.lru_cache(maxsize=32)
def _sampled(reference, duration: float, samples: int, order: int) -> np.ndarray:
    return reference_rows(reference, np.linspace(0.0, duration, samples), order)


def reference_half_range(reference, duration: float, order: int) -> np.ndarray:
    """(m,) half of max - min of y_d over [0, duration] per joint (m = 1 for a 1-DOF plant)."""
    y = sampled_positions(reference, duration, REFERENCE_SAMPLES, order)
    return 0.5 * (y.max(axis=0) - y.min(axis=0))


def criteria(scn: Scenario, reference, order: int, param_names: tuple[str, ...]) -> Criteria:
    """The run's Criteria from scn.success; a bound on a parameter the law does not estimate is a
    ScenarioError naming it."""
    spec = scn.success
    half = reference_half_range(reference, scn.simulation.duration, order)
    if spec.tail_rms is not None:
        tail = tuple(float(spec.tail_rms) for _ in half)
        rule = "success.tail_rms"
    else:
        tail = tuple(max(spec.tail_fraction * float(h), spec.tail_floor) for h in half)
        rule = (f"{spec.tail_fraction:g} x the reference's half-range, at least {spec.tail_floor:g} "
                "(success.tail_fraction, success.tail_floor)")
    if isinstance(spec.param_error, dict):
        unknown = [n for n in spec.param_error if n not in param_names]
        if unknown:
            raise ScenarioError(f"{scn.source}: success.param_error.{unknown[0]}: not a parameter of the law "
                                f"(its parameters: {', '.join(param_names)})")
        params = dict(spec.param_error)
    elif spec.param_error is not None:
        params = {n: float(spec.param_error) for n in param_names}
    else:
        params = {}
    kind = _plant_kind(scn.plant.kind)
    tail_sat = spec.tail_saturation if spec.tail_saturation is not None else getattr(kind, "tail_saturation", None)
    osc = spec.oscillation if spec.oscillation is not None else getattr(kind, "oscillation", None)
    return Criteria(tail_rms=tail, tail_rule=rule, param_error=params, saturation=spec.saturation,
                    physical=spec.physical, tail_saturation=1.0 if tail_sat is None else float(tail_sat),
                    oscillation=math.inf if osc is None else float(osc))


def _plant_kind(name: str):
    """The built-in plant kind `name` (its stability criteria's defaults), or None (a plugin's)."""
    from adaptive_mj.plants import kinds

    return kinds.built_in().get(name)


def _relative_error(estimate: float | None, truth: float | None) -> float:
    if estimate is None or truth is None:
        return math.inf
    err = abs(estimate - truth)
    return err / abs(truth) if truth != 0 else (0.0 if err == 0 else math.inf)


def judge(summary: dict, c: Criteria, *, unit: str = "") -> list[str]:
    """The criteria a finished run missed, each as "<what> <measured> > <bound> (<key>)"; empty when
    every one holds. summary: report.metrics.summary's dict (metrics, final)."""
    m, final, missed = summary.get("metrics") or {}, summary.get("final") or {}, []
    unit = "" if unit == "-" else unit  # a dimensionless output
    per_joint = m.get("rms_tracking_error_tail_per_joint")
    tails = list(per_joint.items()) if per_joint else [("", m.get("rms_tracking_error_tail"))]
    for (joint, value), bound in zip(tails, c.tail_rms, strict=True):
        if value is None or not math.isfinite(value) or value > bound:
            where = f" on {joint}" if joint else ""
            u = f" {unit}" if unit else ""
            missed.append(f"tail RMS tracking error{where} {_show(value)}{u} > {bound:.3g}{u} (success.tail_rms)")
    est, true = final.get("theta_hat", {}), final.get("theta", {})
    for name, bound in c.param_error.items():
        rel = _relative_error(est.get(name), true.get(name))
        if not rel <= bound:
            missed.append(f"final error of {name} {_show(100 * rel)} % > {100 * bound:.3g} % (success.param_error)")
    sat = m.get("saturation_fraction_per_joint") or ({"": m["saturation_fraction"]} if "saturation_fraction" in m
                                                     else {})
    for joint, frac in sat.items():
        if frac is not None and frac > c.saturation:
            where = f" on {joint}" if joint else ""
            missed.append(f"time at the actuator limit{where} {100 * frac:.3g} % > {100 * c.saturation:.3g} % "
                          "(success.saturation)")
    missed += unstable(m, c.tail_saturation, c.oscillation)
    if c.physical:
        for body, e in (m.get("identification") or {}).items():
            if e.get("impossible"):
                missed.append(f"the final estimate of body {body} is no possible body: {e['impossible']} "
                              "(success.physical)")
    return missed


def unstable(metrics: dict, tail_saturation: float | None, oscillation: float | None) -> list[str]:
    """The stability criteria a finished run missed (judge's, and the studies' failure rule: study.job.passes):
    the fraction of the tail's rows with any actuator at a limit (metrics["saturation_fraction_tail"]) above
    tail_saturation, the body rate's sustained oscillation over the tail (metrics["rate_oscillation_tail"]
    ["amplitude"], report.metrics.rate_oscillation) above oscillation [rad/s]. A bound of None (or 1, inf) is not
    judged, nor a figure the run does not have."""
    out = []
    share = metrics.get("saturation_fraction_tail")
    if share is not None and tail_saturation is not None and share > tail_saturation:
        out.append(f"time at an actuator limit over the tail {100 * share:.4g} % > {100 * tail_saturation:.3g} % "
                   "(success.tail_saturation)")
    osc = metrics.get("rate_oscillation_tail") or {}
    amp = osc.get("amplitude")
    if amp is not None and oscillation is not None and amp > oscillation:
        out.append(f"a sustained oscillation of the body rate over the tail, {amp:.3g} rad/s at {osc['frequency']:.3g}"
                   f" Hz about body {'xyz'[int(osc['axis'])]} > {oscillation:.3g} rad/s (success.oscillation)")
    return out


def _show(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3g}"

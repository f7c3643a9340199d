"""What a run identified: a verdict on the estimates beside the verdict on the tracking.

A run can track well and identify nothing (the lecture: the estimates converge to the truth only under
persistent excitation), and an arm's law can get a payload's mass right while its inertia estimate is no
body at all. Three things are said of every run that estimates parameters (the summary's "identification",
docs/METRICS.md "Identification"):

- each parameter's final relative error |θ̂_i − θ_i| / |θ_i| where the truth is known (θ_i = 0: relative to the
  largest |θ_j|), and whether it is identified: within IDENTIFIED of its truth;
- which parameters the reference did not excite over the run's tail: the regressor along the reference, sampled
  at SAMPLES times over the tail, gives the information matrix M = mean Yᵀ Y; normalised to a correlation matrix
  C = D^-1/2 M D^-1/2 (D = diag M, so the units drop out), an eigenvalue of C at most UNEXCITED is a direction
  the motion does not excite, and the parameters that weigh in it (|v_i| >= WEIGHT) are named; a parameter whose
  column is zero is not excited at all. excitation_index is C's smallest eigenvalue (0: some direction never
  excited, 1: orthogonal columns), as bench section 8 computes it;
- for every body whose ten standard parameters are estimated, whether the estimate is a possible body
  (report.metrics.body_identification: a positive-semidefinite pseudo-inertia, mass >= 0).

The regressor comes from the plant where it offers one (`regressor_rows(q, q̇, q̈)`: the manipulators, at the
desired motion) or from the law's model form (a ModelForm: ψ = [y_d^(n) when d is estimated, φ(x_d)]); with
neither (MRAC, the quadrotor's laws), the excitation is not said.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

IDENTIFIED = 0.05  # [-] a parameter within this relative error of its truth is identified
UNEXCITED = 1e-6  # [-] an eigenvalue of the normalised tail information matrix at most this: a direction not excited
WEIGHT = 0.3  # [-] a parameter whose component in such a direction is at least this is named as not excited
SAMPLES = 64  # reference samples over the tail


def relative_errors(names, estimate, truth) -> dict[str, float]:
    """{name: |θ̂_i − θ_i| / scale_i} with scale_i = |θ_i|, or, for θ_i = 0, the largest |θ_j| (NaN where every θ
    is 0 or a value is not finite). estimate, truth: (n_theta,)."""
    est, true = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    floor = float(np.max(np.abs(true))) if true.size else 0.0
    out = {}
    for name, e, t in zip(names, est, true, strict=True):
        scale = abs(t) if t != 0 else floor
        out[name] = float(abs(e - t) / scale) if scale > 0 and math.isfinite(e) and math.isfinite(t) else math.nan
    return out


def excitation(rows: np.ndarray, names) -> dict[str, Any]:
    """The excitation of the parameters `names` by regressor rows (N, m, n_theta) (m outputs per sample): the
    normalised information matrix's smallest eigenvalue ("index") and the parameters the rows do not excite
    ("not_excited", in `names`' order). See the module docstring."""
    Y = np.asarray(rows, dtype=float).reshape(-1, len(names))
    M = Y.T @ Y / max(1, len(Y))
    d = np.sqrt(np.clip(np.diag(M), 0.0, None))
    scale = float(d.max()) if d.size else 0.0
    zero = d <= 1e-12 * scale if scale > 0 else np.ones(len(names), dtype=bool)
    not_excited = set(np.flatnonzero(zero).tolist())
    index = 0.0 if zero.any() else math.nan
    live = np.flatnonzero(~zero)
    if live.size:
        C = M[np.ix_(live, live)] / np.outer(d[live], d[live])
        lam, vec = np.linalg.eigh(0.5 * (C + C.T))
        if not zero.any():
            index = float(max(0.0, lam[0]))
        for k in np.flatnonzero(lam <= UNEXCITED):
            not_excited.update(live[np.abs(vec[:, k]) >= WEIGHT].tolist())
    return {"index": index, "not_excited": [names[i] for i in sorted(not_excited)]}


def identification(names, estimate, truth, rows: np.ndarray | None = None) -> dict[str, Any]:
    """The summary's "identification" of one run: tolerance, relative_error {name: [-]}, identified and off (names
    within and beyond the tolerance, truth known), and with regressor rows (N, m, n_theta) along the tail the
    excitation: excitation_index and not_excited (names). See the module docstring."""
    rel = relative_errors(names, estimate, truth)
    out: dict[str, Any] = {"tolerance": IDENTIFIED, "relative_error": rel,
                           "identified": [n for n, r in rel.items() if r <= IDENTIFIED],
                           "off": [n for n, r in rel.items() if r > IDENTIFIED]}
    if rows is not None and len(rows):
        ex = excitation(rows, tuple(names))
        out["excitation_index"], out["not_excited"] = ex["index"], ex["not_excited"]
    return out


def tail_times(t0: float, t1: float) -> np.ndarray:
    """SAMPLES times [s] over the tail [t0, t1] of a run."""
    return np.linspace(t0, t1, SAMPLES)


def form_rows(form, ref_rows: np.ndarray) -> np.ndarray:
    """(N, 1, n_theta) the 1-DOF model form's regressor along the reference: ψ = [y_d^(n) (when the form estimates
    d), φ(x_d)], ref_rows (N, n+1) = [y_d, ..., y_d^(n)] (the law's parameters: d first, then p)."""
    n = form.order
    phi = np.array([np.asarray(form.phi(row[:n]), dtype=float) for row in ref_rows])
    psi = phi if form.d_name is None else np.column_stack([ref_rows[:, n], phi])
    return psi[:, None, :]

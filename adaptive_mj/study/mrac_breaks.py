"""The published break points of MRAC, measured (issue 21; docs/THEORY.md, "Rohrs' counterexample"
and "The delay threshold"): the frozen-gain stability limit of a loop u = k y + ..., and the onset
time of Rohrs' instability read from a trajectory. Pure functions over arrays and a Trajectory.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.trajectory import Trajectory


def _stable(num, den, k: float) -> bool:
    """Whether den(s) - k num(s) (the loop y = num/den u, u = k y) has every root in the open left half-plane."""
    poly = np.polysub(np.asarray(den, dtype=float), k * np.asarray(num, dtype=float))
    return bool(np.max(np.roots(poly).real) < 0.0)


def frozen_gain_limit(num, den, *, rel: float = 1e-12) -> float:
    """The most negative output-feedback gain k <= 0 that keeps y = num(s)/den(s) u, u = k y + (any r term)
    stable, by bisection on the roots of den - k num (den must be stable at k = 0). [units of u per y]"""
    if not _stable(num, den, 0.0):
        raise ValueError("the open loop must be stable at k = 0")
    lo = -1.0
    while _stable(num, den, lo):
        lo *= 2.0
        if lo < -1e12:
            return -math.inf
    hi = lo / 2.0  # stable at hi, unstable at lo
    while hi - lo > rel * abs(lo):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _stable(num, den, mid) else (mid, hi)
    return hi


def rohrs_onset(traj: Trajectory, limit: float, *, gain: str = "k_y") -> float | None:
    """The onset time [s]: the first logged t at which the adapted output gain k̂_y is below `limit`
    (the frozen-gain stability limit of the true plant): from then on the loop, were its gains frozen,
    would be unstable. None if it never is."""
    k = traj.theta_hat[:, traj.names.index(gain)]
    below = np.nonzero(k < limit)[0]
    return float(traj.t[below[0]]) if below.size else None


def phase_lag_deg(num, den, omega: float) -> float:
    """The phase of num(jω)/den(jω) [deg]: e.g. the unmodelled factor's lag at the command's frequency."""
    value = np.polyval(num, 1j * omega) / np.polyval(den, 1j * omega)
    return float(np.degrees(np.angle(value)))

"""Metrics and the run summary: pure functions of a Trajectory.

Every metric is defined, with its formula, in docs/METRICS.md.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.trajectory import Trajectory

TAIL_FRACTION = 0.25  # "tail" = the last 25% of the run's duration


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else math.nan


def tail_mask(traj: Trajectory, fraction: float = TAIL_FRACTION) -> np.ndarray:
    """(N,) rows with t >= t_0 + (1 - fraction) * (t_end - t_0), t_end = last row + dt."""
    if len(traj) == 0:
        return np.zeros(0, dtype=bool)
    dt = traj.meta.get("dt", 0.0) * traj.meta.get("log_every", 1)
    t0, t_end = traj.t[0], traj.t[-1] + dt
    return traj.t >= t0 + (1.0 - fraction) * (t_end - t0)


def metrics(traj: Trajectory) -> dict:
    """The metrics of one run (see docs/METRICS.md)."""
    e = traj.y_tilde
    tail = tail_mask(traj)
    dV = np.diff(traj.V)
    final_err = traj.theta_hat[-1] - traj.theta[-1] if len(traj) else np.full(len(traj.names), math.nan)
    out = {
        "rms_tracking_error": _rms(e),
        "rms_tracking_error_tail": _rms(e[tail]),
        "max_abs_tracking_error_tail": float(np.max(np.abs(e[tail]))) if tail.any() else math.nan,
        "control_rms": _rms(traj.u),
        "control_total_variation": float(np.sum(np.abs(np.diff(traj.u, axis=0)))),
        "rms_s_tail": _rms(traj.s[tail]),
        "param_error_final": {n: float(v) for n, v in zip(traj.names, final_err, strict=True)},
        "lyapunov_initial": float(traj.V[0]) if len(traj) else math.nan,
        "lyapunov_final": float(traj.V[-1]) if len(traj) else math.nan,
        "lyapunov_max_increase": float(max(0.0, dV.max())) if dV.size else 0.0,
    }
    if traj.joint_names:
        out.update(joint_metrics(traj))
    return out


def joint_metrics(traj: Trajectory) -> dict:
    """For m joints: tail RMS and max tracking error per joint [rad or m], the RMS of the
    error norm |q̃| over the tail, and the RMS torque per joint [N m or N]."""
    e = traj.joint_errors
    tail = tail_mask(traj)
    norm = np.linalg.norm(e, axis=1)
    u = np.asarray(traj.u).reshape(len(traj.t), max(1, len(traj.joint_names)))

    def per(f):
        return {j: f(i) for i, j in enumerate(traj.joint_names)}

    return {
        "rms_tracking_error_tail_per_joint": per(lambda i: _rms(e[tail, i])),
        "max_abs_tracking_error_tail_per_joint": per(
            lambda i: float(np.max(np.abs(e[tail, i]))) if tail.any() else math.nan),
        "rms_tracking_error_norm_tail": _rms(norm[tail]),
        "control_rms_per_joint": per(lambda i: _rms(u[:, i])),
    }


def summary(name: str, traj: Trajectory, *, steps: int | None = None) -> dict:
    """The summary object printed by `run --json` and `replay --json`.

    steps: physics steps run (defaults to the number of rows).
    duration: simulated time covered [s] = steps * dt.
    """
    steps = len(traj) if steps is None else steps
    dt = traj.meta.get("dt", 0.0)
    if len(traj):
        last = {
            "t": float(traj.t[-1]),
            "q": np.atleast_1d(traj.x[-1, 0]).astype(float).tolist(),
            "qd": np.atleast_1d(traj.qd[-1]).astype(float).tolist(),
            "theta_hat": {n: float(v) for n, v in zip(traj.names, traj.theta_hat[-1], strict=True)},
            "theta": {n: float(v) for n, v in zip(traj.names, traj.theta[-1], strict=True)},
        }
    else:
        last = {"t": 0.0, "q": [], "qd": [], "theta_hat": {}, "theta": {}}
    return {
        "scenario": name,
        "status": traj.status,
        "reason": traj.reason,
        "duration": steps * dt,
        "steps": steps,
        "metrics": metrics(traj),
        "final": last,
    }


def clean_json(obj):
    """NaN/inf -> None so the summary is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: clean_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_json(v) for v in obj]
    return obj

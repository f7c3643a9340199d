"""Metrics and the run summary: pure functions of a Trajectory.

Every metric is defined, with its formula, in docs/METRICS.md.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.laws import pseudo_inertia
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


def _row_rate(traj: Trajectory) -> float | None:
    """The rate of the trajectory's rows [Hz] (1/(dt · log_every)), or None where dt is not on record."""
    dt = traj.meta.get("dt", 0.0) * traj.meta.get("log_every", 1)
    return 1.0 / dt if dt > 0 else None


def metrics(traj: Trajectory) -> dict:
    """The metrics of one run (see docs/METRICS.md)."""
    e = traj.y_tilde
    tail = tail_mask(traj)
    with np.errstate(invalid="ignore", over="ignore"):  # a diverged run's inf rows: NaN figures, said by its status
        dV = np.diff(traj.V)
        du = np.abs(np.diff(traj.u, axis=0))
    final_err = traj.theta_hat[-1] - traj.theta[-1] if len(traj) else np.full(len(traj.names), math.nan)
    out = {
        "rms_tracking_error": _rms(e),
        "rms_tracking_error_tail": _rms(e[tail]),
        "max_abs_tracking_error_tail": float(np.max(np.abs(e[tail]))) if tail.any() else math.nan,
        "control_rms": _rms(traj.u),
        "control_total_variation": float(np.sum(du)),
        # the rate of the rows the total variation is summed over [Hz] (every physics step live; the log's rate
        # from a log): a lower bound of the control's where it moves faster than the rows
        "control_total_variation_rate_hz": _row_rate(traj),
        "rms_s_tail": _rms(traj.s[tail]),
        "param_error_final": {n: float(v) for n, v in zip(traj.names, final_err, strict=True)},
        "lyapunov_initial": float(traj.V[0]) if len(traj) else math.nan,
        "lyapunov_final": float(traj.V[-1]) if len(traj) else math.nan,
        "lyapunov_max_increase": float(max(0.0, dV.max())) if dV.size else 0.0,
    }
    if traj.joint_names:
        out.update(joint_metrics(traj))
        ident = body_identification(traj.names, traj.theta_hat[-1], traj.theta[-1]) if len(traj) else {}
        if ident and tail.any():
            spread = body_identification(traj.names, traj.theta_hat[tail], traj.theta[tail])
            for body, e in ident.items():  # the last sample, and the tail's mean [min, max] beside it
                e["tail"] = {k: _spread(v) for k, v in spread[body].items() if k not in ("com_undefined", "impossible")}
            out["identification"] = ident
    out.update(saturation_metrics(traj))
    osc = rate_oscillation(traj)
    if osc is not None:
        out["rate_oscillation_tail"] = osc
    return out


_INERTIA = ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
#: an estimated mass at most this fraction of the true one (the mass error reads -99.9 % or -100 %; <= 0 where
#: law.projection = "physical" stops it at 0) has no centre of mass: c = (m c) / m divides by (nearly) nothing,
#: which printed 8.45e+20 mm (m̂ = 1e-20 kg) or 1.8 km (m̂ = 1 g of 8.4 kg)
COM_MASS_FLOOR = 1e-3


def _spread(v: np.ndarray) -> dict:
    """{"mean", "min", "max"} of a figure over the tail's rows, ignoring NaN (an undefined centre of mass); NaN
    where no row has it."""
    v = np.asarray(v, dtype=float)
    ok = v[np.isfinite(v)]
    if ok.size == 0:
        return {"mean": math.nan, "min": math.nan, "max": math.nan}
    return {"mean": float(ok.mean()), "min": float(ok.min()), "max": float(ok.max())}


def body_identification(names, estimate, truth) -> dict:
    """For every body whose ten standard parameters ("<body>.m", ".mcx/.mcy/.mcz", ".Ixx" ... ".Izz",
    inertia about the body's origin) are estimated: the mass error [%], centre-of-mass error
    |ĉ - c| with c = (m c) / m [mm], and inertia error ||Î - I||_F [kg m²], also relative to ||I||_F.
    Where the estimated mass m̂ is <= COM_MASS_FLOOR |m| (0 under a projection that stops it there), ĉ is
    undefined: com_error_mm is NaN and com_undefined says why (otherwise "").
    estimate, truth: (n_theta,) one row (floats out), or (N, n_theta) rows ((N,) arrays out; com_undefined the
    last row's)."""
    est_all, true_all = np.asarray(estimate, dtype=float), np.asarray(truth, dtype=float)
    rows = est_all.ndim == 2
    est_all, true_all = np.atleast_2d(est_all), np.atleast_2d(true_all)
    if est_all.shape[0] == 0:  # no rows (a tail of a run too short to have one): nothing to say
        return {}
    index = {n: i for i, n in enumerate(names)}
    out = {}
    for name in names:
        if not name.endswith(".m"):
            continue
        body = name[:-2]
        keys = [f"{body}.{k}" for k in ("m", "mcx", "mcy", "mcz", *_INERTIA)]
        if not all(k in index for k in keys):
            continue
        cols = [index[k] for k in keys]
        est, true = est_all[:, cols], true_all[:, cols]

        def inertia(v):
            xx, xy, yy, xz, yz, zz = (v[:, k] for k in range(4, 10))
            return np.stack([np.stack([xx, xy, xz], -1), np.stack([xy, yy, yz], -1), np.stack([xz, yz, zz], -1)], -2)

        defined = (true[:, 0] != 0) & (est[:, 0] > COM_MASS_FLOOR * np.abs(true[:, 0]))
        with np.errstate(divide="ignore", invalid="ignore"):
            com_err = np.where(defined, np.linalg.norm(est[:, 1:4] / est[:, :1] - true[:, 1:4] / true[:, :1],
                                                       axis=1) * 1e3, math.nan)
            mass = np.where(true[:, 0] != 0, 100 * (est[:, 0] - true[:, 0]) / true[:, 0], math.nan)
            i_err = np.linalg.norm(inertia(est) - inertia(true), axis=(1, 2))
            i_norm = np.linalg.norm(inertia(true), axis=(1, 2))
            i_rel = np.where(i_norm != 0, i_err / i_norm, math.nan)
        last_est, last_true = est[-1, 0], true[-1, 0]
        undefined = "" if defined[-1] else (f"undefined (estimated mass {last_est:.3g} kg)" if last_true != 0
                                            else "undefined (true mass 0 kg)")
        finite = np.all(np.isfinite(est), axis=1)  # a diverged run's last rows: no eigenvalues (its status says why)
        eig = np.full((len(est), 4), math.nan)
        if finite.any():  # (N, 4) ascending: the estimate's pseudo-inertia
            eig[finite] = pseudo_inertia.eigenvalues(est[finite], [0])[..., 0, :]
        with np.errstate(invalid="ignore"):
            possible = pseudo_inertia.is_physical(eig[:, 0], np.sum(np.abs(eig), axis=1)) | ~finite
        fig = {"mass_error_percent": mass, "com_error_mm": com_err, "inertia_error": i_err,
               "inertia_error_relative": i_rel, "pseudo_inertia_min_eigenvalue": eig[:, 0],
               "not_physical": (~possible).astype(float)}
        out[body] = {k: (v if rows else float(v[0])) for k, v in fig.items()}
        out[body]["com_undefined"] = undefined
        out[body]["impossible"] = _impossible(est[-1, 0], float(eig[-1, 0]), bool(possible[-1]))
    return out


def _impossible(mass: float, lowest: float, possible: bool) -> str:
    """Why a body's estimate (its last row) is no body at all, or "" (a possible one): a negative mass, or a
    pseudo-inertia that is not positive semidefinite (no distribution of mass has those ten parameters, e.g. a
    principal moment above the sum of the other two)."""
    if mass < 0:
        return f"a negative mass ({mass:.3g} kg)"
    if not possible:
        return (f"its pseudo-inertia is not positive semidefinite (smallest eigenvalue {lowest:.3g}): no distribution "
                "of mass has these parameters")
    return ""


def _at_limits(traj: Trajectory) -> np.ndarray | None:
    """(N, m) whether each actuator's applied control sits at its limit in each row (within 1e-9 relative), from
    traj.meta["ctrl_range"] = (lo, hi) in control units; None when the run has no limits on record (logs before
    format 5)."""
    rng = traj.meta.get("ctrl_range")
    if rng is None or len(traj) == 0:
        return None
    lo, hi = (np.atleast_1d(np.asarray(b, dtype=float)) for b in rng)
    u = np.asarray(traj.u, dtype=float).reshape(len(traj.t), -1)
    tol_lo, tol_hi = 1e-9 * np.maximum(1.0, np.abs(lo)), 1e-9 * np.maximum(1.0, np.abs(hi))
    return (u <= lo + tol_lo) | (u >= hi - tol_hi)


def saturation_fraction(traj: Trajectory) -> np.ndarray | None:
    """(m,) fraction of the rows in which each actuator's applied control sits at its limit (_at_limits); None
    when the run has no limits on record (logs before format 5)."""
    at = _at_limits(traj)
    return None if at is None else at.mean(axis=0)


def saturated_rows(traj: Trajectory) -> np.ndarray | None:
    """(N,) whether any actuator's applied control sits at its limit in each row (_at_limits), None without limits
    on record."""
    at = _at_limits(traj)
    return None if at is None else np.any(at, axis=1)


def saturation_metrics(traj: Trajectory) -> dict:
    """saturation_fraction: the largest fraction of the run any actuator spent at its limit;
    for m joints also per joint; saturation_fraction_tail: the fraction of the tail's rows (tail_mask) in which any
    actuator sits at a limit (success.tail_saturation's figure). Empty without limits on record."""
    frac = saturation_fraction(traj)
    if frac is None:
        return {}
    out: dict = {"saturation_fraction": float(frac.max())}
    if traj.joint_names:
        out["saturation_fraction_per_joint"] = {j: float(f) for j, f in zip(traj.actuators, frac, strict=True)}
    rows, tail = saturated_rows(traj), tail_mask(traj)
    if rows is not None and tail.any():
        out["saturation_fraction_tail"] = float(rows[tail].mean())
    return out


OSCILLATION_MIN_HZ = 1.0  # [Hz] spectral lines below this are the manoeuvre's, not an oscillation's
OSCILLATION_MIN_ROWS = 16  # a tail with fewer rows has no spectrum to speak of


def rate_oscillation(traj: Trajectory) -> dict | None:
    """The body rate's sustained oscillation over the tail (success.oscillation's figure), for a run whose state
    has a row named "omega" (traj.meta["state_names"]: a quadrotor's Ω (3,) [rad/s], body frame): per axis, the
    tail's samples with their least-squares line removed, Hann-windowed, and their largest spectral line at or
    above OSCILLATION_MIN_HZ read as a sinusoid's amplitude, A = 2 |X_k| / Σ w. Returns {"amplitude" [rad/s],
    "frequency" [Hz], "axis" (0, 1, 2: body x, y, z)} of the axis with the largest A; None without such a row,
    with fewer than OSCILLATION_MIN_ROWS tail rows or a non-finite tail. A steady spin (a constant Ω_z) and a
    drift (a ramp) are removed by the line; the figure-eight's own rates (0.16 and 0.32 Hz) lie below the band;
    a limit cycle of the attitude loop (near its crossover, 7.5 Hz on the bundled vehicle) does not."""
    names = tuple(traj.meta.get("state_names") or ())
    if "omega" not in names or len(traj) == 0:
        return None
    tail = tail_mask(traj)
    t = np.asarray(traj.t[tail], dtype=float)
    w = np.asarray(traj.x[tail, names.index("omega")], dtype=float).reshape(len(t), -1)
    if len(t) < OSCILLATION_MIN_ROWS or not np.all(np.isfinite(w)):
        return None
    dt = traj.meta.get("dt", 0.0) * traj.meta.get("log_every", 1)
    if not dt > 0:
        return None
    tc = t - t.mean()
    slope = (tc @ (w - w.mean(axis=0))) / (tc @ tc)
    resid = w - w.mean(axis=0) - np.outer(tc, slope)
    win = np.hanning(len(t))
    spec = np.abs(np.fft.rfft(resid * win[:, None], axis=0)) * 2.0 / win.sum()
    freq = np.fft.rfftfreq(len(t), dt)
    band = freq >= OSCILLATION_MIN_HZ
    if not band.any():
        return None
    sub = spec[band]
    k, axis = np.unravel_index(int(np.argmax(sub)), sub.shape)
    return {"amplitude": float(sub[k, axis]), "frequency": float(freq[band][k]), "axis": int(axis)}


def joint_metrics(traj: Trajectory) -> dict:
    """For m joints: tail RMS and max tracking error per joint [rad or m], the RMS of the
    error norm |q̃| over the tail, and the RMS torque per joint [N m or N]."""
    e = traj.joint_errors
    tail = tail_mask(traj)
    norm = np.linalg.norm(e, axis=1)
    u = np.asarray(traj.u).reshape(len(traj.t), max(1, len(traj.actuators)))

    def per(f, names=traj.joint_names):
        return {j: f(i) for i, j in enumerate(names)}

    return {
        "rms_tracking_error_tail_per_joint": per(lambda i: _rms(e[tail, i])),
        "max_abs_tracking_error_tail_per_joint": per(
            lambda i: float(np.max(np.abs(e[tail, i]))) if tail.any() else math.nan),
        "rms_tracking_error_norm_tail": _rms(norm[tail]),
        "control_rms_per_joint": per(lambda i: _rms(u[:, i]), traj.actuators),
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
    m = metrics(traj)
    impossible = [f"the estimate of body {body} at the end is no possible body: {e['impossible']}"
                  for body, e in (m.get("identification") or {}).items() if e.get("impossible")]
    return {
        "scenario": name,
        "status": traj.status,
        "reason": traj.reason,
        "duration": steps * dt,
        "steps": steps,
        "metrics": m,
        "final": last,
        "warnings": [*traj.meta.get("warnings", ()), *joint_limit_warnings(traj), *impossible],
    }


def joint_limit_warnings(traj: Trajectory) -> list[str]:
    """One line per joint whose position reached its range's end (traj.meta["joint_limits"], (m, 2)
    [lo, hi], ±inf where unlimited): when first, and by how much at most past it."""
    limits = traj.meta.get("joint_limits")
    if limits is None or len(traj) == 0:
        return []
    q = np.asarray(traj.x[:, 0], dtype=float).reshape(len(traj.t), -1)
    names = traj.joint_names or ("the joint",)
    out = []
    for j, (lo, hi) in enumerate(np.asarray(limits, dtype=float).reshape(-1, 2)):
        at = (q[:, j] <= lo) | (q[:, j] >= hi)
        if at.any():
            i = int(np.argmax(at))
            past = float(max(lo - q[:, j].min(), q[:, j].max() - hi, 0.0))
            out.append(f"{names[j]} reached its limit [{lo:.4g}, {hi:.4g}] at t={traj.t[i]:.6g} s "
                       f"(at most {past:.3g} past it; {100 * at.mean():.3g} % of the run)")
    return out


def clean_json(obj):
    """NaN/inf -> None so the summary is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: clean_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_json(v) for v in obj]
    return obj

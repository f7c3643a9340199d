"""Analyses the bench reports beyond the summary metrics: pure functions of a
full-rate Trajectory and the run's Setup (its law and scenario events).
Each is defined, with its formula, in docs/METRICS.md.
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.laws.protocol import JointFeedback, Law, SurfaceFeedback
from adaptive_mj.report.metrics import tail_mask
from adaptive_mj.trajectory import Status, Trajectory

RELATIVE_PARAM_TOLERANCE = 0.10  # "converged": every |θ̂_i − θ_i| <= 10 % of |θ_i| (or of max|θ|)


def desired_regressor(traj: Trajectory, form) -> np.ndarray:
    """(N, n_theta) rows [y_d^(n), phi(x_d)] (d column only when d is unknown), along the reference."""
    n = form.order
    xd = traj.ref[:, :n]
    phi = np.array([form.phi(row) for row in xd])
    if form.d_name is None:
        return phi
    return np.column_stack([traj.ref[:, n], phi])


def excitation(traj: Trajectory, form, *, window: float | None = None) -> float:
    """Excitation index: lambda_min of the normalised information matrix of the desired regressor.

    M = (1/T) * integral over the last `window` seconds (default: the whole run) of psi psi^T dt,
    normalised to a correlation matrix C = D^-1/2 M D^-1/2 (D = diag M), so the index lies in
    [0, 1] whatever the units: 0 = some parameter direction is never excited, 1 = orthogonal columns.
    """
    rows = np.ones(len(traj), dtype=bool) if window is None else traj.t >= traj.t[-1] - window
    psi = desired_regressor(traj, form)[rows]
    M = psi.T @ psi / max(1, len(psi))
    dg = np.sqrt(np.diag(M))
    if np.any(dg == 0):
        return 0.0
    C = M / np.outer(dg, dg)
    return float(max(0.0, np.linalg.eigvalsh(C)[0]))


def excitation_index(traj: Trajectory, setup) -> float:
    """`excitation` over the whole run, for the run's law form."""
    return excitation(traj, setup.law.form)


def excitation_rate(traj: Trajectory, setup) -> float:
    """Slowest predicted convergence rate of the estimates [1/s]:

        rho = lambda_min(Gamma^-1/2 M Gamma^-1/2) / k,   M = mean over the run of psi psi^T

    (psi: desired regressor, Gamma = diag(gamma)). It follows from the slow-
    adaptation approximation s ≈ psi^T θ̃ / k of d s' = -k s + psi^T θ̃, which turns
    gamma θ̃' = -psi s into θ̃' ≈ -Gamma^-1 psi psi^T θ̃ / k. exp(-rho T) estimates the
    fraction of the initial parameter error left after T seconds.
    """
    law = setup.law
    psi = desired_regressor(traj, law.form)
    M = psi.T @ psi / max(1, len(psi))
    g = np.sqrt(np.asarray(law.gamma, dtype=float))
    return float(max(0.0, np.linalg.eigvalsh(M / np.outer(g, g))[0]) / law.k)


def relative_param_error(traj: Trajectory) -> np.ndarray:
    """(N,) max_i |θ̂_i − θ_i| / scale_i, scale_i = |θ_i| or, for θ_i = 0, max_j |θ_j|."""
    scale = np.abs(traj.theta)
    floor = np.max(scale, axis=1, keepdims=True)
    scale = np.where(scale > 0, scale, floor)
    return np.max(np.abs(traj.theta_hat - traj.theta) / scale, axis=1)


def drift_rate(traj: Trajectory, setup=None, *, start_fraction: float = 0.2) -> float:
    """Growth of ||(θ̂(t) − θ̂(t0)) / |θ(t0)| || per 100 s (dimensionless fraction per 100 s).

    t0 = t_start + start_fraction * run length (after the initial transient); the
    rate is the least-squares slope of the norm over [t0, t_end], times 100.
    """
    t = traj.t
    t0 = t[0] + start_fraction * (t[-1] - t[0])
    rows = t >= t0
    i0 = int(np.argmax(rows))
    scale = np.abs(traj.theta[i0])
    scale = np.where(scale > 0, scale, np.max(scale))
    dev = np.linalg.norm((traj.theta_hat[rows] - traj.theta_hat[i0]) / scale, axis=1)
    slope = np.polyfit(t[rows] - t0, dev, 1)[0]
    return float(slope * 100.0)


def estimate_drift(traj: Trajectory, setup=None, *, start_fraction: float = 0.2) -> float:
    """Growth of ‖θ̂(t) − θ̂(t0)‖ / ‖θ(t0)‖ per 100 s (dimensionless fraction per 100 s): drift_rate's slope, of the
    estimates' change relative to the whole parameter vector rather than to each parameter, so that a parameter
    near zero (an arm's small products of inertia) does not blow the figure up. The scorecard's hold task reads it.
    """
    t = traj.t
    t0 = t[0] + start_fraction * (t[-1] - t[0])
    rows = t >= t0
    i0 = int(np.argmax(rows))
    scale = float(np.linalg.norm(traj.theta[i0]))
    dev = np.linalg.norm(traj.theta_hat[rows] - traj.theta_hat[i0], axis=1) / (scale if scale > 0 else 1.0)
    slope = np.polyfit(t[rows] - t0, dev, 1)[0]
    return float(slope * 100.0)


def first_event_time(setup) -> float | None:
    return setup.events[0].t if setup is not None and setup.events else None


def settle_time(t: np.ndarray, ok: np.ndarray, t_from: float) -> float | None:
    """Time after t_from from which `ok` holds to the end of the run (None: it never settles)."""
    rows = t >= t_from
    tt, good = t[rows], ok[rows]
    if tt.size == 0 or not good[-1]:
        return None
    bad = np.nonzero(~good)[0]
    return 0.0 if bad.size == 0 else float(tt[bad[-1] + 1] - t_from)


SWAP_THRESHOLD = 0.005  # rad: |ỹ| below which the arm counts as recovered after a payload swap


def swap_response(traj: Trajectory, setup) -> dict:
    """After the first event (payload swap): peak |ỹ|, recovery time (|ỹ| stays < SWAP_THRESHOLD),
    re-convergence time: every parameter the event changed stays within 10 % of its new value."""
    t_e = first_event_time(setup)
    if t_e is None:
        return {}
    after = traj.t >= t_e
    e = np.abs(traj.y_tilde)
    i_e = int(np.argmax(after))
    changed = traj.theta[i_e] != traj.theta[max(0, i_e - 1)]
    rel = np.abs(traj.theta_hat - traj.theta)[:, changed] / np.abs(traj.theta[:, changed])
    ok = np.all(rel <= RELATIVE_PARAM_TOLERANCE, axis=1) if changed.any() else np.ones(len(traj), dtype=bool)
    neg = traj.theta_hat[:, 0] < 0.0  # a negative leading coefficient (Ĵ or d̂): unphysical
    return {
        "event_time": t_e,
        "peak_error_after": float(e[after].max()) if after.any() else math.nan,
        "peak_time_after": float(traj.t[after][np.argmax(e[after])] - t_e) if after.any() else math.nan,
        "estimate_min": {n: float(v) for n, v in zip(traj.names, traj.theta_hat.min(axis=0), strict=True)},
        "estimate_min_time": {n: float(traj.t[i])
                              for n, i in zip(traj.names, traj.theta_hat.argmin(axis=0), strict=True)},
        "leading_negative_seconds": float(np.sum(neg) * traj.meta["dt"]),
        "recovery_time": settle_time(traj.t, e < SWAP_THRESHOLD, t_e),
        "reconvergence_time": settle_time(traj.t, ok, t_e),
        "changed": [n for n, c in zip(traj.names, changed, strict=True) if c],
        "threshold": SWAP_THRESHOLD,
    }


CHANGE_WINDOW = 0.01  # s: the envelope's window in change_response


def change_response(traj: Trajectory, setup) -> dict:
    """After the first event (a parameter change): the peak of the tracking error (|ỹ| [m or rad], or ‖q̃‖/√m on
    m joints: the RMS over the joints, the tail error's scale) and its envelope, the maximum over each
    CHANGE_WINDOW after the event, for a caller to read a recovery time against its own bound
    (adaptive_mj.study.score). Empty without an event."""
    t_e = first_event_time(setup)
    if t_e is None:
        return {}
    y = traj.y_tilde
    # on m joints ‖q̃‖/√m: the scale of the tail RMS error (its RMS over the joints), so one bound judges both
    e = np.abs(y) if y.ndim == 1 else np.linalg.norm(y, axis=1) / math.sqrt(y.shape[1])
    after = traj.t >= t_e
    if not after.any():
        return {}
    idx = np.floor((traj.t[after] - t_e) / CHANGE_WINDOW + 1e-9).astype(int)
    env = np.zeros(int(idx[-1]) + 1)
    np.maximum.at(env, idx, e[after])
    return {"event_time": float(t_e), "peak_error_after": float(e[after].max()), "window": CHANGE_WINDOW,
            "envelope": env.tolist()}


def lyapunov_check(traj: Trajectory, setup) -> dict:
    """V non-increasing and V' = -k s² (ideal case): the largest one-step increase of V,
    max |ΔV/Δt + k mean(s²)| relative to max k s² (midpoint rule, as the discrete V' check),
    and mean |V'| over the first and the last 10 % of the run (V' -> 0, Barbalat)."""
    dt = traj.meta["dt"]
    dV = np.diff(traj.V)
    feedback = setup.law.feedback()
    k = feedback.k if isinstance(feedback, SurfaceFeedback) else math.nan
    ks2 = k * 0.5 * (traj.s[:-1] ** 2 + traj.s[1:] ** 2)
    scale = float(np.max(k * traj.s**2)) or 1.0
    return {
        "max_increase": float(max(0.0, dV.max())) if dV.size else 0.0,
        "V0": float(traj.V[0]),
        "V_end": float(traj.V[-1]),
        "vdot_residual_rel": float(np.max(np.abs(dV / dt + ks2)) / scale) if dV.size else 0.0,
        "dissipated": float(np.sum(ks2) * dt),
        "vdot_start": float(np.mean(np.abs(dV[: max(1, dV.size // 10)]))) / dt if dV.size else 0.0,
        "vdot_tail": float(np.mean(np.abs(dV[-max(1, dV.size // 10):]))) / dt if dV.size else 0.0,
        **_unmodelled_drag_power(traj, setup, k),
    }


def _unmodelled_drag_power(traj: Trajectory, setup, k: float) -> dict:
    """With MuJoCo's viscous drag −c_v y' acting on the vehicle but absent from the regressor (the plant's
    unmodelled_drag(); nothing is returned for a plant that has none),
    d ṡ gains + c_v y' and V' = −k s² + c_v y' s exactly: V grows where c_v y' s > k s². Returns
    c_v [N s/m], the total growth of V measured (Σ max(ΔV, 0)) and predicted
    (∫ max(0, c_v y' s − k s²) dt), and max |ΔV/Δt − (−k s² + c_v y' s)| / max k s²."""
    cv = setup.plant.unmodelled_drag()
    if cv is None:
        return {}
    dt = traj.meta["dt"]
    s, yd = traj.s, traj.x[:, 1]
    p = -k * s ** 2 + cv * yd * s  # the predicted V'
    p_mid = 0.5 * (p[:-1] + p[1:])
    dV = np.diff(traj.V)
    scale = float(np.max(k * s ** 2)) or 1.0
    return {"drag_cv": cv, "growth_measured": float(np.sum(np.maximum(dV, 0.0))),
            "growth_predicted": float(np.sum(np.maximum(p_mid, 0.0)) * dt),
            "vdot_residual_rel_with_drag": float(np.max(np.abs(dV / dt - p_mid)) / scale) if dV.size else 0.0}


def manipulator_response(traj: Trajectory, setup) -> dict:
    """A run of m joints: per-joint tail RMS error [rad], the Lyapunov check (largest one-step
    increase of V relative to V(0), and max |ΔV/Δt + sᵀK_D s| relative to max sᵀK_D s, midpoint
    rule), after the first event the peak error max_j |q̃_j| and the recovery time (every joint
    stays below SWAP_THRESHOLD), and for a payload body among the unknowns the identification
    errors over time: mass (relative), centre of mass m·c/m [m] and inertia [kg m²]."""
    from adaptive_mj.report.metrics import tail_mask

    e = traj.joint_errors
    tail = tail_mask(traj)
    out: dict = {"tail_rms_per_joint": np.sqrt(np.mean(e[tail] ** 2, axis=0)).tolist()}
    dt = traj.meta["dt"]
    law: Law = setup.law
    feedback = law.feedback()
    kd = np.asarray(feedback.kd if isinstance(feedback, JointFeedback) else np.zeros(e.shape[1]))
    s = np.asarray(traj.s).reshape(e.shape)
    sks = np.sum(kd * s * s, axis=1)
    dV = np.diff(traj.V)
    t_e = first_event_time(setup)
    events = traj.meta.get("events") or []
    t_applied = events[0][0] if events else t_e  # the step the event was applied at (t_k >= t_e - dt/2)
    keep = np.ones(len(dV), dtype=bool) if t_applied is None else \
        (traj.t[1:] < t_applied) | (traj.t[:-1] >= t_applied)
    scale = float(np.max(sks)) or 1.0
    out["lyapunov_max_increase_rel"] = float(max(0.0, dV[keep].max()) / traj.V[0]) if dV.size and traj.V[0] else 0.0
    out["lyapunov_rate_error_rel"] = float(np.max(np.abs(dV / dt + 0.5 * (sks[:-1] + sks[1:]))[keep]) / scale) \
        if dV.size and law.adapt else None
    if t_e is not None:
        after = traj.t >= t_e
        worst = np.abs(e).max(axis=1)
        out["event_time"] = t_e
        out["peak_error_after"] = float(worst[after].max()) if after.any() else math.nan
        out["recovery_time"] = settle_time(traj.t, worst < SWAP_THRESHOLD, t_e)
    names = list(traj.names)
    if "payload/body.m" in names:
        i = names.index("payload/body.m")
        m_hat, m = traj.theta_hat[:, i], traj.theta[:, i]
        c_hat = traj.theta_hat[:, i + 1:i + 4] / np.where(np.abs(m_hat) > 1e-9, m_hat, np.nan)[:, None]
        c = traj.theta[:, i + 1:i + 4] / m[:, None]
        out["payload"] = {
            "t": traj.t.tolist()[::max(1, len(traj.t) // 400)],
            "mass_rel_error": (np.abs(m_hat - m) / m).tolist()[::max(1, len(traj.t) // 400)],
            "com_error": np.linalg.norm(c_hat - c, axis=1).tolist()[::max(1, len(traj.t) // 400)],
            "inertia_error": np.abs(traj.theta_hat[:, i + 4:i + 10] - traj.theta[:, i + 4:i + 10]).max(axis=1)
            .tolist()[::max(1, len(traj.t) // 400)],
            "final": {"mass": float(m_hat[-1]), "mass_true": float(m[-1]),
                      "mass_rel_error": float(abs(m_hat[-1] - m[-1]) / m[-1]),
                      "com": c_hat[-1].tolist(), "com_true": c[-1].tolist(),
                      "com_error": float(np.linalg.norm(c_hat[-1] - c[-1])),
                      "inertia": traj.theta_hat[-1, i + 4:i + 10].tolist(),
                      "inertia_true": traj.theta[-1, i + 4:i + 10].tolist(),
                      "inertia_error": float(np.abs(traj.theta_hat[-1, i + 4:i + 10]
                                                    - traj.theta[-1, i + 4:i + 10]).max())},
        }
    return out


def windowed_rms(t: np.ndarray, e: np.ndarray, window: float) -> np.ndarray:
    """(N,) RMS of e over the trailing `window` seconds at each row (NaN until a window is full)."""
    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    n = max(1, int(round(window / dt)))
    c = np.concatenate(([0.0], np.cumsum(np.asarray(e, dtype=float) ** 2)))
    out = np.full(len(e), np.nan)
    if len(e) >= n:
        out[n - 1:] = np.sqrt((c[n:] - c[:-n]) / n)
    return out


def critical_leading_estimate(d: float, k: float, lam: float, delay: float) -> float:
    """d̂ at which the n = 2 sliding loop on the plant d ÿ = u, with u delayed by `delay` [s],
    loses its last degree of phase margin (linearised at a set-point, drag slope 0 there).

    With a set-point the law is u = d̂ λ ỹ' + k (ỹ' + λ ỹ) + (terms that cancel the plant's):
    a PD with K_v = k + d̂ λ and K_p = k λ. The loop L(jω) = (K_p + jω K_v) e^(−jωT) / (−d ω²)
    crosses |L| = 1 at ω_c and has phase margin atan(ω_c K_v / K_p) − ω_c T; the returned d̂
    makes that margin 0 (found by bisection). Returns inf if the margin never reaches 0."""
    from scipy.optimize import brentq

    def margin(dh: float) -> float:
        kv, kp = k + dh * lam, k * lam
        w = brentq(lambda w: math.hypot(kp, w * kv) - d * w * w, 1e-9, 1e9)
        return math.atan2(w * kv, kp) - w * delay

    if delay <= 0 or margin(d * 1e6) > 0:
        return math.inf
    lo = 0.0 if margin(0.0) > 0 else None
    if lo is None:
        return 0.0
    return float(brentq(margin, lo, d * 1e6))


FAILURE_WINDOW = 1.0  # s: the RMS of ỹ is taken over this trailing window to call a failure


def sudden_failure(traj: Trajectory, setup) -> dict:
    """When a drifting loop fails: the first time the thrust saturates (the loop has left its
    linear regime: bursting), and the first time the RMS of ỹ over the last FAILURE_WINDOW
    seconds exceeds the noise std σ_y (the loop's error is as large as what it measures).
    Also d̂/d at those times and at the end, its maximum, and the predicted critical d̂/d
    from the delay margin (critical_leading_estimate)."""
    t, e = traj.t, traj.y_tilde
    ratio = traj.theta_hat[:, 0] / traj.theta[:, 0]
    bound = float(setup.noise_std[0]) if setup.noise_std is not None and setup.noise_std[0] > 0 else 1e-3
    rms = windowed_rms(t, e, FAILURE_WINDOW)
    fail = np.nonzero(rms > bound)[0]
    t_fail = float(t[fail[0]]) if len(fail) else None
    lo, hi = setup.plant.ctrl_range if setup.plant.ctrl_range is not None else (-math.inf, math.inf)
    sat = np.nonzero((traj.u <= lo) | (traj.u >= hi))[0]
    t_sat = float(t[sat[0]]) if len(sat) else None
    feedback = setup.law.feedback()
    d = float(traj.theta[0, 0])
    delay = traj.meta.get("control_delay", 0) * traj.meta["dt"]
    crit = critical_leading_estimate(d, feedback.k, feedback.lam, delay) / d \
        if isinstance(feedback, SurfaceFeedback) and feedback.lam is not None else math.nan
    if traj.status == Status.DIVERGED and t_fail is None:
        t_fail = float(t[-1])
    return {"t_fail": t_fail, "t_saturation": t_sat, "bound": bound,
            "ratio_at_saturation": float(ratio[sat[0]]) if len(sat) else None,
            "ratio_max": float(np.max(ratio)), "ratio_final": float(ratio[-1]), "critical_ratio": crit,
            "t_critical": float(t[np.argmax(ratio > crit)]) if np.any(ratio > crit) else None,
            "rms_before": float(np.sqrt(np.mean(e[t < (t_sat if t_sat is not None else t[-1] + 1)] ** 2))),
            "rms_tail": float(np.sqrt(np.mean(e[tail_mask(traj)] ** 2)))}  # the tail of every metric


CHATTER_CUTOFF_HZ = 5.0  # Hz: u above this counts as chattering (the references are below 1 Hz)
CHATTER_WINDOW = 0.5  # s: the stretch of u shown at every physics step, where it chatters most


def lowpass_zero_phase(u: np.ndarray, dt: float, cutoff_hz: float) -> np.ndarray:
    """A first-order low-pass run forwards then backwards (no phase lag), cut-off in Hz."""
    a = math.exp(-2.0 * math.pi * cutoff_hz * dt)

    def once(x):
        y = np.empty_like(x)
        acc = x[0]
        for i, v in enumerate(x):
            acc = a * acc + (1.0 - a) * v
            y[i] = acc
        return y

    u = np.asarray(u, dtype=float)
    return once(once(u)[::-1])[::-1]


def chattering(traj: Trajectory, setup=None) -> dict:
    """Chattering as the high-frequency part of u, at the full physics rate:
    total variation of u − lowpass(u) with a zero-phase first-order low-pass at
    CHATTER_CUTOFF_HZ, over the run and per second [units of u, and per s]; plus the total
    variation of u itself and of its low-passed part (feed-forward + smooth feedback)."""
    u = np.asarray(traj.u, dtype=float).reshape(len(traj.t), -1)[:, 0]
    dt = traj.meta["dt"]
    slow = lowpass_zero_phase(u, dt, CHATTER_CUTOFF_HZ)
    fast = u - slow
    T = max(dt, float(traj.t[-1] - traj.t[0]))
    steps = np.abs(np.diff(fast))
    tv_fast = float(np.sum(steps))
    # the CHATTER_WINDOW s where the high-frequency part moves most (the last ones when u never chatters)
    n = min(len(u), max(2, round(CHATTER_WINDOW / dt)))
    activity = np.convolve(steps, np.ones(n - 1), mode="valid") if n >= 2 else np.zeros(1)
    start = int(len(activity) - 1 - np.argmax(activity[::-1]))  # the latest of equally active windows
    window = slice(start, start + n)
    return {"cutoff_hz": CHATTER_CUTOFF_HZ, "tv_high_frequency": tv_fast, "tv_high_frequency_per_s": tv_fast / T,
            "tv_total": float(np.sum(np.abs(np.diff(u)))), "tv_low_frequency": float(np.sum(np.abs(np.diff(slow)))),
            "window_t": traj.t[window].tolist(), "window_u": u[window].tolist()}


def flight_metrics(traj: Trajectory, setup) -> dict:
    """A quadrotor run's figures (adaptive_mj.plants.quadrotor; AdaptiveQuadBench's): the largest position error
    ‖p_d − p‖ over the whole run [m] (its success criterion), its RMS over the run and over the tail [m], the largest
    heading error |ψ| [deg] (the references hold ψ_d = 0; ψ = atan2(R₂₁, R₁₁)), and the fraction of steps with some
    rotor at a thrust limit."""
    from adaptive_mj.laws.flight import rotation
    from adaptive_mj.report.metrics import tail_mask

    e = np.linalg.norm(traj.y_tilde, axis=1)
    if not len(e):
        return {}
    heading = max(abs(math.degrees(math.atan2(R[1, 0], R[0, 0]))) for R in (rotation(phi) for phi in traj.x[::10, 2]))
    rng = traj.meta.get("ctrl_range")
    sat = None
    if rng is not None:
        lo, hi = (np.asarray(b, dtype=float) for b in rng)
        u = np.asarray(traj.u, dtype=float)
        sat = float(np.mean(np.any((u <= lo + 1e-12) | (u >= hi - 1e-9 * np.maximum(1.0, np.abs(hi))), axis=1)))
    tail = tail_mask(traj)
    return {"max_error": float(e.max()), "rms_error": float(np.sqrt(np.mean(e**2))),
            "tail_rms_error": float(np.sqrt(np.mean(e[tail] ** 2))) if tail.any() else math.nan,
            "max_heading_deg": float(heading), "saturation_any": sat}


ONSET_MULTIPLES = (5.0, 25.0)  # the precursors: max_j |q̃_j| past these multiples of its baseline
SUDDEN_WINDOW = 5.0  # [s] a failure is "sudden" only when its precursors come within this long before the bound


def failure_onset(traj: Trajectory, bound: float, baseline_until: float) -> dict:
    """When a failing run's precursors came (docs/METRICS.md, "Failure onsets"): e(t) = max_j |q̃_j(t)| (|ỹ| on
    one axis); baseline = its median over t ≤ baseline_until [s]; the first time any actuator sat at its limit
    (traj.meta["ctrl_range"]), the first crossings of each ONSET_MULTIPLES × baseline, and of `bound` (the
    failure); sudden: every precursor within SUDDEN_WINDOW s before the bound's crossing (None: no failure)."""
    e = np.abs(np.asarray(traj.y_tilde, dtype=float).reshape(len(traj.t), -1)).max(axis=1)
    early = traj.t <= baseline_until
    baseline = float(np.median(e[early])) if early.any() else math.nan

    def first(mask: np.ndarray) -> float | None:
        idx = np.nonzero(mask)[0]
        return float(traj.t[idx[0]]) if len(idx) else None

    saturation = None
    rng = traj.meta.get("ctrl_range")
    if rng is not None:
        lo, hi = (np.atleast_1d(np.asarray(b, dtype=float)) for b in rng)
        u = np.asarray(traj.u, dtype=float).reshape(len(traj.t), -1)
        at = (u <= lo + 1e-9 * np.maximum(1.0, np.abs(lo))) | (u >= hi - 1e-9 * np.maximum(1.0, np.abs(hi)))
        saturation = first(at.any(axis=1))
    crossings = {f"x{k:g}": first(e > k * baseline) for k in ONSET_MULTIPLES}
    failed = first(e > bound)
    sudden = None
    if failed is not None:
        marks = [v for v in (saturation, *crossings.values()) if v is not None]
        sudden = all(failed - v <= SUDDEN_WINDOW for v in marks)
    return {"baseline": baseline, "baseline_until": baseline_until, "saturation": saturation, **crossings,
            "bound": bound, "failure": failed, "sudden": sudden, "window": SUDDEN_WINDOW}


def pseudo_inertia_eigenvalues(theta: np.ndarray) -> np.ndarray:
    """(N, bodies, 4) the eigenvalues, ascending, of each body's pseudo-inertia J = [[½tr(I)·1 − I, h], [hᵀ, m]]
    (Wensing, Kim & Slotine 2017: the body is physically possible exactly when J ⪰ 0), from rows of θ (N, 10 ×
    bodies) in the rigid-body order [m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (I about the body frame's
    origin, h = m c)."""
    from adaptive_mj.laws.pseudo_inertia import eigenvalues

    th = np.atleast_2d(np.asarray(theta, dtype=float))
    return eigenvalues(th, range(0, 10 * (th.shape[1] // 10), 10))


def window_spread(t: np.ndarray, values: np.ndarray, window: float) -> dict:
    """A figure over the last `window` s of a run instead of its last sample: mean, min and max of `values` (N,)
    over rows with t ≥ t_end − window, and the last value."""
    v = np.asarray(values, dtype=float)
    rows = np.asarray(t) >= t[-1] - window
    w = v[rows]
    return {"window": window, "mean": float(np.mean(w)), "min": float(np.min(w)), "max": float(np.max(w)),
            "last": float(v[-1])}

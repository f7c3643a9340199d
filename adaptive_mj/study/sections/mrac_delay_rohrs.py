"""Section 16: MRAC's published break points: Nguyen's input-delay threshold on γ (mrac_time_delay.toml)
and Rohrs' counterexample (rohrs_counterexample.toml).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _row, _save, _status_note, plt,
                                               register)
from adaptive_mj.trajectory import Status


NGUYEN_PUBLISHED = (2.0, 2.9)  # Nguyen, Model-Reference Adaptive Control, §8.3: γ = 2 stable, γ = 2.9 unstable
ROHRS_CONSTANT_R = ("reference.amplitudes=[]", "reference.omegas=[]", "reference.offset=2.0")
ROHRS_VARIANTS = [
    ("published", "r = 0.3 + 1.85 sin 16.1t", []),
    ("constant_r", "r = 2", list(ROHRS_CONSTANT_R)),
    ("no_unmodelled", "the same r, plant 2/(s+1) only", ["plant.unmodelled_num=[1.0]", "plant.unmodelled_den=[1.0]"]),
    ("sigma", "σ-modification σ = 0.1", ["law.sigma=0.1"]),
    ("e_mod", "e-modification ν = 0.5", ["law.e_modification=0.5"]),
    ("projection", "projection k_y ∈ [−5, 0], k_r ∈ [0, 5]", ["law.projection={k_y=[-5, 0], k_r=[0, 5]}"]),
    ("dead_zone", "dead-zone |e| < 0.5", ["law.dead_zone={width=0.5}"]),
    ("dead_zone_0.3", "dead-zone |e| < 0.3", ["law.dead_zone={width=0.3}"]),
    ("mit", "the MIT rule", ["law.rule=mit"]),
]


def _nguyen_gammas(quick: bool) -> list[float]:
    """γ from 2 to 2.9: every 0.05 (quick: every 0.3)."""
    step = 0.3 if quick else 0.05
    return [round(2.0 + i * step, 3) for i in range(int(round(0.9 / step)) + 1)]


TITLE = "MRAC: Nguyen's delay threshold and Rohrs' counterexample"
CLAIM = ("Direct MRAC (Lyapunov rule) is stable with the plant it was designed for; an input delay "
         "puts a ceiling on γ (published between 2 and 2.9), and unmodelled dynamics excited by a "
         "high-frequency command make the gains drift until the loop is unstable (Rohrs).")


@register(16, "mrac", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    from adaptive_mj.study.mrac_breaks import frozen_gain_limit, phase_lag_deg, rohrs_onset

    gammas = _nguyen_gammas(quick)
    jobs = [_job("mrac", f"nguyen_gamma_{g:g}", "mrac_time_delay", logs, [f"law.gamma={g}"], expect="measured")
            for g in gammas]  # a sweep across Nguyen's threshold: each verdict is the measurement
    jobs.append(_job("mrac", "nguyen_projection", "mrac_time_delay", logs,
                     ["law.gamma=2.9", "law.projection={k_y=[-2, 0], k_r=[0, 4]}"]))
    variants = ROHRS_VARIANTS[:3] if quick else ROHRS_VARIANTS  # quick: the published pair and the mechanism
    jobs += [_job("mrac", f"rohrs_{key}", "rohrs_counterexample", logs, ov,
                  expect="fail" if key == "published" else "measured") for key, _, ov in variants]
    rohrs = sc.load(SCN / "rohrs_counterexample.toml")
    lin = rohrs.plant.linear
    assert lin is not None
    num, den = np.polymul(lin.num, lin.unmodelled_num), np.polymul(lin.den, lin.unmodelled_den)
    limit = frozen_gain_limit(num, den)
    lag = phase_lag_deg(lin.unmodelled_num, lin.unmodelled_den, 16.1)

    def analyze(res, out):
        rows, lines = [], ["| γ | verdict | diverged at [s] | tail RMS e |", "|---|---|---|---|"]
        ok_g: list[float] = []
        bad_g: list[float] = []
        for g in gammas:
            r = res[f"mrac/nguyen_gamma_{g:g}"]
            div = r.trajectory is not None and r.trajectory.status == Status.DIVERGED
            (bad_g if div or r.trajectory is None else ok_g).append(g)
            t_end = f"{r.trajectory.t[-1]:.2f}" if div and r.trajectory is not None else "—"
            tail = (r.summary or {}).get("metrics", {}).get("rms_tracking_error_tail")
            lines.append(f"| {g:g} | {r.status} | {t_end} | {_g(tail)} |")
            rows.append(_row("MRAC delay", f"gamma {g:g}", r))
        stable = [g for g in ok_g if not any(b < g for b in bad_g)]
        first_bad = min(bad_g) if bad_g else None
        crit = (f"largest bounded γ {max(stable):g}, smallest diverging γ {first_bad:g}"
                if stable and first_bad is not None else "no bracket inside [2, 2.9]")
        pr = res["mrac/nguyen_projection"]
        rows.append(_row("MRAC delay", "gamma 2.9 + projection", pr))
        text = (f"**Nguyen's delay threshold** (`scenarios/mrac_time_delay.toml`: ẋ = −x + u(t − 0.5 s), "
                f"x_m' = −2x_m + 2r, r = sin t, 60 s runs, RK4 at 5 ms, the delay an exact 100-step line). "
                f"Published: γ = {NGUYEN_PUBLISHED[0]:g} stable, γ = {NGUYEN_PUBLISHED[1]:g} unstable. Measured over "
                f"this grid: {crit}; `adaptive-mj sweep mrac_time_delay --breaking-point law.gamma=2:2.9 "
                f"--tail-bound 0.3 --steps 6` bisects it finer. γ = 2.9 with projection k_y ∈ [−2, 0]: "
                f"{pr.status}.\n\n" + "\n".join(lines))
        r_lines = ["| run | verdict | end [s] | onset [s] | final k̂_y | tail RMS e |", "|---|---|---|---|---|---|"]
        fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
        onset_pub = None
        for key, label, _ in variants:
            r = res[f"mrac/rohrs_{key}"]
            rows.append(_row("Rohrs", key, r))
            tr = r.trajectory
            if tr is None:
                r_lines.append(f"| {label} | {r.status} | | | | |")
                continue
            onset = rohrs_onset(tr, limit)
            if key == "published":
                onset_pub = onset
            tail = (r.summary or {}).get("metrics", {}).get("rms_tracking_error_tail")
            r_lines.append(f"| {label} | {r.status} | {tr.t[-1]:.2f} | {_g(onset) if onset is not None else '—'} | "
                           f"{_g(tr.theta_hat[-1, 0])} | {_g(tail)} |")
            if key in ("published", "constant_r", "no_unmodelled", "e_mod"):
                ax[0].plot(tr.t, tr.theta_hat[:, 0], lw=1.1, label=label)
                ax[1].plot(tr.t, np.clip(tr.x[:, 0] - tr.ref[:, 0], -5, 5), lw=0.8, label=label)
        ax[0].axhline(limit, color="k", ls="--", lw=1, label=f"frozen-gain limit {limit:.2f}")
        if onset_pub is not None:
            ax[0].axvline(onset_pub, color="r", ls=":", lw=1)
        ax[0].set_ylabel("$\\hat k_y$")
        ax[0].set_ylim(max(limit * 1.5, -40), 1)
        ax[0].legend(fontsize=8)
        ax[1].set_ylabel("e = y − y_m (clipped ±5)")
        ax[1].set_xlabel("time t [s]")
        for a in ax:
            a.grid(alpha=0.3)
        fig.suptitle("Rohrs' counterexample: k_y drifts past the frozen-gain limit")
        img = _save(fig, out, "rohrs")
        text += ("\n\n**Rohrs' counterexample** (`scenarios/rohrs_counterexample.toml`: 2/(s+1) · "
                 "229/(s² + 30s + 229), x_m from 3/(s+3), k_y(0) = −0.65, k_r(0) = 1.14, γ = 1, 30 s, "
                 "|y| > 100 counts as diverged). "
                 f"Mechanism: at 16.1 rad/s the unmodelled factor lags by {abs(lag):.1f}°, so the gradient e·y "
                 "has a non-zero mean that drives k̂_y down; with the gains frozen, the loop with the unmodelled "
                 f"dynamics is stable only for k_y > {limit:.3f} (the roots of den − k·num; Routh gives "
                 "(1 − 31·259/229)/2). The **onset** is the first time k̂_y crosses that limit: "
                 f"{_g(onset_pub) if onset_pub is not None else 'never'} s for the published r. The same r on the "
                 "plant without its unmodelled factor (the row below) shows whether the drift needs it.\n\n"
                 + "\n".join(r_lines) + "\n\n" + img)
        return SectionReport(text + _status_note(res), rows)

    return tuple(jobs), analyze

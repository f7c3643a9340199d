"""Section 5: the order-n sliding law on the heave vehicle with a thruster lag (n = 3 models the lag,
n = 2 does not).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _ok, _row, _save, _status_note, plt,
                                               register)


TITLE = "Sliding adaptive control of order n"
CLAIM = ("for d y⁽ⁿ⁾ = f + φp + hu, s = (d/dt + λ)ⁿ⁻¹ỹ and ṡ_r = ((d/dt + λ)ⁿ⁻¹ − (d/dt)ⁿ⁻¹)ỹ' + y_d⁽ⁿ⁾ "
         "give the same V' = −k s².")


@register(5, "nth_order", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    dur = ["simulation.duration=30.0"] if quick else []
    jobs = (_job("nth_order", "n3_models_lag", "heave_thruster_n3", logs, dur),
            _job("nth_order", "n2_lag_unmodelled", "heave_thruster_n2", logs, dur))
    tau = sc.load(SCN / "heave_thruster_n3.toml").plant.thruster_time_constant

    def analyze(res, out):
        fig, ax = plt.subplots(figsize=(9, 4), constrained_layout=True)
        lines = ["| law | tail RMS ỹ [m] | u RMS [N] | Σ\\|Δu\\| [N] | final d̂ / d | final b̂ / b | final ĉ / c |",
                 "|---|---|---|---|---|---|---|"]
        rows = []
        for job in jobs:
            r = res[job.tag]
            v = job.tag.split("/")[1]
            rows.append(_row("n-th order", v, r))
            if not _ok(r):
                lines.append(f"| {v} | {r.status} ||||||")
                continue
            m, f, tr = r.summary["metrics"], r.summary["final"], r.trajectory
            ratio = {n: f["theta_hat"][n] / f["theta"][n] for n in ("d", "b", "c")}
            lines.append(f"| {v} | {_g(m['rms_tracking_error_tail'])} | {_g(m['control_rms'])} | "
                         f"{_g(m['control_total_variation'])} | {ratio['d']:.3f} | {ratio['b']:.3f} | "
                         f"{ratio['c']:.3f} |")
            ax.semilogy(tr.t, np.abs(tr.y_tilde) + 1e-9, lw=1, label=v)
        ax.set_xlabel("time t [s]")
        ax.set_ylabel("|ỹ| [m]")
        ax.legend()
        ax.grid(alpha=0.3)
        ax.set_title(f"heave vehicle with thruster lag τ = {tau:g} s")
        img = _save(fig, out, "nth_order")
        text = (f"The vehicle's thruster is a first-order lag (MuJoCo actuator `dyntype=\"filter\"`, τ = {tau:g} s). "
                "The n = 3 law uses s = (d/dt + λ)²ỹ and the third-order model τd y''' = −2τb|y'|y'' − d y'' − "
                "b y'|y'| − c g + u (θ = τd, τb, d, b, c); the n = 2 law is the lecture's and ignores the lag. "
                "Both from zero estimates, starting on the reference.\n\n" + "\n".join(lines) + "\n\n" + img
                + _status_note(res))
        return SectionReport(text, rows)

    return jobs, analyze

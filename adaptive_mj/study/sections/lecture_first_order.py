"""Section 1: the lecture's first-order example (lecture_first_order.toml, the analytic twin): tracking,
the estimates against a and b, and V.
"""
from __future__ import annotations

from pathlib import Path


from adaptive_mj.study.sections.common import (Built, SectionReport, _final_table, _g, _job, _ok, _row, _save,
                                               _status_note, plt, register)


TITLE = "Adaptive control of a first-order system"
CLAIM = ("u = ẋ_d − f − φp̂ + k x̃ with p̂' = −φᵀx̃/γ gives V' = −k x̃², so x̃ → 0; the estimates "
         "are only shown bounded (whether they reach a and b depends on excitation and time: see the "
         "table).")


@register(1, "first_order", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    dur = ["simulation.duration=15.0"] if quick else []
    jobs = (_job("first_order", "lecture", "lecture_first_order", logs, dur),)

    def analyze(res, out):
        r = res["first_order/lecture"]
        if not _ok(r):
            return SectionReport("Run failed." + _status_note(res), [_row("first-order", "lecture example", r)])
        tr, m = r.trajectory, r.summary["metrics"]
        fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
        ax[0].plot(tr.t, tr.ref[:, 0], "k--", lw=1, label="$x_d = \\cos t$")
        ax[0].plot(tr.t, tr.q, lw=1.2, label="x")
        ax[0].set_ylabel("x [-]")
        ax[0].legend()
        ax[0].grid(alpha=0.3)
        for i, name in enumerate(tr.names):
            ax[1].plot(tr.t, tr.theta[:, i], "k--", lw=1)
            ax[1].plot(tr.t, tr.theta_hat[:, i], lw=1.2, label=f"$\\hat {name}$ (true {tr.theta[0, i]:g}, dashed)")
        ax[1].set_ylabel("parameters [-]")
        ax[1].set_xlabel("time t [s]")
        ax[1].legend()
        ax[1].grid(alpha=0.3)
        fig.suptitle("lecture first-order example: $\\dot x = \\sin x - a x + b x^2 + u$")
        img = _save(fig, out, "first_order")
        text = (f"Twin of the lecture's system with a = 2, b = 1.5, k = 2, γ = 0.5, x(0) = 0, p̂(0) = 0, "
                f"x_d = cos t. Measured: tracking error RMS over the run {_g(m['rms_tracking_error'])}, "
                f"over the last 25 % {_g(m['rms_tracking_error_tail'])}; largest one-step increase of "
                f"V = ½x̃² + ½γp̃ᵀp̃: {_g(m['lyapunov_max_increase'])} (V(0) = {_g(m['lyapunov_initial'])}).\n\n"
                + _final_table(r, "first_order") + "\n\n" + img)
        err = max(abs(v) for v in m["param_error_final"].values())
        return SectionReport(text, [_row("first-order", "lecture example", r, f"max |p̂-p| = {_g(err)}")])

    return jobs, analyze

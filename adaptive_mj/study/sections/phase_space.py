"""Section 2: the phase portrait of the error dynamics (x̃, p̃) with one uncertain parameter
(lecture_phase_space.toml from several initial errors).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _job, _ok, _row, _save, _status_note, plt,
                                               register)


PHASE_POINTS = [(5.0, -5.0), (-5.0, 5.0), (5.0, 5.0), (-5.0, -5.0), (2.0, -4.0), (-2.0, 4.0), (4.0, 1.0),
                (1.0, 4.0)]


TITLE = "Phase-space view"
CLAIM = ("with one uncertain parameter the closed loop is a 2-D system in (x̃, p̃); trajectories reach "
         "x̃ = 0 but p̃ stops wherever it is when x̃ vanishes.")


@register(2, "phase", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    base = sc.load(SCN / "lecture_phase_space.toml")
    assert base.plant.theta is not None  # plant.theta is required for plant.kind = 'first_order' (scenario._plant)
    p_true = base.plant.theta["p"]
    points = PHASE_POINTS[:4] if quick else PHASE_POINTS
    jobs = tuple(_job("phase", f"x{xe:+g}_p{pe:+g}", "lecture_phase_space", logs,
                      [f"simulation.initial_state=[{-xe!r}]", f"law.initial_estimates={{p={p_true + pe!r}}}"])
                 for xe, pe in points)
    k, gamma = base.law.k, base.law.gamma
    assert isinstance(gamma, float)  # lecture_phase_space.toml gives law.gamma as one number

    def analyze(res, out):
        fig, ax = plt.subplots(figsize=(7.5, 6.5), constrained_layout=True)
        X, P = np.meshgrid(np.linspace(-6, 6, 25), np.linspace(-7, 7, 25))
        phi = np.sin(X) ** 2
        U, V = phi * P - k * X, -phi * X / gamma
        ax.streamplot(X, P, U, V, color="0.8", density=1.0, linewidth=0.6)
        lines = ["| start (x̃, p̃) | final x̃ | final p̃ |", "|---|---|---|"]
        rows = []
        for (xe, pe), job in zip(points, jobs, strict=True):
            r = res[job.tag]
            if not _ok(r):
                lines.append(f"| ({xe:g}, {pe:g}) | {r.status} | |")
                rows.append(_row("phase space", job.tag.split("/")[1], r))
                continue
            tr = r.trajectory
            xt, pt = tr.y_tilde, tr.theta_tilde[:, 0]
            ax.plot(xt, pt, lw=1.5)
            ax.plot(xt[0], pt[0], "ko", ms=4)
            ax.plot(xt[-1], pt[-1], "rx", ms=7)
            lines.append(f"| ({xe:g}, {pe:g}) | {xt[-1]:.2e} | {pt[-1]:+.3f} |")
            rows.append(_row("phase space", job.tag.split("/")[1], r, f"final x̃ {xt[-1]:.1e}, p̃ {pt[-1]:+.2f}"))
        ax.set_xlabel("tracking error $\\tilde x = x_d - x$ [-]")
        ax.set_ylabel("parameter error $\\tilde p = \\hat p - p$ [-]")
        ax.set_title("error dynamics, $\\phi = \\sin^2 x$: start ●, end ×")
        ax.set_xlim(-6, 6)
        ax.set_ylim(-7, 7)
        ax.grid(alpha=0.3)
        img = _save(fig, out, "phase_portrait")
        text = (f"Error dynamics x̃' = φ p̃ − k x̃, p̃' = −φ x̃/γ with φ = sin²x, x_d = 0, k = {k:g}, γ = {gamma:g}, "
                f"{len(points)} initial points (p̃ = p̂ − p; the lecture's phase section uses the opposite sign "
                "for p̃, which mirrors the portrait in p̃). Every trajectory ends on the line x̃ = 0 at a "
                "different p̃: tracking converges, the parameter does not.\n\n" + "\n".join(lines) + "\n\n" + img
                + _status_note(res))
        return SectionReport(text, rows)

    return jobs, analyze

"""Section 17: wing rock: the sliding adaptive law and MRAC on the roll dynamics [rad] through a change
of flight condition.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _row, _save, _status_note, plt,
                                               register)


TITLE = "Aircraft: wing rock"
CLAIM = ("The sliding adaptive law and MRAC hold a roll reference on the wing-rock dynamics within the "
         "aileron limit; when the flight condition changes they must re-adapt (docs/THEORY.md, \"Wing rock\"): "
         "the table says how far each gets within the run.")
READAPTED = 2.0  # a law has re-adapted within the run when its RMS error at the end is within this factor of before


def _readapt_words(key: str, f: dict) -> str:
    ratio = f["post"] / f["pre"] if f["pre"] > 0 else float("inf")
    done = ratio <= READAPTED
    return (f"{key}: the RMS error over the last part is {ratio:.2g}× its value before the change and ‖θ̃‖/‖θ‖ goes "
            f"from {f['err_change']:.2g} just after the change to {f['err_end']:.2g} at the end: "
            + ("re-adapted within the run" if done else
               f"re-adaptation is not shown within the run (not back within {READAPTED:g}× its error)") + ". ")


@register(17, "wing_rock", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    jobs = (_job("wing_rock", "sliding", "wing_rock", logs, []),  # the same 60 s runs under --quick
            _job("wing_rock", "mrac", "wing_rock_mrac", logs, []))

    from adaptive_mj.plants.wing_rock import INPUT_LIMIT

    scn = sc.load(SCN / "wing_rock.toml")
    t_ch, t_end = scn.events[0].t, scn.simulation.duration  # the flight-condition change, the run's end [s]

    def analyze(res, out):
        lines = [f"| law | verdict | RMS error {t_ch / 3:g}–{t_ch:g} s [rad] | RMS error {t_ch + 10:g}–{t_end:g} s "
                 f"[rad] | peak error after the change [rad] | time at ±{INPUT_LIMIT:g} |", "|---|---|---|---|---|---|"]
        rows, words = [], []
        fig, ax = plt.subplots(1, 1, figsize=(9, 3.5), constrained_layout=True)
        for key in ("sliding", "mrac"):
            r = res[f"wing_rock/{key}"]
            rows.append(_row("wing rock", key, r))
            tr = r.trajectory
            if tr is None:
                lines.append(f"| {key} | {r.status} | | | | |")
                continue
            err = tr.ref[:, 0] - tr.x[:, 0]
            pre, post = (tr.t > t_ch / 3) & (tr.t < t_ch), tr.t >= t_ch + 10
            after = tr.t >= t_ch
            sat = float(np.mean(np.abs(tr.u) >= INPUT_LIMIT - 1e-12))
            lines.append(f"| {key} | {r.status} | {_g(np.sqrt(np.mean(err[pre] ** 2)))} | "
                         f"{_g(np.sqrt(np.mean(err[post] ** 2)))} | {_g(np.max(np.abs(err[after])))} | {sat:.1%} |")
            rel = np.linalg.norm(tr.theta_hat - tr.theta, axis=1) / np.maximum(np.linalg.norm(tr.theta, axis=1), 1e-300)
            words.append(_readapt_words(key, {"pre": float(np.sqrt(np.mean(err[pre] ** 2))),
                                              "post": float(np.sqrt(np.mean(err[post] ** 2))),
                                              "err_change": float(rel[np.argmax(after)]), "err_end": float(rel[-1])}))
            ax.plot(tr.t, err, lw=0.8, label=key)
        ax.axvline(t_ch, color="k", ls=":", lw=1)
        ax.set_xlabel("time t [s]")
        ax.set_ylabel("roll error [rad]")
        ax.legend()
        ax.grid(alpha=0.3)
        img = _save(fig, out, "wing_rock")
        text = ("Wing rock (`scenarios/wing_rock.toml`, `wing_rock_mrac.toml`): ẋ₂ = Wᵀ[x₁, x₂, |x₁|x₂, |x₂|x₂, x₁³] "
                f"+ L_δ u with Elzebda's 25° coefficients, |u| ≤ {INPUT_LIMIT:g}, a roll reference of 0.3 and 0.15 "
                f"rad at 0.5 and 1.3 rad/s. At t = {t_ch:g} s W is tripled and L_δ halved: a stated change, not a "
                f"published second set (none was found). RMS error measured from {t_ch / 3:g} s to {t_ch:g} s and "
                f"from {t_ch + 10:g} s to {t_end:g} s. " + "".join(words) + "\n\n"
                + "\n".join(lines) + "\n\n" + img)
        return SectionReport(text + _status_note(res), rows)

    return jobs, analyze

"""Section 10: sudden failure of the heave vehicle after drift under an unmodelled control delay
(heave_sudden_failure.toml), and the modifications that prevent it.
"""
from __future__ import annotations

from pathlib import Path


from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import analysis
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _ok, _row, _save, _status_note, plt,
                                               register)


def _failure_variants(quick: bool) -> list[tuple[str, list[str]]]:
    """The unmodified law and each robust modification on heave_sudden_failure; the numbers are
    derived from the scenario (σ_s from its noise, the box from the model's true d)."""
    from adaptive_mj.setup.build import build

    path = SCN / "heave_sudden_failure.toml"
    d = float(build(sc.load(path)).plant.true_theta()[0])
    variants = [("no_modification", []),
                ("dead_zone_3sigma", ["law.dead_zone={width_in_noise_std=3.0}"]),
                ("sigma", ["law.sigma=1e-3"]),
                ("e_modification", ["law.e_modification=0.1"]),
                ("projection", [f"law.projection={{d=[{0.5 * d!r}, {2.0 * d!r}]}}"])]
    if not quick:  # 200 s of physics on the compiled callback (the 1-DOF kernel's composite variant)
        variants.append(("composite", ["law.composite={gain=1e-4, filter=2.0}"]))
    return variants


TITLE = "Sudden failure, and the modifications that prevent it"
CLAIM = ("parameter drift \"leads to sudden failure of the adaptive control system (by exciting unmodeled "
         "dynamics)\"; a number of techniques for modifying the adaptation law are available.")


@register(10, "failure", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    path = SCN / "heave_sudden_failure.toml"
    scn = sc.load(path)
    jobs = tuple(_job("failure", v, "heave_sudden_failure", logs, ov, ["sudden_failure"],
                      expect={"no_modification": "fail", "composite": "measured"}.get(v, "ok"))
                 for v, ov in _failure_variants(quick))
    overrides = {job.tag: job.overrides for job in jobs}

    def analyze(res, out):
        fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=True, constrained_layout=True)
        lines = ["| law | failure time [s] | thrust first saturated at [s] | d̂/d there | max d̂/d | RMS ỹ before "
                 "[m] | tail RMS ỹ [m] |", "|---|---|---|---|---|---|---|"]
        rows, crit, bound, t_fail0 = [], None, None, None
        for i, job in enumerate(jobs):
            r, v = res[job.tag], job.tag.split("/")[1]
            if not _ok(r):
                rows.append(_row("failure", v, r))
                lines.append(f"| {v} | {r.status} ||||||")
                continue
            f, tr = r.extras["sudden_failure"], r.trajectory
            crit, bound = f["critical_ratio"], f["bound"]
            fail = "none" if f["t_fail"] is None else f"{f['t_fail']:.2f}"
            sat = "never" if f["t_saturation"] is None else f"{f['t_saturation']:.2f}"
            at = "–" if f["ratio_at_saturation"] is None else f"{f['ratio_at_saturation']:.3f}"
            lines.append(f"| {v} (`{' '.join(overrides[job.tag]) or 'as the scenario'}`) | {fail} | {sat} | {at} | "
                         f"{f['ratio_max']:.3g} | {_g(f['rms_before'])} | {_g(f['rms_tail'])} |")
            rows.append(_row("failure", v, r, "no failure" if f["t_fail"] is None else f"fails at {fail} s"))
            if v == "no_modification":
                t_fail0 = f["t_fail"]
            color = f"C{i}"
            ax[0].semilogy(tr.t, tr.theta_hat[:, 0] / tr.theta[:, 0], color=color, lw=1.2, label=v)
            rms = analysis.windowed_rms(tr.t, tr.y_tilde, analysis.FAILURE_WINDOW)
            ax[1].semilogy(tr.t, rms, color=color, lw=1, label=v)
            if f["t_fail"] is not None:
                for a in ax:
                    a.axvline(f["t_fail"], color=color, ls=":", lw=1.2)
        if crit is not None:
            ax[0].axhline(crit, color="k", ls="--", lw=1, label=f"predicted loss of delay margin, d̂/d = {crit:.3g}")
            ax[1].axhline(bound, color="k", ls="--", lw=1, label=f"failure bound σ_y = {bound:g} m")
        ax[0].set_ylabel("d̂ / d [-]")
        ax[1].set_ylabel(f"RMS ỹ over {analysis.FAILURE_WINDOW:g} s [m]")
        ax[1].set_xlabel("time t [s] (dotted: failure time)")
        for a in ax:
            a.grid(alpha=0.3)
            a.legend(fontsize=7)
        fig.suptitle("sudden failure: drift until the loop runs out of delay margin, and the modifications")
        img = _save(fig, out, "sudden_failure")
        delay_ms = scn.simulation.control_delay * (scn.simulation.timestep or 0.001) * 1e3
        text = (f"`heave_sudden_failure`: the heave vehicle holds y_d = 0 (not persistently exciting) under "
                f"sensor noise σ_y = {scn.noise.std['y']:g} m, σ_y' = {scn.noise.std['y_dot']:g} m/s, with "
                f"λ = {scn.law.lam:g}, k = {scn.law.k:g}, estimates starting at the truth, and a "
                f"{delay_ms:g} ms delay between computing the thrust and applying it (`simulation.control_delay`) "
                "that the law does not model. The noise makes d̂ drift upwards, which raises the loop's derivative "
                "gain k + d̂λ and its crossover frequency until the delay's phase lag uses up the margin: the "
                "prediction (linearised loop, `analysis.critical_leading_estimate`) is d̂/d = "
                f"{_g(crit)}. Failure: the RMS of ỹ over the last {analysis.FAILURE_WINDOW:g} s exceeds the "
                f"depth noise σ_y; bursting starts when the thrust first saturates."
                + (f" Without a modification the run failed at t = {t_fail0:.2f} s." if t_fail0 is not None else "")
                + "\n\n" + "\n".join(lines) + "\n\n" + img + _status_note(res))
        return SectionReport(text, rows)

    return jobs, analyze

"""Section 9: Slotine–Li on the 6-joint UR5e-style arm: a payload swap against computed torque and PD +
gravity, and the payload's identification (ur5e_payload_swap.toml, ur5e_identification.toml).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import analysis
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _ok, _recovery, _row, _save,
                                               _status_note, plt, register)


TITLE = "Slotine–Li on a 6-joint arm"
CLAIM = ("robots have to manipulate loads of various sizes, weights and mass distributions; an adaptive "
         "controller identifies the unknown load on line and keeps tracking where fixed-parameter "
         "controllers designed for another load do not.")


@register(9, "manipulator", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    swap_scn = sc.load(SCN / "ur5e_payload_swap.toml")
    ev = swap_scn.events[0]
    dur = swap_scn.simulation.duration
    over = []
    if quick:
        dur, t_ev = 10.0, 5.0
        over = [f"simulation.duration={dur}", f"events=[{{t={t_ev}, kind='payload_swap', payload='{ev.payload}'}}]"]
    else:
        t_ev = ev.t
    ex = ["manipulator_response"]
    base = ["law.nominal='model'"]
    jobs = (_job("manipulator", "slotine_li", "ur5e_payload_swap", logs, over, ex),
            _job("manipulator", "computed_torque", "ur5e_payload_swap", logs,
                 ["law.kind=computed_torque", *base, *over], ex, expect="measured"),
            _job("manipulator", "pd_gravity", "ur5e_payload_swap", logs, ["law.kind=pd_gravity", *base, *over], ex,
                 expect="measured"),
            _job("manipulator", "identification", "ur5e_identification", logs,
                 ["simulation.duration=15.0"] if quick else [], ex))
    ident_scn = sc.load(SCN / "ur5e_identification.toml")

    def analyze(res, out):
        rows, lines = [], ["| controller | tail RMS q̃ per joint [mrad] (" + ", ".join(
            j for j in ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")) +
            ") | peak max_j \\|q̃_j\\| after swap [rad] | recovery |", "|---|---|---|---|"]
        fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
        for job, style in zip(jobs[:3], ["-", "--", ":"], strict=True):
            r, v = res[job.tag], job.tag.split("/")[1]
            if not _ok(r):
                rows.append(_row("manipulator §9", v, r))
                lines.append(f"| {v} | {r.status} |||")
                continue
            mr = r.extras["manipulator_response"]
            tails = ", ".join(f"{1e3 * x:.3g}" for x in mr["tail_rms_per_joint"])
            rec = _recovery(mr.get("recovery_time"), mr.get("peak_error_after"))
            lines.append(f"| {v} | {tails} | {mr.get('peak_error_after', math.nan):.4f} | {rec} |")
            rows.append(_row("manipulator §9", v, r,
                             f"worst joint tail {1e3 * max(mr['tail_rms_per_joint']):.3g} mrad"))
            tr = r.trajectory
            ax[0].semilogy(tr.t, np.abs(tr.joint_errors).max(axis=1), style, lw=1, label=v)
            if v == "slotine_li":
                i = list(tr.names).index("payload/body.m")
                ax[1].plot(tr.t, tr.theta[:, i], "k--", lw=1, label="true payload mass")
                ax[1].plot(tr.t, tr.theta_hat[:, i], lw=1.2, label="estimate (Slotine–Li)")
        ax[0].axhline(analysis.SWAP_THRESHOLD, color="0.35", lw=0.9, ls="-.",  # not a controller's colour
                      label=f"recovery threshold {analysis.SWAP_THRESHOLD} rad")
        ax[0].set_ylabel("max_j |q̃_j| [rad]")
        ax[0].legend(fontsize=8)
        ax[1].set_ylabel("payload mass [kg]")
        ax[1].set_xlabel("time t [s]")
        ax[1].legend(fontsize=8)
        for a in ax:
            a.axvline(t_ev, color="grey", ls=":", lw=1)
            a.grid(alpha=0.3)
        fig.suptitle(f"6-joint arm: payload tool_offset → {ev.payload} at t = {t_ev:g} s")
        img = _save(fig, out, "manipulator_swap")
        text = (f"`ur5e_payload_swap`: the 6-joint UR5e-style arm (`models/ur5e_arm.xml`, link inertials from the "
                f"maker's published data) tracks sums of sines on every joint; its payload's 10 inertial parameters "
                f"are unknown (Slotine–Li starts them at zero); at t = {t_ev:g} s the 1.5 kg `tool_offset` payload is "
                f"swapped for `{ev.payload}` (mass, centre of mass and inertia change together). The baselines use the "
                "same Λ and K_D with the true parameters of the first payload (nominal = the model at t = 0). "
                f"Recovery: time after the swap from which every joint stays below {analysis.SWAP_THRESHOLD} rad.\n\n"
                + "\n".join(lines) + "\n\n" + img)
        r = res[jobs[0].tag]
        if _ok(r):
            mr = r.extras["manipulator_response"]
            inc, rate = mr["lyapunov_max_increase_rel"], mr["lyapunov_rate_error_rel"]
            text += (f"\n\nLyapunov check (Slotine–Li, away from the swap): largest one-step increase of V = "
                     f"{_g(inc)} × V(0); max |ΔV/Δt + sᵀK_D s| = {_g(rate)} × max sᵀK_D s.")
        r = res[jobs[3].tag]
        if _ok(r):
            p = r.extras["manipulator_response"]["payload"]
            f = p["final"]
            fig, axes = plt.subplots(3, 1, figsize=(9, 6), sharex=True, constrained_layout=True)
            # three quantities, three units: one axis each
            for a, y, label, color in ((axes[0], 100 * np.asarray(p["mass_rel_error"]), "mass error [%]", "C0"),
                                       (axes[1], 1e3 * np.asarray(p["com_error"]), "centre of mass error [mm]", "C1"),
                                       (axes[2], p["inertia_error"], "inertia error,\nmax entry [kg m²]", "C2")):
                a.semilogy(p["t"], y, color=color)
                a.set_ylabel(label, fontsize=9)
                a.grid(alpha=0.3)
            axes[-1].set_xlabel("time t [s]")
            fig.suptitle(f"{ident_scn.name}: the payload's identification error", fontsize=10)
            img2 = _save(fig, out, "manipulator_identification")
            rows.append(_row("manipulator §9", "identification", r,
                             f"mass err {100 * f['mass_rel_error']:.3g} %, c err {1e3 * f['com_error']:.3g} mm"))
            text += (f"\n\n`{ident_scn.name}`: a persistently exciting trajectory (three sines per joint), estimates "
                     f"from zero, {r.summary['duration']:g} s. At the end: mass {f['mass']:.4f} kg (true "
                     f"{f['mass_true']:.4f} kg, error {100 * f['mass_rel_error']:.3g} %), centre of mass "
                     f"[{', '.join(f'{1e3 * c:.2f}' for c in f['com'])}] mm (true "
                     f"[{', '.join(f'{1e3 * c:.2f}' for c in f['com_true'])}] mm, error "
                     f"{1e3 * f['com_error']:.3g} mm), inertia entries within {f['inertia_error']:.2g} kg m² of the "
                     "truth (read from the compiled model).\n\n" + img2)
        return SectionReport(text + _status_note(res), rows)

    return jobs, analyze

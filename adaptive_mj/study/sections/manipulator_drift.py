"""Section 12: drift and failure on the 6-joint arm at rest with noisy encoders (ur5e_drift.toml), the
failure's onset and precursors, and what the dead-zone, σ-modification, the physically consistent projection and
the cheaper nonnegative box did.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from adaptive_mj.laws.pseudo_inertia import is_physical
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.analysis import SUDDEN_WINDOW, failure_onset, pseudo_inertia_eigenvalues

if TYPE_CHECKING:
    from adaptive_mj.laws.slotine_li import SlotineLiLaw
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _ok, _row, _save, _status_note, plt,
                                               register)


ARM_DRIFT_VARIANTS: tuple[tuple[str, list[str]], ...] = (
    ("adaptive", []), ("dead_zone_3sigma", ["law.dead_zone={width_in_noise_std=3.0}"]),
    ("sigma", ["law.sigma=0.02"]), ("consistent", ["law.projection='consistent'"]),
    ("box", ["law.projection='nonnegative'"]))
ARM_DRIFT_ONSET = 100.0  # a failure: max_j |q̃_j| above this many encoder noise σ_q


TITLE = "Drift and failure on the 6-joint arm"
CLAIM = ("the lecture's second half where researchers use Slotine–Li: realistic encoder noise and a "
         "differentiated velocity make the unexcited estimates drift until the loop fails (\"parameter drift does "
         "not affect tracking accuracy until instability occurs\": the onsets below say how true that is here); "
         "the dead-zone sized from the noise and σ-modification are the lecture's fixes.")


def _t(v: float | None) -> str:
    return "never" if v is None else f"{v:.1f}"


def _facts(tr, err: np.ndarray) -> dict:
    """What the section's words rest on, from one run's rows: how far θ̂ moved, ‖θ̃‖/‖θ‖ at 20 s and its median
    after, and the pseudo-inertia's smallest eigenvalue per row (the payload physically possible when ≥ 0, to the
    rounding of a projected estimate: pseudo_inertia.is_physical)."""
    eig = pseudo_inertia_eigenvalues(tr.theta_hat)[:, 0, :]
    bad = ~is_physical(eig[:, 0], np.sum(np.abs(eig), axis=1))
    late = tr.t >= 20.0
    return {"moved": float(np.max(np.abs(tr.theta_hat - tr.theta_hat[0]))),
            "err_20": float(np.interp(20.0, tr.t, err)) if tr.t[-1] >= 20.0 else float("nan"),
            "err_after_20": float(np.median(err[late])) if late.any() else float("nan"),
            "not_psd": int(np.sum(bad)), "rows": len(tr.t), "m_min": float(np.min(tr.theta_hat[:, 0])),
            "m_at_zero": int(np.sum(tr.theta_hat[:, 0] <= 0.0)), "final_eig": eig[-1].tolist(),
            "first_not_psd": float(tr.t[np.argmax(bad)]) if bad.any() else None}


def _failure_words(f: dict | None, quiet: float | None) -> str:
    """The unmodified law's failure, worded from its onsets: "suddenly" only when the precursors were short."""
    if f is None or "onset" not in f:
        return "Without a modification the estimates drift. "
    fo = f["onset"]
    if fo["failure"] is None:
        return "Without a modification the estimates drift; no failure occurred within the run. "
    head = (f"Without a modification the estimates drift while max_j |q̃_j| stays near {_g(quiet)} rad (median over "
            f"the first 60 s), and at t = {fo['failure']:.1f} s it crosses the failure bound. ")
    if fo["sudden"]:
        return head + f"Every precursor comes within {fo['window']:g} s before it: the failure is sudden. "
    marks = [(name, fo[key]) for name, key in (("torques first saturate", "saturation"),
                                               ("the error passes 5× its baseline", "x5"),
                                               ("25×", "x25")) if fo[key] is not None]
    return head + ("It is not sudden: " + ", ".join(f"{name} at {v:.1f} s" for name, v in marks)
                   + f" (the lecture's \"no effect on tracking until instability\" does not hold here: the decline "
                   f"is in the log {fo['failure'] - min(v for _, v in marks):.0f} s before the failure). ")


def _modification_words(facts: dict) -> str:
    """What each modification did, from its rows (not what it is meant to do)."""
    out = []
    dz = facts.get("dead_zone_3sigma")
    if dz is not None:
        out.append("It " + ("never opened: θ̂ never moved (max |θ̂ − θ̂(0)| = 0), so adaptation was "
                                            "off, not bounded. " if dz["moved"] == 0.0 else
                                            f"moved θ̂ by at most {_g(dz['moved'])}. "))
    sg = facts.get("sigma")
    if sg is not None:
        out.append(f"σ-modification (σ = 0.02) keeps θ̂ bounded, not at the truth: ‖θ̃‖/‖θ‖ is "
                   f"{sg['err_20']:.3g} at 20 s and {sg['err_after_20']:.3g} (median) after. ")
    pc = facts.get("consistent")
    if pc is not None:
        eig = ", ".join(f"{e:.3g}" for e in pc["final_eig"])
        out.append("The physically consistent projection (`law.projection = \"consistent\"`: the payload's "
                   "pseudo-inertia kept positive semidefinite, projected in the metric of Γ, docs/THEORY.md) keeps "
                   + ("a possible body in every row" if pc["not_psd"] == 0 else
                      f"a possible body in all but {pc['not_psd']} of the {pc['rows']} rows")
                   + f" (final pseudo-inertia eigenvalues {eig}); it bounds nothing else: the set is a cone, and "
                   f"‖θ̃‖/‖θ‖ is {pc['err_after_20']:.3g} (median after 20 s). ")
    ph = facts.get("box")
    if ph is not None:
        eig = ", ".join(f"{e:.3g}" for e in ph["final_eig"])
        out.append("The cheaper box (`law.projection = \"nonnegative\"`, formerly `\"physical\"`; a relaxation) clips "
                   f"m̂ at 0 ({ph['m_at_zero']} of {ph['rows']} rows at 0) but not the inertia, and the payload's "
                   f"pseudo-inertia is not positive semidefinite in {ph['not_psd']} of the {ph['rows']} rows"
                   + (f" (first at {ph['first_not_psd']:.1f} s)" if ph["first_not_psd"] is not None else "")
                   + f"; its final eigenvalues {eig}. ")
    return "".join(out)


@register(12, "arm_drift", TITLE, CLAIM)
def section(quick: bool, logs: Path) -> Built:
    """ur5e_drift (the arm holding home, noisy encoders, differentiated velocity, estimates from the
    truth) with no modification, the dead-zone sized from the noise, σ-modification, the physically consistent
    projection and the nonnegative box; the same 150 s in the full and the quick bench (5 runs)."""
    name = "ur5e_drift"
    # the plain law's drift is the demonstration; the projections are measured (they keep the estimate possible,
    # or m̂ ≥ 0 only, and bound nothing else)
    jobs = tuple(_job("arm_drift", v, name, logs, over,
                      expect={"adaptive": "fail", "consistent": "measured", "box": "measured"}.get(v, "ok"))
                 for v, over in ARM_DRIFT_VARIANTS)

    def analyze(res, out):
        from adaptive_mj.setup.build import build

        scn = sc.load(SCN / f"{name}.toml")
        sigma_q = float(scn.noise.std["q"])
        setup = build(sc.load(SCN / f"{name}.toml", overrides=list(ARM_DRIFT_VARIANTS[1][1])))
        law = cast("SlotineLiLaw", setup.law)  # ur5e_drift.toml: law.kind = 'slotine_li'
        width = law.dead_zone.width if law.dead_zone is not None else float("nan")
        bound = ARM_DRIFT_ONSET * sigma_q
        fig, ax = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, constrained_layout=True)
        lines = ["| law | drift of ‖θ̃‖/‖θ‖ over the first 60 s [per 100 s] | failure onset (max_j abs(q̃_j) > "
                 f"{_g(bound)} rad) | final m̂ (true {_g(float(setup.plant.true_theta()[0]))} kg) | "
                 "final ‖θ̃‖/‖θ‖ | tail RMS q̃ (over the joints) [rad] | verdict |", "|---|---|---|---|---|---|---|"]
        rows, onsets, quiet, facts = [], {}, None, {}
        onset_lines = ["| law | baseline max_j abs(q̃_j) [rad] (median, first 60 s) | first torque at a limit [s] | "
                       "first above 5× baseline [s] | first above 25× [s] | failure (the bound) [s] | sudden? |",
                       "|---|---|---|---|---|---|---|"]
        for job, (v, _) in zip(jobs, ARM_DRIFT_VARIANTS, strict=True):
            r = res[job.tag]
            if not _ok(r):
                rows.append(_row("manipulator §12", v, r))
                lines.append(f"| {v} | {r.status} ||||||")
                continue
            tr = r.trajectory
            err = np.linalg.norm(tr.theta_hat - tr.theta, axis=1) / np.linalg.norm(tr.theta, axis=1)
            early = tr.t <= 60.0
            slope = float(np.polyfit(tr.t[early], err[early], 1)[0]) * 100.0 if early.sum() > 2 else float("nan")
            e = np.abs(tr.joint_errors).max(axis=1)
            bad = np.nonzero(e > bound)[0]
            onset = float(tr.t[bad[0]]) if len(bad) else None
            onsets[v] = onset
            if v == "adaptive":
                quiet = float(np.median(e[early]))
            fo = failure_onset(tr, bound, 60.0)
            if fo["failure"] is not None or fo["saturation"] is not None or fo["x5"] is not None:
                onset_lines.append(
                    f"| {v} | {_g(fo['baseline'])} | {_t(fo['saturation'])} | {_t(fo['x5'])} | {_t(fo['x25'])} | "
                    f"{_t(fo['failure'])} | "
                    + ("-" if fo["sudden"] is None else ("yes" if fo["sudden"] else "no")) + " |")
            facts[v] = _facts(tr, err)
            if v == "adaptive":
                facts[v]["onset"] = fo
            tail = (r.summary or {}).get("metrics", {}).get("rms_tracking_error_tail")
            when = f"none in {_g(float(tr.t[-1]))} s" if onset is None else f"{onset:.1f} s"
            lines.append(f"| {v} | {slope:.3g} | {when} | {_g(float(tr.theta_hat[-1, 0]))} kg | {err[-1]:.3g} | "
                         f"{_g(tail)} | {r.status} |")
            row = _row("manipulator §12", v, r, f"drift {slope:.3g} per 100 s, onset {when}")
            row.update({"drift_per_100s": slope, "onset": onset, "final_relative_error": float(err[-1])})
            rows.append(row)
            ax[0].semilogy(tr.t, np.where(err > 0, err, np.nan), lw=1, label=v)
            ax[1].semilogy(tr.t, np.where(e > 0, e, np.nan), lw=0.8, label=v)
        ax[0].set_ylabel("‖θ̂ − θ‖ / ‖θ‖ [-]")
        ax[1].axhline(bound, color="k", ls=":", lw=1)
        ax[1].set_ylabel("max_j |q̃_j| [rad]")
        ax[1].set_xlabel("time t [s]")
        for a in ax:
            a.grid(alpha=0.3)
            a.legend(fontsize=8)
        fig.suptitle("6-joint arm at rest, noisy encoders, differentiated velocity: drift, then failure")
        img = _save(fig, out, "arm_drift")
        sudden = _failure_words(facts.get("adaptive"), quiet)
        text = (f"`{name}`: the UR5e holds `home` (no excitation), the payload's 10 estimates start at the truth, the "
                f"encoders have σ_q = {sigma_q:g} rad of noise and the law gets q̇ differentiated from them through a "
                f"{scn.sensors.velocity_cutoff_hz:g} Hz low-pass (docs/THEORY.md, \"Sensors, disturbances and "
                "saturation on the arms\"). " + sudden +
                f"The dead-zone on ‖s‖ has width ε = 3 σ_s = {_g(width)} rad/s, σ_s from the encoder noise through the "
                "velocity filter (adaptive_mj.sensors.surface_noise_std). " + _modification_words(facts) +
                "Drift: least-squares slope of ‖θ̃‖/‖θ‖ over the first 60 s.\n\n"
                + "\n".join(lines) + "\n\n**Failure onsets and their precursors** (docs/METRICS.md, \"Failure "
                f"onsets\"; at the log's 100 Hz; a failure is \"sudden\" only when every precursor comes within "
                f"{SUDDEN_WINDOW:g} s before it):\n\n" + "\n".join(onset_lines) + "\n\n" + img + _status_note(res))
        return SectionReport(text, rows)

    return jobs, analyze

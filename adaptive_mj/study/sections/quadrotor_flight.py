"""Section 18: the aircraft on MuJoCo: the quadrotor with an unknown payload under the geometric, the geometric
adaptive and the L1 geometric laws, on six tasks, and how much of each disturbance and of a control delay each
law takes before the vehicle fails (AdaptiveQuadBench's when2fail and delay margin, on a grid: adaptive_mj.study.
flight; benchmarks/flight_margins.py bisects them).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from adaptive_mj.study.job import SUMMARY_LOG_RATE_HZ
from adaptive_mj.study import flight
from adaptive_mj.study.job import passes
from adaptive_mj.study.sections.common import (Built, SectionReport, _g, _job, _ok, _row, _save, _status_note, plt,
                                               register)

TASKS = (  # (scenario, what it asks)
    ("quadrotor_hover_payload", "take-off and hover at 1 m, unknown 10 g payload"),
    ("quadrotor_lemniscate", "figure-eight (A 0.5 m, ω 1 rad/s), unknown 10 g payload"),
    ("quadrotor_payload_release", "figure-eight, the 10 g payload released at 10 s"),
    ("quadrotor_wind_gust", "hover with the payload, a 2 m/s gust from 8 to 12 s"),
    ("quadrotor_rotor_loss", "figure-eight, rotor 1 loses 30 % of its thrust at 8 s"),
    ("quadrotor_cable_payload", "figure-eight, a 10 g ball on a 0.2 m cable (unmodelled pendulum)"),
)
#: a task run succeeds when it does not crash and its position error stays within this bound after the first 2 s
#: (the take-off and the laws' first adaptation): about the vehicle's own size (92 mm across)
TASK_BOUND = 0.1  # [m]
# the geometric adaptive law with its inertia adapted too (law.adapt_inertia), on the lemniscate only
INERTIA = "geometric_adaptive_inertia"
INERTIA_LABEL = "geometric adaptive + Ĵ (law.adapt_inertia)"
SETTLE = 2.0  # [s]

TITLE = "The aircraft on MuJoCo: a quadrotor with an unknown payload (geometric, adaptive and L1 control)"
CLAIM = ("aircraft are among the systems whose dynamics change with configuration (the lecture's first reasons for "
         "adaptive control): a quadrotor that picks up, drops or swings a payload, loses a rotor's thrust or meets "
         "wind is flown by the same law, which must adapt to it.")


#: the folder, under the bench's logs/, of the margin grid's runs (the report's header names it where it is there)
MARGIN_LOGS = "quadrotor-margins"


@register(18, "quadrotor", TITLE, CLAIM)
def section(quick: bool, logs: Path, duration: float | None = None, full_logs: bool = False) -> Built:
    """The tasks (every law on each), and the margins on a grid (quick: 8 levels, 1 seed; full: 12, 2 seeds);
    duration: cut every task run to this many seconds (for tests). The grid's runs log their summary and a row per
    second (job.SUMMARY_LOG_RATE_HZ; full_logs: every row), their success judged on the full trajectory."""
    dur = [f"simulation.duration={duration}"] if duration is not None else []
    task_jobs = tuple(_job("quadrotor", f"{name.removeprefix('quadrotor_')}-{law}", name, logs,
                           [f"law={law}", *dur], extras=("flight_metrics",),
                           expect="measured" if law == "geometric" else "ok")  # the baseline: the comparison
                      for name, _ in TASKS for law in flight.LAWS) + (
        _job("quadrotor", f"lemniscate-{INERTIA}", "quadrotor_lemniscate", logs,
             ["law=geometric_adaptive", "law.adapt_inertia=true", *dur], extras=("flight_metrics",)),)
    levels, seeds = (8, 1) if quick else (12, 2)
    found = flight.searches()
    extra = [f"simulation.duration={min(duration, flight.RUN_SECONDS)}"] if duration is not None else []
    if not full_logs:
        extra.append(f"log.rate_hz={SUMMARY_LOG_RATE_HZ!r}")
    margin_jobs = tuple(flight.grid_jobs(found, levels, seeds, logs / MARGIN_LOGS, extra))

    def analyze(res, out):
        text, rows = _tasks(res, out)
        margins = flight.grid_results(found, levels, seeds, res)
        text += "\n\n" + _margins_text(margins, levels, seeds)
        return SectionReport(text + _status_note({k: v for k, v in res.items() if k.startswith("quadrotor/")}), rows)

    return task_jobs + margin_jobs, analyze


def _task_figures(r) -> dict:
    """The run's figures: tail RMS and max ‖p_d − p‖ after SETTLE [m], heading [deg], saturation, final m̂ error."""
    tr = r.trajectory
    fm = r.extras.get("flight_metrics") or {}
    e = np.linalg.norm(tr.y_tilde, axis=1)
    after = tr.t >= SETTLE
    crashed = r.crashed
    i = tr.names.index("m")
    m_err = (tr.theta_hat[-1, i] - tr.theta[-1, i]) / tr.theta[-1, i]
    J_err = float(np.linalg.norm(tr.theta_hat[-1, 1:7] - tr.theta[-1, 1:7]) / np.linalg.norm(tr.theta[-1, 1:7]))
    max_after = float(e[after].max()) if after.any() else math.nan
    return {"tail": fm.get("tail_rms_error"), "max": max_after, "heading": fm.get("max_heading_deg"),
            "sat": fm.get("saturation_any"), "m_err": float(m_err), "J_err": J_err, "crashed": crashed,
            "success": passes(r) and max_after <= TASK_BOUND}


def _flown(r) -> bool:
    """A task run with rows to analyse: it completed, or it crashed (its rows up to the crash)."""
    return _ok(r) or (r.crashed and r.trajectory is not None)


def _tasks(res, out: Path) -> tuple[str, list[dict]]:
    lines = ["| task | law | verdict | success | tail RMS ‖e‖ [cm] | max ‖e‖ after 2 s [cm] | max heading [deg] | "
             "a rotor at a limit [%] | final m̂ error | Ĵ error |", "|---|---|---|---|---|---|---|---|---|---|"]
    rows = []
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    for name, _ in TASKS:
        for law in (*flight.LAWS, *((INERTIA,) if name == "quadrotor_lemniscate" else ())):
            tag = f"{name.removeprefix('quadrotor_')}-{law}"
            r = res.get(f"quadrotor/{tag}")
            if r is None or not _flown(r):
                lines.append(f"| {name.removeprefix('quadrotor_')} | {law} | {r.status if r else 'missing'} |||||||")
                if r is not None:
                    rows.append(_row("quadrotor", tag, r))
                continue
            f = _task_figures(r)
            fixed = "" if law in ("geometric_adaptive", INERTIA) else " (fixed)"
            m_text = f"{100 * f['m_err']:+.2g} %{fixed}"
            label = INERTIA_LABEL if law == INERTIA else flight.LAW_LABEL[law]
            lines.append(f"| {name.removeprefix('quadrotor_')} | {label} | {r.status} | "
                         f"{'yes' if f['success'] else ('crashed' if f['crashed'] else 'no')} | "
                         f"{_g(100 * f['tail'] if f['tail'] is not None else None, '.3g')} | "
                         f"{_g(100 * f['max'], '.3g')} | {_g(f['heading'], '.3g')} | "
                         f"{_g(100 * f['sat'] if f['sat'] is not None else None, '.3g')} | {m_text} | "
                         f"{100 * f['J_err']:.3g} %{'' if law == INERTIA else ' (fixed)'} |")
            rows.append(_row("quadrotor", tag, r, f"max ‖e‖ {_g(100 * f['max'], '.3g')} cm"))
            if name == "quadrotor_lemniscate" and law != INERTIA:
                ax = axes[flight.LAWS.index(law)]
                tr = r.trajectory
                ax.plot(tr.ref[:, 0, 0], tr.ref[:, 0, 1], "k--", lw=0.8, label="reference")
                ax.plot(tr.x[:, 0, 0], tr.x[:, 0, 1], lw=1.0, label="flown")
                ax.set_title(f"{flight.LAW_LABEL[law]}: max ‖e‖ {100 * f['max']:.3g} cm after 2 s", fontsize=9)
                ax.set_xlabel("x [m]")
                ax.set_ylabel("y [m]")
                ax.set_aspect("equal")
                ax.legend(fontsize=7)
    figure = _save(fig, out, "quadrotor-lemniscate")
    tasks = "\n".join(f"- `{name}`: {what}" for name, what in TASKS)
    text = (f"**The plant** (`models/quadrotor.xml`): a Crazyflie 2.x as RotorPy models it (30 g, four rotors of "
            f"0.144 N, the thrust-to-weight 1.95), a free body with RotorPy's rotor drag (`opt.wind` is a real wind) "
            f"and motor lag, the payload attached under it by MuJoCo's attach. The laws: the SE(3) geometric "
            f"controller at the bare vehicle's mass and inertia (Lee, Leok & McClamroch 2010), the same with the "
            f"lecture's sliding adaptive law on the translational dynamics (m̂ and a force d̂), and with L1 "
            f"augmentation (predictor, piecewise-constant adaptation, low-pass; Wu et al. 2023); all compiled in "
            f"MuJoCo's control callback. Tasks:\n\n{tasks}\n\nA task run succeeds when it does not crash and "
            f"‖p_d − p‖ stays within {100 * TASK_BOUND:g} cm (about the vehicle's size) after the first {SETTLE:g} s; "
            f"the verdict column is the scenario's own ([success] tail RMS per axis). The Ĵ error is "
            f"‖Ĵ − J‖_F / ‖J‖_F at the end: held at the bare airframe's (its error the payload's share) but by the "
            f"adaptive law with `law.adapt_inertia` (the lecture's sliding law on SO(3), docs/THEORY.md \"The "
            f"inertia\"), whose Ĵ moves without converging on this trajectory: the moment the air puts on the "
            f"fuselage, which no law models, is as large as the inertia's own signal.\n\n" + "\n".join(lines)
            + f"\n\n{figure}")
    return text, rows


def _margins_text(found, levels: int, seeds: int) -> str:
    return (f"**How much each law takes** ({flight.RUN_SECONDS:g} s figure-eights without a payload, "
            f"{seeds} seed(s) of small sensor noise per intensity, {levels} intensities per disturbance on a grid: "
            f"geometric where the range spans a decade, even otherwise; a run fails when it crashes or "
            f"‖p_d − p‖ exceeds {flight.MAX_ERROR:g} m at any time (the bound of AdaptiveQuadBench's delay test only), "
            f"or when its tail is saturated or its body rate oscillates: success.tail_saturation, "
            f"success.oscillation: the rule 'ours' of flight.RULES). *Margin*: the "
            f"largest intensity every seed survived (in brackets the next intensity tried, where one failed); "
            f"*when2fail*: the smallest at which every seed failed (in brackets the last one where one survived): "
            f"the brackets are the resolution. `python benchmarks/flight_margins.py` bisects them to a finer "
            f"resolution, on this Crazyflie and on AdaptiveQuadBench's vehicle (`--airframe both`), under either "
            f"rule (`--rule both`), and runs AdaptiveQuadBench's delay test (`--study delay-test`).\n\n"
            f"**What AdaptiveQuadBench does, and where this differs** (valmik/AdaptiveQuadBench at "
            f"{flight.AQB_COMMIT}, read from its code): it flies a {flight.AQB.vehicle_mass.number:g} kg quadrotor "
            f"(here `plant.model = \"quadrotor_aqb\"`), not the Crazyflie; a trial flies a random "
            f"{flight.AQB.trajectory_time.number:g} s motion primitive and succeeds when its RMS position error is "
            f"below {flight.AQB_RMS_BOUND:g} m, with no crash check (the rule 'aqb', whose runs here fly on past any "
            f"tilt and out of the ground's reach, as RotorPy's do: flight.RULE_RUNS); when2fail raises an intensity "
            f"on a grid of {flight.AQB.intensity_step.number:g} until no trial succeeds. Its "
            f"{flight.AQB_DELAY_TEST.bound.number:g} m bound on the largest error is its delay test's only: a delay "
            f"raised in {1e3 * flight.AQB_DELAY_TEST.step.number:g} ms steps up to "
            f"{flight.AQB_DELAY_TEST.stop.number:g} s over {int(flight.AQB_DELAY_TEST.trajectories.number)} "
            f"trajectories (flight.AQB_DELAY_TEST; here whole physics steps of 2 ms, the circle a lemniscate of its "
            f"size). The margins above hold one disturbance from t = 0 on a lemniscate, bisected or on a grid, and "
            f"fail by the stricter rule 'ours'; AdaptiveQuadBench draws a primitive and a switched disturbance per "
            f"trial (`python benchmarks/aqb_protocol.py` runs that protocol). The disturbances:\n\n"
            + "\n".join(f"- {d.name}: {d.doc}" for d in (*flight.DISTURBANCES, flight.DELAY))
            + "\n\n" + flight.table(found).to_markdown()
            + "\n\nAdaptiveQuadBench's own protocol (its vehicle, random motion primitives, its randomisation: "
              "`python benchmarks/aqb_protocol.py` runs it) draws each trial from these ranges (`flight.AQB`), "
              "each with where this suite differs:\n\n"
            + flight.protocol_text())

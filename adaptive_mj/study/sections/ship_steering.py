"""Section 15: the adaptive heading autopilot on the MuJoCo ship against frozen estimates and a PD autopilot,
with the Nomoto fit at each condition (headings in rad, shown in degrees).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study.sections.common import (Built, SCN, SectionReport, _g, _job, _ok, _row, _save, _status_note, plt,
                                               register)


#: the baselines of the ship section: the same law with its estimates frozen at their start ("frozen": the
#: fit at the first condition), and a PD autopilot (the law's own feedback k s = k psi~' + k lambda psi~, no model)
SHIP_FROZEN = ("law.kind=fixed_nominal", "law.saturation=ignore")
SHIP_PD = SHIP_FROZEN + ("law.nominal={T_over_K=0.0, one_over_K=0.0, alpha_over_K=0.0, rudder_bias=0.0}",)
SHIP_SCENARIOS = (  # (scenario, what changes, its variants)
    ("ship_course_changes", "none (estimates from a rough guess)", ("adaptive", "pd")),
    ("ship_loading", "loading: hull mass and inertia x1.6", ("adaptive", "frozen", "pd")),
    ("ship_speed_change", "propeller thrust x0.25 (speed halves)", ("adaptive", "frozen", "pd")),
    ("ship_wind_waves", "wind yaw moment 2 N m (waves 0.5 N m throughout)", ("adaptive", "frozen", "pd")),
)
_SHIP_OVERRIDES = {"adaptive": (), "frozen": SHIP_FROZEN, "pd": SHIP_PD}


TITLE = "Ship steering on MuJoCo: the adaptive heading autopilot"
CLAIM = ("a ship's dynamics depend strongly on its loading, speed, water depth, wind and waves; an "
         "adaptive autopilot adjusts to them (the sliding law on the heading, with the rudder angle as "
         "input and the Nomoto/Norrbin regressor).")


@register(15, "ship", TITLE, CLAIM)
def section(quick: bool, logs: Path, duration: float | None = None) -> Built:
    """The heading autopilot on the MuJoCo ship (the runs are short: the full and the quick bench alike;
    duration: cut every run to this many seconds, for tests)."""
    dur = [f"simulation.duration={duration}"] if duration is not None else []
    jobs = tuple(_job("ship", f"{name.removeprefix('ship_')}-{v}", name, logs, [*_SHIP_OVERRIDES[v], *dur],
                      expect="ok" if v == "adaptive" else "measured")  # the baselines' verdicts are the comparison
                 for name, _, variants in SHIP_SCENARIOS for v in variants)

    def analyze(res, out):
        parts, rows = [_ship_fits(res)], []
        for name, change, variants in SHIP_SCENARIOS:
            text, r = _ship_scenario(res, name, change, variants, out)
            parts.append(text)
            rows.extend(r)
        return SectionReport("\n\n".join(parts) + _status_note(res), rows)

    return jobs, analyze


def _ship_theta(tr, row: int) -> tuple[float, float, float, float]:
    from adaptive_mj.plants.nomoto import from_theta

    return from_theta(tr.theta[row])


def _ship_fits(res) -> str:
    """The fitted Nomoto parameters at each condition the runs met (read from the logged true theta), with
    the cruise speed of the model at that condition."""
    import mujoco

    from adaptive_mj.plants import ship

    model = mujoco.MjModel.from_xml_path(str(ship.MODEL_PATH))
    prop = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, ship.PROPELLER)
    F0 = float(model.actuator_biasprm[prop, 0])  # [N] the design thrust
    L = 2.0 * float(model.geom_size[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, ship.HULL), 0])  # [m]
    u0 = ship.cruise_speed(model)
    lines = ["| condition | U [m/s] | K [1/s] | T [s] | α [s²] | δ_b [deg] | K' = KL/U | T' = TU/L |",
             "|---|---|---|---|---|---|---|---|"]
    conditions = [(f"light ship, {F0:g} N thrust", "ship_loading", 0, 1.0)]
    conditions += [("loaded (mass, inertia x1.6)", "ship_loading", -1, 1.0),
                   ("thrust x0.25", "ship_speed_change", -1, 0.25), ("wind moment 2 N m", "ship_wind_waves", -1, 1.0)]
    K0 = T0 = None
    for label, name, row, thrust in conditions:
        r = res.get(f"ship/{name.removeprefix('ship_')}-adaptive")
        if r is None or not _ok(r):
            lines.append(f"| {label} | (run {r.status if r else 'missing'}) |||||||")
            continue
        K, T, al, b = _ship_theta(r.trajectory, row)
        model.actuator_biasprm[prop, 0] = F0 * thrust
        U = ship.cruise_speed(model) if thrust != 1.0 else u0
        K0, T0 = (K, T) if K0 is None or T0 is None else (K0, T0)  # (both are None until the first row)
        lines.append(f"| {label} | {U:.3f} | {K:.4f} ({K / K0:.2f}x) | {T:.3f} ({T / T0:.2f}x) | {al:.3g} | "
                     f"{math.degrees(b):.2f} | {K * L / U:.2f} | {T * U / L:.2f} |")
    return ("**The plant** (`models/ship.xml`): a 3 m model-scale hull in MuJoCo's ellipsoid fluid, rudder ±35° at "
            "15°/s, constant-thrust propeller; output the heading ψ [rad], input the commanded rudder angle δ [rad]. "
            "**The truth** is not typed: at each condition the plant fits T ψ̈ + ψ̇ + α ψ̇³ = K (δ + δ_b) to the "
            "hull's own responses to rudder steps of ±5, 10, 20 and 35° (adaptive_mj/plants/ship.py); a run logs "
            "θ = [T/K, 1/K, α/K, δ_b] of that fit, refitted at each event. The fitted parameters at each condition "
            f"(the first row is the reference for the ratios; L = {L:g} m):\n\n" + "\n".join(lines))


def _ship_hard_over() -> tuple[float, float]:
    """The steering gear's ctrlrange [deg] in the bundled model."""
    import mujoco

    from adaptive_mj.plants import ship

    model = mujoco.MjModel.from_xml_path(str(ship.MODEL_PATH))
    lo, hi = model.actuator_ctrlrange[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, ship.STEERING_GEAR)]
    return math.degrees(lo), math.degrees(hi)


def _ship_errors(tr, window) -> tuple[float, float, float]:
    """(max |ψ̃|, RMS ψ̃, max |δ|) over rows `window`, in degrees."""
    e = tr.ref[window, 0] - tr.x[window, 0]
    if not e.size:
        return math.nan, math.nan, math.nan
    return (math.degrees(float(np.abs(e).max())), math.degrees(float(np.sqrt(np.mean(e ** 2)))),
            math.degrees(float(np.abs(tr.u[window]).max())))


CONVERGED = 0.5  # an estimate within 50 % of its fit is reported as converging; beyond, the text says it is not


def _ship_scenario(res, name: str, change: str, variants, out: Path) -> tuple[str, list[dict]]:
    """One scenario's table (heading error before/after its event, rudder, final estimates against the
    fitted truth) and figure (course, heading error, rudder, estimates)."""
    scn = sc.load(SCN / f"{name}.toml")
    t_ev = scn.events[0].t if scn.events else None
    lines = ["| autopilot | status | max \\|ψ̃\\| before / after [deg] | RMS ψ̃ before / after [deg] | "
             "max \\|δ\\| [deg] | final estimates T/K [s²], 1/K [s] (fitted) |", "|---|---|---|---|---|---|"]
    rows, words = [], ""
    fig, ax = plt.subplots(4, 1, figsize=(9, 10), sharex=True, constrained_layout=True)
    for v, style in zip(variants, ["-", "--", ":"], strict=False):
        r = res[f"ship/{name.removeprefix('ship_')}-{v}"]
        if not _ok(r):
            rows.append(_row("ship", f"{name.removeprefix('ship_')}-{v}", r))
            lines.append(f"| {v} | {r.status} |||||")
            continue
        tr = r.trajectory
        split = tr.t < (t_ev if t_ev is not None else tr.t[-1] + 1.0)
        b, a = _ship_errors(tr, split), _ship_errors(tr, ~split)
        (d_hat, a_hat), (d, a_) = tr.theta_hat[-1, :2], tr.theta[-1, :2]
        est = f"{d_hat:.3g}, {a_hat:.3g} ({d:.3g}, {a_:.3g})" if v != "pd" else f"— ({d:.3g}, {a_:.3g})"
        if v == "adaptive":
            off = max(abs(d_hat - d) / abs(d), abs(a_hat - a_) / abs(a_))
            if off > CONVERGED:  # say it where the number is shown: tracking is not identification here
                words = (f" The adaptive autopilot's final estimates are not the fit's (T/K {d_hat:.3g} against "
                         f"{d:.3g} s², 1/K {a_hat:.3g} against {a_:.3g} s: {100 * off:.0f} % off at worst): it "
                         "steers on estimates that do not converge to the ship's parameters "
                         "within this run.")
        lines.append(f"| {v} | {r.status} | {b[0]:.3f} / {_g(a[0], '.3f')} | {b[1]:.3f} / {_g(a[1], '.3f')} | "
                     f"{max(b[2], a[2] if math.isfinite(a[2]) else 0.0):.1f} | {est} |")
        rows.append(_row("ship", f"{name.removeprefix('ship_')}-{v}", r,
                         f"max |ψ̃| after {_g(a[0], '.3f')}°" if t_ev is not None else f"max |ψ̃| {b[0]:.3f}°"))
        deg = np.degrees
        if v == variants[0]:
            ax[0].plot(tr.t, deg(tr.ref[:, 0]), "k", lw=2, alpha=0.3, label="ψ_d")
        ax[0].plot(tr.t, deg(tr.x[:, 0]), style, lw=1, label=f"ψ, {v}")
        ax[1].plot(tr.t, deg(tr.ref[:, 0] - tr.x[:, 0]), style, lw=1, label=v)
        ax[2].plot(tr.t, deg(tr.u), style, lw=1, label=v)
        if v == "adaptive":
            for i, c in ((0, "C0"), (1, "C1")):
                ax[3].plot(tr.t, tr.theta_hat[:, i], c, lw=1.2, label=f"{tr.names[i]} estimate")
                ax[3].plot(tr.t, tr.theta[:, i], c, ls="--", lw=1, label=f"{tr.names[i]} fitted")
            bias = ax[3].twinx()
            bias.plot(tr.t, deg(tr.theta_hat[:, 3]), "C2", lw=1.2, label="rudder_bias estimate")
            bias.plot(tr.t, deg(tr.theta[:, 3]), "C2", ls="--", lw=1, label="rudder_bias fitted")
            bias.set_ylabel("δ_b [deg]", color="C2")
            bias.legend(fontsize=7, loc="lower right")
    ax[0].set_ylabel("course [deg]")
    ax[1].set_ylabel("ψ̃ = ψ_d − ψ [deg]")
    ax[1].set_yscale("symlog", linthresh=0.1)
    ax[2].set_ylabel("rudder δ [deg]")
    for lim in _ship_hard_over():
        ax[2].axhline(lim, color="grey", ls=":", lw=1)
    ax[3].set_ylabel("T/K [s²], 1/K [s]")
    ax[3].set_xlabel("time t [s]")
    for a_ in ax:
        a_.grid(alpha=0.3)
        a_.legend(fontsize=7)
        if t_ev is not None:
            a_.axvline(t_ev, color="grey", ls=":", lw=1)
    fig.suptitle(f"{name}: {change}")
    img = _save(fig, out, name)
    when = f" at t = {t_ev:g} s" if t_ev is not None else ""
    return (f"**`{name}`** — change{when}: {change}. Heading error ψ̃ before and after the change (the whole run when "
            "there is none); the final estimates (frozen: those it held) against the fit at the run's last condition "
            "(K = 1/(1/K), T = (T/K)/(1/K))." + words + "\n\n" + "\n".join(lines) + "\n\n" + img), rows

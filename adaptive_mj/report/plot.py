"""Figures of a run: pure functions of a Trajectory, written headless (Agg)."""
from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np

from adaptive_mj.trajectory import Trajectory

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 (after matplotlib.use("Agg"): figures are drawn headless)


def plot_run(traj: Trajectory, path: str | Path, *, title: str = "", kind: str | None = None) -> Path:
    """Tracking, tracking error, control and s, estimates against truth, V.  Returns the path.

    kind: the plant kind ("heave", "arm", "first_order"), for the units on the axes.
    A run of m joints is drawn by plot_joints."""
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    if traj.joint_names:
        return plot_joints(traj, path, title=title, unit=units.output_unit(kind or "") or "rad")

    yu = units.output_unit(kind or "")
    uu = units.control_unit(kind or "")
    n = traj.x.shape[1]
    su = yu if n == 1 or yu in ("", "-") else f"{yu}/s" if n == 2 else f"{yu}/s²"
    vu = units.lyapunov_unit(kind)

    def lab(text, unit):
        return f"{text} [{unit}]" if unit else text

    n_par = len(traj.names)
    rows = 2 + (n_par + 1) // 2 + (1 if n_par % 2 == 0 else 0)  # V fills the free slot when n_par is odd
    fig = plt.figure(figsize=(11, 2.8 * rows), constrained_layout=True)
    grid = fig.add_gridspec(rows, 2)
    t = traj.t
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t, traj.ref[:, 0], "k--", lw=1, label="$y_d$")
    ax.plot(t, traj.q, lw=1.2, label="$y$")
    ax.set_ylabel(lab("output y", yu))
    ax.legend(loc="upper right")
    ax.set_title(title or "tracking")
    ax = fig.add_subplot(grid[1, 0])
    ax.plot(t, traj.y_tilde, lw=1)
    ax.set_ylabel(lab(r"$\tilde y = y_d - y$", yu))
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, traj.u, lw=1, color="C2", label="u")
    ax.set_ylabel(lab("control u", uu), color="C2")
    ax2 = ax.twinx()
    ax2.plot(t, traj.s, lw=0.8, color="C3", label="s")
    ax2.set_ylabel(lab("sliding variable s", su), color="C3")
    for i, name in enumerate(traj.names):
        ax = fig.add_subplot(grid[2 + i // 2, i % 2])
        ax.plot(t, traj.theta[:, i], "k--", lw=1, label=f"true {name}")
        ax.plot(t, traj.theta_hat[:, i], lw=1.2, label=f"estimate {name}")
        ax.set_ylabel(lab(name, units.param_unit(kind, name)))
        ax.legend(loc="best", fontsize=8)
    ax = fig.add_subplot(grid[-1, :] if n_par % 2 == 0 else grid[-1, 1])
    ax.plot(t, traj.V, lw=1.2, color="C4")
    ax.set_ylabel(lab("Lyapunov V", vu))
    if np.all(traj.V > 0):
        ax.set_yscale("log")
    for a in fig.axes:
        a.grid(alpha=0.3)
        for (te, _label) in traj.meta.get("events", []):
            a.axvline(te, color="grey", lw=0.8, ls=":")
    for a in fig.axes:
        spec = a.get_subplotspec()
        if spec is not None and spec.is_last_row():
            a.set_xlabel("time t [s]")
    fig.axes[-1].set_xlabel("time t [s]")
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_joints(traj: Trajectory, path: str | Path, *, title: str = "", unit: str = "rad") -> Path:
    """A run of m joints (or axes: a quadrotor's x, y, z): tracking error per joint (one panel each up to 6
    joints, else the norm |q̃| and the worst joint) [unit], joint torques (or the named controls), the
    estimates against truth (masses, first moments m·c, inertias, joint terms: one panel per group), and V."""
    t = traj.t
    m = traj.m
    e = traj.joint_errors
    per_joint = m <= 6
    err_rows = (m + 1) // 2 if per_joint else 1
    groups = _param_groups(traj.names)
    rows = err_rows + 1 + (len(groups) + 1) // 2 + 1
    fig = plt.figure(figsize=(11, 2.4 * rows), constrained_layout=True)
    grid = fig.add_gridspec(rows, 2)
    if per_joint:
        for i, name in enumerate(traj.joint_names):
            ax = fig.add_subplot(grid[i // 2, i % 2])
            ax.plot(t, e[:, i], lw=0.8)
            ax.set_ylabel(f"{name}: " + r"$\tilde q$" + f" [{unit}]", fontsize=8)
    else:
        ax = fig.add_subplot(grid[0, :])
        ax.semilogy(t, np.linalg.norm(e, axis=1), lw=0.8, label=r"$|\tilde q|$")
        ax.semilogy(t, np.abs(e).max(axis=1), lw=0.8, label="worst joint")
        ax.set_ylabel(f"tracking error [{unit}]")
        ax.legend(fontsize=8)
    fig.axes[0].set_title(title or "tracking error per joint")
    ax = fig.add_subplot(grid[err_rows, :])
    u = np.asarray(traj.u).reshape(len(t), len(traj.actuators))
    for i, name in enumerate(traj.actuators):
        ax.plot(t, u[:, i], lw=0.7, label=name)
    ax.set_ylabel(r"joint torque $\tau$ [N m]" if not traj.control_names else "control u")
    ax.legend(fontsize=7, ncol=min(len(traj.actuators), 6), loc="upper right")
    for g, (label, idx) in enumerate(groups):
        ax = fig.add_subplot(grid[err_rows + 1 + g // 2, g % 2])
        for k, i in enumerate(idx):
            ax.plot(t, traj.theta[:, i], "--", color=f"C{k % 10}", lw=0.9)
            ax.plot(t, traj.theta_hat[:, i], color=f"C{k % 10}", lw=1.1, label=traj.names[i].split(".")[-1])
        ax.set_ylabel(label, fontsize=8)
        ax.legend(fontsize=7, ncol=3, loc="best", title="estimate (solid), true (dashed)", title_fontsize=7)
    ax = fig.add_subplot(grid[-1, :])
    ax.plot(t, traj.V, lw=1.2, color="C4")
    ax.set_ylabel(r"V = ½ sᵀMs + ½ π̃ᵀΓπ̃ [J]")
    if np.all(traj.V > 0):
        ax.set_yscale("log")
    for a in fig.axes:
        a.grid(alpha=0.3)
        for (te, _label) in traj.meta.get("events", []):
            a.axvline(te, color="grey", lw=0.8, ls=":")
    fig.axes[-1].set_xlabel("time t [s]")
    path = Path(path)
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


def _param_groups(names) -> list[tuple[str, list[int]]]:
    """Parameter indices grouped by kind: mass [kg], first moment [kg m], inertia [kg m²], joint terms."""
    kinds = [("mass m [kg]", ("m",)), ("first moment m·c [kg m]", ("mcx", "mcy", "mcz")),
             ("inertia [kg m²]", ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")),
             ("joint armature [kg m²] / damping [N m s] / Coulomb [N m]", ("armature", "damping", "coulomb"))]
    out = []
    for label, suffixes in kinds:
        idx = [i for i, n in enumerate(names) if n.rstrip("*").rsplit(".", 1)[-1] in suffixes]
        if idx:
            out.append((label, idx))
    rest = [i for i in range(len(names)) if not any(i in g for _, g in out)]
    if rest:
        out.append(("parameters", rest))
    return out

"""Figures of a run: pure functions of a Trajectory, written headless (Agg)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from adaptive_mj.trajectory import Trajectory  # noqa: E402


def plot_run(traj: Trajectory, path: str | Path, *, title: str = "") -> Path:
    """Tracking, tracking error, control and s, estimates against truth, V.  Returns the path."""
    n_par = len(traj.names)
    rows = 2 + (n_par + 1) // 2 + (1 if n_par % 2 == 0 else 0)  # V fills the free slot when n_par is odd
    fig = plt.figure(figsize=(11, 2.8 * rows), constrained_layout=True)
    grid = fig.add_gridspec(rows, 2)
    t = traj.t
    ax = fig.add_subplot(grid[0, :])
    ax.plot(t, traj.ref[:, 0], "k--", lw=1, label="$y_d$")
    ax.plot(t, traj.q, lw=1.2, label="$y$")
    ax.set_ylabel("output y")
    ax.legend(loc="upper right")
    ax.set_title(title or "tracking")
    ax = fig.add_subplot(grid[1, 0])
    ax.plot(t, traj.y_tilde, lw=1)
    ax.set_ylabel(r"$\tilde y = y_d - y$")
    ax = fig.add_subplot(grid[1, 1])
    ax.plot(t, traj.u, lw=1, color="C2", label="u")
    ax.set_ylabel("control u", color="C2")
    ax2 = ax.twinx()
    ax2.plot(t, traj.s, lw=0.8, color="C3", label="s")
    ax2.set_ylabel("sliding variable s", color="C3")
    for i, name in enumerate(traj.names):
        ax = fig.add_subplot(grid[2 + i // 2, i % 2])
        ax.plot(t, traj.theta[:, i], "k--", lw=1, label=f"true {name}")
        ax.plot(t, traj.theta_hat[:, i], lw=1.2, label=f"estimate {name}")
        ax.set_ylabel(name)
        ax.legend(loc="best", fontsize=8)
    ax = fig.add_subplot(grid[-1, :] if n_par % 2 == 0 else grid[-1, 1])
    ax.plot(t, traj.V, lw=1.2, color="C4")
    ax.set_ylabel("Lyapunov V")
    if np.all(traj.V > 0):
        ax.set_yscale("log")
    for a in fig.axes:
        a.grid(alpha=0.3)
        for (te, label) in traj.meta.get("events", []):
            a.axvline(te, color="grey", lw=0.8, ls=":")
    fig.axes[-1].set_xlabel("time t [s]")
    path = Path(path)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path

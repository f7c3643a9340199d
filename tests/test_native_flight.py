"""The quadrotor's compiled callback (plants/quadrotor_kernel.py, driven by adaptive_mj.sim.native_mujoco) against
the Python callback: the same rows,
bit for bit, for the three flight laws (L1's filters included), through noise, a control delay, sampled-data
control, events that change forces, wind and mass, the robust modifications, and crashes (mid-chunk and at a
chunk's end)."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.setup import scenario as sc
from adaptive_mj.sim import loop
from adaptive_mj.runs.runner import execute

NOISE = "noise={std={p=0.001, v=0.01, phi=0.001, omega=0.01}, seed=3}"
FORCES = ("events=[{t=1.0, kind='external_force', force=[0.01, 0, 0], torque=[0, 0, 1e-5]}, "
          "{t=2.0, kind='wind', velocity=[1.0, 0, 0]}, {t=2.5, kind='payload_mass', value=0.015}, "
          "{t=2.8, kind='payload_swap', payload='quad_cable'}, {t=3.0, kind='payload_release'}]")
CASES = {
    "lemniscate": ("quadrotor_lemniscate", ["simulation.duration=3"]),
    "noise, delay, events": ("quadrotor_lemniscate", [NOISE, "simulation.control_delay=7", FORCES,
                                                      "simulation.duration=4"]),
    "sampled at 10 ms": ("quadrotor_wind_gust", ["control.period=0.01", "simulation.duration=3", "events=[]"]),
    "geometric, rotor loss": ("quadrotor_rotor_loss", [
        "law=geometric", "simulation.duration=3", "events=[{t=1.0, kind='rotor_efficiency', rotor=2, value=0.6}]"]),
    "leakage, projection, dead-zone": ("quadrotor_hover_payload", [
        "law.sigma=0.01", "law.e_modification=0.1", "law.projection={m=[0.02, 0.035]}",
        "law.dead_zone={width=0.001}", "simulation.duration=4"]),
    "cable payload": ("quadrotor_cable_payload", ["simulation.duration=3"]),
    "inertia adapted, noise, delay, events": ("quadrotor_lemniscate", [
        "law.adapt_inertia=true", "law.gamma_j=1e3", "law.sigma=0.01", NOISE, "simulation.control_delay=3", FORCES,
        "simulation.duration=4"]),
    "l1, noise, delay, events": ("quadrotor_lemniscate", ["law=l1_geometric", NOISE, "simulation.control_delay=5",
                                                          FORCES, "simulation.duration=4"]),
    "l1, rotor loss": ("quadrotor_rotor_loss", ["law=l1_geometric", "simulation.duration=3",
                                                "events=[{t=1.0, kind='rotor_efficiency', rotor=3, value=0.7}]"]),
    "yaw-last past the one-rotor limit": ("quadrotor_rotor_loss", [
        "simulation.duration=3", "events=[{t=1.0, kind='rotor_efficiency', rotor=1, value=0.45}]"]),
    "exact-clip past the one-rotor limit": ("quadrotor_rotor_loss", [
        "law.allocation='exact_clip'", "simulation.duration=3",
        "events=[{t=1.0, kind='rotor_efficiency', rotor=1, value=0.45}]"]),
    "crash mid-chunk": ("quadrotor_lemniscate", ["plant.payload_mass=0.05", "simulation.duration=5"]),
    "crash under sampled control": ("quadrotor_lemniscate", ["plant.payload_mass=0.05", "simulation.duration=5",
                                                             "control.period=0.01"]),
    "divergence before a crash": ("quadrotor_lemniscate", ["plant.payload_mass=0.05", "simulation.duration=5",
                                                           "simulation.state_bound=1.3"]),
    "tilt crash": ("quadrotor_rotor_loss", ["plant.crash_tilt=2", "simulation.duration=3",
                                            "events=[{t=0.5, kind='rotor_efficiency', rotor=1, value=0.7}]"]),
}


def _both(name, over):
    runs = []
    for python in (True, False):
        scn = sc.load(sc.SCENARIOS_DIR / f"{name}.toml",
                      overrides=[*over, *(["simulation.python_callback=true"] if python else [])])
        runs.append(execute(scn))
    return runs


@pytest.mark.parametrize("case", list(CASES))
def test_the_compiled_callback_gives_the_python_path_s_rows_bit_for_bit(case):
    name, over = CASES[case]
    py, nat = _both(name, over)
    assert py.trajectory.meta["native"] is False and nat.trajectory.meta["native"] is True
    assert (py.summary["status"], py.summary["reason"]) == (nat.summary["status"], nat.summary["reason"])
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        a, b = getattr(py.trajectory, field), getattr(nat.trajectory, field)
        assert a.shape == b.shape and np.array_equal(a, b), field
    if case in ("crash mid-chunk", "crash under sampled control", "tilt crash"):
        assert nat.summary["status"] == "crashed" and nat.summary["reason"].startswith("crashed at t = ")
    if case == "divergence before a crash":  # the state bound is passed on the way down, before the ground
        assert nat.summary["status"] == "diverged" and "beyond the bound 1.3" in nat.summary["reason"]


def test_a_crash_at_a_chunk_s_last_step_ends_the_run_there(monkeypatch):
    """The crash the mid-chunk case finds, with chunks cut to end exactly on the step that crashed: the loop's
    check after the chunk (not the callback's at the next step) ends the run, with the same rows."""
    name, over = CASES["crash mid-chunk"]
    py, _ = _both(name, over)
    steps = len(py.trajectory)
    monkeypatch.setattr(loop, "NATIVE_CHUNK", steps)
    scn = sc.load(sc.SCENARIOS_DIR / f"{name}.toml", overrides=over)
    nat = execute(scn)
    assert nat.trajectory.meta["native"] is True and len(nat.trajectory) == steps
    assert nat.summary["reason"] == py.summary["reason"]
    assert np.array_equal(nat.trajectory.x, py.trajectory.x)

"""The pre-flight check's delay figure for a flight law (issue 52, item 4b): the attitude loop's delay margin from
its computed crossover and phase margin, not the first-order bound μh < 2 sin(π/(2(2D + 1))), which passed 14 steps
of 2 ms on the bundled quadrotor. The loop's numbers are computed here again, independently: the inertia and the
rotor lag read from the compiled model with MuJoCo's arrays, the loop's frequency response scanned with numpy."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from adaptive_mj.laws import flight
from adaptive_mj.plants import quadrotor
from adaptive_mj.runs.runner import control_timing
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim import preflight


def _scan(J: float, kR: float, kW: float, tau: float) -> tuple[float, float, float]:
    """(ω_c [rad/s], PM [deg], delay margin [s]) of L(jω) = (k_Ω jω + k_R)/(J (jω)² (τ jω + 1)) from a dense
    logarithmic scan: the crossover interpolated in log ω where |L| passes 1, the phase there."""
    w = np.logspace(0, 4, 400001)
    s = 1j * w
    L = (kW * s + kR) / (J * s ** 2 * (tau * s + 1))
    mag = np.abs(L)
    i = int(np.argmax(mag < 1.0))
    lw = np.interp(0.0, [np.log(mag[i]), np.log(mag[i - 1])], [np.log(w[i]), np.log(w[i - 1])])
    wc = float(np.exp(lw))
    Lc = (kW * 1j * wc + kR) / (J * (1j * wc) ** 2 * (tau * 1j * wc + 1))
    pm = 180.0 + math.degrees(float(np.angle(Lc)))
    return wc, pm, math.radians(pm) / wc


def _model_numbers() -> tuple[float, float]:
    """(J_xx [kg m²], τ_m [s]) of the bundled quadrotor, read from the compiled model's arrays."""
    model = quadrotor.load().model
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "quad")
    taus = {float(model.actuator_dynprm[a, 0]) for a in range(model.nu)
            if model.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_FILTER}
    assert len(taus) == 1
    return float(min(model.body_inertia[body])), taus.pop()


def test_the_attitude_loop_s_margins_against_a_frequency_scan():
    J, tau = _model_numbers()
    kR, kW = flight.KR.default, flight.KW.default
    for lag in (0.0, tau):
        wc, pm, dm = preflight.loop_margins(J, kR, kW, lag)
        swc, spm, sdm = _scan(J, kR, kW, lag)
        assert wc == pytest.approx(swc, rel=1e-5)
        assert math.degrees(pm) == pytest.approx(spm, abs=1e-3)
        assert dm == pytest.approx(sdm, rel=1e-4)
    # the figures of the notes (RotorPy's attitude gains on its Crazyflie): without the lag, and with τ_m = 5 ms
    wc, pm, dm = preflight.loop_margins(J, kR, kW, 0.0)
    assert (round(wc, 1), round(math.degrees(pm), 1), round(1e3 * dm, 1)) == (48.2, 76.4, 27.7)
    assert tau == 0.005 and round(1e3 * preflight.loop_margins(J, kR, kW, tau)[2], 1) == 23.3


def _check(delay: int, *overrides: str) -> preflight.Preflight:
    scn = sc.load(sc.SCENARIOS_DIR / "quadrotor_rotor_loss.toml",  # the bundled vehicle, no payload
                  overrides=[f"simulation.control_delay={delay}", *overrides])
    s = build(scn)
    return preflight.check(s.plant, s.law, s.reference, duration=scn.simulation.duration,
                           timing=control_timing(scn, s))


def test_fourteen_steps_of_2_ms_are_past_the_bundled_vehicle_s_delay_margin():
    J, tau = _model_numbers()
    margin = _scan(J, flight.KR.default, flight.KW.default, tau)[2]
    pre = _check(14)
    assert pre.measure == "delay" and pre.limit == pytest.approx(margin, rel=1e-4)
    assert pre.figure == pytest.approx(14 * 0.002 + 0.001)  # the delay line's 14 steps and the hold's half step
    assert not pre.ok
    line = pre.line()
    assert "delay margin of 23.3 ms" in line and "the run's delay of 29 ms is past it" in line
    assert "simulation.control_delay <= 11 steps" in line
    # the first-order bound it replaces passed those 14 steps: μh = 0.0505 < 2 sin(π/58) = 0.108 (a 61 ms limit)
    _, limit, _ = preflight.step_limit(control_timing(*(lambda scn: (scn, build(scn)))(
        sc.load(sc.SCENARIOS_DIR / "quadrotor_rotor_loss.toml", overrides=["simulation.control_delay=14"]))), 4)
    J_true = float(np.linalg.eigvalsh(np.diag(quadrotor.load().true_theta()[1:4])).min())
    mu = float(np.abs(np.roots([J_true, flight.KW.default, flight.KR.default])).max())
    assert mu * 0.002 < limit


@pytest.mark.parametrize("delay", [10, 11, 12, 14])
def test_the_delay_figure_s_edge(delay):
    """The margin is 23.35 ms: 11 steps (22 ms + the hold's 1 ms = 23 ms) pass, 12 (25 ms) do not."""
    pre = _check(delay)
    assert pre.figure == pytest.approx(delay * 0.002 + 0.001)
    assert pre.ok is (delay <= 11)


def test_no_delay_keeps_the_step_s_stability_check():
    pre = _check(0)
    assert pre.measure == "rate" and pre.ok

"""The analytic twin reproduces the MuJoCo plant step for step when the
regressor covers every force (heave without water viscosity; the arm)."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.laws import SlidingAdaptiveLaw
from adaptive_mj.sim.loop import run
from adaptive_mj.plants import arm, twin
from adaptive_mj.reference import Cosine, Sine

RK4 = mujoco.mjtIntegrator.mjINT_RK4
EULER = mujoco.mjtIntegrator.mjINT_EULER
# The issue asks for RMS <= 1e-6; the measured difference is ~1e-16 (round-off),
# while water viscosity alone (the one unmodelled force) gives ~1e-6 over 10 s.
# So the matched cases are also held to a bound far below that effect.
TIGHT = 1e-10


def _compare(plant, make_law, reference, theta_hat0, duration):
    tw = twin.twin_of(plant)
    assert tw.dt == plant.dt and tw.ctrl_range == plant.ctrl_range
    np.testing.assert_array_equal(tw.true_theta(), plant.true_theta())
    np.testing.assert_array_equal(tw.observe(), plant.observe())
    a = run(plant, make_law(plant.form), reference, duration=duration, theta_hat0=theta_hat0)
    b = run(tw, make_law(tw.form), reference, duration=duration, theta_hat0=theta_hat0)
    assert a.status == b.status == "ok" and len(a) == len(b) == int(round(duration / plant.dt))
    np.testing.assert_array_equal(a.t, b.t)
    rms = float(np.sqrt(np.mean(np.sum((a.x - b.x) ** 2, axis=1))))
    return a, b, rms


@pytest.mark.parametrize("integrator", [RK4, EULER], ids=["rk4", "euler"])
def test_twin_matches_mujoco_heave(make_heave, heave_gains, integrator):
    plant = make_heave(viscosity=0.0, integrator=integrator, x0=[1.0, 0.0])
    expected = twin.Integrator.RK4 if integrator == RK4 else twin.Integrator.EULER
    assert twin.twin_of(plant).integrator is expected
    duration = 10.0 if integrator == RK4 else 3.0
    a, b, rms = _compare(plant, lambda f: SlidingAdaptiveLaw(f, **heave_gains), Cosine(),
                         [0.0, 0.0, 0.0], duration)
    print(f"heave {expected.value}: RMS state difference twin vs MuJoCo = {rms:.3g}")
    assert rms <= 1e-6  # the bound
    assert rms <= TIGHT
    np.testing.assert_allclose(a.theta_hat, b.theta_hat, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(a.u, b.u, rtol=1e-6, atol=1e-6)
    assert np.max(np.abs(a.x[:, 1])) > 0.5  # the run actually moved


def test_twin_matches_mujoco_arm_with_payload(arm_gains):
    plant = arm.load(payload_mass=1.0)
    assert plant.model.opt.integrator == RK4
    plant.set_state([0.0, 0.0])
    theta0 = arm.load().true_theta()
    a, b, rms = _compare(plant, lambda f: SlidingAdaptiveLaw(f, **arm_gains),
                         Sine(amplitude=0.8, omega=1.5), theta0, 10.0)
    print(f"arm rk4: RMS state difference twin vs MuJoCo = {rms:.3g}")
    assert rms <= 1e-6  # the bound
    assert rms <= TIGHT
    np.testing.assert_allclose(a.theta_hat, b.theta_hat, rtol=1e-6, atol=1e-6)
    assert np.max(np.abs(a.x[:, 0])) > 0.5


def test_twin_with_viscosity_differs_measurably(make_heave, heave_gains):
    """Control for the tests above: the viscous force the regressor does not model
    is visible at the TIGHT resolution, so agreement there is not an accident."""
    plant = make_heave(x0=[1.0, 0.0])  # water viscosity on
    _, _, rms = _compare(plant, lambda f: SlidingAdaptiveLaw(f, **heave_gains), Cosine(),
                         [0.0, 0.0, 0.0], 2.0)
    print(f"heave with viscosity: RMS twin vs MuJoCo = {rms:.3g}")
    assert rms > 100 * TIGHT

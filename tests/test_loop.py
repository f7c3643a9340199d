"""The closed loop: callback hygiene, estimates integrated once per physics
step (RK4 stages included), policy call counts, events, divergence."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from adaptive_mj.laws import Law, LawStep, SlidingAdaptiveLaw
from adaptive_mj.sim.loop import Event, run
from adaptive_mj.plants import arm, heave, twin
from adaptive_mj.plants.mujoco_plant import compile_xml_path
from adaptive_mj.reference import Cosine

RK4 = mujoco.mjtIntegrator.mjINT_RK4
EULER = mujoco.mjtIntegrator.mjINT_EULER


class ConstantRateLaw(Law):
    """u = 0 and theta_hat_dot = c whatever the state; records every call."""

    def __init__(self, names, rate, u=0.0):
        self.order = 2
        self.names = tuple(names)
        self.rate = np.asarray(rate, dtype=float)
        self.u = u
        self.calls = []  # (t, x copy, theta_hat copy)

    def __call__(self, t, x, ref, theta_hat):
        self.calls.append((t, np.array(x), np.array(theta_hat)))
        return LawStep(self.u, self.rate.copy(), 0.0, 0.0)

    def lyapunov(self, s, theta_hat, theta):
        return np.zeros(len(s))


class CountingLaw(Law):
    """Wraps a law and counts its calls."""

    def __init__(self, inner):
        self.inner, self.order, self.names, self.n = inner, inner.order, inner.names, 0

    def __call__(self, *args):
        self.n += 1
        return self.inner(*args)

    def lyapunov(self, *args):
        return self.inner.lyapunov(*args)


class Boom(RuntimeError):
    pass


class ExplodingLaw(ConstantRateLaw):
    def __init__(self, after):
        super().__init__(("d", "b", "c"), np.zeros(3))
        self.after = after

    def __call__(self, t, x, ref, theta_hat):
        if len(self.calls) >= self.after:
            raise Boom(f"law failed at t={t}")
        return super().__call__(t, x, ref, theta_hat)


def _heave_twin(integrator):
    return twin.TwinPlant(heave.heave_form(9.81), [37.0, 60.0, 1.0], dt=1e-3,
                          integrator=integrator, x0=[1.0, 0.0])


PLANTS = {
    "mujoco_rk4": lambda make_heave: make_heave(integrator=RK4, x0=[1.0, 0.0]),
    "mujoco_euler": lambda make_heave: make_heave(integrator=EULER, x0=[1.0, 0.0]),
    "twin_rk4": lambda make_heave: _heave_twin(twin.Integrator.RK4),
    "twin_euler": lambda make_heave: _heave_twin(twin.Integrator.EULER),
}
STAGES = {"mujoco_rk4": 4, "mujoco_euler": 1, "twin_rk4": 4, "twin_euler": 1}


# ----------------------------------------------------------------- callback hygiene
def _sentinel(model, data):  # pragma: no cover - replaced during the run
    raise AssertionError("the sentinel callback must not run during adaptive_mj.run")


def test_callback_restored_after_a_run(make_heave, heave_gains):
    plant = make_heave(x0=[1.0, 0.0])  # compile before installing any callback
    law = SlidingAdaptiveLaw(plant.form, **heave_gains)
    mujoco.set_mjcb_control(_sentinel)
    try:
        tr = run(plant, law, Cosine(), duration=0.05, theta_hat0=[0, 0, 0])
        assert mujoco.get_mjcb_control() is _sentinel
    finally:
        mujoco.set_mjcb_control(None)
    assert tr.status == "ok" and len(tr) == 50


def test_callback_restored_and_exception_propagates_from_the_law(make_heave):
    plant = make_heave(x0=[1.0, 0.0])
    law = ExplodingLaw(after=4 * 10 + 2)  # fails in the middle of step 11's RK4 stages
    mujoco.set_mjcb_control(_sentinel)
    try:
        with pytest.raises(Boom, match="law failed"):
            run(plant, law, Cosine(), duration=1.0, theta_hat0=[0, 0, 0])
        assert mujoco.get_mjcb_control() is _sentinel
    finally:
        mujoco.set_mjcb_control(None)
    # the run stopped inside step 10 (MuJoCo leaves data at the failing RK4 stage)
    assert 10 * plant.dt - 1e-12 <= plant.time < 11 * plant.dt
    assert len(law.calls) == 42
    # and with nothing installed beforehand, nothing is left installed
    with pytest.raises(Boom):
        run(make_heave(x0=[1.0, 0.0]), ExplodingLaw(after=0), Cosine(), duration=1.0, theta_hat0=[0, 0, 0])
    assert mujoco.get_mjcb_control() is None


# ----------------------------------------------------------------- estimates once per step
@pytest.mark.parametrize("kind", PLANTS)
def test_estimates_advance_exactly_once_per_step(kind, make_heave):
    plant = PLANTS[kind](make_heave)
    c = np.array([0.5, -2.0, 3.0])
    theta0 = np.array([1.0, 2.0, -1.0])
    law = ConstantRateLaw(("d", "b", "c"), c)
    n = 300
    tr = run(plant, law, Cosine(), duration=(n + 1) * plant.dt, theta_hat0=theta0)
    assert tr.status == "ok" and len(tr) == n + 1
    k = np.arange(n + 1)[:, None]
    # row k holds the estimate at the start of step k, i.e. after k steps
    np.testing.assert_allclose(tr.theta_hat, theta0 + k * plant.dt * c, rtol=0, atol=1e-12)
    # the policy ran `stages` times per step: 4 under RK4, 1 under Euler
    stages = STAGES[kind]
    assert plant.stages == stages
    assert len(law.calls) == stages * (n + 1)
    # and each stage saw the RK4 stage estimate at the RK4 stage time
    h = plant.dt
    offsets = (0.0, 0.5, 0.5, 1.0)[:stages]
    for step in (0, 1, 137, n):
        for i, a in enumerate(offsets):
            t, _, th = law.calls[stages * step + i]
            assert t == pytest.approx(step * h + a * h, abs=1e-12)
            np.testing.assert_allclose(th, theta0 + (step + a) * h * c, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind", PLANTS)
def test_policy_call_count_with_a_real_law(kind, make_heave, heave_gains):
    plant = PLANTS[kind](make_heave)
    law = CountingLaw(SlidingAdaptiveLaw(plant.form, **heave_gains))
    tr = run(plant, law, Cosine(), duration=0.2, theta_hat0=[0, 0, 0])
    assert len(tr) == 200
    assert law.n == STAGES[kind] * 200


@pytest.mark.parametrize("built, switched", [(RK4, EULER), (EULER, RK4)], ids=["rk4->euler", "euler->rk4"])
def test_integrator_changed_on_a_loaded_plant(built, switched, make_heave):
    """Regression (was a bug): MujocoPlant read the stage
    count from model.opt.integrator once, in __init__. Setting the integrator on
    plant.model afterwards (the same way scenarios set viscosity) then breaks the
    loop: RK4 -> Euler raises RuntimeError ("called the controller 1 times in a
    step, expected 4"); Euler -> RK4 silently integrates the estimates with Euler
    while MuJoCo integrates the plant with RK4 (stages 2-4 get the stale θ̂_k)."""
    plant = make_heave(integrator=built, x0=[1.0, 0.0])
    plant.model.opt.integrator = switched
    plant.model_changed()
    c = np.array([0.5, -2.0, 3.0])
    law = ConstantRateLaw(("d", "b", "c"), c)
    tr = run(plant, law, Cosine(), duration=0.02, theta_hat0=[0, 0, 0])
    stages = 4 if switched == RK4 else 1
    assert len(law.calls) == stages * len(tr)
    offsets = (0.0, 0.5, 0.5, 1.0)[:stages]
    for i, a in enumerate(offsets):  # step 3's stage estimates
        np.testing.assert_allclose(law.calls[3 * stages + i][2], (3 + a) * plant.dt * c, atol=1e-12)


def test_run_rejects_mismatched_law_and_estimates(make_heave, heave_gains):
    plant = make_heave()
    law = SlidingAdaptiveLaw(plant.form, **heave_gains)
    with pytest.raises(ValueError, match="theta_hat0 must have 3 entries"):
        run(plant, law, Cosine(), duration=0.01, theta_hat0=[0, 0])
    first = twin.lecture_first_order_form()
    from adaptive_mj.laws import FirstOrderAdaptiveLaw

    with pytest.raises(ValueError, match="law of order 1 on a plant of order 2"):
        run(plant, FirstOrderAdaptiveLaw(first, k=1, gamma=1), Cosine(), duration=0.01, theta_hat0=[0, 0])
    with pytest.raises(ValueError, match="rng"):
        run(plant, law, Cosine(), duration=0.01, theta_hat0=[0, 0, 0], noise_std=[0.01, 0.01])
    assert mujoco.get_mjcb_control() is None


# ----------------------------------------------------------------- events
def test_event_changes_the_true_parameters_at_its_time(arm_gains):
    plant = arm.load()
    heavy = arm.load(payload_mass=1.0).true_theta()
    nominal = plant.true_theta().copy()
    law = SlidingAdaptiveLaw(plant.form, **arm_gains)
    event = Event(0.1, "payload 1 kg", lambda p: p.set_body_mass("payload/body", 1.0))
    tr = run(plant, law, Cosine(amplitude=0.3), duration=0.2, theta_hat0=nominal, events=[event])
    before, after = tr.t < 0.1 - 1e-9, tr.t >= 0.1 - 1e-9
    assert before.sum() == 100 and after.sum() == 100
    np.testing.assert_array_equal(tr.theta[before], np.broadcast_to(nominal, (100, 4)))
    np.testing.assert_allclose(tr.theta[after], np.broadcast_to(heavy, (100, 4)), rtol=1e-12)


# ----------------------------------------------------------------- divergence
def test_twin_beyond_state_bound_is_reported_diverged():
    plant = _heave_twin(twin.Integrator.RK4)  # lecture-scale numbers, no actuator limit
    law = ConstantRateLaw(("d", "b", "c"), np.zeros(3), u=1e6)
    tr = run(plant, law, Cosine(), duration=10.0, theta_hat0=[0, 0, 0], state_bound=100.0)
    assert tr.status == "diverged"
    assert "beyond the bound 100" in tr.reason
    assert 1 <= len(tr) < 10_000  # stopped early
    assert np.all(np.abs(tr.x) <= 100.0)  # recorded rows are the ones before the breach
    assert np.any(np.abs(plant.observe()) > 100.0)
    assert len(tr.V) == len(tr.theta_hat) == len(tr.u) == len(tr)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy overflow on the way to inf
def test_twin_finite_time_blow_up_is_reported_diverged():
    """x' = sin x - a x + b x² with u = 0 escapes to infinity from x0 = 3."""
    form = twin.lecture_first_order_form()
    plant = twin.TwinPlant(form, [2.0, 1.5], dt=1e-3, x0=[3.0])
    law = ConstantRateLaw(("a", "b"), np.zeros(2))
    law.order = 1
    tr = run(plant, law, Cosine(), duration=5.0, theta_hat0=[0, 0])
    assert tr.status == "diverged"
    assert tr.reason.startswith("non-finite state")
    assert len(tr) < 2000


def test_mujoco_instability_is_reported_diverged(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo appends its warnings to ./MUJOCO_LOG.TXT
    model = compile_xml_path(heave.MODEL_PATH)
    model.actuator_ctrllimited[:] = 0  # let a huge command through to MuJoCo
    plant = heave.HeavePlant(model)
    assert plant.ctrl_range is None
    law = ConstantRateLaw(("d", "b", "c"), np.zeros(3), u=1e15)
    tr = run(plant, law, Cosine(), duration=1.0, theta_hat0=[0, 0, 0])
    assert tr.status == "diverged"
    assert "mjWARN_BADCTRL" in tr.reason
    assert len(tr) < 1000
    assert mujoco.get_mjcb_control() is None


def test_non_finite_control_is_reported_diverged(make_heave, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # MuJoCo appends its warnings to ./MUJOCO_LOG.TXT
    law = ConstantRateLaw(("d", "b", "c"), np.zeros(3), u=math.nan)
    tr = run(make_heave(x0=[0.0, 0.0]), law, Cosine(), duration=1.0, theta_hat0=[0, 0, 0])
    assert tr.status == "diverged" and "non-finite control" in tr.reason
    assert len(tr) == 1

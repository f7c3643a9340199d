"""The native (numba-compiled) control callback runs the same law code as the
Python path: trajectories agree to 1e-12 (here: bit for bit), including noise,
events, dead-zone, baselines, Euler, and where a run diverges."""
import numpy as np
import pytest

from adaptive_mj import run

from adaptive_mj.sim import native_mujoco as native
from adaptive_mj.laws import DeadZone, DeadZoneOn, FixedNominalLaw, Law, RobustSlidingLaw, SlidingAdaptiveLaw
from adaptive_mj.sim.loop import Event
from adaptive_mj.plants import arm, heave
from adaptive_mj.reference import Cosine, SumOfSines

FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")


def both(make_plant, make_law, reference, **kw):
    out = []
    for nat in (False, True):
        plant = make_plant()
        law = make_law(plant)
        kw2 = dict(kw)
        if "noise_std" in kw:
            kw2["rng"] = np.random.default_rng(5)
        if "events" in kw:
            kw2["events"] = kw["events"]()
        out.append(run(plant, law, reference, native=nat, **kw2))
    return out


def assert_same(a, b, tol=1e-12):
    assert a.status == b.status and a.reason == b.reason
    assert len(a) == len(b)
    for f in FIELDS:
        np.testing.assert_allclose(getattr(b, f), getattr(a, f), rtol=0, atol=tol, err_msg=f)
    assert b.meta["native"] and not a.meta["native"]


def heave_plant(integrator=None, x0=(1.0, 0.0)):
    def make():
        p = heave.load()
        if integrator is not None:
            p.model.opt.integrator = integrator
        p.set_state(list(x0))
        return p
    return make


GAMMA = [0.0025, 0.002, 0.5]


@pytest.mark.parametrize("integrator", [None, 0], ids=["rk4", "euler"])
def test_heave_adaptive_native_matches_python(integrator):
    a, b = both(heave_plant(integrator), lambda p: SlidingAdaptiveLaw(p.form, lam=5, k=200, gamma=GAMMA), Cosine(),
                duration=3.0, theta_hat0=[0, 0, 0])
    assert_same(a, b)


def test_noise_dead_zone_and_tracking_error_variant():
    for on in (DeadZoneOn.S, DeadZoneOn.TRACKING_ERROR):
        a, b = both(heave_plant(x0=(0.0, 0.0)), lambda p, on=on: SlidingAdaptiveLaw(
            p.form, lam=5, k=200, gamma=GAMMA, dead_zone=DeadZone(0.02, on)), Cosine(amplitude=0.0),
            duration=2.0, theta_hat0=[37, 60, 1], noise_std=[0.001, 0.01])
        assert_same(a, b)


def test_baselines_native_match_python():
    nominal = [30.0, 45.0, 1.5]
    for make in (lambda p: FixedNominalLaw(p.form, lam=5, k=200),
                 lambda p: RobustSlidingLaw(p.form, lam=5, k=200, K=30.0, boundary_layer=0.005)):
        a, b = both(heave_plant(), make, Cosine(), duration=2.0, theta_hat0=nominal)
        assert_same(a, b)


def test_arm_with_payload_swap_event():
    def plant():
        p = arm.load()
        p.set_state([0.0, 0.0])
        return p

    theta0 = arm.load().true_theta()
    events = lambda: [Event(0.7, "swap", lambda p: p.set_body_mass("payload/body", 2.0))]  # noqa: E731 (a one-line local converter)
    a, b = both(plant, lambda p: SlidingAdaptiveLaw(p.form, lam=10, k=5, gamma=[0.16, 0.07, 0.025, 0.075]),
                SumOfSines((0.4, 0.3, 0.2), (0.8, 1.9, 3.7), (0.0, 0.0, 0.0)), duration=1.5, theta_hat0=theta0,
                events=events)
    assert_same(a, b)
    assert b.meta["events"] == [(b.t[700], "swap")]


@pytest.mark.parametrize("kind", ["sine", "step"])
def test_a_time_varying_disturbance_and_a_force_event_give_the_python_path_s_rows_bit_for_bit(kind):
    """The disturbance force (force_offset + d(t) per step, as MujocoPlant.step adds them) prepared per chunk and
    written into qfrc_applied by the callback: the same rows as the Python path, across a constant_force event."""
    def plant():
        p = heave_plant()()
        p.disturbance = ((lambda t: 20.0 * float(np.sin(2.0 * t + 0.3))) if kind == "sine"
                         else (lambda t: 15.0 if t >= 0.77 else 0.0))
        return p

    def push(p):
        p.force_offset += 5.0

    a, b = both(plant, lambda p: SlidingAdaptiveLaw(p.form, lam=5, k=200, gamma=GAMMA), Cosine(), duration=2.5,
                theta_hat0=[0, 0, 0], events=lambda: [Event(1.3, "push", push)])
    np.testing.assert_array_equal(b.u, a.u)
    assert_same(a, b, tol=0.0)
    calm = heave_plant()()
    c = run(calm, SlidingAdaptiveLaw(calm.form, lam=5, k=200, gamma=GAMMA), Cosine(), duration=2.5,
            theta_hat0=[0, 0, 0], native=True)
    assert np.max(np.abs(c.u - b.u)) > 1.0  # the callback applied the disturbance: the thrust answers it


def test_divergence_is_found_at_the_same_step():
    a, b = both(heave_plant(x0=(0.0, 0.0)), lambda p: SlidingAdaptiveLaw(p.form, lam=5, k=200, gamma=GAMMA),
                Cosine(), duration=3.0, theta_hat0=[0, 0, 0], state_bound=0.5)
    assert a.status == "diverged" and "beyond the bound" in a.reason
    assert_same(a, b)


def test_native_is_chosen_only_where_supported():
    p = heave.load()
    law = SlidingAdaptiveLaw(p.form, lam=5, k=200, gamma=GAMMA)
    assert native.supported(p, law)
    p.disturbance = lambda t: 1.0
    assert native.supported(p, law)  # a time-varying disturbance: evaluated per chunk, applied by the callback

    class UserLaw(Law):  # a user's own law in plain Python is not native (Law's default): Python path
        order, names = 2, ("d", "b", "c")

        def __call__(self, t, x, ref, theta_hat):
            return law(t, x, ref, theta_hat)

        def lyapunov(self, s, th, theta):
            return law.lyapunov(s, th, theta)

    p = heave.load()
    assert not native.supported(p, UserLaw())
    p.set_state([1.0, 0.0])
    tr = run(p, UserLaw(), Cosine(), duration=0.5, theta_hat0=[0, 0, 0])
    assert tr.status == "ok" and not tr.meta["native"]


# -- composite adaptation (laws.composite) on the compiled callback ---------------------------------------------

def _scenario_both(name, overrides):
    """A bundled scenario run on the Python path and on the native callback, with the runner's own arguments
    (noise, events, the control delay)."""
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.runs.runner import start

    out = []
    for nat in (False, True):
        st = start(load(SCENARIOS_DIR / f"{name}.toml", overrides=overrides))
        kw = dict(st.kwargs)
        kw["native"] = nat
        out.append((st.setup.law, run(st.setup.plant, st.setup.law, st.setup.reference, **kw)))
    return out


@pytest.mark.parametrize("extra", [
    [],  # the bench's failure/composite run: noise, a 20 ms control delay
    ["law.composite={gain=1.0, filter=2.0}", "events=[{t=1.5, kind='constant_force', value=20.0}]"],
    ["law.composite={gain=1.0, filter=10.0}", "law.projection={d=[30.0, 45.0]}", "law.sigma=1e-3"],
    ["law.composite={gain=1.0, filter=2.0}", "law.dead_zone={width_in_noise_std=3.0}", "law.e_modification=0.1"],
    ["law.composite={gain=1.0, filter=2.0}", "simulation.integrator='euler'", "simulation.control_delay=0"],
], ids=["failure", "force_event", "projection+sigma", "dead_zone+e_mod", "euler"])
def test_composite_on_the_sudden_failure_scenario_gives_the_python_path_s_rows_bit_for_bit(extra):
    from adaptive_mj.laws import CompositeSlidingLaw

    (law, a), (_, b) = _scenario_both("heave_sudden_failure", ["law.composite={gain=1e-4, filter=2.0}",
                                                                "simulation.duration=3", *extra])
    assert isinstance(law, CompositeSlidingLaw)
    assert_same(a, b, tol=0.0)
    assert not np.array_equal(a.theta_hat[1], a.theta_hat[-1])


def test_composite_with_a_payload_event_on_the_arm_gives_the_python_path_s_rows_bit_for_bit():
    (law, a), (_, b) = _scenario_both("arm_payload_swap", ["simulation.duration=3",
                                                            "events=[{t=1.5, kind='payload_mass', value=2.0}]",
                                                            "law.composite={gain=1.0, filter=2.0}"])
    assert_same(a, b, tol=0.0)
    assert [label for _, label in b.meta["events"]] == [label for _, label in a.meta["events"]] != []


def test_composite_with_a_parameter_change_on_the_heave_vehicle():
    """A water-density step (drag b and buoyancy c change) during a tracking run, and the correction does move the
    estimates: the composite run differs from the plain sliding law's."""
    from adaptive_mj.laws import CompositeSlidingLaw

    def make(p):
        return CompositeSlidingLaw(p.form, lam=5, k=200, gamma=GAMMA, kappa=1.0, filter_rate=5.0)

    events = lambda: [Event(1.2, "density", lambda p: p.set_fluid_density(1100.0))]  # noqa: E731
    a, b = both(heave_plant(), make, Cosine(), duration=2.5, theta_hat0=[30, 50, 0.9], events=events)
    assert_same(a, b, tol=0.0)
    plain = heave_plant()()
    c = run(plain, SlidingAdaptiveLaw(plain.form, lam=5, k=200, gamma=GAMMA), Cosine(), duration=2.5,
            theta_hat0=[30, 50, 0.9], events=events())
    assert np.max(np.abs(c.theta_hat - b.theta_hat)) > 1e-3


def test_composite_native_is_chosen_and_refuses_sampled_control():
    from adaptive_mj.laws import CompositeSlidingLaw
    from adaptive_mj.sim.stage import ControlTiming

    p = heave.load()
    law = CompositeSlidingLaw(p.form, lam=5, k=200, gamma=GAMMA, kappa=1.0, filter_rate=2.0)
    assert native.supported(p, law)
    with pytest.raises(ValueError, match="continuous control only"):
        native.Controller(p, law, Cosine(), [0, 0, 0], 10,
                          control=ControlTiming.of(p.dt, mode="sampled", period=2 * p.dt))


# -- order 3: the heave vehicle with its thruster lag (y'' from the thrust state and MuJoCo's forces) ---------

@pytest.mark.parametrize("extra", [
    [],  # the bench's nth_order/n3_models_lag run, cut short
    ["noise.std={y=0.001, y_dot=0.01, y_ddot=0.1}", "noise.seed=3"],
    ["events=[{t=0.9, kind='constant_force', value=25.0}, {t=1.6, kind='fluid_density_scale', value=1.1}]"],
    ["disturbance={kind='sine', magnitude=30.0, omega=3.0}",
     "events=[{t=1.2, kind='constant_force', value=-10.0}]"],
    ["simulation.control_delay=5"],
    ["control.mode='sampled'", "control.period=0.004"],
    ["simulation.integrator='euler'"],
], ids=["plain", "noise", "force+density_events", "disturbance+force", "delay", "sampled", "euler"])
def test_order_three_on_the_native_callback_gives_the_python_path_s_rows_bit_for_bit(extra):
    (law, a), (_, b) = _scenario_both("heave_thruster_n3", ["simulation.duration=2.5", *extra])
    assert law.order == 3 and a.x.shape[1] == 3
    assert_same(a, b, tol=0.0)
    assert np.ptp(a.x[:, 2]) > 0.1  # y'' moves: the third state is read, not left at zero


def test_order_three_is_native_only_on_the_lagged_heave_vehicle():
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load

    s = build(load(SCENARIOS_DIR / "heave_thruster_n3.toml"))
    assert s.plant.native_third_state is not None and native.supported(s.plant, s.law)
    p = heave.load()
    assert p.native_third_state is None  # order 2: no third state to read


def test_mujoco_timers_are_off_while_a_native_run_steps_and_the_physics_is_the_same(monkeypatch):
    """The native path steps with mjcb_time = mujoco_plant.no_timer (MuJoCo's clock not read: mjData.timer stays
    zero), restores the previous mjcb_time afterwards, and gives the rows and final state of a run with MuJoCo's
    own timers on, bit for bit."""
    import mujoco

    from adaptive_mj.plants import mujoco_plant

    def one(timers_on: bool):
        if timers_on:  # mjcb_time None: MuJoCo's own clock
            monkeypatch.setattr(mujoco_plant, "no_timer", lambda: type("On", (), {"ctypes": None})())
        plant = heave_plant()()
        law = SlidingAdaptiveLaw(plant.form, lam=5, k=200, gamma=GAMMA)
        traj = run(plant, law, Cosine(), native=True, duration=1.0, theta_hat0=[0, 0, 0])
        monkeypatch.undo()
        return traj, plant.data.qpos.copy(), plant.data.qvel.copy(), float(plant.data.timer[0].duration)

    off, on = one(False), one(True)
    assert mujoco.get_mjcb_time() is None
    with mujoco_plant.timers_off(False):
        assert mujoco.get_mjcb_time() is None
    with mujoco_plant.timers_off():
        assert mujoco.get_mjcb_time() is not None
    assert mujoco.get_mjcb_time() is None
    assert off[0].meta["native"] and on[0].meta["native"]
    assert off[3] == 0.0 and on[3] > 0.0  # mjTIMER_STEP: the clock was read only with the timers on
    for f in FIELDS:
        assert np.array_equal(getattr(off[0], f), getattr(on[0], f)), f
    assert np.array_equal(off[1], on[1]) and np.array_equal(off[2], on[2])

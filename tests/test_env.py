"""adaptive_mj.env: dm_env environments over the scenarios (dm_env's conventions,
the scenario's events and noise, the law as the policy, MCAP logs)."""
from __future__ import annotations

import collections

import dm_env
import mujoco
import numpy as np
import pytest
from absl.testing import absltest
from dm_control.rl import control
from dm_env import specs, test_utils

from adaptive_mj import env as amj_env
from adaptive_mj.laws import Law
from adaptive_mj.setup.build import build
from adaptive_mj.errors import ScenarioError
from adaptive_mj.sim.loop import run
from adaptive_mj.report.metrics import metrics
from adaptive_mj.log.replay import read_log
from adaptive_mj.runs.runner import execute
from adaptive_mj.setup.scenario import SCENARIOS_DIR, load as load_scenario

SHORT = ("simulation.duration=0.05",)  # 50 physics steps of 1 ms
SWAP_AT_50MS = ("simulation.duration=0.1", "events=[{t = 0.05, kind = 'payload_mass', value = 2.0}]")


def _episode(env, policy=None):
    """Reset and step to LAST; returns the TimeSteps (policy(timestep) -> action, default zeros)."""
    steps = [env.reset()]
    while not steps[-1].last():
        steps.append(env.step(np.zeros(1) if policy is None else policy(steps[-1])))
    return steps


def _scenario_run(name, overrides):
    """What `adaptive-mj run` computes for the scenario (no log; the native callback when it applies)."""
    scn = load_scenario(SCENARIOS_DIR / f"{name}.toml", overrides=overrides)
    return execute(scn).trajectory


def _python_run(name, overrides):
    """loop.run on the Python path (no numba compile; tests/test_native.py ties it to the native one)."""
    scn = load_scenario(SCENARIOS_DIR / f"{name}.toml", overrides=overrides)
    s = build(scn)
    return run(s.plant, s.law, s.reference, duration=scn.simulation.duration, theta_hat0=s.theta_hat0,
               noise_std=s.noise_std, rng=s.rng, events=s.events, state_bound=scn.simulation.state_bound,
               native=False)


# -- dm_env's own conformance checks ------------------------------------------------

class HeaveEnvironmentConformance(test_utils.EnvironmentTestMixin, absltest.TestCase):
    """dm_env.test_utils on the heave vehicle, with episodes short enough to reach LAST."""

    def make_object_under_test(self):
        return amj_env.load("heave_drift", overrides=("simulation.duration=0.01",))

    def make_action_sequence(self):
        rng = np.random.default_rng(0)
        spec = self.environment.action_spec()
        for _ in range(25):  # 10 steps per episode: crosses LAST -> FIRST twice
            yield rng.uniform(spec.minimum, spec.maximum)


# -- specs ----------------------------------------------------------------------------

def test_specs_heave():
    env = amj_env.load("heave_tracking", overrides=SHORT)
    assert isinstance(env, dm_env.Environment) and isinstance(env, control.Environment)
    action = env.action_spec()
    assert isinstance(action, specs.BoundedArray)
    assert action.name == "u" and action.shape == (1,) and action.dtype == np.float64
    np.testing.assert_array_equal(action.minimum, [-200.0])  # the thruster's ctrlrange [N]
    np.testing.assert_array_equal(action.maximum, [200.0])
    obs_spec = env.observation_spec()
    assert isinstance(obs_spec, collections.OrderedDict)
    assert list(obs_spec) == ["state", "reference", "t"]  # nothing privileged by default
    assert {k: s.shape for k, s in obs_spec.items()} == {"state": (2,), "reference": (3,), "t": ()}
    assert all(type(s) is specs.Array and s.dtype == np.float64 for s in obs_spec.values())
    first = env.reset()
    for key, spec in obs_spec.items():
        spec.validate(first.observation[key])
    np.testing.assert_array_equal(first.observation["state"], [1.0, 0.0])   # simulation.initial_state
    np.testing.assert_allclose(first.observation["reference"], [1.0, 0.0, -1.0])  # cos t at t = 0
    assert first.observation["t"] == 0.0
    assert env.control_timestep() == pytest.approx(0.001)


def test_specs_privileged_and_order_three():
    env = amj_env.load("heave_thruster_n3", overrides=SHORT, privileged=True)
    obs_spec = env.observation_spec()
    assert list(obs_spec) == ["state", "reference", "t", "theta"]
    assert obs_spec["state"].shape == (3,) and obs_spec["reference"].shape == (4,)
    assert env.task.param_names == ("tau_d", "tau_b", "d", "b", "c")
    obs = env.reset().observation
    assert obs["theta"].shape == (5,)
    np.testing.assert_allclose(obs["theta"], build(env.task.scenario).plant.true_theta())


def test_twin_scenarios_are_refused():
    with pytest.raises(ScenarioError, match="needs a MuJoCo plant.*'first_order'"):
        amj_env.load("lecture_first_order")


# -- step types, discounts, time limit, reset -------------------------------------------

@pytest.mark.parametrize("kwargs, n_agent_steps", [({}, 50), ({"n_sub_steps": 10}, 5),
                                                   ({"control_timestep": 0.005}, 10)])
def test_first_mid_last_and_reset(kwargs, n_agent_steps):
    env = amj_env.load("heave_drift", overrides=SHORT, **kwargs)  # heave_drift has sensor noise
    steps = _episode(env)
    first, *mid, last = steps
    assert first.step_type is dm_env.StepType.FIRST
    assert first.reward is None and first.discount is None
    assert all(ts.step_type is dm_env.StepType.MID and ts.discount == 1.0 for ts in mid)
    assert all(isinstance(ts.reward, float) and ts.reward <= 0.0 for ts in steps[1:])
    assert last.step_type is dm_env.StepType.LAST
    assert last.discount == amj_env.DISCOUNT_TIME_LIMIT == 1.0
    assert len(steps) - 1 == n_agent_steps == round(0.05 / env.control_timestep())
    assert last.observation["t"] == pytest.approx(0.05)
    assert mujoco.get_mjcb_control() is None  # the callback lives only inside step
    again = env.step(np.zeros(1))  # after LAST: a new episode, from the same start and noise
    assert again.step_type is dm_env.StepType.FIRST
    for key in first.observation:
        np.testing.assert_array_equal(again.observation[key], first.observation[key])
    assert env.step(np.zeros(1)).step_type is dm_env.StepType.MID


def test_seed_sets_the_noise():
    def first_state(seed):
        return amj_env.load("heave_drift", overrides=SHORT, seed=seed).reset().observation["state"]

    np.testing.assert_array_equal(first_state(3), first_state(3))
    assert not np.array_equal(first_state(3), first_state(4))
    noise = first_state(3) - np.array([0.0, 0.0])  # starts at rest at 0; std 1 mm and 1 cm/s
    assert np.all(noise != 0) and np.all(np.abs(noise) < [0.01, 0.1])


def test_reward_is_minus_squared_error_times_dt():
    """Agent step i covers physics steps 5i..5i+4; its reward sums -(y_d - y)^2 * dt at their ends."""
    env = amj_env.load("heave_tracking", overrides=SHORT, n_sub_steps=5)  # no noise: state is true
    steps = _episode(env, policy=lambda ts: np.array([50.0]))
    rewards = np.array([ts.reward for ts in steps[1:]])
    last = steps[-1].observation
    end_errors = np.append(env.task.trajectory().y_tilde[1:], last["reference"][0] - last["state"][0])
    np.testing.assert_allclose(rewards, -0.001 * (end_errors ** 2).reshape(10, 5).sum(axis=1), rtol=1e-12)
    assert np.all(rewards < 0)


def test_actions_are_clipped_to_the_spec_or_rejected():
    env = amj_env.load("heave_tracking", overrides=SHORT)
    env.reset()
    env.step(np.array([1e6]))
    env.step(np.array([-1e6]))
    env.step(np.array([12.5]))
    np.testing.assert_array_equal(env.task.trajectory().u, [200.0, -200.0, 12.5])
    with pytest.raises(ValueError, match=r"shape \(1,\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="must be finite"):
        env.step(np.array([np.nan]))


def test_divergence_ends_the_episode_with_discount_zero(tmp_path):
    env = amj_env.load("heave_tracking", overrides=("simulation.duration=1", "simulation.state_bound=1.02"),
                       log=tmp_path)
    steps = _episode(env, policy=lambda ts: np.array([200.0]))  # full thrust up from y = 1 m
    assert steps[-1].last() and steps[-1].discount == amj_env.DISCOUNT_DIVERGED == 0.0
    assert len(steps) - 1 < 1000
    assert steps[-1].observation["state"][0] > 1.02
    assert "beyond the bound" in env.task.trajectory().reason
    assert read_log(env.task.log_paths[0]).status == "diverged"


# -- events -----------------------------------------------------------------------------

def test_payload_swap_changes_the_privileged_true_parameters_at_its_time():
    env = amj_env.load("arm_payload_swap", overrides=SWAP_AT_50MS, privileged=True)
    steps = _episode(env)
    t = np.array([float(ts.observation["t"]) for ts in steps])
    theta = np.array([ts.observation["theta"] for ts in steps])
    before, after = t < 0.05 - 0.0005, t >= 0.05 - 0.0005
    assert before.sum() == 50 and after.sum() == 51
    assert np.all(theta[before] == theta[0]) and np.all(theta[after] == theta[-1])
    J = env.task.param_names.index("J")
    assert theta[-1, J] > theta[0, J]  # a heavier payload at the tip: more inertia
    events = env.task.trajectory().meta["events"]
    assert events == [(pytest.approx(0.05), "payload_mass payload/body = 2.0 kg")]
    # the next episode starts from the compiled model again (the swap is undone)
    np.testing.assert_array_equal(env.reset().observation["theta"], theta[0])


# -- the law as the policy -----------------------------------------------------------------

@pytest.mark.parametrize("name, overrides, n_sub_steps, reference_run", [
    ("heave_tracking", ("simulation.duration=1",), 1, _scenario_run),  # adaptive-mj run itself
    ("heave_tracking", ("simulation.duration=1",), 1, _python_run),
    ("heave_drift", ("simulation.duration=0.5",), 7, _python_run),     # noise; 500 = 71*7 + 3 steps
    ("heave_thruster_n3", ("simulation.duration=0.5",), 1, _python_run),  # order 3
    ("arm_payload_swap", SWAP_AT_50MS, 1, _python_run),                 # an event
])
def test_law_in_the_env_is_bit_identical_to_adaptive_mj_run(name, overrides, n_sub_steps, reference_run):
    expected = reference_run(name, overrides)
    env = amj_env.load(name, overrides=overrides, law="scenario", n_sub_steps=n_sub_steps)
    steps = _episode(env, policy=lambda ts: None)  # the action is ignored
    assert steps[-1].discount == 1.0
    got = env.task.trajectory()
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        np.testing.assert_array_equal(getattr(got, field), getattr(expected, field), err_msg=field)
    assert got.meta["events"] == expected.meta["events"]
    assert mujoco.get_mjcb_control() is None


def test_a_law_object_can_be_the_policy():
    from adaptive_mj.laws import FixedNominalLaw

    scn = load_scenario(SCENARIOS_DIR / "heave_tracking.toml", overrides=("simulation.duration=0.2",))
    form = build(scn).plant.form
    env = amj_env.load(scn, law=FixedNominalLaw(form, lam=5.0, k=200.0))
    _episode(env)
    traj = env.task.trajectory()
    assert np.all(traj.theta_hat == env.task.theta_hat0)  # no adaptation
    with pytest.raises(ValueError, match="order 1 on a plant of order 2"):
        from adaptive_mj.laws import FirstOrderAdaptiveLaw
        from adaptive_mj.plants.twin import lecture_first_order_form

        amj_env.load(scn, law=FirstOrderAdaptiveLaw(lecture_first_order_form(), k=1.0, gamma=1.0))


def test_the_scenario_law_tracks_in_the_env_and_as_an_agent():
    """heave_tracking over 10 s: the law driven by the env tracks (tail RMS < 1 cm, the estimates
    still settling), and the law as an ordinary agent (law_policy: u held over the step, Euler
    estimates) tracks within 2x of `adaptive-mj run`, at 1 ms and at 10 ms control steps."""
    overrides = ("simulation.duration=10",)
    reference = metrics(_scenario_run("heave_tracking", overrides))["rms_tracking_error_tail"]
    env = amj_env.load("heave_tracking", overrides=overrides, law="scenario")
    _episode(env)
    in_env = metrics(env.task.trajectory())["rms_tracking_error_tail"]
    assert in_env == reference < 1e-2
    for n_sub in (1, 10):
        agent_env = amj_env.load("heave_tracking", overrides=overrides, n_sub_steps=n_sub)
        steps = _episode(agent_env, amj_env.law_policy(agent_env))
        traj = agent_env.task.trajectory()
        tail = metrics(traj)["rms_tracking_error_tail"]
        assert tail < 2 * reference, (n_sub, tail, reference)
        assert np.all(np.isnan(traj.theta_hat))  # an agent's estimates are its own
        episode_return = sum(ts.reward for ts in steps[1:])
        assert episode_return == pytest.approx(-np.sum(traj.y_tilde ** 2) * 0.001, rel=0.05)


# -- logs -------------------------------------------------------------------------------

def test_episodes_are_logged_to_mcap_like_adaptive_mj_run(tmp_path):
    overrides = ("simulation.duration=0.5", "events=[{t = 0.25, kind = 'constant_force', value = 5.0}]",
                 "success.tail_rms=inf")  # 0.5 s from rest: the verdict's tail bound is not the point here
    env = amj_env.load("heave_tracking", overrides=overrides, law="scenario", log=tmp_path / "env")
    _episode(env)
    env.reset()
    env.step(None)
    env.close()  # the second episode is cut short
    first, second = env.task.log_paths
    assert first.parent == tmp_path / "env" and first.suffix == ".mcap" and first != second
    logged = read_log(first)
    assert logged.status == "ok" and logged.summary["policy"] == "law"
    assert logged.summary["control_timestep"] == pytest.approx(0.001)
    assert [e["label"] for e in logged.events] == ["constant force +5"]
    # the same header and rows as the log `adaptive-mj run` writes for this scenario
    scn = env.task.scenario
    run_log = tmp_path / "run.mcap"
    execute(scn, log_path=run_log)
    expected = read_log(run_log)
    ignore = {"created_unix"}
    assert {k: v for k, v in logged.header.items() if k not in ignore} == \
           {k: v for k, v in expected.header.items() if k not in ignore}
    assert logged.scenario_text == expected.scenario_text and logged.model_xml == expected.model_xml
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        np.testing.assert_array_equal(getattr(logged.trajectory, field), getattr(expected.trajectory, field))
    assert logged.summary["metrics"] == expected.summary["metrics"]
    assert read_log(second).status == "interrupted"


def test_agent_episode_logs_read_back(tmp_path):
    env = amj_env.load("heave_tracking", overrides=("simulation.duration=0.2",), log=tmp_path)
    _episode(env, policy=lambda ts: np.array([10.0]))
    logged = read_log(env.task.log_paths[0])
    # a constant 10 N is no controller: the episode's verdict says it did not track
    assert logged.status == "failed" and "(success.tail_rms)" in logged.trajectory.reason
    assert logged.summary["policy"] == "agent" and logged.summary["preflight"]["checked"] is False
    traj = logged.trajectory
    assert len(traj) == 20  # 100 Hz over 0.2 s
    np.testing.assert_array_equal(traj.u, 10.0)
    assert np.all(np.isnan(traj.theta_hat)) and np.all(np.isnan(traj.V))
    np.testing.assert_array_equal(traj.x, env.task.trajectory().x[::10])


def test_reset_mid_episode_closes_the_log_as_interrupted(tmp_path):
    env = amj_env.load("heave_tracking", overrides=SHORT, log=tmp_path)
    env.reset()
    for _ in range(3):
        env.step(np.zeros(1))
    env.reset()
    logged = read_log(env.task.log_paths[0])
    assert logged.status == "interrupted" and len(logged.trajectory) == 1  # rows 0..2, logged at 100 Hz
    env.close()
    assert len(env.task.log_paths) == 2 and read_log(env.task.log_paths[1]).status == "interrupted"


def test_a_failing_law_leaves_no_callback_and_a_failed_log(tmp_path):
    scn = load_scenario(SCENARIOS_DIR / "heave_tracking.toml", overrides=SHORT)
    scenario_law = build(scn).law

    class Failing(Law):
        order, names, lyapunov = scenario_law.order, scenario_law.names, scenario_law.lyapunov

        def __call__(self, t, x, ref, theta_hat):
            if t > 0.0115:  # inside step 11 (its last stage, t = 0.012)
                raise RuntimeError("law failed")
            return scenario_law(t, x, ref, theta_hat)

    env = amj_env.load(scn, law=Failing(), log=tmp_path)
    env.reset()
    with pytest.raises(RuntimeError, match="law failed"):
        for _ in range(50):
            env.step(None)
    assert mujoco.get_mjcb_control() is None
    logged = read_log(env.task.log_paths[0])
    assert logged.status == "failed" and "law failed" in logged.summary["reason"]
    assert len(logged.trajectory) == 2  # rows 0 and 10 of the 11 whole steps, at 100 Hz

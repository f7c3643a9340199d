"""The Gymnasium environment (adaptive_mj.gym_env, the optional [gym] extra): it passes Gymnasium's
own check_env, and it is the dm_env environment underneath: the same observations, rewards and
episode end, and law="scenario" gives the rows of `adaptive-mj run`."""
import warnings

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium", reason="the optional extra [gym] (gymnasium) is not installed: "
                                                    "pip install -e '.[gym]'")

from adaptive_mj import env as dm_env_module, gym_env  # noqa: E402 (after the skip above)

SHORT = ["simulation.duration=0.05", "events=[]"]


@pytest.mark.parametrize("scenario, law", [("heave_tracking", None), ("heave_tracking", "scenario"),
                                           ("ur5e_payload_swap", None)])
def test_passes_gymnasiums_check_env(scenario, law):
    from gymnasium.utils.env_checker import check_env

    env = gym_env.make(scenario, law=law, overrides=SHORT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    # its only warning may be the one every unbounded observation Box gets
    assert all("unbounded" in str(w.message).lower() or "inf" in str(w.message).lower() for w in caught), \
        [str(w.message) for w in caught]
    env.close()


def test_spaces_follow_the_scenario():
    heave = gym_env.make("heave_tracking", privileged=True, overrides=SHORT)
    assert heave.action_space.shape == (1,) and set(heave.observation_space) == {"state", "reference", "t", "theta"}
    assert heave.observation_space["state"].shape == (2,) and heave.observation_space["theta"].shape == (3,)
    arm = gym_env.make("ur5e_payload_swap", overrides=SHORT)
    assert arm.action_space.shape == (6,) and arm.observation_space["state"].shape == (2, 6)
    spec = arm.dm_env.action_spec()
    assert np.array_equal(arm.action_space.low, spec.minimum) and np.array_equal(arm.action_space.high, spec.maximum)


def test_steps_equal_the_dm_env_and_the_episode_is_truncated_at_its_duration():
    gym = gym_env.make("heave_tracking", overrides=SHORT)
    dm = dm_env_module.load("heave_tracking", overrides=SHORT)
    obs, info = gym.reset(seed=0)
    ts = dm.reset()
    assert info["t"] == 0.0 and all(np.array_equal(obs[k], ts.observation[k]) for k in obs)
    steps = 0
    while True:
        action = np.array([20.0 * np.sin(steps)])
        obs, reward, terminated, truncated, info = gym.step(action)
        ts = dm.step(action)
        steps += 1
        assert reward == ts.reward and all(np.array_equal(obs[k], ts.observation[k]) for k in obs)
        if terminated or truncated:
            break
    assert ts.last() and truncated and not terminated and steps == 50  # 0.05 s of 1 ms steps


def test_a_diverged_run_is_terminated():
    env = gym_env.make("heave_tracking", overrides=["simulation.state_bound=1.05"])
    env.reset(seed=0)
    for _ in range(5000):
        _, _, terminated, truncated, info = env.step(np.array([env.action_space.high[0]]))
        if terminated or truncated:
            break
    assert terminated and not truncated and info["status"] == "diverged"


def test_law_scenario_gives_adaptive_mj_runs_rows(tmp_path):
    from adaptive_mj.cli import main
    from adaptive_mj.log.replay import read_log

    log = tmp_path / "run.mcap"
    assert main(["run", "heave_tracking", "-o", str(log), "--set", "simulation.duration=0.2", "--python-callback"]) \
        in (0, 1)
    env = gym_env.make("heave_tracking", law="scenario", overrides=["simulation.duration=0.2"])
    env.reset()
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(None)
        done = terminated or truncated
    ran = read_log(log).trajectory
    ours = env.dm_env.task.trajectory()
    np.testing.assert_array_equal(ours.x[::len(ours) // len(ran)][:len(ran)], ran.x)
    assert info["theta_hat"].shape == (3,)


def test_reset_seed_is_the_noise_seed():
    env = gym_env.make("heave_tracking", overrides=[*SHORT, "noise.std={y=0.001}"])
    first = env.reset(seed=3)[0]["state"]
    again = env.reset(seed=3)[0]["state"]
    other = env.reset(seed=4)[0]["state"]
    assert np.array_equal(first, again) and not np.array_equal(first, other)

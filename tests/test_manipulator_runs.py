"""The issue's numbers on the bundled 6-joint arm, through the scenario/runner path (the
native callback), and a user's position-servo arm converted to torque motors."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.study import analysis

from adaptive_mj.setup import scenario
from adaptive_mj.setup.build import build
from adaptive_mj.cli import main
from adaptive_mj.runs.runner import execute


def _run(name, *overrides):
    scn = scenario.load(scenario.SCENARIOS_DIR / f"{name}.toml", overrides=list(overrides))
    result = execute(scn)
    return result.trajectory, build(scn)


def test_identification_scenario_identifies_the_payload():
    traj, setup = _run("ur5e_identification")
    assert traj.status == "ok" and traj.meta["native"]
    p = analysis.manipulator_response(traj, setup)["payload"]["final"]
    assert p["mass_rel_error"] <= 0.01, p
    assert p["com_error"] <= 1e-3, p
    dV = np.diff(traj.V)
    assert dV.max() <= 1e-12 * traj.V[0]  # V non-increasing beyond round-off (ideal case)


def test_payload_swap_scenario_tracks_after_the_swap():
    traj, setup = _run("ur5e_payload_swap")
    assert traj.status == "ok" and traj.meta["native"]
    assert [label for _, label in traj.meta["events"]] == ["payload_swap payload/body = sphere (0.5 kg)"]
    tail = np.sqrt(np.mean(traj.joint_errors[traj.t >= 22.5] ** 2, axis=0))
    assert tail.max() <= 1e-3, tail
    # the true parameters follow the swap: 1.5 kg before, 0.5 kg after
    assert traj.theta[0, 0] == 1.5 and traj.theta[-1, 0] == 0.5
    check = analysis.manipulator_response(traj, setup)
    assert check["lyapunov_max_increase_rel"] <= 1e-12  # away from the swap, V never increases
    assert check["lyapunov_rate_error_rel"] < 1e-2  # V' = -sᵀ K_D s (midpoint rule at 1 ms)
    assert check["recovery_time"] is not None


SERVO_ARM = """<mujoco model="two_link_servo">
  <option timestep="0.001" integrator="RK4"/>
  <worldbody>
    <body name="upper" pos="0 0 0.5">
      <joint name="shoulder" axis="0 1 0" armature="0.05" damping="0.2"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1.2" contype="0" conaffinity="0"/>
      <body name="lower" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0" armature="0.05" damping="0.2"/>
        <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.025" mass="0.6" contype="0" conaffinity="0"/>
        <site name="tip" pos="0.25 0 0"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="shoulder_servo" joint="shoulder" kp="100" forcerange="-40 40"/>
    <position name="elbow_servo" joint="elbow" kp="60" forcerange="-20 20"/>
  </actuator>
  <keyframe><key name="ready" qpos="0.3 -0.6"/></keyframe>
</mujoco>
"""

SERVO_SCENARIO = """schema_version = 1
[plant]
kind = "manipulator"
model = "my_arm.xml"
payload = "sphere"
payload_mass = 0.3
servo_to_torque = {servo}
[simulation]
duration = 8.0
[reference]
kind = "joint_waypoints"
waypoints = ["ready", {{shoulder = 0.8, elbow = -1.2}}, "ready"]
durations = [2.0, 2.0]
t0 = 0.5
cycle = true
[law]
kind = "slotine_li"
lambda = 10.0
kd = {{shoulder = 20.0, elbow = 10.0}}
gamma = 0.2
"""


def test_position_servo_arm_runs_through_servo_to_torque(tmp_path, capsys):
    (tmp_path / "my_arm.xml").write_text(SERVO_ARM)
    bad = tmp_path / "servo_off.toml"
    bad.write_text(SERVO_SCENARIO.format(servo="false"))
    assert main(["run", str(bad), "-o", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'shoulder_servo' is not a torque <motor>" in err[0] and "servo_to_torque" in err[0]
    good = tmp_path / "servo_on.toml"
    good.write_text(SERVO_SCENARIO.format(servo="true"))
    log = tmp_path / "arm.mcap"
    assert main(["run", str(good), "-o", str(log)]) == 0
    captured = capsys.readouterr()
    assert ("note: plant.servo_to_torque: servo(s) rebuilt as torque motors: 'shoulder_servo' |tau| <= [-40, 40] N*m"
            in captured.err) and captured.err.count("servo(s) rebuilt") == 1  # one note for the run
    assert "tail rms per joint [rad]: shoulder" in captured.out
    from adaptive_mj.log.replay import read_log

    run = read_log(log)
    assert run.header["notes"][0].startswith(
        "plant.servo_to_torque: servo(s) rebuilt as torque motors: 'shoulder_servo'")
    tail = np.sqrt(np.mean(run.trajectory.joint_errors[run.trajectory.t >= 6.0] ** 2, axis=0))
    assert tail.max() < 1e-3, tail
    assert main(["replay", str(log), "--verify"]) == 0
    assert "bit-identical" in capsys.readouterr().out


@pytest.mark.parametrize("override,match", [
    ("plant.unknown=['nope']", r"plant.unknown names body 'nope'"),
    ("reference.center='nokey'", r"reference.center names keyframe 'nokey'.*keyframes: \['home'\]"),
    ("law.kd={elbow=3.0}", r"law.kd must give every joint a value, missing shoulder_pan"),
    ("noise.std.y=0.01", r"unknown key 'noise.std.y' \(measured signals: q, q_dot\)"),
])
def test_manipulator_scenario_errors_are_one_line(override, match, capsys):
    assert main(["run", "ur5e_payload_swap", "--set", override, "--set", "simulation.duration=0.1",
                 "--set", "events=[]"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    import re

    assert re.search(match, err[0]), err[0]


ARM_ENV = ("simulation.duration=0.2", "events=[{t = 0.1, kind = 'payload_swap', payload = 'sphere'}]")


def _arm_python_run(overrides):
    from adaptive_mj.setup.build import build
    from adaptive_mj.sim.loop import run
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load as load_scenario

    scn = load_scenario(SCENARIOS_DIR / "ur5e_payload_swap.toml", overrides=overrides)
    s = build(scn)
    return run(s.plant, s.law, s.reference, duration=scn.simulation.duration, theta_hat0=s.theta_hat0,
               events=s.events, native=False)


def test_dm_env_on_the_arm_has_per_joint_specs_and_runs_the_law_bit_identically():
    """The action is the 6 joint torques with the motors' ranges; the law as the policy (through
    the swap event) gives exactly loop.run's rows, V included (M(q) from the plant)."""
    from adaptive_mj import env as amj_env

    env = amj_env.load("ur5e_payload_swap", overrides=ARM_ENV, law="scenario", n_sub_steps=3)
    plant = build(scenario.load(scenario.SCENARIOS_DIR / "ur5e_payload_swap.toml", overrides=ARM_ENV)).plant
    spec = env.action_spec()
    assert spec.shape == (6,) and spec.name == "tau"
    np.testing.assert_array_equal(spec.minimum, plant.ctrl_range[0])
    np.testing.assert_array_equal(spec.maximum, plant.ctrl_range[1])
    assert env.observation_spec()["state"].shape == (2, 6)
    assert env.observation_spec()["reference"].shape == (3, 6)
    ts = env.reset()
    while not ts.last():
        ts = env.step(None)
    assert ts.discount == 1.0
    got, expected = env.task.trajectory(), _arm_python_run(ARM_ENV)
    assert got.joint_names == expected.joint_names == plant.joint_names
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        np.testing.assert_array_equal(getattr(got, field), getattr(expected, field), err_msg=field)
    assert got.meta["events"] == expected.meta["events"]
    assert expected.theta[0, 0] != expected.theta[-1, 0]  # the swap changed the payload mass


def test_dm_env_arm_agent_actions_are_checked_and_law_policy_tracks(tmp_path):
    from adaptive_mj import env as amj_env
    from adaptive_mj.log.replay import read_log

    overrides = ("simulation.duration=0.3", "events=[]")
    env = amj_env.load("ur5e_payload_swap", overrides=overrides, log=tmp_path)
    env.reset()
    with pytest.raises(ValueError, match=r"action must have shape \(6,\) \(the joint torques tau of shoulder_pan"):
        env.step(np.zeros(1))
    with pytest.raises(ValueError, match="action tau must be finite"):
        env.step(np.full(6, np.nan))
    policy = amj_env.law_policy(env)
    ts = env.reset()
    rewards = []
    while not ts.last():
        ts = env.step(policy(ts))
        rewards.append(ts.reward)
    traj = env.task.trajectory()
    in_loop = np.max(np.abs(_arm_python_run(overrides).y_tilde))  # u held over RK4 stages, Euler estimates
    assert np.max(np.abs(traj.y_tilde)) < 1.5 * in_loop < 1e-2, (np.max(np.abs(traj.y_tilde)), in_loop)
    assert sum(rewards) == pytest.approx(-np.sum(traj.y_tilde[1:] ** 2) * 0.001, rel=0.05)
    logged = read_log(env.task.log_paths[-1])
    assert logged.status == "ok" and logged.summary["policy"] == "agent"
    assert logged.trajectory.joint_names == traj.joint_names and logged.trajectory.u.shape[1:] == (6,)

"""The issue's numbers on the bundled 6-joint arm, through the scenario/runner path (the
native callback), and a user's position-servo arm converted to torque motors."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj import analysis, scenario
from adaptive_mj.build import build
from adaptive_mj.cli import main
from adaptive_mj.runner import execute


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
    assert "note: actuator 'shoulder_servo': servo rebuilt as a torque motor, |tau| <= [-40, 40] N*m" in captured.err
    assert "tail rms per joint [rad]: shoulder" in captured.out
    from adaptive_mj.replay import read_log

    run = read_log(log)
    assert run.header["notes"][0].startswith("actuator 'shoulder_servo': servo rebuilt")
    tail = np.sqrt(np.mean(run.trajectory.joint_errors[run.trajectory.t >= 6.0] ** 2, axis=0))
    assert tail.max() < 1e-3, tail
    assert main(["replay", str(log), "--verify"]) == 0
    assert "bit-identical" in capsys.readouterr().out


@pytest.mark.parametrize("override,match", [
    ("plant.unknown=['nope']", r"plant.unknown names body 'nope'"),
    ("reference.center='nokey'", r"reference.center names keyframe 'nokey'.*keyframes: \['home'\]"),
    ("law.kd={elbow=3.0}", r"law.kd must give every joint a value, missing shoulder_pan"),
    ("noise.std.y=0.01", r"noise.std is not supported for plant.kind = 'manipulator'"),
])
def test_manipulator_scenario_errors_are_one_line(override, match, capsys):
    assert main(["run", "ur5e_payload_swap", "--set", override, "--set", "simulation.duration=0.1", "--set", "events=[]"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    import re

    assert re.search(match, err[0]), err[0]


def test_dm_env_refuses_a_manipulator_with_one_line():
    from adaptive_mj import env
    from adaptive_mj.errors import ScenarioError

    with pytest.raises(ScenarioError, match=r"adaptive_mj.env supports 1-DOF plants for now.*manipulator"):
        env.load("ur5e_payload_swap", overrides=("simulation.duration=0.1", "events=[]"))

"""The manipulator regressor against MuJoCo's own inverse dynamics, the Christoffel C,
base parameters, refusals, and the Slotine–Li law on the bundled 6-joint arm."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.errors import ModelError
from adaptive_mj.laws.slotine_li import Mode, SlotineLiLaw
from adaptive_mj.sim.loop import run
from adaptive_mj.plants import manipulator as mp
from adaptive_mj.plants.arm import MODELS, build_arm_xml
from adaptive_mj.reference import JointSumOfSines

UR5E = MODELS / "ur5e_arm.xml"

# An arm written here: slide and hinge joints with skew axes, offset bodies, rotated
# inertia frames, two joints on one body, a branch, a massless frame body and a
# welded (jointless) body.
TEST_ARM = """
<mujoco><option gravity="0.4 -0.7 -9.81" timestep="0.001" integrator="RK4"/>
<worldbody><body name="base" pos="0.1 0.2 0.3" quat="0.9 0.1 0.3 0.2">
  <joint name="j1" type="hinge" axis="0.3 0.5 0.8" armature="0.1" damping="0.7"/>
  <inertial pos="0.05 -0.1 0.2" quat="0.8 0.3 -0.2 0.4" mass="2.5" diaginertia="0.3 0.2 0.15"/>
  <body name="l2" pos="0.3 0 0.1" euler="0.3 0.2 0.1">
    <joint name="j2" type="slide" axis="1 0.2 0" damping="0.3" armature="0.2"/>
    <joint name="j3" type="hinge" axis="0 1 0.3" armature="0.05"/>
    <inertial pos="0 0.1 0.05" mass="1" diaginertia="0.1 0.07 0.05" quat="0.3 0.4 0.5 0.6"/>
    <body name="l3a" pos="0.2 0.1 0"><joint name="j4" type="hinge" axis="0 0 1"/>
      <inertial pos="0.1 0.1 0" mass="0.5" diaginertia="0.01 0.02 0.03"/></body>
    <body name="frame" pos="0 0.1 0.3" quat="0.7 0 0.7 0">
      <body name="l3b"><joint name="j5" type="hinge" axis="1 0 0" damping="0.2"/>
        <inertial pos="0.1 0.1 0" mass="0.5" diaginertia="0.01 0.02 0.03"/>
        <body name="tool" pos="0.1 0 0">
          <inertial pos="0.02 0.03 0.01" mass="0.3" diaginertia="0.001 0.002 0.003" quat="0.5 0.5 0.5 0.1"/>
        </body></body></body></body></body></worldbody>
<actuator><motor joint="j1" gear="2"/><motor joint="j2"/><motor joint="j3"/><motor joint="j4"/>
  <motor joint="j5" gear="0.5"/></actuator></mujoco>"""


def _arms():
    out = {"test_arm": mujoco.MjModel.from_xml_string(TEST_ARM)}
    out["ur5e"] = mujoco.MjModel.from_xml_path(str(UR5E))
    for payload in ("tool_offset", "sphere"):
        xml, assets = build_arm_xml(arm=UR5E, payload=payload, site="tip")
        out[f"ur5e+{payload}"] = mujoco.MjModel.from_xml_string(xml, assets)
    return out


ARMS = _arms()


def _eval(plant, q, v, w, a):
    d = plant.data
    d.qpos[:] = q
    d.qvel[:] = v
    mujoco.mj_kinematics(plant.model, d)
    mujoco.mj_comPos(plant.model, d)
    Y, tau_known = plant.regressor(v, w, a)
    return Y.copy(), tau_known.copy()


@pytest.mark.parametrize("name", sorted(ARMS))
@pytest.mark.parametrize("unknown,joints", [("all", True), ("all", False), ("some", False)])
def test_regressor_matches_mj_inverse(name, unknown, joints):
    """Y π_true + τ_known = qfrc_inverse (rne + armature q̈ + damping q̇) at random states."""
    model = ARMS[name]
    if unknown == "some":
        unknown = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, mp.moving_bodies(model)[-1])]
    plant = mp.ManipulatorPlant(model, unknown=unknown, joint_params=joints)
    pi = plant.true_theta()
    rng = np.random.default_rng(1)
    d = mujoco.MjData(model)
    worst = 0.0
    for _ in range(20):
        q, v, a = rng.uniform(-3, 3, model.nq), rng.normal(size=model.nv) * 2, rng.normal(size=model.nv) * 5
        Y, tau_known = _eval(plant, q, v, v, a)
        d.qpos[:], d.qvel[:], d.qacc[:] = q, v, a
        mujoco.mj_inverse(model, d)
        scale = max(1.0, np.abs(d.qfrc_inverse).max())
        worst = max(worst, np.abs(Y @ pi + tau_known - d.qfrc_inverse).max() / scale)
    assert worst <= 1e-10, worst


@pytest.mark.parametrize("name", ["test_arm", "ur5e+tool_offset"])
def test_christoffel_form(name):
    """C(q, v) w from the regressor: C(q, v) v = MuJoCo's bias, and Ṁ - 2C is skew."""
    model = ARMS[name]
    plant = mp.ManipulatorPlant(model, unknown="all", joint_params=True)
    pi = plant.true_theta()
    rng = np.random.default_rng(2)
    nv = model.nv
    q, v = rng.uniform(-2, 2, nv), rng.normal(size=nv)
    zero = np.zeros(nv)
    g = _eval(plant, q, zero, zero, zero)
    g = g[0] @ pi + g[1]

    def C_times(w):
        Y, tk = _eval(plant, q, v, w, zero)
        return Y @ pi + tk - g - model.dof_damping * v

    C = np.column_stack([C_times(e) for e in np.eye(nv)])
    d = mujoco.MjData(model)
    d.qpos[:], d.qvel[:] = q, v
    mujoco.mj_forward(model, d)
    assert np.allclose(C @ v + g, d.qfrc_bias, rtol=0, atol=1e-12)

    def M_at(qq):
        dd = mujoco.MjData(model)
        dd.qpos[:] = qq
        mujoco.mj_forward(model, dd)
        out = np.zeros((nv, nv))
        mujoco.mj_fullM(model, dd, out)
        return out

    h = 1e-6
    Mdot = (M_at(q + h * v) - M_at(q - h * v)) / (2 * h)
    N = Mdot - 2 * C
    assert np.abs(N + N.T).max() < 1e-8 * max(1.0, np.abs(Mdot).max())
    # and C is not just any factorisation: it differs from the skew-breaking 0.5*Mdot-only split
    assert np.abs(C).max() > 1e-3


def test_base_parameters_reproduce_the_dynamics():
    """With every body unknown the full set is not identifiable; the base set is, and
    Y_base π_base = Y π exactly."""
    model = ARMS["ur5e+tool_offset"]
    full = mp.ManipulatorPlant(model, unknown="all", joint_params=True)
    base = mp.ManipulatorPlant(model, unknown="all", joint_params=True, base=True)
    assert len(base.names) < len(full.names)
    rng = np.random.default_rng(3)
    W = []
    for _ in range(10):
        q, v, w, a = (rng.normal(size=model.nv) for _ in range(4))
        Yf, tkf = _eval(full, q, v, w, a)
        Yb, tkb = _eval(base, q, v, w, a)
        assert np.allclose(Yb @ base.true_theta() + tkb, Yf @ full.true_theta() + tkf, rtol=0, atol=1e-9)
        W.append(Yb)
    W = np.vstack(W)
    assert np.linalg.matrix_rank(W) == len(base.names)


def test_payload_alone_is_identifiable():
    model = ARMS["ur5e+tool_offset"]
    plant = mp.ManipulatorPlant(model, unknown="payload")
    assert plant.names[0] == "payload/body.m" and len(plant.names) == 10
    assert plant.true_theta()[0] == pytest.approx(model.body_mass[plant.layout.bodies[0]], abs=0)
    base = mp.ManipulatorPlant(model, unknown="payload", base=True)
    assert len(base.names) == 10


def _with(xml_patch: tuple[str, str]) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(TEST_ARM.replace(*xml_patch))


@pytest.mark.parametrize("patch,match", [
    (('type="hinge" axis="0 0 1"', 'type="ball"'), "j4.*ball joint.*hinge and slide"),
    (('<motor joint="j4"/>', ''), r"\['j4'\] have no actuator"),
    (('<motor joint="j4"/>', '<position joint="j4" kp="10"/>'), "not a torque <motor>.*servo_to_torque"),
    (('<motor joint="j4"/>', '<motor joint="j4"/><motor joint="j4"/>'), "more than one actuator"),
    (('</worldbody>', '</worldbody><equality><joint joint1="j4" joint2="j5"/></equality>'),
     "equality constraint"),
    (('damping="0.7"', 'damping="0.7" stiffness="3"'), "j1.*stiffness"),
    (('<body name="l2"', '<body name="l2" gravcomp="1"'), "gravcomp"),
])
def test_unsupported_models_are_refused_with_one_line(patch, match):
    model = _with(patch)
    with pytest.raises(ModelError, match=match) as info:
        mp.ManipulatorPlant(model, unknown="all")
    assert "\n" not in str(info.value)


def test_free_floating_base_is_refused():
    model = mujoco.MjModel.from_xml_string(
        '<mujoco><worldbody><body><freejoint name="float"/><geom size="0.1"/></body></worldbody></mujoco>')
    with pytest.raises(ModelError, match="'float' is a free joint.*fixed base"):
        mp.ManipulatorPlant(model, unknown="all")


def test_unknown_body_names_are_checked():
    with pytest.raises(ModelError, match="body 'nope'.*moving bodies"):
        mp.ManipulatorPlant(ARMS["test_arm"], unknown=["nope"])
    with pytest.raises(ModelError, match="no payload body"):
        mp.ManipulatorPlant(ARMS["test_arm"], unknown="payload")


def test_servo_to_torque_rebuilds_position_servos():
    spec = mujoco.MjSpec.from_string(TEST_ARM.replace(
        '<motor joint="j4"/>', '<position name="servo4" joint="j4" kp="10" forcerange="-3 3"/>'))
    notes = mp.servo_to_torque(spec)
    assert notes == ["plant.servo_to_torque: servo(s) rebuilt as torque motors: 'servo4' |tau| <= [-3, 3] N*m"]
    plant = mp.ManipulatorPlant(spec.compile(), unknown="all")
    assert plant.ctrl_range[0][3] == -3 and plant.ctrl_range[1][3] == 3
    spec = mujoco.MjSpec.from_string(TEST_ARM.replace(
        '<motor joint="j4"/>', '<position name="servo4" joint="j4" kp="10"/>'))
    with pytest.raises(ModelError, match="servo4.*forcerange"):
        mp.servo_to_torque(spec)


def _ur5e_run(duration, *, mode=Mode.ADAPTIVE, events=(), payload="tool_offset"):
    xml, assets = build_arm_xml(arm=UR5E, payload=payload, site="tip")
    model = mujoco.MjModel.from_xml_string(xml, assets)
    plant = mp.ManipulatorPlant(model, unknown="payload")
    home = model.key("home").qpos
    ref = JointSumOfSines(center=tuple(home), amplitudes=((0.3, 0.2),) * 6,
                          omegas=((0.9, 2.3), (1.1, 2.7), (0.7, 1.9), (1.3, 3.1), (1.7, 2.9), (0.8, 3.7)))
    law = SlotineLiLaw(plant.regressor, plant.names, plant.m, lam=10.0, kd=50.0, gamma=0.5, mode=mode)
    plant.set_state(ref(0.0, 2)[:2])
    theta0 = np.zeros(len(plant.names)) if mode is Mode.ADAPTIVE else plant.true_theta() * 0.5
    return run(plant, law, ref, duration=duration, theta_hat0=theta0, events=events, native=False)


def test_slotine_li_lyapunov_non_increasing_and_tracks():
    traj = _ur5e_run(3.0)
    assert traj.status == "ok"
    assert traj.x.shape == (3000, 2, 6) and traj.u.shape == (3000, 6) and traj.joint_names[0] == "shoulder_pan"
    dV = np.diff(traj.V)
    assert dV.max() <= 1e-9 * traj.V[0], dV.max()
    assert traj.V[-1] < 0.1 * traj.V[0]
    e = traj.joint_errors
    assert np.sqrt(np.mean(e[-500:] ** 2, axis=0)).max() < 3e-3


GRIPPER_ARM = """<mujoco model="gripper_arm"><option timestep="0.001" integrator="RK4"/>
<worldbody><body name="link1"><joint name="shoulder" type="hinge" axis="0 1 0" armature="0.1"/>
  <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
  <body name="link2" pos="0.3 0 0"><joint name="elbow" type="hinge" axis="0 1 0" armature="0.1"/>
    <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="0.8"/>
    <body name="hand" pos="0.3 0 0"><geom type="box" size="0.02 0.04 0.02" mass="0.3"/>
      <body name="left_finger" pos="0.03 0.02 0"><joint name="finger1" type="slide" axis="0 1 0" range="0 0.04"/>
        <geom type="box" size="0.01 0.005 0.02" mass="0.02"/></body>
      <body name="right_finger" pos="0.03 -0.02 0"><joint name="finger2" type="slide" axis="0 -1 0" range="0 0.04"/>
        <geom type="box" size="0.01 0.005 0.02" mass="0.02"/></body>
    </body></body></body></worldbody>
<tendon><fixed name="split"><joint joint="finger1" coef="0.5"/><joint joint="finger2" coef="0.5"/></fixed></tendon>
<equality><joint joint1="finger1" joint2="finger2" polycoef="0 1 0 0 0"/></equality>
<actuator><motor name="m_shoulder" joint="shoulder"/><motor name="m_elbow" joint="elbow"/>
  <position name="grip" tendon="split" kp="100"/></actuator></mujoco>"""


def test_an_arm_with_a_gripper_is_refused_once_for_every_reason_with_a_fix_that_pastes(tmp_path, capsys):
    """A Panda-like arm (a tendon and an equality coupling two unactuated finger joints, no site `tip`): one line
    with all four reasons, numbered; the suggested plant.fixed_joints pastes as printed, and with it (and the
    payload site named) the arm is a manipulator: the fingers welded, the tendon, the equality and the grip's
    actuator gone, said in one note."""
    import re

    from adaptive_mj.cli import main

    (tmp_path / "gripper_arm.xml").write_text(GRIPPER_ARM)
    scenario = tmp_path / "mine.toml"
    scenario.write_text('schema_version = 1\n[plant]\nkind = "manipulator"\nmodel = "gripper_arm.xml"\n'
                        'payload = "tool_offset"\nunknown = "payload"\n[simulation]\nduration = 1.0\n'
                        '[reference]\nkind = "joint_sum_of_sines"\ncenter = { shoulder = 0.3, elbow = 0.5 }\n'
                        'amplitudes = { shoulder = [0.2], elbow = [0.2] }\n'
                        'omegas = { shoulder = [1.0], elbow = [1.3] }\n'
                        '[law]\nkind = "slotine_li"\nlambda = 10.0\nkd = 5.0\ngamma = 0.2\n')
    assert main(["run", str(scenario), "-o", str(tmp_path / "a.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "for 4 reasons: (1) no site named 'tip'" in err, err
    for reason in ("(2) the model has 1 tendon(s)", "(3) the model has 1 equality constraint(s)",
                   "(4) joint(s) ['finger1', 'finger2'] have no actuator"):
        assert reason in err, (reason, err)
    fix = re.search(r"--set '(plant\.fixed_joints=\[[^]]*\])'", err)
    assert fix is not None and fix.group(1) == 'plant.fixed_joints=["finger1", "finger2"]', err
    # pasted as printed, with the payload at a site the model has: the refusals are gone
    spec = mujoco.MjSpec.from_string(GRIPPER_ARM)
    notes = mp.fix_joints(spec, ("finger1", "finger2"))
    model = spec.compile()
    assert mp.refusals(model) == [] and (model.njnt, model.nu, model.ntendon, model.neq) == (2, 2, 0, 0)
    assert notes == ["plant.fixed_joints: joint(s) ['finger1', 'finger2'] fixed at their reference position "
                     "(removed with them: tendon(s) ['split'], 1 equality constraint(s), actuator(s) ['grip'])"]
    plant = mp.ManipulatorPlant(model, unknown="all")
    assert plant.joint_names == ("shoulder", "elbow") and len(plant.names) == 10 * 5  # the hand, the welded fingers
    assert main(["run", str(scenario), "-o", str(tmp_path / "b.mcap"), "--set", fix.group(1),
                 "--set", "plant.payload='none'", "--set", "plant.unknown='all'", "--set", "simulation.duration=0.05",
                 "--set", "simulation.python_callback=true"]) in (0, 1)
    out = capsys.readouterr()
    assert "note: plant.fixed_joints: joint(s) ['finger1', 'finger2'] fixed" in out.err
    with pytest.raises(ModelError, match=r"plant\.fixed_joints: no joint named 'thumb'.*'finger1'"):
        mp.fix_joints(mujoco.MjSpec.from_string(GRIPPER_ARM), ("thumb",))


def test_the_model_s_own_integrator_is_kept_unless_the_scenario_names_one_and_a_change_is_said(tmp_path):
    """A Menagerie arm declares <option integrator="implicitfast"/>: a scenario that names none keeps it (it was
    silently replaced by rk4) and says so once; one that names another says that it replaces the model's."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build

    (tmp_path / "arm.xml").write_text(GRIPPER_ARM.replace('integrator="RK4"', 'integrator="implicitfast"'))
    text = ('schema_version = 1\n[plant]\nkind = "manipulator"\nmodel = "arm.xml"\npayload = "none"\n'
            'unknown = "all"\nfixed_joints = ["finger1", "finger2"]\n[simulation]\nduration = 1.0\n'
            '[reference]\nkind = "joint_sum_of_sines"\ncenter = { shoulder = 0.3, elbow = 0.5 }\n'
            'amplitudes = { shoulder = [0.2], elbow = [0.2] }\nomegas = { shoulder = [1.0], elbow = [1.3] }\n'
            '[law]\nkind = "slotine_li"\nlambda = 10.0\nkd = 5.0\ngamma = 0.2\n')
    (tmp_path / "mine.toml").write_text(text)
    scn = sc.load(tmp_path / "mine.toml")
    setup = build(scn)
    assert scn.simulation.integrator == "implicitfast"
    assert setup.plant.model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    said = [n for n in setup.notes if "integrator" in n]
    assert said == ["simulation.integrator: the model's own 'implicitfast' (the scenario names none; without one "
                    "in the model: 'rk4')"]
    scn = sc.load(tmp_path / "mine.toml", overrides=["simulation.integrator='rk4'"])
    setup = build(scn)
    assert setup.plant.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    assert [n for n in setup.notes if "integrator" in n] == [
        "simulation.integrator = 'rk4' replaces the model's own 'implicitfast'"]
    (tmp_path / "arm.xml").write_text(GRIPPER_ARM.replace(' integrator="RK4"', ''))  # none declared: rk4, unsaid
    scn = sc.load(tmp_path / "mine.toml")
    assert scn.simulation.integrator == "rk4" and scn.simulation.integrator_note == ""

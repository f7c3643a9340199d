"""True parameters derived from the compiled model agree with MuJoCo's own dynamics.

Each plant's ``true_theta(model)`` is checked against an independent
identification: states (q, q', u) are set on an MjData, ``mj_forward`` gives
qacc, and the parameters of the plant's equation are solved for by least
squares over several points. Nothing here reuses the plant's own formulas.
"""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import arm, heave
from adaptive_mj.plants.mujoco_plant import compile_xml_path

REL = 1e-9


def assert_theta_close(estimate, truth, rel=REL):
    """Entry-wise relative agreement; entries that are zero in truth are compared
    absolutely against rel * |truth| (they carry no scale of their own)."""
    estimate, truth = np.asarray(estimate), np.asarray(truth)
    scale = np.linalg.norm(truth)
    tiny = np.abs(truth) <= 1e-12 * scale
    rel_err = np.abs(estimate - truth) / np.where(tiny, scale, np.abs(truth))
    assert np.all(rel_err <= rel), f"estimate {estimate} vs true {truth}: rel err {rel_err}"
    return rel_err


def _forward(model, data, q, qd, u):
    data.qpos[0], data.qvel[0], data.ctrl[0] = q, qd, u
    mujoco.mj_forward(model, data)
    assert data.ncon == 0 and not np.any(data.qfrc_constraint)
    return float(data.qacc[0])


# --------------------------------------------------------------------------- heave
def identify_heave(model) -> np.ndarray:
    """Solve d*qacc + b*v|v| + c*g = gear*u for [d, b, c] by least squares."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    g = float(-model.opt.gravity @ data.xaxis[0])  # gravity along the (upward) slide axis
    gear = float(model.actuator_gear[0, 0])
    rng = np.random.default_rng(1)
    rows, rhs = [], []
    for v in np.linspace(-2.0, 2.0, 9):
        q, u = rng.uniform(-1, 1), rng.uniform(-150, 150)
        qacc = _forward(model, data, q, v, u)
        rows.append([qacc, v * abs(v), g])
        rhs.append(gear * u)
    sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    return sol


def test_heave_true_theta_matches_mujoco_dynamics():
    model = compile_xml_path(heave.MODEL_PATH)
    model.opt.viscosity = 0.0  # the viscous term is a separate, unmodelled force
    truth = heave.true_theta(model)
    rel = assert_theta_close(identify_heave(model), truth)
    print(f"heave identification rel err {rel}")
    # the file's own derivation, as a sanity check of units and magnitudes
    np.testing.assert_allclose(truth, [37.0, 60.0, 1.0], rtol=1e-12)


def test_heave_true_theta_after_fluid_density_change():
    plant = heave.load()
    plant.model.opt.viscosity = 0.0
    plant.set_fluid_density(1025.0)  # sea water: more drag and more buoyancy
    truth = plant.true_theta()
    assert_theta_close(identify_heave(plant.model), truth)
    assert truth[1] == pytest.approx(60.0 * 1.025, rel=1e-12)
    assert truth[2] == pytest.approx(25.0 - 1025.0 * 0.024, rel=1e-12)  # now lighter than water


def test_heave_unmodelled_linear_drag_is_the_viscous_force():
    """With viscosity > 0 the only extra generalised force is -c_lin * v."""
    wet = compile_xml_path(heave.MODEL_PATH)
    assert wet.opt.viscosity > 0
    dry = compile_xml_path(heave.MODEL_PATH)
    dry.opt.viscosity = 0.0
    c_lin = heave.unmodelled_linear_drag(wet)
    assert c_lin > 0
    assert heave.unmodelled_linear_drag(dry) == 0.0
    d_wet, d_dry = mujoco.MjData(wet), mujoco.MjData(dry)
    for v in [-3.0, -0.2, -1e-3, 1e-4, 0.05, 1.0, 2.5]:
        _forward(wet, d_wet, 0.1, v, 0.0)
        _forward(dry, d_dry, 0.1, v, 0.0)
        extra = d_wet.qfrc_passive[0] - d_dry.qfrc_passive[0]
        assert extra == pytest.approx(-c_lin * v, rel=1e-9)
    # the regressor form itself does not depend on viscosity
    np.testing.assert_array_equal(heave.true_theta(wet), heave.true_theta(dry))


OBLIQUE_HULL_XML = """
<mujoco model="oblique_hull">
  <compiler angle="radian"/>
  <option timestep="0.001" gravity="0 0 -9.81" density="1000" viscosity="0"/>
  <worldbody>
    <body name="sub" gravcomp="0.9">
      <joint name="z" type="slide" axis="0 0 1" armature="5"/>
      <geom type="box" size="0.20 0.15 0.10" euler="0.5 0.3 0.2" mass="25"
            contype="0" conaffinity="0"/>
    </body>
  </worldbody>
  <actuator><motor joint="z" gear="1"/></actuator>
</mujoco>
"""


def test_heave_true_theta_with_hull_not_aligned_to_the_joint(tmp_path):
    """Regression (was a bug in heave.true_theta): the drag coefficient
    was computed as b = ½ rho sum_i A_i a_i², but MuJoCo's inertia-box drag acts
    per principal axis (F_i = -½ rho A_i |v_i| v_i), so along the joint
    b = ½ rho sum_i A_i |a_i|³. The two agree only when the joint is along a
    principal axis of the hull; a user's heave MJCF with a rotated hull gets a
    wrong "true" b (here 53.8 instead of 41.1 kg/m)."""
    path = tmp_path / "oblique.xml"
    path.write_text(OBLIQUE_HULL_XML)
    model = heave.load(path).model
    assert_theta_close(identify_heave(model), heave.true_theta(model))


# --------------------------------------------------------------------------- arm
def identify_arm(model, ctrl_max: float = 15.0) -> np.ndarray:
    """Solve J*qacc + b*q' + g_sin*sin q + g_cos*cos q = gear*u for [J, b, g_sin, g_cos]."""
    data = mujoco.MjData(model)
    gear = float(model.actuator_gear[0, 0])
    rng = np.random.default_rng(2)
    rows, rhs = [], []
    for q in np.linspace(-np.pi, np.pi, 11, endpoint=False):
        qd, u = rng.uniform(-4, 4), rng.uniform(-ctrl_max, ctrl_max)
        qacc = _forward(model, data, q, qd, u)
        rows.append([qacc, qd, np.sin(q), np.cos(q)])
        rhs.append(gear * u)
    sol, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
    return sol


@pytest.mark.parametrize(
    "kwargs",
    [dict(), dict(payload_mass=1.0), dict(payload="box_offset")],
    ids=["sphere", "sphere_1kg", "box_offset"],
)
def test_arm_true_theta_matches_mujoco_dynamics(kwargs):
    model = arm.compile_arm(**kwargs)
    truth = arm.true_theta(model)
    rel = assert_theta_close(identify_arm(model), truth)
    print(f"arm {kwargs} identification rel err {rel}")
    # the bundled arm hangs down at q = 0: gravity enters through sin q only
    assert abs(truth[3]) <= 1e-12 * np.linalg.norm(truth)
    assert truth[2] > 0


def test_arm_plant_wraps_the_same_theta():
    plant = arm.load(payload_mass=1.0)
    np.testing.assert_array_equal(plant.true_theta(), arm.true_theta(plant.model))
    assert plant.form.names == arm.THETA_NAMES
    assert plant.ctrl_range == (-20.0, 20.0)


# A user's own arm: hinge along x, link horizontal (along y) at q = 0, a rotated
# body frame, a joint anchor off the body origin, a second moving body with an
# offset, full (non-diagonal) inertia, a fixed body that must not count, a
# gear != 1, and names the plant has to find by itself.
USER_ARM_XML = """
<mujoco model="my_own_arm">
  <option timestep="0.002" gravity="0 0 -9.81"><flag contact="disable"/></option>
  <worldbody>
    <body name="stand" pos="0 0 0.5"><geom type="box" size="0.05 0.05 0.5" mass="3"/></body>
    <body name="upper_xyz" pos="0.1 0.2 1.2" quat="0.9 0.1 0.3 0.2">
      <joint name="roll_joint_7" type="hinge" axis="1 0 0" pos="0.02 -0.01 0.03"
             damping="0.13" armature="0.004" {ref}/>
      <geom type="capsule" fromto="0 0 0 0 0.4 0" size="0.03" mass="1.2"/>
      <body name="tool" pos="0.05 0.4 0.02" euler="0.3 -0.2 0.5" {gravcomp}>
        <inertial pos="0.03 0.06 -0.02" mass="0.7"
                  fullinertia="0.004 0.003 0.002 0.0004 -0.0003 0.0002"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor name="drive_unit_B" joint="roll_joint_7" gear="2.5"/></actuator>
</mujoco>
"""


@pytest.mark.parametrize(
    "extra",
    [dict(ref="", gravcomp=""), dict(ref='ref="0.3"', gravcomp='gravcomp="0.25"')],
    ids=["plain", "with_ref_and_gravcomp"],
)
def test_user_arm_with_other_zero_angle_convention(tmp_path, extra):
    path = tmp_path / "my_arm.xml"
    path.write_text(USER_ARM_XML.format(**extra))
    plant = arm.load_bare(path)  # joint and actuator found without names
    model = plant.model
    assert mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, plant.joint_id) == "roll_joint_7"
    assert mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, plant.actuator_id) == "drive_unit_B"
    assert plant.form.h(np.zeros(2)) == 2.5
    truth = plant.true_theta()
    rel = assert_theta_close(identify_arm(model), truth)
    print(f"user arm {extra} identification rel err {rel}")
    # horizontal at q = 0 with an offset centre of mass: gravity acts through cos q too
    assert abs(truth[3]) > 0.1 * abs(truth[2]) and abs(truth[3]) > 1.0
    # the stand is not moved by the hinge; J is the moved bodies' inertia only
    M = np.zeros((1, 1))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    mujoco.mj_fullM(model, data, M)
    assert truth[0] == pytest.approx(M[0, 0], rel=1e-12)


@pytest.mark.parametrize("payload, mass", [("sphere", 1.3), ("box_offset", 0.35)])
def test_runtime_payload_mass_change_matches_fresh_compile(payload, mass):
    swapped = arm.load(payload=payload)
    before = swapped.true_theta().copy()
    swapped.set_body_mass("payload/body", mass)
    fresh = arm.load(payload=payload, payload_mass=mass)
    after = swapped.true_theta()
    assert not np.allclose(after, before)  # the change did something
    assert_theta_close(after, fresh.true_theta())
    # same dynamics: qacc at the same states, and 200 RK4 steps under the same control
    for q, qd, u in [(0.0, 0.0, 0.0), (0.7, -1.3, 4.0), (-2.5, 2.0, -9.0), (3.0, 0.4, 12.0)]:
        a = _forward(swapped.model, swapped.data, q, qd, u)
        b = _forward(fresh.model, fresh.data, q, qd, u)
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12)
    for plant in (swapped, fresh):
        plant.set_state([0.4, 0.0])
        for i in range(200):
            plant.data.ctrl[0] = 3.0 * np.sin(0.01 * i)
            plant.step()
    np.testing.assert_allclose(swapped.observe(), fresh.observe(), rtol=1e-9, atol=1e-12)

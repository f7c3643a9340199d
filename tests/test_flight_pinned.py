"""The flight plant's events, crash check and rotor drag pinned with independent numbers (issue 54): each checked
where it acts. A rotor-efficiency event on every rotor (1 to 4) read off the actuator's force and the moment MuJoCo
applies, against the rotor's place written out by hand; two external-force events adding, read off xfrc_applied and
the velocity one step gives; a vehicle that takes off and comes down (a crash) against one that never rose (none);
the tilt crash; the crash check's rules and edges by name; the attitude measured from a quaternion; and RotorPy's
rotor drag (plants.airframe.rotor_drag_into, run as plain Python: no numba) against hand-computed numbers and an
independent vectorised formula.

Every number here is typed from the model's documented values (models/quadrotor.xml: a = 0.030405592 m the hub
offset, c = 0.03391304 m the yaw torque per unit thrust, rotor_dir (+1, −1, +1, −1), mass 0.03 kg, inertia
diag(1.43e-5, 1.43e-5, 2.86e-5) kg m², T_max = 0.14375 N, the fuselage's half-height 0.0145 m) or computed by hand
in the test. tools/mutate.py runs this file for the plant's modules; it runs in seconds."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import airframe
from adaptive_mj.plants import quadrotor as quad
from adaptive_mj.specs import EventSpec

A_HUB = 0.030405592  # [m] each hub's |x| and |y| in the body frame
C_YAW = 0.03391304  # [m] yaw torque per unit thrust
ROTOR_XY_DIR = {1: (A_HUB, A_HUB, +1), 2: (A_HUB, -A_HUB, -1), 3: (-A_HUB, -A_HUB, +1), 4: (-A_HUB, A_HUB, -1)}
MASS = 0.03  # [kg]
JXX, JZZ = 1.43e-5, 2.86e-5  # [kg m²]
CLEARANCE = 0.0145  # [m] the fuselage ellipsoid's half-height: where the level body's origin rests on the ground
H = 0.002  # [s] the model's time step
COS80 = math.cos(math.radians(80.0))


def _jointed():
    """The bundled quadrotor between two bodies on slide joints of their own (declared before and after it): the
    free joint's qpos at 1 to 7 of 9, its qvel at 1 to 6 of 8 (addresses read as the airframe's, not as 0, and
    slices that end where the free joint's do)."""
    def slider(name):
        return (f'<body name="{name}" pos="1 1 0.5"><joint name="{name}" type="slide" axis="1 0 0"/>'
                '<geom size="0.01" mass="0.1" contype="0" conaffinity="0"/></body>')

    xml = quad.MODEL_PATH.read_text(encoding="utf-8")
    xml = xml.replace("<worldbody>", "<worldbody>" + slider("before"), 1).replace(
        "</worldbody>", slider("after") + "</worldbody>", 1)
    plant = quad.QuadrotorPlant(mujoco.MjModel.from_xml_string(xml))
    assert (plant.airframe.qpos, plant.airframe.qvel, plant.model.nq, plant.model.nv) == (1, 1, 9, 8)
    return plant


MODELS = {"bundled": quad.load, "after a slide joint": _jointed}


def _ground(t, speed, z):
    """The reason a ground crash gives (t [s], speed [m/s], z [m]), typed as the crash check documents it."""
    return f"crashed at t = {t:.4g} s: hit the ground at {speed:.3g} m/s (its centre {z:.3g} m up)"


def _level(plant, z=1.0):
    """The plant level and at rest at height z [m] above the origin (set_state: the rotors trimmed to the weight)."""
    plant.set_state(np.array([[0.0, 0.0, z], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))


# --- the crash check, by its rules ---------------------------------------------------------------------------


def test_a_level_vehicle_high_up_is_no_crash_and_is_airborne():
    assert quad.crash_check(1.0, 1.0, 0.0, 0.0, 0.0, False, 0.1, CLEARANCE, COS80) == (quad.NO_CRASH, 0.0, True)


def test_airborne_means_risen_more_than_5_cm_above_the_start():
    """z0 + 0.05 exactly is not yet airborne (strictly above); a hair more is; once airborne it stays so."""
    z0 = 0.5
    rise = 0.5 + 0.05  # 0.55
    assert quad.crash_check(rise, 1.0, 0.0, 0.0, 0.0, False, z0, CLEARANCE, COS80)[2] is False
    assert quad.crash_check(rise + 1e-9, 1.0, 0.0, 0.0, 0.0, False, z0, CLEARANCE, COS80)[2] is True
    assert quad.crash_check(0.2, 1.0, 0.0, 0.0, 0.0, True, z0, CLEARANCE, COS80) == (quad.NO_CRASH, 0.0, True)


def test_down_to_the_clearance_is_a_crash_only_once_airborne():
    """At the clearance exactly (and below it, above the plane): a crash with value z after take-off; none for a
    vehicle still sitting where it started."""
    assert quad.crash_check(CLEARANCE, 1.0, 0.0, 0.0, 0.0, True, 0.0145, CLEARANCE, COS80) == \
        (quad.CRASH_GROUND, CLEARANCE, True)
    assert quad.crash_check(0.01, 1.0, 0.0, 0.0, 0.0, True, 0.0145, CLEARANCE, COS80) == \
        (quad.CRASH_GROUND, 0.01, True)
    assert quad.crash_check(CLEARANCE + 1e-6, 1.0, 0.0, 0.0, 0.0, True, 0.0145, CLEARANCE, COS80)[0] == quad.NO_CRASH
    assert quad.crash_check(CLEARANCE, 1.0, 0.0, 0.0, 0.0, False, 0.0145, CLEARANCE, COS80) == \
        (quad.NO_CRASH, 0.0, False)
    assert quad.crash_check(0.0, 1.0, 0.0, 0.0, 0.0, False, 0.0145, CLEARANCE, COS80) == (quad.NO_CRASH, 0.0, False)


def test_the_centre_below_the_ground_plane_is_a_crash_airborne_or_not():
    assert quad.crash_check(-0.001, 1.0, 0.0, 0.0, 0.0, False, 0.0145, CLEARANCE, COS80) == \
        (quad.CRASH_BELOW, -0.001, False)
    assert quad.crash_check(-0.001, 1.0, 0.0, 0.0, 0.0, True, 0.0145, CLEARANCE, COS80)[:2] == \
        (quad.CRASH_BELOW, -0.001)


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.6, 0.8, 0.0)])
def test_a_tilt_past_80_degrees_is_a_crash_with_its_cosine(axis):
    """A rotation by θ about a horizontal axis tilts body z by θ: cos θ = w² − x² − y² + z² = cos²(θ/2) −
    sin²(θ/2). 81° is past 80° (value cos 81° = 0.15643), 79° is not."""
    for deg, crash in ((81.0, True), (79.0, False)):
        half = math.radians(deg) / 2
        q = (math.cos(half), axis[0] * math.sin(half), axis[1] * math.sin(half), axis[2] * math.sin(half))
        code, value, _ = quad.crash_check(1.0, *q, True, 0.1, CLEARANCE, COS80)
        if crash:
            assert code == quad.CRASH_TILT_CODE and value == pytest.approx(0.15643446504, abs=1e-10)
        else:
            assert code == quad.NO_CRASH


def test_a_yaw_is_no_tilt_and_a_tilt_exactly_at_the_bound_is_not_past_it():
    """Rotating 170° about z leaves body z up (cos = w² + z² = 1); a bound met exactly is no crash."""
    half = math.radians(170.0) / 2
    assert quad.crash_check(1.0, math.cos(half), 0.0, 0.0, math.sin(half), True, 0.1, CLEARANCE, COS80)[0] == \
        quad.NO_CRASH
    assert quad.crash_check(1.0, 1.0, 0.0, 0.0, 0.0, True, 0.1, CLEARANCE, 1.0)[0] == quad.NO_CRASH


def test_the_tilt_is_checked_first_then_the_plane_then_the_ground():
    q = (math.cos(math.radians(45.0)), math.sin(math.radians(45.0)), 0.0, 0.0)  # 90° about x: cos = 0
    assert quad.crash_check(-0.5, *q, True, 0.1, CLEARANCE, COS80)[0] == quad.CRASH_TILT_CODE
    assert quad.crash_check(-0.5, 1.0, 0.0, 0.0, 0.0, True, 0.1, CLEARANCE, COS80)[0] == quad.CRASH_BELOW


def test_the_crash_reasons_read_as_written():
    assert quad.crash_text(quad.CRASH_TILT_CODE, 0.5, 1.25, 80.0, 3.0) == \
        "crashed at t = 1.25 s: tilted 60.0 deg, past plant.crash_tilt = 80 deg"
    assert quad.crash_text(quad.CRASH_TILT_CODE, -1.0000001, 2.0, 80.0, 0.0).endswith("tilted 180.0 deg, past "
                                                                                      "plant.crash_tilt = 80 deg")
    assert quad.crash_text(quad.CRASH_TILT_CODE, 1.0000001, 2.0, 80.0, 0.0).endswith("tilted 0.0 deg, past "
                                                                                     "plant.crash_tilt = 80 deg")
    assert quad.crash_text(quad.CRASH_BELOW, -0.002, 0.5, 80.0, 1.0) == \
        "crashed at t = 0.5 s: the body's centre is 0.002 m below the ground plane"
    assert quad.crash_text(quad.CRASH_GROUND, 0.0141, 0.684, 80.0, 2.5) == \
        "crashed at t = 0.684 s: hit the ground at 2.5 m/s (its centre 0.0141 m up)"


# --- the attitude measured --------------------------------------------------------------------------------------


def test_the_rotation_vector_of_quaternions_by_hand():
    s = math.sqrt(0.5)
    np.testing.assert_allclose(quad.rotation_vector(np.array([s, 0.0, 0.0, s])), [0.0, 0.0, math.pi / 2],
                               rtol=1e-14)
    np.testing.assert_allclose(quad.rotation_vector(np.array([s, -s, 0.0, 0.0])), [-math.pi / 2, 0.0, 0.0],
                               rtol=1e-14)
    # 200° about y is −160° about y: the shorter way round
    half = math.radians(200.0) / 2
    np.testing.assert_allclose(quad.rotation_vector(np.array([math.cos(half), 0.0, math.sin(half), 0.0])),
                               [0.0, -math.radians(160.0), 0.0], rtol=1e-13)
    # half a turn exactly (w = 0: angle 2 atan2(1, 0) = π) stays +π; an axis part below 1e-15 reads as no rotation,
    # from 1e-15 on it is 2 x it (the angle of a small rotation)
    np.testing.assert_allclose(quad.rotation_vector(np.array([0.0, 1.0, 0.0, 0.0])), [math.pi, 0.0, 0.0],
                               rtol=1e-15)
    assert np.array_equal(quad.rotation_vector(np.array([1.0, 1e-16, 0.0, 0.0])), [0.0, 0.0, 0.0])
    for small in (1e-15, 1.5e-15, 1e-10):
        np.testing.assert_allclose(quad.rotation_vector(np.array([1.0, small, 0.0, 0.0])), [2 * small, 0.0, 0.0],
                                   rtol=1e-9)


def test_the_state_is_read_from_the_free_joint_s_own_addresses():
    """qpos/qvel with the free joint not first (qadr 2, dadr 1): x = [p; v; φ; Ω]; φ of a quaternion with four
    different components against scipy's."""
    from scipy.spatial.transform import Rotation

    q = np.array([1.0, 2.0, 3.0, 4.0]) / math.sqrt(30.0)
    x = np.full((4, 3), np.nan)
    quad.measure_into(np.array([9.0, 9.0, 1.0, 2.0, 3.0, *q, 9.0, 8.0, 7.0]), np.arange(8.0), 2, 1, x)
    np.testing.assert_allclose(x[2], Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_rotvec(), rtol=1e-13)
    np.testing.assert_array_equal(x[[0, 1, 3]], [[1.0, 2.0, 3.0], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    s = math.sqrt(0.5)
    qpos = np.array([9.0, 9.0, 1.0, 2.0, 3.0, s, 0.0, 0.0, s, 9.0])
    qvel = np.array([9.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 9.0])
    x = np.full((4, 3), np.nan)
    quad.measure_into(qpos, qvel, 2, 1, x)
    np.testing.assert_allclose(x, [[1.0, 2.0, 3.0], [0.1, 0.2, 0.3], [0.0, 0.0, math.pi / 2], [0.4, 0.5, 0.6]],
                               rtol=1e-14)
    qpos[5:9] = [1.0, 0.0, 0.0, 0.0]  # no rotation: φ written as zeros over what x held
    x[:] = np.nan
    quad.measure_into(qpos, qvel, 2, 1, x)
    assert np.array_equal(x[2], [0.0, 0.0, 0.0])


# --- the events, where they act ---------------------------------------------------------------------------------


@pytest.mark.parametrize("rotor", [1, 2, 3, 4])
def test_a_rotor_efficiency_event_weakens_that_rotor_and_no_other(rotor):
    """Rotor r at half efficiency with every rotor's activation at 0.1 N: its actuator gives 0.05 N, the others
    0.1 N, and the moment MuJoCo applies (qfrc_actuator's rotational dofs, body frame = world at level) is the
    missing 0.05 N's: −0.05 (y_r, −x_r, c dir_r) [N m]; the force 0.35 N up."""
    plant = quad.load()
    event = quad._rotor(EventSpec(t=1.0, kind="rotor_efficiency", value=0.5, params={"rotor": rotor}), None, None)
    assert event.t == 1.0 and event.label == f"rotor {rotor} thrust x 0.5"
    event.apply(plant)
    _level(plant)
    d = plant.data
    d.act[:] = 0.1
    mujoco.mj_forward(plant.model, d)
    expected = np.full(4, 0.1)
    expected[rotor - 1] = 0.05
    np.testing.assert_allclose(d.actuator_force, expected, rtol=1e-12)
    x, y, sign = ROTOR_XY_DIR[rotor]
    np.testing.assert_allclose(d.qfrc_actuator[3:6], [-0.05 * y, 0.05 * x, -0.05 * C_YAW * sign], rtol=1e-6,
                               atol=1e-15)
    np.testing.assert_allclose(d.qfrc_actuator[:3], [0.0, 0.0, 0.35], rtol=1e-12, atol=1e-15)


def test_two_rotor_events_on_one_rotor_multiply():
    plant = quad.load()
    plant.scale_rotor(4, 0.5)
    plant.scale_rotor(4, 0.5)
    assert list(plant.model.actuator_gainprm[:4, 0]) == [1.0, 1.0, 1.0, 0.25]


def test_two_external_force_events_add_and_act_on_the_body():
    """(0.1, 0, 0) N with (0, 0, 1e-4) N m, then (0.05, −0.02, 0) N with (2e-4, 0, 0) N m: the plant holds their sum,
    θ's d and τ say it, each step puts it in xfrc_applied, and one step from rest gives v = F h/m (5 and −2/3 m/s²
    over 2 ms) and Ω = τ h/J (about x 2e-4/1.43e-5, about z 1e-4/2.86e-5 rad/s²) while the rotors hold the weight."""
    plant = quad.load()
    _level(plant)
    assert np.array_equal(plant.true_theta()[7:13], np.zeros(6))  # cached before the events
    for force, torque in (((0.1, 0.0, 0.0), (0.0, 0.0, 1e-4)), ((0.05, -0.02, 0.0), (2e-4, 0.0, 0.0))):
        spec = EventSpec(t=0.0, kind="external_force", value=0.0, params={"force": force, "torque": torque})
        quad._force(spec, None, None).apply(plant)
    np.testing.assert_allclose(plant.external_force, [0.15, -0.02, 0.0], rtol=1e-15)
    np.testing.assert_allclose(plant.external_torque, [2e-4, 0.0, 1e-4], rtol=1e-15)
    np.testing.assert_allclose(plant.true_theta()[7:13], [0.15, -0.02, 0.0, 2e-4, 0.0, 1e-4], rtol=1e-15)
    d = plant.data
    d.ctrl[:] = MASS * 9.81 / 4  # the activations start trimmed there
    plant.step()
    np.testing.assert_allclose(d.xfrc_applied[plant.body], [0.15, -0.02, 0.0, 2e-4, 0.0, 1e-4], rtol=1e-15)
    # to 5e-4: the roll torque tilts the thrust by ~1e-5 rad within the step (9.81 x 1e-5 m/s² against 0.67 m/s²)
    np.testing.assert_allclose(d.qvel[:3], [0.15 / MASS * H, -0.02 / MASS * H, 0.0], rtol=5e-4, atol=1e-9)
    # Ω_y: the gyroscopic coupling of Ω_x and Ω_z within the step, ~2e-7 rad/s
    np.testing.assert_allclose(d.qvel[3:6], [2e-4 / JXX * H, 0.0, 1e-4 / JZZ * H], rtol=1e-4, atol=1e-6)
    assert plant.termination() is None


def test_a_vehicle_that_takes_off_and_comes_down_has_crashed():
    """From rest on the ground (z = 0.0145 m, not airborne), full thrust for 0.2 s, then none: it rises far above
    the 5 cm that make it airborne and falls back. The crash is the first step that ends at or below the clearance
    after it had risen past 0.0645 m (found here from the heights the test records), with the speed then."""
    plant = quad.load()
    _level(plant, CLEARANCE)
    d = plant.data
    risen, expected = False, None
    for k in range(600):
        d.ctrl[:] = 0.14375 if k < 100 else 0.0
        plant.step()
        z = float(d.qpos[2])
        if expected is None and risen and z <= CLEARANCE:
            expected = (float(d.time), float(np.linalg.norm(d.qvel[:3])), z)
        risen = risen or z > CLEARANCE + 0.05
        if k == 99:
            assert plant.termination() is None and z > 0.1  # took off
    assert expected is not None and 0.4 < expected[0] < 1.0
    t, speed, z = expected
    assert speed > 1.0
    assert plant.termination() == _ground(t, speed, z)


def test_a_vehicle_that_never_rose_5_cm_is_no_crash():
    """Dropped from 5 cm (below the clearance + 5 cm that count as airborne) with no thrust: it lands, no crash."""
    plant = quad.load()
    _level(plant, 0.05)
    d = plant.data
    for _ in range(300):
        d.ctrl[:] = 0.0
        plant.step()
    assert float(d.qpos[2]) < CLEARANCE + 1e-3
    assert plant.termination() is None


@pytest.mark.parametrize("model", MODELS)
def test_a_vehicle_that_starts_in_the_air_and_falls_has_crashed(model):
    """From the model's start (0.1 m > 0.0145 + 0.05: airborne from the first step), moving at (0.3, −0.4, 0) m/s with
    no thrust: it falls (no horizontal force: it keeps (0.3, −0.4)) and hits the ground at the first step that ends
    at or below the clearance, at the speed it has then: about √(0.25 + 2 g (0.1 − z)) by hand."""
    plant = MODELS[model]()
    plant.set_state(np.array([[0.2, -0.3, 0.1], [0.3, -0.4, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    d, a, dv = plant.data, plant.airframe.qpos, plant.airframe.qvel
    expected, before = None, None
    for _ in range(150):
        d.ctrl[:] = 0.0
        plant.step()
        if expected is None and d.qpos[a + 2] <= CLEARANCE:
            expected = (float(d.time), float(np.linalg.norm(d.qvel[dv:dv + 3])), float(d.qpos[a + 2]))
            # the step before, in free fall still (the ground's contact acts within the crash's step)
            z_before, v_before = before
            np.testing.assert_allclose(v_before[:2], [0.3, -0.4], rtol=1e-9)
            assert np.linalg.norm(v_before) == pytest.approx(math.sqrt(0.25 + 2 * 9.81 * (0.1 - z_before)), rel=1e-3)
        before = (float(d.qpos[a + 2]), d.qvel[dv:dv + 3].copy())
    assert expected is not None
    t, speed, z = expected
    assert plant.termination() == _ground(t, speed, z)


def test_a_vehicle_dropped_from_exactly_5_cm_above_its_rest_is_not_airborne():
    """Starting at the clearance + 0.05 m exactly is not above it: not airborne, and with no thrust it lands
    without a crash."""
    plant = quad.load()
    _level(plant, plant.clearance + 0.05)
    for _ in range(200):
        plant.data.ctrl[:] = 0.0
        plant.step()
    assert float(plant.data.qpos[2]) < CLEARANCE and plant.termination() is None


@pytest.mark.parametrize("steps, crash", [(30, False), (40, True)])
def test_a_hop_counts_as_airborne_from_5_cm_above_its_start(steps, crash):
    """From 6 cm (not airborne: below 0.0145 + 0.05), full thrust for 30 steps lifts it to 9.3 cm, 3.3 cm above its
    start: down again is no crash; 40 steps lift it to 11.8 cm, past 6 + 5 cm: down again is a crash."""
    plant = quad.load()
    _level(plant, 0.06)
    d, peak = plant.data, 0.0
    for k in range(250):
        d.ctrl[:] = 0.14375 if k < steps else 0.0
        plant.step()
        peak = max(peak, float(d.qpos[2]))
    assert (0.08 < peak < 0.105) if not crash else (0.115 < peak < 0.13)
    assert float(d.qpos[2]) < CLEARANCE
    assert ("hit the ground" in (plant.termination() or "")) is crash


@pytest.mark.parametrize("model", MODELS)
def test_a_tilt_past_the_bound_ends_the_run_and_the_first_crash_is_kept(model):
    """φ = (1.3, −0.8, 0.9) rad (every quaternion component non-zero), at p = (0.2, −0.3, 1): body z tilted by
    acos(R[2, 2]) of scipy's rotation, 83.7°, past 80°: a crash at the first step, its text kept after."""
    from scipy.spatial.transform import Rotation

    phi = np.array([1.3, -0.8, 0.9])
    tilt = math.degrees(math.acos(Rotation.from_rotvec(phi).as_matrix()[2, 2]))
    assert 82.0 < tilt < 86.0
    plant = MODELS[model]()
    plant.set_state(np.array([[0.2, -0.3, 1.0], [0.0, 0.0, 0.0], phi, [0.0, 0.0, 0.0]]))
    plant.step()
    text = f"crashed at t = 0.002 s: tilted {tilt:.1f} deg, past plant.crash_tilt = 80 deg"
    assert plant.termination() == text
    plant.step()
    assert plant.termination() == text
    upright = quad.load(crash_tilt=90.0)
    upright.set_state(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], phi, [0.0, 0.0, 0.0]]))
    upright.step()
    assert upright.termination() is None


# --- RotorPy's rotor drag, as plain Python --------------------------------------------------------------------


def _drag(qvel, dadr, R, ctrl, act, gain, acts, actadr, rotors, wind, coeffs, nv=None):
    """qfrc (nv,) [N, N m] of rotor_drag_into for qvel (nv,) [m/s, rad/s] with the free joint at dadr, R (3, 3)
    body-to-world (passed as MjData.xmat's row-major (9,)), ctrl (4,) and act [N], one gain for every actuator, acts
    (4,), actadr (4,), rotors (4, 3) [m], wind (3,) [m/s], coeffs [k_eta, k_d, k_z]; [lo, hi] = [0, 0.5] N. qfrc
    starts at NaN where it writes and 7 elsewhere, so the rest must be left alone."""
    qfrc = np.full(len(qvel) if nv is None else nv, 7.0)
    qfrc[dadr:dadr + 6] = np.nan
    gainprm = np.zeros((len(ctrl), 10))
    gainprm[:, 0] = gain
    airframe.rotor_drag_into(np.asarray(qvel, float), dadr, np.asarray(R, float).reshape(9), np.asarray(ctrl, float),
                             np.asarray(act, float), gainprm, np.asarray(acts), np.asarray(actadr),
                             np.zeros(4), np.full(4, 0.5), np.asarray(rotors, float), np.asarray(wind, float),
                             np.asarray(coeffs, float), qfrc)
    return qfrc


SQUARE = [[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0]]


def test_the_rotor_drag_of_a_level_body_flying_along_x_by_hand():
    """k_eta 0.01, k_d 0.5, k_z 0.25; thrusts 0.04, 0.09, 0.01, 0.16 N (ω = 2, 3, 1, 4 rad/s); v = (2, 0, 1) m/s,
    level, hubs at (±1, ±1, 0) m: H_i = −ω_i (0.5·2, 0, 0.25·1) = −ω_i (1, 0, 0.25); F = −10 (1, 0, 0.25);
    M = Σ r_i × H_i = Σ −ω_i (y_i 0.25, −0.25 x_i, −y_i) = −(0.25 Σω y, −0.25 Σω x, −Σω y) with Σω x = 2 + 3 − 1 − 4
    = 0, Σω y = 2 − 3 − 1 + 4 = 2: M = (−0.5, 0, 2)."""
    got = _drag([2.0, 0.0, 1.0, 0.0, 0.0, 0.0], 0, np.eye(3), [0.04, 0.09, 0.01, 0.16], [0.0], 1.0,
                [0, 1, 2, 3], [-1, -1, -1, -1], SQUARE, [0.0, 0.0, 0.0], [0.01, 0.5, 0.25])
    np.testing.assert_allclose(got, [-10.0, 0.0, -2.5, -0.5, 0.0, 2.0], rtol=1e-14, atol=1e-15)


def test_the_rotor_drag_in_a_yawed_frame_reads_the_body_airspeed_and_writes_the_world_force():
    """Yawed 90° (body x = world y), flying along world y at 3 m/s in a 1 m/s wind along world y: body airspeed
    (2, 0, 0); equal thrusts 0.04 N (ω = 2): F_body = −4·2·(0.5·2, 0, 0) = (−8, 0, 0), in the world (0, −8, 0);
    no moment (the hubs are symmetric)."""
    R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    got = _drag([0.0, 3.0, 0.0, 0.0, 0.0, 0.0], 0, R, [0.04] * 4, [0.0], 1.0, [0, 1, 2, 3], [-1] * 4, SQUARE,
                [0.0, 1.0, 0.0], [0.01, 0.5, 0.25])
    np.testing.assert_allclose(got, [0.0, -8.0, 0.0, 0.0, 0.0, 0.0], atol=1e-14)


def test_the_rotor_drag_of_a_spinning_body_by_hand():
    """At rest but turning at Ω = (0, 0, 1) rad/s, one rotor only (rotor 1 at (1, 0, 0.5) m, ω = 2): its hub moves
    at Ω × r = (0, 1, 0): H = −2 (0, 0.5, 0) = (0, −1, 0); M = r × H = (0.5, 0, −1) [N m]."""
    rotors = [[1.0, 0.0, 0.5], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    got = _drag([0.0, 0.0, 0.0, 0.0, 0.0, 1.0], 0, np.eye(3), [0.04, 0.0, 0.0, 0.0], [0.0], 1.0, [0, 1, 2, 3],
                [-1] * 4, rotors, [0.0, 0.0, 0.0], [0.01, 0.5, 0.25])
    np.testing.assert_allclose(got, [0.0, -1.0, 0.0, 0.5, 0.0, -1.0], atol=1e-14)


def test_the_rotor_drag_reads_each_rotor_s_own_thrust():
    """A lagged rotor's thrust is gain · its activation (not its control); an unlagged one's gain · its control
    clamped into [lo, hi] = [0, 0.5]; the rotors' actuators in another order (acts (2, 0, 3, 1)) and a gain of 4:
    rotor i's thrust feeds rotor i's hub. Level, v = (1, 0, 0), k_eta 1, k_d 1: H_i = −ω_i (1, 0, 0), and
    M_z = Σ −y_i H_ix = Σ y_i ω_i."""
    # rotor 0: actuator 2, lagged (act[0] = 0.25: thrust 1, ω 1); rotor 1: actuator 0, ctrl 0.0625 (thrust 0.25,
    # ω 0.5); rotor 2: actuator 3, ctrl 9 clamped to 0.5 (thrust 2, ω √2); rotor 3: actuator 1, ctrl −1 clamped to
    # 0 (ω 0)
    ctrl = [0.0625, -1.0, 100.0, 9.0]
    rotors = [[0.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 3.0, 0.0], [0.0, 4.0, 0.0]]
    got = _drag([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0, np.eye(3), ctrl, [5.0, 0.25], 4.0, [2, 0, 3, 1], [-1, -1, -1, -1],
                rotors, [0.0] * 3, [1.0, 1.0, 1.0])
    # with no rotor lagged: actuator 2's ctrl 100 clamps to 0.5 (thrust 2)
    w = np.array([math.sqrt(2.0), 0.5, math.sqrt(2.0), 0.0])
    np.testing.assert_allclose(got, [-w.sum(), 0, 0, 0, 0, w @ [1, 2, 3, 4]], rtol=1e-14, atol=1e-15)
    got = _drag([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], 0, np.eye(3), ctrl, [0.25, 5.0], 4.0, [2, 0, 3, 1], [0, -1, -1, -1],
                rotors, [0.0] * 3, [1.0, 1.0, 1.0])
    w = np.array([1.0, 0.5, math.sqrt(2.0), 0.0])
    np.testing.assert_allclose(got, [-w.sum(), 0, 0, 0, 0, w @ [1, 2, 3, 4]], rtol=1e-14, atol=1e-15)


def _rotorpy(R, v, W, wind, thrusts, rotors, k_eta, k_d, k_z):
    """RotorPy's rotor drag written vectorised (rotorpy/vehicles/multirotor.py, compute_body_wrench): the world
    force R ΣH and the body moment Σ r × H."""
    omega = np.sqrt(np.asarray(thrusts) / k_eta)
    u = (R.T @ (v - wind))[None, :] + np.cross(W, rotors)
    Hs = -omega[:, None] * u * np.array([k_d, k_d, k_z])
    return R @ Hs.sum(axis=0), np.cross(rotors, Hs).sum(axis=0)


def test_the_rotor_drag_against_rotorpy_s_formula_at_random_states():
    """Random attitude (a proper rotation from a QR factorisation), velocity, rate, wind, hub positions off the plane
    and thrusts; the free joint at dadr 3 of nv 10 (the rest of qfrc untouched)."""
    rng = np.random.default_rng(54)
    for _ in range(20):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        R = Q * np.sign(np.linalg.det(Q))
        v, W, wind = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
        rotors = rng.normal(0.0, 0.05, size=(4, 3))
        thrusts = rng.uniform(0.01, 0.14, 4)
        coeffs = [2.3e-8, 1.02506e-6, 7.553e-7]
        qvel = np.concatenate([[5.0, 5.0, 5.0], v, W, [5.0]])
        got = _drag(qvel, 3, R, thrusts, [0.0], 1.0, [0, 1, 2, 3], [-1] * 4, rotors, wind, coeffs)
        F, M = _rotorpy(R, v, W, wind, thrusts, rotors, *coeffs)
        np.testing.assert_allclose(got[3:6], F, rtol=1e-10, atol=1e-16)
        np.testing.assert_allclose(got[6:9], M, rtol=1e-10, atol=1e-16)
        assert np.array_equal(got[[0, 1, 2, 9]], [7.0, 7.0, 7.0, 7.0])


def test_the_drag_needs_k_eta_and_k_d_or_k_z():
    def frame(drag):
        return airframe.Airframe(0, 0, 0, 1.0, np.eye(3), np.zeros((4, 3)), np.zeros(4), np.ones(4),
                                 np.arange(4), np.eye(4), -np.ones(4, dtype=np.int64), np.asarray(drag, float))

    assert frame([1.0, 1.0, 0.0]).has_drag and frame([1.0, 0.0, 1.0]).has_drag
    assert not frame([0.0, 1.0, 1.0]).has_drag and not frame([1.0, 0.0, 0.0]).has_drag


def test_the_thrusts_invert_the_allocation_and_clip_into_0_t_max():
    """Allocation rows [1 1 1 1], [y], [−x], [c dir] of hubs at (±1, ±1) and c = 0.5: f = 4, M = 0 gives 1 each;
    M_x = 2 (y = +1 rotors up 0.5, y = −1 down 0.5); T_max 1.2 clips; a negative share clips to 0."""
    xy = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])
    A = np.vstack([np.ones(4), xy[:, 1], -xy[:, 0], 0.5 * np.array([1.0, -1.0, 1.0, -1.0])])
    frame = airframe.Airframe(0, 0, 0, 1.0, np.eye(3), np.zeros((4, 3)), np.zeros(4), np.full(4, 1.2),
                              np.arange(4), A, -np.ones(4, dtype=np.int64), np.zeros(3))
    np.testing.assert_allclose(frame.thrusts(4.0, np.zeros(3)), [1.0, 1.0, 1.0, 1.0], rtol=1e-14)
    np.testing.assert_allclose(frame.thrusts(4.0, np.array([2.0, 0.0, 0.0])), [1.2, 0.5, 0.5, 1.2], rtol=1e-14)
    np.testing.assert_allclose(frame.thrusts(0.0, np.array([2.0, 0.0, 0.0])), [0.5, 0.0, 0.0, 0.5], rtol=1e-14)

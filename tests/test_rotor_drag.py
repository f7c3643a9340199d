"""RotorPy's rotor drag on the quadrotor (adaptive_mj.plants.airframe.rotor_drag_into, issue 52 item 1): the wrench
the plant applies, pinned against RotorPy's formula written out here in numpy (rotorpy/vehicles/multirotor.py,
Multirotor.compute_body_wrench, at 9b760b8: H = −ω (k_d u_x, k_d u_y, k_z u_z) at each hub, u the hub's body-frame
airspeed, the moment Σ r × H), at several airspeeds (6 m/s among them), attitudes, body rates and unequal lagged
thrusts; exactly zero in still air at rest; and applied by the control callback at every stage.

The only numbers typed here are RotorPy's (crazyflie_params.py), to check the model against its source."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import quadrotor as quad

K_ETA = 2.3e-8  # [N/(rad/s)^2]
K_D = 1.02506e-6  # [N/(rad m/s^2)] 'k_d'
K_Z = 7.553e-7  # [N/(rad m/s^2)] 'k_z'
ARM = 0.043  # [m] 'd'
ROTOR_POS = ARM * np.array([[0.70710678118, 0.70710678118, 0], [0.70710678118, -0.70710678118, 0],
                            [-0.70710678118, -0.70710678118, 0], [-0.70710678118, 0.70710678118, 0]])


def rotorpy_wrench(R, v, w, wind, thrusts):
    """(F_body (3,), M_body (3,)): RotorPy's rotor drag (aero=True, c_D = k_h = k_flap = 0) as its code computes
    it, from R (3, 3) body-to-world, v (3,) world velocity, w (3,) body rate, wind (3,) and the rotor thrusts (4,)."""
    rotor_speeds = np.sqrt(np.asarray(thrusts) / K_ETA)
    body_airspeed_vector = R.T @ (v - wind)
    hat = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    local_airspeeds = body_airspeed_vector[:, np.newaxis] + hat @ ROTOR_POS.T
    rotor_drag_matrix = np.diag([K_D, K_D, K_Z])
    H = -rotor_speeds * (rotor_drag_matrix @ local_airspeeds)
    M = sum(np.cross(ROTOR_POS[i], H[:, i]) for i in range(4))
    return H.sum(axis=1), M


def _rotation(phi):
    q = np.array([1.0, 0, 0, 0])
    angle = np.linalg.norm(phi)
    if angle > 0:
        mujoco.mju_axisAngle2Quat(q, np.asarray(phi) / angle, angle)
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, q)
    return R.reshape(3, 3)


CASES = {  # name: (φ [rad], v [m/s], Ω [rad/s], wind [m/s], thrusts [N])
    "6 m/s wind, level, hover": ((0, 0, 0), (0, 0, 0), (0, 0, 0), (6.0, 0, 0), (0.073575,) * 4),
    "6 m/s wind, 18 deg lean into it": ((0, -np.radians(18), 0), (0, 0, 0), (0, 0, 0), (6.0, 0, 0),
                                        (0.0774,) * 4),
    "6 m/s flight along y, 30 deg roll, turning": ((np.radians(30), 0, 0.4), (0.3, 6.0, -0.5), (1.0, -2.0, 3.0),
                                                  (0, 0, 0), (0.05, 0.09, 0.07, 0.11)),
    "2 m/s gust, climbing, tilted": ((0.1, 0.2, -0.3), (0, 0, 1.5), (0.2, 0.1, -0.5), (2.0, -1.0, 0.5),
                                     (0.08, 0.06, 0.075, 0.071)),
    "still air, spinning in yaw": ((0, 0, 0), (0, 0, 0), (0, 0, 8.0), (0, 0, 0), (0.07, 0.08, 0.07, 0.08)),
}


@pytest.mark.parametrize("name", CASES)
def test_the_rotor_drag_is_rotorpy_s(name):
    """The generalized force the plant applies: the force R F [N] (world) and the moment M [N m] (body frame, about
    the body's origin, which is RotorPy's centre of mass on the bare vehicle) against RotorPy's formula, to 1e-7
    (the model's hubs are at d/√2 written to 9 digits, 0.030405592 m: 1.4e-8 relative from RotorPy's)."""
    phi, v, w, wind, thrusts = (np.asarray(a, dtype=float) for a in CASES[name])
    plant = quad.load()
    plant.set_state(np.vstack([[0, 0, 1.0], v, phi, w]))
    d, af = plant.data, plant.airframe
    plant.model.opt.wind[:] = wind
    d.act[af.act] = thrusts  # the lagged rotors' thrusts now (MuJoCo's thrust = gain · act)
    mujoco.mj_kinematics(plant.model, d)
    got = plant.rotor_wrench()
    R = d.xmat[af.body].reshape(3, 3)
    F, M = rotorpy_wrench(R, v, w, wind, thrusts)
    np.testing.assert_allclose(got[:3], R @ F, rtol=1e-7, atol=1e-15)
    np.testing.assert_allclose(got[3:], M, rtol=1e-7, atol=1e-15)
    assert np.linalg.norm(got[:3]) > 0


def test_the_drag_at_6_m_s_hover():
    """Level at hover thrust in a 6 m/s wind: 4 k_d ω v = 0.0440 N along the wind (ω = √(m g/4/k_eta) = 1,789
    rad/s), no moment: what the ellipsoid fluid model's 0.0948 N (level) and 0.126 N, −0.102 N and −2.68 mN m (18°
    lean) were replaced by."""
    plant = quad.load()
    plant.set_state(np.vstack([[0, 0, 1.0], np.zeros((3, 3))]))
    plant.model.opt.wind[:] = [6.0, 0, 0]
    got = plant.rotor_wrench()
    omega = np.sqrt(0.03 * 9.81 / 4 / K_ETA)
    np.testing.assert_allclose(got, [4 * K_D * omega * 6.0, 0, 0, 0, 0, 0], rtol=1e-12, atol=1e-18)
    assert got[0] == pytest.approx(0.0440, abs=5e-5)


def test_hover_in_still_air_is_exact_and_the_callback_applies_the_drag_at_each_stage():
    """At rest in still air the drag is exactly zero (hover stays exact); in a wind the control callback writes
    it into qfrc_applied at each evaluation, so MuJoCo's acceleration is (thrust + drag)/m."""
    plant = quad.load()
    af, m = plant.airframe, plant.model
    plant.set_state(np.vstack([[0, 0, 1.0], np.zeros((3, 3))]))
    hover = plant.data.act[af.act].copy()  # trimmed at the weight's share
    with plant.controlled_by(lambda t, x: hover):
        for _ in range(200):
            plant.step()
    np.testing.assert_array_equal(plant.data.qfrc_applied, 0.0)
    assert abs(plant.data.qpos[2] - 1.0) < 1e-9 and np.all(plant.data.qvel == 0.0)
    m.opt.wind[:] = [6.0, 0, 0]
    d = plant.data
    with plant.controlled_by(lambda t, x: hover):
        mujoco.mj_forward(m, d)
    F, _ = rotorpy_wrench(np.eye(3), np.zeros(3), np.zeros(3), np.array([6.0, 0, 0]), hover)
    mass = af.mass
    np.testing.assert_allclose(d.qacc[af.qvel], F[0] / mass, rtol=1e-9)
    np.testing.assert_allclose(d.qfrc_applied[af.qvel:af.qvel + 3], F, rtol=1e-12)

"""The flight laws' allocation under saturation (laws.flight_kernel.allocate, law.allocation; issue 52, item 3):
"yaw_last" keeps the collective thrust and the roll and pitch moments where a rotor would saturate, at the expense of
the yaw moment; "exact_clip" inverts exactly and clips each rotor, losing all four. The mixer matrix is formed here
from the compiled model's sites and gears with MuJoCo's own calls, not read from the airframe the laws use."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.laws import flight_kernel as fk
from adaptive_mj.plants import quadrotor
from adaptive_mj.runs.runner import execute
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build


def _mixer(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """(A (4, 4), T_max (4,)): [f, M_x, M_y, M_z] = A @ thrusts from each rotor's site position, its gear's force
    and torque rotated into the body frame, r × (0, 0, 1) plus the gear's torque; T_max the ctrlrange's top."""
    cols, tmax = [], []
    for a in range(model.nu):
        site = model.actuator_trnid[a, 0]
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, model.site_quat[site])
        R = R.reshape(3, 3)
        force, torque = R @ model.actuator_gear[a, :3], R @ model.actuator_gear[a, 3:]
        moment = np.cross(model.site_pos[site], force) + torque
        cols.append([force[2], *moment])
        tmax.append(model.actuator_ctrlrange[a, 1])
    return np.array(cols).T, np.array(tmax)


@pytest.fixture(scope="module")
def rig():
    scn = sc.load(sc.SCENARIOS_DIR / "quadrotor_rotor_loss.toml")
    law = build(scn).law
    A, tmax = _mixer(quadrotor.load().model)
    return law, A, tmax


def _allocate(law, mode: float, wrench) -> np.ndarray:
    P = law.P.copy()
    P[fk.P_ALLOC] = mode
    u = np.empty(4)
    fk.allocate(law.Ainv, float(wrench[0]), float(wrench[1]), float(wrench[2]), float(wrench[3]), P, u)
    return u


def _demands(A, tmax):
    """Thrust, roll/pitch and yaw demands the rotors meet without yaw but not with it: hover thrust with a large yaw
    moment, and a roll moment with a yaw moment of either sign."""
    f = 0.30  # [N] about the 30 g vehicle's weight
    yaw = float(np.max(np.abs(A[3]))) * tmax.min()  # [N m] one rotor's reaction torque at full thrust (the
    # four give at most about 1.9 times it at this thrust)
    return [np.array([f, 0.0, 0.0, 2.5 * yaw]), np.array([f, 2e-3, -1e-3, -2.2 * yaw]),
            np.array([f, -1e-3, 1.5e-3, 3.0 * yaw])]


def test_the_law_s_allocation_is_the_model_s_mixer(rig):
    law, A, tmax = rig
    np.testing.assert_allclose(law.airframe.allocation, A, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(law.P[fk.P_TMAX:fk.P_TMAX + 4], tmax)
    assert law.allocation == "yaw_last" and law.P[fk.P_ALLOC] == fk.ALLOC_YAW_LAST


def test_yaw_last_keeps_thrust_roll_and_pitch_and_gives_up_yaw_where_a_rotor_saturates(rig):
    law, A, tmax = rig
    for w in _demands(A, tmax):
        exact = np.linalg.solve(A, w)
        assert np.any((exact < 0) | (exact > tmax))  # the exact inverse leaves the rotors' box
        # by hand: thrusts are affine in the share k of yaw kept, u(k) = a + k b; the largest k in [0, 1] that keeps
        # every rotor in [0, T_max] (a inside the box here)
        a, b = np.linalg.solve(A, [*w[:3], 0.0]), np.linalg.solve(A, [0.0, 0.0, 0.0, w[3]])
        assert np.all((a >= 0) & (a <= tmax))
        ks = np.linspace(0.0, 1.0, 200001)
        inside = np.all((a + ks[:, None] * b >= -1e-15) & (a + ks[:, None] * b <= tmax + 1e-15), axis=1)
        k_hand = ks[inside].max()

        u = np.clip(_allocate(law, fk.ALLOC_YAW_LAST, w), 0.0, tmax)  # the loop's clamp after the law
        delivered = A @ u
        np.testing.assert_allclose(delivered[:3], w[:3], rtol=1e-12, atol=1e-15)  # f, M_x, M_y exactly
        assert abs(delivered[3]) < abs(w[3]) and np.sign(delivered[3]) == np.sign(w[3])
        assert delivered[3] / w[3] == pytest.approx(k_hand, abs=1e-5)
        assert np.any(np.isclose(u, 0.0, atol=1e-15) | np.isclose(u, tmax, rtol=1e-12))  # a rotor at its limit

        clipped = np.clip(_allocate(law, fk.ALLOC_EXACT_CLIP, w), 0.0, tmax)
        np.testing.assert_array_equal(_allocate(law, fk.ALLOC_EXACT_CLIP, w), law.Ainv @ w)
        missed = A @ clipped - w
        assert np.max(np.abs(missed[:3] / np.array([w[0], 1e-3, 1e-3]))) > 1e-3  # thrust or roll/pitch lost


def test_where_the_exact_inverse_fits_both_allocations_give_its_bits(rig):
    law, A, tmax = rig
    w = np.array([0.29, 1e-4, -2e-4, 1e-5])
    exact = _allocate(law, fk.ALLOC_EXACT_CLIP, w)
    assert np.all((exact > 0) & (exact < tmax))
    np.testing.assert_array_equal(_allocate(law, fk.ALLOC_YAW_LAST, w), exact)


def test_thrust_beyond_the_rotors_even_without_yaw_keeps_yaw_from_making_it_worse(rig):
    """Roll and pitch asking more than the rotors give (a rotor outside its box at k = 0): the yaw moment may not push
    that rotor further out; what is left the loop clips."""
    law, A, tmax = rig
    w = np.array([0.5, 6e-3, 0.0, 5e-4])
    a = np.linalg.solve(A, [*w[:3], 0.0])
    assert np.any((a < 0) | (a > tmax))
    u = _allocate(law, fk.ALLOC_YAW_LAST, w)
    out = np.maximum(u - tmax, 0.0) + np.maximum(-u, 0.0)
    out0 = np.maximum(a - tmax, 0.0) + np.maximum(-a, 0.0)
    assert np.all(out <= out0 + 1e-15)


def test_law_allocation_is_read_checked_and_reaches_the_kernel():
    base = sc.SCENARIOS_DIR / "quadrotor_rotor_loss.toml"
    for kind in ("geometric", "geometric_adaptive", "l1_geometric"):
        law = build(sc.load(base, overrides=[f"law.kind='{kind}'", "law.allocation='exact_clip'"])).law
        assert law.allocation == "exact_clip" and law.P[fk.P_ALLOC] == fk.ALLOC_EXACT_CLIP
    with pytest.raises(Exception, match="law.allocation.*one of 'exact_clip', 'yaw_last'"):
        sc.load(base, overrides=["law.allocation='airmode'"])


def test_past_the_one_rotor_limit_yaw_last_keeps_flying_where_exact_clip_crashes():
    """Rotor 1 loses 55 % of its thrust at t = 1 s, past 1 − mg/(4 T_max) = 48.8 %: with the exact inverse clipped
    the vehicle tips over within a second; giving up yaw it stays up (spinning about z, as Mueller & D'Andrea's
    vehicle does), though the geometric law, which holds a heading, does not track."""
    out = {}
    for alloc in ("exact_clip", "yaw_last"):
        scn = sc.load(sc.SCENARIOS_DIR / "quadrotor_rotor_loss.toml", overrides=[
            "law.kind='geometric_adaptive'", f"law.allocation='{alloc}'", "simulation.duration=4",
            "events=[{t=1.0, kind='rotor_efficiency', rotor=1, value=0.45}]"])
        out[alloc] = execute(scn)
    assert out["exact_clip"].summary["status"] == "crashed"
    assert out["yaw_last"].summary["status"] != "crashed"
    assert abs(out["yaw_last"].trajectory.x[-1, 3, 2]) > 10.0  # [rad/s] spinning about z

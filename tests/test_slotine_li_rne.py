"""Slotine–Li in O(n) (regressor_kernel.rne_law_torque / rne_law_rate, SlotineLiLaw evaluation "recursive"):
τ = Y π̂ + τ_known and Yᵀ s by one forward and one backward pass over the tree agree with the regressor form
(Y formed whole) to ≤ 1e-10 relative at random states, on the UR5e with its payload (the payload unknown,
every body unknown, base parameters, joint and friction columns) and on a branched tree with slide joints,
two joints on one body, a massless frame and a welded body; and the law gives the same u and θ' both ways.
Native vs Python bit-identity of the O(n) law: tests/test_native_manipulator.py (its default)."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.laws import DeadZone, DeadZoneOn
from adaptive_mj.laws.slotine_li import Mode, SlotineLiLaw
from adaptive_mj.plants import manipulator as mp
from test_manipulator import ARMS

RTOL = 1e-10

# (arm, unknown, joint_params, friction_params, base)
CASES = [
    ("ur5e+tool_offset", "payload", False, False, False),
    ("ur5e+tool_offset", "all", True, False, False),
    ("ur5e+tool_offset", "all", False, True, True),
    ("ur5e+sphere", "all", True, False, True),
    ("test_arm", "all", True, False, False),  # the branched tree
    ("test_arm", "all", False, True, True),
    ("test_arm", ["l3a", "tool"], False, False, False),  # two leaves of the two branches unknown
]


def _random_state(plant, rng):
    model, d = plant.model, plant.data
    d.qpos[:] = rng.uniform(-np.pi, np.pi, model.nq)
    mujoco.mj_kinematics(model, d)
    mujoco.mj_comPos(model, d)
    return (rng.normal(size=model.nv) for _ in range(4))


def _rel(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


@pytest.mark.parametrize("case", range(len(CASES)))
def test_recursions_give_Y_pi_and_Yt_s(case):
    arm, unknown, joints, friction, base = CASES[case]
    model = ARMS[arm]
    plant = mp.ManipulatorPlant(model, unknown=unknown, joint_params=joints, friction_params=friction, base=base)
    reg, n = plant.regressor, len(plant.names)
    assert (reg.base_map is not None) == base
    rng = np.random.default_rng(case)
    worst_tau = worst_rate = 0.0
    for _ in range(25):
        v, w, a, s = _random_state(plant, rng)
        theta = rng.normal(size=n)
        Y, tau_known = reg(v, w, a)
        want_tau, want_rate = Y @ theta + tau_known, Y.T @ s
        tau = reg.torque(v, w, a, theta).copy()
        rate = reg.rate(v, a, s, np.empty(n))
        worst_tau, worst_rate = max(worst_tau, _rel(tau, want_tau)), max(worst_rate, _rel(rate, want_rate))
    assert worst_tau <= RTOL and worst_rate <= RTOL, (worst_tau, worst_rate)


def test_gravity_alone_and_a_known_arm():
    """At v = w = a = 0 the recursion gives g(q) (MuJoCo's qfrc_bias at q̇ = 0) with the true parameters."""
    plant = mp.ManipulatorPlant(ARMS["ur5e+tool_offset"], unknown="all")
    model, d, rng = plant.model, plant.data, np.random.default_rng(3)
    zero = np.zeros(model.nv)
    for _ in range(5):
        d.qpos[:] = rng.uniform(-np.pi, np.pi, model.nq)
        d.qvel[:] = 0.0
        mujoco.mj_forward(model, d)
        tau = plant.regressor.torque(zero, zero, zero, plant.true_theta())
        np.testing.assert_allclose(tau, d.qfrc_bias, rtol=1e-10, atol=1e-10 * np.abs(d.qfrc_bias).max())


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("freeze", [False, True])
def test_the_law_gives_the_same_u_and_rate_both_ways(mode, freeze):
    """SlotineLiLaw with evaluation "recursive" and "regressor" at random states: u and θ' agree ≤ 1e-10
    (relative), with saturation-aware adaptation (some joints frozen) and a dead-zone on ‖q̃‖."""
    plant = mp.ManipulatorPlant(ARMS["test_arm"], unknown="all", joint_params=True)
    m, n, rng = plant.m, len(plant.names), np.random.default_rng(11)
    sat = (np.full(m, -5.0), np.full(m, 5.0)) if freeze else None
    laws = {ev: SlotineLiLaw(plant.regressor, plant.names, m, lam=3.0, kd=20.0, gamma=0.5, mode=mode,
                             saturation=sat, dead_zone=DeadZone(0.2, DeadZoneOn.TRACKING_ERROR), evaluation=ev)
            for ev in ("recursive", "regressor")}
    assert laws["recursive"].recursive and not laws["regressor"].recursive
    adapted = 0
    for _ in range(20):
        q, qd, _, _ = _random_state(plant, rng)
        x = np.stack([plant.data.qpos.copy(), qd])
        ref = np.stack([x[0] + 0.3 * rng.normal(size=m), rng.normal(size=m), rng.normal(size=m)])
        theta = rng.normal(size=n)
        a, b = (laws[ev](0.0, x, ref, theta) for ev in ("recursive", "regressor"))
        assert _rel(a.u, b.u) <= RTOL
        if np.any(b.theta_hat_dot):
            adapted += 1
            assert _rel(a.theta_hat_dot, b.theta_hat_dot) <= RTOL
        else:
            assert not np.any(a.theta_hat_dot)
        np.testing.assert_array_equal(a.s, b.s)
    assert adapted > 0 if mode is Mode.ADAPTIVE else adapted == 0


def test_scenario_key_and_log_header(tmp_path):
    """law.evaluation selects the form (default "recursive"); the log header records it, and a re-run of the
    log (replay --verify) is bit-identical."""
    from adaptive_mj import run_scenario
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.runs.verify import verify

    for ev in ("recursive", "regressor"):
        over = ["simulation.duration=0.05"] + ([f"law.evaluation='{ev}'"] if ev == "regressor" else [])
        r = run_scenario("ur5e_identification", set=over, seed=0, log=tmp_path / f"{ev}.mcap")
        logged = read_log(r.log_path)
        assert logged.header["law_evaluation"] == ev
        ok, msg = verify(logged)
        assert ok, msg

"""Joint friction and actuator lag on the manipulator plant (issue 19 §2), each against its
defining equation: plant.damping / plant.frictionloss land in the compiled model; the
Coulomb column is tanh(q̇ / ε) of the measured velocity with dof_frictionloss as its true
value; a first-order actuator lag's step response is τ_c (1 - e^{-t/T}); and Slotine–Li
identifies a 2-joint arm's viscous and Coulomb friction. (Native vs Python, bit for bit,
with these on: tests/test_native_manipulator.py.)"""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from adaptive_mj.errors import ModelError, ScenarioError
from adaptive_mj.laws.slotine_li import SlotineLiLaw
from adaptive_mj.plants import manipulator as mp
from adaptive_mj.plants import regressor_kernel as rk
from adaptive_mj.plants.mujoco_plant import with_userdata
from adaptive_mj.reference import JointSumOfSines
from adaptive_mj.setup import build
from adaptive_mj.setup import scenario as sc
from adaptive_mj.sim.loop import run

# Two links in a vertical plane (gravity acts), viscous damping and dry friction on both joints.
ARM2 = """<mujoco model="arm2">
  <option timestep="0.001" integrator="RK4"/>
  <worldbody>
    <body name="l1">
      <joint name="j1" type="hinge" axis="0 1 0" damping="0.3" frictionloss="0.4"/>
      <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="1.5" contype="0" conaffinity="0"/>
      <body name="l2" pos="0.4 0 0">
        <joint name="j2" type="hinge" axis="0 1 0" damping="0.1" frictionloss="0.2"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.025" mass="0.8" contype="0" conaffinity="0"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor name="m1" joint="j1"/><motor name="m2" joint="j2" gear="2"/></actuator>
</mujoco>"""

SCENARIO = "scenarios/ur5e_payload_swap.toml"


def _arm2(integrator: str = "RK4", edit=None) -> mujoco.MjModel:
    spec = mujoco.MjSpec.from_string(ARM2.replace('integrator="RK4"', f'integrator="{integrator}"'))
    if edit is not None:
        edit(spec)
    return with_userdata(spec).compile()


# --- the scenario keys, as model edits ----------------------------------------------------------
def test_scenario_keys_edit_the_compiled_model():
    scn = sc.load(SCENARIO, overrides=["plant.damping=0.5", "plant.frictionloss={elbow = 1.5, wrist_1 = 0.3}",
                                       "plant.actuator_lag={wrist_3 = 0.01}", "plant.friction_params=true",
                                       "plant.coulomb_smoothing=0.02"])
    plant = build.build(scn).plant
    m = plant.model
    assert np.array_equal(m.dof_damping, np.full(6, 0.5))
    assert np.array_equal(m.dof_frictionloss, [0, 0, 1.5, 0.3, 0, 0])
    lagged = [mujoco.mjtDyn.mjDYN_NONE] * 5 + [mujoco.mjtDyn.mjDYN_FILTER]  # rk4: filter (set_actuator_lag)
    assert list(m.actuator_dyntype) == lagged and m.actuator_dynprm[5, 0] == 0.01 and m.na == 1
    joints = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
    assert plant.names[-12:] == tuple(f"{j}.damping" for j in joints) + tuple(f"{j}.coulomb" for j in joints)
    assert np.array_equal(plant.true_theta()[-12:], np.r_[m.dof_damping, m.dof_frictionloss])
    assert plant.layout.coulomb_smoothing == 0.02
    euler = build.build(sc.load(SCENARIO, overrides=["plant.actuator_lag=0.01", "simulation.integrator=euler",
                                                      "plant.frictionloss=0.25"]))
    assert set(euler.plant.model.actuator_dyntype.tolist()) == {int(mujoco.mjtDyn.mjDYN_FILTEREXACT)}
    # the edits are in the model the log embeds (the compiled MJCF), so a replay rebuilds them
    assert euler.model_xml.count('dyntype="filterexact"') == 6 and 'frictionloss="0.25"' in euler.model_xml


@pytest.mark.parametrize("override, message", [
    ("plant.frictionloss={elbo = 1}", "plant.frictionloss names joint 'elbo'"),
    ("plant.damping=-0.1", "plant.damping must be >= 0"),
    ("plant.frictionloss={elbow = -1}", "plant.frictionloss.elbow must be >= 0"),
    ("plant.actuator_lag=true", "plant.actuator_lag must be a number"),
    ("plant.coulomb_smoothing=0.05", "absent unless plant.friction_params = true"),
    ("plant.friction_params=1", "plant.friction_params must be true or false"),
])
def test_bad_friction_keys_are_refused(override, message):
    with pytest.raises(ScenarioError, match=message.replace(".", r"\.").replace("(", r"\(")):
        build.build(sc.load(SCENARIO, overrides=[override]))
    with pytest.raises(ScenarioError, match="absent unless plant.kind = 'manipulator'"):
        sc.load("scenarios/heave_tracking.toml", overrides=["plant.frictionloss=1"])


def test_check_supported_accepts_friction_and_a_lag_only():
    model = _arm2()
    mp.check_supported(model, "arm2")  # frictionloss != 0 is accepted (unmodelled unless friction_params)

    def other_dynamics(spec):
        spec.actuators[0].dyntype = mujoco.mjtDyn.mjDYN_INTEGRATOR

    with pytest.raises(ModelError, match="not a torque <motor>"):
        mp.check_supported(_arm2(edit=other_dynamics), "arm2")

    def poly_damping(spec):
        spec.joints[1].damping = [0.1, 0.05, 0.0]

    with pytest.raises(ModelError, match="'j2' has nonlinear damping"):
        mp.check_supported(_arm2(edit=poly_damping), "arm2")


# --- the Coulomb column -------------------------------------------------------------------------
@pytest.mark.parametrize("eps", [rk.DEFAULT_COULOMB_SMOOTHING, 0.2])
def test_coulomb_column_is_tanh_of_the_measured_velocity(eps):
    """Y[j, <joint>.coulomb] = tanh(v_j / ε), 0 elsewhere; its true value is dof_frictionloss; a
    known Coulomb term adds nothing to τ_known (dry friction is unmodelled without the column)."""
    model = _arm2()
    with_cols = mp.ManipulatorPlant(model, unknown=["l2"], friction_params=True, coulomb_smoothing=eps)
    without = mp.ManipulatorPlant(model, unknown=["l2"])
    names = with_cols.names
    assert names[10:] == ("j1.damping", "j2.damping", "j1.coulomb", "j2.coulomb")
    assert np.array_equal(with_cols.true_theta()[10:], [0.3, 0.1, 0.4, 0.2])
    rng = np.random.default_rng(1)
    for _ in range(20):
        with_cols.data.qpos[:] = rng.uniform(-3, 3, 2)
        with_cols.update_kinematics()
        without.data.qpos[:] = with_cols.data.qpos
        without.update_kinematics()
        v, w, a = (rng.normal(size=2) * eps * 5 for _ in range(3))
        Y, tau = (x.copy() for x in with_cols.regressor(v, w, a))
        Y0, tau0 = without.regressor(v, w, a)
        assert np.array_equal(Y[:, 12:], np.diag([math.tanh(v[0] / eps), math.tanh(v[1] / eps)]))
        assert np.array_equal(Y[:, 10:12], np.diag(v))  # the damping columns: the measured v too
        # the same dynamics: the columns times the true values are what τ_known held (damping) or
        # left out (Coulomb)
        pi = with_cols.true_theta()
        assert np.allclose(Y[:, :12] @ pi[:12] + tau, Y0 @ without.true_theta() + tau0, rtol=0, atol=1e-12)
        assert np.allclose(tau + Y[:, 10:12] @ pi[10:12], tau0, rtol=0, atol=1e-12)


def test_base_parameters_keep_the_friction_columns():
    """Each joint's damping and Coulomb columns are independent of the inertial ones (v and tanh(v/ε)
    enter one dof each): the base set keeps all of them, unregrouped."""
    model = _arm2()
    plant = mp.ManipulatorPlant(model, unknown="all", friction_params=True, base=True)
    plain = mp.ManipulatorPlant(model, unknown="all", base=True)
    friction = [n for n in plant.names if n.endswith((".damping", ".coulomb"))]
    assert friction == ["j1.damping", "j2.damping", "j1.coulomb", "j2.coulomb"]
    assert len(plant.names) == len(plain.names) + 4
    assert np.array_equal(plant.true_theta()[-4:], [0.3, 0.1, 0.4, 0.2])


# --- the actuator lag ---------------------------------------------------------------------------
@pytest.mark.parametrize("integrator, exact, tol", [("Euler", True, 1e-15), ("implicitfast", True, 1e-15),
                                                     ("RK4", False, 1e-7)])
def test_actuator_lag_step_response(integrator, exact, tol):
    """A held ctrl through a lag T: the joint torque MuJoCo applies (qfrc_actuator = gear·actuator_force)
    is τ_c (1 - e^{-t/T}) [N m], τ_c = gear·ctrl.
    One-stage integrators with filterexact: exact (to rounding); RK4 with filter: fourth order, at
    h/T = 0.05 well inside 1e-7 of τ_c (measured 2e-8)."""
    T = 0.02
    model = _arm2(integrator, edit=lambda spec: mp.set_actuator_lag(spec, {"j2": T}, exact=exact))
    mp.check_supported(model, "arm2")
    assert model.actuator_dyntype[0] == mujoco.mjtDyn.mjDYN_NONE and model.actuator_dynprm[1, 0] == T
    data = mujoco.MjData(model)
    data.ctrl[:] = [0.5, 0.35]
    tau_c = 0.35 * 2.0  # gear 2
    worst = 0.0
    for _ in range(150):
        mujoco.mj_step(model, data)
        mujoco.mj_forward(model, data)
        assert data.qfrc_actuator[0] == 0.5  # no lag on the other motor
        worst = max(worst, abs(data.qfrc_actuator[1] - tau_c * (1.0 - math.exp(-data.time / T))) / tau_c)
    assert worst <= tol, worst


def test_a_lagged_arm_runs_under_the_law():
    """The law writes ctrl as before (Python path here, native in test_native_manipulator.py); the
    applied torque lags the commanded one, which the law does not know: with T = 5 ms the arm still
    tracks, with its error larger than without the lag."""
    errs = {}
    for T in (0.0, 0.005):
        model = _arm2(edit=lambda spec, T=T: mp.set_actuator_lag(spec, T, exact=False))
        plant, law, ref = _identification_setup(model)
        traj = run(plant, law, ref, duration=2.0, theta_hat0=np.zeros(len(plant.names)), native=False)
        assert traj.status == "ok", traj.reason
        e = traj.ref[:, 0] - traj.x[:, 0]
        errs[T] = float(np.sqrt(np.mean(e[1000:] ** 2)))
    assert errs[0.005] > errs[0.0] and errs[0.005] < 0.01, errs


# --- identification -----------------------------------------------------------------------------
def _identification_setup(model, gamma=0.2):
    """Both joints' damping and Coulomb friction unknown; a reference that keeps the joints moving:
    joint speeds up to about 4 rad/s, |q̇| < 3ε only 0.6-1.2 % of the time."""
    plant = mp.ManipulatorPlant(model, unknown=[], friction_params=True)
    ref = JointSumOfSines(center=(0.0, 0.0), amplitudes=((2.0, 0.6), (2.0, 0.8)), omegas=((1.3, 3.1), (1.7, 3.7)))
    law = SlotineLiLaw(plant.regressor, plant.names, plant.m, lam=20.0, kd=5.0, gamma=gamma)
    plant.set_state(ref(0.0, 2)[:2].copy())
    return plant, law, ref


def test_friction_identified_on_a_two_joint_arm():
    """Slotine–Li with the friction columns on identifies MuJoCo's damping and frictionloss within 5 %.

    The tanh column is F sign(q̇) wherever |q̇| ≳ 3ε; MuJoCo's frictionloss is a soft constraint that
    reaches F only above a transition speed of its own (a few 0.01 rad/s here) and can stick at
    q̇ = 0. The two differ only around velocity reversals, 1-2 % of the time on this reference, and
    bias the estimates by about that much. Measured (mean over the last 20 s of 40 s; true 0.3, 0.1,
    0.4, 0.2): 0.297, 0.103, 0.406, 0.194, i.e. 0.9, 2.6, 1.6, 3.0 % off."""
    plant, law, ref = _identification_setup(_arm2())
    traj = run(plant, law, ref, duration=40.0, theta_hat0=np.zeros(4))
    assert traj.status == "ok", traj.reason
    true = plant.true_theta()
    assert np.array_equal(true, [0.3, 0.1, 0.4, 0.2])
    tail = traj.theta_hat[len(traj.theta_hat) // 2:].mean(axis=0)
    assert np.all(np.abs(tail - true) <= 0.05 * true), (tail, true)
    v = traj.x[:, 1]
    assert np.mean(np.abs(v) < 3 * plant.layout.coulomb_smoothing) < 0.02  # the joints keep moving

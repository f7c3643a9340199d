"""The native (numba cfunc) closed loop for manipulators reproduces the Python path:
the specialised regressor kernel gives regressor_kernel's numbers, and chunks driven as
loop.run's native branch drives them give the rows of run(..., native=False) (here:
bit for bit) for the adaptive law, both baselines, a base-parameter plant, saturation,
a dead-zone, measurement noise, and joint friction with Coulomb columns and lagged motors,
under RK4 and Euler; with Slotine–Li's O(n) recursions (the default) and with Y formed whole."""
from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import manipulator_kernel as nm
from adaptive_mj.sim.native_mujoco import MujocoController
from adaptive_mj.laws import DeadZone, DeadZoneOn, Modification
from adaptive_mj.laws.slotine_li import Mode, SlotineLiLaw
from adaptive_mj.sim.loop import run
from adaptive_mj.plants import manipulator as mp
from adaptive_mj.plants.arm import MODELS, build_arm_xml
from adaptive_mj.plants.mujoco_plant import compile_spec, spec_from_text, with_userdata
from adaptive_mj.reference import JointSumOfSines, JointWaypoints
from test_manipulator import TEST_ARM

UR5E = MODELS / "ur5e_arm.xml"
FIELDS = ("t", "x", "u", "s", "ref", "theta_hat")
TOL = 1e-12  # relative to each field's scale; the paths agree bit for bit today

# Slide and hinge joints with skew axes, two joints on one body, a branch, a massless
# frame body, a welded body, gears and damping/armature (for the kernel comparison).
SMALL_ARM = TEST_ARM.replace(' integrator="RK4"', "")  # the same arm as tests/test_manipulator.py


UR5E_XML = build_arm_xml(arm=UR5E, payload="tool_offset", site="tip")  # (xml, assets)


def _compile(xml: str, assets=None) -> mujoco.MjModel:
    """As the plants compile a model: with the userdata slot the native callback's context needs."""
    return with_userdata(spec_from_text(xml, assets)).compile()


def _ur5e_model(friction: bool = False, euler: bool = False) -> mujoco.MjModel:
    if not friction:
        return _compile(*UR5E_XML)
    # joint friction and a first-order motor lag (as plant.damping/.frictionloss/.actuator_lag set them)
    def edit(spec):
        mp.set_joint_friction(spec, damping=0.5, frictionloss={"shoulder_lift": 2.0, "elbow": 1.0, "wrist_2": 0.2})
        mp.set_actuator_lag(spec, {"shoulder_pan": 0.004, "wrist_3": 0.002}, exact=euler)

    return compile_spec(*UR5E_XML, where="ur5e", edit=edit)[0]


def _setup(mode=Mode.ADAPTIVE, unknown="payload", base=False, euler=False, limit=None, dead_zone=None,
           waypoints=False, modification=None, friction=False, evaluation="recursive"):
    """A UR5e + tool_offset plant, its law, a joint reference and θ̂(0), built the same way each call
    (friction: joint friction, two lagged motors and the friction columns, see _ur5e_model)."""
    model = _ur5e_model(friction, euler)
    if euler:
        model.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    if limit is not None:  # tighter torque limits (m,), so the clamp acts
        limit = np.asarray(limit, dtype=float)[:, None]
        model.actuator_ctrlrange[:] = np.hstack([-limit, limit]) / model.actuator_gear[:, :1]
        model.actuator_ctrllimited[:] = 1
    plant = mp.ManipulatorPlant(model, unknown=unknown, base=base, friction_params=friction)
    home = np.array(model.key("home").qpos)
    if waypoints:
        ref = JointWaypoints(waypoints=(tuple(home), tuple(home + 0.3), tuple(home - 0.2)), durations=(0.3, 0.4),
                             t0=0.05)
    else:
        ref = JointSumOfSines(center=tuple(home), amplitudes=((0.3, 0.2),) * 6,
                              omegas=((0.9, 2.3), (1.1, 2.7), (0.7, 1.9), (1.3, 3.1), (1.7, 2.9), (0.8, 3.7)))
    law = SlotineLiLaw(plant.regressor, plant.names, plant.m, lam=10.0, kd=50.0, gamma=0.5, mode=mode,
                       dead_zone=dead_zone, modification=modification(plant) if modification else None,
                       evaluation=evaluation)
    x0 = ref(0.0, 2)[:2].copy()
    x0[0] += 0.05  # start off the reference
    plant.set_state(x0)
    theta0 = np.zeros(len(plant.names)) if mode is Mode.ADAPTIVE else plant.true_theta() * 0.5
    return plant, law, ref, theta0


def _native(plant, law, ref, theta0, duration, *, chunk=250, noise_std=None, rng=None, between=None):
    """loop.run's native branch (no events): chunks of `chunk` rows, rows concatenated."""
    n = int(round(duration / plant.dt))
    nc = MujocoController(plant, law, ref, theta0, chunk)
    parts = []
    with plant.controlled_natively(nc.callback):
        k = 0
        while k < n:
            rows = min(chunk, n - k)
            noise = rng.normal(0.0, noise_std, size=(rows, 2, plant.m)) if noise_std is not None else None
            parts.append(nc.chunk(rows, noise))
            k += rows
            if between is not None:
                between(plant, nc)
    return dict(zip(FIELDS, (np.concatenate(f) for f in zip(*parts, strict=True)), strict=True)), nc


def _compare(setup_kw, duration, **native_kw):
    """Max relative difference per field between the Python and the native path."""
    plant_py, law, ref, theta0 = _setup(**setup_kw)
    rng_kw = {}
    if "noise_std" in native_kw:
        rng_kw = dict(noise_std=native_kw["noise_std"], rng=np.random.default_rng(7))
        native_kw = dict(native_kw, rng=np.random.default_rng(7))
    traj = run(plant_py, law, ref, duration=duration, theta_hat0=theta0, native=False, **rng_kw)
    assert traj.status == "ok", traj.reason
    plant, law, ref, theta0 = _setup(**setup_kw)
    assert nm.supported(plant, law)
    rows, nc = _native(plant, law, ref, theta0, duration, **native_kw)
    diffs = {}
    for f in FIELDS:
        a, b = np.asarray(getattr(traj, f)), rows[f]
        assert a.shape == b.shape, (f, a.shape, b.shape)
        diffs[f] = float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(a)))))
    diffs["x_end"] = float(np.max(np.abs(plant_py.observe() - plant.observe())))
    return diffs, traj, rows, nc


CASES = {
    "adaptive_payload": dict(mode=Mode.ADAPTIVE),
    "computed_torque": dict(mode=Mode.COMPUTED_TORQUE),
    "pd_gravity": dict(mode=Mode.PD_GRAVITY),
    "base_all": dict(mode=Mode.ADAPTIVE, unknown="all", base=True),
    "friction_lag": dict(mode=Mode.ADAPTIVE, friction=True),
    "friction_base_all": dict(mode=Mode.ADAPTIVE, unknown="all", base=True, friction=True),
    # Y formed whole (law.evaluation = "regressor"; the others run Slotine–Li's O(n) recursions)
    "regressor_payload": dict(mode=Mode.ADAPTIVE, evaluation="regressor"),
    "regressor_base_all": dict(mode=Mode.ADAPTIVE, unknown="all", base=True, friction=True, evaluation="regressor"),
}


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_native_chunks_reproduce_python_path(case, integrator):
    diffs, traj, rows, nc = _compare(dict(CASES[case], euler=integrator == "euler"), 1.0)
    assert max(diffs.values()) <= TOL, diffs
    assert traj.t.shape == (1000,) and rows["x"].shape == (1000, 2, 6)
    assert nc.context[0]["recursive"] == int(CASES[case].get("evaluation", "recursive") == "recursive")
    if CASES[case]["mode"] is Mode.ADAPTIVE:  # the estimates moved, and the native ones kept moving
        assert np.abs(rows["theta_hat"][-1]).max() > 0
        assert not np.array_equal(nc.theta, rows["theta_hat"][-1])
    else:
        assert np.array_equal(rows["theta_hat"], np.broadcast_to(rows["theta_hat"][0], rows["theta_hat"].shape))


def _leak_and_box(plant):
    """σ- and e-modification toward zero, and the payload's mass, Ixx, Iyy, Izz kept >= 0."""
    lower = np.array([0.0 if n.rsplit(".", 1)[1] in ("m", "Ixx", "Iyy", "Izz") else -np.inf for n in plant.names])
    return Modification(sigma=0.05, e_mod=0.5, theta0=np.zeros(len(plant.names)), lower=lower,
                        upper=np.full(len(plant.names), np.inf))


@pytest.mark.parametrize("integrator", ["rk4", "euler"])
def test_robust_modifications_native_match_python(integrator):
    """σ, e-modification and projection run in the compiled callback with the Python path's numbers,
    and the projection holds: the masses and principal inertias never go below 0."""
    diffs, traj, rows, nc = _compare(dict(modification=_leak_and_box, euler=integrator == "euler"), 1.0)
    assert max(diffs.values()) <= TOL, diffs
    plant = _setup()[0]
    held = [i for i, n in enumerate(plant.names) if n.rsplit(".", 1)[1] in ("m", "Ixx", "Iyy", "Izz")]
    assert np.min(rows["theta_hat"][:, held]) == 0.0 and np.min(nc.theta[held]) >= 0.0
    if integrator == "rk4":  # without the box the same run takes some of them below 0
        free = lambda p: dataclasses.replace(_leak_and_box(p), lower=None, upper=None)  # noqa: E731 (a one-line local converter)
        _, traj, _, _ = _compare(dict(modification=free), 1.0)
        assert np.min(traj.theta_hat[:, held]) < -1e-3


def test_saturation_dead_zone_and_waypoints():
    limit = (100.0, 100.0, 100.0, 20.0, 20.0, 20.0)
    diffs, traj, rows, nc = _compare(dict(limit=limit, waypoints=True,
                                          dead_zone=DeadZone(0.02, DeadZoneOn.TRACKING_ERROR)), 0.6)
    assert max(diffs.values()) <= TOL, diffs
    assert np.all(np.any(np.abs(rows["u"]) == limit, axis=0))  # the clamp acted on every joint
    e = np.linalg.norm(rows["ref"][:, 0] - rows["x"][:, 0], axis=1)
    assert np.any(e < 0.02) and np.any(e >= 0.02)  # adaptation went off and on
    diffs, *_ = _compare(dict(dead_zone=DeadZone(0.3, DeadZoneOn.S), euler=True), 0.5)
    assert max(diffs.values()) <= TOL, diffs


def test_measurement_noise_and_uneven_chunks():
    """Noise drawn per chunk (rows, 2, m) is the same stream as the Python path's per step."""
    diffs, *_ = _compare(dict(euler=True), 0.5, chunk=97, noise_std=np.full((2, 6), 1e-3))
    assert max(diffs.values()) <= TOL, diffs


def test_extra_forward_and_other_data_leave_ctrl_alone():
    """mj_forward on the plant's data between chunks (a call past the step's stages) and on another
    MjData change no ctrl, no estimate, no record: the run still matches the Python path."""
    def between(plant, nc):
        ctrl, theta = plant.data.ctrl.copy(), nc.theta.copy()
        mujoco.mj_forward(plant.model, plant.data)
        other = mujoco.MjData(plant.model)
        mujoco.mj_forward(plant.model, other)
        assert np.array_equal(plant.data.ctrl, ctrl) and np.array_equal(nc.theta, theta)
        assert not other.ctrl.any()

    diffs, *_ = _compare(dict(), 0.5, between=between)
    assert max(diffs.values()) <= TOL, diffs


def test_two_controllers_interleaved():
    """The tables follow the controller whose chunk runs (the newest is bound at construction)."""
    kws = [dict(euler=True), dict(mode=Mode.COMPUTED_TORQUE, euler=True)]
    runs = [_setup(**kw) for kw in kws]
    ctrls = [MujocoController(p, law, ref, th0, 100) for p, law, ref, th0 in runs]
    out = [[], []]
    with runs[0][0].controlled_natively(ctrls[0].callback):
        for _ in range(3):
            for i in (0, 1):
                out[i].append(ctrls[i].chunk(100, None))
    for i, kw in enumerate(kws):
        plant, law, ref, th0 = _setup(**kw)
        traj = run(plant, law, ref, duration=0.3, theta_hat0=th0, native=False)
        for f, got in zip(FIELDS, (np.concatenate(a) for a in zip(*out[i], strict=True)), strict=True):
            np.testing.assert_allclose(got, getattr(traj, f), rtol=0, atol=TOL, err_msg=f)


def _kernel_arms():
    arm = _compile(SMALL_ARM)
    ur5e = _ur5e_model()
    return [(arm, "all", True, False), (arm, "all", False, False), (arm, ["l3a", "tool"], False, False),
            (ur5e, "all", True, False), (ur5e, "payload", False, False),
            (arm, "all", True, True), (_ur5e_model(friction=True), "payload", False, True)]  # Coulomb columns


@pytest.mark.parametrize("i", range(7))
def test_specialised_kernel_gives_regressor_kernel_numbers(i):
    model, unknown, joints, friction = _kernel_arms()[i]
    plant = mp.ManipulatorPlant(model, unknown=unknown, joint_params=joints, friction_params=friction,
                                coulomb_smoothing=0.05 if i == 5 else 0.01)
    reg, d = plant.regressor, plant.data
    fast = nm.kernel()
    scratch, need = np.zeros(18 * model.nbody), np.ones(reg.n_standard, dtype=np.int64)
    Y, tau = np.zeros_like(reg.Y_std), np.zeros(model.nv)
    rng = np.random.default_rng(i)
    for trial in range(50):
        d.qpos[:] = rng.uniform(-3, 3, model.nq)
        mujoco.mj_kinematics(model, d)
        mujoco.mj_comPos(model, d)
        v, w, a = (rng.normal(size=model.nv) * 3 for _ in range(3))
        if trial == 0:
            v = w = a = np.zeros(model.nv)
        Y_ref, tau_ref = (arr.copy() for arr in reg(v, w, a))
        fast(*reg.static_args(), d.cdof, d.xpos, d.xmat, d.subtree_com, d.cinert, model.opt.gravity, v, w, a,
             Y, tau, scratch, need)
        assert np.array_equal(Y, Y_ref) and np.array_equal(tau, tau_ref), (np.abs(Y - Y_ref).max(),
                                                                             np.abs(tau - tau_ref).max())
    # columns left out (need = 0) stay 0, the others are unchanged
    need[::3] = 0
    fast(*reg.static_args(), d.cdof, d.xpos, d.xmat, d.subtree_com, d.cinert, model.opt.gravity, v, w, a,
         Y, tau, scratch, need)
    body_cols = np.arange(10 * len(plant.layout.bodies))
    skipped = body_cols[need[body_cols] == 0]
    assert not Y[:, skipped].any()
    kept = np.setdiff1d(np.arange(reg.n_standard), skipped)
    assert np.array_equal(Y[:, kept], Y_ref[:, kept]) and np.array_equal(tau, tau_ref)


def test_supported():
    from adaptive_mj.laws import SlidingAdaptiveLaw
    from adaptive_mj.plants import heave

    plant, law, ref, theta0 = _setup()
    assert nm.supported(plant, law)
    other = mp.ManipulatorPlant(_ur5e_model(), unknown="payload")
    assert not nm.supported(other, law)  # the law's regressor is another plant's
    plant.model.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert nm.supported(plant, law)  # one stage
    hv = heave.load()
    assert not nm.supported(hv, SlidingAdaptiveLaw(hv.form, lam=5, k=200, gamma=[1, 1, 1]))


@pytest.mark.parametrize("case", ["adaptive_payload", "friction_base_all"])
def test_v_from_the_mass_matrix_the_callback_recorded_equals_v_from_the_logged_q(case):
    """The native run's V = ½ sᵀ M(q) s + ... takes M as MuJoCo computed it at each step's start (copied by
    the callback from mjData.M, made dense by ManipulatorPlant.full_mass): bit for bit the V that
    ManipulatorPlant.mass_matrices gives at the logged q (four MuJoCo calls per row, the Python path's)."""
    plant, law, ref, theta0 = _setup(**CASES[case])
    calls = []
    recompute = plant.mass_matrices
    plant.mass_matrices = lambda q: calls.append(len(q)) or recompute(q)  # type: ignore[method-assign]
    traj = run(plant, law, ref, duration=1.35, theta_hat0=theta0, native=True)  # a chunk of 1000 rows and one of 350
    assert traj.status == "ok", traj.reason
    assert calls == []  # every row's M came from the callback
    M = recompute(traj.x[:, 0])
    np.testing.assert_array_equal(traj.V, law.lyapunov(traj.s, traj.theta_hat, traj.theta, M=M))
    d = mujoco.MjData(plant.model)  # full_mass against mj_fullM on a state of its own
    d.qpos[:] = np.linspace(-1.0, 1.0, plant.model.nq)
    mujoco.mj_forward(plant.model, d)
    dense = np.zeros((plant.m, plant.m))
    mujoco.mj_fullM(plant.model, d, dense)
    np.testing.assert_array_equal(plant.full_mass(d.M[None, :].copy())[0], dense)


@pytest.mark.parametrize("native", [True, False])
def test_v_before_a_payload_swap_mid_second_has_the_inertia_of_its_own_step(native):
    """A payload swap at 0.15 s (not at a flush, which comes every simulated second): V at the rows before
    it is ½ sᵀ M s + ... with M of the arm as it was then. Earlier versions computed those rows' V at the
    flush after the swap, with the new payload's inertia (tests/test_log_formats.py keeps such a log)."""
    from pathlib import Path

    from adaptive_mj.data import SCENARIOS
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build

    over = ["simulation.duration=0.3", "events=[{t=0.15, kind='payload_swap', payload='sphere'}]"]
    setup = build(sc.load(Path(SCENARIOS / "ur5e_payload_swap.toml"), overrides=over))
    traj = run(setup.plant, setup.law, setup.reference, duration=0.3, theta_hat0=setup.theta_hat0,
               events=setup.events, native=native)
    assert traj.status == "ok" and traj.meta["events"][0][0] == pytest.approx(0.15)
    # the same arm without the swap: the old payload's inertia
    before = build(sc.load(Path(SCENARIOS / "ur5e_payload_swap.toml"), overrides=[over[0], "events=[]"]))
    M = before.plant.mass_matrices(traj.x[:150, 0])
    np.testing.assert_array_equal(traj.V[:150], setup.law.lyapunov(traj.s[:150], traj.theta_hat[:150],
                                                                   traj.theta[:150], M=M))
    M_after = setup.plant.mass_matrices(traj.x[150:, 0])  # the plant's model now has the new payload
    np.testing.assert_array_equal(traj.V[150:], setup.law.lyapunov(traj.s[150:], traj.theta_hat[150:],
                                                                   traj.theta[150:], M=M_after))


@pytest.mark.parametrize("evaluation", ["regressor", "recursive"])
def test_a_state_mujoco_finds_bad_mid_chunk_ends_diverged_with_the_python_path_s_rows(tmp_path, evaluation):
    """On the 6-joint arm a sinusoidal torque of 1000 N m (the stress study's top) drives the state to a huge
    acceleration or velocity (with Y formed whole a bad acceleration 9.12 s in; with the O(n) form a bad
    velocity 15.17 s in here: the run is chaotic, θ̂ grows past 1e8, and the two forms' last bits apart grow
    to other steps where MuJoCo gives up): MuJoCo warns, resets the data and steps on, and the callback stops
    in mid-step. The run ends `diverged` (not a RuntimeError), its log closed, with the rows of the Python
    path bit for bit. (On a bad velocity the native run keeps one row fewer than the Python path, the step
    MuJoCo reset at its start: a difference of the two paths' divergence handling, not of the law; the
    rows both keep are compared.)"""
    from adaptive_mj import run_scenario
    from adaptive_mj.study import stress

    plant = next(p for p in stress.plants(20.0) if p.name == "ur5e")
    overrides = [*plant.base, *dict(stress.laws(plant, composite=False))["sigma"],
                 "disturbance={kind='sine', magnitude=1000.0, omega=2.0}", f"law.evaluation='{evaluation}'"]
    a = run_scenario("ur5e_identification", set=overrides, seed=0, log=tmp_path / "native.mcap")
    b = run_scenario("ur5e_identification", set=[*overrides, "simulation.python_callback=true"], seed=0)
    assert a.trajectory.meta["native"] and not b.trajectory.meta["native"]
    assert a.status == b.status == "diverged"
    assert "mjWARN_BADQACC" in a.summary["reason"] or "mjWARN_BADQVEL" in a.summary["reason"]
    assert "in the step from t=" in a.summary["reason"]  # 9.121 s / 15.168 s here (the model's numbers are the CPU's)
    n = len(a.trajectory.t)
    if "mjWARN_BADQACC" in a.summary["reason"]:
        assert n == len(b.trajectory.t) > 1000
    else:  # mjWARN_BADQVEL: the Python path records the step whose start MuJoCo reset
        assert n + 1 == len(b.trajectory.t) and n > 1000
    for f in ("t", "x", "u", "s", "theta_hat"):
        np.testing.assert_array_equal(getattr(a.trajectory, f), getattr(b.trajectory, f)[:n], err_msg=f)
    from adaptive_mj.log.replay import read_log

    assert read_log(a.log_path).status == "diverged"

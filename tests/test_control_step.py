"""The control step written once (adaptive_mj.sim.stage, driven by adaptive_mj.sim.driver): the
native callbacks, the Python controller and adaptive_mj.env give the same rows bit for bit in both
control modes, on the heave vehicle, the 1-DOF arm and the 6-joint arm, with a control delay and an
event; sampled-data control holds its output and its estimates over each control period; the
compiled callback finds its run through mjData.userdata, so several runs and laws share a process
and a second process loads the compiled callback from numba's disk cache."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import mujoco
import numpy as np
import pytest

from adaptive_mj import env as amj_env
from adaptive_mj.errors import ScenarioError
from adaptive_mj.setup.scenario import SCENARIOS_DIR, load as load_scenario
from adaptive_mj.runs.runner import execute
from adaptive_mj.sim.stage import ControlTiming


FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")
SAMPLED_4 = ("control.mode='sampled'", "control.period=0.004")
SAMPLED_1 = ("control.mode='sampled'",)
DELAY = ("simulation.control_delay=3",)
CASES = {
    "heave": ("heave_tracking", ("simulation.duration=0.6",)),
    "arm_event": ("arm_payload_swap", ("simulation.duration=0.3",
                                       "events=[{t = 0.15, kind = 'payload_mass', value = 2.0}]")),
    "ur5e_event": ("ur5e_payload_swap", ("simulation.duration=0.2",
                                         "events=[{t = 0.1, kind = 'payload_mass', value = 1.5}]")),
}


def _run(name, overrides, *, python: bool):
    extra = ("simulation.python_callback=true",) if python else ()
    scn = load_scenario(SCENARIOS_DIR / f"{name}.toml", overrides=list(overrides) + list(extra))
    return execute(scn).trajectory


def _same(a, b):
    assert (a.status, a.reason) == (b.status, b.reason)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert a.meta["events"] == b.meta["events"]


@pytest.mark.parametrize("control", [(), SAMPLED_1, SAMPLED_4], ids=["continuous", "sampled_1", "sampled_4"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_native_python_and_env_give_the_same_rows(case, control):
    name, overrides = CASES[case]
    overrides = overrides + control + DELAY
    native = _run(name, overrides, python=False)
    python = _run(name, overrides, python=True)
    assert native.meta["native"] and not python.meta["native"]
    _same(native, python)
    env = amj_env.load(name, overrides=overrides, law="scenario", n_sub_steps=1)
    ts = env.reset()
    while not ts.last():
        ts = env.step(np.zeros(1))
    _same(env.task.trajectory(), python)
    assert mujoco.get_mjcb_control() is None
    if control == SAMPLED_4:
        assert native.meta["control_period_steps"] == 4 and native.meta["control_mode"] == "sampled"


@pytest.mark.parametrize("case", ["heave", "ur5e_event"])
def test_sampled_control_holds_over_the_period(case):
    """u is constant over each 4-step period and changes between periods; θ̂ only changes from one
    period to the next, by T times the rate computed at the sample (Euler, T = 4 dt)."""
    name, overrides = CASES[case]
    traj = _run(name, overrides + SAMPLED_4, python=False)
    n = len(traj) // 4 * 4
    u = traj.u[:n].reshape((n // 4, 4) + traj.u.shape[1:])
    assert np.array_equal(u, np.broadcast_to(u[:, :1], u.shape))
    assert np.any(u[1:, 0] != u[:-1, 0])
    th = traj.theta_hat[:n].reshape(n // 4, 4, -1)
    assert np.array_equal(th, np.broadcast_to(th[:, :1], th.shape))
    assert np.any(th[1:, 0] != th[:-1, 0])


def test_sampled_at_the_physics_step_differs_from_continuous_only_by_the_hold():
    """Sampled with T = dt evaluates the law once per step (RK4 stages see the held control); under
    explicit Euler one stage is all there is, so the two modes coincide bit for bit."""
    over = CASES["heave"][1] + ("simulation.integrator='euler'",)
    _same(_run("heave_tracking", over, python=False), _run("heave_tracking", over + SAMPLED_1, python=False))
    rk4_c = _run("heave_tracking", CASES["heave"][1], python=False)
    rk4_s = _run("heave_tracking", CASES["heave"][1] + SAMPLED_1, python=False)
    assert not np.array_equal(rk4_c.x, rk4_s.x)
    assert np.max(np.abs(rk4_c.x - rk4_s.x)) < 1e-3  # the same loop, held over 1 ms


def test_runs_and_laws_in_one_process_one_after_the_other():
    """Each run reaches its own context through its MjData: a heave run, a 6-joint run and the heave
    run again in one process give the first run's rows again (no table left pointing elsewhere)."""
    first = _run("heave_tracking", CASES["heave"][1], python=False)
    _run("ur5e_payload_swap", CASES["ur5e_event"][1], python=False)
    _run("arm_payload_swap", CASES["arm_event"][1] + SAMPLED_4, python=False)
    _same(first, _run("heave_tracking", CASES["heave"][1], python=False))


def test_a_scratch_mjdata_is_left_alone_by_the_native_callback():
    from adaptive_mj.setup.build import build
    from adaptive_mj.sim import native_mujoco

    scn = load_scenario(SCENARIOS_DIR / "heave_tracking.toml", overrides=["simulation.duration=0.1"])
    s = build(scn)
    nc = native_mujoco.Controller(s.plant, s.law, s.reference, s.theta_hat0, 10)
    other = mujoco.MjData(s.plant.model)  # userdata[0] = 0: no context
    with s.plant.controlled_natively(nc.callback):
        mujoco.mj_step(s.plant.model, other, nstep=5)
        assert not other.ctrl.any() and nc.context[0]["row"] == 0
        nc.chunk(10, None)
    assert nc.context[0]["row"] == 10


@pytest.mark.parametrize("overrides, match", [
    (("control.period=0.0015",), r"control\.period must be a whole multiple of the physics timestep 0\.001"),
    (("control.mode='continuous'", "control.period=0.002"), r"control\.period must be left out under"),
    (("control.hold='foh'",), r"control\.hold must be one of"),
    (("control.mode='sampled'", "law.composite={gain=1.0, filter=10.0}"),
     r"law\.composite runs under control\.mode = 'continuous'"),
])
def test_bad_control_keys_are_one_line_errors(overrides, match):
    with pytest.raises(ScenarioError, match=match):
        _run("heave_tracking", ("simulation.duration=0.1",) + overrides, python=False)


def test_control_timing_from_scenario_terms():
    t = ControlTiming.of(0.001, mode="sampled", period=0.004, delay=2)
    assert (t.steps, t.period, t.delay, t.sampled) == (4, 0.004, 2, True)
    assert ControlTiming.of(0.002).describe() == {"control_mode": "continuous", "control_period": 0.002,
                                                  "control_period_steps": 1}
    with pytest.raises(ValueError, match="not a whole multiple"):
        ControlTiming.of(0.001, mode="sampled", period=0.0025)


def test_struct_offsets_find_every_pointer_of_a_real_model():
    from adaptive_mj.plants.arm import compile_arm
    from adaptive_mj.sim.native_context import mujoco_offsets
    import ctypes

    off = mujoco_offsets()
    m = compile_arm()
    d = mujoco.MjData(m)
    for name in ("userdata", "qpos", "qvel", "ctrl", "cdof", "xpos", "xmat", "subtree_com", "cinert",
                 "qacc_warmstart", "qfrc_applied", "qfrc_passive", "qfrc_bias"):
        assert ctypes.c_int64.from_address(d._address + off[name]).value == getattr(d, name).ctypes.data, name
    for name in ("dof_armature", "dof_damping", "body_mass", "actuator_gear", "actuator_gainprm"):
        assert ctypes.c_int64.from_address(m._address + off[f"model.{name}"]).value == getattr(m, name).ctypes.data
    assert ctypes.c_double.from_address(m._address + off["model.gravity"] + 16).value == m.opt.gravity[2]
    # the activation state (the arm has none): the heave vehicle with its thruster lag
    from adaptive_mj.setup.build import build

    d = build(load_scenario(SCENARIOS_DIR / "heave_thruster_n3.toml")).plant.data
    assert d.act.size == 1 and ctypes.c_int64.from_address(d._address + off["act"]).value == d.act.ctypes.data


def test_a_second_process_loads_the_compiled_callback_from_the_disk_cache(tmp_path):
    code = textwrap.dedent("""
        from adaptive_mj.laws import SlidingAdaptiveLaw
        from adaptive_mj.plants import heave
        from adaptive_mj.sim import native_mujoco
        p = heave.load()
        law = SlidingAdaptiveLaw(p.form, lam=5.0, k=200.0, gamma=[1.0] * len(p.form.names))
        print(native_mujoco.compiled(p.mujoco_kernel, p.mujoco_kernel.variant(p, law)).cache_hits)
    """)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    hits = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
            for _ in range(2)]
    assert [h.split()[-1] for h in hits] == ["0", "1"]
    assert any(tmp_path.rglob("*.nbi"))


def test_a_single_short_run_takes_the_python_callback_with_the_same_rows():
    """`adaptive-mj run` on a short 1-DOF run skips the compiled callback's ~0.5 s load
    (runner.QUICK_START_MAX_STEPS); a study's run (single=False) and a manipulator stay compiled."""
    from adaptive_mj.runs.runner import QUICK_START_MAX_STEPS

    scn = load_scenario(SCENARIOS_DIR / "heave_tracking.toml", overrides=["simulation.duration=0.3"])
    quick, study = execute(scn, single=True).trajectory, execute(scn).trajectory
    assert not quick.meta["native"] and study.meta["native"]
    _same(quick, study)
    long = load_scenario(SCENARIOS_DIR / "heave_tracking.toml",
                         overrides=[f"simulation.duration={QUICK_START_MAX_STEPS * 1e-3 + 0.1}"])
    assert long.simulation.timestep == 1e-3 and execute(long, single=True).trajectory.meta["native"]
    arm = load_scenario(SCENARIOS_DIR / "ur5e_payload_swap.toml", overrides=["simulation.duration=0.05", "events=[]"])
    assert execute(arm, single=True).trajectory.meta["native"]


def test_the_step_order_is_written_once():
    """stage.control_stage is the one definition of a stage's order: the Python Controller runs its code, and no
    other module of the loop or the compiled callbacks calls the pieces of the order itself (the delay line, the
    rate's sum, the end of a stage), so a change of order cannot be made in one path only."""
    import inspect
    import re

    from adaptive_mj.plants import manipulator_kernel, one_dof_kernel, quadrotor_kernel
    from adaptive_mj.sim import loop, native_chunk, native_mujoco, native_step, stage
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.setup.build import build

    s = build(load(SCENARIOS_DIR / "heave_tracking.toml", overrides=["simulation.duration=0.01"]))
    ctrl = loop.Controller(s.law, s.reference, s.theta_hat0, s.plant.ctrl_range, 2, s.plant.stages, s.plant.dt)
    assert ctrl._stage.__code__ is stage.control_stage.__code__
    for module in (loop, native_mujoco, native_chunk, native_step, one_dof_kernel, manipulator_kernel,
                   quadrotor_kernel):
        calls = re.findall(r"\b(delay_slot|accumulate_rate|end_stage|is_sample_step)\(", inspect.getsource(module))
        assert calls == [], f"{module.__name__} calls {calls}: the step's order belongs to stage.control_stage"

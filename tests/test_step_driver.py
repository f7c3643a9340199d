"""The step driver (adaptive_mj.sim.driver): what happens between physics steps is written once. No module outside
adaptive_mj/sim/ steps a plant (a plant's own step definitions apart); every plant kind declares its compiled loop
(each MuJoCo kind its kernel spec beside its code, one generic controller for them all);
adaptive_mj.env ends an episode on the plant's termination as a run ends."""
from __future__ import annotations

import ast
import importlib
from pathlib import Path

import numpy as np

import adaptive_mj
from adaptive_mj.setup.scenario import SCENARIOS_DIR
from adaptive_mj.trajectory import Status

PACKAGE = Path(adaptive_mj.__file__).parent
STEPPING = {"mj_step", "mj_step1", "mj_step2", "step_native"}  # calls that advance MuJoCo's or a plant's time
#: (module, function) outside sim/ allowed to step: the plants' own step definitions, and the scorecard's bare
#: mj_step timing baseline (a model stepped with no law, the denominator of "cost × mj_step")
ALLOWED_FUNCTIONS = {"step", "step_native"}
ALLOWED = {("study/score.py", "timed")}


def _steps_a_plant(call: ast.Call) -> bool:
    func = call.func
    if not isinstance(func, ast.Attribute):
        return False
    if func.attr in STEPPING:
        return True
    receiver = ast.unparse(func.value)
    return func.attr == "step" and (receiver == "plant" or receiver.endswith(".plant"))


def _stepping_calls(path: Path) -> list[tuple[str, int, str]]:
    """(enclosing function, line, call) of every call in the module that steps a plant."""
    found: list[tuple[str, int, str]] = []

    def visit(node: ast.AST, function: str) -> None:
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else function
            if isinstance(child, ast.Call) and _steps_a_plant(child):
                found.append((function, child.lineno, ast.unparse(child.func)))
            visit(child, name)

    visit(ast.parse(path.read_text()), "")
    return found


def test_no_module_outside_sim_steps_a_plant():
    """Only adaptive_mj/sim/ (its step driver) advances a plant between steps: elsewhere a call of mj_step,
    step_native or plant.step() sits in a plant module's own step definition, or is the scorecard's bare timing."""
    offenders = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("sim/"):
            continue
        for function, line, call in _stepping_calls(path):
            if rel.startswith("plants/") and function in ALLOWED_FUNCTIONS or (rel, function) in ALLOWED:
                continue
            offenders.append(f"adaptive_mj/{rel}:{line} {call}() in {function or 'the module'}")
    assert not offenders, "stepped outside adaptive_mj/sim/:\n" + "\n".join(offenders)


def test_the_scan_sees_a_plant_stepped():
    """The scan above finds what it looks for (a copy of the env's old step body)."""
    source = "def one_step(self):\n    plant = self.plant\n    plant.step()\n    mujoco.mj_step(m, d)\n"
    calls = []

    def visit(node, function):
        for child in ast.iter_child_nodes(node):
            name = child.name if isinstance(child, ast.FunctionDef) else function
            if isinstance(child, ast.Call) and _steps_a_plant(child):
                calls.append((function, ast.unparse(child.func)))
            visit(child, name)

    visit(ast.parse(source), "")
    assert calls == [("one_step", "plant.step"), ("one_step", "mujoco.mj_step")]


def test_every_plant_kind_declares_its_compiled_loop():
    """Dispatch by declaration (protocol.Plant.compiled_loop): each bundled plant class names the module of its
    compiled loop, which gives `supported` and `Controller`; the wing-rock plant under MRAC names none."""
    from adaptive_mj.plants.linear import LinearPlant
    from adaptive_mj.plants.manipulator import ManipulatorPlant
    from adaptive_mj.plants.mujoco_plant import MujocoPlant
    from adaptive_mj.plants.quadrotor import QuadrotorPlant
    from adaptive_mj.plants.twin import TwinPlant

    expected = {MujocoPlant: "native_mujoco", ManipulatorPlant: "native_mujoco", QuadrotorPlant: "native_mujoco",
                LinearPlant: "native_chunk", TwinPlant: "native_chunk"}
    for cls, module in expected.items():
        assert cls.compiled_loop == f"adaptive_mj.sim.{module}", cls
        loop_module = importlib.import_module(cls.compiled_loop)
        assert callable(loop_module.supported) and isinstance(loop_module.Controller, type)


def _defining_modules(kernel) -> set[str]:
    """The modules defining a MuJoCo kernel spec's functions: its hooks and the pieces and laws compiled into its
    callback (the functions of its variants' cache keys)."""
    import dataclasses
    import types

    fns = [getattr(kernel, f.name) for f in dataclasses.fields(kernel)]
    return {fn.__module__ for fn in fns if isinstance(fn, types.FunctionType) and fn.__name__ != "<lambda>"}


def test_each_mujoco_kind_declares_its_kernel_beside_its_code_and_one_controller_serves_all():
    """Issue 51, item 2: each MuJoCo plant kind (the 1-DOF MujocoPlant, the arms, the quadrotor) declares its kernel
    spec (plants.mujoco_kernel.MujocoKernel) in a module beside its code, under adaptive_mj/plants/ (or laws/), never
    sim/; the one generic controller (sim.native_mujoco) compiles and drives every one of them: each kind's bundled
    scenario runs compiled through it, no other compiled MuJoCo controller module is left in sim/."""
    from adaptive_mj.plants.manipulator import ManipulatorPlant
    from adaptive_mj.plants.mujoco_kernel import MujocoKernel
    from adaptive_mj.plants.mujoco_plant import MujocoPlant
    from adaptive_mj.plants.quadrotor import QuadrotorPlant
    from adaptive_mj.runs.runner import execute
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.scenario import load
    from adaptive_mj.sim import loop, native_mujoco
    from adaptive_mj.sim.stage import ControlTiming

    kinds = {MujocoPlant: ("one_dof_kernel", "heave_tracking"), ManipulatorPlant: ("manipulator_kernel", "ur5e_drift"),
             QuadrotorPlant: ("quadrotor_kernel", "quadrotor_lemniscate")}
    for cls, (module, scenario) in kinds.items():
        kernel = cls.mujoco_kernel
        assert isinstance(kernel, MujocoKernel) and cls.compiled_loop == "adaptive_mj.sim.native_mujoco", cls
        assert kernel.plant_type() is cls
        defined = _defining_modules(kernel)
        assert f"adaptive_mj.plants.{module}" in defined, (cls, defined)
        assert all(m.startswith(("adaptive_mj.plants.", "adaptive_mj.laws.")) for m in defined), (cls, defined)
        s = build(load(SCENARIOS_DIR / f"{scenario}.toml", overrides=["simulation.duration=0.01", "events=[]"]))
        assert type(s.plant).mujoco_kernel is kernel and native_mujoco.supported(s.plant, s.law), scenario
        variant = kernel.variant(s.plant, s.law)
        assert not [fn for fn in variant.key_functions if fn.__module__.startswith("adaptive_mj.sim")], scenario
        nc = loop._native_controller(s.plant, s.law, s.reference, np.asarray(s.theta_hat0, dtype=float),
                                     ControlTiming(period=s.plant.dt), None, chunk=5)
        assert type(nc) is native_mujoco.MujocoController and nc.kernel is kernel, scenario
        nc.__exit__(None, None, None)
        traj = execute(load(SCENARIOS_DIR / f"{scenario}.toml",
                            overrides=["simulation.duration=0.01", "events=[]"])).trajectory
        assert traj.meta["native"] is True, scenario
    left = sorted(p.name for p in (PACKAGE / "sim").glob("native*.py"))
    assert left == ["native_chunk.py", "native_context.py", "native_mujoco.py", "native_step.py"], left


def test_an_episode_ends_on_the_plant_s_termination():
    """adaptive_mj.env asks the plant's termination() after every physics step, as a run does: the episode ends
    there (LAST, discount 0) with status "crashed" and the rows up to that step."""
    from adaptive_mj import env as amj_env

    for law in ("scenario", None):
        env = amj_env.load(SCENARIOS_DIR / "heave_tracking.toml", law=law, n_sub_steps=4,
                           overrides=["simulation.duration=0.1"])
        ts = env.reset()
        plant = env.task._episode.plant
        plant.termination = lambda plant=plant: "crashed at t = 0.02 s: a test" if plant.time >= 0.02 - 1e-12 else None
        steps = 0
        while not ts.last():
            ts = env.step(np.zeros(1))
            steps += 1
        traj = env.task.trajectory()
        assert (traj.status, traj.reason) == (Status.CRASHED, "crashed at t = 0.02 s: a test"), law
        assert ts.discount == amj_env.DISCOUNT_DIVERGED and steps == 5 and len(traj.t) == 20
        env.close()

"""A law's compiled form is declared beside its kind (laws.protocol.Law.chunk_kernel, laws.kernel.LawKernel) and the
compiled paths find it by declaration: the analytic chunk engine (adaptive_mj.sim.native_chunk) asks the law object,
with no list of law classes. A built-in law kind whose law is plain array code in the plugin form
(laws.plugin.KernelLaw) runs compiled as a plugin's law does: a toy kind registered in this test alone runs compiled
on a MuJoCo plant (the heave vehicle, adaptive_mj.plants.one_dof_kernel's 1-DOF callback) and on an analytic plant
(the heave vehicle's twin, the chunk engine), its rows bit for bit the Python path's (simulation.python_callback)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from same_rows import same_rows

from adaptive_mj.keys import Key
from adaptive_mj.laws import kinds
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws.common import as_gamma
from adaptive_mj.laws.kernel import LawKernel
from adaptive_mj.laws.kinds import Form, LawKind
from adaptive_mj.laws.plugin import KernelLaw, LawPlugin, Param, Shared, plugin_kernel
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim import native_chunk
from adaptive_mj.specs import LawSpec

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


# --- the toy kind: an adaptive law of order 2 written to the plugin interface, a built-in kind of this test --------
def toy_law(x, ref, theta, phi, f, h, params, rate):
    """s = ỹ' + λ ỹ, u = (d̂ ṡ_r - f - φᵀp̂ + k s) / h, d̂' = ṡ_r s / γ_d, p̂' = -φ s / γ_p: the lecture's
    sliding law of order 2 in plain scalar code; params = [λ, k, γ (n_theta)]."""
    lam, k = params[0], params[1]
    e0 = ref[0] - x[0]
    e1 = ref[1] - x[1]
    s = e1 + lam * e0
    s_r_dot = ref[2] + lam * e1
    acc = theta[0] * s_r_dot - f
    for i in range(phi.shape[0]):
        acc = acc - phi[i] * theta[1 + i]
    rate[0] = s_r_dot * s / params[2]
    for i in range(phi.shape[0]):
        rate[1 + i] = -phi[i] * s / params[3 + i]
    return (acc + k * s) / h, s


TOY = LawPlugin(law=toy_law, params=(Param("lambda", gt=0), Param("k", ge=0), Param("gamma", per_parameter=True)),
                gain="gamma", orders=(2,), doc="the sliding law of order 2 as plain array code (a test's toy)")


def _read(t, kind, plant, order):
    law_order = shared.read_order(t, plant, order)
    params = {"lambda": t.number("lambda", gt=0), "k": t.number("k", ge=0)}
    gamma = shared.read_gamma(t)
    shared.required(t, gamma, "law.gamma", kind)
    dead_zone = shared.read_dead_zone(t)
    initial = shared.read_estimates(t, "initial_estimates")
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=gamma, dead_zone=dead_zone,
                   initial_estimates=initial, nominal=None, K=None, boundary_layer=None, params=params)


def _build(ctx):
    form = ctx.model_form()
    gamma = as_gamma(ctx.gamma(form.names), len(form.names))
    params = np.array([ctx.law.params["lambda"], ctx.law.params["k"], *gamma])
    shared_mods = Shared.of(len(form.names), gamma=gamma, dead_zone=ctx.dead_zone(), modification=ctx.modification)
    return KernelLaw(TOY, form, params, kind=ctx.law.kind, shared=shared_mods, modification=ctx.modification)


TOY_KIND = LawKind(
    "toy_kernel", frozenset({Form.MODEL}), True, "the sliding law of order 2 as plain array code (a test's toy)",
    keys=(shared.KIND, shared.ORDER, Key("lambda", "number", unit="1/s", bounds="> 0", required=True),
          Key("k", "number", bounds=">= 0", required=True), shared.GAMMA_REQUIRED, shared.DEAD_ZONE,
          shared.INITIAL_ESTIMATES),
    read=_read, build=_build, module=__name__)


@pytest.fixture
def toy_kind(monkeypatch):
    """The toy kind registered as a built-in one for the test (the registry restored after it)."""
    monkeypatch.setattr(kinds, "_BUILT_IN", kinds.built_in())
    kinds.register(TOY_KIND)
    return TOY_KIND


def _same(name: str, overrides):
    return same_rows(SCENARIOS / f"{name}.toml", ["law.kind='toy_kernel'", *overrides])


@pytest.mark.parametrize("name,extra", [
    ("heave_tracking", ["simulation.duration=2"]),
    ("heave_tracking", ["simulation.duration=2", "law.dead_zone={width=0.01}", "noise.std={y=0.001, y_dot=0.01}",
                        "noise.seed=3"]),
    ("lecture_heave", ["simulation.duration=3"]),
    ("lecture_heave", ["simulation.duration=3", "law.dead_zone={width=0.01, on='tracking_error'}",
                       "noise.std={y=0.001, y_dot=0.01}", "noise.seed=2"]),
], ids=["mujoco", "mujoco_dead_zone_noise", "analytic", "analytic_dead_zone_noise"])
def test_a_built_in_kind_of_plain_array_code_runs_compiled_bit_for_bit(toy_kind, name, extra):
    traj = _same(name, extra)  # compiled (meta "native" True), every row the Python path's bit for bit
    assert str(traj.status) == "ok" and np.abs(np.diff(traj.theta_hat, axis=0)).max() > 0  # it adapts


def test_the_toy_law_is_found_by_its_declaration(toy_kind):
    """The chunk engine takes the kernel the law object declares: the plugin form's kernel with the toy's function
    bound in, as a plugin's; the law is no plugin (nothing installed, the log records none)."""
    setup = build(sc.load(SCENARIOS / "lecture_heave.toml", overrides=["law.kind='toy_kernel'"]))
    law = setup.law
    assert isinstance(law, KernelLaw) and law.installed is None and law.native
    lk = native_chunk.law_of(law, setup.plant)
    assert isinstance(lk, LawKernel) and lk.fn is plugin_kernel and lk.user_law is toy_law and lk.form is law.form
    assert "toy_kernel" in lk.what
    assert law.chunk_kernel(law.order + 1) is None  # on a plant of another order: the Python path
    assert native_chunk.supported(setup.plant, law)
    assert law.native_params()["plugin_law"] is toy_law  # what the MuJoCo 1-DOF callback compiles


@pytest.mark.parametrize("name", ["lecture_first_order", "lecture_heave", "rohrs_counterexample"])
def test_each_built_in_kernel_lives_beside_its_kind(name):
    """The kernel a bundled law declares is defined in its law kind's own module, and the engine's module holds no
    law kernel (it imports none from laws/ but the spec)."""
    scn = sc.load(SCENARIOS / f"{name}.toml")
    setup = build(scn)
    lk = native_chunk.law_of(setup.law, setup.plant)
    assert lk is not None
    assert lk.fn.__module__ == kinds.built_in()[scn.law.kind].module == type(setup.law).__module__
    source = Path(native_chunk.__file__).read_text()
    assert "isinstance(law" not in source and "from adaptive_mj.laws.mrac" not in source


# --- a built-in multi-joint kind written to the plugin interface: compiled like a plugin's ------------------------
ROBUST_SL = Path(__file__).resolve().parent.parent / "examples" / "robust_sl_law" / "robust_sl_law.py"


@pytest.fixture
def joint_toy_kind(monkeypatch):
    """The example multi-joint plugin's declaration (examples/robust_sl_law) as a built-in kind of this test."""
    import importlib.util

    from adaptive_mj.laws.plugin import JointKernelLaw

    spec = importlib.util.spec_from_file_location("robust_sl_law_toy", ROBUST_SL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    def read(t, kind, plant, order):
        law_order = shared.read_order(t, plant, order)
        params = {"lambda": t.number("lambda", gt=0), "kd": t.number("kd", ge=0)}
        gamma = shared.read_gamma(t)
        initial = shared.read_estimates(t, "initial_estimates")
        t.finish()
        return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=gamma, dead_zone=None,
                       initial_estimates=initial, nominal=None, K=None, boundary_layer=None, params=params)

    def build_law(ctx):
        rb = ctx.rigid_body()
        gamma = as_gamma(ctx.gamma(rb.names), len(rb.names))
        params = np.array([ctx.law.params["lambda"], ctx.law.params["kd"], 1.0, 0.05, *gamma])
        sh = Shared.of(len(rb.names), gamma=gamma, modification=ctx.modification)
        return JointKernelLaw(module.LAW, rb.regressor, rb.names, rb.m, params, kind=ctx.law.kind, shared=sh,
                              modification=ctx.modification)

    kind = LawKind("toy_joint_kernel", frozenset({Form.RIGID_BODY}), True, "robust Slotine-Li (a test's toy)",
                   keys=(shared.KIND, shared.ORDER, Key("lambda", "number", bounds="> 0", required=True),
                         Key("kd", "number", bounds=">= 0", required=True), shared.GAMMA_REQUIRED,
                         shared.INITIAL_ESTIMATES),
                   read=read, build=build_law, module=__name__)
    monkeypatch.setattr(kinds, "_BUILT_IN", kinds.built_in())
    kinds.register(kind)
    return kind


def test_a_built_in_multi_joint_kind_of_plain_array_code_runs_compiled_bit_for_bit(joint_toy_kind):
    """A JointKernelLaw (a built-in kind's multi-joint law function, no plugin installed) runs compiled in the arm
    callback as an installed plugin's does (plants/manipulator_kernel.py: plugin_functions, supported take any
    JointKernelLaw's native_params), every row the Python path's bit for bit."""
    traj = same_rows(SCENARIOS / "ur5e_drift.toml", ["law.kind='toy_joint_kernel'", "simulation.duration=0.2"])
    assert str(traj.status) == "ok" and len(traj.t) == 200
    assert np.all(np.isfinite(traj.u)) and np.all(np.isfinite(traj.V))  # V: the declaration's lyapunov

"""The compiled chunk of the linear plant under MRAC (adaptive_mj.sim.native_chunk) gives the Python path's rows
bit for bit (np.array_equal, not allclose), its status and reason too; what it does not run falls back to the
Python path; the law's shared arithmetic (laws.mrac.mrac_values) is the numpy expressions it replaced, bit for
bit; the reference model's vectorised rows are its scalar calls' (reference.ModelResponse.scalar_rows)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from same_rows import FIELDS, run_scenario, same_rows

from adaptive_mj.form import plain_dot
from adaptive_mj.laws.common import DeadZone, DeadZoneOn, Modification, modify_rate
from adaptive_mj.laws.mrac import MracLaw, Rule
from adaptive_mj.reference import ModelResponse
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.plants import linear
from adaptive_mj.sim import native_chunk
from adaptive_mj.runs.runner import execute

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
DELAY, ROHRS = SCENARIOS / "mrac_time_delay.toml", SCENARIOS / "rohrs_counterexample.toml"
_same = same_rows


def test_nguyen_delay_bounded():
    """γ = 2 with the 0.5 s input delay (100 steps of the delay line)."""
    traj = _same(DELAY, ["simulation.duration=20"])
    assert str(traj.status) == "ok" and len(traj.t) == 4000


def test_nguyen_delay_diverges_at_the_same_row():
    """γ = 2.9 diverges: the same last row, the same status and reason."""
    traj = _same(DELAY, ["law.gamma=2.9"])
    assert str(traj.status) == "diverged" and "beyond the bound" in traj.reason


def test_nguyen_delay_projection_and_clamp():
    _same(DELAY, ["law.gamma=2.9", "law.projection={k_y=[-2, 0], k_r=[0, 4]}", "simulation.duration=15"])
    _same(DELAY, ["plant.ctrl_range=[-1.5, 1.5]", "simulation.duration=15"])


def test_rohrs_with_its_unmodelled_dynamics():
    """Rohrs' published case (a third-order plant: A x through BLAS as on the Python path) diverges alike."""
    traj = _same(ROHRS, [])
    assert str(traj.status) == "diverged"


@pytest.mark.parametrize("overrides", [
    ["law.sigma=0.1"],
    ["law.e_modification=0.5"],
    ["law.projection={k_y=[-5, 0], k_r=[0, 5]}"],
    ["law.dead_zone={width=0.5}"],
    ["law.dead_zone={width=0.2, on='tracking_error'}", "law.sigma=0.05"],
], ids=["sigma", "e_mod", "projection", "dead_zone", "dead_zone_error_sigma"])
def test_rohrs_modifications(overrides):
    _same(ROHRS, overrides + ["simulation.duration=12"])


def test_noise_control_delay_and_sampled_control():
    _same(ROHRS, ["noise.std={y=0.01}", "noise.seed=3", "simulation.duration=8"])
    _same(ROHRS, ["simulation.control_delay=3", "simulation.duration=8"])
    _same(ROHRS, ["control.mode='sampled'", "control.period=0.02", "simulation.duration=8"])
    _same(DELAY, ["control.mode='sampled'", "control.period=0.01", "simulation.control_delay=2",
                  "simulation.duration=8"])


def test_disturbance_and_a_constant_force_event(tmp_path):
    """force_offset + disturbance(t) per step, and an event that changes force_offset mid-run (the chunk ends
    there)."""
    text = ROHRS.read_text() + ('\n[disturbance]\nkind = "sine"\nmagnitude = 0.3\nomega = 2.0\n\n'
                                '[[events]]\nt = 3.0\nkind = "constant_force"\nvalue = 0.4\n')
    path = tmp_path / "rohrs_forced.toml"
    path.write_text(text)
    traj = _same(path, ["simulation.duration=6"])
    assert traj.meta["events"]


def test_mit_rule_falls_back_to_the_python_path():
    """The MIT rule's sensitivity filter is stepped in Python: the run takes the Python path (same rows)."""
    _same(ROHRS, ["law.rule='mit'", "simulation.duration=3"], native=False)


def test_python_callback_forces_the_python_path():
    traj = run_scenario(ROHRS, ["simulation.duration=1"], python=True)
    assert traj.meta["native"] is False
    setup = build(sc.load(ROHRS))
    assert native_chunk.supported(setup.plant, setup.law)


def test_mrac_values_are_the_numpy_expressions_it_replaced():
    """MracLaw.__call__ before the shared functions, as numpy expressions: the same bits on random inputs, with
    and without a dead-zone (on s, on e), leakage and a box, order 1 and 2."""
    rng = np.random.default_rng(5)
    for trial in range(300):
        order = 1 + trial % 2
        nth = order + 1
        dz = [None, DeadZone(0.3), DeadZone(0.3, DeadZoneOn.TRACKING_ERROR)][trial % 3]
        mod = Modification(sigma=0.1 * (trial % 4 == 0), e_mod=0.5 * (trial % 5 == 0),
                           lower=np.full(nth, -0.5) if trial % 7 == 0 else None,
                           upper=np.full(nth, 0.5) if trial % 7 == 0 else None)
        alpha = [3.0] if order == 1 else [4.0, 2.8]
        law = MracLaw(order=order, alpha=alpha, beta=2.5, gamma=rng.uniform(0.5, 3.0, nth),
                      sign_b=[1.0, -1.0][trial % 2], dead_zone=dz, modification=mod)
        x, ref, th = rng.normal(size=order), rng.normal(size=order + 1), rng.normal(size=nth)
        out = law(0.0, x, ref, th)
        # the former arithmetic, its dot products (numpy's `@`, BLAS) summed as BLAS sums them without fused
        # multiply-adds (form.plain_dot: OpenBLAS fuses on AVX-512, one ulp apart in about a quarter of draws)
        r = float((ref[order] + plain_dot(law.alpha, ref[:order])) / law.beta)
        omega = np.concatenate([np.asarray(x[:order], dtype=float), np.array([r])])
        u = plain_dot(th, omega)
        e = x[:order] - ref[:order]
        s = plain_dot(e, law.pb)
        if dz is None or dz.adapting(s, float(e[0])):
            rate = -law.sign_b * law.gamma * omega * s
        else:
            rate = np.zeros(nth)
        sigma, e_mod, theta0, lower, upper = mod.arrays(nth)
        modify_rate(rate, th, abs(s), sigma, e_mod, theta0, 1.0 / law.gamma, lower, upper)
        assert out.u == u and out.s == -s and out.s_r_dot == float(ref[order])
        assert np.array_equal(out.theta_hat_dot, rate)
    assert MracLaw(order=1, alpha=[3.0], beta=3.0, gamma=1.0, rule=Rule.MIT).compiled_form is False


@pytest.mark.parametrize("kw", [
    dict(alpha=(2.0,), beta=2.0, amplitudes=(1.0,), omegas=(1.0,), phases=(0.0,)),
    dict(alpha=(3.0,), beta=3.0, offset=0.3, amplitudes=(1.85,), omegas=(16.1,), phases=(0.0,)),
    dict(alpha=(4.0, 2.8), beta=4.0, amplitudes=(0.3, 0.15), omegas=(0.5, 1.3), phases=(0.0, 0.2)),
    dict(alpha=(2.0, 3.0), beta=1.5, offset=-0.7),
])
def test_model_response_rows_are_its_scalar_calls(kw):
    """ModelResponse.scalar_rows at the RK4 stage times of 2000 steps: each column is a scalar call's bits."""
    ref = ModelResponse(**kw)
    t = np.cumsum(np.r_[0.0, np.full(1999, 0.005)])
    times = np.sort(np.r_[t, t + 0.0025])
    order = len(kw["alpha"])
    rows = ref.scalar_rows(times, order)
    for i, ti in enumerate(times):
        assert np.array_equal(rows[:, i], ref(float(ti), order))


def test_chunk_size_does_not_change_the_rows():
    """Chunks of 7 steps (the delay lines and the held s carried across chunks) give the 1000-step chunks' rows."""
    from adaptive_mj.sim.loop import drive, prepare

    out = []
    for chunk in (7, 1000):
        setup = build(sc.load(DELAY, overrides=["simulation.duration=2", "simulation.control_delay=3"]))
        r = prepare(setup.plant, setup.law, setup.reference, duration=2.0, theta_hat0=setup.theta_hat0,
                    control_delay=3, chunk=chunk)
        assert r.nc is not None and r.nc.max_rows == chunk
        out.append(drive(r, setup.law, setup.reference))
    for name in FIELDS:
        assert np.array_equal(getattr(out[0], name), getattr(out[1], name), equal_nan=True), name


def test_a_python_path_log_verifies_on_the_compiled_path(tmp_path, monkeypatch, capsys):
    """A log written on the Python path (as every linear-plant log before the compiled loop was) re-simulates on the
    compiled loop bit for bit: `replay --verify` says so."""
    from adaptive_mj.cli import main
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.runs.verify import verify

    log = tmp_path / "rohrs.mcap"
    with monkeypatch.context() as m:
        m.setattr(native_chunk, "supported", lambda plant, law: False)
        result = execute(sc.load(ROHRS, overrides=["simulation.duration=25"]), log_path=log)
    assert result.trajectory.meta["native"] is False and str(result.trajectory.status) == "diverged"
    ok, message = verify(read_log(log))
    assert ok, message
    main(["replay", str(log), "--verify"])  # its exit status says the run diverged; the verdict is on stdout
    assert "verify: bit-identical" in capsys.readouterr().out


def test_the_cache_key_follows_every_compiled_source():
    """The compiled stepper's cache key hashes the modules of everything it compiles in, however deep: the law's
    kernel, declared beside its kind, and its arithmetic (laws.mrac.mrac_kernel → mrac_values → common.modify_rate,
    dead_zone_open), the step's order (stage.control_stage → clip_into), the plant's step
    (plants.analytic.analytic_step) and kernel (plants.linear) and the stepper itself."""
    import inspect

    from adaptive_mj.laws.mrac import mrac_kernel
    from adaptive_mj.sim.native_context import reached_functions

    fns = reached_functions(*native_chunk.key_functions(mrac_kernel), linear.KERNEL.rate, linear.KERNEL.observe)
    names = {fn.__name__ for fn in fns}
    assert {"mrac_values", "mrac_regressor", "modify_rate", "dead_zone_open", "clip_into", "control_stage",
            "end_stage", "accumulate_rate", "delay_slot", "analytic_step", "linear_rate"} <= names
    files = {Path(inspect.getsourcefile(fn) or "").name for fn in fns}
    assert {"mrac.py", "common.py", "stage.py", "native_chunk.py", "native_step.py", "analytic.py",
            "linear.py"} <= files

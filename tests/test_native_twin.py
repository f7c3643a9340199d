"""The twin's compiled chunk (adaptive_mj.sim.native_chunk) gives the Python path's rows bit for bit (np.array_equal,
not allclose), its status and reason too, under the first-order law, the sliding laws and their modifications;
what it does not run falls back to the Python path; the first-order law's shared arithmetic
(laws.first_order.first_order_values) is the numpy expression it replaced; numba_util.scalar_power compiles to
numpy's scalar pow, not to a product."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from same_rows import same_rows

from adaptive_mj.form import plain_dot
from adaptive_mj.laws.common import modify_rate
from adaptive_mj.laws.first_order import FirstOrderGains, first_order_values
from adaptive_mj.numba_util import scalar_power
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim import native_chunk

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def _same(name: str, overrides, *, native: bool = True):
    """same_rows on the bundled scenario `name`."""
    return same_rows(SCENARIOS / f"{name}.toml", overrides, native=native)


@pytest.mark.parametrize("start", [[-5.0, -4.0], [2.0, 3.0], [-1.0, -3.0]], ids=["lecture", "x+2_p-4", "x+1_p+4"])
def test_phase_space_portrait(start):
    """x' = sin²(x) p + u: the lecture's starting point and two more (x(0), p̂(0)); sin² is pow, not a product."""
    x0, p0 = start
    traj = _same("lecture_phase_space", ["simulation.duration=8", f"simulation.initial_state=[{x0}]",
                                         f"law.initial_estimates={{p={p0}}}"])
    assert str(traj.status) == "ok" and abs(traj.x[-1, 0]) < 1e-2


@pytest.mark.parametrize("extra", [
    [],
    ["law.dead_zone={width=0.05, on='tracking_error'}"],
    ["law.sigma=0.1", "law.projection={a=[0.0, 1.5]}"],
    ["law.e_modification=0.2"],
    ["noise.std={y=0.01}", "noise.seed=4"],
    ["plant.ctrl_range=[-2.0, 2.0]"],
    ["events=[{t=3.0, kind='constant_force', value=0.5}]"],
    ["simulation.integrator='euler'"],
    ["control.mode='sampled'", "control.period=0.01"],
    ["simulation.control_delay=3"],
], ids=["plain", "dead_zone", "sigma+projection", "e_mod", "noise", "clamp", "force_event", "euler", "sampled",
        "delay"])
def test_first_order_law(extra):
    _same("lecture_first_order", ["simulation.duration=6", *extra])


@pytest.mark.parametrize("extra", [
    [],
    ["law.dead_zone={width=0.01}", "law.sigma=0.01"],
    ["law.kind='robust_sliding'", "law.K=2.0", "law.boundary_layer=0.05"],
    ["law.kind='fixed_nominal'"],
    ["noise.std={y=0.001, y_dot=0.01}", "noise.seed=2"],
    ["disturbance={kind='sine', magnitude=3.0, omega=2.0}"],
    ["simulation.integrator='euler'"],
], ids=["plain", "dead_zone+sigma", "robust", "fixed_nominal", "noise", "disturbance", "euler"])
def test_heave_twin_sliding_law(extra):
    """The lecture's vehicle on the twin (d = 1.5, b = 1.9, c = 5.2) under the sliding laws."""
    _same("lecture_heave", ["simulation.duration=4", *extra])


def test_the_twin_of_a_mujoco_model_and_of_the_lagged_vehicle():
    """plant.backend = "twin" on a MuJoCo scenario: its form and θ from the compiled model; order 3 (thruster lag)."""
    _same("heave_tracking", ["plant.backend='twin'", "simulation.duration=3"])
    _same("heave_thruster_n3", ["plant.backend='twin'", "simulation.duration=2"])


def test_wing_rock_sliding_law_and_divergence_at_the_same_row():
    """The wing-rock twin (φ with |x1| x2, x1³) under the sliding law; a gain past the loop's limit diverges on the
    same row with the same reason."""
    _same("wing_rock", ["simulation.duration=32"])  # its flight-condition event at 30 s
    traj = _same("lecture_heave", ["simulation.duration=3", "law.k=1e6", "simulation.state_bound=50"])
    assert str(traj.status) == "diverged"


def test_what_it_does_not_run_falls_back_to_python():
    """Composite adaptation takes the Python path (same rows: it is that path)."""
    _same("lecture_heave", ["simulation.duration=1", "law.composite={gain=1.0, filter=2.0}"], native=False)


def test_mrac_with_matched_terms_runs_compiled_bit_for_bit():
    """MRAC on the wing-rock twin, its matched terms ψ = [|x1| x2, |x2| x2, x1³] compiled in (laws.mrac
    .mrac_psi_kernel; it ran on the Python path before), through its flight-condition event: every row the Python
    path's."""
    setup = build(sc.load(SCENARIOS / "wing_rock_mrac.toml"))
    assert native_chunk.supported(setup.plant, setup.law) and setup.law.psi is not None
    traj = _same("wing_rock_mrac", ["simulation.duration=32"])  # its event at 30 s
    assert traj.meta["native"] is True


def test_first_order_values_is_the_expression_it_replaced():
    """The shared function against FirstOrderAdaptiveLaw's former numpy arithmetic, bit for bit, on random inputs
    (one and two parameters, with and without leakage)."""
    rng = np.random.default_rng(11)
    for n_p in (1, 2):
        for sigma, e_mod in ((0.0, 0.0), (0.3, 0.7)):
            gains = FirstOrderGains(k=float(rng.uniform(0.1, 5)), dz_width=0.0, sigma=sigma, e_mod=e_mod,
                                    dead_zone=False)
            gamma = rng.uniform(0.1, 3, n_p)
            theta0, lower, upper = np.zeros(n_p), np.full(n_p, -np.inf), np.full(n_p, np.inf)
            for _ in range(2000):
                x, ref, th = rng.normal(size=1) * 3, rng.normal(size=2) * 3, rng.normal(size=n_p) * 5
                phi, f, h = rng.normal(size=n_p) * 2, float(rng.normal()), float(rng.uniform(0.5, 2))
                rate = np.empty(n_p)
                u, x_tilde = first_order_values(x, ref, th, gains, gamma, theta0, lower, upper, phi, f, h, rate)
                old_x_tilde = float(ref[0] - x[0])
                # numpy's phi @ th summed as BLAS sums it without fused multiply-adds (form.plain_dot: OpenBLAS
                # fuses on AVX-512, one ulp apart in about a quarter of draws)
                old_u = (ref[1] - f - plain_dot(phi, th) + gains.k * old_x_tilde) / h
                old_rate = -phi * old_x_tilde / gamma
                modify_rate(old_rate, th, abs(old_x_tilde), sigma, e_mod, theta0, gamma, lower, upper)
                assert u == old_u and x_tilde == old_x_tilde
                assert np.array_equal(rate, old_rate)


def _square(v):
    return scalar_power(v, 2)


def test_scalar_power_compiles_to_numpy_scalar_pow():
    """numba_util.scalar_power compiled (jit_tree: libm_pow) gives numpy's np.float64 ** 2 on every value, where
    numba's own v ** 2 (a product) does not on all of them: the barrier that keeps the paths together is needed."""
    import numba

    from adaptive_mj.numba_util import jit_tree

    compiled = jit_tree(_square, numba.njit)
    product = numba.njit(lambda v: v ** 2)
    values = np.sin(np.random.default_rng(3).normal(size=20000) * 3)
    numpy_pow = np.array([np.float64(v) ** 2 for v in values])
    assert np.array_equal(np.array([compiled(v) for v in values]), numpy_pow)
    assert not np.array_equal(np.array([product(v) for v in values]), numpy_pow)


def test_each_variant_is_named_apart():
    """Every variant's compiled function carries its cache key in its name (native_context.unique_factory): the
    variants share their argument types, so two of them compiled in two processes must not define one symbol."""
    names = set()
    for name in ("lecture_phase_space", "lecture_first_order", "lecture_heave"):
        setup = build(sc.load(SCENARIOS / f"{name}.toml"))
        plant = setup.plant
        fn = native_chunk.compiled(plant.kernel, plant.kernel.functions(plant), native_chunk.law_of(setup.law, plant))
        names.add(fn.py_func.__qualname__)
        assert fn.py_func.__qualname__.startswith("chunk_factory_") and ".callback_" in fn.py_func.__qualname__
    assert len(names) == 3

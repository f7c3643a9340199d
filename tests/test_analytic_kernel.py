"""A new analytic plant kind runs compiled by declaring its kernel in its own module only (here, this test): a
scalar first-order plant d y' = -a y + u + force, its kernel (plants.analytic.AnalyticKernel: params, rate,
observe) written below and nothing in adaptive_mj.sim touched, is stepped by the analytic chunk engine
(adaptive_mj.sim.native_chunk) under MRAC and under the lecture's first-order law, and gives the Python path's rows
bit for bit (np.array_equal, not allclose), with a disturbance, noise, an input delay and Euler steps too."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.first_order import FirstOrderAdaptiveLaw
from adaptive_mj.laws.mrac import MracLaw, gain_names, ideal_gains
from adaptive_mj.plants.analytic import AnalyticKernel, AnalyticPlant
from adaptive_mj.reference import Cosine, ModelResponse
from adaptive_mj.sim import loop, native_chunk

FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")


# --- the toy kind: its kernel and its plant, all it declares ----------------------------------------------------
def toy_params(plant):
    return plant.a, plant.d


def toy_rate(p, x, u, force, out):
    """y' = (-a y + u + force) / d."""
    a, d = p
    out[0] = (-a * x[0] + u + force) / d


def toy_observe(p, x, y):
    y[0] = x[0]


TOY = AnalyticKernel("toy_first_order", params=toy_params, rate=toy_rate, observe=toy_observe)


class ToyPlant(AnalyticPlant):
    """d y' = -a y + u (+ force); theta: the true parameters in the law's coordinates (names)."""

    kernel = TOY
    joint_shape: tuple[int, ...] = ()
    joint_names: tuple[str, ...] = ()
    first_contact = None
    joint_limits = None
    order = 1

    def __init__(self, a: float, d: float, *, names, theta, dt: float, stages: int = 4, delay_steps: int = 0,
                 ctrl_range=None):
        self.a, self.d, self.dt, self._stages = float(a), float(d), float(dt), stages
        self.names, self._theta = tuple(names), np.asarray(theta, dtype=float)
        self.delay_steps, self.ctrl_range = delay_steps, ctrl_range
        self.x = np.zeros(1)
        self.init_steps(1)

    @property
    def stages(self) -> int:
        return self._stages

    def set_state(self, x0) -> None:
        self.x = np.array(x0, dtype=float).reshape(1)
        self.restart()

    def observe(self) -> np.ndarray:
        return self.x.copy()

    def true_theta(self) -> np.ndarray:
        return self._theta


# --- the runs -----------------------------------------------------------------------------------------------------
def _mrac(stages: int, delay: int):
    a, b = 1.5, 1.0  # d = 1/b
    plant = ToyPlant(a, 1.0 / b, names=gain_names(1), theta=ideal_gains([-a], b, [], [2.0], 2.0), dt=0.005,
                     stages=stages, delay_steps=delay, ctrl_range=(-4.0, 4.0))
    law = MracLaw(order=1, alpha=[2.0], beta=2.0, gamma=[2.0, 2.0], b_abs=b)
    ref = ModelResponse(alpha=(2.0,), beta=2.0, amplitudes=(1.0,), omegas=(1.3,), phases=(0.0,))
    return plant, law, ref


def _first_order(stages: int, delay: int):
    form = ModelForm(order=1, p_names=("a",), phi=lambda x: np.array([-x[0]]), d_name=None)
    plant = ToyPlant(0.8, 1.0, names=("a",), theta=[0.8], dt=0.002, stages=stages, delay_steps=delay)
    return plant, FirstOrderAdaptiveLaw(form, k=3.0, gamma=[0.5]), Cosine(amplitude=0.7, omega=2.0)


def _run(make, stages: int, delay: int, native: bool):
    plant, law, ref = make(stages, delay)
    plant.set_state([0.3])
    plant.disturbance = lambda t: 0.2 * np.sin(3.0 * t)
    plant.force_offset = 0.1
    traj = loop.run(plant, law, ref, duration=4.0, theta_hat0=np.zeros(len(law.names)), noise_std=[0.01],
                    rng=np.random.default_rng(7), native=native)
    return traj, plant


@pytest.mark.parametrize("stages,delay", [(4, 0), (4, 5), (1, 0)], ids=["rk4", "rk4_input_delay", "euler"])
@pytest.mark.parametrize("make", [_mrac, _first_order], ids=["mrac", "first_order"])
def test_a_kind_declared_in_a_test_runs_compiled_bit_for_bit(make, stages, delay):
    plant, law, _ = make(stages, delay)
    assert native_chunk.supported(plant, law)
    compiled, p_c = _run(make, stages, delay, native=True)
    python, p_p = _run(make, stages, delay, native=False)
    assert compiled.meta["native"] is True and python.meta["native"] is False
    assert len(compiled.t) == 2000 if make is _first_order else len(compiled.t) == 800
    for field in FIELDS:
        assert np.array_equal(getattr(compiled, field), getattr(python, field), equal_nan=True), field
    assert (compiled.status, compiled.reason) == (python.status, python.reason)
    assert np.array_equal(p_c.x, p_p.x) and p_c.time == p_p.time and p_c._k == p_p._k  # the plant left alike
    assert np.abs(np.diff(compiled.theta_hat, axis=0)).max() > 0  # it adapts


def test_the_toy_kinds_variants_are_compiled_apart():
    """The toy kind's chunk is its own compiled function (its cache key names its kernel and law)."""
    plant, law, _ = _mrac(4, 0)
    fn = native_chunk.compiled(plant.kernel, {}, native_chunk.law_of(law, plant))
    assert fn.py_func.__qualname__.startswith("chunk_factory_")

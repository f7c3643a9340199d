"""The flight laws' per-axis position gains (issue 52 item 2): RotorPy's by default (kp_pos = (6.5, 6.5, 15),
kd_pos = (4, 4, 9) times the 0.03 kg Crazyflie: z stiffer than x and y), one number still meaning every axis (an
older scenario's law.kx = 0.195 loads and means 0.195 on x, y and z), three numbers per axis, and bad input refused
in one line naming the key."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.errors import ScenarioError
from adaptive_mj.laws import flight_kernel as fk
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build

LEMNISCATE = sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml"
MASS = 0.03  # [kg] RotorPy's Crazyflie, which its gains are per unit mass of
KP_POS, KD_POS = np.array([6.5, 6.5, 15.0]), np.array([4.0, 4.0, 9.0])  # RotorPy's SE3Control


def _law(*overrides):
    return build(sc.load(LEMNISCATE, overrides=list(overrides))).law


def _axes(law, at):
    return law.P[at:at + 3]


@pytest.mark.parametrize("kind", ["geometric", "l1_geometric"])
def test_the_default_gains_are_rotorpy_s_per_axis(kind):
    law = _law(f"law.kind='{kind}'")
    np.testing.assert_allclose(_axes(law, fk.P_KX), MASS * KP_POS, rtol=1e-12)
    np.testing.assert_allclose(_axes(law, fk.P_KV), MASS * KD_POS, rtol=1e-12)
    np.testing.assert_allclose(_axes(law, fk.P_C), KP_POS / KD_POS, rtol=1e-12)


def test_the_adaptive_law_s_default_matches_the_geometric_law_s_per_axis():
    """k s = k e_v + k λ e_x: k = k_v and k λ = k_x on every axis."""
    law = _law()
    assert law.adapt
    np.testing.assert_allclose(_axes(law, fk.P_K), MASS * KD_POS, rtol=1e-12)
    np.testing.assert_allclose(_axes(law, fk.P_K) * _axes(law, fk.P_C), MASS * KP_POS, rtol=1e-12)


def test_one_number_means_every_axis_and_three_numbers_one_each():
    old = _law("law.kind='geometric'", "law.kx=0.195", "law.kv=0.12")
    np.testing.assert_array_equal(_axes(old, fk.P_KX), [0.195] * 3)
    np.testing.assert_array_equal(_axes(old, fk.P_KV), [0.12] * 3)
    np.testing.assert_array_equal(_axes(old, fk.P_C), [0.195 / 0.12] * 3)
    new = _law("law.kind='geometric'", "law.kx=[0.1, 0.2, 0.3]")
    np.testing.assert_array_equal(_axes(new, fk.P_KX), [0.1, 0.2, 0.3])
    adaptive = _law("law.lambda=2.0", "law.k=[0.1, 0.1, 0.2]")
    np.testing.assert_array_equal(_axes(adaptive, fk.P_C), [2.0] * 3)
    np.testing.assert_array_equal(_axes(adaptive, fk.P_K), [0.1, 0.1, 0.2])


@pytest.mark.parametrize("override, words", [
    ("law.kx=[0.1, 0.2]", "law.kx must be a number or 3 numbers (x, y, z)"),
    ("law.kx=[0.1, -0.2, 0.3]", "law.kx must be > 0 on every axis"),
    ("law.kv=0.0", "law.kv must be > 0 on every axis"),
    ("law.kx='stiff'", "law.kx must be a number"),
])
def test_bad_gains_are_refused_naming_the_key(override, words):
    with pytest.raises(ScenarioError) as exc:
        _law("law.kind='geometric'", override)
    assert words in str(exc.value) and "\n" not in str(exc.value), str(exc.value)

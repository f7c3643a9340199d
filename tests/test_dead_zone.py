"""The dead-zone's boundary, through every law that has one: adaptation is on at
|signal| == width and off at the next float below it (common.dead_zone_open, the one
comparison all the laws share). Each case sets the width to the signal the law itself
computes, so the equality is exact in floating point."""
from __future__ import annotations

import math
import types

import numpy as np
import pytest

from adaptive_mj.laws import DeadZone, DeadZoneOn, FirstOrderAdaptiveLaw, SlidingAdaptiveLaw
from adaptive_mj.laws.common import dead_zone_open
from adaptive_mj.laws.slotine_li import SlotineLiLaw
from adaptive_mj.plants import heave
from adaptive_mj.plants.twin import lecture_first_order_form


def _just_above(width: float) -> float:
    """The next float above width: the signal |s| == width is then the next float below it."""
    return float(np.nextafter(width, math.inf))


def _open_at_closed_below(make, width, on, plain, *args):
    """Call the law made by make(width, on) at exactly |signal| == width and one float below it:
    at the width it adapts as the law without a dead-zone (plain, whose rate is all nonzero),
    below it every rate is exactly 0. Returns both steps."""
    assert np.all(plain.theta_hat_dot != 0)
    at = make(width, on)(*args)
    np.testing.assert_array_equal(at.theta_hat_dot, plain.theta_hat_dot)
    below = make(_just_above(width), on)(*args)
    np.testing.assert_array_equal(below.theta_hat_dot, np.zeros_like(plain.theta_hat_dot))
    return at, below


def test_dead_zone_open_boundary():
    for w in (0.05, 0.75, 1e-300, 5e-324, 1e300):
        assert dead_zone_open(w, w) and dead_zone_open(-w, w)
        below = float(np.nextafter(w, 0.0))
        assert not dead_zone_open(below, w) and not dead_zone_open(-below, w)
    assert dead_zone_open(0.0, 0.0) and dead_zone_open(-0.0, 0.0)  # width 0: always adapting
    assert not dead_zone_open(math.nan, 0.0)
    below = float(np.nextafter(0.75, 0.0))
    for on in DeadZoneOn:  # DeadZone.adapting is the same function on its chosen signal
        zone = DeadZone(0.75, on=on)
        assert zone.adapting(0.75, 0.75) and zone.adapting(-0.75, -0.75)
        assert not zone.adapting(below, below) and not zone.adapting(-below, -below)


def test_dead_zone_open_compiles_with_numba_and_agrees():
    numba = pytest.importorskip("numba")
    compiled = numba.njit(dead_zone_open)
    for signal, width in ((0.75, 0.75), (-0.75, 0.75), (float(np.nextafter(0.75, 0.0)), 0.75), (0.0, 0.0),
                          (math.nan, 0.0), (-3.0, 2.0)):
        assert compiled(signal, width) is dead_zone_open(signal, width)


# ----------------------------------------------------------------- the 1-DOF sliding law
FORM = heave.heave_form(9.81)
GAMMA = np.array([0.0025, 0.002, 0.5])
TH = np.array([37.0, 60.0, 1.0])


def _sliding(width=None, on=DeadZoneOn.S):
    dz = None if width is None else DeadZone(width, on=on)
    return SlidingAdaptiveLaw(FORM, lam=4.0, k=200.0, gamma=GAMMA, dead_zone=dz)


# ỹ = 0.125, ỹ' = 0.25, s = ỹ' + 4 ỹ = 0.75 (exact), and the same mirrored
CASES = [(np.array([-0.125, -0.25]), np.zeros(3)), (np.array([0.125, 0.25]), np.zeros(3))]


@pytest.mark.parametrize("x, ref", CASES)
def test_sliding_law_dead_zone_on_s_boundary(x, ref):
    plain = _sliding()(0.0, x, ref, TH)
    s_abs = abs(plain.s)
    assert s_abs == 0.75 and abs(ref[0] - x[0]) != s_abs  # the test is on s, not ỹ
    at, below = _open_at_closed_below(_sliding, s_abs, DeadZoneOn.S, plain, 0.0, x, ref, TH)
    assert at.u == below.u == plain.u  # the control is untouched


@pytest.mark.parametrize("x, ref", CASES)
def test_sliding_law_dead_zone_on_tracking_error_boundary(x, ref):
    plain = _sliding()(0.0, x, ref, TH)
    y_abs = abs(ref[0] - x[0])  # ỹ as sliding_terms computes it
    assert y_abs == 0.125 and abs(plain.s) > y_abs
    _open_at_closed_below(_sliding, y_abs, DeadZoneOn.TRACKING_ERROR, plain, 0.0, x, ref, TH)


# ----------------------------------------------------------------- Slotine–Li
Y = np.random.default_rng(5).normal(size=(2, 4))
NAMES = ("a", "b", "c", "d")
# q̃ = ±[0.75, 1.0] (‖q̃‖ = 1.25), q̃' = 0, Λ = 2: s = ±[1.5, 2.0], ‖s‖ = 2.5 (all exact)
ARM_CASES = [(np.zeros((2, 2)), np.array([[0.75, 1.0], [0.0, 0.0], [0.0, 0.0]])),
             (np.zeros((2, 2)), np.array([[-0.75, -1.0], [0.0, 0.0], [0.0, 0.0]]))]


def _slotine(width=None, on=DeadZoneOn.S):
    dz = None if width is None else DeadZone(width, on=on)
    return SlotineLiLaw(lambda v, w, a: (Y, np.zeros(2)), NAMES, 2, lam=2.0, kd=7.0, gamma=[1.0, 2.0, 3.0, 4.0],
                        dead_zone=dz)


def _s_norm(s) -> float:
    """‖s‖ as slotine_li_output computes it (the same sum, in the same order)."""
    acc = 0.0
    for v in s:
        acc += v * v
    return math.sqrt(acc)


@pytest.mark.parametrize("x, ref", ARM_CASES)
def test_slotine_li_dead_zone_on_s_norm_boundary(x, ref):
    th = np.array([0.3, -0.2, 0.1, 0.5])
    plain = _slotine()(0.0, x, ref, th)
    s_norm = _s_norm(plain.s)
    assert s_norm == 2.5
    at, below = _open_at_closed_below(_slotine, s_norm, DeadZoneOn.S, plain, 0.0, x, ref, th)
    np.testing.assert_array_equal(at.u, below.u)


@pytest.mark.parametrize("x, ref", ARM_CASES)
def test_slotine_li_dead_zone_on_tracking_error_boundary(x, ref):
    th = np.array([0.3, -0.2, 0.1, 0.5])
    plain = _slotine()(0.0, x, ref, th)
    e_norm = float(np.linalg.norm(ref[0] - x[0]))  # ‖q̃‖ as the law computes it
    assert e_norm == 1.25 and _s_norm(plain.s) > e_norm
    _open_at_closed_below(_slotine, e_norm, DeadZoneOn.TRACKING_ERROR, plain, 0.0, x, ref, th)


# ----------------------------------------------------------------- first-order law
@pytest.mark.parametrize("on", list(DeadZoneOn))
@pytest.mark.parametrize("x, ref", [(np.array([1.0]), np.array([1.25, 0.0])),
                                    (np.array([1.0]), np.array([0.75, 0.0]))])
def test_first_order_law_dead_zone_boundary(on, x, ref):
    form = lecture_first_order_form()
    p_hat = np.array([0.4, -0.3])

    def law(width=None):
        return FirstOrderAdaptiveLaw(form, k=2.0, gamma=0.5, dead_zone=None if width is None else DeadZone(width, on))

    plain = law()(0.0, x, ref, p_hat)
    x_abs = abs(plain.s)  # s = x̃
    assert x_abs == 0.25 and np.all(plain.theta_hat_dot != 0)
    np.testing.assert_array_equal(law(x_abs)(0.0, x, ref, p_hat).theta_hat_dot, plain.theta_hat_dot)
    np.testing.assert_array_equal(law(_just_above(x_abs))(0.0, x, ref, p_hat).theta_hat_dot, np.zeros(2))


# ----------------------------------------------------------------- the compiled laws
def _compiled(fn, numba):
    """fn compiled as the compiled callbacks (sim.native_mujoco, sim.native_chunk) compile the laws: every plain
    function it calls through its module globals (recursively) replaced by its numba version."""
    replace = {name: _compiled(fn.__globals__[name], numba) for name in fn.__code__.co_names
               if isinstance(fn.__globals__.get(name), types.FunctionType)}
    return numba.njit(types.FunctionType(fn.__code__, {**fn.__globals__, **replace}, fn.__name__))


def test_compiled_sliding_law_has_the_same_boundary():
    numba = pytest.importorskip("numba")
    from adaptive_mj.laws.sliding import SlidingArrays, SlidingGains, sliding_law_values

    law = _compiled(sliding_law_values, numba)
    x, ref = CASES[0]
    inf3 = np.full(3, math.inf)
    arrays = SlidingArrays(coeffs=_sliding()._coeffs, gamma=GAMMA, theta0=TH, lower=-inf3, upper=inf3)

    def rate(width, on_s):
        out = np.empty(3)
        gains = SlidingGains(k=200.0, dz_width=width, K=0.0, boundary_layer=1.0, sigma=0.0, e_mod=0.0,
                             sat_lo=-math.inf, sat_hi=math.inf, adapt=True, dz_on_s=on_s, freeze=False)
        law(x, ref, TH, gains.record()[0], arrays, FORM.phi(x), FORM.f(x), FORM.h(x), out)  # the compiled record
        return out

    plain = _sliding()(0.0, x, ref, TH).theta_hat_dot
    for width, on_s in ((0.75, True), (0.125, False)):
        np.testing.assert_array_equal(rate(width, on_s), plain)
        np.testing.assert_array_equal(rate(_just_above(width), on_s), np.zeros(3))


def test_compiled_slotine_li_output_has_the_same_boundary():
    numba = pytest.importorskip("numba")
    from adaptive_mj.laws.slotine_li import SlotineLiArrays, SlotineLiGains, slotine_li_output

    out_fn = _compiled(slotine_li_output, numba)
    s = np.array([1.5, 2.0])
    kd, gamma, th = np.full(2, 7.0), np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.3, -0.2, 0.1, 0.5])
    inf4 = np.full(4, math.inf)

    def rate(width, on_s):
        u, r = np.empty(2), np.empty(4)
        gains = SlotineLiGains(mode=0, adapt=True, dz_width=width, dz_on_s=on_s, sigma=0.0, e_mod=0.0, freeze=False)
        arrays = SlotineLiArrays(kd=kd, gamma=gamma, theta0=th, lower=-inf4, upper=inf4, sat_lo=-inf4[:2],
                                 sat_hi=inf4[:2])
        out_fn(Y, np.zeros(2), th, s, 1.25, gains.record()[0], arrays, u, r)  # the compiled path reads a record
        return r

    plain = _slotine()(0.0, *ARM_CASES[0], th).theta_hat_dot
    for width, on_s in ((2.5, True), (1.25, False)):
        np.testing.assert_array_equal(rate(width, on_s), plain)
        np.testing.assert_array_equal(rate(_just_above(width), on_s), np.zeros(4))

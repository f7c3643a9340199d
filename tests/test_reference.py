"""References: closed-form derivatives agree with finite differences; shapes;
the lecture's cosine (with its ddy_d slip fixed); the smooth step's ends."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.reference import Constant, Cosine, Sine, SmoothStep, SumOfSines

ORDER = 4
REFERENCES = {
    "constant": Constant(0.7),
    "cosine": Cosine(),
    "cosine_params": Cosine(amplitude=0.4, omega=2.3, phase=0.3, offset=-0.2),
    "sine": Sine(amplitude=0.8, omega=1.5),
    "sine_params": Sine(amplitude=1.3, omega=0.6, phase=-1.1, offset=0.5),
    "sum_of_sines": SumOfSines(),
    "sum_of_sines_params": SumOfSines(amplitudes=(0.2, 0.5), omegas=(3.0, 0.5), phases=(0.4, 1.0), offset=2.0),
    "smooth_step": SmoothStep(),
    "smooth_step_down": SmoothStep(start=2.0, end=-1.0, t0=0.5, rise_time=1.5),
}
# sample times that avoid the smooth step's corners (t0, t0 + rise_time), where
# its 5th derivative jumps and the central difference of the 4th loses accuracy
T = np.linspace(0.05, 6.0, 41)
H = 1e-5  # central-difference step [s]


@pytest.mark.parametrize("name", REFERENCES)
def test_derivatives_match_central_differences(name):
    ref = REFERENCES[name]
    plus, minus, mid = ref(T + H, ORDER), ref(T - H, ORDER), ref(T, ORDER)
    for k in range(1, ORDER + 1):
        fd = (plus[k - 1] - minus[k - 1]) / (2 * H)
        # truncation ~ H² |y^(k+2)| / 6, round-off ~ eps |y^(k-1)| / H
        scale = 1.0 + np.max(np.abs(mid[k - 1 : k + 1]))
        np.testing.assert_allclose(fd, mid[k], atol=1e-7 * scale, rtol=0,
                                   err_msg=f"{name}: derivative {k}")


@pytest.mark.parametrize("name", REFERENCES)
def test_scalar_and_array_times_give_consistent_shapes(name):
    ref = REFERENCES[name]
    for order in (0, 1, 2, 4):
        assert ref(1.3, order).shape == (order + 1,)
        arr = ref(T, order)
        assert arr.shape == (order + 1, len(T))
        for i in (0, 7, len(T) - 1):
            np.testing.assert_allclose(arr[:, i], ref(T[i], order), rtol=1e-15, atol=1e-15)
        grid = T[:40].reshape(5, 8)
        assert ref(grid, order).shape == (order + 1, 5, 8)
        np.testing.assert_array_equal(ref(grid, order).reshape(order + 1, -1), ref(T[:40], order))
    np.testing.assert_array_equal(ref(T, 2)[:2], ref(T, 1))  # lower orders are a prefix


def test_cosine_is_the_lecture_reference_with_the_slip_fixed():
    t = np.linspace(0, 30, 301)
    y_d, dy_d, ddy_d = Cosine()(t, 2)
    np.testing.assert_allclose(y_d, np.cos(t), atol=1e-15)
    np.testing.assert_allclose(dy_d, -np.sin(t), atol=1e-15)
    np.testing.assert_allclose(ddy_d, -np.cos(t), atol=1e-15)  # the lecture wrote +cos t
    np.testing.assert_allclose(Cosine()(t, 4)[3:], [np.sin(t), np.cos(t)], atol=1e-15)


def test_sine_and_sum_of_sines_closed_forms():
    t = np.linspace(0, 10, 101)
    y = Sine(amplitude=0.8, omega=1.5)(t, 2)
    np.testing.assert_allclose(y, [0.8 * np.sin(1.5 * t), 1.2 * np.cos(1.5 * t), -1.8 * np.sin(1.5 * t)],
                               atol=1e-14)
    s = SumOfSines()(t, 1)
    expected = sum(a * np.sin(w * t) for a, w in zip((0.5, 0.3, 0.2), (0.7, 1.9, 3.1), strict=True))
    np.testing.assert_allclose(s[0], expected, atol=1e-14)
    with pytest.raises(ValueError, match="same length"):
        SumOfSines(amplitudes=(1.0,), omegas=(1.0, 2.0), phases=(0.0,))


def test_constant_is_a_setpoint():
    out = Constant(2.5)(np.linspace(0, 3, 7), 3)
    np.testing.assert_array_equal(out[0], 2.5)
    np.testing.assert_array_equal(out[1:], 0.0)


@pytest.mark.parametrize("step", [SmoothStep(), SmoothStep(start=2.0, end=-1.0, t0=0.5, rise_time=1.5)],
                         ids=["default", "down"])
def test_smooth_step_ends(step):
    t_start, t_end = step.t0, step.t0 + step.rise_time
    before = np.array([t_start - 1.0, t_start - 1e-9, t_start])
    after = np.array([t_end, t_end + 1e-9, t_end + 5.0])
    np.testing.assert_allclose(step(before, ORDER)[0], step.start, rtol=0, atol=1e-12)
    np.testing.assert_allclose(step(after, ORDER)[0], step.end, rtol=0, atol=1e-12)
    # derivatives 1..4 vanish at both ends (exactly there, and continuously from inside)
    np.testing.assert_array_equal(step(np.array([t_start, t_end]), ORDER)[1:], 0.0)
    span = abs(step.end - step.start)
    for delta in (1e-2, 1e-3):
        inside = step(np.array([t_start + delta, t_end - delta]), ORDER)
        for k in range(1, ORDER + 1):
            # S'(x) = 630 x^4 (1-x)^4, so near an end y^(k) <= 630*4!/(5-k)! * span *
            # (delta/T)^(5-k) / T^k -> 0 (bounded by 2e4 * ...; 1e-11 for round-off)
            bound = 2e4 * span * (delta / step.rise_time) ** (5 - k) / step.rise_time**k
            assert np.all(np.abs(inside[k]) <= bound + 1e-11 * span), (k, delta, inside[k], bound)
        np.testing.assert_allclose(inside[0], [step.start, step.end], atol=1e-11 + 1e3 * delta**5)
    # monotone blend, strictly inside the two levels in the middle
    t = np.linspace(t_start, t_end, 201)
    y, dy = step(t, 1)
    assert np.all(np.sign(step.end - step.start) * dy >= 0)
    lo, hi = sorted((step.start, step.end))
    assert lo < y[100] < hi
    assert y[100] == pytest.approx(0.5 * (step.start + step.end), rel=1e-12)  # symmetric blend

"""The lecture's laws as plain array code: formulas, dead-zone, baselines, gain checks.

Every expected value below is written out by hand from lecture 7 (binomial
expansion of (d/dt + lambda)^(n-1) for n = 1, 2, 3), never taken from the
module under test.
"""
from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from adaptive_mj.form import ModelForm
from adaptive_mj.laws import (
    DeadZone,
    DeadZoneOn,
    FirstOrderAdaptiveLaw,
    FixedNominalLaw,
    RobustSlidingLaw,
    SlidingAdaptiveLaw,
)
from adaptive_mj.plants import twin
from adaptive_mj.reference import SumOfSines


# ----------------------------------------------------------------- import hygiene
def test_law_code_imports_no_mujoco():
    code = textwrap.dedent(
        """
        import sys
        import adaptive_mj.laws, adaptive_mj.reference, adaptive_mj.form
        import adaptive_mj.sim.loop, adaptive_mj.trajectory
        bad = sorted(m for m in sys.modules if m == 'mujoco' or m.startswith('mujoco.')
                     or m.startswith('dm_control'))
        assert not bad, bad
        print('ok')
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "ok"


# ----------------------------------------------------------------- hand-written forms
def _form(order: int, *, with_d: bool = True) -> ModelForm:
    """A form with non-trivial known f and h, and a 3-entry regressor."""

    def phi(x):
        return np.array([-x[-1] * abs(x[-1]), -np.sin(x[0]), -1.0])

    return ModelForm(
        order=order,
        p_names=("b", "g", "c"),
        phi=phi,
        f=lambda x: 0.3 * x[0] - 0.1 * np.cos(x[-1]),
        h=lambda x: 1.7 + 0.5 * np.cos(x[0]),
        d_name="d" if with_d else None,
    )


def _expected_s_and_sr(order, lam, x, ref):
    """The binomial expansion written out for n = 1, 2, 3."""
    e = ref[:order] - x  # [ỹ, ỹ', ỹ'']
    if order == 1:
        return e[0], ref[1]
    if order == 2:
        return e[1] + lam * e[0], ref[2] + lam * e[1]
    if order == 3:
        return e[2] + 2 * lam * e[1] + lam**2 * e[0], ref[3] + 2 * lam * e[2] + lam**2 * e[1]
    raise AssertionError(order)


def _samples(order, n=25, seed=0):
    rng = np.random.default_rng(seed + order)
    for _ in range(n):
        x = rng.normal(0, 1.5, order)
        ref = rng.normal(0, 1.5, order + 1)
        theta_hat = rng.normal(0, 2, 4)
        theta_hat[0] = abs(theta_hat[0]) + 0.5
        yield rng.uniform(0, 10), x, ref, theta_hat


@pytest.mark.parametrize("order", [1, 2, 3])
def test_sliding_law_matches_the_lecture_formulas(order):
    form = _form(order)
    lam, k = 2.7, 4.2
    gamma = np.array([0.8, 0.3, 2.0, 5.0])  # one value per entry of theta = (d, b, g, c)
    law = SlidingAdaptiveLaw(form, lam=lam, k=k, gamma=gamma)
    assert law.order == order and law.names == ("d", "b", "g", "c")
    for t, x, ref, th in _samples(order):
        s, s_r = _expected_s_and_sr(order, lam, x, ref)
        out = law(t, x, ref, th)
        assert out.s == pytest.approx(s, rel=1e-13, abs=1e-13)
        assert out.s_r_dot == pytest.approx(s_r, rel=1e-13, abs=1e-13)
        d_hat, p_hat = th[0], th[1:]
        phi = form.phi(x)
        u = (d_hat * s_r - form.f(x) - phi @ p_hat + k * s) / form.h(x)
        assert out.u == pytest.approx(u, rel=1e-12, abs=1e-12)
        rate = np.concatenate([[s_r * s / gamma[0]], -phi * s / gamma[1:]])
        np.testing.assert_allclose(out.theta_hat_dot, rate, rtol=1e-12, atol=1e-14)


def test_scalar_gamma_is_the_lecture_gamma():
    form = _form(2)
    scalar = SlidingAdaptiveLaw(form, lam=10, k=1, gamma=0.5)
    vector = SlidingAdaptiveLaw(form, lam=10, k=1, gamma=[0.5] * 4)
    for t, x, ref, th in _samples(2, n=5):
        np.testing.assert_array_equal(scalar(t, x, ref, th).theta_hat_dot,
                                      vector(t, x, ref, th).theta_hat_dot)


def test_lecture_heave_controller_code():
    """The lecture's second-order controller code (with ddy_d as given) line by line."""
    from adaptive_mj.plants.heave import heave_form

    g, L, k, gamma = 9.81, 10.0, 1.0, 0.5
    law = SlidingAdaptiveLaw(heave_form(g), lam=L, k=k, gamma=gamma)
    rng = np.random.default_rng(7)
    for _ in range(10):
        y, dy = rng.normal(size=2)
        y_d, dy_d, ddy_d = rng.normal(size=3)
        p_hat, d_hat = rng.normal(size=2), rng.uniform(0.5, 3)
        phi = np.array([-dy * abs(dy), -g])
        y_e, dy_e = y_d - y, dy_d - dy
        s = dy_e + L * y_e
        ds_r = ddy_d + L * dy_e
        u = (d_hat * ds_r - 0 - phi @ p_hat + k * s) / 1
        dp_hat = -phi.T * s / gamma
        dd_hat = ds_r * s / gamma
        out = law(0.0, np.array([y, dy]), np.array([y_d, dy_d, ddy_d]), np.r_[d_hat, p_hat])
        assert out.u == pytest.approx(u, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(out.theta_hat_dot, np.r_[dd_hat, dp_hat], rtol=1e-12, atol=1e-14)


def test_lyapunov_function_values():
    form = _form(2)
    gamma = np.array([0.8, 0.3, 2.0, 5.0])
    law = SlidingAdaptiveLaw(form, lam=1.0, k=1.0, gamma=gamma)
    s = np.array([0.5, -2.0])
    theta = np.array([[2.0, 1.0, -1.0, 0.5]] * 2)
    theta_hat = theta + np.array([[0.1, -0.2, 0.3, 0.0], [0.0, 0.0, 0.0, 1.0]])
    expected = [0.5 * 2.0 * 0.25 + 0.5 * (0.8 * 0.01 + 0.3 * 0.04 + 2.0 * 0.09),
                0.5 * 2.0 * 4.0 + 0.5 * 5.0 * 1.0]
    np.testing.assert_allclose(law.lyapunov(s, theta_hat, theta), expected, rtol=1e-14)
    fixed = FixedNominalLaw(form, lam=1.0, k=1.0)
    np.testing.assert_allclose(fixed.lyapunov(s, theta_hat, theta), [0.25, 4.0], rtol=1e-14)


# ----------------------------------------------------------------- dead-zone
def test_dead_zone_on_s_is_the_default_and_uses_s():
    eps, lam = 0.05, 4.0
    form = _form(2)
    assert DeadZone(eps).on is DeadZoneOn.S
    plain = SlidingAdaptiveLaw(form, lam=lam, k=2, gamma=1.0)
    dz = SlidingAdaptiveLaw(form, lam=lam, k=2, gamma=1.0, dead_zone=DeadZone(eps))
    th = np.array([1.0, 0.5, -0.2, 0.3])
    ref = np.array([0.0, 0.0, 0.0])
    # large ỹ (0.1 > eps) but |s| = 0.001 < eps: adaptation off
    x_small_s = np.array([-0.1, lam * 0.1 - 0.001])  # ỹ = 0.1, ỹ' = -0.399 -> s = 0.001
    out = dz(0.0, x_small_s, ref, th)
    assert abs(out.s) < eps and abs(ref[0] - x_small_s[0]) >= eps
    np.testing.assert_array_equal(out.theta_hat_dot, np.zeros(4))
    assert out.u == plain(0.0, x_small_s, ref, th).u  # the control is unaffected
    # small ỹ (0.01 < eps) but |s| >= eps: adaptation on, identical to the plain law
    x_big_s = np.array([-0.01, -0.3])
    out = dz(0.0, x_big_s, ref, th)
    assert abs(out.s) >= eps and abs(x_big_s[0]) < eps
    np.testing.assert_array_equal(out.theta_hat_dot, plain(0.0, x_big_s, ref, th).theta_hat_dot)
    assert np.any(out.theta_hat_dot != 0)


def test_dead_zone_on_tracking_error_uses_y_tilde():
    eps, lam = 0.05, 4.0
    form = _form(2)
    plain = SlidingAdaptiveLaw(form, lam=lam, k=2, gamma=1.0)
    dz = SlidingAdaptiveLaw(form, lam=lam, k=2, gamma=1.0,
                            dead_zone=DeadZone(eps, on=DeadZoneOn.TRACKING_ERROR))
    th = np.array([1.0, 0.5, -0.2, 0.3])
    ref = np.zeros(3)
    x_small_s = np.array([-0.1, lam * 0.1 - 0.001])  # |ỹ| = 0.1 >= eps, s = 0.001: adapting
    out = dz(0.0, x_small_s, ref, th)
    assert abs(out.s) < eps
    np.testing.assert_array_equal(out.theta_hat_dot, plain(0.0, x_small_s, ref, th).theta_hat_dot)
    assert np.any(out.theta_hat_dot != 0)
    x_big_s = np.array([-0.01, -0.3])  # |ỹ| = 0.01 < eps, |s| large: not adapting
    out = dz(0.0, x_big_s, ref, th)
    assert abs(out.s) >= eps
    np.testing.assert_array_equal(out.theta_hat_dot, np.zeros(4))


def test_dead_zone_boundary_and_validation():
    eps = 0.05
    for on in DeadZoneOn:
        zone = DeadZone(eps, on=on)
        assert zone.adapting(eps, eps)  # |signal| >= eps adapts
        assert zone.adapting(-eps, -eps)
        assert not zone.adapting(eps * (1 - 1e-12), eps * (1 - 1e-12))
        assert not zone.adapting(0.0, 0.0)
    assert DeadZone(0.0).adapting(0.0, 0.0)  # zero width: always adapting
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="dead-zone width"):
            DeadZone(bad)


# ----------------------------------------------------------------- baselines
def test_fixed_nominal_law_does_not_adapt():
    form = _form(2)
    fixed = FixedNominalLaw(form, lam=3.0, k=2.0)
    adaptive = SlidingAdaptiveLaw(form, lam=3.0, k=2.0, gamma=1.0)
    for t, x, ref, th in _samples(2, n=10):
        out = fixed(t, x, ref, th)
        np.testing.assert_array_equal(out.theta_hat_dot, np.zeros(4))
        ref_out = adaptive(t, x, ref, th)
        assert (out.u, out.s, out.s_r_dot) == (ref_out.u, ref_out.s, ref_out.s_r_dot)


def test_robust_sliding_law_adds_saturated_switching_term():
    form = _form(2)
    K, phi_bl = 3.0, 0.2
    robust = RobustSlidingLaw(form, lam=3.0, k=2.0, K=K, boundary_layer=phi_bl)
    fixed = FixedNominalLaw(form, lam=3.0, k=2.0)
    n_inside = n_outside = 0
    for t, x, ref, th in _samples(2, n=60, seed=11):
        x = x * 0.05
        ref = ref * 0.05
        base = fixed(t, x, ref, th)
        out = robust(t, x, ref, th)
        sat = np.clip(base.s / phi_bl, -1.0, 1.0)
        assert out.u == pytest.approx(base.u + K * sat / form.h(x), rel=1e-12, abs=1e-12)
        np.testing.assert_array_equal(out.theta_hat_dot, np.zeros(4))
        inside = abs(base.s) < phi_bl
        n_inside += inside
        n_outside += not inside
    assert n_inside > 3 and n_outside > 3  # both branches of sat exercised
    with pytest.raises(ValueError, match="K must"):
        RobustSlidingLaw(form, lam=1, k=1, K=-1, boundary_layer=0.1)
    with pytest.raises(ValueError, match="boundary_layer"):
        RobustSlidingLaw(form, lam=1, k=1, K=1, boundary_layer=0.0)


# ----------------------------------------------------------------- first-order law
def test_first_order_law_is_the_lecture_code():
    """The lecture's `control(x, desired, p_hat)` for x' = sin x - a x + b x² + u."""
    form = twin.lecture_first_order_form()
    gamma, k = 0.5, 2.0
    law = FirstOrderAdaptiveLaw(form, k=k, gamma=gamma)
    assert law.names == ("a", "b") and law.order == 1
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = rng.normal(0, 2)
        x_d, dx_d = rng.normal(size=2)
        p_hat = rng.normal(size=2)
        phi = np.array([-x, x**2])
        x_e = x_d - x
        u = dx_d - np.sin(x) - phi @ p_hat + k * x_e
        dp_hat = -phi.T * x_e / gamma
        out = law(0.0, np.array([x]), np.array([x_d, dx_d]), p_hat)
        assert out.u == pytest.approx(u, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(out.theta_hat_dot, dp_hat, rtol=1e-12, atol=1e-14)
        assert out.s == x_e


def test_first_order_law_equals_order_one_sliding_law_with_known_d():
    """With d̂ = d = 1 the n = 1 sliding law gives the first-order law's u, p̂' and V."""
    fo_form = _form(1, with_d=False)
    sl_form = _form(1, with_d=True)
    gamma_p = np.array([0.3, 2.0, 5.0])
    fo = FirstOrderAdaptiveLaw(fo_form, k=1.5, gamma=gamma_p)
    sl = SlidingAdaptiveLaw(sl_form, lam=123.0, k=1.5, gamma=np.r_[0.7, gamma_p])  # lam unused at n=1
    for t, x, ref, th in _samples(1, n=20):
        p_hat = th[1:]
        a = fo(t, x, ref, p_hat)
        b = sl(t, x, ref, np.r_[1.0, p_hat])
        assert a.u == pytest.approx(b.u, rel=1e-13, abs=1e-13)
        np.testing.assert_allclose(a.theta_hat_dot, b.theta_hat_dot[1:], rtol=1e-13, atol=1e-15)
        assert a.s == pytest.approx(b.s, abs=1e-15)
        p_true = p_hat + 0.3
        assert fo.lyapunov(a.s, p_hat, p_true) == pytest.approx(
            sl.lyapunov(b.s, np.r_[1.0, p_hat], np.r_[1.0, p_true]), rel=1e-13)


def test_first_order_law_dead_zone_on_tracking_error():
    form = twin.lecture_first_order_form()
    law = FirstOrderAdaptiveLaw(form, k=2, gamma=0.5, dead_zone=DeadZone(0.05))
    out = law(0.0, np.array([1.0]), np.array([1.04, 0.0]), np.zeros(2))
    np.testing.assert_array_equal(out.theta_hat_dot, np.zeros(2))
    out = law(0.0, np.array([1.0]), np.array([1.06, 0.0]), np.zeros(2))
    assert np.all(out.theta_hat_dot != 0)


# ----------------------------------------------------------------- gain checks
@pytest.mark.parametrize("cls", [SlidingAdaptiveLaw, FixedNominalLaw])
@pytest.mark.parametrize("lam", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_lambda_raises_naming_lambda(cls, lam):
    kwargs = dict(gamma=1.0) if cls is SlidingAdaptiveLaw else {}
    with pytest.raises(ValueError, match=r"lambda must be finite and > 0"):
        cls(_form(2), lam=lam, k=1.0, **kwargs)


@pytest.mark.parametrize("gamma", [0.0, -0.5, [1.0, 1.0, 0.0, 1.0], [1.0, -2.0, 1.0, 1.0], float("nan")])
def test_bad_gamma_raises_naming_gamma(gamma):
    with pytest.raises(ValueError, match=r"gamma must be finite and > 0"):
        SlidingAdaptiveLaw(_form(2), lam=1.0, k=1.0, gamma=gamma)
    fo_gamma = gamma[1:] if isinstance(gamma, list) else gamma
    with pytest.raises(ValueError, match=r"gamma must be finite and > 0"):
        FirstOrderAdaptiveLaw(_form(1, with_d=False), k=1.0, gamma=fo_gamma)


def test_bad_gamma_shape_and_k_and_form_raise():
    with pytest.raises(ValueError):
        SlidingAdaptiveLaw(_form(2), lam=1.0, k=1.0, gamma=[1.0, 1.0])  # 2 values for 4 parameters
    with pytest.raises(ValueError, match=r"k must be finite and >= 0"):
        SlidingAdaptiveLaw(_form(2), lam=1.0, k=-1.0, gamma=1.0)
    with pytest.raises(ValueError, match=r"k must be finite and >= 0"):
        FirstOrderAdaptiveLaw(_form(1, with_d=False), k=float("nan"), gamma=1.0)
    with pytest.raises(ValueError, match="unknown leading coefficient"):
        SlidingAdaptiveLaw(_form(2, with_d=False), lam=1.0, k=1.0, gamma=1.0)
    with pytest.raises(ValueError, match="order-1 form"):
        FirstOrderAdaptiveLaw(_form(2, with_d=False), k=1.0, gamma=1.0)
    with pytest.raises(ValueError, match="order-1 form"):
        FirstOrderAdaptiveLaw(_form(1, with_d=True), k=1.0, gamma=1.0)


# ----------------------------------------------------------------- ṡ = ṡ_r - y^(n) along a run
def _third_order_form() -> ModelForm:
    """d y''' = f + phi.p + h u with f = -0.5 y, h = 1.5 + 0.5 cos y."""
    return ModelForm(
        order=3,
        p_names=("a2", "a1", "c"),
        phi=lambda x: np.array([-x[2], -x[1] * abs(x[1]), -np.sin(x[0])]),
        f=lambda x: -0.5 * x[0],
        h=lambda x: 1.5 + 0.5 * np.cos(x[0]),
    )


def test_s_dot_equals_s_r_dot_minus_highest_derivative_on_a_twin_run():
    from adaptive_mj.sim.loop import run

    form = _third_order_form()
    theta = np.array([2.0, 0.8, 0.3, 1.1])
    ref = SumOfSines()
    # start 5 cm off the reference with matched derivatives: a smooth run, so the
    # O(dt²) error of the central difference stays far below the tolerance
    x0 = ref(0.0, 2) + np.array([0.05, 0.0, 0.0])
    plant = twin.TwinPlant(form, theta, dt=1e-3, x0=x0)
    law = SlidingAdaptiveLaw(form, lam=3.0, k=4.0, gamma=[1.0, 2.0, 1.0, 0.5])
    # the Python path: this form's lambdas would compile a twin variant no other test uses (tens of seconds from a
    # cold cache); the law's identity is what is checked, and the compiled path gives the same rows bit for bit
    # (tests/test_native_twin.py, tests/test_analytic_kernel.py)
    tr = run(plant, law, ref, duration=4.0, theta_hat0=[1.0, 0.0, 0.0, 0.0], native=False)
    assert tr.status == "ok" and len(tr) == 4000
    dt = tr.meta["dt"]
    s_dot_fd = (tr.s[2:] - tr.s[:-2]) / (2 * dt)
    predicted = np.empty(len(tr) - 2)
    for i, k in enumerate(range(1, len(tr) - 1)):
        step = law(tr.t[k], tr.x[k], tr.ref[k], tr.theta_hat[k])
        assert step.s == pytest.approx(tr.s[k], rel=1e-12, abs=1e-14)
        y_n = form.highest_derivative(tr.x[k], tr.u[k], tr.theta[k])
        predicted[i] = step.s_r_dot - y_n
    scale = np.max(np.abs(predicted))
    assert scale > 0.1  # the check is not vacuous
    err = np.max(np.abs(s_dot_fd - predicted))
    print(f"n=3: max |ds/dt (central diff) - (s_r_dot - y''')| = {err:.3g} (scale {scale:.3g})")
    assert err <= 1e-4 * scale

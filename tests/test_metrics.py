"""Metrics and analyses on synthetic trajectories with known answers."""
import math

import numpy as np
import pytest

from adaptive_mj.study import analysis
from adaptive_mj.report.metrics import metrics, summary, tail_mask
from adaptive_mj.trajectory import Trajectory


def make(t, y, yd, u=None, s=None, theta_hat=None, theta=None, V=None, dt=None):
    n = len(t)
    dt = dt if dt is not None else float(t[1] - t[0])
    theta = np.ones((n, 2)) if theta is None else theta
    theta_hat = theta.copy() if theta_hat is None else theta_hat
    return Trajectory(t=np.asarray(t, float), x=np.column_stack([y, np.zeros(n)]),
                      u=np.zeros(n) if u is None else np.asarray(u, float),
                      s=np.zeros(n) if s is None else np.asarray(s, float),
                      ref=np.column_stack([yd, np.zeros(n), np.zeros(n)]), theta_hat=theta_hat, theta=theta,
                      V=np.zeros(n) if V is None else np.asarray(V, float), names=("d", "b"), meta={"dt": dt})


def test_tracking_metrics_known_answers():
    t = np.arange(100) * 0.1  # 10 s; tail = t >= 7.5
    e = np.where(t >= 7.5, 0.5, 2.0)
    tr = make(t, np.zeros(100), e)
    assert tail_mask(tr).sum() == 25
    m = metrics(tr)
    assert m["rms_tracking_error"] == pytest.approx(math.sqrt((75 * 4 + 25 * 0.25) / 100))
    assert m["rms_tracking_error_tail"] == pytest.approx(0.5)
    assert m["max_abs_tracking_error_tail"] == pytest.approx(0.5)


def test_control_metrics_known_answers():
    t = np.arange(4) * 1.0
    tr = make(t, np.zeros(4), np.zeros(4), u=[1.0, -1.0, 1.0, 3.0])
    m = metrics(tr)
    assert m["control_rms"] == pytest.approx(math.sqrt((1 + 1 + 1 + 9) / 4))
    assert m["control_total_variation"] == pytest.approx(2 + 2 + 2)


def test_parameter_and_lyapunov_metrics():
    t = np.arange(5) * 1.0
    theta = np.tile([2.0, 3.0], (5, 1))
    hat = theta + np.array([[0.5, -1.0]] * 5)
    tr = make(t, np.zeros(5), np.zeros(5), theta_hat=hat, theta=theta, V=[5.0, 4.0, 4.5, 1.0, 1.2])
    m = metrics(tr)
    assert m["param_error_final"] == {"d": 0.5, "b": -1.0}
    assert m["lyapunov_max_increase"] == pytest.approx(0.5)
    assert m["lyapunov_initial"] == 5.0 and m["lyapunov_final"] == 1.2


def test_summary_shape_and_duration():
    t = np.arange(10) * 0.01
    tr = make(t, np.zeros(10), np.ones(10))
    s = summary("x", tr)
    assert s["scenario"] == "x" and s["status"] == "ok" and s["steps"] == 10
    assert s["duration"] == pytest.approx(0.1)
    assert set(s["final"]) == {"t", "q", "qd", "theta_hat", "theta"}


def test_drift_rate_of_a_linear_ramp():
    t = np.linspace(0, 200, 2001)
    theta = np.tile([10.0, 4.0], (len(t), 1))
    hat = theta.copy()
    hat[:, 0] = 10.0 + 0.05 * t  # d drifts 5 per 100 s = 0.5 of its true value per 100 s
    tr = make(t, np.zeros(len(t)), np.zeros(len(t)), theta_hat=hat, theta=theta)
    assert analysis.drift_rate(tr) == pytest.approx(0.5, rel=1e-9)
    flat = make(t, np.zeros(len(t)), np.zeros(len(t)), theta_hat=theta.copy(), theta=theta)
    assert analysis.drift_rate(flat) == pytest.approx(0.0, abs=1e-12)


def test_settle_time():
    t = np.arange(10) * 1.0
    ok = np.array([1, 0, 0, 1, 0, 1, 1, 1, 1, 1], bool)
    assert analysis.settle_time(t, ok, 2.0) == 3.0  # from t = 5 on
    assert analysis.settle_time(t, np.ones(10, bool), 2.0) == 0.0
    assert analysis.settle_time(t, ~np.ones(10, bool), 2.0) is None


class _Form:
    order = 2
    d_name = "d"

    @staticmethod
    def phi(x):
        return np.array([-x[1] * abs(x[1]), -9.81])


def test_excitation_index_zero_for_a_setpoint_and_high_for_a_cosine():
    t = np.linspace(0, 60, 6001)
    const = make(t, np.zeros(len(t)), np.ones(len(t)))
    assert analysis.excitation(const, _Form) == pytest.approx(0.0, abs=1e-12)
    ref = np.column_stack([np.cos(t), -np.sin(t), -np.cos(t)])
    cos = Trajectory(t=t, x=np.zeros((len(t), 2)), u=np.zeros(len(t)), s=np.zeros(len(t)), ref=ref,
                     theta_hat=np.ones((len(t), 3)), theta=np.ones((len(t), 3)), V=np.zeros(len(t)),
                     names=("d", "b", "c"), meta={"dt": 0.01})
    idx = analysis.excitation(cos, _Form)
    assert 0.5 < idx <= 1.0


def test_swap_response_on_a_synthetic_swap():
    t = np.arange(0, 10, 0.01)
    e = np.where(t < 5, 0.0, 0.05 * np.exp(-(t - 5)))  # peak 0.05 at the swap, below 0.005 after ln(10) s
    theta = np.tile([1.0, 0.1], (len(t), 1))
    theta[t >= 5, 0] = 4.0
    hat = theta.copy()
    hat[(t >= 5) & (t < 7), 0] = 1.0  # re-converges at t = 7
    tr = make(t, np.zeros(len(t)), e, theta_hat=hat, theta=theta)

    class Setup:
        events = [type("E", (), {"t": 5.0})()]

    r = analysis.swap_response(tr, Setup)
    assert r["peak_error_after"] == pytest.approx(0.05)
    assert r["recovery_time"] == pytest.approx(math.log(10), abs=0.011)
    assert r["reconvergence_time"] == pytest.approx(2.0, abs=1e-9)
    assert r["changed"] == ["d"]

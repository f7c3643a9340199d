"""Direct MRAC (adaptive_mj.laws.mrac), the analytic linear plant with its delay line
(adaptive_mj.plants.linear), the reference model's closed form, and the two published break points:
Rohrs' counterexample and Nguyen's delay threshold (issue 21)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from adaptive_mj.errors import ScenarioError
from adaptive_mj.laws.common import Modification
from adaptive_mj.laws.mrac import MracLaw, Rule, ideal_gains, lyapunov_matrix
from adaptive_mj.plants.linear import LinearPlant, canonical
from adaptive_mj.reference import ModelResponse
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim.loop import run
from adaptive_mj.runs.runner import execute
from adaptive_mj.study.mrac_breaks import frozen_gain_limit, rohrs_onset


def _law(**kw):
    args = dict(order=1, alpha=[3.0], beta=3.0, gamma=[0.7, 1.3], sign_b=-1.0)
    args.update(kw)
    return MracLaw(**args)


def test_lyapunov_rule_is_its_equation():
    """sign(b) = -1: θ̂' = -sign(b) γ ω e = γ ω e."""
    rng = np.random.default_rng(1)
    law = _law()
    for _ in range(20):
        x, ref, th = rng.normal(size=1), rng.normal(size=2), rng.normal(size=2)
        out = law(0.0, x, ref, th)
        r = (ref[1] + 3.0 * ref[0]) / 3.0  # r from the reference model y_m' = -3 y_m + 3 r
        omega, e = np.array([x[0], r]), x[0] - ref[0]
        assert out.u == pytest.approx(th @ omega, rel=1e-14)
        np.testing.assert_allclose(out.theta_hat_dot, np.array([0.7, 1.3]) * omega * e, rtol=1e-14)
        assert out.s == pytest.approx(-e, rel=1e-14)


def test_modifications_use_the_rate_gain():
    mod = Modification(sigma=0.2, theta0=np.array([0.5, -0.5]))
    law, plain = _law(modification=mod), _law()
    x, ref, th = np.array([0.3]), np.array([0.1, -0.2]), np.array([1.0, 2.0])
    leak = law(0.0, x, ref, th).theta_hat_dot - plain(0.0, x, ref, th).theta_hat_dot
    np.testing.assert_allclose(leak, -0.2 * np.array([0.7, 1.3]) * (th - [0.5, -0.5]), rtol=1e-14)
    box = _law(modification=Modification(lower=np.array([-1.0, 0.0]), upper=np.array([1.0, 2.0])))
    assert box.bounds is not None
    rate = box(0.0, np.array([5.0]), np.array([0.0, 0.0]), np.array([1.0, 2.0])).theta_hat_dot
    assert rate[0] == 0.0 or rate[0] < 0  # at the upper bound k_y = 1 the rate may only point inward


def test_mit_rule_uses_the_filtered_regressor():
    law = _law(rule=Rule.MIT)
    assert law.has_filters
    law.reset()
    x, ref, th = np.array([0.4]), np.array([0.1, 0.3]), np.array([0.0, 0.0])
    law.step_begins(x)
    first = law(0.0, x, ref, th)
    np.testing.assert_array_equal(first.theta_hat_dot, 0.0)  # ω_f starts at 0
    omega = law.regressor(x, ref)[0]
    for _ in range(3):  # the other RK4 stages, same ω
        law(0.0, x, ref, th)
    law.step_ends([x] * 4, [0.0] * 4, [1 / 6, 1 / 3, 1 / 3, 1 / 6], 0.01)
    np.testing.assert_allclose(law.omega_f, (1 - math.exp(-3.0 * 0.01)) * omega, rtol=1e-14)
    nxt = law(0.0, x, ref, th)
    np.testing.assert_allclose(nxt.theta_hat_dot, np.array([0.7, 1.3]) * law.omega_f * (x[0] - ref[0]), rtol=1e-14)
    assert math.isnan(float(law.lyapunov(np.array([1.0]), th[None], th[None])[0]))


def test_lyapunov_matrix_solves_its_equation():
    P = lyapunov_matrix([4.0, 2.8])
    A = np.array([[0.0, 1.0], [-4.0, -2.8]])
    np.testing.assert_allclose(A.T @ P + P @ A, -np.eye(2), atol=1e-12)
    assert np.all(np.linalg.eigvalsh(P) > 0)


def test_v_is_non_increasing_on_the_matched_plant():
    """No unmodelled dynamics, no delay: V = ½e² + |b|/2 Σ θ̃²/γ has V' = -α_0 e² <= 0."""
    a, b = -1.0, 2.0
    A, B, C = canonical([b], [1.0, -a])
    theta = ideal_gains([a], b, [], [3.0], 3.0)
    plant = LinearPlant(A, B, C, dt=0.002, names=("k_y", "k_r"), theta=theta)
    law = MracLaw(order=1, alpha=[3.0], beta=3.0, gamma=1.0, b_abs=abs(b))
    ref = ModelResponse(alpha=(3.0,), beta=3.0, offset=0.3, amplitudes=(1.85,), omegas=(16.1,), phases=(0.0,))
    plant.set_state([0.0])
    traj = run(plant, law, ref, duration=10.0, theta_hat0=[-0.65, 1.14])
    assert traj.status == "ok"
    assert np.max(np.diff(traj.V)) <= 1e-9 * traj.V[0]
    assert traj.V[-1] < 0.8 * traj.V[0]  # measured: 0.68 V(0) after 10 s


def test_linear_plant_matches_the_closed_form_step_response():
    """1/((s+1)(s+2)): y(t) = ½ - e^{-t} + ½ e^{-2t}; and Rohrs' plant settles at its DC gain 2."""
    A, B, C = canonical([1.0], np.polymul([1.0, 1.0], [1.0, 2.0]))
    plant = LinearPlant(A, B, C, dt=0.001, names=("k",), theta=[0.0])
    plant.set_state([0.0])
    ys, ts = [], []
    with plant.controlled_by(lambda t, x: 1.0):
        for _ in range(5000):
            plant.step()
            ys.append(plant.observe()[0])
            ts.append(plant.time)
    t = np.array(ts)
    np.testing.assert_allclose(ys, 0.5 - np.exp(-t) + 0.5 * np.exp(-2 * t), atol=1e-12)
    A, B, C = canonical(np.polymul([2.0], [229.0]), np.polymul([1.0, 1.0], [1.0, 30.0, 229.0]))
    rohrs = LinearPlant(A, B, C, dt=0.001, names=("k",), theta=[0.0])
    rohrs.set_state([0.0])
    with rohrs.controlled_by(lambda t, x: 1.0):
        for _ in range(20000):
            rohrs.step()
    assert rohrs.observe()[0] == pytest.approx(2.0, abs=1e-7)


def _delayed_run(delay: int, n: int, num=(1.0,), den=(1.0, 1.0)):
    A, B, C = canonical(num, den)
    plant = LinearPlant(A, B, C, dt=0.01, names=("k",), theta=[0.0], delay_steps=delay)
    plant.set_state([0.0])
    ys, us = [plant.observe()[0]], []

    def policy(t, x):
        return math.sin(3.0 * t) + 0.5

    with plant.controlled_by(policy):
        for _ in range(n):
            us.append(policy(plant.time, None))
            plant.step()
            ys.append(plant.observe()[0])
    return np.array(ys), np.array(us)


def test_delay_line_is_exact():
    """With D steps the plant is driven over step k by the stage-0 control of step k - D, held:
    a run with delay 5 is the run with delay 3 shifted by 2 steps, bit for bit; on an integrator
    y_{k+1} - y_k = h u_{k-D}, zero for k < D."""
    y3, _ = _delayed_run(3, 300)
    y5, _ = _delayed_run(5, 300)
    np.testing.assert_array_equal(y5[2:], y3[:-2])
    assert np.all(y5[:6] == 0.0) and y5[6] != 0.0
    y, u = _delayed_run(4, 200, num=(1.0,), den=(1.0, 0.0))
    steps = np.diff(y)
    np.testing.assert_array_equal(steps[:4], 0.0)
    np.testing.assert_allclose(steps[4:], 0.01 * u[:-4], rtol=0, atol=1e-15)  # round-off of y_{k+1} - y_k


def test_reference_model_response_is_exact():
    m = ModelResponse(alpha=(3.0,), beta=3.0, offset=0.3, amplitudes=(1.85,), omegas=(16.1,), phases=(0.0,))
    t = np.linspace(0.0, 3.0, 301)
    y = m(t, 1)
    np.testing.assert_allclose(y[1], -3.0 * y[0] + 3.0 * (0.3 + 1.85 * np.sin(16.1 * t)), atol=1e-13)
    assert y[0][0] == 0.0 or abs(y[0][0]) < 1e-15
    with pytest.raises(ValueError, match="distinct and stable"):
        ModelResponse(alpha=(-1.0,), beta=1.0)


def _run(name, *overrides):
    scn = sc.load(sc.SCENARIOS_DIR / f"{name}.toml", overrides=list(overrides))
    return execute(scn, log_path=None)


CONSTANT_R = ("reference.amplitudes=[]", "reference.omegas=[]", "reference.offset=2.0")


def test_rohrs_bounded_for_constant_r():
    res = _run("rohrs_counterexample", *CONSTANT_R)
    assert res.trajectory.status == "ok" and res.summary["status"] == "ok"
    assert np.max(np.abs(res.trajectory.x)) < 3.0


def test_rohrs_diverges_for_the_published_r():
    """30 s run: diverges (|y| > 100) after k_y has drifted past the frozen-gain limit."""
    res = _run("rohrs_counterexample")
    traj = res.trajectory
    assert traj.status == "diverged" and res.summary["status"] == "diverged"
    limit = frozen_gain_limit([2.0 * 229.0], np.polymul([1.0, 1.0], [1.0, 30.0, 229.0]))
    assert limit == pytest.approx((1.0 - 31.0 * 259.0 / 229.0) / 2.0, rel=1e-9)  # Routh: s³ + 31s² + 259s + 229(1 - 2k)
    onset = rohrs_onset(traj, limit)
    assert onset is not None and 5.0 < onset < traj.t[-1]


@pytest.mark.parametrize("gamma, status", [(2.0, "ok"), (2.9, "diverged")])
def test_nguyen_delay_threshold(gamma, status):
    """Over the scenario's 60 s: gamma = 2 stays bounded and tracks, 2.9 diverges."""
    res = _run("mrac_time_delay", f"law.gamma={gamma}")
    assert res.trajectory.status == status
    if status == "ok":
        assert res.summary["status"] == "ok" and res.trajectory.t[-1] > 59.9


def test_projection_restores_the_delayed_loop():
    res = _run("mrac_time_delay", "law.gamma=2.9", "law.projection={k_y=[-2, 0], k_r=[0, 4]}")
    assert res.trajectory.status == "ok"
    assert np.all(res.trajectory.theta_hat[:, 0] >= -2.0)


def test_bad_mrac_keys_name_the_key(tmp_path):
    text = (sc.SCENARIOS_DIR / "mrac_time_delay.toml").read_text()
    with pytest.raises(ScenarioError, match="law.model must be 1 coefficient"):
        sc.loads(text, overrides=["law.model=[-2.0]"])
    with pytest.raises(ScenarioError, match="plant.input_delay must be a whole number of timesteps"):
        build(sc.loads(text, overrides=["plant.input_delay=0.5003"]))
    with pytest.raises(ScenarioError, match="reference_model' needs law.kind = 'mrac'"):
        sc.loads((sc.SCENARIOS_DIR / "wing_rock.toml").read_text(), overrides=["reference.kind=reference_model"])
    with pytest.raises(ScenarioError, match="law.kind = .mrac. serves the MRAC state.*plant.kind = .heave. offers"):
        sc.loads((sc.SCENARIOS_DIR / "heave_tracking.toml").read_text(), overrides=["law.kind=mrac"])


def test_wing_rock_flight_condition_moves_the_truth():
    scn = sc.load(sc.SCENARIOS_DIR / "wing_rock_mrac.toml", overrides=["simulation.duration=31"])
    setup = build(scn)
    before = setup.plant.true_theta().copy()
    setup.events[0].apply(setup.plant)
    after = setup.plant.true_theta()
    assert after[2] == pytest.approx(2 * before[2])  # k_r* = β / L_δ: L_δ halved
    assert not np.allclose(before, after)


@pytest.mark.parametrize("name", ["wing_rock", "wing_rock_mrac"])
def test_wing_rock_tracks_roll_through_the_flight_condition_change(name):
    """Both laws hold the roll reference within the aileron limit and re-adapt after the change at 30 s:
    the RMS error over the last 20 s is below 0.02 rad (measured 0.006 sliding, 0.014 MRAC)."""
    traj = _run(name).trajectory
    assert traj.status == "ok" and traj.meta["events"]
    err = traj.ref[:, 0] - traj.x[:, 0]
    assert float(np.sqrt(np.mean(err[traj.t >= 40.0] ** 2))) < 0.02
    assert np.all(np.abs(traj.u) <= 1.75)


def test_state_space_keys_give_the_same_plant_as_the_transfer_function():
    """Rohrs' plant written as A, B, C (its canonical form) runs the same as num/den x unmodelled."""
    A, B, C = canonical(np.polymul([2.0], [229.0]), np.polymul([1.0, 1.0], [1.0, 30.0, 229.0]))
    text = (sc.SCENARIOS_DIR / "rohrs_counterexample.toml").read_text()
    text = text.replace("unmodelled_num = [229.0]\nunmodelled_den = [1.0, 30.0, 229.0]\n",
                        f"A = {A.tolist()}\nB = {B.tolist()}\nC = {C.tolist()}\n")
    short = ["simulation.duration=2.0"]
    a = execute(sc.loads(text, overrides=short)).trajectory
    b = _run("rohrs_counterexample", *short).trajectory
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.theta_hat, b.theta_hat)
    with pytest.raises(ScenarioError, match="plant.C must be given with plant.A, plant.B and plant.C together"):
        sc.loads(text.replace("C = ", "#C = "))
    with pytest.raises(ScenarioError, match=r"plant.B must be an array of 3 numbers"):
        sc.loads(text.replace(f"B = {B.tolist()}", "B = [0.0, 1.0]"))


def test_first_order_law_is_mrac_with_known_b():
    """docs/THEORY.md: the lecture's first-order law is MRAC with ω = φ(x), k_φ = −p̂, e = x − x_m, x_m = x_d
    (the model x_m' = −k x_m + r with r = x_d' + k x_d), rate Γ = 1/γ, plus the known part r − k x − f(x)."""
    from adaptive_mj.laws import FirstOrderAdaptiveLaw
    from adaptive_mj.plants.twin import lecture_first_order_form

    form, k, gamma = lecture_first_order_form(), 2.0, 0.5
    law = FirstOrderAdaptiveLaw(form, k=k, gamma=gamma)
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, ref, p_hat = rng.normal(size=1), rng.normal(size=2), rng.normal(size=2)
        out = law(0.0, x, ref, p_hat)
        r, e, omega, k_phi = ref[1] + k * ref[0], x[0] - ref[0], form.phi(x), -p_hat
        assert out.u == pytest.approx(r - k * x[0] - form.f(x) + k_phi @ omega, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(-out.theta_hat_dot, -(1.0 / gamma) * omega * e, rtol=1e-12, atol=1e-15)


def test_mit_rule_is_refused_under_sampled_control():
    with pytest.raises(ScenarioError, match=r"law.rule = 'mit' runs under control.mode = 'continuous' only"):
        _run("rohrs_counterexample", "law.rule=mit", "control.period=0.01")

"""Robust modifications of the adaptive laws (σ, e-modification, projection, composite
adaptation, a dead-zone in units of the noise): each against its defining equation, in
the compiled callback as in Python, and on the physics where it matters."""
from __future__ import annotations

import math

import numpy as np
import pytest

from adaptive_mj import run
from adaptive_mj.cli import main
from adaptive_mj.laws import (CompositeSlidingLaw, FirstOrderAdaptiveLaw, Modification, SlidingAdaptiveLaw)
from adaptive_mj.laws.common import modify_rate
from adaptive_mj.laws.slotine_li import SlotineLiLaw
from adaptive_mj.plants import heave
from adaptive_mj.plants.twin import lecture_first_order_form
from adaptive_mj.setup.build import build
from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
from adaptive_mj.runs.runner import execute

RNG = np.random.default_rng(3)  # θ₀ draws
GAMMA = np.array([0.0025, 0.002, 0.5])


def _laws(modification, seed=0):
    """(law, x, ref, θ̂) for the three adaptive laws at one random state (the same for a seed)."""
    RNG = np.random.default_rng(seed)
    form = heave.heave_form(9.81)
    x, ref = RNG.normal(size=2), RNG.normal(size=3)
    sliding = SlidingAdaptiveLaw(form, lam=5.0, k=200.0, gamma=GAMMA, modification=modification(3))
    first = FirstOrderAdaptiveLaw(lecture_first_order_form(), k=2.0, gamma=[0.5, 2.0], modification=modification(2))
    Y = RNG.normal(size=(2, 4))
    slotine = SlotineLiLaw(lambda v, w, a: (Y, np.zeros(2)), ("a", "b", "c", "d"), 2, lam=3.0, kd=7.0,
                           gamma=[1.0, 2.0, 3.0, 4.0], modification=modification(4))
    xs = RNG.normal(size=(2, 2))
    return [(sliding, x, ref, RNG.normal(size=3) * 10),
            (first, x[:1], ref[:2], RNG.normal(size=2)),
            (slotine, xs, RNG.normal(size=(3, 2)), RNG.normal(size=4))]


@pytest.mark.parametrize("kind", ["sigma", "e"])
def test_leakage_is_its_defining_equation(kind):
    """θ̂' = (law's θ̂') − (σ + ν|s|) Γ⁻¹ (θ̂ − θ₀), for the order-n, first-order and Slotine–Li laws."""
    sigma, nu = (0.7, 0.0) if kind == "sigma" else (0.0, 3.0)
    theta0 = {n: RNG.normal(size=n) for n in (2, 3, 4)}
    plain = _laws(lambda n: None)
    modified = _laws(lambda n: Modification(sigma=sigma, e_mod=nu, theta0=theta0[n]))
    for (law0, *_), (law1, x, ref, th) in zip(plain, modified, strict=True):
        law0_step = law0(0.0, x, ref, th)
        step = law1(0.0, x, ref, th)
        s_abs = float(np.linalg.norm(step.s))
        expected = law0_step.theta_hat_dot - (sigma + nu * s_abs) * (th - theta0[len(th)]) / law1.gamma
        np.testing.assert_allclose(step.theta_hat_dot, expected, rtol=1e-13, atol=1e-13)
        assert np.all(step.u == law0_step.u)  # the control is untouched


def test_projection_cuts_the_rate_only_where_it_leaves_the_box():
    lower, upper = np.array([0.0, -1.0, -np.inf]), np.array([np.inf, 1.0, 2.0])
    theta = np.array([0.0, 1.0, 2.0])  # each on a face of the box
    rate = np.array([-5.0, 3.0, 4.0])  # each pointing out of it
    modify_rate(rate, theta, 0.0, 0.0, 0.0, np.zeros(3), np.ones(3), lower, upper)
    assert np.all(rate == 0.0)
    rate = np.array([5.0, -3.0, -4.0])  # pointing in: untouched
    modify_rate(rate, theta, 0.0, 0.0, 0.0, np.zeros(3), np.ones(3), lower, upper)
    assert np.all(rate == [5.0, -3.0, -4.0])


def _run(name, overrides, native=None):
    scn = load(SCENARIOS_DIR / f"{name}.toml", overrides=overrides)
    s = build(scn)
    return run(s.plant, s.law, s.reference, duration=scn.simulation.duration, theta_hat0=s.theta_hat0,
               noise_std=s.noise_std, rng=s.rng, events=s.events, native=native), s


SWAP = ["simulation.duration=24"]  # the payload x4 at 20 s


def test_projection_keeps_J_positive_through_the_arm_payload_swap():
    """Without projection Ĵ dips below 0 (to -0.81 kg m² against a true 0.59) after the swap;
    with law.projection = {J = [0.05, inf]} it stays >= 0.05, and the swap's error is smaller."""
    plain, _ = _run("arm_payload_swap", SWAP)
    boxed, _ = _run("arm_payload_swap", SWAP + ["law.projection={J=[0.05, inf]}"])
    assert plain.theta_hat[:, 0].min() < -0.5
    assert boxed.theta_hat[:, 0].min() == 0.05  # reached, held, never crossed
    after = plain.t >= 20.0
    assert np.abs(boxed.y_tilde[after]).max() < 0.75 * np.abs(plain.y_tilde[after]).max()


@pytest.mark.parametrize("native", [False, True])
def test_projection_leaves_V_non_increasing_in_the_ideal_case(native):
    """Noise-free MuJoCo arm, estimates from far off, a box that holds the true θ with Ĵ's lower bound
    active for a while (without it Ĵ dips to -0.03):
    V = ½ J s² + ½ Σγθ̃² never increases (beyond round-off), on both callback paths."""
    traj, setup = _run("arm_payload_swap", ["events=[]", "simulation.duration=6",
                                            "law.initial_estimates={J=0.3, b=0.0, g_sin=0.0, g_cos=0.0}",
                                            "law.projection={J=[0.2, inf], b=[0.0, inf]}"], native=native)
    assert traj.meta["native"] is native
    J = traj.theta_hat[:, 0]
    assert np.mean(J == 0.2) > 0.01  # the bound (true J = 0.213 kg m²) held for a while
    assert np.min(traj.theta_hat[:, 1]) >= 0.0
    assert np.max(np.diff(traj.V)) <= 1e-9 * traj.V[0]


def test_native_and_python_agree_with_every_modification():
    overrides = ["simulation.duration=3", "law.sigma=0.02", "law.e_modification=0.5",
                 "law.projection={d=[30.0, 45.0], c=[0.0, inf]}", "law.initial_estimates={d=30.0, b=0.0, c=0.0}"]
    a, _ = _run("heave_tracking", overrides, native=False)
    b, _ = _run("heave_tracking", overrides, native=True)
    for f in ("x", "u", "s", "theta_hat", "V"):
        np.testing.assert_allclose(getattr(b, f), getattr(a, f), rtol=0, atol=1e-12, err_msg=f)
    assert a.theta_hat[:, 0].min() == 30.0 and a.theta_hat[:, 0].max() <= 45.0


def test_sigma_modification_bounds_the_lecture_drift():
    """heave_drift (noise, constant set-point): d̂/d grows without a modification; σ-modification
    toward the initial estimates keeps it within 5 % over the same 60 s."""
    plain = execute(load(SCENARIOS_DIR / "heave_drift.toml", overrides=["simulation.duration=60"])).trajectory
    sigma = execute(load(SCENARIOS_DIR / "heave_drift.toml",
                         overrides=["simulation.duration=60", "law.sigma=0.01"])).trajectory

    def ratio(tr):
        return tr.theta_hat[-1, 0] / tr.theta[-1, 0]

    assert ratio(plain) > 1.05
    assert abs(ratio(sigma) - 1.0) < 0.05, ratio(sigma)


# -- composite adaptation ----------------------------------------------------------------

def test_composite_prediction_error_vanishes_at_the_true_parameters():
    """The per-step identity d·Δy'/h − φ̄ᵀp = τ̄ holds on MuJoCo's RK4 to round-off, and the
    filters keep it: e(θ) = Y_f θ − τ_f ≈ 0 along a run."""
    scn = load(SCENARIOS_DIR / "arm_payload_swap.toml",
               overrides=["events=[]", "simulation.duration=2", "law.composite={gain=1.0, filter=2.0}"])
    s = build(scn)
    law, theta = s.law, s.plant.true_theta()
    errors = []
    begins = law.step_begins

    def record(x):
        begins(x)
        Yf, e = law.prediction(theta)
        errors.append(abs(e) / max(1e-12, float(np.abs(Yf * theta).max())))

    law.step_begins = record
    traj = run(s.plant, law, s.reference, duration=2.0, theta_hat0=s.theta_hat0, native=False)
    assert traj.meta["native"] is False  # the Python path calls step_begins (the callback runs the same code)
    assert max(errors[1:]) < 1e-9


def _convergence_time(traj, gamma, fraction):
    w = np.sqrt(np.sum(gamma * (traj.theta_hat - traj.theta) ** 2, axis=1))
    above = np.nonzero(w > fraction * w[0])[0]
    return math.inf if above[-1] + 1 >= len(w) else float(traj.t[above[-1] + 1])


def test_composite_adaptation_converges_faster_on_the_same_reference():
    """The arm from J = 0.3 and b = g = 0 on arm_payload_swap's sum of sines: the Γ-weighted
    parameter error falls below 10 % of its start more than twice as fast with composite
    adaptation (κ = 1, λ_f = 2/s) as with the tracking error alone, and V never increases."""
    base = ["events=[]", "simulation.duration=20", "law.initial_estimates={J=0.3, b=0.0, g_sin=0.0, g_cos=0.0}"]
    plain, setup = _run("arm_payload_swap", base)
    comp, _ = _run("arm_payload_swap", base + ["law.composite={gain=1.0, filter=2.0}"])
    assert isinstance(_.law, CompositeSlidingLaw)
    t_plain = _convergence_time(plain, setup.law.gamma, 0.1)
    t_comp = _convergence_time(comp, setup.law.gamma, 0.1)
    assert t_comp < 0.5 * t_plain, (t_comp, t_plain)
    assert np.max(np.diff(comp.V)) <= 1e-9 * comp.V[0]


def test_composite_filters_restart_with_each_run():
    scn = load(SCENARIOS_DIR / "arm_payload_swap.toml",
               overrides=["events=[]", "simulation.duration=0.5", "law.composite={gain=1.0, filter=2.0}"])
    s = build(scn)
    first = run(s.plant, s.law, s.reference, duration=0.5, theta_hat0=s.theta_hat0)
    s2 = build(scn)
    s2.plant.set_state(first.x[0])
    again = run(s2.plant, s.law, s2.reference, duration=0.5, theta_hat0=s.theta_hat0)  # the same law object
    np.testing.assert_array_equal(again.theta_hat, first.theta_hat)


# -- dead-zone in units of the noise ---------------------------------------------------------

def test_dead_zone_width_in_noise_std():
    """ε = k σ_s with σ_s² = σ_ẏ² + λ² σ_y² for s = ỹ' + λ ỹ (heave_drift: λ = 5, σ_y = 1 mm,
    σ_ẏ = 1 cm/s); on the tracking error, ε = k σ_y."""
    s = build(load(SCENARIOS_DIR / "heave_drift.toml", overrides=["law.dead_zone={width_in_noise_std=3.0}"]))
    assert s.law.dead_zone.width == pytest.approx(3.0 * math.hypot(0.01, 5.0 * 0.001), rel=1e-15)
    s = build(load(SCENARIOS_DIR / "heave_drift.toml",
                   overrides=["law.dead_zone={width_in_noise_std=2.0, on='tracking_error'}"]))
    assert s.law.dead_zone.width == pytest.approx(2.0 * 0.001, rel=1e-15)


# -- scenario keys: one-line errors -----------------------------------------------------------

@pytest.mark.parametrize("name, override, match", [
    ("arm_payload_swap", "law.projection={Q=[0.0, 1.0]}", r"law.projection names parameter 'Q', which the law does "
                                                          r"not have \(parameters: J, b, g_sin, g_cos\)"),
    ("arm_payload_swap", "law.projection={J=[1.0, 0.0]}", r"law.projection.J must be \[lower, upper\] with lower <= "
                                                          r"upper, got an array \[1.0, 0.0\]"),
    ("arm_payload_swap", "law.projection={J=[1.0, inf]}", r"law.projection: the initial estimate J = 0.\d+ is "
                                                          r"outside its box \[1, inf\]"),
    ("arm_payload_swap", "law.sigma=-1", r"law.sigma must be >= 0, got -1"),
    ("arm_payload_swap", "law.projection='physical'", r"law.projection must be a table \{parameter = \[lower, "
                                                      r"upper\]\}, got 'physical'"),
    ("lecture_first_order", "law.composite={gain=1.0, filter=2.0}",
     r"law.composite must be absent for law.kind = 'first_order_adaptive' \(composite adaptation is implemented "
     r"for law.kind = 'sliding_adaptive'\)"),
    ("heave_tracking", "law.dead_zone={width_in_noise_std=3.0}",
     r"law.dead_zone.width_in_noise_std needs noise.std \(the noise its width is a multiple of\), got no noise"),
    ("ur5e_payload_swap", "law.composite={gain=1.0, filter=2.0}", r"law.composite must be absent for law.kind = "
                                                                  r"'slotine_li'"),
    ("ur5e_payload_swap", "law.projection={nope=[0.0, inf]}", r"law.projection names parameter 'nope'"),
])
def test_robust_keys_errors_are_one_line(name, override, match, capsys):
    args = ["run", name, "--set", override, "--set", "simulation.duration=0.01", "--set", "events=[]"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    import re

    assert re.search(match, err[0]), err[0]


def test_baselines_ignore_the_modifications_as_they_ignore_gamma():
    """law.kind = fixed_nominal on a scenario with σ, projection and composite keys: the same run as
    the baseline without them (so a law grid over kinds needs no per-kind overrides)."""
    base = ["simulation.duration=1", "events=[]", "law.kind='fixed_nominal'", "law.nominal='model'"]
    plain, _ = _run("arm_payload_swap", base)
    keyed, setup = _run("arm_payload_swap", base + ["law.sigma=0.3", "law.projection={J=[0.0, inf]}",
                                                    "law.composite={gain=1.0, filter=2.0}"])
    assert type(setup.law).__name__ == "FixedNominalLaw"
    np.testing.assert_array_equal(keyed.u, plain.u)


# -- control delay and the lecture's sudden failure -------------------------------------------

def test_control_delay_applies_the_control_computed_D_steps_earlier():
    """u applied during step k = the clamped stage-0 control the law computed at step k − D (zero
    before), on both callback paths, bit for bit."""
    D = 5
    over = ["simulation.duration=0.5", f"simulation.control_delay={D}"]
    scn = load(SCENARIOS_DIR / "heave_tracking.toml", overrides=over)
    runs = []
    for native in (False, True):
        s = build(scn)
        runs.append(run(s.plant, s.law, s.reference, duration=0.5, theta_hat0=s.theta_hat0, native=native,
                        control_delay=D))
    py, nat = runs
    assert nat.meta["native"] and not py.meta["native"] and py.meta["control_delay"] == D
    for f in ("x", "u", "s", "theta_hat"):
        np.testing.assert_array_equal(getattr(nat, f), getattr(py, f), err_msg=f)
    assert np.all(py.u[:D] == 0.0)
    lo, hi = s.plant.ctrl_range
    for k in (D, D + 1, 100, 499):
        j = k - D
        computed = s.law(py.t[j], py.x[j], py.ref[j], py.theta_hat[j]).u
        assert py.u[k] == min(max(computed, lo), hi)


def test_critical_leading_estimate_is_where_the_phase_margin_vanishes():
    from adaptive_mj.study.analysis import critical_leading_estimate

    d, k, lam, T = 37.0, 200.0, 20.0, 0.02
    dc = critical_leading_estimate(d, k, lam, T)
    kv, kp = k + dc * lam, k * lam
    w = np.roots([d * d, 0.0, -kv * kv, 0.0, -kp * kp])  # |L(jω)| = 1
    w = float(max(r.real for r in w if abs(r.imag) < 1e-9 and r.real > 0))
    assert abs(math.atan2(w * kv, kp) - w * T) < 1e-9
    assert critical_leading_estimate(d, k, lam, 0.0) == math.inf


def test_sudden_failure_happens_where_the_delay_margin_predicts_and_sigma_prevents_it():
    """heave_sudden_failure (120 s): the drifting d̂/d crosses the predicted critical value, the
    thrust saturates within 1 % of it and the loop fails about 100 s in; with σ-modification
    the same seed does not fail."""
    from adaptive_mj.study.analysis import sudden_failure

    out = {}
    for name, extra in (("plain", []), ("sigma", ["law.sigma=1e-3"])):
        scn = load(SCENARIOS_DIR / "heave_sudden_failure.toml", overrides=["simulation.duration=120", *extra])
        s = build(scn)
        traj = run(s.plant, s.law, s.reference, duration=120.0, theta_hat0=s.theta_hat0, noise_std=s.noise_std,
                   rng=s.rng, control_delay=scn.simulation.control_delay)
        out[name] = sudden_failure(traj, s)
    f = out["plain"]
    assert 80.0 < f["t_saturation"] < f["t_fail"] < 115.0, f
    assert abs(f["ratio_at_saturation"] / f["critical_ratio"] - 1.0) < 0.01, f
    assert out["sigma"]["t_fail"] is None and out["sigma"]["t_saturation"] is None
    assert out["sigma"]["ratio_max"] < 1.2


def test_composite_update_is_its_defining_equation():
    """θ̂' = (sliding law's θ̂') − κ Γ⁻¹ Y_f (Y_f θ̂ − τ_f), with Y_f = [z_a, −z_φ] and τ_f = z_τ the
    filtered per-step a = Δy'/h, φ̄ and τ̄ = f̄ + h̄ u (one step by hand: the filters start at it)."""
    form = heave.heave_form(9.81)
    plain = SlidingAdaptiveLaw(form, lam=5.0, k=200.0, gamma=GAMMA)
    comp = CompositeSlidingLaw(form, lam=5.0, k=200.0, gamma=GAMMA, kappa=0.3, filter_rate=2.0)
    comp.reset()
    rng = np.random.default_rng(11)
    xs = [rng.normal(size=2) for _ in range(4)]
    us = list(rng.normal(size=4) * 50)
    w = [1 / 6, 1 / 3, 1 / 3, 1 / 6]
    h = 0.001
    comp.step_ends(xs, us, w, h)
    x_next = rng.normal(size=2)
    comp.step_begins(x_next)
    a = (x_next[1] - xs[0][1]) / h
    phi_bar = sum(wi * form.phi(x) for wi, x in zip(w, xs, strict=True))
    tau_bar = sum(wi * (form.f(x) + form.h(x) * u) for wi, x, u in zip(w, xs, us, strict=True))
    Yf = np.concatenate(([a], -phi_bar))
    theta, ref = rng.normal(size=3) * 10, rng.normal(size=3)
    expected = plain(0.0, x_next, ref, theta).theta_hat_dot - 0.3 * Yf * (Yf @ theta - tau_bar) / GAMMA
    np.testing.assert_allclose(comp(0.0, x_next, ref, theta).theta_hat_dot, expected, rtol=1e-12, atol=1e-12)

"""Margins that mean stability (issue 52, item 4a): a run also fails when its tail is saturated for more than a
stated share of its rows (success.tail_saturation, the quadrotor's 0.2), or its body rate oscillates (success
.oscillation, the quadrotor's 1 rad/s: the largest spectral line above 1 Hz of Ω over the tail); the verdict says so
and the studies' failure rule (study.job.passes) fails it. Each rule's edge, then the quadrotor's delayed loop."""
from __future__ import annotations

import math

import numpy as np
import pytest

from adaptive_mj.plants import quadrotor
from adaptive_mj.report import metrics as mx
from adaptive_mj.runs.runner import execute
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.success import unstable
from adaptive_mj.study import stress
from adaptive_mj.study.job import RunOutcome, RunSpec, passes
from adaptive_mj.trajectory import Trajectory

DT = 0.01  # [s] the synthetic rows' spacing
N = 2000  # 20 s: a tail of 500 rows


def _traj(omega: np.ndarray | None = None, u: np.ndarray | None = None) -> Trajectory:
    """A quadrotor-shaped trajectory of N rows: x (N, 4, 3) with Ω = omega (N, 3), thrusts u (N, 4) in [0, 0.14]."""
    x = np.zeros((N, 4, 3))
    if omega is not None:
        x[:, 3] = omega
    return Trajectory(t=np.arange(N) * DT, x=x, u=np.full((N, 4), 0.07) if u is None else u, s=np.zeros((N, 3)),
                      ref=np.zeros((N, 5, 3)), theta_hat=np.zeros((N, 1)), theta=np.zeros((N, 1)), V=np.zeros(N),
                      names=("m",), joint_names=("x", "y", "z"), control_names=("r1", "r2", "r3", "r4"),
                      meta={"dt": DT, "ctrl_range": ([0.0] * 4, [0.14] * 4),
                            "state_names": ("p", "v", "phi", "omega")})


def test_the_quadrotor_kind_declares_its_bounds():
    kind = quadrotor.KIND
    assert (kind.tail_saturation, kind.oscillation) == (0.2, 1.0)


@pytest.mark.parametrize("extra, fails", [(0, False), (1, True)])
def test_tail_saturation_s_edge(extra, fails):
    """The tail's rows (499 of 2000 here) with a rotor at a limit: ⌊0.2 n⌋ is at most 20 %, one more is over."""
    tail = mx.tail_mask(_traj())
    n = int(tail.sum())
    saturated = int(math.floor(0.2 * n)) + extra
    u = np.full((N, 4), 0.07)
    rows = np.flatnonzero(tail)[:saturated]
    u[rows, 2] = 0.14  # at T_max
    u[:200, 1] = 0.0  # saturation before the tail counts for nothing
    m = mx.metrics(_traj(u=u))
    assert m["saturation_fraction_tail"] == saturated / n
    missed = unstable(m, 0.2, None)
    assert bool(missed) is fails
    if fails:
        assert missed[0].startswith("time at an actuator limit over the tail 20.")
        assert missed[0].endswith("% > 20 % (success.tail_saturation)")


def test_rate_oscillation_reads_a_sinusoid_s_amplitude_and_leaves_spin_drift_and_manoeuvre_out():
    t = np.arange(N) * DT
    spin_drift = np.stack([0.2 * np.sin(2 * np.pi * 0.16 * t), 0.05 * t, np.full(N, 30.0)], axis=1)  # rad/s
    calm = mx.rate_oscillation(_traj(spin_drift))
    assert calm is not None and calm["amplitude"] < 0.02
    wobble = spin_drift.copy()
    wobble[:, 1] += 2.0 * np.sin(2 * np.pi * 7.0 * t)  # 7 Hz: 35 cycles in the 5 s tail
    osc = mx.rate_oscillation(_traj(wobble))
    assert osc == {"amplitude": pytest.approx(2.0, rel=5e-3), "frequency": pytest.approx(7.0, abs=0.1), "axis": 1}


@pytest.mark.parametrize("amplitude, fails", [(0.99, False), (1.01, True)])
def test_oscillation_s_edge(amplitude, fails):
    t = np.arange(N) * DT
    w = np.zeros((N, 3))
    w[:, 0] = amplitude * np.sin(2 * np.pi * 6.0 * t)
    m = mx.metrics(_traj(w))
    assert m["rate_oscillation_tail"]["amplitude"] == pytest.approx(amplitude, rel=5e-3)
    assert bool(unstable(m, None, 1.0)) is fails


def _outcome(metrics: dict, success: dict) -> RunOutcome:
    return RunOutcome(RunSpec(sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml"), "ok",
                      {"metrics": {"rms_tracking_error_tail": 0.01, **metrics}, "success": success},
                      extras={"flight_metrics": {"max_error": 0.1}})


@pytest.mark.parametrize("share, amp, ok", [(0.2, 1.0, True), (0.2001, 0.5, False), (0.0, 1.0001, False)])
def test_the_studies_failure_rule_reads_the_bounds_the_run_recorded(share, amp, ok):
    r = _outcome({"saturation_fraction_tail": share, "rate_oscillation_tail": {"amplitude": amp, "frequency": 6.0,
                                                                               "axis": 0}},
                 {"tail_saturation": 0.2, "oscillation": 1.0})
    assert passes(r, tail_bound=0.02) is ok and passes(r, max_error=1.0) is ok
    assert passes(r, tail_bound=0.02, stable=False)
    # a run of a kind that declares no bounds (null: not judged) passes whatever its figures
    assert passes(_outcome({"saturation_fraction_tail": 1.0}, {"tail_saturation": 1.0, "oscillation": None}),
                  tail_bound=0.02)


def test_a_scenario_sets_or_switches_off_the_bounds():
    scn = sc.load(sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml",
                  overrides=["success.tail_saturation=0.5", "success.oscillation=inf"])
    assert (scn.success.tail_saturation, scn.success.oscillation) == (0.5, math.inf)
    with pytest.raises(Exception, match="success.tail_saturation"):
        sc.load(sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml", overrides=["success.tail_saturation=1.5"])


@pytest.mark.parametrize("delay, status", [(11, "ok"), (12, "failed")])
def test_the_delayed_attitude_loop_s_limit_cycle_fails_though_its_tail_error_passes(delay, status):
    """The stress study's lemniscate (10 g payload, its noise): at 12 steps of delay the attitude loop settles into a
    saturated limit cycle whose tail RMS error (1.2 cm) is inside the 2 cm bound; it now fails, by both rules."""
    p = next(q for q in stress.plants() if q.name == "quadrotor")
    scn = sc.load(sc.SCENARIOS_DIR / f"{p.scenario}.toml", overrides=[*p.base, f"simulation.control_delay={delay}"],
                  seed=0)
    res = execute(scn)
    m = res.summary["metrics"]
    assert m["rms_tracking_error_tail"] < 0.02
    assert res.summary["status"] == status
    if status == "failed":
        assert "(success.tail_saturation)" in res.summary["reason"] and "(success.oscillation)" in res.summary["reason"]
        assert m["saturation_fraction_tail"] > 0.5 and m["rate_oscillation_tail"]["amplitude"] > 3.0
    else:
        assert m["saturation_fraction_tail"] < 0.01 and m["rate_oscillation_tail"]["amplitude"] < 0.2

"""The flight study's failure rules (adaptive_mj.study.flight.RULES; issue 52, item 5) on hand-filled trajectories:
"ours" (a crash, 1 m of position error at any time, or the stability criteria) and "aqb", AdaptiveQuadBench's own
success rule for its disturbance trials (github.com/valmik/AdaptiveQuadBench at ee7df29,
aqb/experiments/experiment_runner.py: `(df['pos_tracking_error'] < 5).mean()`, the error the RMS of ‖x − x_des‖
over the trajectory, parallel_data_collection.compute_cost; no crash check). The figures each rule reads are
computed from the rows by the study's own analysis (study.analysis.flight_metrics)."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import flight
from adaptive_mj.study.analysis import flight_metrics
from adaptive_mj.study.job import RunOutcome, RunSpec
from adaptive_mj.trajectory import Trajectory

DT = 0.01  # [s] the rows' spacing
N = 500  # 5 s: AdaptiveQuadBench's trial length


def _traj(error: np.ndarray) -> Trajectory:
    """N level, still rows of a quadrotor whose position is the reference's p_d = 0 minus error (N, 3) [m]."""
    x = np.zeros((N, 4, 3))
    x[:, 0] = error  # y_tilde = p_d - p = -error: its norm is ‖error‖
    return Trajectory(t=np.arange(N) * DT, x=x, u=np.full((N, 4), 2.0), s=np.zeros((N, 3)), ref=np.zeros((N, 5, 3)),
                      theta_hat=np.zeros((N, 1)), theta=np.zeros((N, 1)), V=np.zeros(N), names=("m",),
                      joint_names=("x", "y", "z"), control_names=("r1", "r2", "r3", "r4"),
                      meta={"dt": DT, "ctrl_range": ([0.0] * 4, [7.64] * 4), "state_names": ("p", "v", "phi", "omega")})


def _outcome(error: np.ndarray, status: str = "ok") -> RunOutcome:
    """A run that flew these rows, met its stability criteria, and ended with `status`."""
    summary = {"metrics": {"rms_tracking_error_tail": 0.0, "saturation_fraction_tail": 0.0,
                           "rate_oscillation_tail": {"amplitude": 0.0, "frequency": 1.0, "axis": 0}},
               "success": {"tail_saturation": 0.2, "oscillation": 1.0}, "reason": ""}
    return RunOutcome(RunSpec(sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml"), status, summary,
                      extras={"flight_metrics": flight_metrics(_traj(error), None)})


def _steady(e: float) -> np.ndarray:
    """(N, 3) an error of e [m] along x on every row."""
    out = np.zeros((N, 3))
    out[:, 0] = e
    return out


def _spike(e: float) -> np.ndarray:
    """(N, 3) an error of e [m] along z on one row, none on the others."""
    out = np.zeros((N, 3))
    out[N // 2, 2] = e
    return out


def test_the_rules_are_named():
    assert set(flight.RULES) == {"ours", "aqb"} and flight.RULES["ours"] is flight.succeeded
    assert (flight.MAX_ERROR, flight.AQB_RMS_BOUND) == (1.0, 5.0)
    with pytest.raises(ValueError, match="expected one of ours, aqb"):
        flight.rule_of("1m")


@pytest.mark.parametrize("rows, status, ours, aqb", [
    (_steady(0.5), "ok", True, True),  # within both
    (_steady(2.0), "ok", False, True),  # 2 m all along: past 1 m, an RMS of 2 m < 5 m
    (_steady(4.999), "failed", False, True),  # the scenario's own verdict is neither rule's
    (_steady(5.0), "ok", False, False),  # an RMS of exactly 5 m is not below 5 m
    (_spike(3.0), "ok", False, True),  # one row 3 m off: the largest error fails, the RMS (0.13 m) does not
    (_steady(0.1), "crashed", False, True),  # AdaptiveQuadBench checks no crash
    (_steady(0.1), "diverged", False, False),  # no figures of a whole run
])
def test_each_rule_on_hand_filled_rows(rows, status, ours, aqb):
    r = _outcome(rows, status)
    fm = r.extras["flight_metrics"]
    e = np.linalg.norm(rows, axis=1)
    assert fm["rms_error"] == pytest.approx(float(np.sqrt(np.mean(e**2))), rel=1e-12)
    assert fm["max_error"] == pytest.approx(float(e.max()), rel=1e-12)
    assert flight.RULES["ours"](r) is ours
    assert flight.RULES["aqb"](r) is aqb


def test_a_run_that_did_not_run_fails_both():
    r = RunOutcome(RunSpec(sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml"), "error", None, error="no such key")
    assert not flight.RULES["ours"](r) and not flight.RULES["aqb"](r)


def test_the_grid_results_judge_by_the_rule_asked_for():
    """The same grid runs read by either rule: 2 m of steady error passes "aqb" and fails "ours"."""
    (s,) = flight.searches(("geometric",), (flight.DELAY,))
    levels, seeds = 2, 1
    results = {}
    for v in flight.grid(s.disturbance, levels):
        name = f"{s.law}-{s.disturbance.name.replace(' ', '_')}={v:.6g}"
        results[f"{name} seed 0"] = _outcome(_steady(2.0))
    ours = flight.grid_results(flight.searches(("geometric",), (flight.DELAY,)), levels, seeds, results)
    aqb = flight.grid_results(flight.searches(("geometric",), (flight.DELAY,)), levels, seeds, results, rule="aqb")
    assert all(not any(v) for v in ours[0].evaluations.values())
    assert all(all(v) for v in aqb[0].evaluations.values())

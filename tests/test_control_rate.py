"""Sampled-data control as a study: the bench's control-rate section (its predicted stability
figure derived from the compiled models, checked against short runs) and the control period as
a breaking-point stressor (`adaptive-mj stress`, `sweep --breaking-point control.period=LO:HI`),
searched in whole physics steps."""
from __future__ import annotations

import json
import math
import re

import mujoco
import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.study import bench_catalogue, stress
from adaptive_mj.study.breaking_point import TAIL_BOUND, Search, Stressor, _mid, search_all, whole_steps
from adaptive_mj.study.parallel import run_jobs

HEAVE = sc.SCENARIOS_DIR / "heave_tracking.toml"
ARM6 = sc.SCENARIOS_DIR / "ur5e_identification.toml"
BASE = ("simulation.duration=3.0", "simulation.initial_state='reference'", "law.initial_estimates='model'",
        "noise.std={y=0.0005, y_dot=0.005}")


def _is_whole_steps(v: float, dt: float) -> bool:
    return v >= dt and abs(v / dt - round(v / dt)) < 1e-9


# ---------------------------------------------------------------- the bench section
def test_the_predicted_figures_come_from_the_compiled_models():
    """Heave: k/d with d the model's; arm: K_D / M_jj with M from mj_fullM, its smallest diagonal
    entry along the reference, which is at most the entry at the initial pose (computed here
    separately)."""
    heave = bench_catalogue.sampled_loop(HEAVE)
    setup = build(sc.load(HEAVE))
    assert heave.inertia[0] == pytest.approx(setup.plant.true_theta()[0])
    assert heave.gain[0] == sc.load(HEAVE).law.k
    assert heave.figure(0.01)[0] == pytest.approx(sc.load(HEAVE).law.k * 0.01 / setup.plant.true_theta()[0])

    arm = bench_catalogue.sampled_loop(ARM6)
    s = build(sc.load(ARM6))
    model = s.plant.model
    data = mujoco.MjData(model)
    data.qpos[:] = s.plant.data.qpos
    mujoco.mj_forward(model, data)
    M0 = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M0)
    assert np.all(arm.inertia <= np.diag(M0) + 1e-12) and np.all(arm.inertia > model.dof_armature)
    assert arm.names == s.plant.joint_names and len(arm.names) == 6
    fig, joint = arm.figure(0.004)
    j = arm.names.index(joint)
    assert fig == pytest.approx(float(np.max(np.asarray(s.law.kd) * 0.004 / arm.inertia)))
    assert fig == pytest.approx(s.law.kd[j] * 0.004 / arm.inertia[j])
    assert arm.coupled >= arm.rate.max() * (1 - 1e-9)  # λ_max(M⁻¹K_D) ≥ max_j K_D/M_jj (Rayleigh quotient)
    assert np.all(arm.lam == 10.0) and arm.figure_with_surface(0.004) == pytest.approx(fig + 10.0 * 0.004)
    assert heave.figure_with_surface(0.01) == pytest.approx(heave.figure(0.01)[0] + sc.load(HEAVE).law.lam * 0.01)
    assert heave.lowest_stable_rate() == pytest.approx(sc.load(HEAVE).law.k / (2 * heave.inertia[0]))


def test_control_rate_section_on_short_runs(tmp_path):
    """3 s runs: on the 6-joint arm the figure at 100 Hz exceeds 2 and the loop breaks (tail error
    above the study's bound), at 1 kHz it is below 2 and the tail error is small; the heave
    vehicle's figure stays far below 2 and its error does not depend on the rate."""
    section = bench_catalogue._control_rate(False, tmp_path / "logs", duration=3.0)
    assert len(section.jobs) == 2 * len(bench_catalogue.CONTROL_RATES_HZ)
    for job in section.jobs:  # every period a whole number of physics steps, under sampled control
        period = float(next(o for o in job.overrides if o.startswith("control.period=")).split("=")[1])
        assert "control.mode='sampled'" in job.overrides and _is_whole_steps(period, 0.001)
    results = run_jobs(list(section.jobs), n_jobs=2)
    rep = section.analyze({r.job.tag: r for r in results}, tmp_path)
    rows = {(r["plant"], r["rate_hz"]): r for r in rep.rows}
    assert len(rows) == 8

    fast, slow = rows[("ur5e_identification", 1000.0)], rows[("ur5e_identification", 100.0)]
    assert fast["figure"] < 2.0 and fast["predicted_stable"] and fast["holds"]
    assert fast["tail"] < 1e-3 and fast["y_unit"] == "rad" and fast["period"] == pytest.approx(0.001)
    assert slow["figure"] > 2.0 and not slow["predicted_stable"] and not slow["holds"]
    assert slow["tail"] > TAIL_BOUND["arm"] and slow["tail"] > 100 * fast["tail"]
    assert slow["figure"] == pytest.approx(10 * fast["figure"])  # K_D T / M_jj is linear in T
    assert slow["figure_at"] == fast["figure_at"]
    assert rows[("ur5e_identification", 250.0)]["figure"] < 2.0
    assert re.search(r"the sampled pole leaves the unit circle \(\\\|1 − K_D T/M_jj\\\| = [0-9.]+ > 1 at joint "
                     + slow["figure_at"], rep.text)

    heave = [rows[("heave_tracking", rate)] for rate in bench_catalogue.CONTROL_RATES_HZ]
    assert all(r["predicted_stable"] and r["figure"] < 0.1 and r["y_unit"] == "m" for r in heave)
    tails = [r["tail"] for r in heave]
    assert max(tails) / min(tails) < 1.05
    assert (tmp_path / "figures" / "control_rate.png").stat().st_size > 10_000


def test_the_section_is_in_both_benches(tmp_path):
    for quick in (True, False):
        keys = [s.key for s in bench_catalogue.catalogue(quick=quick, logs=tmp_path)]
        i = keys.index("control_rate")  # then the arm's sections; issue 21's (ship, mrac, wing_rock) come after
        assert keys[i:i + 3] == ["control_rate", "arm_drift", "arm_conditions"]


# ---------------------------------------------------------------- the control period as a stressor
def test_a_control_period_stressor_tries_whole_steps_only():
    st = Stressor.control_period(0.0004, 0.9996, 0.001)
    assert (st.lo, st.hi) == (0.001, 1.0)
    assert st.overrides(0.032) == ["control.mode='sampled'", "control.period=0.032"]
    lo, hi, seen = st.lo, st.hi, []
    while round((hi - lo) / st.step) > 1:  # a bisection that always fails at the midpoint
        v = _mid(lo, hi, st)
        assert lo < v < hi and _is_whole_steps(v, 0.001)
        seen.append(v)
        hi = v
    assert seen[0] == 0.032 and hi == 0.002  # sqrt(0.001 * 1.0) = 0.0316 -> 32 steps
    assert whole_steps(0.0004, 0.001) == 0.001 and whole_steps(0.0371, 0.001) == 37 * 0.001


def test_breaking_point_of_the_control_period_brackets_the_sampled_pole(tmp_path):
    """The heave vehicle (k = 200, d = 37 kg from the model), 8 s runs: the bisection over whole steps
    ends with a passing period below a failing one, both whole steps, and the margin lies below the
    sampled pole's bound 2d/k (0.37 s; the hold's lag T/2 breaks the loop before the pole leaves
    the unit circle: measured 0.256 s, next 0.268 s) but within a factor 2 of it. (Runs much shorter
    than 8 s overstate the margin: an unstable loop has too few periods to grow past the bound.)"""
    st = Stressor.control_period(0.001, 1.0, 0.001)
    base = ("simulation.duration=8.0", *BASE[1:])
    (m,) = search_all([Search(HEAVE, "heave/adaptive", base, st, TAIL_BOUND["heave"])], seeds=1, steps=8,
                      logs=tmp_path, n_jobs=2)
    assert m.margin is not None and m.first_fail is not None and m.margin < m.first_fail
    assert m.at(m.margin).passes and not m.at(m.first_fail).passes
    for e in m.evaluations:
        assert _is_whole_steps(e.value, 0.001), e.value
        assert e.passes == (e.value <= m.margin)
    d = float(build(sc.load(HEAVE)).plant.true_theta()[0])
    bound = 2 * d / sc.load(HEAVE).law.k
    assert 0.5 * bound <= m.margin < bound
    assert m.resolution <= 0.02


def test_stress_has_the_control_period_for_every_law_but_composite():
    plants = stress.plants(10.0)
    for p in plants:
        (period,) = [s for s in stress.stressors(p, 10.0) if s.name == stress.PERIOD]
        dt = float(stress._setup(p)[1].plant.dt)  # whole physics steps: 1 ms, the quadrotor's 2 ms
        assert period.step == dt and period.lo == dt and period.hi == stress.PERIOD_MAX
        assert period.unit == "s" and period.overrides(0.25) == ["control.mode='sampled'", "control.period=0.25"]
    short = [s for s in stress.stressors(plants[0], 0.5) if s.name == stress.PERIOD][0]
    assert short.hi == 0.5  # never longer than the run
    searches = stress.study(composite=True, duration=10.0)
    with_period = {s.label for s in searches if s.stressor.name == stress.PERIOD}
    assert with_period and not any(label.endswith(("/composite", "/l1_geometric")) for label in with_period)
    assert {s.label for s in searches if s.label.endswith("/composite")}  # composite keeps its other stressors


def test_sweep_breaking_point_on_the_control_period(tmp_path, capsys):
    out = tmp_path / "bp"
    assert main(["sweep", "heave_tracking", "--breaking-point", "control.period=0.0004:1.0004", "--tail-bound",
                 "0.01", "--seeds", "1", "--steps", "4", "--set", "simulation.duration=3",
                 "--set", "simulation.initial_state='reference'", "--set", "law.initial_estimates='model'",
                 "-o", str(out), "--jobs", "2"]) == 0
    record = json.loads((out / "breaking_point.json").read_text())
    assert (record["lo"], record["hi"], record["step"], record["integer"]) == (0.001, 1.0, 0.001, False)
    assert 0.001 <= record["margin"] < record["first_fail"] <= 1.0
    assert all(_is_whole_steps(e["value"], 0.001) for e in record["evaluations"])
    assert not any("refused" in e["statuses"] for e in record["evaluations"])  # past the pre-flight limit: run too
    assert len(record["evaluations"]) == 6 and len(list((out / "logs").rglob("*.mcap"))) == 6
    captured = capsys.readouterr()
    assert "control.period rounded to whole physics steps of 0.001 s: [0.001, 1] s" in captured.err
    assert "control.period: margin" in captured.out
    assert math.isfinite(record["tail_mean"])


def test_sweep_control_period_that_rounds_to_one_step_is_refused(tmp_path, capsys):
    assert main(["sweep", "heave_tracking", "--breaking-point", "control.period=0.0011:0.0014", "--tail-bound",
                 "0.01", "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "round to the same whole number of physics steps" in err[0], err

"""The flight study on both airframes and AdaptiveQuadBench's delay test (issue 52, item 5; adaptive_mj.study.flight):
the searches on AdaptiveQuadBench's vehicle built on its task, model and gains, with the disturbances' ranges scaled
from the Crazyflie's by quantities read here from the two compiled models with MuJoCo's own arrays; the delay test's
levels, bound, runs and scan as AdaptiveQuadBench defines them, its verdicts on hand-filled outcomes. No run flies.

The numbers typed here are AdaptiveQuadBench's (github.com/valmik/AdaptiveQuadBench at ee7df29):
- aqb/experiments/experiment_runner.py:321-322 (num_trajectories = 5) and 342-352, compute_delay_margin(...,
  initial_delay=0.0, max_delay=0.5, delay_step=0.01, test_duration=5.0, position_threshold=1.0);
- aqb/utils/delay_analysis.py:89-128 (generate_random_trajectories: HoverTraj, CircularTraj radius 2, then rapid
  trajectories at difficulty (i + 1)/(n − 2) with goal ranges 2 + 2d [m], 1 + 2d [m/s], 0.5 + 1.5d [m/s²], the
  goal's z made positive) and 205-225 (unstable when max ‖x − x_des‖ > threshold; the margin is that delay less one
  step; the scan stops there);
- aqb/quad_param/quadrotor.py:7 (mass 0.826 kg); aqb/controller/geometric_control.py, GeoControl.__init__'s last
  self.k (k_x = (5, 5, 10), k_v = (4, 4, 8), k_R = 0.3, k_W = 0.03)."""
from __future__ import annotations

import math
import tomllib

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants.quadrotor import DISTURBANCES
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import flight
from adaptive_mj.study.job import RunOutcome, RunSpec

# AdaptiveQuadBench at ee7df29
MASS = 0.826  # [kg]
KX, KV, KR, KW = [5.0, 5.0, 10.0], [4.0, 4.0, 8.0], 0.3, 0.03
DELAY_START, DELAY_STOP, DELAY_STEP = 0.0, 0.5, 0.01  # [s]
DELAY_DURATION, DELAY_BOUND, TRAJECTORIES = 5.0, 1.0, 5  # [s], [m], hover + circle + 3 rapid
PHYSICS_DT = 0.002  # [s] this suite's step (the scenarios' simulation.timestep, checked below)


def _numbers(scenario: str) -> dict[str, float]:
    """A scenario's vehicle read with MuJoCo's arrays (its plant.model compiled bare): weight [N], spare lift [kg]
    (Σ ctrlrange upper − m g)/g, roll authority [N m] (the largest upper thrust times its site's |y|)."""
    with open(sc.SCENARIOS_DIR / f"{scenario}.toml", "rb") as f:
        name = tomllib.load(f)["plant"].get("model", "quadrotor")
    model = mujoco.MjModel.from_xml_path(str(sc.SCENARIOS_DIR.parent / "models" / f"{name}.xml"))
    quad = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "quad")
    m, g = float(model.body_subtreemass[quad]), float(-model.opt.gravity[2])
    tmax = model.actuator_ctrlrange[:, 1]
    y = np.array([abs(model.site_pos[model.actuator_trnid[a, 0], 1]) for a in range(model.nu)])
    return {"mass": m, "weight": m * g, "spare lift": (float(tmax.sum()) - m * g) / g,
            "roll authority": float(np.max(tmax * y))}


def test_the_aqb_airframe_flies_its_own_task_model_and_gains():
    aqb = flight.VEHICLES["aqb"]
    assert aqb.scenario == "quadrotor_aqb_lemniscate"
    assert _numbers(aqb.scenario)["mass"] == pytest.approx(MASS, rel=1e-12)
    for s in flight.searches(airframe="aqb"):
        job = flight._jobs(s, s.disturbance.lo, 1, sc.SCENARIOS_DIR, ())[0]
        assert job.scenario.name == "quadrotor_aqb_lemniscate.toml"
        scn = sc.load(job.scenario, overrides=job.overrides)
        assert scn.plant.model.name == "quadrotor_aqb.xml" and scn.law.kind == s.law
        assert scn.simulation.duration == flight.RUN_SECONDS and scn.plant.payload in (None, "quad_box")
        p = scn.law.params or {}
        if s.law == "geometric_adaptive":
            assert (list(p["lambda"]), list(p["k"])) == ([x / v for x, v in zip(KX, KV, strict=True)], KV)
        else:
            assert (list(p["kx"]), list(p["kv"])) == (KX, KV)
        assert (p["kR"], p["kW"]) == (KR, KW)


def test_the_crazyflie_s_searches_are_issue_33_s():
    found = flight.searches()
    assert {s.airframe for s in found} == {"crazyflie"}
    assert [s.disturbance for s in found[::3]] == [*DISTURBANCES, flight.DELAY]
    job = flight._jobs(found[0], 1.0, 1, sc.SCENARIOS_DIR, ())[0]
    assert job.scenario.name == "quadrotor_lemniscate.toml" and "law=geometric" in job.overrides
    assert job.tag == "geometric-wind=1 seed 0"  # the Crazyflie's names are kept (the bench's section reads them)


def test_the_aqb_airframe_s_ranges_scale_with_the_compiled_vehicles():
    mine, ref = _numbers("quadrotor_aqb_lemniscate"), _numbers("quadrotor_lemniscate")
    ratio = {"wind": 1.0, "rotor loss": 1.0, "force": mine["weight"] / ref["weight"],
             "payload": mine["spare lift"] / ref["spare lift"],
             "torque": mine["roll authority"] / ref["roll authority"]}
    got = {s.disturbance.name: s.disturbance for s in flight.searches(airframe="aqb")}
    assert set(got) == {d.name for d in DISTURBANCES} | {flight.DELAY.name}
    for d in DISTURBANCES:
        assert (got[d.name].lo, got[d.name].hi) == pytest.approx((d.lo * ratio[d.name], d.hi * ratio[d.name]),
                                                                 rel=1e-9), d.name
    assert ratio["force"] == pytest.approx(MASS / 0.030, rel=1e-9)  # the Crazyflie's 30 g
    assert got["payload"].hi < mine["spare lift"]  # the range stops below what the rotors can lift, as on the Crazyflie
    assert got["force"].overrides(2.5) == ["events=[{t=0.0, kind='external_force', force=[2.5, 0.0, 0.0]}]"]
    assert got["delay"] is flight.DELAY


def test_the_airframes_runs_do_not_share_names():
    tags = {j.tag for frame in flight.VEHICLES for s in flight.searches(airframe=frame)
            for j in flight._jobs(s, s.disturbance.hi, 2, sc.SCENARIOS_DIR, ())}
    assert len(tags) == 2 * 3 * 6 * 2


def test_the_delay_test_is_aqb_s():
    t = flight.AQB_DELAY_TEST
    levels = t.levels()
    assert len(levels) == 51 and levels[0] == DELAY_START and levels[-1] == DELAY_STOP
    np.testing.assert_allclose(np.diff(levels), DELAY_STEP, rtol=0, atol=1e-12)
    assert (t.duration.number, t.bound.number, int(t.trajectories.number)) == (DELAY_DURATION, DELAY_BOUND,
                                                                               TRAJECTORIES)
    rec = t.record()
    runner = "valmik/AdaptiveQuadBench@ee7df29:aqb/experiments/experiment_runner.py"
    assert rec["step"]["source"] == f"{runner}:349" and rec["bound"]["source"].startswith(f"{runner}:351")
    assert (flight.AQB_DELAY.lo, flight.AQB_DELAY.hi, flight.AQB_DELAY.step) == (DELAY_START, DELAY_STOP, DELAY_STEP)
    with open(sc.SCENARIOS_DIR / "quadrotor_aqb_lemniscate.toml", "rb") as f:
        assert tomllib.load(f)["simulation"]["timestep"] == PHYSICS_DT
    assert flight.AQB_DELAY.overrides(0.01) == ["simulation.control_delay=5"]  # 10 ms = 5 steps of 2 ms
    assert flight.AQB_DELAY.overrides(0.5) == ["simulation.control_delay=250"]


@pytest.mark.parametrize("seed", [0, 1, 7])
def test_the_delay_test_s_trajectories(seed):
    refs = flight.AQB_DELAY_TEST.references(seed)
    assert [n for n, _ in refs] == ["hover", "circle", "rapid1", "rapid2", "rapid3"]
    goals = flight.AQB_DELAY_TEST.rapid_goals(seed)
    assert goals == flight.AQB_DELAY_TEST.rapid_goals(seed) != flight.AQB_DELAY_TEST.rapid_goals(seed + 1)
    for i, (p, v, a) in enumerate(goals):
        d = (i + 1) / (TRAJECTORIES - 2)
        assert max(map(abs, p)) <= 2 + 2 * d and p[2] >= 0
        assert max(map(abs, v)) <= 1 + 2 * d and max(map(abs, a)) <= 0.5 + 1.5 * d
    jobs = flight.delay_jobs("aqb", "geometric", 0.03, range(2), sc.SCENARIOS_DIR)
    assert len(jobs) == 2 * TRAJECTORIES
    scn = sc.load(jobs[TRAJECTORIES + 4].scenario, overrides=jobs[TRAJECTORIES + 4].overrides)
    assert scn.plant.model.name == "quadrotor_aqb.xml" and scn.simulation.control_delay == 15
    assert scn.simulation.duration == DELAY_DURATION and scn.reference.kind == "motion_primitive"
    assert scn.plant.kind_spec.crash_tilt == 180.0  # RotorPy's runs go on (terminate=False): no tilt ends one
    assert scn.reference.params["position"] == pytest.approx(flight.AQB_DELAY_TEST.rapid_goals(1)[2][0])
    circle = sc.load(jobs[1].scenario, overrides=jobs[1].overrides).reference
    assert circle.kind == "lemniscate" and circle.params["amplitude"] == 2.0
    assert circle.params["omega"] == pytest.approx(2 * math.pi * 0.2)


def _outcome(max_error: float, status: str = "ok") -> RunOutcome:
    """A run with this largest position error [m] (RMS the same), stable, ended with `status`."""
    summary = {"metrics": {"saturation_fraction_tail": 0.0,
                           "rate_oscillation_tail": {"amplitude": 0.0, "frequency": 1.0, "axis": 0}},
               "success": {"tail_saturation": 0.2, "oscillation": 1.0}, "reason": ""}
    return RunOutcome(RunSpec(sc.SCENARIOS_DIR / "quadrotor_aqb_lemniscate.toml"), status, summary,
                      extras={"flight_metrics": {"max_error": max_error, "rms_error": max_error}})


@pytest.mark.parametrize("e, status, aqb, ours", [
    (0.99, "ok", True, True), (1.0, "ok", True, True),  # the bound itself is stable (unstable: > 1 m)
    (1.01, "ok", False, False), (4.0, "ok", False, False),  # past 1 m: unstable, though the RMS rule passes 4 m
    (0.5, "crashed", True, False),  # no crash check in AdaptiveQuadBench's test
    (float("nan"), "ok", False, False), (0.1, "error", False, False)])
def test_the_delay_test_s_rule(e, status, aqb, ours):
    r = _outcome(e, status)
    assert flight.DELAY_RULES["aqb"](r) is aqb and flight.DELAY_RULES["ours"](r) is ours


def test_the_scan_fails_every_delay_past_a_trajectory_s_first_failure():
    levels = [0.0, 0.01, 0.02, 0.03]
    ok, bad = _outcome(0.2), _outcome(3.0)
    outcomes = {0.0: [ok, ok], 0.01: [ok, bad], 0.02: [ok, ok], 0.03: [ok, None]}
    got = flight.scan_results(levels, outcomes, flight.DELAY_RULES["aqb"])
    assert got == {0.0: [True, True], 0.01: [True, False], 0.02: [True, False], 0.03: [True, False]}
    s = flight.Search("geometric", flight.AQB_DELAY, got, airframe="aqb")
    assert flight.scan_margins(s, DELAY_STEP) == [0.03, 0.0]  # none failed: the last delay; else first fail − step
    assert s.margin() == (0.0, 0.01) and s.when2fail() == (0.03, None)


def test_the_delay_test_raises_each_trajectory_s_delay_until_it_fails(monkeypatch):
    """A fake run: trajectory j (seed-major) goes unstable (max error 3 m) from delay 0.01·(j + 1) s on; under the
    rule "ours" one also crashes a step earlier. The test asks for no run past a trajectory's failure under every
    rule, and stops when all have failed."""
    from adaptive_mj.study import parallel

    asked: list[tuple[str, float]] = []

    def run_jobs(jobs, *, n_jobs=1, backend=None):
        out = []
        for j in jobs:
            v = round(int(next(o for o in j.overrides if o.startswith("simulation.control_delay="))
                          .split("=")[1]) * PHYSICS_DT, 12)
            col = [n for n, _ in flight.AQB_DELAY_TEST.references(j.seed)].index(j.tag.split("-")[-1].split("=")[0])
            col += TRAJECTORIES * j.seed
            asked.append((j.tag, v))
            first = 0.01 * (col + 1)
            out.append(_outcome(3.0 if v >= first - 1e-12 else 0.2,
                                "crashed" if col == 0 and v >= first - 0.01 - 1e-12 else "ok"))
        return out

    monkeypatch.setattr(parallel, "run_jobs", run_jobs)
    found = flight.delay_test(["geometric"], airframe="crazyflie", seeds=1, logs=sc.SCENARIOS_DIR)
    aqb, ours = found["aqb"][0], found["ours"][0]
    assert flight.scan_margins(aqb, DELAY_STEP) == [0.0, 0.01, 0.02, 0.03, 0.04]
    # under "ours" trajectory 0 crashed at 0 s: AdaptiveQuadBench's margin, the first failure less one step, is −0.01
    assert flight.scan_margins(ours, DELAY_STEP) == [-0.01, 0.01, 0.02, 0.03, 0.04]
    assert aqb.margin() == (0.0, 0.01) and aqb.when2fail() == (0.04, 0.05)
    assert max(v for _, v in asked) == 0.05  # the last trajectory's first failure: then every one has failed
    assert len(asked) == sum(range(2, 7))  # trajectory j is run at 0 .. its failure: j + 2 delays
    assert {s.airframe for s in found["aqb"]} == {"crazyflie"}


def test_the_rule_aqb_flies_its_runs_on_as_aqb_s_do(monkeypatch):
    """The rule "aqb"'s bisection runs (flight.RULE_RUNS): no tilt ends one and the task starts out of a free fall's
    reach of the ground over the run (AdaptiveQuadBench has no ground, and RotorPy's runs go on); the rule "ours"'s
    runs are the task's own; the two go under different labels (no run shared between different overrides)."""
    from adaptive_mj.study import breaking_point

    seen = []

    def search_all(probes, **kw):
        seen.extend(probes)
        return [breaking_point.Margin(p, None, None) for p in probes]

    monkeypatch.setattr(breaking_point, "search_all", search_all)
    found = flight.searches(["geometric"], airframe="aqb")[:1]
    out = flight.margins_by_rule(found, rules=("ours", "aqb"), seeds=1, steps=0, logs=sc.SCENARIOS_DIR)
    assert set(out) == {"ours", "aqb"} and [len(v) for v in out.values()] == [1, 1]
    ours, aqb = seen[0], seen[2]
    assert (ours.label, aqb.label) == ("aqb-geometric", "aqb-geometric-aqb-runs")
    for probe, lifted in ((ours, False), (aqb, True)):
        scn = sc.load(probe.scenario, overrides=probe.overrides)
        z, tilt = scn.reference.params["center"][2], scn.plant.kind_spec.crash_tilt
        assert (z > 0.5 * 9.81 * flight.RUN_SECONDS ** 2, tilt == 180.0) == (lifted, lifted)

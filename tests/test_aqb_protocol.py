"""AdaptiveQuadBench's protocol (issue 52, item 5; adaptive_mj.study.flight): its randomisation ranges read from one
declaration (flight.AQB) and recorded in the study's output, the seeded sampler (draw_task) deterministic per seed
and inside the ranges, the random motion primitive (adaptive_mj.reference.MotionPrimitive) meeting its end
conditions, the point payload event, and short runs of drawn tasks on AdaptiveQuadBench's vehicle.

The numbers typed here are AdaptiveQuadBench's (github.com/valmik/AdaptiveQuadBench at ee7df29,
aqb/config/randomization_config.py and aqb/quad_param/quadrotor.py), read from its code, not from the module."""
from __future__ import annotations

import dataclasses
import json
import math
import tomllib

import mujoco
import numpy as np
import pytest

from adaptive_mj.reference import MotionPrimitive
from adaptive_mj.study import flight
from adaptive_mj.study.api import run_scenario

# AdaptiveQuadBench at ee7df29
MASS, ARM = 0.826, 0.166  # [kg], [m] aqb/quad_param/quadrotor.py 'mass', d
GOAL = (-2.0, 2.0)  # traj_pos_range, traj_vel_range, traj_acc_range [m, m/s, m/s²]
T_TRAJ = 5.0  # traj_time [s]
PAYLOAD_CAP, OFFSET = 2.0, 0.2  # min(2.0, intensity) x mass; payload_offset_ratio_range (-0.2, 0.2) x arm
EFFICIENCY_CAP = 0.6  # max(-0.6, -intensity), min(0.6, intensity)
TOGGLES, WINDOW, GAP = (1, 4), (0.5, 4.5), 0.5  # randint(1, 5); uniform(0.5, 5 - 0.5); min_toggle_interval
SEEDS = range(200)


def test_the_ranges_come_from_one_declaration_with_their_sources():
    rec = flight.AQB.record()
    assert rec["vehicle_mass"]["value"] == MASS and rec["arm_length"]["value"] == ARM
    for name in ("trajectory_position", "trajectory_velocity", "trajectory_acceleration"):
        assert rec[name]["value"] == list(GOAL)
    assert rec["trajectory_time"]["value"] == T_TRAJ
    assert rec["payload_mass_cap"]["value"] == PAYLOAD_CAP and rec["payload_offset"]["value"] == [-OFFSET, OFFSET]
    assert rec["rotor_efficiency_cap"]["value"] == EFFICIENCY_CAP
    assert rec["toggles"]["value"] == list(TOGGLES) and rec["toggle_window"]["value"] == list(WINDOW)
    assert rec["toggle_gap"]["value"] == GAP and rec["success_rms"]["value"] == 5.0
    for name, r in rec.items():
        if name != "ours":  # every figure cites AdaptiveQuadBench's file and lines at the commit read
            assert r["source"].startswith("valmik/AdaptiveQuadBench@ee7df29:aqb/"), name
            assert r["source"].rsplit(":", 1)[1][0].isdigit(), name
    assert any("Dryden" in line for line in rec["ours"])  # what we do instead of its gusts is said


def test_the_study_output_records_the_ranges_and_is_json():
    found = flight.protocol_results(["geometric"], ["wind"], [0.0, 1.0], 2, {}, rule="aqb")
    out = json.loads(json.dumps(flight.protocol_output({"aqb": found}, seeds=2, levels=[0.0, 1.0])))
    assert out["format"] == 2 and out["randomization"]["payload_mass_cap"]["value"] == PAYLOAD_CAP
    assert out["randomization"]["toggle_window"]["source"].endswith("randomization_config.py:323,356")
    assert out["rules"]["aqb"]["curves"][0]["success_rate"] == [0.0, 0.0]  # no runs: every seed fails
    text = flight.protocol_text()
    assert "payload_offset: (-0.2, 0.2) × arm length" in text and "randomization_config.py:78,306-307" in text


def test_the_sampler_reads_the_declaration():
    """A declaration with other ranges draws inside those: the sampler has no copy of its own."""
    aqb = flight.AQB
    narrow = dataclasses.replace(aqb, payload_mass_cap=dataclasses.replace(aqb.payload_mass_cap, value=0.5),
                                 trajectory_position=dataclasses.replace(aqb.trajectory_position, value=(0.25, 0.5)))
    d = flight.draw_task(7, "payload", 3.0, narrow)
    assert d.payload_mass == pytest.approx(0.5 * MASS)
    assert all(0.25 <= x <= 0.5 for x in d.position)


def test_same_seed_same_draw_and_seeds_differ():
    a, b = flight.draw_task(11, "force", 2.0), flight.draw_task(11, "force", 2.0)
    assert a == b and a.overrides() == b.overrides()
    draws = [flight.draw_task(k, "wind", 1.0) for k in range(20)]
    assert len({d.position for d in draws}) == 20 and len({d.wind_direction for d in draws}) == 20
    assert len({d.toggles for d in draws}) == 20


def test_a_seed_draws_the_same_trajectory_and_timing_at_every_intensity():
    lo, hi = flight.draw_task(5, "rotor_efficiency", 0.1), flight.draw_task(5, "rotor_efficiency", 7.0)
    assert (lo.position, lo.velocity, lo.acceleration, lo.toggles, lo.wind_direction) == \
           (hi.position, hi.velocity, hi.acceleration, hi.toggles, hi.wind_direction)
    # the factors' deviations scale from 0.1 to the cap 0.6: the same draw u, 1 + c u
    np.testing.assert_allclose(np.subtract(hi.rotor_factors, 1.0), 6.0 * np.subtract(lo.rotor_factors, 1.0),
                               rtol=1e-12)


@pytest.mark.parametrize("intensity", [0.0, 0.3, 1.5, 10.0])
def test_draws_stay_inside_the_ranges(intensity):
    c, ratio = min(intensity, EFFICIENCY_CAP), min(intensity, PAYLOAD_CAP)
    counts = set()
    for k in SEEDS:
        d = flight.draw_task(k, "payload", intensity)
        for v in (*d.position, *d.velocity, *d.acceleration):
            assert GOAL[0] <= v <= GOAL[1]
        assert TOGGLES[0] <= len(d.toggles) <= TOGGLES[1]
        counts.add(len(d.toggles))
        assert list(d.toggles) == sorted(d.toggles)
        assert all(WINDOW[0] <= t <= WINDOW[1] for t in d.toggles)
        assert all(b - a >= GAP for a, b in zip(d.toggles, d.toggles[1:], strict=False))
        assert math.isclose(math.hypot(*d.wind_direction), 1.0, rel_tol=1e-12)
        assert all(1.0 - c <= f <= 1.0 + c for f in d.rotor_factors)
        assert d.payload_mass == pytest.approx(ratio * MASS, rel=1e-12)
        assert all(abs(o) <= OFFSET * ARM for o in d.payload_offset)
    assert counts == {1, 2, 3, 4}


def test_force_switches_on_and_off_at_the_drawn_times():
    d = flight.draw_task(3, "force", 2.0)
    events = next(o for o in d.overrides() if o.startswith("events="))
    assert events.count("external_force") == len(d.toggles)
    for k, t in enumerate(d.toggles):  # off at t = 0: on at the first switch, off at the second, ...
        v = 2.0 if k % 2 == 0 else -2.0
        assert f"{{t={t!r}, kind='external_force', force=[{v!r}, {v!r}, {v!r}]}}" in events


def test_the_motion_primitive_meets_its_ends():
    ref = MotionPrimitive(center=(0.5, -1.0, 3.0), position=(1.0, -2.0, 0.5), velocity=(2.0, 0.0, -1.0),
                          acceleration=(-2.0, 1.0, 0.25), duration=4.0)
    start, end = ref(0.0, 2), ref(4.0, 2)
    np.testing.assert_allclose(start, [[0.5, -1.0, 3.0], [0, 0, 0], [0, 0, 0]], atol=1e-12)
    np.testing.assert_allclose(end, [[1.5, -3.0, 3.5], [2.0, 0.0, -1.0], [-2.0, 1.0, 0.25]], atol=1e-9)
    np.testing.assert_allclose(ref(-1.0, 3), [[0.5, -1.0, 3.0], [0, 0, 0], [0, 0, 0], [0, 0, 0]], atol=0)
    # each derivative the central difference of the one below it, inside and past the end
    h = 1e-5
    for t in (0.7, 2.9, 5.5):
        d = ref(np.array([t - h, t, t + h]), 4)
        for k in range(4):
            np.testing.assert_allclose((d[k, 2] - d[k, 0]) / (2 * h), d[k + 1, 1], rtol=1e-6, atol=1e-6)
    # past the end: on at the end's velocity and acceleration
    np.testing.assert_allclose(ref(5.0, 0)[0], [1.5 + 2.0 - 1.0, -3.0 + 0.5, 3.5 - 1.0 + 0.125], atol=1e-9)


def test_a_point_payload_moves_the_vehicle_s_centre_of_mass():
    """After payload_point (m at offset r from the vehicle's centre of mass), the vehicle's subtree has mass M + m
    and its centre of mass at m r / (M + m) from the bare vehicle's, by MuJoCo's own sums."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build

    m, r = 0.4, (0.02, -0.03, 0.01)
    scn = sc.load(sc.SCENARIOS_DIR / f"{flight.PROTOCOL_TASK}.toml", overrides=["plant.payload='quad_box'"])
    plant = build(scn).plant
    plant.set_payload_point("payload/body", m, r)
    model, data = plant.model, mujoco.MjData(plant.model)
    mujoco.mj_forward(model, data)
    quad = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "quad")
    assert model.body_subtreemass[quad] == pytest.approx(MASS + m, rel=1e-12)
    np.testing.assert_allclose(data.subtree_com[quad] - data.xipos[quad], np.multiply(r, m / (MASS + m)), atol=1e-12)


@pytest.mark.parametrize("law", flight.LAWS)
def test_every_law_tracks_a_drawn_primitive_for_a_second(law):
    d = flight.draw_task(1, "wind", 0.0)
    res = run_scenario(flight.PROTOCOL_TASK, set=[*flight.PROTOCOL_GAINS[law], *d.overrides(),
                                                  "simulation.duration=1.0"])
    assert res.status == "ok", res.summary["reason"]
    assert float(np.max(np.linalg.norm(res.trajectory.y_tilde, axis=1))) < 0.02  # [m] on a 0.33 m arm's vehicle


def test_a_drawn_payload_switched_on_within_a_second_is_carried():
    """A payload task whose first switch falls before 1 s: the vehicle's true mass becomes M + the drawn mass, and
    the adaptive law keeps it flying (no crash), falling less than it would without reacting."""
    k = next(k for k in range(100) if flight.draw_task(k, "payload", 1.0).toggles[0] < 0.6)
    d = flight.draw_task(k, "payload", 1.0)
    res = run_scenario(flight.PROTOCOL_TASK, set=[*flight.PROTOCOL_GAINS["geometric_adaptive"],
                                                  *d.overrides(until=1.0), "simulation.duration=1.0"])
    assert res.status in ("ok", "failed"), res.summary["reason"]  # completed: not crashed, not diverged
    assert res.trajectory.t[-1] > 0.99
    assert res.trajectory.theta[-1, 0] == pytest.approx(MASS + MASS, rel=1e-9)  # intensity 1: the vehicle's mass
    assert res.trajectory.theta[0, 0] == pytest.approx(MASS, rel=1e-9)  # off until the first switch
    tr = res.trajectory
    before = tr.t < d.toggles[0]
    assert float(np.max(np.linalg.norm(tr.y_tilde[before], axis=1))) < 0.02  # [m] tracking until the switch
    # after it, the doubled weight pulls the vehicle down: less than an open-loop fall at the unbalanced
    # acceleration g m/(M + m) from the switch to the end would (½ a τ²)
    fall = 0.5 * 9.81 * 0.5 * (1.0 - d.toggles[0]) ** 2
    assert float(np.max(np.linalg.norm(tr.y_tilde, axis=1))) < fall


def test_no_drawn_primitive_reaches_the_ground():
    """The task's primitive starts at rest at reference.center; the lowest point any goal in AdaptiveQuadBench's box
    can reach is the start minus 2 × max_t Σ|basis(t)| (z is linear in the goal's position, velocity and
    acceleration, each in [−2, 2]), the basis quintics solved by hand from their end conditions (each at t = T one of
    p, v, a equal to 1, the others 0; at rest at t = 0): clear of the ground by more than the vehicle's size."""
    task = flight.sc.SCENARIOS_DIR / f"{flight.PROTOCOL_TASK}.toml"
    center = tomllib.loads(task.read_text())["reference"]["center"]
    t, T = np.linspace(0.0, T_TRAJ, 5001), T_TRAJ
    s = t / T  # the minimum-jerk quintic with one end condition at 1, the others 0 (start at rest)
    p_basis = 10 * s**3 - 15 * s**4 + 6 * s**5
    v_basis = T * (-4 * s**3 + 7 * s**4 - 3 * s**5)
    a_basis = T**2 * (0.5 * s**3 - s**4 + 0.5 * s**5)
    lowest = center[2] - 2.0 * float(np.max(np.abs(p_basis) + np.abs(v_basis) + np.abs(a_basis)))
    assert lowest > 0.3  # [m]: the 0.33 m vehicle's half-span and a tracking error
    # the reference is these quintics: goal position along x, velocity along y, acceleration along z
    ref = MotionPrimitive(center=(0.0, 0.0, 0.0), position=(1.0, 0.0, 0.0), velocity=(0.0, 1.0, 0.0),
                          acceleration=(0.0, 0.0, 1.0), duration=T)(t, 0)[0]
    np.testing.assert_allclose(ref, np.stack([p_basis, v_basis, a_basis], axis=1), atol=1e-9)


def test_a_point_payload_on_a_cable_is_refused_before_the_run():
    from adaptive_mj.errors import ScenarioError

    with pytest.raises(ScenarioError, match="payload_point makes a rigid payload a point mass"):
        run_scenario(flight.PROTOCOL_TASK, set=["plant.payload='quad_cable'", "simulation.duration=0.1",
                                                "events=[{t=0.0, kind='payload_point', value=0.1, offset=[0, 0, 0]}]"])

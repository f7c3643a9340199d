"""AdaptiveQuadBench's protocol in adaptive_mj.study.flight (issue 52), pinned by the numbers its source states and
by hand (issue 54's habit: tools/mutate.py flight_protocol): the rule "aqb" at its edges, the cited constants, the
vehicles' sizes, the delay test's levels and rapid goals, the draw's switches and rotor factors, and a task's
overrides. No run flies."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.study import flight
from adaptive_mj.study.job import RunOutcome, RunSpec


def _outcome(status: str, rms: object = None, metrics: bool = True) -> RunOutcome:
    extras = {"flight_metrics": {"rms_error": rms} if metrics else None}
    return RunOutcome(RunSpec(Path("x.toml")), status, None, extras)


@pytest.mark.parametrize("status, rms, metrics, ok", [
    ("ok", 4.99, True, True), ("ok", 5.0, True, False), ("ok", 6.0, True, False),  # strictly below 5 m
    ("failed", 1.0, True, True),  # a completed run that missed our criteria: AQB judges only its RMS
    ("crashed", 1.0, True, True),  # no crash check in AdaptiveQuadBench
    ("crashed", 7.0, True, False), ("diverged", 1.0, True, False), ("error", 1.0, True, False),
    ("refused", 1.0, True, False), ("interrupted", 1.0, True, False),
    ("ok", None, True, False), ("ok", float("nan"), True, False), ("ok", float("inf"), True, False),
    ("ok", None, False, False),  # no flight_metrics at all
])
def test_the_rule_aqb_at_its_edges(status, rms, metrics, ok):
    assert flight.aqb_succeeded(_outcome(status, rms, metrics)) is ok


def test_the_protocol_s_constants_are_adaptivequadbench_s():
    """The figures of aqb/config/randomization_config.py and config_manager.py at ee7df29, typed here from the
    source (the declaration is the specification: its numbers are stated, not recomputed)."""
    p = flight.AQB
    assert p.wind_speed.number == 1.0 and p.wind_direction.range == (-1.0, 1.0)
    assert p.wind_sigma.range == (30.0, 60.0)
    assert p.force.number == 1.0 and p.torque.number == 1.0
    assert p.rotor_efficiency_cap.number == 0.6 and p.payload_mass_cap.number == 2.0
    assert p.payload_offset.range == (-0.2, 0.2)
    assert p.toggles.range == (1.0, 4.0) and p.toggle_window.range == (0.5, 4.5) and p.toggle_gap.number == 0.5
    assert p.intensity_step.number == 1.0 and p.max_intensity.number == 10.0 and p.success_rms.number == 5.0
    assert p.trajectory_time.number == 5.0
    t = flight.AQB_DELAY_TEST
    assert t.sim_rate.number == 100.0 and t.circle_frequency.number == 0.2
    assert t.rapid_position.range == (2.0, 2.0) and t.rapid_velocity.range == (1.0, 2.0)
    assert t.rapid_acceleration.range == (0.5, 1.5)


def test_each_vehicle_s_size_from_its_compiled_airframe():
    """weight m g [N], spare lift (Σ T_max − m g)/g [kg] and roll authority max T_max,i |y_i| [N m], from the
    airframe's arrays with the model's gravity, against _size."""
    from adaptive_mj.plants import quadrotor
    from adaptive_mj.setup import scenario as sc

    for task in ("quadrotor_lemniscate", "quadrotor_aqb_lemniscate"):
        model = str(sc.load(sc.SCENARIOS_DIR / f"{task}.toml", overrides=("plant.payload='none'",)).plant.model)
        plant = quadrotor.load(model)
        frame, g = plant.airframe, -float(plant.model.opt.gravity[2])
        size = flight._size(model)
        assert size.mass == frame.mass
        assert size.weight == pytest.approx(frame.mass * 9.81, rel=1e-12) and g == 9.81
        lift = sum(float(t) for t in frame.thrust_max)
        assert size.spare_lift * g + size.weight == pytest.approx(lift, rel=1e-12)
        assert size.roll_authority == pytest.approx(max(float(t) * abs(float(r[1])) for t, r in
                                                        zip(frame.thrust_max, frame.rotors, strict=True)), rel=1e-12)


def test_the_delay_test_s_levels_from_its_start_step_and_stop():
    assert flight.AQB_DELAY_TEST.levels() == [k / 100 for k in range(51)]  # 0, 10 ms, ..., 0.5 s
    t = replace(flight.AQB_DELAY_TEST, start=replace(flight.AQB_DELAY_TEST.start, value=0.1),
                step=replace(flight.AQB_DELAY_TEST.step, value=0.1),
                stop=replace(flight.AQB_DELAY_TEST.stop, value=0.3))
    assert t.levels() == [0.1, 0.2, 0.3]  # (0.3 − 0.1)/0.1 is 1.9999999999999998 in floats: the stop is kept


def test_the_rapid_goals_follow_delay_analysis_s_ranges():
    """aqb/utils/delay_analysis.py:110-120: the i-th of n − 2 = 3 rapid goals at difficulty (i + 1)/3, position
    U(−r, r) with r = 2 + 2 d (z made positive), velocity r = 1 + 2 d, acceleration r = 0.5 + 1.5 d, drawn in that
    order from the seed's Generator."""
    for seed in (0, 7):
        rng = np.random.default_rng(np.random.SeedSequence(seed))
        want = []
        for i in range(3):
            d = (i + 1) / 3
            pos = rng.uniform(-(2 + 2 * d), 2 + 2 * d, size=3)
            vel = rng.uniform(-(1 + 2 * d), 1 + 2 * d, size=3)
            acc = rng.uniform(-(0.5 + 1.5 * d), 0.5 + 1.5 * d, size=3)
            pos[2] = abs(pos[2])
            want.append((tuple(pos), tuple(vel), tuple(acc)))
        assert flight.AQB_DELAY_TEST.rapid_goals(seed) == want


def test_the_delay_test_s_references_start_at_the_centre():
    refs = dict(flight.AQB_DELAY_TEST.references(3))
    assert list(refs) == ["hover", "circle", "rapid1", "rapid2", "rapid3"]
    assert refs["hover"] == "reference={kind='hover', center=[0.0, 0.0, 5.0]}"
    assert f"omega={2 * math.pi * 0.2!r}" in refs["circle"] and "center=[0.0, 0.0, 5.0]" in refs["circle"]
    assert all("duration=5.0}" in refs[f"rapid{i}"] for i in (1, 2, 3))


def test_the_switch_times_are_one_to_four_in_the_window_at_least_half_a_second_apart():
    counts = set()
    for seed in range(60):
        times = flight._toggle_times(np.random.default_rng(seed), flight.AQB)
        counts.add(len(times))
        assert 1 <= len(times) <= 4 and list(times) == sorted(times)
        assert all(0.5 <= t <= 4.5 for t in times)
        assert all(b - a >= 0.5 for a, b in zip(times, times[1:], strict=False))
    assert counts == {1, 2, 3, 4}


def test_the_rotor_factors_spread_about_one_within_the_capped_range():
    """Each rotor's efficiency 1 + U(−c, c), c = min(I, 0.6): four factors, within [1 − c, 1 + c], on both sides of
    1 over a few seeds; the cap holds at I = 5."""
    for intensity, c in ((0.3, 0.3), (5.0, 0.6)):
        lows = highs = 0
        for seed in range(10):
            f = flight.draw_task(seed, "rotor_efficiency", intensity).rotor_factors
            assert len(f) == 4 and all(1 - c <= x <= 1 + c for x in f)
            lows += any(x < 1 for x in f)
            highs += any(x > 1 + c / 2 for x in f)
        assert lows and highs


def test_a_task_s_overrides_scale_the_axis_and_name_every_rotor():
    force = replace(flight.AQB, force=replace(flight.AQB.force, value=0.5))
    task = flight.draw_task(2, "force", 2.0, force)
    out = task.overrides(force)
    events = out[-1]
    t0 = task.toggles[0]
    assert f"{{t={t0!r}, kind='external_force', force=[1.0, 1.0, 1.0]}}" in events  # I × 0.5 N per unit, on
    if len(task.toggles) > 1:
        assert "force=[-1.0, -1.0, -1.0]" in events  # and off again
    kept = task.overrides(force, until=t0)  # a switch at the run's last instant is kept
    assert f"t={t0!r}" in kept[-1]
    rotors = flight.draw_task(2, "rotor_efficiency", 0.5).overrides()
    assert [f"rotor={r}" in rotors[-1] for r in (1, 2, 3, 4)] == [True] * 4 and "rotor=0" not in rotors[-1]


def test_the_when2fail_intensities_from_their_step_and_top():
    assert flight.protocol_levels() == [float(k) for k in range(11)]  # 0, 1, ..., 10 (config_manager.py:59-61)
    fine = replace(flight.AQB, intensity_step=replace(flight.AQB.intensity_step, value=0.1),
                   max_intensity=replace(flight.AQB.max_intensity, value=0.3))
    assert flight.protocol_levels(fine) == [0.0, 0.1, 0.2, 0.3]  # 0.3/0.1 is 2.9999999999999996 in floats
    half = replace(flight.AQB, intensity_step=replace(flight.AQB.intensity_step, value=0.5),
                   max_intensity=replace(flight.AQB.max_intensity, value=2.0))
    assert flight.protocol_levels(half) == [0.0, 0.5, 1.0, 1.5, 2.0]


def test_a_draw_s_goal_is_the_first_stream_s_position_velocity_and_acceleration():
    """The motion primitive's goal: the seed's first spawned stream, U(−2, 2) per axis for position, then velocity,
    then acceleration (randomization_config.py:79-81)."""
    for seed in (0, 5):
        traj = np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[0])
        pos, vel, acc = (tuple(float(x) for x in traj.uniform(-2.0, 2.0, size=3)) for _ in range(3))
        task = flight.draw_task(seed, "wind", 1.0)
        assert (task.position, task.velocity, task.acceleration) == (pos, vel, acc)


def test_a_search_with_no_runs_yet_has_an_empty_curve_of_no_seeds():
    (curve,) = flight.success_curves(flight.searches()[:1])
    assert curve["intensity"] == [] and curve["success_rate"] == [] and curve["seeds"] == 0

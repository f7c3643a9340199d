"""Joint-space references (arm of m joints): shapes (order+1,) + shape(t) + (m,);
closed-form derivatives agree with central differences; array calls equal the
stack of scalar calls bit for bit; the waypoint moves start and end at rest,
hold the last pose, repeat when cycled; bad input names the offending field."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.reference import JointSumOfSines, JointWaypoints

H = 1e-5  # central-difference step [s]


def _sines(m: int) -> JointSumOfSines:
    """m joints with 1..3 terms each, distinct frequencies, non-zero phases."""
    rng = np.random.default_rng(m)
    amplitudes, omegas, phases = [], [], []
    for i in range(m):
        n = 1 + i % 3
        amplitudes.append(tuple(rng.uniform(0.1, 0.8, n)))
        omegas.append(tuple(rng.uniform(0.3, 3.5, n)))
        phases.append(tuple(rng.uniform(-np.pi, np.pi, n)))
    center = tuple(rng.uniform(-1.0, 1.0, m))
    return JointSumOfSines(center, tuple(amplitudes), tuple(omegas), tuple(phases))


def _waypoints(m: int, cycle: bool = False) -> JointWaypoints:
    rng = np.random.default_rng(100 + m)
    poses = [tuple(rng.uniform(-1.5, 1.5, m)) for _ in range(4)]
    if cycle:
        poses.append(poses[0])
    durations = tuple(rng.uniform(0.8, 2.5, len(poses) - 1))
    return JointWaypoints(tuple(poses), durations, t0=0.7, cycle=cycle)


REFERENCES = {}
for _m in (1, 3, 6):
    REFERENCES[f"sines_m{_m}"] = _sines(_m)
    REFERENCES[f"waypoints_m{_m}"] = _waypoints(_m)
    REFERENCES[f"waypoints_cycle_m{_m}"] = _waypoints(_m, cycle=True)


def _corners(ref) -> np.ndarray:
    """Times where a waypoint move starts or ends (its 5th derivative jumps there)."""
    if not isinstance(ref, JointWaypoints):
        return np.array([])
    starts = ref.t0 + np.concatenate(([0.0], np.cumsum(ref.durations)))
    passes = 4 if ref.cycle else 1
    return np.concatenate([starts + p * ref.period for p in range(passes)])


def _sample_times(ref, n: int = 60, seed: int = 0) -> np.ndarray:
    """Random times (before, during and after the moves, kept 1e-3 s off the corners)."""
    lo, hi = -1.0, 20.0
    if isinstance(ref, JointWaypoints):  # mostly inside the moves
        lo, hi = ref.t0 - 0.5, ref.t0 + ref.period * (2.5 if ref.cycle else 1.2)
    t = np.random.default_rng(seed).uniform(lo, hi, 4 * n)
    corners = _corners(ref)
    if corners.size:
        t = t[np.min(np.abs(t[:, None] - corners[None, :]), axis=1) > 1e-3]
    return np.sort(t[:n])


@pytest.mark.parametrize("name", REFERENCES)
def test_m_and_shapes_for_scalar_and_array_times(name):
    ref = REFERENCES[name]
    m = int(name.rsplit("_m", 1)[1])
    assert ref.m == m
    t = _sample_times(ref, n=17)
    for order in (0, 1, 2, 4):
        assert ref(1.3, order).shape == (order + 1, m)
        assert ref(np.float64(1.3), order).shape == (order + 1, m)
        assert ref(t, order).shape == (order + 1, len(t), m)
        assert ref(t[:16].reshape(4, 4), order).shape == (order + 1, 4, 4, m)
        assert ref(t[:1], order).shape == (order + 1, 1, m)
        assert ref(t, order).dtype == np.float64
    np.testing.assert_array_equal(ref(t, 2)[:2], ref(t, 1))  # lower orders are a prefix


@pytest.mark.parametrize("name", REFERENCES)
def test_derivatives_match_central_differences(name):
    ref = REFERENCES[name]
    t = _sample_times(ref)
    if isinstance(ref, JointWaypoints):  # the sample must exercise the moves, not only rests
        assert np.count_nonzero(np.any(ref(t, 1)[1] != 0.0, axis=-1)) >= 10
    plus, minus, mid = ref(t + H, 4), ref(t - H, 4), ref(t, 4)
    for k in range(0, 4):
        fd = (plus[k] - minus[k]) / (2 * H)
        # relative to the size of the derivatives involved (they cross zero)
        scale = 1.0 + np.max(np.abs(mid[k : k + 2]))
        np.testing.assert_allclose(fd, mid[k + 1], atol=1e-6 * scale, rtol=0,
                                   err_msg=f"{name}: d/dt of derivative {k}")


@pytest.mark.parametrize("name", REFERENCES)
def test_array_call_equals_stack_of_scalar_calls_bit_for_bit(name):
    ref = REFERENCES[name]
    t = _sample_times(ref, n=40, seed=3)
    if isinstance(ref, JointWaypoints):  # include the corners and rests themselves
        t = np.concatenate((t, _corners(ref), [ref.t0 - 1.0, 1e3]))
    for order in (0, 3, 4):
        arr = ref(t, order)
        stacked = np.stack([ref(float(ti), order) for ti in t], axis=1)
        assert np.array_equal(arr, stacked), f"{name}: order {order}"
        assert np.array_equal(ref(t.reshape(-1, 1), order)[:, :, 0], arr)


def test_sum_of_sines_values_and_none_phases():
    ref = JointSumOfSines((0.1, -0.2), ((0.5, 0.25), (0.3,)), ((1.0, 2.0), (3.0,)), None)
    assert ref.phases == ((0.0, 0.0), (0.0,))
    t = np.linspace(0.0, 5.0, 11)
    q, dq, ddq = ref(t, 2)
    np.testing.assert_allclose(q[:, 0], 0.1 + 0.5 * np.sin(t) + 0.25 * np.sin(2 * t), atol=1e-15)
    np.testing.assert_allclose(q[:, 1], -0.2 + 0.3 * np.sin(3 * t), atol=1e-15)
    np.testing.assert_allclose(dq[:, 1], 0.9 * np.cos(3 * t), atol=1e-15)
    np.testing.assert_allclose(ddq[:, 0], -0.5 * np.sin(t) - 1.0 * np.sin(2 * t), atol=1e-15)


def test_waypoints_start_and_end_each_move_at_rest():
    wp = ((0.0, 1.0, -0.5), (0.4, -0.3, 0.2), (-1.0, 0.5, 0.9))
    ref = JointWaypoints(wp, (1.3, 0.7), t0=0.5)
    t_first = ref.t0 + ref.durations[0]
    for t, pose in ((ref.t0, wp[0]), (t_first, wp[1])):
        out = ref(t, 4)
        assert np.array_equal(out[0], pose), t
        assert np.all(out[1:] == 0.0), t
    # it moves in between, and really rests before t0
    assert np.all(ref(0.5 * (ref.t0 + t_first), 1)[1] != 0.0)
    before = ref(np.linspace(-10.0, ref.t0, 7), 4)
    assert np.all(before[0] == np.array(wp[0])) and np.all(before[1:] == 0.0)
    # after the last move: stays at the last waypoint, at rest
    end = ref.t0 + ref.period
    after = ref(end + np.array([0.0, 1e-9, 0.1, 3.0, 1e4]), 4)
    assert np.all(after[0] == np.array(wp[-1]))
    assert np.all(after[1:] == 0.0)
    # and the last move approaches it continuously, with vanishing derivatives
    near = ref(end - 1e-4, 4)
    np.testing.assert_allclose(near[0], wp[-1], atol=1e-12)
    np.testing.assert_allclose(near[1:3], 0.0, atol=1e-6)


def test_waypoints_midpoint_is_halfway_by_symmetry():
    ref = JointWaypoints(((0.0, 2.0), (1.0, -2.0)), (2.0,), t0=1.0)
    q, dq = ref(2.0, 1)
    np.testing.assert_allclose(q, [0.5, 0.0], atol=1e-14)
    np.testing.assert_allclose(dq, np.array([1.0, -4.0]) * (315 / 128) / 2.0, rtol=1e-12)


def test_waypoints_cycle_is_periodic():
    ref = REFERENCES["waypoints_cycle_m3"]
    P = ref.period
    assert P == pytest.approx(sum(ref.durations))
    t = ref.t0 + _sample_times(ref, n=50, seed=7) % P
    base = ref(t, 4)
    assert np.count_nonzero(base[1]) > 0
    for n in (1, 2, 7):
        shifted = ref(t + n * P, 4)
        for k in range(5):
            scale = 1.0 + np.max(np.abs(base[k]))
            np.testing.assert_allclose(shifted[k], base[k], atol=1e-8 * scale, rtol=0,
                                       err_msg=f"derivative {k}, {n} periods later")
    # back at the first pose, at rest, at every multiple of the period
    for n in (1, 2, 5):
        out = ref(ref.t0 + n * P, 4)
        np.testing.assert_allclose(out[0], ref.waypoints[0], atol=1e-12)
        np.testing.assert_allclose(out[1:], 0.0, atol=1e-6)
    # whereas without cycle the same moves stop at the last pose
    once = JointWaypoints(ref.waypoints, ref.durations, t0=ref.t0)
    assert np.all(once(t + P, 1)[0] == np.array(ref.waypoints[-1]))


def test_waypoints_order_above_four_is_refused():
    ref = REFERENCES["waypoints_m3"]
    assert ref(1.0, 4).shape == (5, 3)
    with pytest.raises(ValueError, match="order"):
        ref(1.0, 5)
    with pytest.raises(ValueError, match="order"):
        ref(1.0, -1)


@pytest.mark.parametrize("kwargs, field", [
    (dict(center=(0.0, 0.0), amplitudes=((1.0,),), omegas=((1.0,), (1.0,))), "amplitudes"),
    (dict(center=(0.0, 0.0), amplitudes=((1.0,), (1.0,)), omegas=((1.0,),)), "omegas"),
    (dict(center=(0.0, 0.0), amplitudes=((1.0,), (1.0, 2.0)), omegas=((1.0,), (1.0,))), r"omegas\[1\]"),
    (dict(center=(0.0, 0.0), amplitudes=((1.0,), (1.0,)), omegas=((1.0,), (1.0,)),
          phases=((0.0,), (0.0, 0.0))), r"phases\[1\]"),
    (dict(center=(0.0, 0.0), amplitudes=((1.0,), (1.0,)), omegas=((1.0,), (1.0,)),
          phases=((0.0,),)), "phases"),
    (dict(center=(), amplitudes=(), omegas=()), "center"),
    (dict(center=((0.0, 1.0),), amplitudes=((1.0,),), omegas=((1.0,),)), "center"),
    (dict(center=(0.0,), amplitudes=((np.nan,),), omegas=((1.0,),)), r"amplitudes\[0\]"),
])
def test_joint_sum_of_sines_bad_input_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        JointSumOfSines(**kwargs)


@pytest.mark.parametrize("kwargs, field", [
    (dict(waypoints=((0.0, 0.0), (1.0, 1.0), (2.0,)), durations=(1.0, 1.0)), r"waypoints\[2\]"),
    (dict(waypoints=((0.0, 0.0),), durations=()), "waypoints"),
    (dict(waypoints=((0.0,), (1.0,), (2.0,)), durations=(1.0,)), "durations"),
    (dict(waypoints=((0.0,), (1.0,)), durations=(1.0, 1.0)), "durations"),
    (dict(waypoints=((0.0,), (1.0,)), durations=(0.0,)), "durations"),
    (dict(waypoints=((0.0,), (1.0,)), durations=(-1.0,)), "durations"),
    (dict(waypoints=((0.0,), (1.0,)), durations=(1.0,), t0=np.inf), "t0"),
    (dict(waypoints=((0.0,), (1.0,), (0.5,)), durations=(1.0, 1.0), cycle=True), "cycle"),
])
def test_joint_waypoints_bad_input_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        JointWaypoints(**kwargs)


def test_references_are_frozen_and_hashable():
    for ref in (REFERENCES["sines_m3"], REFERENCES["waypoints_cycle_m3"]):
        hash(ref)
        with pytest.raises(AttributeError):
            ref.t0 = 1.0 if isinstance(ref, JointWaypoints) else None  # type: ignore[misc]
        if isinstance(ref, JointSumOfSines):
            with pytest.raises(AttributeError):
                ref.center = (0.0,)  # type: ignore[misc]
    # lists are accepted and stored as tuples
    ref = JointWaypoints([[0.0, 1.0], [1.0, 0.0]], [2.0])
    assert ref.waypoints == ((0.0, 1.0), (1.0, 0.0)) and ref.durations == (2.0,)
    hash(ref)

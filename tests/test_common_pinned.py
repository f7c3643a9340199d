"""The laws' shared estimate helpers (adaptive_mj.laws.common) pinned by hand (issue 54): clip_into's edge cases by
name, modify_rate's leakage and the box's tangent cone, and the dead-zone's boundary. Plain Python, no numba
(tools/mutate.py runs this file for common)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from adaptive_mj.laws import common

INF = math.inf


def _clip(theta, lower, upper):
    theta = np.array(theta, dtype=float)
    common.clip_into(theta, np.array(lower, dtype=float), np.array(upper, dtype=float))
    return theta


def test_clip_into_inside_the_box_changes_nothing():
    assert _clip([0.5, -2.0], [0.0, -3.0], [1.0, 3.0]).tolist() == [0.5, -2.0]


def test_clip_into_below_the_lower_bound_is_the_lower_bound():
    assert _clip([-0.5, -4.0], [0.0, -3.0], [1.0, 3.0]).tolist() == [0.0, -3.0]


def test_clip_into_above_the_upper_bound_is_the_upper_bound():
    assert _clip([1.5, 4.0], [0.0, -3.0], [1.0, 3.0]).tolist() == [1.0, 3.0]


def test_clip_into_on_a_bound_stays_on_it():
    assert _clip([0.0, 3.0], [0.0, -3.0], [1.0, 3.0]).tolist() == [0.0, 3.0]


def test_clip_into_with_infinite_bounds_is_a_no_op():
    assert _clip([-1e300, 1e300, 0.0], [-INF] * 3, [INF] * 3).tolist() == [-1e300, 1e300, 0.0]


def test_clip_into_a_zero_width_box_pins_the_estimate():
    assert _clip([-1.0, 2.0, 7.0], [2.0] * 3, [2.0] * 3).tolist() == [2.0, 2.0, 2.0]


def test_clip_into_a_one_sided_box():
    assert _clip([-1.0, 5.0], [0.0, 0.0], [INF, INF]).tolist() == [0.0, 5.0]
    assert _clip([-1.0, 5.0], [-INF, -INF], [1.0, 1.0]).tolist() == [-1.0, 1.0]


def test_clip_into_leaves_nan_as_nan():
    """NaN compares false with either bound: it is left for the run's own checks to find."""
    out = _clip([math.nan, 2.0], [0.0, 0.0], [1.0, 1.0])
    assert math.isnan(out[0]) and out[1] == 1.0


def test_clip_into_projects_the_bodies_only_when_a_record_follows(monkeypatch):
    """lower longer than θ̂ (a Modification with bodies): after the clip, project_bodies(θ̂, lower, n_theta) on the
    clipped θ̂; as long as θ̂: no projection."""
    calls = []
    monkeypatch.setattr(common, "project_bodies", lambda th, rec, n: calls.append((th.tolist(), rec.tolist(), n)))
    _clip([5.0, -5.0], [0.0, 0.0, 9.0], [1.0, 1.0, 9.0])
    assert calls == [([1.0, 0.0], [0.0, 0.0, 9.0], 2)]
    calls.clear()
    _clip([5.0, -5.0], [0.0, 0.0], [1.0, 1.0])
    assert calls == []


def _modify(rate, theta, s_abs, sigma, e_mod, theta0, gamma, lower, upper):
    rate = np.array(rate, dtype=float)
    common.modify_rate(rate, np.array(theta, float), s_abs, sigma, e_mod, np.array(theta0, float),
                       np.array(gamma, float), np.array(lower, float), np.array(upper, float))
    return rate


def test_modify_rate_leaks_toward_theta0_by_sigma_plus_nu_s():
    """rate_i −= (σ + ν|s|)(θ_i − θ₀_i)/γ_i: σ 0.5, ν 2, |s| 0.25 (leak 1); θ − θ₀ = (2, −1), γ = (4, 0.5):
    rate (1, 1) − (0.5, −2) = (0.5, 3)."""
    got = _modify([1.0, 1.0], [3.0, 0.0], 0.25, 0.5, 2.0, [1.0, 1.0], [4.0, 0.5], [-INF] * 2, [INF] * 2)
    np.testing.assert_allclose(got, [0.5, 3.0], rtol=1e-15)
    got = _modify([1.0, 1.0], [3.0, 0.0], 0.25, 0.0, 0.0, [1.0, 1.0], [4.0, 0.5], [-INF] * 2, [INF] * 2)
    assert got.tolist() == [1.0, 1.0]


def test_modify_rate_stops_a_rate_that_leaves_the_box_and_keeps_one_that_enters_it():
    """At (or past) the lower bound a falling rate is 0 and a rising one kept; at the upper bound the mirror; inside
    every rate is kept (rates of 0.5 and 2 in size: a threshold other than 0 shows)."""
    lo, hi = [0.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0, 1.0]
    got = _modify([-0.5, 0.5, 0.5, -0.5, -2.0], [0.0, 0.0, 1.0, 1.0, 0.5], 0.0, 0.0, 0.0, [0.0] * 5, [1.0] * 5, lo,
                  hi)
    assert got.tolist() == [0.0, 0.5, 0.0, -0.5, -2.0]
    got = _modify([-2.0, 2.0], [0.0, 1.0], 0.0, 0.0, 0.0, [0.0] * 2, [1.0] * 2, [0.0, 0.0], [1.0, 1.0])
    assert got.tolist() == [0.0, 0.0]
    got = _modify([-1.0, 1.0], [-0.5, 1.5], 0.0, 0.0, 0.0, [0.0] * 2, [1.0] * 2, [0.0, 0.0], [1.0, 1.0])
    assert got.tolist() == [0.0, 0.0]


def test_modify_rate_cuts_after_the_leak():
    """The leak pushes a zero rate at the lower bound down (θ above θ₀): the cone then stops it."""
    got = _modify([0.0], [0.0], 0.0, 1.0, 0.0, [-1.0], [1.0], [0.0], [1.0])
    assert got.tolist() == [0.0]
    got = _modify([0.0], [0.5], 0.0, 1.0, 0.0, [-1.0], [1.0], [0.0], [1.0])
    assert got.tolist() == [-1.5]


@pytest.mark.parametrize("signal, width, open_", [(0.5, 0.5, True), (-0.5, 0.5, True), (0.4999, 0.5, False),
                                                  (-0.4999, 0.5, False), (0.0, 0.0, True), (math.nan, 0.0, False)])
def test_the_dead_zone_is_open_from_its_width_on(signal, width, open_):
    assert common.dead_zone_open(signal, width) is open_

"""The scorecard's statistics and scoring pinned with numbers computed by hand here (issue 54): never by the function
under test, nor by the module's own normalisers(), weights or CRITERIA. Where a constant is the specification (a
weight, a normaliser, a suite's size), the test states the documented value (docs/METRICS.md, "Scorecard").

Edge cases by name: touching and zero-width intervals, a criterion above its normaliser (the cap), a negative one
(no bonus), a crashed run inside a task that otherwise finished, laws that share a rank and the order they are
listed in, CVaR on hand-filled values. No runs: every outcome is made by hand (tools/mutate.py runs this file for
adaptive_mj.study.stats, score, score_suite and score_card)."""
from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import pytest

from adaptive_mj.study import score_suite as suite
from adaptive_mj.study.job import RunOutcome, RunSpec
from adaptive_mj.study.stats import (CONFIDENCE, Estimate, cvar, differs, estimate, paired_difference, paired_ranks,
                                     ranks, separable, separated_pairs, t_quantile)

T975_4 = 2.7764451051977934  # Student's t, 97.5 % quantile, 4 degrees of freedom (tables: 2.776)
T975_2 = 4.302652729749462  # 2 degrees of freedom (tables: 4.303)
T975_1 = 12.706204736174694  # 1 degree of freedom (tables: 12.71)

#: docs/METRICS.md "Scorecard": the weights w_i (they sum to 1)
WEIGHTS = {"tail_error": 0.30, "peak_after_change": 0.10, "recovery_time": 0.10, "control_rms": 0.10,
           "control_tv_rate": 0.10, "param_error": 0.15, "drift_rate": 0.15}


# ------------------------------------------------------------------------------------------------- stats


def test_the_confidence_and_the_t_quantiles_are_the_tables():
    assert CONFIDENCE == 0.95
    assert t_quantile(0.975, 4) == pytest.approx(T975_4, rel=1e-12)
    assert t_quantile(0.975, 1) == pytest.approx(T975_1, rel=1e-12)


def test_an_estimate_of_one_to_five_by_hand():
    e = estimate([1.0, 2.0, 3.0, 4.0, 5.0])
    half = T975_4 * math.sqrt(2.5) / math.sqrt(5)  # s² = (4 + 1 + 0 + 1 + 4) / 4
    assert (e.mean, e.n) == (3.0, 5)
    assert e.lo == pytest.approx(3.0 - half, rel=1e-12) and e.hi == pytest.approx(3.0 + half, rel=1e-12)
    clipped = estimate([1.0, 2.0, 3.0, 4.0, 5.0], lowest=2.0, highest=4.5)
    assert (clipped.lo, clipped.hi) == (2.0, 4.5)


def test_a_standard_deviation_of_exactly_one_still_has_its_interval():
    e = estimate([0.0, 1.0, 2.0])  # s = 1 exactly
    assert e.hi - e.mean == pytest.approx(T975_2 / math.sqrt(3), rel=1e-12)
    assert e.mean - e.lo == pytest.approx(T975_2 / math.sqrt(3), rel=1e-12)


def test_a_zero_width_estimate_and_one_value_and_none():
    assert estimate([0.25, 0.25, 0.25]) == Estimate(0.25, 0.25, 0.25, 3)
    assert estimate([0.3]) == Estimate(0.3, -math.inf, math.inf, 1)
    assert estimate([0.3], lowest=0.0, highest=1.0) == Estimate(0.3, 0.0, 1.0, 1)
    empty = estimate([])
    assert empty.n == 0 and math.isnan(empty.mean) and math.isnan(empty.lo) and math.isnan(empty.hi)
    assert estimate([math.nan, math.inf, -math.inf]).n == 0
    two = estimate([math.nan, 2.0, 4.0, math.inf])  # a run with no value is left out: n counts the rest
    assert (two.mean, two.n) == (3.0, 2)
    assert two.hi - two.mean == pytest.approx(T975_1 * math.sqrt(2.0) / math.sqrt(2.0), rel=1e-12)


def test_an_estimate_reads_back_from_json_with_its_open_ends():
    e = Estimate(0.5, -math.inf, math.inf, 1)
    d = e.as_dict()
    assert d == {"mean": 0.5, "lo": None, "hi": None, "n": 1}
    back = Estimate.from_dict(d)
    assert back.lo == -math.inf and back.hi == math.inf and back.mean == 0.5 and back.n == 1
    none = Estimate.from_dict({"mean": None, "lo": None, "hi": None, "n": 0})
    assert math.isnan(none.mean) and none.lo == -math.inf and none.hi == math.inf
    assert Estimate.from_dict({"mean": 1, "lo": 0, "hi": 2, "n": 3}) == Estimate(1.0, 0.0, 2.0, 3)


def test_an_estimate_s_text():
    assert Estimate(0.5, 0.25, 0.75, 3).text() == "0.5 [0.25, 0.75]"
    assert Estimate(0.5, 0.5, 0.5, 3).text() == "0.5"  # zero width: no brackets
    assert Estimate(0.5, 0.5, 0.5, 0).text() == "n/a"  # no seed, whatever the mean says
    assert Estimate(math.nan, math.nan, math.nan, 3).text() == "n/a"
    assert Estimate(0.12345, 0.1, 0.2, 2).text(".2f") == "0.12 [0.10, 0.20]"


def test_touching_intervals_are_not_separable_and_zero_width_ones_are_when_apart():
    a, b = Estimate(0.5, 0.0, 1.0, 3), Estimate(1.5, 1.0, 2.0, 3)  # they touch at 1.0
    assert not separable(a, b) and not separable(b, a)
    c = Estimate(1.5, 1.0 + 1e-12, 2.0, 3)
    assert separable(a, c) and separable(c, a)
    point, other = Estimate(1.0, 1.0, 1.0, 3), Estimate(1.2, 1.2, 1.2, 3)
    assert separable(point, other) and not separable(point, Estimate(1.0, 1.0, 1.0, 4))


def test_unpaired_ranks_by_hand():
    top = Estimate(0.9, 0.85, 0.95, 3)
    near = Estimate(0.83, 0.8, 0.85, 3)  # touches top: not separable from it
    low = Estimate(0.5, 0.45, 0.55, 3)
    none = Estimate(math.nan, math.nan, math.nan, 0)
    assert ranks([top, near, low, none]) == [1, 1, 3, 4]
    assert ranks([top, near, low, none], higher_is_better=False) == [2, 2, 1, 4]
    assert ranks([low, top]) == [2, 1]
    assert ranks([none]) == [1]


def test_differs_needs_two_seeds_and_an_interval_clear_of_zero():
    assert not differs(Estimate(0.0, 0.0, 0.0, 3))  # two copies of one law
    assert differs(Estimate(0.1, 0.1, 0.1, 2))  # a constant nonzero difference, on two seeds
    assert not differs(Estimate(0.1, 0.1, 0.1, 1))
    assert not differs(Estimate(0.1, 0.0, 0.2, 3))  # touching zero from above
    assert not differs(Estimate(-0.1, -0.2, 0.0, 3))  # touching zero from below
    assert differs(Estimate(-0.1, -0.2, -1e-12, 3))


def test_paired_difference_by_hand():
    d = paired_difference([3.0, 5.0, 4.0, math.nan], [1.0, 2.0, 3.0, 0.0])  # differences 2, 3, 1
    half = T975_2 * 1.0 / math.sqrt(3)
    assert (d.mean, d.n) == (2.0, 3)
    assert d.lo == pytest.approx(2.0 - half, rel=1e-12) and d.hi == pytest.approx(2.0 + half, rel=1e-12)
    assert paired_difference([math.nan, 1.0], [1.0, math.nan]).n == 0


def test_laws_that_share_a_rank_keep_their_order_and_the_next_rank_counts_them():
    a = [0.9, 0.8, 0.7]
    twin = list(a)
    low = [0.5, 0.41, 0.3]  # 0.4, 0.39, 0.4 below a: separable
    none = [math.nan] * 3
    assert paired_ranks([a, twin, low]) == [1, 1, 3]  # 1 + the two laws above it, not 2
    assert paired_ranks([low, twin, a]) == [3, 1, 1]
    assert paired_ranks([none, low, a]) == [3, 2, 1]  # no value: last; it beats nobody
    assert paired_ranks([none, low, a], higher_is_better=False) == [3, 1, 2]
    assert separated_pairs([a, twin, low]) == 2
    assert separated_pairs([a, twin]) == 0


def test_cvar_by_hand():
    assert cvar([1.0, 5.0, 3.0, 2.0, 4.0]) == 5.0  # ⌈0.1 · 5⌉ = 1: the worst
    assert cvar([1.0, 5.0, 3.0, 2.0, 4.0], 0.4) == 4.5  # ⌈2⌉ = 2: (5 + 4) / 2
    assert cvar([1.0, 5.0, 3.0, 2.0, 4.0], 0.5) == 4.0  # ⌈2.5⌉ = 3: (5 + 4 + 3) / 3
    assert cvar([1.0, 5.0, 3.0, 2.0, 4.0], 0.0) == 5.0  # at least one value
    assert cvar(list(range(11))) == 9.5  # default 10 %: ⌈1.1⌉ = 2 worst of 0..10
    assert cvar([2.0, 2.0], 1.0) == 2.0
    assert cvar([3.0]) == 3.0  # one seed: itself
    assert math.isnan(cvar([]))


# ------------------------------------------------------------------------------------------------- the suite


def test_the_criteria_weights_normaliser_rules_and_suites_are_the_documented_ones():
    assert {c.name: c.weight for c in suite.CRITERIA} == WEIGHTS
    assert sum(WEIGHTS.values()) == pytest.approx(1.0, abs=1e-15)
    assert {c.name: c.task for c in suite.CRITERIA} == {
        "tail_error": "tracking", "peak_after_change": "change", "recovery_time": "change",
        "control_rms": "tracking", "control_tv_rate": "tracking", "param_error": "tracking", "drift_rate": "hold"}
    assert suite.JUDGED_TOGETHER == {"drift_rate": "param_error"}
    assert suite.SUITE_VERSION == 3
    quick, full = suite.SUITES["quick"], suite.SUITES["full"]
    assert (quick.seeds, quick.steps, quick.stress_duration) == (5, 6, 5.0)
    assert (full.seeds, full.steps, full.stress_duration) == (8, 8, 20.0)
    assert [quick.duration(t) for t in ("tracking", "change", "hold")] == [10.0, 10.0, 20.0]
    assert [full.duration(t) for t in ("tracking", "change", "hold")] == [30.0, 30.0, 100.0]


def test_the_definitions_hash_moves_with_every_definition(monkeypatch):
    h = suite.definitions_hash()
    assert len(h) == 16 and int(h, 16) >= 0 and suite.definitions_hash() == h
    moved = []
    with monkeypatch.context() as m:
        m.setattr(suite, "SUITE_VERSION", 4)
        moved.append(suite.definitions_hash())
    with monkeypatch.context() as m:
        m.setattr(suite, "CRITERIA", (suite.CRITERIA[0].__class__(**{**vars(suite.CRITERIA[0]), "weight": 0.31}),
                                      *suite.CRITERIA[1:]))
        moved.append(suite.definitions_hash())
    with monkeypatch.context() as m:
        m.setattr(suite, "JUDGED_TOGETHER", {})
        moved.append(suite.definitions_hash())
    with monkeypatch.context() as m:
        m.setattr(suite, "SUITES", {"quick": suite.SUITES["quick"]})
        moved.append(suite.definitions_hash())
    assert h not in moved and len(set(moved)) == 4


# ------------------------------------------------------------------------------------------------- scoring

#: normalisers written out by docs/METRICS.md's rules for a failure bound of 0.01, actuator limits RMS 3 and sum
#: 12, and a 8 s change run (the change at its half: 4 s left)
NORM = {"tail_error": 0.01, "peak_after_change": 0.1, "recovery_time": 4.0, "control_rms": 3.0,
        "control_tv_rate": 1200.0, "param_error": 1.0, "drift_rate": 1.0}
DURATIONS = {"tracking": 10.0, "change": 8.0, "hold": 20.0}


def test_the_normalisers_follow_the_documented_rules():
    from adaptive_mj.study.score import normalisers

    assert normalisers(0.01, (3.0, 12.0), DURATIONS) == pytest.approx(NORM, rel=1e-15)


def _figs(**over):
    figs = {"tail_error": 0.005, "peak_after_change": 0.3, "recovery_time": 1.0, "control_rms": 1.5,
            "control_tv_rate": 600.0, "param_error": 0.2, "drift_rate": 0.1, "success": 1.0}
    return {**figs, **over}


def test_performance_by_hand_with_a_criterion_above_its_normaliser():
    from adaptive_mj.study.score import performance

    # parts: 0.5, min(1, 3) = 1 (the cap), 0.25, 0.5, 0.5, 0.2, drift max(0.1, 0.2) = 0.2 (judged with identification)
    penalty = 0.30 * 0.5 + 0.10 * 1.0 + 0.10 * 0.25 + 0.10 * 0.5 + 0.10 * 0.5 + 0.15 * 0.2 + 0.15 * 0.2
    assert performance(_figs(), NORM) == pytest.approx(1.0 - penalty, rel=1e-13)
    assert performance(_figs(), NORM) == pytest.approx(0.565, rel=1e-13)
    assert performance(_figs(success=0.0), NORM) == 0.0
    # a drift above the parameter error keeps its own part
    assert performance(_figs(drift_rate=0.6), NORM) == pytest.approx(0.565 - 0.15 * 0.4, rel=1e-13)
    # exactly at its normaliser: the cap's part 1, as far above it
    assert performance(_figs(peak_after_change=0.1), NORM) == performance(_figs(peak_after_change=5.0), NORM)


def test_performance_counts_a_missing_figure_at_its_worst_and_a_negative_one_at_zero():
    from adaptive_mj.study.score import performance

    zero = {name: 0.0 for name in WEIGHTS}
    assert performance({**zero, "success": 1.0}, NORM) == 1.0
    assert performance({**zero, "success": 1.0, "tail_error": -0.02}, NORM) == 1.0  # no bonus below zero
    assert performance({**zero, "success": 1.0, "tail_error": math.nan}, NORM) == pytest.approx(0.70, rel=1e-13)
    assert performance({**zero, "success": 1.0, "control_tv_rate": math.inf}, NORM) == pytest.approx(0.90, rel=1e-13)
    assert performance({**{n: math.nan for n in WEIGHTS}, "success": 1.0}, NORM) == pytest.approx(0.0, abs=1e-15)


def _run(status="ok", tail=0.004, extras=None, final=None, u_rms=1.5, tv=6000.0):
    summary = {"status": status, "metrics": {"rms_tracking_error_tail": tail, "control_rms": u_rms,
                                             "control_total_variation": tv},
               "final": final if final is not None else {"theta_hat": {"a": 3.0, "b": 1.0},
                                                         "theta": {"a": 3.0, "b": 4.0}}}
    return RunOutcome(RunSpec(Path("x.toml")), status, summary, extras or {})


def _change(env, window=0.5, t_e=4.0):
    return {"change_response": {"event_time": t_e, "peak_error_after": max(env), "window": window,
                                "envelope": env}}


ENV = [0.05, 0.02, 0.009, 0.011, 0.005, 0.001]  # above 0.01 in windows 0, 1 and 3 (0.5 s each)


def _runs(**over):
    runs = {"tracking": _run(), "change": _run(extras=_change(ENV)), "hold": _run(extras={"estimate_drift": -0.05})}
    return {**runs, **over}


def test_seed_figures_by_hand():
    from adaptive_mj.study.score import seed_figures

    f = seed_figures(_runs(), 0.01, (3.0, 12.0), DURATIONS)
    assert f["tail_error"] == 0.004 and f["control_rms"] == 1.5
    assert f["control_tv_rate"] == 600.0  # 6000 over the 10 s tracking run
    assert f["param_error"] == pytest.approx(0.6, rel=1e-15)  # ‖(0, −3)‖ / ‖(3, 4)‖
    assert f["peak_after_change"] == 0.05
    assert f["recovery_time"] == 2.0  # the last window above the bound is the 4th: from (3 + 1) · 0.5 s
    assert f["drift_rate"] == 0.05 and f["success"] == 1.0
    penalty = 0.30 * 0.4 + 0.10 * 0.5 + 0.10 * 0.5 + 0.10 * 0.5 + 0.10 * 0.5 + 0.15 * 0.6 + 0.15 * 0.6
    assert f["performance"] == pytest.approx(1.0 - penalty, rel=1e-13)


def test_recovery_at_the_bound_exactly_and_never_and_at_once():
    from adaptive_mj.study.score import seed_figures

    def recovery(env):
        return seed_figures(_runs(change=_run(extras=_change(env))), 0.01, (3.0, 12.0), DURATIONS)["recovery_time"]

    assert recovery([0.001, 0.002, 0.01, 0.002, 0.001]) == 1.5  # at the bound counts as above it
    assert recovery([0.001, 0.002, 0.003]) == 0.0
    assert recovery([0.02] * 5 + [0.01]) == 4.0  # still at the bound at the end: the time left, 8 − 4 s
    assert recovery([0.02] * 20) == 4.0  # past the time left: capped at it
    assert recovery([0.001, 0.001, 0.02]) == 4.0  # above the bound in the last window: never recovered


def test_a_crashed_run_inside_a_task_that_otherwise_finished():
    from adaptive_mj.study.score import seed_figures

    for task in ("tracking", "change", "hold"):
        f = seed_figures(_runs(**{task: _run(status="crashed", extras=_change(ENV))}), 0.01, (3.0, 12.0), DURATIONS)
        assert f["success"] == 0.0 and f["performance"] == 0.0, task
    f = seed_figures(_runs(change=_run(status="crashed", extras=_change(ENV))), 0.01, (3.0, 12.0), DURATIONS)
    assert math.isnan(f["peak_after_change"]) and math.isnan(f["recovery_time"])
    assert f["tail_error"] == 0.004 and f["drift_rate"] == 0.05  # the runs that finished keep their figures
    f = seed_figures(_runs(tracking=_run(status="crashed")), 0.01, (3.0, 12.0), DURATIONS)
    assert all(math.isnan(f[n]) for n in ("tail_error", "control_rms", "control_tv_rate", "param_error"))
    f = seed_figures(_runs(hold=_run(status="crashed", extras={"estimate_drift": 0.0})), 0.01, (3.0, 12.0), DURATIONS)
    assert math.isnan(f["drift_rate"]) and f["recovery_time"] == 2.0
    # a missing task: no success either
    runs = _runs()
    del runs["change"]
    assert seed_figures(runs, 0.01, (3.0, 12.0), DURATIONS)["success"] == 0.0


def test_a_hold_or_change_run_past_its_bound():
    from adaptive_mj.study.score import seed_figures

    f = seed_figures(_runs(hold=_run(tail=0.0100001, extras={"estimate_drift": 0.0})), 0.01, (3.0, 12.0), DURATIONS)
    assert f["success"] == 0.0 and f["drift_rate"] == 0.0  # finished: its figure stands, its success does not
    f = seed_figures(_runs(hold=_run(tail=0.01, extras={"estimate_drift": 0.0})), 0.01, (3.0, 12.0), DURATIONS)
    assert f["success"] == 1.0  # at the bound: passes
    f = seed_figures(_runs(change=_run(tail=0.5, extras=_change(ENV))), 0.01, (3.0, 12.0), DURATIONS)
    assert f["success"] == 1.0  # the change run is judged by its recovery, not its tail
    f = seed_figures(_runs(change=_run()), 0.01, (3.0, 12.0), DURATIONS)  # no change analysis
    assert math.isnan(f["peak_after_change"]) and math.isnan(f["recovery_time"]) and f["success"] == 1.0


def test_the_parameter_error_by_hand():
    from adaptive_mj.study.score import _param_error

    assert _param_error({"final": {"theta_hat": {"a": 3.0, "b": 1.0}, "theta": {"a": 3.0, "b": 4.0}}}) == 0.6
    assert _param_error({"final": {"theta_hat": {"a": 2.0}, "theta": {"a": 0.0}}}) == 2.0  # a zero truth: absolute
    assert _param_error({"final": {"theta_hat": {"a": 0.25}, "theta": {"a": 0.5}}}) == 0.5  # relative below 1 too
    assert math.isnan(_param_error({"final": {"theta_hat": {}, "theta": {"a": 1.0}}}))
    assert math.isnan(_param_error({"final": {"theta_hat": {"a": 1.0}, "theta": {}}}))
    assert math.isnan(_param_error(None))


def test_a_figure_stays_in_its_domain():
    from adaptive_mj.study.score import figure

    half = T975_2 * math.sqrt(1 / 3) / math.sqrt(3)  # values 1, 1, 0: s² = 1/3
    s = figure("success", [1.0, 1.0, 0.0])
    assert s["mean"] == pytest.approx(2 / 3) and s["lo"] == 0.0 and s["hi"] == 1.0 and s["values"] == [1.0, 1.0, 0.0]
    for name in ("performance", "robustness"):
        assert figure(name, [1.0, 1.0, 0.0])["hi"] == 1.0
    t = figure("tail_error", [1.0, 1.0, 0.0])
    assert t["lo"] == 0.0 and t["hi"] == pytest.approx(2 / 3 + half, rel=1e-12)  # no upper clip for a criterion


def _margin(margin, first_fail, at_margin=None, at_hi=None, lo=0.0, hi=10.0):
    from adaptive_mj.study.breaking_point import Evaluation

    evs = []
    if at_margin is not None:
        evs.append(Evaluation(margin, [t for t in at_margin], ["ok"] * len(at_margin), list(at_margin)))
    if at_hi is not None:
        evs.append(Evaluation(hi, [math.inf if f else 0.001 for f in at_hi], ["ok"] * len(at_hi), [0.1] * len(at_hi)))
    return SimpleNamespace(margin=margin, first_fail=first_fail,
                           at=lambda v: next((e for e in evs if v is not None and e.value == v), None))


def test_stressor_and_law_figures_by_hand():
    from adaptive_mj.study.score import law_figures, stressor_figures

    st = SimpleNamespace(name="delay", unit="steps", lo=0.0, hi=10.0)
    ms = [_margin(4.0, 5.0, at_margin=[0.002], at_hi=[True]),
          _margin(None, 0.0, at_hi=[True]),  # the low end fails
          _margin(10.0, None, at_margin=[0.006], at_hi=[False])]  # the high end passes
    entry, pos = stressor_figures(ms, st)
    assert pos == [0.4, 0.0, 1.0]
    assert entry["margins"] == [4.0, None, 10.0] and entry["first_fails"] == [5.0, 0.0, None]
    assert entry["margin"]["mean"] == pytest.approx(14.0 / 3) and entry["margin"]["lo"] == 0.0
    assert entry["margin"]["hi"] == 10.0  # clipped to the range
    assert entry["position"]["mean"] == pytest.approx(1.4 / 3)
    assert (entry["position"]["lo"], entry["position"]["hi"]) == (0.0, 1.0)  # clipped to where a position lies
    assert entry["tail_mean_at_margin"] == pytest.approx(0.004) and entry["tail_cvar10_at_margin"] == 0.006
    assert entry["failure_rate_at_hi"] == pytest.approx(2 / 3)
    assert entry["unit"] == "steps"
    other = SimpleNamespace(name="noise", unit="m", lo=0.0, hi=1.0)
    unused = SimpleNamespace(name="period", unit="s", lo=0.0, hi=1.0)
    per_seed = [dict(_figs(), performance=p) for p in (0.5, 0.6, 0.7)]
    figs, st_out = law_figures(per_seed, {"delay": ms, "noise": [_margin(0.2, 0.3), _margin(0.5, 0.6),
                                                                  _margin(1.0, None)], "period": []},
                               [st, other, unused], 3)
    assert set(st_out) == {"delay", "noise"}  # period: n/a, not in R
    assert figs["robustness"]["values"] == pytest.approx([0.3, 0.25, 1.0])  # mean of (0.4, 0.2), (0, 0.5), (1, 1)
    assert figs["performance"]["mean"] == pytest.approx(0.6)
    figs, st_out = law_figures(per_seed, {}, [st], 3)
    assert st_out == {} and all(math.isnan(v) for v in figs["robustness"]["values"])
    assert len(figs["robustness"]["values"]) == 3


def test_no_value_at_the_margin_leaves_its_tail_figures_out():
    from adaptive_mj.study.score import stressor_figures

    st = SimpleNamespace(name="delay", unit="", lo=1.0, hi=100.0)  # geometric: two decades
    entry, pos = stressor_figures([_margin(10.0, 20.0)], st)
    assert pos == [pytest.approx(0.5)]
    assert entry["tail_mean_at_margin"] is None and entry["tail_cvar10_at_margin"] is None
    assert entry["failure_rate_at_hi"] is None


def _law(perf_mean, rank=1, oracle=False, tested=False, **means):
    figures = {"performance": {"mean": perf_mean, "lo": perf_mean, "hi": perf_mean, "n": 3, "values": [perf_mean] * 3},
               "robustness": {"mean": 0.5, "lo": 0.4, "hi": 0.6, "n": 3, "values": [0.5, 0.4, 0.6]},
               "success": {"mean": 2 / 3, "lo": 0.0, "hi": 1.0, "n": 3, "values": [1.0, 1.0, 0.0]}}
    for c in WEIGHTS:
        m = means.get(c, 0.0)
        figures[c] = {"mean": m, "lo": m, "hi": m, "n": 3 if c != "drift_rate" else 2, "values": [m] * 3}
    return {"figures": figures, "rank": {"performance": rank, "robustness": rank}, "oracle": oracle, "tested": tested,
            "stressors": {}, "compute_ratio": None}


def test_criteria_spread_leaves_the_oracles_out_and_names_the_cap():
    from adaptive_mj.study.score import criteria_spread

    plant = {"normalisers": NORM,
             "laws": {"a": _law(0.5, tail_error=0.01, control_rms=1.5, recovery_time=-1.0),  # at the cap exactly
                      "b": _law(0.5, tail_error=0.03, control_rms=3.0, recovery_time=None),
                      "fixed": _law(0.9, oracle=True, tail_error=0.0, control_rms=0.0)}}
    spread = criteria_spread(plant)
    assert spread["tail_error"] == {"lo": 1.0, "hi": 1.0, "saturated": True}
    assert spread["control_rms"] == {"lo": 0.5, "hi": 1.0, "saturated": False}
    assert spread["recovery_time"] == {"lo": 0.0, "hi": 1.0, "saturated": False}  # None: at the cap; < 0: zero
    assert spread["param_error"] == {"lo": 0.0, "hi": 0.0, "saturated": False}
    assert criteria_spread({"normalisers": NORM, "laws": {"fixed": _law(0.9, oracle=True)}}) == {}


def test_a_draw_multiplies_or_adds_one_factor_or_one_each():
    from adaptive_mj.plants.kinds import Draw
    from adaptive_mj.study.score import _drawn

    class Fixed:
        """A generator whose uniform draws are 1.5, 2.0, 2.5, ... in turn (a draw's order, by hand)."""

        def __init__(self):
            self.next = 1.5

        def uniform(self, lo, hi):
            v, self.next = self.next, self.next + 0.5
            return v

    assert _drawn(2.0, Draw("k", 0.5, 2.0), Fixed()) == 3.0  # one factor: 2 · 1.5
    assert _drawn([1.0, 2.0], Draw("k", 0.5, 2.0), Fixed()) == [1.5, 3.0]  # one factor for them all
    assert _drawn([1.0, 2.0], Draw("k", 0.5, 2.0, each=True), Fixed()) == [2.0, 5.0]  # 1 · 2.0, 2 · 2.5
    assert _drawn({"a": 1.0, "b": (1.0,)}, Draw("k", 0.0, 6.3, add=True), Fixed()) == {"a": 2.5, "b": [2.5]}
    assert _drawn({"a": 1.0, "b": 1.0}, Draw("k", 0.0, 6.3, each=True, add=True), Fixed()) == {"a": 3.0, "b": 3.5}


# ------------------------------------------------------------------------------------------------- the card


def _plant(laws):
    return {"output_unit": "m", "control_unit": "N", "laws": laws,
            "stressors": [{"name": "delay", "unit": "steps", "lo": 0, "hi": 200},
                          {"name": "noise", "unit": "", "lo": 0.0, "hi": 1.0}]}


def test_the_card_orders_laws_by_rank_then_mean_and_keeps_the_given_order_of_equals():
    from adaptive_mj.study.score_card import _order

    laws = {"c": _law(0.7, rank=2), "a": _law(0.6, rank=1), "b": _law(0.8, rank=1), "d": _law(0.6, rank=1),
            "e": _law(None, rank=1), "f": _law(0.9, rank=3)}
    laws["g"] = _law(0.6, rank=1)
    laws["g"]["figures"]["performance"]["mean"] = math.nan
    assert _order(_plant(laws)) == ["b", "a", "d", "e", "g", "c", "f"]


def test_the_card_s_units_names_and_seed_counts():
    from adaptive_mj.study.score_card import _name, _unit, _with_n

    plant = {"output_unit": "rad", "control_unit": "N m"}
    assert [_unit(u, plant) for u in ("output", "control", "control/s", "s", "-")] == [
        "rad", "N m", "N m/s", "s", "-"]
    assert _name("sigma", {"tested": True, "oracle": True}) == "**sigma †**"
    assert _name("sigma", {}) == "sigma"
    assert _with_n(Estimate(0.5, 0.5, 0.5, 3), 3) == "0.5"
    assert _with_n(Estimate(0.5, 0.5, 0.5, 2), 3) == "0.5 (2 of 3 seeds)"


def test_the_leaderboard_rows_by_hand():
    from adaptive_mj.study.score_card import leaderboard, terminal_table

    laws = {"mine": _law(0.6, rank=2, tested=True, tail_error=0.004), "fixed": _law(0.8, rank=1, oracle=True)}
    laws["fixed"]["compute_ratio"] = 1.234
    t = leaderboard(_plant(laws))
    assert list(t.columns[:6]) == ["rank S", "rank R", "law", "S", "R", "success"]
    assert t.columns[6] == "tail RMS error [m]" and t.columns[9] == "control RMS [N]"
    assert t.columns[10] == "control total variation per second [N/s]" and t.columns[-1] == "cost × mj_step"
    first, second = t.rows
    assert first["law"] == "fixed †" and first["cost × mj_step"] == "1.23" and first["success"] == "2/3"
    assert second["law"] == "**mine**" and second["cost × mj_step"] == "n/a" and second["rank S"] == 2
    assert second["tail RMS error [m]"] == "0.004" and second["S"] == "0.6"
    assert second["estimate drift rate [1/100 s]"] == "0 (2 of 3 seeds)"
    term = terminal_table(_plant(laws))
    assert [r["law"] for r in term.rows] == ["  fixed †", "* mine"]
    assert term.rows[1]["S"] == "0.600" and term.rows[1]["R"] == "0.500 [0.400, 0.600]"


def test_the_margins_table_marks_the_top_the_bottom_and_n_a():
    from adaptive_mj.study.score_card import margins_table

    def st(margins, first_fails, fr=None):
        vals = [m if m is not None else 0 for m in margins]
        return {"margin": estimate(vals).as_dict(), "margins": margins, "first_fails": first_fails,
                "failure_rate_at_hi": fr}

    laws = {"top": _law(0.9, rank=1), "bottom": _law(0.5, rank=2), "mixed": _law(0.4, rank=3)}
    laws["top"]["stressors"] = {"delay": st([200, 200], [None, None], 0.0)}
    laws["bottom"]["stressors"] = {"delay": st([None, None], [0, 0], 1.0), "noise": st([0.5, 0.5], [0.6, 0.6])}
    laws["mixed"]["stressors"] = {"delay": st([200, 100], [None, 101], 0.5), "noise": st([None, 0.5], [0.0, 0.6])}
    t = margins_table(_plant(laws))
    assert list(t.columns) == ["law", "R", "delay [steps]", "noise"]
    top, bottom, mixed = t.rows
    assert top["delay [steps]"] == "≥ 200 (top)<br>fail@hi 0 %" and top["noise"] == "n/a"
    assert bottom["delay [steps]"] == "< 0 (bottom)<br>fail@hi 100 %" and bottom["noise"] == "0.5"
    assert mixed["delay [steps]"].startswith("150 [") and mixed["delay [steps]"].endswith("<br>fail@hi 50 %")
    assert "(top)" not in mixed["delay [steps]"] and "(bottom)" not in mixed["delay [steps]"]
    assert mixed["noise"] == "0.25 [-2.93, 3.43]"  # one seed failed at the low end: neither top nor bottom


def test_the_card_s_sentences_by_hand():
    from adaptive_mj.study.score_card import _cell, runs_text, saturated_text, separated_text

    assert separated_text({"plants": {"heave": {}, "arm": {"separated_pairs": {"performance": 1, "robustness": 0,
                                                                               "pairs": 3}}}}) == "arm S 1 and R 0 of 3"
    assert separated_text({"plants": {"heave": {}}}) == "none counted"
    data = {"plants": {"heave": {"criteria_spread": {"tail_error": {"saturated": True},
                                                     "control_rms": {"saturated": False}}},
                       "arm": {"criteria_spread": {"drift_rate": {"saturated": True}}}, "ur5e": {}}}
    assert saturated_text(data) == ("At their cap for every adaptive law, so separating none of them: tail_error on "
                                    "heave, drift_rate on arm. ")
    assert saturated_text({"plants": {"heave": {}}}).startswith("No criterion is at its cap")
    runs = {"runs": {"tasks": 12, "margins": 40, "predicted_unstable": 3,
                     "not_run": [{"plant": "heave", "law": "l1", "stressor": "control period", "seeds": 5,
                                  "why": "continuous only"},
                                 {"plant": "arm", "law": "l1", "stressor": "control period", "seeds": 3,
                                  "why": "another reason"}]}}  # the sentence gives the first one's seeds and why
    text = runs_text(runs)
    assert text.startswith("**Runs.** 12 task runs and 40 margin runs.")
    assert "predicted 3 of the margin runs unstable" in text
    assert text.endswith(" Not run: 2 searches of 5 seeds each (heave/l1: control period; arm/l1: control period): "
                         "continuous only.")
    assert "Not run" not in runs_text({"runs": {"tasks": 1, "margins": 2}})
    assert _cell(None) == "—"
    assert _cell(_law(0.6, rank=2)) == "S 0.600 (rank 2)<br>R 0.500 [0.400, 0.600] (rank 2)"


def test_rank_laws_counts_pairs_by_hand():
    from adaptive_mj.study.score import rank_laws

    def law(perf, rob):
        return {"figures": {"performance": {"values": perf}, "robustness": {"values": rob}}}

    plant = {"laws": {"a": law([0.9, 0.8, 0.7], [0.5, 0.5, 0.5]), "b": law([0.5, 0.41, 0.3], [0.5, 0.5, 0.5]),
                      "c": law([None, None, None], [0.6, 0.6, 0.6])}}
    rank_laws(plant)
    assert {lb: e["rank"] for lb, e in plant["laws"].items()} == {
        "a": {"performance": 1, "robustness": 2}, "b": {"performance": 2, "robustness": 2},
        "c": {"performance": 3, "robustness": 1}}
    assert plant["separated_pairs"] == {"performance": 1, "robustness": 2, "pairs": 3}
    assert type(plant["separated_pairs"]["pairs"]) is int  # a count, written to the card's JSON as one


def test_the_definitions_hash_is_of_sorted_ascii_json_whatever_the_registry_s_order(monkeypatch):
    """On definitions small enough to write out: the sha256 of their JSON with sorted keys and non-ASCII escaped, so
    that cards written on any machine, in any registry order, merge."""
    import hashlib

    c = suite.Criterion("tail_error", "tracking", "tail RMS error", "output", "n", 0.5, "‖e‖")
    monkeypatch.setattr(suite, "SUITE_VERSION", 1)
    monkeypatch.setattr(suite, "CRITERIA", (c,))
    monkeypatch.setattr(suite, "JUDGED_TOGETHER", {})
    monkeypatch.setattr(suite, "SUITES", {})
    monkeypatch.setattr(suite, "TASKS", {"b": (), "a": ()})
    text = ('{"criteria": [{"doc": "\\u2016e\\u2016", "metric": "tail RMS error", "name": "tail_error", '
            '"normaliser": "n", "task": "tracking", "unit": "output", "weight": 0.5}], "suites": {}, '
            '"tasks": {"a": [], "b": []}, "together": {}, "version": 1}')
    assert suite.definitions_hash() == hashlib.sha256(text.encode()).hexdigest()[:16]
    monkeypatch.setattr(suite, "TASKS", {"a": (), "b": ()})
    assert suite.definitions_hash() == hashlib.sha256(text.encode()).hexdigest()[:16]

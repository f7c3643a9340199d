"""The searches pinned with hand-filled results (issue 54): the one bisection (adaptive_mj.study.breaking_point.
search_all) run over outcomes made by hand, with no simulation (its run_jobs replaced by a table of which values
each seed passes), every bracket written out step by step here; the quadrotor's margin and when2fail over
hand-filled evaluations (adaptive_mj.study.flight.Search); the stress study's arithmetic and sentences.

Edge cases by name: a range whose ends span exactly a decade (geometric), a bracket closed to neighbouring whole
values, when2fail returning the right end of its bracket, a value at the bound, screening's runs counted.
tools/mutate.py runs this file for breaking_point, stress and flight_study."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from adaptive_mj.plants.quadrotor import Disturbance
from adaptive_mj.study import breaking_point as bp
from adaptive_mj.study import stress
from adaptive_mj.study.breaking_point import Evaluation, Margin, Search, Stressor, search_all
from adaptive_mj.study.job import RECORD_PREFLIGHT, RunOutcome, RunSpec

BOUND = 0.01


def _outcome(job: RunSpec, tail: float, status: str = "ok", predicted: bool = False) -> RunOutcome:
    summary = {"status": status, "metrics": {"rms_tracking_error_tail": tail},
               "preflight": {"checked": True, "ok": not predicted}}
    return RunOutcome(job, status, summary)


class Table:
    """run_jobs by hand: seed k passes value v when v <= limit[k] (tail 0.001, else 0.5); every job it is given."""

    def __init__(self, limits, crash_above=None):
        self.limits, self.crash_above, self.jobs, self.calls, self.n_jobs = limits, crash_above, [], 0, set()

    def __call__(self, jobs, *, n_jobs=1, on_done=None, backend=None):
        self.calls += 1
        self.n_jobs.add(n_jobs)
        out = []
        for job in jobs:
            self.jobs.append(job)
            v = float(job.overrides[-1].split("=", 1)[1])
            if self.crash_above is not None and v > self.crash_above:
                out.append(_outcome(job, 0.0, status="crashed"))
            else:
                out.append(_outcome(job, 0.001 if v <= self.limits[job.seed] else 0.5, predicted=v > 100))
        return out


def _stressor(lo, hi, **kw) -> Stressor:
    return Stressor("x", lambda v: [f"x={v!r}"], lo, hi, **kw)


def _search(st, label="heave/sigma", rule="all", **kw) -> Search:
    return Search(Path("s.toml"), label, ("law.kind='sigma'",), st, BOUND, rule=rule, **kw)


def _run(monkeypatch, searches, limits, *, seeds=1, steps=3, screen=False, tmp_path=Path("logs"), **kw):
    table = Table(limits, **kw)
    monkeypatch.setattr(bp, "run_jobs", table)
    batches = []
    margins = search_all(searches, seeds=seeds, steps=steps, logs=tmp_path, screen=screen,
                         on_batch=lambda k, total: batches.append((k, total)))
    return margins, table, batches


def test_linear_bisection_step_by_step(monkeypatch):
    (m,), table, batches = _run(monkeypatch, [_search(_stressor(0.0, 16.0))], {0: 5.0})
    # ends 0 (pass) and 16 (fail); then 8 fails, 4 passes, 6 fails
    assert [e.value for e in m.evaluations] == [0.0, 16.0, 8.0, 4.0, 6.0]
    assert (m.margin, m.first_fail, m.resolution) == (4.0, 6.0, 2.0)
    assert batches == [(1, 5), (2, 5), (3, 5), (4, 5)]
    assert table.calls == 4 and len(table.jobs) == 5


def test_geometric_bisection_over_two_decades(monkeypatch):
    (m,), _, _ = _run(monkeypatch, [_search(_stressor(1.0, 100.0))], {0: 20.0})
    # √(1·100) = 10 passes; √(10·100) = 31.6 fails; (10, 31.6) spans less than a decade: its middle, 20.8, fails
    assert [e.value for e in m.evaluations][2:] == pytest.approx([10.0, 1000 ** 0.5, (10 + 1000 ** 0.5) / 2])
    assert m.margin == 10.0 and m.first_fail == pytest.approx((10 + 1000 ** 0.5) / 2)


def test_midpoints_by_hand():
    assert bp._mid(1.0, 10.0, _stressor(1.0, 10.0)) == pytest.approx(10 ** 0.5)  # exactly a decade: geometric
    assert bp._mid(1.0, 9.99, _stressor(1.0, 9.99)) == pytest.approx(5.495)  # less: linear
    assert bp._mid(0.0, 100.0, _stressor(0.0, 100.0)) == 50.0  # from 0: linear
    assert bp._mid(2.0, 6.0, _stressor(0.0, 10.0, integer=True)) == 4.0
    assert bp._mid(1.0, 10.0, _stressor(1.0, 10.0, integer=True)) == 3.0  # √10 rounded
    assert bp._mid(2.0, 4.5, _stressor(0.0, 10.0, integer=True)) == 3.0  # round(3.25)
    assert bp._mid(0.6, 1.4, _stressor(0.0, 10.0, integer=True)) == 1.0
    st = _stressor(0.002, 1.0, step=0.002)
    assert bp._mid(0.002, 0.008, st) == pytest.approx(0.004)  # 5 ms is 2.5 steps: 2 steps (round half to even)
    assert bp._mid(0.002, 0.006, st) == pytest.approx(0.004)
    assert bp._mid(0.002, 1.0, st) == pytest.approx(0.044)  # √0.002 = 0.0447: 22 steps


def test_midpoints_stop_where_a_bracket_is_closed_to_neighbours():
    searches = [_search(_stressor(0, 10, integer=True)), _search(_stressor(0, 10, integer=True)),
                _search(_stressor(0.002, 1.0, step=0.002)), _search(_stressor(0.002, 1.0, step=0.002)),
                _search(_stressor(0.0, 1.0))]
    brackets = [(3.0, 4.0), (3.0, 5.0), (0.004, 0.006), (0.004, 0.008), None]
    assert bp._midpoints(searches, brackets) == [(1, 4.0), (3, pytest.approx(0.006))]
    assert brackets == [None, (3.0, 5.0), None, (0.004, 0.008), None]


def test_an_integer_search_stops_at_neighbouring_values(monkeypatch):
    (m,), table, batches = _run(monkeypatch, [_search(_stressor(0, 200, integer=True))], {0: 37}, steps=20)
    # 100 F, 50 F, 25 P, round(37.5) = 38 F, round(31.5) = 32 P, 35 P, round(36.5) = 36 P, 37 P: (37, 38) closed
    assert [e.value for e in m.evaluations] == [0, 200, 100, 50, 25, 38, 32, 35, 36, 37]
    assert (m.margin, m.first_fail) == (37, 38)
    assert batches[-1] == (9, 22) and len(batches) == 9


def test_a_stepped_search_ends_on_neighbouring_whole_steps(monkeypatch):
    st = Stressor.control_period(0.002, 1.0, 0.002)
    (m,), _, _ = _run(monkeypatch, [_search(st)], {0: 0.01}, steps=30)
    assert m.margin == pytest.approx(0.01) and m.first_fail == pytest.approx(0.012)
    assert all(abs(e.value / 0.002 - round(e.value / 0.002)) < 1e-9 for e in m.evaluations)


def test_a_range_that_fails_at_its_low_end_or_passes_at_its_high_end(monkeypatch):
    (low, high), table, batches = _run(monkeypatch, [_search(_stressor(1.0, 8.0)), _search(_stressor(1.0, 8.0),
                                                                                          label="arm/sigma")],
                                      {0: 0.5}, steps=3)
    assert (low.margin, low.first_fail) == (None, 1.0) and [e.value for e in low.evaluations] == [1.0, 8.0]
    (high,), _, _ = _run(monkeypatch, [_search(_stressor(1.0, 8.0))], {0: 9.0})
    assert (high.margin, high.first_fail) == (8.0, None) and len(high.evaluations) == 2
    assert high.resolution is None and low.resolution is None
    assert batches == [(1, 5)]  # nothing bracketed: no bisection batch


def test_when2fail_is_the_right_end_of_its_bracket_and_shares_the_margin_s_runs(monkeypatch):
    """Seed 0 passes up to 3, seed 1 up to 7. Rule "all" (a margin): 8 F, 4 F, 2 P, 3 P: margin 3, first_fail 4.
    Rule "any" (when2fail): 8 F (both fail), 4 P (seed 1), 6 P, 7 P: first_fail 8, the bracket's right end."""
    st = _stressor(0.0, 16.0)
    (every, some), table, _ = _run(monkeypatch, [_search(st, rule="all"), _search(st, rule="any")], {0: 3.0, 1: 7.0},
                                   seeds=2, steps=4)
    assert [e.value for e in every.evaluations] == [0.0, 16.0, 8.0, 4.0, 2.0, 3.0]
    assert (every.margin, every.first_fail) == (3.0, 4.0)
    assert [e.value for e in some.evaluations] == [0.0, 16.0, 8.0, 4.0, 6.0, 7.0]
    assert (some.margin, some.first_fail) == (7.0, 8.0)
    # the runs both ask for (0, 16, 8, 4) are made once: 8 values × 2 seeds
    assert len(table.jobs) == 16 and len({j.log for j in table.jobs}) == 16


def test_a_value_passes_by_its_rule():
    ev = Evaluation(1.0, [0.001, math.inf], ["ok", "failed"])
    assert not _search(_stressor(0, 1)).value_passes(ev) and _search(_stressor(0, 1), rule="any").value_passes(ev)
    none = Evaluation(1.0, [math.inf, math.inf], ["failed"] * 2)
    assert not _search(_stressor(0, 1), rule="any").value_passes(none)
    assert not ev.passes and Evaluation(1.0, [0.1, 0.2], []).passes
    assert Evaluation(1.0, [0.1, math.inf, math.inf, 0.2], []).failure_rate() == 0.5
    with pytest.raises(ValueError, match=r"Search.rule must be one of \('all', 'any'\), got 'most'"):
        _search(_stressor(0, 1), rule="most")


def test_a_run_is_judged_by_its_bound_or_its_own_criterion():
    spec = RunSpec(Path("s.toml"))
    s = _search(_stressor(0, 1))
    assert s.judged(_outcome(spec, BOUND)) == BOUND  # at the bound: passes, its tail kept
    assert s.judged(_outcome(spec, 0.0100001)) == math.inf
    assert s.judged(_outcome(spec, 0.001, status="crashed")) == math.inf
    own = _search(_stressor(0, 1), run_passes=lambda r: r.status == "ok")
    assert own.judged(_outcome(spec, 0.5)) == 0.5  # its own criterion: the tail bound does not apply
    assert own.judged(_outcome(spec, 0.5, status="failed")) == math.inf
    no_tail = RunOutcome(spec, "ok", {"status": "ok", "metrics": {}})
    assert own.judged(no_tail) == 0.0  # passed by its own criterion, with no tail to show


def test_the_runs_a_search_asks_for_and_what_it_keeps_of_them(monkeypatch, tmp_path):
    st = Stressor("delay", lambda v: [f"simulation.control_delay={int(v)}"], 0, 200, integer=True, unit="steps")
    (m,), table, _ = _run(monkeypatch, [_search(st, label="heave/σ mod")], {0: 150, 1: 150}, seeds=2, steps=0,
                          tmp_path=tmp_path)
    first = table.jobs[0]
    assert first.overrides == (RECORD_PREFLIGHT, "law.kind='sigma'", "simulation.control_delay=0")
    assert first.log == tmp_path / "heave-_mod" / "delay=0-seed0.mcap" and first.seed == 0
    assert first.tag == "heave/σ mod delay=0 seed 0"
    assert [j.seed for j in table.jobs] == [0, 1, 0, 1]
    hi = m.at(200)
    assert hi.tails == [math.inf, math.inf] and hi.raw == [0.5, 0.5] and hi.predicted == [True, True]
    assert [s.log.name for s in hi.specs] == ["delay=200-seed0.mcap", "delay=200-seed1.mcap"]
    assert [str(s) for s in hi.statuses] == ["ok", "ok"]
    shifted = Search(Path("s.toml"), "arm/x", (), _stressor(0.0, 1.0), BOUND, seed=3)
    (m,), table, _ = _run(monkeypatch, [shifted], {3: 1.0, 4: 1.0}, seeds=2, steps=0, tmp_path=tmp_path)
    assert [j.seed for j in table.jobs] == [3, 4, 3, 4]
    assert [j.log.name for j in table.jobs] == ["x=0-seed3.mcap", "x=0-seed4.mcap", "x=1-seed3.mcap",
                                                "x=1-seed4.mcap"]


def test_screening_skips_the_other_seeds_of_a_failing_value_and_completes_the_first_fail(monkeypatch):
    """Every seed passes up to 5. Ends: 0's first seed passes (its others run), 16's fails (2 skipped); 8 fails
    (2 skipped), 4 passes, 6 fails (2 skipped); then first_fail 6 runs on its other two seeds."""
    (m,), table, _ = _run(monkeypatch, [_search(_stressor(0.0, 16.0))], {0: 5.0, 1: 5.0, 2: 5.0}, seeds=3,
                          screen=True)
    assert (m.margin, m.first_fail) == (4.0, 6.0)
    assert m.screened_out == 4
    assert len(table.jobs) == 11
    assert len(m.at(6.0).tails) == 3 and len(m.at(8.0).tails) == 1 and len(m.at(4.0).tails) == 3
    assert len(m.at(6.0).raw) == len(m.at(6.0).predicted) == len(m.at(6.0).specs) == len(m.at(6.0).statuses) == 3
    (m,), table, _ = _run(monkeypatch, [_search(_stressor(0.0, 16.0))], {0: 5.0, 1: 5.0, 2: 5.0}, seeds=3)
    assert (m.margin, m.first_fail, m.screened_out, len(table.jobs)) == (4.0, 6.0, 0, 15)


def test_searches_in_lockstep_each_read_their_own_ends(monkeypatch):
    (low, high), table, _ = _run(monkeypatch, [_search(_stressor(1.0, 8.0)), _search(_stressor(0.0, 0.4),
                                                                                     label="arm/sigma")], {0: 0.5})
    assert (low.margin, low.first_fail) == (None, 1.0) and (high.margin, high.first_fail) == (0.4, None)


def test_the_search_s_defaults_run_every_seed_on_one_process_and_keep_the_rows(monkeypatch):
    table = Table({0: 5.0, 1: 5.0, 2: 5.0})
    monkeypatch.setattr(bp, "run_jobs", table)
    (m,) = search_all([_search(_stressor(0.0, 16.0))], seeds=3, steps=3, logs=Path("logs"))
    assert (m.margin, m.first_fail, m.screened_out, len(table.jobs)) == (4.0, 6.0, 0, 15)
    assert table.n_jobs == {1} and all(j.keep_trajectory for j in table.jobs)


def test_screening_a_search_that_passes_its_high_end(monkeypatch):
    (m, top), table, _ = _run(monkeypatch, [_search(_stressor(0.0, 16.0)), _search(_stressor(0.0, 4.0),
                                                                                   label="arm/x")],
                              {0: 5.0, 1: 5.0}, seeds=2, screen=True)
    assert (top.margin, top.first_fail, top.screened_out) == (4.0, None, 0)
    assert (m.margin, m.first_fail, m.screened_out) == (4.0, 6.0, 2)


def test_screening_with_two_seeds(monkeypatch):
    """0 runs both seeds, 16, 8 and 6 their first only, 4 both; then 6's second: 8 runs, 2 left out."""
    (m,), table, _ = _run(monkeypatch, [_search(_stressor(0.0, 16.0))], {0: 5.0, 1: 5.0}, seeds=2, screen=True)
    assert (m.margin, m.first_fail, m.screened_out, len(table.jobs)) == (4.0, 6.0, 2, 8)


def test_screening_a_rule_any_search_runs_every_seed(monkeypatch):
    (m,), table, _ = _run(monkeypatch, [_search(_stressor(0.0, 16.0), rule="any")], {0: 3.0, 1: 7.0}, seeds=2,
                          steps=4, screen=True)
    assert (m.margin, m.first_fail, m.screened_out) == (7.0, 8.0, 0)
    assert all(len(e.tails) == 2 for e in m.evaluations)


def test_a_margin_s_statistics_by_hand():
    s = _search(_stressor(0.0, 10.0))
    m = Margin(s, 4.0, 6.0, [Evaluation(4.0, [0.1, 0.5, 0.2, 0.3, 0.4], []),
                             Evaluation(6.0, [0.1, math.inf, math.inf, 0.2, math.inf], [])])
    assert m.stats() == {"margin": 4.0, "first_fail": 6.0, "resolution": 2.0, "tail_mean": pytest.approx(0.3),
                         "tail_cvar10": 0.5, "failure_rate_beyond": 0.6}
    tails = [0.01 * k for k in range(20)]
    m = Margin(s, 4.0, None, [Evaluation(4.0, tails, [])])
    st = m.stats()
    assert st["tail_cvar10"] == pytest.approx(0.185) and st["failure_rate_beyond"] is None  # worst 2 of 20
    assert st["resolution"] is None
    st = Margin(s, None, 0.0, [Evaluation(0.0, [math.inf], [])]).stats()
    assert st["tail_mean"] is None and st["failure_rate_beyond"] == 1.0
    assert Margin(s, None, None).at(None) is None


def test_a_margin_as_text():
    st = Stressor("delay", lambda v: [], 0, 200, integer=True, unit="steps")
    s = _search(st)
    assert bp.margin_text(Margin(s, None, 0)) == "< 0 steps"
    assert bp.margin_text(Margin(s, 200, None)) == "≥ 200 steps"
    assert bp.margin_text(Margin(s, 37, 38)) == "37 steps (next 38)"
    assert bp.margin_text(Margin(_search(_stressor(0.5, 2.0)), 1.23456, 1.5)) == "1.23 (next 1.5)"


def test_labels_as_file_names():
    assert bp._file_name("heave/σ mod") == "heave_mod"
    assert bp._file_name("a.b-c_d") == "a.b-c_d"
    assert bp._file_name("__a b__") == "a_b"
    assert bp._file_name("//") == "x"


# ------------------------------------------------------------------------------------------------- the stress study


def test_a_margin_s_place_in_its_range():
    def pos(lo, hi, margin, first_fail=1e9):
        return stress.margin_position({"lo": lo, "hi": hi, "margin": margin, "first_fail": first_fail})

    assert pos(0.0, 10.0, None) == 0.0
    assert pos(0.0, 10.0, 10.0, None) == 1.0
    assert pos(0.0, 10.0, 4.0) == pytest.approx(0.4)
    assert pos(2.0, 12.0, 4.5) == pytest.approx(0.25)
    assert pos(1.0, 100.0, 10.0) == pytest.approx(0.5)  # two decades: geometric
    assert pos(2.0, 200.0, 20.0) == pytest.approx(0.5)  # log(20 / 2) / log(200 / 2)
    assert pos(1.0, 10.0, 10 ** 0.25) == pytest.approx(0.25)  # exactly a decade: geometric
    assert pos(1.0, 9.0, 3.0) == pytest.approx(0.25)  # less than a decade: linear


def _m(label, st, margin, first_fail):
    return Margin(_search(st, label=label), margin, first_fail)


def test_laws_in_one_open_bracket_are_named_and_closed_or_ended_ones_are_not():
    lin, whole = _stressor(0.0, 16.0), Stressor("delay", lambda v: [], 0, 200, integer=True)
    stepped = Stressor("period", lambda v: [], 0.002, 1.0, step=0.002)
    margins = [_m("heave/a", lin, 4.0, 6.0), _m("heave/b", lin, 4.0, 6.0), _m("heave/c", lin, 6.0, 8.0),
               _m("arm/a", lin, 4.0, 6.0),  # another plant: apart
               _m("heave/a", whole, 37, 38), _m("heave/b", whole, 37, 38),  # closed: a real tie
               _m("heave/a", whole, 30, 32), _m("heave/b", whole, 30, 32),
               _m("heave/a", stepped, 0.004, 0.006), _m("heave/b", stepped, 0.004, 0.006),
               _m("heave/c", stepped, 0.004, 0.008), _m("heave/d", stepped, 0.004, 0.008),
               _m("arm/b", lin, None, 0.0), _m("arm/c", lin, None, 0.0),  # the range's low end
               _m("arm/d", lin, 16.0, None), _m("arm/e", lin, 16.0, None)]
    text = stress.unseparated_text(margins, steps=6)
    assert text.startswith("**Not told apart at this resolution** (6 bisection steps;")
    assert "heave x [4, 6): a, b; heave delay [30, 32): a, b; heave period [0.004, 0.008): c, d." in text
    assert "[37, 38)" not in text and "[0.004, 0.006)" not in text and "arm" not in text
    assert stress.unseparated_text(margins[:1] + margins[2:4], steps=6) == ""
    assert stress.margin_text_of(0.5, 1.25) == "[0.5, 1.25)"


def test_the_pre_flight_sentence_counts_by_hand():
    s = _search(_stressor(0.0, 1.0))
    m = Margin(s, 0.5, 1.0, [Evaluation(0.5, [0.1, 0.2], [], predicted=[True, False]),
                             Evaluation(1.0, [math.inf, math.inf], [], predicted=[True, True])], screened_out=3)
    text = stress.preflight_text([m])
    assert text.startswith("The pre-flight check predicted 3 of the runs unstable")
    assert "and 2 of them failed." in text and "Screening left out 3 runs" in text
    quiet = stress.preflight_text([Margin(s, 0.5, 1.0, [Evaluation(0.5, [0.1], [], predicted=[False])])])
    assert quiet.startswith("The pre-flight check predicted none") and "Screening" not in quiet
    screened = stress.preflight_text([Margin(s, 0.5, 1.0, [Evaluation(0.5, [0.1], [], predicted=[False])],
                                             screened_out=4)])
    assert screened.startswith("The pre-flight check predicted none") and screened.endswith(
        " Screening left out 4 runs (a value's other seeds once its first had failed: the value fails either way), "
        "by the same rule for every law.")


def test_the_stress_table_by_hand():
    lin = _stressor(0.0, 16.0)
    other = Stressor("delay", lambda v: [], 0, 200, integer=True, unit="steps")
    m = Margin(_search(lin, label="heave/a"), 4.0, 6.0, [Evaluation(4.0, [0.01, 0.05], []),
                                                          Evaluation(6.0, [math.inf, 0.2], [])])
    t = stress.table([m, _m("heave/b", other, None, 0), _m("heave/b", lin, 16.0, None)], seeds=2)
    assert list(t.columns) == ["plant / law", "x", "delay"]
    a, b = t.rows
    assert a == {"plant / law": "heave/a", "x": "4 (next 6)<br>tail 0.03/0.05, fail 50 %", "delay": "n/a"}
    assert b == {"plant / law": "heave/b", "x": "≥ 16", "delay": "< 0 steps"}


# ------------------------------------------------------------------------------------------------- the quadrotor's


def _flight(evaluations, d=None):
    from adaptive_mj.study.flight import Search as FlightSearch

    return FlightSearch("geometric", d or Disturbance("wind", "m/s", lambda v: [], 0.0, 8.0), dict(evaluations))


def test_when2fail_and_the_margin_over_hand_filled_evaluations():
    T, F = True, False
    s = _flight({0.0: [T, T], 2.0: [T, F], 4.0: [F, T], 6.0: [F, F], 8.0: [F, F]})
    assert s.margin() == (0.0, 2.0)
    assert s.when2fail() == (4.0, 6.0)  # the smallest value every seed fails, and the last below it some passed
    assert s.success_rate(2.0) == 0.5
    # not monotone: the first all-failing value counts, and a success above it is no part of its bracket
    s = _flight({0.0: [T, T], 2.0: [F, F], 4.0: [T, F], 6.0: [F, F]})
    assert s.when2fail() == (0.0, 2.0) and s.margin() == (0.0, 2.0)
    assert _flight({1.0: [T], 3.0: [T]}).when2fail() == (3.0, None)
    assert _flight({1.0: [T], 3.0: [T]}).margin() == (3.0, None)
    assert _flight({1.0: [F], 3.0: [F]}).when2fail() == (None, 1.0)
    assert _flight({1.0: [F], 3.0: [F]}).margin() == (None, 1.0)
    assert _flight({1.0: [F, T], 3.0: [T, T]}).margin() == (3.0, None)  # below the margin: not its first failure


def test_the_flight_grids_by_hand():
    from adaptive_mj.study import flight

    assert flight.grid(Disturbance("d", "", lambda v: [], 0.0, 1.0), 5) == [0.0, 0.25, 0.5, 0.75, 1.0]
    assert flight.grid(Disturbance("d", "", lambda v: [], 1.0, 100.0), 3) == pytest.approx([1.0, 10.0, 100.0])
    assert flight.grid(Disturbance("d", "", lambda v: [], 1.0, 10.0), 3) == pytest.approx([1.0, 10 ** 0.5, 10.0])
    assert flight.grid(Disturbance("d", "", lambda v: [], 1.0, 9.0), 3) == [1.0, 5.0, 9.0]
    assert flight.grid(Disturbance("d", "", lambda v: [], 2.0, 18.0), 3) == [2.0, 10.0, 18.0]  # 9x: even
    assert flight.grid(Disturbance("d", "s", lambda v: [], 0.0, 0.01, step=0.002), 4) == pytest.approx(
        [0.0, 0.004, 0.006, 0.01])  # 0, 1/3, 2/3 and 1 of 5 steps, rounded to whole steps


def test_the_flight_brackets_as_text():
    from adaptive_mj.study.flight import bracket_text

    d = Disturbance("wind", "m/s", lambda v: [], 0.5, 40.0)
    assert bracket_text(d, 2.0, 3.0, upper=True) == "3 m/s (≥ 2 m/s)"
    assert bracket_text(d, None, 3.0, upper=True) == "≤ 3 m/s"
    assert bracket_text(d, 2.0, None, upper=True) == "> 40 m/s"
    assert bracket_text(d, 2.0, 3.0, upper=False) == "2 m/s (< 3 m/s)"
    assert bracket_text(d, 2.0, None, upper=False) == "≥ 2 m/s"
    assert bracket_text(d, None, 3.0, upper=False) == "< 0.5 m/s"


def test_grid_results_fill_each_search_from_its_tags():
    from adaptive_mj.study import flight

    d = Disturbance("rotor loss", "%", lambda v: [], 0.0, 1.0)
    s = flight.searches(("geometric",), (d,))
    ok = _outcome(RunSpec(Path("x.toml")), 0.0)
    ok.extras["flight_metrics"] = {"max_error": 0.5}
    bad = _outcome(RunSpec(Path("x.toml")), 0.0)
    bad.extras["flight_metrics"] = {"max_error": 1.5}
    at_bound = _outcome(RunSpec(Path("x.toml")), 0.0)
    at_bound.extras["flight_metrics"] = {"max_error": 1.0}
    results = {"geometric-rotor_loss=0 seed 0": ok, "geometric-rotor_loss=0 seed 1": at_bound,
               "geometric-rotor_loss=0.5 seed 0": bad, "geometric-rotor_loss=1 seed 1": ok}
    (filled,) = flight.grid_results(s, 3, 2, results)
    assert filled.evaluations == {0.0: [True, True], 0.5: [False, False], 1.0: [False, True]}

"""Breaking points by bisection over seeded runs (adaptive_mj.study.breaking_point) and the
`adaptive-mj stress` command's input checks."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.plants import study_spec
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.scenario import SCENARIOS_DIR
from adaptive_mj.study.breaking_point import Evaluation, Margin, Search, Stressor, margin_text, search_all
from adaptive_mj.study import stress

HEAVE = SCENARIOS_DIR / "heave_tracking.toml"
BASE = ("simulation.duration=3.0", "simulation.initial_state='reference'", "law.initial_estimates='model'",
        "noise.std={y=0.0005, y_dot=0.005}")


def test_bisection_brackets_the_delay_margin(tmp_path):
    """The heave law against a control delay of 0..200 steps, 2 seeds: the margin passes on every
    seed, the next value fails on at least one, the bracket is at most 200 / 2^steps wide (whole
    steps), and every run left its log."""
    search = Search(HEAVE, "heave/adaptive", BASE,
                    Stressor.key("simulation.control_delay", 0, 200, integer=True, unit="steps"), 0.01)
    (m,) = search_all([search], seeds=2, steps=4, logs=tmp_path)
    assert m.margin is not None and m.first_fail is not None
    assert 0 <= m.margin < m.first_fail <= 200
    assert m.resolution <= math.ceil(200 / 2 ** 4)
    assert m.at(m.margin).passes and not m.at(m.first_fail).passes
    for e in m.evaluations:  # monotone in this search: every value above the margin failed
        assert e.passes == (e.value <= m.margin)
    stats = m.stats()
    assert 0 < stats["failure_rate_beyond"] <= 1.0
    assert stats["tail_cvar10"] == max(m.at(m.margin).tails) >= stats["tail_mean"]
    # one log per run: the probes past the delayed loop's pre-flight limit are run too (and fail by their outcome)
    runs = [st for e in m.evaluations for st in e.statuses]
    assert len(list(tmp_path.rglob("*.mcap"))) == len(runs) and "refused" not in runs
    assert any(p for e in m.evaluations for p in e.predicted)  # the range reaches past the pre-flight limit


def test_screening_gives_the_same_margins_with_fewer_runs(tmp_path):
    """screen=True (the stress study's): a value's other seeds only where its first passed, the first_fail completed
    at the end. The same margins, first_fail, evaluated values and statistics (tail mean, CVaR, failure rate over
    every seed) as the full search, the margin's evaluation the same seeds' tails; fewer runs, one log each."""
    delay = Search(HEAVE, "heave/adaptive", BASE,
                   Stressor.key("simulation.control_delay", 0, 200, integer=True, unit="steps"), 0.01)
    low = Search(HEAVE, "heave/low", BASE, Stressor.key("simulation.control_delay", 0, 3, integer=True), 1e-12)
    full = search_all([delay, low], seeds=3, steps=3, logs=tmp_path / "full")
    screened = search_all([delay, low], seeds=3, steps=3, logs=tmp_path / "screened", screen=True)
    for a, b in zip(full, screened, strict=True):
        assert (a.margin, a.first_fail) == (b.margin, b.first_fail)
        assert [e.value for e in a.evaluations] == [e.value for e in b.evaluations]
        assert [e.passes for e in a.evaluations] == [e.passes for e in b.evaluations]
        assert a.stats() == b.stats()
        assert len(b.at(b.first_fail).tails) == 3
    assert screened[1].margin is None and screened[1].first_fail == 0  # the low end failed: completed at the end
    runs = lambda ms: [st for m in ms for e in m.evaluations for st in e.statuses]  # noqa: E731
    assert len(runs(screened)) < len(runs(full))
    # what screening left out is counted (the stress report says it): the full search's runs less the screened's
    assert sum(m.screened_out for m in screened) == len(runs(full)) - len(runs(screened)) > 0
    assert sum(m.screened_out for m in full) == 0
    logs = len(list((tmp_path / "screened").rglob("*.mcap")))
    assert logs == len(runs(screened)) and "refused" not in runs(screened)


def test_margin_beyond_the_range_and_below_it(tmp_path):
    low = Search(HEAVE, "heave/low", BASE, Stressor.key("simulation.control_delay", 0, 3, integer=True), 0.01)
    none = Search(HEAVE, "heave/none", BASE, Stressor.key("simulation.control_delay", 0, 3, integer=True), 1e-12)
    ok, bad = search_all([low, none], seeds=1, steps=2, logs=tmp_path)
    assert ok.margin == 3 and ok.first_fail is None and margin_text(ok) == "≥ 3"
    assert bad.margin is None and bad.first_fail == 0 and margin_text(bad) == "< 0"


def test_cvar_is_the_mean_of_the_worst_tenth():
    m = Margin(Search(HEAVE, "x", (), Stressor.key("k", 0, 1), 1.0), 0.5, 1.0,
               [Evaluation(0.5, list(np.arange(1.0, 21.0)), ["ok"] * 20), Evaluation(1.0, [1, math.inf], ["ok"] * 2)])
    st = m.stats()
    assert st["tail_cvar10"] == pytest.approx(19.5)  # worst 2 of 20
    assert st["tail_mean"] == pytest.approx(10.5)
    assert st["failure_rate_beyond"] == 0.5


def test_the_study_derives_its_laws_from_the_models():
    """Every plant gets the eight laws minus composite unless asked, each with numbers read from
    the scenario and the compiled model (projection box around the true θ, leak toward it)."""
    plants = stress.plants(10.0)
    heave_laws = dict(stress.laws(plants[0], composite=False))
    assert list(heave_laws) == ["adaptive", "dead_zone", "sigma", "e_modification", "projection", "fixed_nominal",
                                "robust_sliding"]
    (box,) = heave_laws["projection"]  # c = 1.0000000000000009 kg as MuJoCo computes it
    assert box.startswith("law.projection={d=[18.5, 74.0], b=[30.0, 120.0], c=[0.500000000000000")
    assert "composite" in dict(stress.laws(plants[1], composite=True))
    names = [s.name for s in stress.stressors(plants[1], 10.0)]
    assert names == ["noise σ_y", "disturbance", "payload ratio", "delay", "control period"]
    assert stress.stressors(plants[1], 10.0)[2].overrides(4.0) == ["events=[{t=5.0, kind='payload_mass', value=2.0}]"]


@pytest.mark.parametrize("args, match", [
    (["--seeds", "0"], r"--seeds must be an integer >= 1, got 0"),
    (["--steps", "-1"], r"--steps must be an integer >= 0, got -1"),
    (["--duration", "0"], r"--duration must be > 0 \[s\], got 0.0"),
])
def test_stress_refuses_bad_numbers_with_one_line(args, match, capsys, tmp_path):
    assert main(["stress", "-o", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(match, err[0]), err


def test_sweep_breaking_point_finds_the_delay_margin(tmp_path, capsys):
    out = tmp_path / "bp"
    assert main(["sweep", "heave_tracking", "--breaking-point", "simulation.control_delay=0:200", "--tail-bound",
                 "0.01", "--seeds", "1", "--steps", "3", "--set", "simulation.duration=3", "-o", str(out)]) == 0
    import json

    record = json.loads((out / "breaking_point.json").read_text())
    assert record["integer"] and 0 <= record["margin"] < record["first_fail"] <= 200
    assert record["resolution"] == record["first_fail"] - record["margin"] <= 25
    assert not any("refused" in e["statuses"] for e in record["evaluations"])  # every probe run
    assert len(list((out / "logs").rglob("*.mcap"))) == len(record["evaluations"]) == 5
    assert "simulation.control_delay: margin" in capsys.readouterr().out


@pytest.mark.parametrize("args, match", [
    (["--breaking-point", "k=0:1"], r"--breaking-point needs --tail-bound B > 0"),
    (["--breaking-point", "k=1:0", "--tail-bound", "1"], r"--breaking-point 'k=1:0': LO must be < HI, got 1 and 0"),
    (["--breaking-point", "k=0:1", "--tail-bound", "1", "--grid", "lambda=1,2"],
     r"--breaking-point and --grid cannot be combined"),
    (["--breaking-point", "nope=0:1", "--tail-bound", "1"], r"nope"),
])
def test_sweep_breaking_point_errors_are_one_line(args, match, capsys, tmp_path):
    assert main(["sweep", "heave_tracking", "-o", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(match, err[0]), err


def test_the_stress_study_covers_the_six_joint_arm(tmp_path):
    """The 6-joint arm's laws are derived from its scenario and model (leak toward the true θ, the
    dead-zone from the nominal noise), its stressors are the real-robot conditions, and a search on
    it finds a noise margin between its ends."""
    from adaptive_mj.setup.build import build

    arm6 = [p for p in stress.plants(2.0) if p.name == "ur5e"][0]
    laws = dict(stress.laws(arm6, composite=False))
    assert list(laws) == ["adaptive", "dead_zone", "sigma", "e_modification", "projection", "saturation_freeze",
                          "computed_torque", "pd_gravity"]
    scn = sc.load(sc.SCENARIOS_DIR / "ur5e_identification.toml", overrides=list(arm6.base))
    s = build(scn)
    assert laws["sigma"][0] == f"law.sigma={float(s.law.gamma[0]) / study_spec.LEAK_TIME!r}"
    assert f"'payload/body.m'={float(s.plant.true_theta()[0])!r}" in laws["sigma"][1]
    names = [st.name for st in stress.stressors(arm6, 2.0)]
    assert names == ["noise σ_y", "encoder Δ", "velocity filter τ", "disturbance", "lag τ", "torque limit ÷",
                     "payload ratio", "delay", "control period"]
    cut = stress.stressors(arm6, 2.0)[5].overrides(10.0)
    assert cut == ["plant.torque_limit={shoulder_pan=15.0, shoulder_lift=15.0, elbow=15.0, wrist_1=2.8, wrist_2=2.8, "
                   "wrist_3=2.8}"]
    enc = stress.stressors(arm6, 2.0)[1]
    assert enc.overrides(2 * math.pi / 4096) == ["sensors={encoder_counts=4096.0}"]
    bench = stress.study(composite=False, duration=2.0, plant_laws=stress.BENCH_SETTINGS["plant_laws"])
    assert {s.label for s in bench if s.label.startswith("ur5e/")} == {
        f"ur5e/{law}" for law in stress.BENCH_SETTINGS["plant_laws"]["ur5e"]}
    noise = [x for x in stress.study(composite=False, duration=2.0)
             if x.label == "ur5e/adaptive" and x.stressor.name == "noise σ_y"]
    (m,) = search_all(noise, seeds=1, steps=2, logs=tmp_path / "logs", n_jobs=2)
    assert m.margin is not None and m.first_fail is not None and 1e-5 <= m.margin < m.first_fail <= 0.1


# ---------------------------------------------------------------- one arena: the same rules for every law

EMOD = Path(__file__).resolve().parents[1] / "examples" / "emod_law" / "emod_law.py"


@pytest.fixture
def emod_law(monkeypatch):
    """The example plugin law `emod` (examples/emod_law: the sliding law with e-modification, no feedback()),
    registered as if pip had installed it (the entry points read in this process)."""
    import importlib.util
    import sys

    from adaptive_mj.laws import plugin
    from adaptive_mj.plugins import Installed

    spec = importlib.util.spec_from_file_location("emod_law", EMOD)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setitem(sys.modules, "emod_law", module)
    real = plugin.installed
    entry = Installed("emod", module.LAW, "adaptive-mj-emod-law", "0.1.0", "0" * 64)
    monkeypatch.setattr(plugin, "installed", lambda: {**real(), "emod": entry})
    return module.LAW


def test_a_law_the_pre_flight_check_flags_and_a_copy_without_feedback_get_the_same_margin(emod_law, monkeypatch,
                                                                                         tmp_path):
    """The heave vehicle's sliding law (it declares feedback(): the pre-flight check finds μT = 2.08 past the held
    loop's limit 2 at a 0.2 s control period), the emod plugin with ν = 0 and the same gains (the same law, its
    feedback() declared: checked alike) and that plugin without feedback() (never checked), searched over the
    control period: every probe at 0.2 s is run, all pass (tail error about 3 mm < 10 mm), and the three margins,
    brackets and tail errors are the same. Before, the checked laws' probes were refused, counted as failures with
    no run behind them, and their margins came out lower than the unchecked copy's."""
    import dataclasses

    from adaptive_mj.laws import plugin
    from adaptive_mj.plugins import Installed

    unchecked = dataclasses.replace(emod_law, feedback=None)
    with_emod = plugin.installed
    monkeypatch.setattr(plugin, "installed", lambda: {
        **with_emod(), "emod_unchecked": Installed("emod_unchecked", unchecked, "adaptive-mj-emod-law", "0.1.0",
                                                   "0" * 64)})
    stressor = Stressor.control_period(0.15, 0.2, 0.001, name="control period")
    base = (*BASE[1:], "simulation.duration=20.0")
    emod_gains = ("law.lambda=5.0", "law.k=200.0", "law.gamma_d=0.0025", "law.gamma_p=0.5", "law.nu=0.0")
    built_in = Search(HEAVE, "heave/adaptive", (*base, "law.gamma={d=0.0025, b=0.5, c=0.5}"), stressor, 0.01)
    copy = Search(HEAVE, "heave/emod", (*base, sc.law_swap("emod"), *emod_gains), stressor, 0.01)
    bare = Search(HEAVE, "heave/emod_unchecked", (*base, sc.law_swap("emod_unchecked"), *emod_gains), stressor, 0.01)
    margins = search_all([built_in, copy, bare], seeds=2, steps=1, logs=tmp_path)
    assert all([e.value for e in m.evaluations] == [0.15, 0.2] for m in margins)
    at = [m.at(0.2) for m in margins]
    assert [e.predicted for e in at] == [[True, True], [True, True], [False, False]]  # it warns; it decides nothing
    for e in at:  # run and judged by the outcome: a verdict of the scenario's own criteria, never "refused"
        assert e.statuses == at[0].statuses and "refused" not in e.statuses and e.passes
        np.testing.assert_allclose(e.raw, at[0].raw, rtol=1e-6)
    assert max(at[0].raw) < 0.01
    assert [(m.margin, m.first_fail) for m in margins] == [(0.2, None)] * 3


# ---------------------------------------------------------------- one search for every study


def test_a_value_passes_by_its_search_s_rule():
    """rule "all": every seed must pass (a margin); rule "any": one seed suffices (AdaptiveQuadBench's when2fail is
    then the first value where none does); a run_passes predicate replaces the tail bound."""
    st = Stressor.key("x", 0.0, 1.0)
    ev = Evaluation(0.5, [0.001, math.inf], ["ok", "diverged"])
    assert not Search(HEAVE, "a", (), st, 0.01).value_passes(ev)
    assert Search(HEAVE, "a", (), st, 0.01, rule="any").value_passes(ev)
    assert not Search(HEAVE, "a", (), st, 0.01, rule="any").value_passes(Evaluation(0.5, [math.inf] * 2, []))
    with pytest.raises(ValueError, match=r"Search.rule must be one of \('all', 'any'\), got 'most'"):
        Search(HEAVE, "a", (), st, 0.01, rule="most")

    from adaptive_mj.study.job import RunOutcome, RunSpec

    # a completed run whose tail is beyond the bound, which its own predicate passes
    run = RunOutcome(RunSpec(HEAVE), "ok", {"metrics": {"rms_tracking_error_tail": 0.5}, "reason": ""})
    assert Search(HEAVE, "a", (), st, 0.01).judged(run) == math.inf
    assert Search(HEAVE, "a", (), st, 0.01, run_passes=lambda r: True).judged(run) == 0.5
    assert Search(HEAVE, "a", (), st, 0.01, run_passes=lambda r: False).judged(run) == math.inf


def test_the_quadrotor_s_when2fail_and_the_heave_breaking_point_come_from_one_search(monkeypatch, tmp_path):
    """flight.margins (AdaptiveQuadBench's margin and when2fail) runs breaking_point.search_all, the search of the
    stress study and the scorecard: a search of rule "all" and one of rule "any" per (law, disturbance), both judging
    a run by flight.succeeded and sharing the runs both ask for (one log per intensity and seed)."""
    from adaptive_mj.study import breaking_point, flight

    calls = []
    real = breaking_point.search_all

    def spy(searches, **kw):
        margins = real(searches, **kw)
        calls.append((list(searches), margins))
        return margins

    monkeypatch.setattr(breaking_point, "search_all", spy)
    force = next(d for d in flight.DISTURBANCES if d.name == "force")
    (s,) = flight.margins(flight.searches(laws=("geometric_adaptive",), disturbances=(force,)), seeds=2, steps=3,
                          logs=tmp_path)
    ((probes, (margin, when2fail)),) = calls
    assert [p.rule for p in probes] == ["all", "any"] and all(p.run_passes is flight.succeeded for p in probes)
    assert margin.margin is not None and margin.first_fail is not None and when2fail.first_fail is not None
    assert s.margin() == (margin.margin, margin.first_fail)
    assert s.when2fail() == (when2fail.margin, when2fail.first_fail)
    assert not any(s.evaluations[when2fail.first_fail]) and any(s.evaluations[when2fail.margin])
    assert len(list(tmp_path.rglob("*.mcap"))) == 2 * len(s.evaluations)  # shared: each value and seed run once


def test_laws_in_the_same_open_bracket_are_named_as_not_told_apart():
    """The bench's study bisects 2 steps, so on the UR5e every law's delay margin came out "0 (next 50)": the report
    names such groups as not told apart at this resolution, and leaves out brackets closed to neighbouring values
    (a real tie), searches the range ends (failing at its low end, passing at its high end) and laws whose brackets
    differ."""
    delay = Stressor("delay", lambda v: [], 0, 200, integer=True, unit="steps")
    noise = Stressor("noise", lambda v: [], 0.0, 1.0)

    def m(label, st, lo, hi):
        return Margin(Search(HEAVE, label, (), st, 0.01), lo, hi)

    margins = [m("ur5e/adaptive", delay, 0, 50), m("ur5e/sigma", delay, 0, 50), m("ur5e/pd", delay, 50, 100),
               m("heave/adaptive", delay, 7, 8), m("heave/sigma", delay, 7, 8),  # closed: a tie, not a question
               m("heave/adaptive", noise, 0.25, 0.5), m("heave/sigma", noise, 0.25, 0.5),
               m("arm/adaptive", noise, None, 0.0), m("arm/sigma", noise, None, 0.0),  # both fail at the low end
               m("arm/adaptive", delay, 200, None), m("arm/sigma", delay, 200, None)]  # both pass the high end
    text = stress.unseparated_text(margins, steps=2)
    assert text.startswith("**Not told apart at this resolution** (2 bisection steps")
    assert "ur5e delay [0, 50): adaptive, sigma" in text and "pd" not in text
    assert "heave noise [0.25, 0.5): adaptive, sigma" in text and "heave delay" not in text
    assert "arm" not in text  # the range ends those searches, not the resolution
    assert stress.unseparated_text([m("ur5e/adaptive", delay, 0, 50), m("ur5e/pd", delay, 50, 100)], steps=2) == ""

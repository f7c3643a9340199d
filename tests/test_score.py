"""adaptive-mj score: a law ranked against the baselines (adaptive_mj.study.score), its statistics
(adaptive_mj.study.stats), the card's files and --merge, and its one-line refusals."""
import importlib.util
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.errors import ScenarioError
from adaptive_mj.setup import scenario as sc
from adaptive_mj.study import score_suite, stress
from adaptive_mj.study import api
from adaptive_mj.study.stats import Estimate, estimate, ranks, separable

REPO = Path(__file__).resolve().parents[1]
EMOD = REPO / "examples" / "emod_law" / "emod_law.py"
EMOD_GAINS = "[heave]\nlambda = 5.0\nk = 200.0\ngamma_d = 0.0025\ngamma_p = 0.002\nnu = 0.0\n"


# ---------------------------------------------------------------- statistics


def test_an_interval_is_the_t_interval_and_identical_values_have_none():
    e = estimate([1.0, 2.0, 3.0])
    assert e.mean == 2.0 and e.n == 3
    assert math.isclose(e.hi - e.mean, 4.302652729911275 * 1.0 / math.sqrt(3), rel_tol=1e-9)  # t_{0.975, 2} s/√n
    assert estimate([0.5, 0.5, 0.5]) == Estimate(0.5, 0.5, 0.5, 3)
    assert estimate([1.0]).lo == -math.inf  # one seed says nothing of the spread
    assert estimate([math.nan, math.inf]).n == 0


def test_ranks_share_a_place_when_intervals_overlap():
    a, b, c = Estimate(0.9, 0.88, 0.92, 3), Estimate(0.89, 0.85, 0.91, 3), Estimate(0.5, 0.45, 0.55, 3)
    assert not separable(a, b) and separable(a, c)
    assert ranks([a, b, c]) == [1, 1, 3]
    assert ranks([a, b, c], higher_is_better=False) == [2, 2, 1]
    # not a grouping (stats' docstring): wide overlaps both, which are separable from each other
    wide, top, low = Estimate(0.8, 0.7, 0.95, 3), Estimate(0.9, 0.88, 0.92, 3), Estimate(0.75, 0.74, 0.76, 3)
    assert ranks([top, wide, low]) == [1, 1, 2]


def test_an_interval_stays_in_its_figure_s_domain_and_reads_back_from_strict_json():
    e = estimate([0.0, 0.0, 0.3], lowest=0.0)
    assert e.lo == 0.0 and e.hi > 0.3
    assert estimate([0.99, 1.0, 0.9], lowest=0.0, highest=1.0).hi == 1.0
    one = estimate([0.4], lowest=0.0, highest=1.0)
    assert (one.lo, one.hi) == (0.0, 1.0)
    back = Estimate.from_dict(json.loads(json.dumps(estimate([1.0]).as_dict(), allow_nan=False)))
    assert back.lo == -math.inf and back.hi == math.inf and back.mean == 1.0
    assert math.isnan(Estimate.from_dict(json.loads(json.dumps(estimate([]).as_dict(), allow_nan=False))).mean)


# ---------------------------------------------------------------- one seed's figures


def _Run(status="ok", tail=0.001, extras=None, final=None):
    """A task run's outcome with hand-set figures."""
    from pathlib import Path

    from adaptive_mj.study.job import RunOutcome, RunSpec

    summary = {"status": status, "metrics": {"rms_tracking_error_tail": tail, "control_rms": 10.0,
                                             "control_total_variation": 500.0},
               "final": final or {"theta_hat": {"a": 1.5, "b": 0.0}, "theta": {"a": 1.0, "b": 2.0}}}
    return RunOutcome(RunSpec(Path("x.toml")), status, summary, extras or {})


def _change(env, t_e=5.0):
    return {"change_response": {"event_time": t_e, "peak_error_after": max(env), "window": 0.01, "envelope": env}}


def test_seed_figures_read_each_criterion_from_its_run():
    from adaptive_mj.study.score import seed_figures

    bound, limits, durations = 0.01, (100.0, 100.0), {"tracking": 10.0, "change": 10.0, "hold": 20.0}
    env = [0.05, 0.03, 0.02] + [0.001] * 10  # above the bound for the first three 10 ms windows
    runs = {"tracking": _Run(tail=0.004), "change": _Run(extras=_change(env)),
            "hold": _Run(extras={"estimate_drift": -0.2})}
    f = seed_figures(runs, bound, limits, durations)
    assert f["tail_error"] == 0.004 and f["control_rms"] == 10.0 and f["control_tv_rate"] == 50.0
    assert f["param_error"] == pytest.approx(math.sqrt(0.85), rel=1e-15)  # ‖(0.5, −2)‖ / ‖(1, 2)‖ = √(4.25 / 5)
    assert f["recovery_time"] == pytest.approx(0.03) and f["peak_after_change"] == 0.05
    assert f["drift_rate"] == 0.2 and f["success"] == 1.0
    # by hand (docs/METRICS.md's weights and normalisers): tail 0.30 · 0.004/0.01, peak 0.10 · 0.05/0.1, recovery
    # 0.10 · 0.03/5, control 0.10 · 10/100, TV 0.10 · 50/10⁴, parameter error 0.15 · √0.85, and the drift judged
    # with it: 0.15 · max(0.2, √0.85)
    penalty = 0.12 + 0.05 + 0.0006 + 0.01 + 0.0005 + 2 * 0.15 * math.sqrt(0.85)
    assert f["performance"] == pytest.approx(1.0 - penalty, rel=1e-12)
    # never recovered: the time left; a tracking run past the bound: no success, S = 0
    f = seed_figures({**runs, "change": _Run(extras=_change([0.05] * 13))}, bound, limits, durations)
    assert f["recovery_time"] == 5.0
    f = seed_figures({**runs, "tracking": _Run(tail=0.02)}, bound, limits, durations)
    assert f["success"] == 0.0 and f["performance"] == 0.0
    # a run that diverged gives no figure: NaN, counted at its worst in S
    f = seed_figures({**runs, "hold": _Run(status="diverged")}, bound, limits, durations)
    assert math.isnan(f["drift_rate"]) and f["success"] == 0.0


def test_a_law_that_does_not_adapt_earns_nothing_for_a_still_estimate():
    """Drift is judged with identification (score_suite.JUDGED_TOGETHER): a law whose estimates never move (drift 0)
    but end the tracking run 50 % off scores as a law that drifts 50 % per 100 s; one that identified (1 % off) and
    holds still keeps its 1 %."""
    from adaptive_mj.study.score import seed_figures

    bound, limits, durations = 0.01, (100.0, 100.0), {"tracking": 10.0, "change": 10.0, "hold": 20.0}
    base = {"change": _Run(extras=_change([0.001] * 13))}

    def s(theta_hat: float, drift: float) -> float:
        final = {"theta_hat": {"a": theta_hat}, "theta": {"a": 1.0}}
        return seed_figures({**base, "tracking": _Run(final=final), "hold": _Run(extras={"estimate_drift": drift})},
                            bound, limits, durations)["performance"]

    frozen, drifting, identified = s(1.5, 0.0), s(1.5, 0.5), s(1.01, 0.0)
    assert frozen == pytest.approx(drifting, rel=1e-15)  # the frozen law gains nothing from its zero drift
    assert identified - frozen == pytest.approx(2 * 0.15 * (0.5 - 0.01), rel=1e-12)


def test_change_response_is_on_the_tail_error_s_scale_on_joints():
    """On m joints the envelope is ‖q̃‖/√m (the RMS over the joints), the scale of the tail error and its bound."""
    from types import SimpleNamespace

    from adaptive_mj.study.analysis import change_response
    from adaptive_mj.trajectory import Trajectory

    n, m = 200, 6
    t = np.arange(n) * 0.001
    ref = np.zeros((n, 3, m))
    x = np.zeros((n, 2, m))
    x[:, 0, :] = -0.002  # q̃ = 0.002 rad on every joint
    traj = Trajectory(t=t, x=x, u=np.zeros((n, m)), s=np.zeros((n, m)), ref=ref, theta_hat=np.zeros((n, 1)),
                      theta=np.zeros((n, 1)), V=np.zeros(n), names=("p",), status="ok", reason="",
                      meta={"dt": 0.001}, joint_names=tuple(f"j{i}" for i in range(m)))
    r = change_response(traj, SimpleNamespace(events=[SimpleNamespace(t=0.1)]))
    assert r["peak_error_after"] == pytest.approx(0.002, rel=1e-12)


# ---------------------------------------------------------------- bad input, one line


def test_bad_options_are_one_line_naming_what_is_wrong(tmp_path):
    with pytest.raises(ScenarioError, match="'sliding_adaptiv' is not a law kind.*did you mean 'sliding_adaptive'"):
        api.score("sliding_adaptiv", out=tmp_path / "a")
    gains = tmp_path / "g.toml"
    gains.write_text("[hove]\nlambda = 5.0\n")
    with pytest.raises(ScenarioError, match=r"g\.toml: key 'hove': expected a table named after a scored plant kind"):
        api.score("sliding_adaptive", gains=gains, out=tmp_path / "b")
    with pytest.raises(ScenarioError, match="--against: 'lecture' is no baseline"):
        api.score("sliding_adaptive", against="lecture", out=tmp_path / "c")
    with pytest.raises(ScenarioError, match="--plants: 'ship' is not a scored plant"):
        api.score("sliding_adaptive", plants="ship", out=tmp_path / "d")
    with pytest.raises(ScenarioError, match="--suite must be one of quick, full"):
        api.score("sliding_adaptive", suite="huge")
    with pytest.raises(ScenarioError, match="--seeds must be an integer >= 2"):
        api.score("sliding_adaptive", seeds=1)
    gains.write_text("[heave]\ninitial_estimates = 'model'\n")
    with pytest.raises(ScenarioError, match=r"key heave.initial_estimates: the suite sets law.initial_estimates"):
        api.score("sliding_adaptive", gains=gains, out=tmp_path / "e")
    with pytest.raises(ScenarioError, match=r"--set: law.kind is the study's"):
        api.score("sliding_adaptive", set=["law.kind='fixed_nominal'"], out=tmp_path / "e")
    gains.write_text("[manipulator]\ngamma = 0.2\n")
    with pytest.raises(ScenarioError, match=r"key 'manipulator': law 'sliding_adaptive' does not run on that plant"):
        api.score("sliding_adaptive", gains=gains, out=tmp_path / "e")
    assert not any((tmp_path / n).exists() for n in "abcde")  # refused before any folder is made


def test_gains_for_a_plant_left_out_by_plants_are_kept_not_refused(tmp_path):
    from adaptive_mj.study.score import plan

    gains = tmp_path / "g.toml"
    gains.write_text("[heave]\nk = 150.0\n[arm]\nk = 4.0\n")
    pl = plan("sliding_adaptive", label=None, sets=(), gains=gains, against=["dead_zone"], suite_name="quick",
              seeds=None, plants=["heave"])
    assert [p.name for p in pl.rows] == ["heave"] and pl.entries["heave"][0].overrides[-1] == "law.k=150.0"
    assert [e.label for e in pl.entries["heave"]] == ["sliding_adaptive", "dead_zone"]
    assert pl.entries["heave"][0].tested and not pl.entries["heave"][1].oracle


# ---------------------------------------------------------------- scoring


@pytest.fixture(scope="module")
def emod_installed():
    """The example plugin's law registered as if pip had installed it (entry points read in this process; the
    forked workers inherit it)."""
    from adaptive_mj.laws import plugin
    from adaptive_mj.plugins import Installed

    spec = importlib.util.spec_from_file_location("emod_law", EMOD)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules["emod_law"] = module
    real = plugin.installed
    entry = Installed("emod", module.LAW, "adaptive-mj-emod-law", "0.1.0", "0" * 64)
    plugin.installed = lambda: {**real(), "emod": entry}
    yield
    plugin.installed = real


@pytest.fixture(scope="module")
def cards(tmp_path_factory, emod_installed):
    """Two quick cards on the heave vehicle against the lecture's law and its dead-zone: the emod plugin, and the
    built-in sliding law itself under another name."""
    root = tmp_path_factory.mktemp("score")
    gains = root / "gains.toml"
    gains.write_text(EMOD_GAINS)
    plugin_card = api.score("emod", gains=gains, against="adaptive,dead_zone", plants="heave", seeds=3,
                            out=root / "emod", cost=False, jobs=2)
    twin_card = api.score("sliding_adaptive", label="twin", against=["adaptive", "dead_zone"], plants=["heave"],
                          seeds=3, out=root / "twin", cost=False, jobs=2)
    return plugin_card, twin_card


def test_a_law_without_its_required_gains_is_refused_before_any_run_naming_the_plant_and_the_table(emod_installed,
                                                                                                   tmp_path):
    with pytest.raises(ScenarioError) as err:
        api.score("emod", plants="heave", out=tmp_path / "x")
    text = str(err.value)
    assert "\n" not in text and "on plant heave (heave)" in text and "law.lambda" in text
    assert "[heave] table of --gains FILE.toml" in text
    assert not (tmp_path / "x").exists()


def test_a_plugin_law_is_scored_against_the_baselines_with_its_files(cards):
    card = cards[0]
    assert card.exit_code == 0 and card.plants == ["heave"]
    assert card.laws("heave") == ["emod", "adaptive", "dead_zone"]
    for law in card.laws("heave"):
        for name in ("performance", "robustness", "tail_error", "drift_rate"):
            assert card.figure("heave", law, name).n == 3
        assert 0.0 <= card.figure("heave", law, "robustness").mean <= 1.0
    data = json.loads((card.out / "scorecard.json").read_text())
    assert data["suite"]["version"] == score_suite.SUITE_VERSION and len(data["suite"]["hash"]) == 16
    assert data["versions"]["law_plugin"]["distribution"] == "adaptive-mj-emod-law"
    md = (card.out / "scorecard.md").read_text()
    assert "| **emod** |" in md and "![heave performance](heave-performance.png)" in md
    # every probe run, whatever the law; the card counts the pre-flight check's predictions and lists what it left out
    assert data["runs"]["not_run"] == [] and data["runs"]["predicted_unstable"] >= 0
    assert (f"**Runs.** {data['runs']['tasks']} task runs and {data['runs']['margins']} margin runs. Every probe is "
            "run and judged by its outcome") in md and "none was refused" in md
    assert (card.out / "scorecard.html").stat().st_size > 10_000  # the figures embedded
    logs = sorted((card.out / "logs" / "tasks" / "heave" / "emod").glob("*.mcap"))
    assert [p.name for p in logs][:3] == ["change-seed0.mcap", "change-seed1.mcap", "change-seed2.mcap"]
    from adaptive_mj.log.replay import read_log

    assert read_log(logs[0]).header["law_plugin"]["name"] == "emod"
    margins = list((card.out / "logs" / "margins").rglob("*.mcap"))
    assert len(margins) >= 3 * 3 * 5 * 2  # every margin run's log: laws × seeds × stressors × (both ends at least)


def test_the_dead_zone_drifts_less_ranks_by_the_paired_rule_and_two_copies_of_one_law_tie(cards):
    card = cards[1]
    drift = {law: card.figure("heave", law, "drift_rate") for law in ("adaptive", "dead_zone")}
    assert separable(drift["adaptive"], drift["dead_zone"])  # the dead-zone stops the drift under noise
    assert drift["dead_zone"].hi < drift["adaptive"].lo
    # ranks by the paired rule (suite version 3 judges the drift with the parameter error: tests above): the
    # dead-zone ranks above the lecture's law exactly when their paired S differs
    from adaptive_mj.study.stats import differs, paired_difference

    plant = card.data["plants"]["heave"]["laws"]
    d = paired_difference(plant["dead_zone"]["figures"]["performance"]["values"],
                          plant["adaptive"]["figures"]["performance"]["values"])
    assert (card.rank("heave", "dead_zone") < card.rank("heave", "adaptive")) == (differs(d) and d.mean > 0)
    # the same law under another name: the same numbers, the same ranks, never separable
    for name in ("performance", "robustness", "tail_error", "drift_rate"):
        assert card.figure("heave", "twin", name) == card.figure("heave", "adaptive", name)
    for score in ("performance", "robustness"):
        assert card.rank("heave", "twin", score) == card.rank("heave", "adaptive", score)
    # the margins are resolved finely enough to differ between seeds (6 bisection steps on a log scale)
    m = card.margin("heave", "adaptive", "noise σ_y")
    assert m.n == 3 and 1e-4 < m.mean < 0.1 and m.lo < m.hi  # the seeds' margins differ


def test_merge_joins_cards_of_one_suite_and_refuses_another_version(cards, tmp_path):
    from adaptive_mj.study import score

    a, b = (c.out / "scorecard.json" for c in cards)
    assert json.loads(a.read_text())["suite"]["hash"] == score.card_hash(5.0)  # whichever plants a card covers
    merged = api.score(merge=[a, b], out=tmp_path / "m")
    assert set(merged.laws("heave")) == {"emod", "twin", "adaptive", "dead_zone"}  # the baselines kept once
    assert merged.rank("heave", "twin") == merged.rank("heave", "adaptive")
    assert "| **twin** |" in (merged.out / "scorecard.md").read_text()
    other = json.loads(b.read_text())
    other["suite"]["version"] = 0
    old = tmp_path / "old.json"
    old.write_text(json.dumps(other))
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "score", "--merge", str(a), str(old), "-o",
                        str(tmp_path / "n")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert f"old.json: key 'suite.version': expected {score_suite.SUITE_VERSION}" in r.stderr and "got 0" in r.stderr
    other = json.loads(b.read_text())
    other["suite"]["seeds"] = 8
    old.write_text(json.dumps(other))
    with pytest.raises(ScenarioError, match=r"old.json: key 'suite.seeds': expected 3"):
        api.score(merge=[a, old], out=tmp_path / "p")
    old.write_text(json.dumps({"format": "adaptive-mj scorecard"}))
    with pytest.raises(ScenarioError, match=r"old.json: key 'suite': expected a JSON object, got NoneType"):
        api.score(merge=[a, old], out=tmp_path / "q")
    # a law in two cards with other figures is not dropped: each copy named after its card
    other = json.loads(b.read_text())
    other["plants"]["heave"]["laws"]["dead_zone"]["figures"]["performance"]["mean"] = 0.0
    old.write_text(json.dumps(other))
    both = api.score(merge=[a, old], out=tmp_path / "r")
    assert {"dead_zone", "dead_zone [card 2]"} <= set(both.laws("heave"))


# ---------------------------------------------------------------- stress --law, bench --law


def test_stress_law_adds_the_law_beside_the_built_in_ones_on_the_plants_it_serves():
    from adaptive_mj.study import stress

    labels = {s.label for s in stress.study(composite=False, duration=1.0, law="sliding_adaptive")}
    assert {"heave/sliding_adaptive", "arm/sliding_adaptive", "heave/adaptive"} <= labels
    assert not any(lb.startswith("ur5e/sliding_adaptive") for lb in labels)  # a 1-DOF law: not on the 6-joint arm
    joint = {s.label for s in stress.study(composite=False, duration=1.0, law="slotine_li",
                                        plant_laws={"ur5e": ("adaptive",)})}
    assert "ur5e/slotine_li" in joint and "ur5e/sigma" not in joint and "heave/slotine_li" not in joint
    searches = [s for s in stress.study(composite=False, duration=1.0, law="sliding_adaptive",
                                        sets=("law.k=150.0",)) if s.label == "heave/sliding_adaptive"]
    assert searches and all(s.overrides[-2:] == ("law=sliding_adaptive", "law.k=150.0") for s in searches)


def test_stress_law_passes_the_law_s_gains_per_plant_kind_and_refuses_a_law_that_serves_no_plant():
    from adaptive_mj.study import stress

    searches = [s for s in stress.study(composite=False, duration=1.0, law="sliding_adaptive",
                                        gains={"heave": ["law.k=150.0"], "arm": ["law.k=4.0"]})
                if s.label in ("heave/sliding_adaptive", "arm/sliding_adaptive")]
    assert {s.label: s.overrides[-1] for s in searches} == {"heave/sliding_adaptive": "law.k=150.0",
                                                            "arm/sliding_adaptive": "law.k=4.0"}
    with pytest.raises(ScenarioError, match="--law: 'first_order_adaptive' serves none of the study's plants"):
        stress.study(composite=False, duration=1.0, law="first_order_adaptive")


def test_stress_and_bench_refuse_law_options_in_one_line(tmp_path):
    for argv in (["stress", "--set", "law.k=3", "-o", str(tmp_path / "a")],
                 ["bench", "--quick", "--law", "sliding_adaptiv", "-o", str(tmp_path / "b")],
                 ["bench", "--quick", "--gains", "g.toml", "-o", str(tmp_path / "c")]):
        r = subprocess.run([sys.executable, "-m", "adaptive_mj", *argv], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, (argv, r.stderr)
    assert not any((tmp_path / n).exists() for n in "abc")


def test_bench_law_section_is_the_law_s_scorecard(tmp_path, monkeypatch):
    """bench --law's section: the score's leaderboards (here a reduced card: heave, one baseline, 2 seeds) with
    their figures under score/."""
    from adaptive_mj.study import bench, score
    from adaptive_mj.study.job import Backend

    real = score.run_score
    monkeypatch.setattr(score, "run_score", lambda law, **kw: real(law, plants=["heave"], against=["dead_zone"],
                                                                     seeds=2, cost=False, **kw))
    text, runs = bench._law_section(tmp_path, Backend(jobs=2), "sliding_adaptive", None, ())
    assert text.startswith("## Your law: sliding_adaptive against the baselines")
    assert "### heave (plant kind heave): leaderboard" in text and "](score/heave-performance.png)" in text
    assert "| **sliding_adaptive** |" in text and "| dead_zone |" in text
    assert (tmp_path / "score" / "heave-performance.png").is_file()
    assert runs >= 2 * 3 * 2 + 2 * 5 * 2 * 2  # tasks, and both ends of every margin search


# ---------------------------------------------------------------- your own plant (score --scenario)


def test_score_on_a_users_own_arm_writes_its_card_and_its_runs_replay_bit_identically(tmp_path, capsys):
    """A two-link servo arm that is not bundled (tests/test_manipulator_runs.py's), scored by --scenario: its card
    has the arm as a plant of its own with its leaderboard and margins, the tasks derived from the file (tracking as
    given, the payload's mass ×4 at half time, the start held) and the file's hash; a task run and a margin run
    replay bit-identically."""
    import hashlib

    from test_manipulator_runs import SERVO_ARM, SERVO_SCENARIO

    from adaptive_mj.cli import main

    (tmp_path / "my_arm.xml").write_text(SERVO_ARM)
    scenario = tmp_path / "my_arm.toml"
    scenario.write_text(SERVO_SCENARIO.format(servo="true"))
    card = api.score(None, scenarios=[scenario], against=["adaptive", "pd_gravity"], seeds=2, out=tmp_path / "card",
                     cost=False, jobs=2)
    assert card.exit_code == 0 and card.plants == ["my_arm"]
    assert card.laws("my_arm") == ["adaptive", "pd_gravity"] or card.laws("my_arm") == ["pd_gravity", "adaptive"]
    for law in ("adaptive", "pd_gravity"):
        for name in ("performance", "robustness", "tail_error", "drift_rate"):
            assert math.isfinite(card.figure("my_arm", law, name).mean), (law, name)
        assert card.rank("my_arm", law) in (1, 2)
    data = json.loads((card.out / "scorecard.json").read_text())
    mine = data["plants"]["my_arm"]
    assert mine["kind"] == "manipulator" and mine["scenario"]["file"] == str(scenario.resolve())
    assert mine["scenario"]["sha256"] == hashlib.sha256(scenario.read_bytes()).hexdigest()
    tasks = {t["name"]: t for t in mine["scenario"]["tasks"]}
    assert tasks["tracking"]["overrides"] == [] and tasks["tracking"]["noise_scale"] == 0.0
    assert "kind='payload_mass'" in tasks["change"]["overrides"][1]
    # (templates, as the suite's own tasks are written: {{ }} is one brace) the keyframe 'ready' held
    assert "center={{\"shoulder\"=0.3, \"elbow\"=-0.6}}" in tasks["hold"]["overrides"][2]
    assert set(mine["laws"]["adaptive"]["stressors"]) >= {"noise σ_y", "payload ratio", "delay", "control period"}
    # the derived hold held still: the adaptive law's estimates drift, the fixed-parameter law's cannot
    assert card.figure("my_arm", "pd_gravity", "drift_rate").mean == 0.0
    task_log = card.out / "logs" / "tasks" / "my_arm" / "adaptive" / "change-seed0.mcap"
    margin_log = next((card.out / "logs" / "margins").rglob("*.mcap"))
    capsys.readouterr()
    for log in (task_log, margin_log):
        assert main(["replay", str(log), "--verify"]) in (0, 1)  # the run's own verdict: ok, or a failed probe
        assert "verify: bit-identical" in capsys.readouterr().out, log


@pytest.mark.parametrize("edit, match", [
    (lambda text: text.replace('payload = "sphere"\npayload_mass = 0.3\n', ""),
     r"my_arm.toml: score's change task multiplies the payload's mass: expected plant.payload"),
    (lambda text: text.replace('kind = "manipulator"', 'kind = "ship"'), r"plant.kind"),
])
def test_score_on_a_scenario_it_cannot_derive_tasks_from_is_one_line(tmp_path, edit, match):
    from test_manipulator_runs import SERVO_ARM, SERVO_SCENARIO

    (tmp_path / "my_arm.xml").write_text(SERVO_ARM)
    scenario = tmp_path / "my_arm.toml"
    scenario.write_text(edit(SERVO_SCENARIO.format(servo="true")))
    with pytest.raises(ScenarioError, match=match) as err:
        api.score(None, scenarios=[scenario], seeds=2, out=tmp_path / "card", cost=False, jobs=1)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "card").exists()


# ---------------------------------------------------------------- one arena: a plugin copy scores as the original


def sliding_copy(x, ref, theta, phi, f, h, params, rate):
    """The built-in sliding law of order 2 (laws.sliding.sliding_law_values with coeffs [λ, 1], no robust term, no
    dead-zone), written as a plugin: the same operations in the same order."""
    lam, k = params[0], params[1]
    e0 = ref[0] - x[0]
    e1 = ref[1] - x[1]
    s = 0.0
    s += lam * e0
    s += 1.0 * e1
    s_r_dot = ref[2] + lam * e1
    acc = theta[0] * s_r_dot - f + k * s
    for j in range(phi.shape[0]):
        acc -= phi[j] * theta[j + 1]
    u = acc / h
    rate[0] = s_r_dot * s / params[2]
    for j in range(phi.shape[0]):
        rate[j + 1] = -phi[j] * s / params[3 + j]
    return u, s


@pytest.fixture
def sliding_copy_installed(monkeypatch):
    """`sliding_copy` registered as an installed plugin law (in this process; forked workers inherit it). It
    declares no feedback(), as the issue's copy did: the pre-flight check never checks it."""
    from adaptive_mj.laws import plugin
    from adaptive_mj.laws.plugin import LawPlugin, Param
    from adaptive_mj.plugins import Installed

    law = LawPlugin(law=sliding_copy, orders=(2,), gain="gamma", doc="the built-in sliding law, as a plugin",
                    params=(Param("lambda", gt=0.0), Param("k", ge=0.0), Param("gamma", gt=0.0, per_parameter=True)))
    real = plugin.installed
    monkeypatch.setattr(plugin, "installed", lambda: {**real(), "sliding_copy": Installed(
        "sliding_copy", law, "test-sliding-copy", "0.1.0", "0" * 64)})


def test_a_plugin_copy_of_the_built_in_law_gets_its_scores_ranks_and_margins(sliding_copy_installed, tmp_path):
    """The built-in `adaptive` law and a plugin that is that law (its gains read from the plant's scenario), scored
    together on the heave vehicle over score's fewest seeds (2): the same S and R to the last printed digit, the same
    ranks, the same margins. Before, the built-in law's control-period probes past the
    pre-flight check's limit were refused (failures with no run) while the plugin's ran: R 0.674 against 0.687 on
    heave, 'separable'."""
    import tomllib

    law = tomllib.loads((REPO / "scenarios" / "heave_tracking.toml").read_text())["law"]
    gamma = ", ".join(f"{k} = {v!r}" for k, v in law["gamma"].items())
    gains = tmp_path / "gains.toml"
    gains.write_text(f"[heave]\nlambda = {law['lambda']!r}\nk = {law['k']!r}\ngamma = {{ {gamma} }}\n")
    card = api.score("sliding_copy", gains=gains, against="adaptive", plants="heave", seeds=2,
                     out=tmp_path / "card", cost=False, jobs=2)
    assert card.exit_code == 0 and card.plants == ["heave"]
    for plant in card.plants:
        for name in ("performance", "robustness", "tail_error", "drift_rate", "param_error"):
            copy, built_in = card.figure(plant, "sliding_copy", name), card.figure(plant, "adaptive", name)
            assert f"{copy.mean:.3f} [{copy.lo:.3f}, {copy.hi:.3f}]" == \
                f"{built_in.mean:.3f} [{built_in.lo:.3f}, {built_in.hi:.3f}]", (plant, name)
        for score in ("performance", "robustness"):
            assert card.rank(plant, "sliding_copy", score) == card.rank(plant, "adaptive", score) == 1
        for stressor in ("control period", "delay"):
            assert card.margin(plant, "sliding_copy", stressor) == card.margin(plant, "adaptive", stressor)


def test_a_multi_joint_plugin_copy_of_slotine_li_gets_its_scores_and_ranks_on_the_ur5e(monkeypatch, tmp_path):
    """examples/robust_sl_law with k_s = 0 is Slotine–Li (its robust term off, its box unbounded): scored beside the
    built-in law on the 6-joint arm with the bundled scenarios' gains, the same S and R to the last printed digit,
    the same ranks."""
    from adaptive_mj.laws import plugin
    from adaptive_mj.plugins import Installed

    spec = importlib.util.spec_from_file_location("robust_sl_law", REPO / "examples" / "robust_sl_law" /
                                                  "robust_sl_law.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setitem(sys.modules, "robust_sl_law", module)
    real = plugin.installed
    monkeypatch.setattr(plugin, "installed", lambda: {**real(), "robust_sl": Installed(
        "robust_sl", module.LAW, "adaptive-mj-robust-sl-law", "0.1.0", "0" * 64)})
    import tomllib

    law = tomllib.loads((REPO / "scenarios" / "ur5e_identification.toml").read_text())["law"]
    gains = tmp_path / "gains.toml"
    gains.write_text(f"[manipulator]\nlambda = {law['lambda']!r}\nkd = {law['kd']!r}\nks = 0.0\n"
                     f"gamma = {law['gamma']!r}\n")
    card = api.score("robust_sl", gains=gains, against="adaptive", plants="ur5e", seeds=2, out=tmp_path / "card",
                     cost=False, jobs=2)
    assert card.exit_code == 0
    for name in ("performance", "robustness", "tail_error", "drift_rate", "param_error"):
        copy, built_in = card.figure("ur5e", "robust_sl", name), card.figure("ur5e", "adaptive", name)
        assert f"{copy.mean:.3g} [{copy.lo:.3g}, {copy.hi:.3g}]" == \
            f"{built_in.mean:.3g} [{built_in.lo:.3g}, {built_in.hi:.3g}]", name
    for score in ("performance", "robustness"):
        assert card.rank("ur5e", "robust_sl", score) == card.rank("ur5e", "adaptive", score) == 1


def test_each_seed_draws_its_task_and_every_law_meets_the_same_draw():
    """score.draws (suite version 3): a seed's draw depends on the suite version, the plant, the task and the seed
    alone (the same for every law and on every call), differs between seeds, lies in the declared ranges, and loads:
    on the 1-DOF arm the payload's mass within [0.5, 2] × 0.5 kg, the amplitudes scaled by one factor in
    [0.75, 1.25], each phase in [0, 2π], each estimate within [0.5, 2] × the bundled scenario's truth (so inside
    the projection baseline's box [θ/2, 2θ] about it, whatever payload the seed drew)."""
    from adaptive_mj.setup.build import build
    from adaptive_mj.study.score import draws, task_overrides
    from adaptive_mj.study.score_suite import TASKS

    arm = {p.name: p for p in stress.plants(5.0)}["arm"]
    task = TASKS["arm"][0]
    over0, v0 = draws(arm, task, 0)
    draws.cache_clear()
    assert draws(arm, task, 0) == (over0, v0)  # recomputed, not remembered: the same
    _, v1 = draws(arm, task, 1)
    assert v1["plant.payload_mass"] != v0["plant.payload_mass"]
    for v in (v0, v1):
        assert 0.25 <= v["plant.payload_mass"] <= 1.0
        ratios = np.array(v["reference.amplitudes"]) / np.array([0.4, 0.3, 0.2])
        assert np.ptp(ratios) < 1e-12 and 0.75 <= ratios[0] <= 1.25
        assert all(0.0 <= ph <= 2 * math.pi for ph in v["reference.phases"])
    scn = sc.load(stress.scenario_path(task.scenario), overrides=[*task_overrides(arm, task, 1.0), *over0])
    s = build(scn)
    assert scn.plant.payload_mass == v0["plant.payload_mass"] and scn.reference.params["phases"] == tuple(
        v0["reference.phases"])
    bundled = build(sc.load(stress.scenario_path(task.scenario)))
    truth = dict(zip(bundled.law.names, bundled.plant.true_theta(), strict=True))
    assert s.plant.true_theta()[0] != truth["J"]  # the drawn payload changed the truth, not the estimates' base
    for name, est in v0["law.initial_estimates"].items():
        assert (est == 0.0 == truth[name]) or 0.5 <= est / truth[name] <= 2.0, name


def test_a_criterion_at_its_cap_for_every_adaptive_law_is_named_as_saturated():
    """score.criteria_spread: each criterion's range of min(1, c/n) over the laws that are not oracles (†), from
    their means; saturated when every one is at the cap. Hand-made plant: drift at 3 and 2 × its normaliser for both
    adaptive laws (saturated, whatever the oracle's 0), the tail error at 0.5 and 0.2 of the bound (not)."""
    from adaptive_mj.study.score import criteria_spread
    from adaptive_mj.study.score_card import saturated_text

    names = [c.name for c in score_suite.CRITERIA]

    def law(drift: float, tail: float, oracle: bool = False) -> dict:
        figs = {n: {"mean": 0.0} for n in names}
        figs["drift_rate"], figs["tail_error"] = {"mean": drift}, {"mean": tail}
        return {"oracle": oracle, "figures": figs}

    plant = {"normalisers": {**{n: 1.0 for n in names}, "tail_error": 0.01},
             "laws": {"a": law(3.0, 0.005), "b": law(2.0, 0.002), "truth": law(0.0, 0.0, oracle=True)}}
    spread = criteria_spread(plant)
    assert spread["drift_rate"] == {"lo": 1.0, "hi": 1.0, "saturated": True}
    assert spread["tail_error"] == {"lo": 0.2, "hi": 0.5, "saturated": False}
    assert saturated_text({"plants": {"p": {**plant, "criteria_spread": spread}}}) == (
        "At their cap for every adaptive law, so separating none of them: drift_rate on p. ")


def test_a_seed_s_margin_runs_run_its_drawn_task_from_the_truth():
    """score.margin_draws: seed k's margin searches carry its tracking task's draw (reference, payload) but not the
    drawn initial estimates (a margin run starts from the truth, law.initial_estimates='model' in the row's base)."""
    from adaptive_mj.study.score import draws, margin_draws
    from adaptive_mj.study.score_suite import TASKS

    arm = {p.name: p for p in stress.plants(5.0)}["arm"]
    task_over = draws(arm, TASKS["arm"][0], 2)[0]
    got = margin_draws(arm, 2)
    assert got == tuple(o for o in task_over if not o.startswith("law.initial_estimates="))
    assert any(o.startswith("plant.payload_mass=") for o in got) and len(got) == len(task_over) - 1
    assert margin_draws(arm, 1) != got


def test_no_criterion_is_at_its_cap_for_every_adaptive_law_on_the_bundled_plants(tmp_path):
    """Suite version 3's normalisers on heave, the 1-DOF arm and the UR5e: over the laws that are not given the truth
    (no †), each criterion's place on its normaliser's scale, min(1, c/n) of the mean over 2 seeds, is below the cap
    for at least one law, so each criterion can separate them (score.criteria_spread; the task runs only). And on
    the arm the dead-zone, which version 2 credited with a perfect drift for never adapting, no longer has the
    lowest drift term of them."""
    from adaptive_mj.study import score
    from adaptive_mj.study.parallel import run_jobs

    pl = score.plan(None, label=None, sets=(), gains=None, against=None, suite_name="quick", seeds=2,
                    plants=["heave", "arm", "ur5e"])
    pl.entries = {name: [e for e in es if not e.oracle] for name, es in pl.entries.items()}
    jobs, keys = score.task_jobs(pl, tmp_path)
    runs: dict = {}
    for (plant, label, task, seed), r in zip(keys, run_jobs(jobs, n_jobs=2), strict=True):
        runs.setdefault((plant, label, seed), {})[task] = r
    for p in pl.rows:
        durations = dict(pl.settings.durations)
        bound, limits = stress.tail_bound(p), score.actuator_limits(p)
        laws = {}
        for e in pl.entries[p.name]:
            per_seed = [score.seed_figures(runs[(p.name, e.label, k)], bound, limits, durations) for k in range(2)]
            laws[e.label] = {"figures": {c.name: {"mean": float(np.mean([f[c.name] for f in per_seed]))}
                                         for c in score_suite.CRITERIA}}
        spread = score.criteria_spread({"normalisers": score.normalisers(bound, limits, durations), "laws": laws})
        print(p.name, {c: (round(s["lo"], 3), round(s["hi"], 3)) for c, s in spread.items()})
        assert not [c for c, s in spread.items() if s["saturated"]], (p.name, spread)
        if p.name == "arm":  # the drift's term in S: judged with the parameter error (JUDGED_TOGETHER)
            term = {lb: max(law["figures"]["drift_rate"]["mean"], law["figures"]["param_error"]["mean"])
                    for lb, law in laws.items()}
            print("arm drift terms", term)
            assert min(term, key=lambda lb: term[lb]) != "dead_zone"

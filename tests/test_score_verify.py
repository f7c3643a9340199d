"""adaptive-mj score --verify: a card's runs re-run from the specs scorecard.json records, bit for bit, and its figures
recomputed from its own per-seed values (adaptive_mj.study.score_verify); a merged card keeps its specs, and its
leaderboard.html opens in headless Chromium without errors."""
import json
import shutil
from pathlib import Path

import pytest

from adaptive_mj.cli import main
from adaptive_mj.study import api, score_verify
from headless_chromium import Browser, find_browser
from test_report_html import NO_BROWSER, blank


@pytest.fixture(scope="module")
def cards(tmp_path_factory):
    """Two reduced cards of the baselines on the heave vehicle (2 seeds, no cost timing), and the two merged."""
    root = tmp_path_factory.mktemp("verify")
    a = api.score(None, against=["adaptive", "fixed_nominal"], plants="heave", seeds=2, cost=False, jobs=2,
                  out=root / "a")
    b = api.score(None, against=["adaptive", "dead_zone"], plants="heave", seeds=2, cost=False, jobs=2,
                  out=root / "b")
    merged = api.score(merge=[a.out / "scorecard.json", b.out / "scorecard.json"], out=root / "m")
    return a, b, merged


def edited(card_dir: Path, name: str, edit) -> Path:
    """The card's scorecard.json with `edit` applied, written beside it (so its logs stay where it says)."""
    data = json.loads((card_dir / "scorecard.json").read_text())
    edit(data)
    path = card_dir / name
    path.write_text(json.dumps(data))
    return path


def test_the_card_records_each_run_s_spec(cards):
    data = json.loads((cards[0].out / "scorecard.json").read_text())
    specs = data["specs"]
    assert len(specs["tasks"]) == 2 * 2 and len(specs["searches"]) == 2 * 2 * len(data["plants"]["heave"]["stressors"])
    run = specs["tasks"][0]["runs"][0]
    assert run["log"] == "logs/tasks/heave/adaptive/tracking-seed0.mcap" and run["seed"] == 0
    assert Path(run["scenario"]).is_absolute() and len(run["sha256"]) == 64
    assert (cards[0].out / run["log"]).is_file()
    probe = specs["searches"][0]["probes"][0]
    assert (cards[0].out / probe["log"]).is_file() and probe["passes"] in (True, False)


def test_verify_passes_on_a_fresh_card_with_every_run_and_with_a_sample(cards, capsys):
    card = cards[0].out / "scorecard.json"
    assert main(["score", "--verify", str(card), "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    assert "re-ran 24 of 24 run records" in out and "the card agrees" in out
    v = api.score(verify=card, sample=2, jobs=2)
    assert v.exit_code == 0 and len(v.picked) == 2, v.text
    assert v.picked == api.score(verify=card, sample=2, jobs=2).picked  # the same card picks the same runs
    assert ", ".join(v.picked) in v.text


@pytest.mark.parametrize("what, edit, named", [
    ("a per-seed value", lambda d: d["plants"]["heave"]["laws"]["adaptive"]["figures"]["tail_error"]["values"]
     .__setitem__(1, 2 * d["plants"]["heave"]["laws"]["adaptive"]["figures"]["tail_error"]["values"][1]),
     "heave/adaptive: figure.tail_error"),
    ("a per-seed score", lambda d: d["plants"]["heave"]["laws"]["adaptive"]["figures"]["performance"]["values"]
     .__setitem__(0, 0.99), "heave/adaptive: figure.performance.values[0]: card 0.99, re-computed"),
    ("a mean", lambda d: d["plants"]["heave"]["laws"]["fixed_nominal"]["figures"]["robustness"].__setitem__(
        "mean", 0.5), "heave/fixed_nominal: figure.robustness.mean: card 0.5, re-computed"),
    ("a rank", lambda d: d["plants"]["heave"]["laws"]["adaptive"]["rank"].__setitem__("performance", 99),
     "heave/adaptive: rank.performance: card 99, re-computed"),
    ("a margin", lambda d: d["plants"]["heave"]["laws"]["adaptive"]["stressors"]["delay"]["margins"].__setitem__(
        0, None), "heave/adaptive: figure.robustness.values[0]"),
])
def test_a_card_edited_by_hand_fails_naming_the_figure(cards, capsys, what, edit, named):
    path = edited(cards[0].out, "edited.json", edit)
    assert main(["score", "--verify", str(path), "--sample", "0"]) == 1, what
    out = capsys.readouterr().out
    assert f"verify: MISMATCH: {named}" in out, (what, out)


def test_a_run_whose_log_differs_fails_naming_the_run(cards, tmp_path):
    """The card copied, and the log of the run record --sample 1 picks replaced by another run's: the re-run
    differs from it, and the message names the run (plant, law, task or stressor, seed) and the field."""
    card = tmp_path / "card"
    shutil.copytree(cards[0].out, card)
    data = score_verify.read(card / "scorecard.json")
    (kind, unit), = score_verify.picked_units(data, 1)
    runs = unit["runs"] if kind == "tasks" else unit["probes"]
    shutil.copyfile(card / runs[1]["log"], card / runs[0]["log"])
    v = api.score(verify=card, sample=1, jobs=2)
    assert v.exit_code == 1 and len(v.problems) == 1, v.text
    assert v.problems[0].startswith(score_verify.unit_name(kind, unit) + ": ") and "log field" in v.problems[0]


def test_a_card_without_specs_is_one_line_exit_2(cards, capsys):
    path = edited(cards[0].out, "old.json", lambda d: d.pop("specs"))
    assert main(["score", "--verify", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "old.json: key 'specs'" in err
    assert "written before specs were recorded: re-score it" in err
    assert main(["score", "--verify", str(cards[0].out / "missing.json")]) == 2
    assert "missing.json: no such scorecard file" in capsys.readouterr().err
    assert main(["score", "--sample", "2"]) == 2
    assert "--sample needs --verify" in capsys.readouterr().err


def test_a_merged_card_keeps_the_specs_and_verifies(cards):
    a, b, merged = cards
    data = json.loads((merged.out / "scorecard.json").read_text())
    assert set(merged.laws("heave")) == {"adaptive", "fixed_nominal", "dead_zone"}
    # the baseline both cards ran is kept once, with the first card's runs; logs relative to the merged card
    assert sorted({u["law"] for u in data["specs"]["tasks"]}) == ["adaptive", "dead_zone", "fixed_nominal"]
    assert len(data["specs"]["tasks"]) == 3 * 2
    log = data["specs"]["tasks"][0]["runs"][0]["log"]
    assert log.startswith("../a/") and (merged.out / log).is_file()
    v = api.score(verify=merged.out / "scorecard.json", sample=3, jobs=2)
    assert v.exit_code == 0, v.text
    assert api.score(verify=merged.out, sample=0).exit_code == 0


def test_merge_writes_one_leaderboard_page(cards):
    a, b, merged = cards
    md = (merged.out / "leaderboard.md").read_text()
    assert "| law | heave |" in md and "| fixed_nominal † | S " in md and "(rank 1)<br>R " in md
    assert "[the baselines](../a/scorecard.html)" in md and "[the baselines](../b/scorecard.html)" in md
    doc = (merged.out / "leaderboard.html").read_text()
    assert '<a href="../b/scorecard.html">' in doc


@pytest.mark.skipif(find_browser() is None, reason=NO_BROWSER)
def test_chromium_opens_the_merged_leaderboard_without_errors(cards):
    merged = cards[2]
    with Browser(width=1000, height=800) as b:
        page = b.open(merged.out / "leaderboard.html")
        assert b.evaluate("document.title") == "adaptive-mj leaderboard"
        assert b.evaluate("document.querySelectorAll('table.sortable tbody tr').length") == 3
        assert b.evaluate("Array.from(document.links).filter(a => a.href.endsWith('/scorecard.html')).length") == 2
        assert b.evaluate("performance.getEntriesByType('resource').length") == 0
        shot = b.screenshot()
    assert page.errors == [], page.errors
    assert not blank(shot)

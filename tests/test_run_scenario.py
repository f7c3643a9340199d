"""adaptive_mj.run_scenario: one scenario from Python with the verdict `adaptive-mj run` gives (its [success]
criteria applied), on every bundled scenario; its log is the run's."""
import json
import tomllib

import pytest

import adaptive_mj
from adaptive_mj.cli import main
from adaptive_mj.errors import ScenarioError
from adaptive_mj.setup.scenario import SCENARIOS_DIR
from adaptive_mj.study.sweep import to_toml

BUNDLED = sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
SHORT = 2.0  # [s] each scenario cut to this (the two paths are compared, not the scenario's result)


def shortened(name: str) -> list[str]:
    """--set expressions that cut the bundled scenario `name` to SHORT s, its events (if any) at the same fraction of
    the run as in the file, so every event still happens."""
    raw = tomllib.loads((SCENARIOS_DIR / f"{name}.toml").read_text())
    scale = SHORT / raw["simulation"]["duration"]
    sets = [f"simulation.duration={SHORT!r}"]
    if raw.get("events"):
        sets.append(f"events={to_toml([{**e, 't': e['t'] * scale} for e in raw['events']])}")
    return sets


@pytest.mark.parametrize("name", BUNDLED)
def test_run_scenario_gives_the_verdict_of_run(name, tmp_path, capsys):
    sets = shortened(name)
    result = adaptive_mj.run_scenario(name, set=sets, log=tmp_path / "api.mcap")
    capsys.readouterr()
    code = main(["run", name, *[a for s in sets for a in ("--set", s)], "--json", "-o", str(tmp_path / "cli.mcap")])
    summary = json.loads(capsys.readouterr().out)
    assert result.status == summary["status"] and result.summary["reason"] == summary["reason"]
    assert code == (0 if result.ok else 1)
    assert result.summary["metrics"] == summary["metrics"]  # the same run, bit for bit
    assert result.log_path == tmp_path / "api.mcap" and result.log_path.stat().st_size > 0
    assert result.trajectory.t[-1] < SHORT  # cut short, as asked


def test_the_sudden_failure_is_failed_from_python_too():
    """The [success] verdict, not only the loop's own status: the drifting loop bursts, so the run misses its
    criteria (loop.run alone says "ok": it completed)."""
    result = adaptive_mj.run_scenario("heave_sudden_failure")
    assert result.status == "failed" and result.trajectory.status == "failed" and not result.ok
    assert result.log_path is None


def test_bad_input_is_one_line():
    with pytest.raises(ScenarioError, match="did you mean 'heave_tracking'"):
        adaptive_mj.run_scenario("heave_trackin")
    with pytest.raises(ScenarioError, match="law.kk"):
        adaptive_mj.run_scenario("heave_tracking", set=["law.kk=3"])
    with pytest.raises(ScenarioError, match="seed must be an integer >= 0"):
        adaptive_mj.run_scenario("heave_tracking", seed=-1)

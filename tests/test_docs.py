"""The docs cannot rot: the worked examples in docs/ are extracted and run."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.S | re.M)


def blocks(path: Path):
    """(language, info, body) of every fenced block."""
    return [(m.group(1), m.group(2).strip(), m.group(3)) for m in FENCE.finditer(path.read_text())]


def cli(line: str) -> list[str]:
    words = line.split()
    assert words[0] == "adaptive-mj", line
    return [sys.executable, "-m", "adaptive_mj", *words[1:]]


def env():
    return dict(os.environ, MUJOCO_GL="egl", PYTHONPATH=str(REPO))


def test_adding_a_law_example_runs_and_its_claim_holds():
    code = "\n".join(body for lang, _, body in blocks(REPO / "docs" / "ADDING_A_LAW.md") if lang == "python")
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, env=env(), timeout=300)
    assert r.returncode == 0, r.stderr
    assert "with sigma-modification" in r.stdout


def test_adding_a_plant_example_runs(tmp_path):
    for _lang, info, body in blocks(REPO / "docs" / "ADDING_A_PLANT.md"):
        m = re.match(r"file=(\S+)", info)
        if m:
            (tmp_path / m.group(1)).write_text(body)
    for lang, _, body in blocks(REPO / "docs" / "ADDING_A_PLANT.md"):
        if lang == "sh":
            for line in body.strip().splitlines():
                r = subprocess.run(cli(line), cwd=tmp_path, capture_output=True, text=True, env=env(), timeout=300)
                assert r.returncode == 0, (line, r.stdout, r.stderr)
        if lang == "python":
            r = subprocess.run([sys.executable, "-c", body], cwd=tmp_path, capture_output=True, text=True,
                               env=env(), timeout=120)
            assert r.returncode == 0, r.stderr
            # horizontal at q = 0: gravity through cos q
            assert r.stdout.strip() == "{'J': 0.0458, 'b': 0.02, 'g_sin': 0.0, 'g_cos': 1.7658}"
    assert (tmp_path / "my_arm.mcap").stat().st_size > 10_000


#: the README and the guide it sends a newcomer to: their commands and Python blocks run as written
FRONT_DOOR = (REPO / "README.md", REPO / "docs" / "GUIDE.md")
#: a command that needs an example plugin installed by the line before it (`pip install -e examples/emod_law`),
#: which the test environment does not install: tests/test_plugin.py and test_score.py run those paths
NEEDS_AN_EXAMPLE_PLUGIN = ("score emod",)


def readme_commands() -> list[str]:
    """Every `.venv/bin/adaptive-mj ...` line in the code blocks of the README and docs/GUIDE.md (comments cut),
    each once, in order; but those that need an example plugin (NEEDS_AN_EXAMPLE_PLUGIN)."""
    out, inside = [], False
    for path in FRONT_DOOR:
        for line in path.read_text().splitlines():
            if line.startswith("```"):
                inside = not inside
                continue
            line = line.split("   #")[0].strip()
            if inside and line.startswith(".venv/bin/adaptive-mj ") and not any(k in line for k in
                                                                                 NEEDS_AN_EXAMPLE_PLUGIN):
                out.append(line)
    return list(dict.fromkeys(out))


def python_blocks() -> list[str]:
    """The Python blocks of the README and docs/GUIDE.md, in order."""
    return [c for path in FRONT_DOOR for c in re.findall(r"^```python\n(.*?)^```", path.read_text(), re.S | re.M)]


@pytest.mark.timeout(1800)  # the README's eight commands, a sweep and the whole bench --quick among them, in turn
def test_every_readme_command_runs(tmp_path):
    import shlex

    cmds = readme_commands()
    assert len(cmds) >= 8, cmds
    e = dict(env(), ADAPTIVE_MJ_LOGS=str(tmp_path / "logs"))
    for line in cmds:
        argv = [sys.executable, "-m", "adaptive_mj", *shlex.split(line)[1:]]
        r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, env=e, timeout=600,
                           stdin=subprocess.DEVNULL)
        assert r.returncode == 0, (line, r.stdout[-2000:], r.stderr[-2000:])
    assert (tmp_path / "logs" / "tour" / "heave.png").stat().st_size > 20_000
    assert (tmp_path / "logs" / "arm.mp4").stat().st_size > 10_000
    assert list((tmp_path / "logs").glob("bench-quick-*/report.md"))
    assert list((tmp_path / "logs").glob("sweep-*/sweep.csv"))


def test_readme_python_examples_run(tmp_path):
    """The README's and the guide's Python blocks (the loop from Python, run_scenario, the dm_env agent) run as
    shown."""
    codes = python_blocks()
    assert len(codes) >= 3
    printed = []
    for code in codes:
        r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                           env=dict(env(), ADAPTIVE_MJ_LOGS=str(tmp_path / "logs")), timeout=300)
        assert r.returncode == 0, (code, r.stderr[-2000:])
        printed.append(r.stdout)
    assert any("adaptive law: return -0.001" in out for out in printed)


def test_readme_study_example_prints_its_rows_and_writes_its_report(tmp_path):
    """The README's study example: a 2 x 2 sweep from Python prints a row per run and the paths of its plot
    and report.html, which exist."""
    (code,) = [c for c in python_blocks() if "study.sweep(" in c]
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                       env=dict(env(), ADAPTIVE_MJ_LOGS=str(tmp_path / "logs")), timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert [line.split()[:3] for line in lines[:4]] == [["100", "0", "ok"], ["100", "1", "ok"], ["400", "0", "ok"],
                                                        ["400", "1", "ok"]]
    assert lines[4].startswith("tail errors: [")
    png, html = lines[5].split()
    assert Path(png).stat().st_size > 10_000 and Path(html).name == "report.html" and Path(html).is_file()
    assert Path(html).parent.parent == tmp_path / "logs"


def test_scenarios_md_says_noise_and_disturbance_work_on_manipulators_and_they_do(tmp_path):
    """docs/SCENARIOS.md's manipulator section once said `[noise]` and `[disturbance]` are refused there; both
    run (issue 35): the section says so, and a UR5e run with both ends ok, its log recording both."""
    import numpy as np

    text = (REPO / "docs" / "SCENARIOS.md").read_text()
    section = text.split("## Manipulators", 1)[1].split("\n### ", 1)[0]
    assert "refused" not in section.split("are as above", 1)[1].split("\n\n", 1)[0], section
    assert "`[noise]`" in section and "`[disturbance]`" in section
    from adaptive_mj.cli import main
    from adaptive_mj.log.replay import read_log

    common = ["--set", "simulation.duration=0.2", "--set", "events=[]", "--set", "success.tail_rms=inf"]
    with_both = ["--set", "noise.std={q=1e-3, q_dot=1e-2}",
                 "--set", "disturbance={kind='sine', magnitude=2.0, omega=20.0}"]
    plain, both = tmp_path / "plain.mcap", tmp_path / "both.mcap"
    assert main(["run", "ur5e_payload_swap", "-o", str(plain), *common]) == 0
    assert main(["run", "ur5e_payload_swap", "-o", str(both), *common, *with_both]) == 0
    a, b = read_log(plain), read_log(both)
    assert b.status == "ok"
    assert any("noise.std" in o for o in b.overrides) and any("disturbance" in o for o in b.overrides)
    assert np.max(np.abs(a.trajectory.x - b.trajectory.x)) > 1e-6  # they act on the arm


def test_the_guide_points_at_results_sections_that_exist_and_types_no_run_figure():
    """docs/GUIDE.md says where each study's figures are (docs/RESULTS.md, written by the bench) instead of typing
    them (issue 53): every `RESULTS.md, "SECTION"` it names is a section heading of that page, which the bench
    writes from its runs' sections; figures once typed there from runs (a drift time, a tail error, a
    margin) are gone from it, and the card it links is a file the score command wrote."""
    guide = (REPO / "docs" / "GUIDE.md").read_text()
    results = (REPO / "docs" / "RESULTS.md").read_text()
    headings = set(re.findall(r"^## (.+)$", results, re.M))
    cited = {name for run in re.findall(r'RESULTS\.md, ("[^"]+"(?:(?:, | to )"[^"]+")*)', guide)
             for name in re.findall(r'"([^"]+)"', run)}
    assert len(cited) >= 8, cited
    assert cited <= headings, sorted(cited - headings)
    for typed in ("101.53", "3.59 at t", "0.0198 rad", "21.8 cm", "0.93 cm", "6.1 m/s", "1.18·10⁵", "256 MB",
                  "0.934 [0.908"):
        assert typed not in guide, typed
    card = (REPO / "docs" / "cards" / "emod-heave" / "scorecard.md").read_text()
    assert card.startswith("# adaptive-mj scorecard: `emod` against the baselines")
    assert "](cards/emod-heave/scorecard.md)" in guide and all(
        (REPO / "docs" / "cards" / "emod-heave" / png).is_file() for png in re.findall(r"\]\(([^)]+\.png)\)", card))

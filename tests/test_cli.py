"""The command line end to end: run -> log -> replay gives the same summary,
--verify is bit-identical, --plot draws, bad input exits 2 with one line."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from adaptive_mj.cli import main

REPO = Path(__file__).resolve().parents[1]


def cli(*args, cwd=REPO):
    env = dict(os.environ, MUJOCO_GL="egl")
    return subprocess.run([sys.executable, "-m", "adaptive_mj", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=env, stdin=subprocess.DEVNULL, timeout=300)


def test_list_shows_every_bundled_scenario():
    r = cli("list")
    assert r.returncode == 0, r.stderr
    names = {line.split()[0] for line in r.stdout.splitlines()}
    assert {"lecture_first_order", "lecture_heave", "heave_tracking", "arm_payload_swap"} <= names
    assert "INVALID" not in r.stdout


@pytest.mark.parametrize("name, overrides", [
    ("lecture_first_order", ["simulation.duration=3.0", "success.tail_rms=inf"]),  # 3 s: not converged yet
    ("heave_tracking", ["simulation.duration=3.0", "noise.std={y=0.001, y_dot=0.01}"]),
    ("arm_payload_swap", ["simulation.duration=3.0", "events=[{t=1.5, kind='payload_mass', value=2.0}]"]),
])
def test_run_then_replay_gives_identical_summary_and_verify_is_bit_identical(tmp_path, name, overrides):
    log = tmp_path / f"{name}.mcap"
    sets = [a for o in overrides for a in ("--set", o)]
    r = cli("run", name, "-o", log, "--json", *sets)
    assert r.returncode == 0, r.stderr
    run_summary = json.loads(r.stdout)
    assert run_summary["status"] == "ok" and run_summary["steps"] == 3000
    r2 = cli("replay", log, "--json", "--verify", "--plot", tmp_path / "run.png")
    assert r2.returncode == 0, r2.stderr
    assert json.loads(r2.stdout) == run_summary
    assert r2.stdout == r.stdout  # byte-identical JSON
    assert "bit-identical" in r2.stderr
    assert (tmp_path / "run.png").stat().st_size > 20_000


def test_payload_swap_changes_true_theta_in_log(tmp_path):
    from adaptive_mj.log.replay import read_log

    log = tmp_path / "swap.mcap"
    assert main(["run", "arm_payload_swap", "-o", str(log), "--set", "simulation.duration=2.0",
                 "--set", "events=[{t=1.0, kind='payload_mass', value=2.0}]"]) == 0
    logged = read_log(log)
    theta = logged.trajectory.theta
    t = logged.trajectory.t
    before, after = theta[t < 1.0][-1], theta[t >= 1.0][0]
    assert after[0] > before[0] and after[2] > before[2]  # J and g_sin grow with the payload
    assert before[1] == after[1]  # damping unchanged
    assert any("payload_mass" in e["label"] for e in logged.events)


def test_run_refuses_to_overwrite_without_force(tmp_path):
    log = tmp_path / "x.mcap"
    log.write_bytes(b"keep me")
    r = cli("run", "lecture_first_order", "-o", log, "--set", "simulation.duration=0.5",
            "--set", "success.tail_rms=inf")
    assert r.returncode == 2
    assert "file exists; pass --force" in r.stderr and "Traceback" not in r.stderr
    assert log.read_bytes() == b"keep me"
    r = cli("run", "lecture_first_order", "-o", log, "--set", "simulation.duration=0.5",
            "--set", "success.tail_rms=inf", "--force")
    assert r.returncode == 0, r.stderr


def test_default_log_names_never_overwrite(tmp_path, monkeypatch):
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.runs.runner import reserve_log_path

    scn = sc.load(REPO / "scenarios" / "lecture_first_order.toml")
    paths = {reserve_log_path(scn, directory=tmp_path) for _ in range(3)}
    assert len(paths) == 3 and all(p.parent == tmp_path for p in paths)


def test_bad_scenario_exits_2_with_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((REPO / "scenarios" / "heave_tracking.toml").read_text().replace("k = 200.0", "k = -1.0"))
    r = cli("run", bad)
    assert r.returncode == 2
    assert r.stderr.strip() == f"adaptive-mj: error: {bad}: law.k must be >= 0, got -1.0"
    assert not list(tmp_path.glob("*.mcap"))


def test_unreadable_log_exits_2(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not an mcap file")
    r = cli("replay", junk)
    assert r.returncode == 2
    assert str(junk) in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_diverged_run_exits_1(tmp_path):
    log = tmp_path / "div.mcap"
    r = cli("run", "lecture_heave", "-o", log, "--json", "--set", "simulation.state_bound=0.5")
    assert r.returncode == 1, r.stderr
    s = json.loads(r.stdout)
    assert s["status"] == "diverged" and "beyond the bound" in s["reason"]
    r2 = cli("replay", log, "--json")
    assert json.loads(r2.stdout) == s and r2.returncode == 1


def test_debug_after_the_command_shows_the_traceback():
    r = cli("run", "no_such_scenario_file.toml", "--debug")
    assert r.returncode != 0 and "Traceback" in r.stderr and "scenario file not found" in r.stderr


def test_list_into_a_closed_pipe_is_quiet():
    env = dict(os.environ, MUJOCO_GL="egl")
    r = subprocess.run(f"{sys.executable} -m adaptive_mj list | head -1", shell=True, capture_output=True, text=True,
                       cwd=REPO, env=env, timeout=120)
    assert r.returncode == 0 and len(r.stdout.splitlines()) == 1 and "Traceback" not in r.stderr


def test_misspelt_required_key_is_pointed_out(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((REPO / "scenarios" / "heave_tracking.toml").read_text().replace("lambda = 5.0", "lamda = 5.0"))
    r = cli("run", bad)
    assert r.returncode == 2
    assert "law.lambda is required but missing (found 'law.lamda': a misspelling?)" in r.stderr


def test_malformed_video_range_is_bad_input(tmp_path):
    log = tmp_path / "x.mcap"
    assert cli("run", "heave_tracking", "-o", log, "--set", "simulation.duration=0.2").returncode == 0
    r = cli("replay", log, "--video", tmp_path / "x.gif", "--video-range", "5")
    assert r.returncode == 2 and "--video-range '5': expected T0:T1" in r.stderr
    assert not (tmp_path / "x.gif").exists()


def test_payload_mass_event_without_payload_says_so(tmp_path):
    r = cli("run", "arm_payload_swap", "-o", tmp_path / "x.mcap", "--set", "plant.payload=none")
    assert r.returncode == 2 and "needs a payload (plant.payload is 'none')" in r.stderr

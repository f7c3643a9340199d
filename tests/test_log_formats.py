"""Formats are promises: logs written in format 1 (by adaptive-mj before multi-joint runs), format 2
(before law plugins) and format 3 (before sampled-data control) still read and replay bit for bit; a
multi-joint run round-trips."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.log import record

from adaptive_mj.setup import scenario
from adaptive_mj.cli import main
from adaptive_mj.log.replay import read_log
from adaptive_mj.sim.runner import execute

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("name", ["heave_tracking_format1.mcap", "arm_payload_swap_format1.mcap"])
def test_format1_logs_read_and_verify(name, capsys):
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 1 < record.LOG_FORMAT_VERSION
    assert run.status == "ok" and run.trajectory.joint_names == ()
    assert run.trajectory.x.ndim == 2 and run.trajectory.u.ndim == 1
    assert main(["replay", str(DATA / name), "--verify"]) == 0
    assert "verify: bit-identical" in capsys.readouterr().out


@pytest.mark.parametrize("name, joints", [("heave_tracking_format2.mcap", 0), ("ur5e_payload_swap_format2.mcap", 6)])
def test_format2_logs_read_and_verify(name, joints, capsys):
    """Written by adaptive-mj before law plugins (format 2, no law_plugin in the header)."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 2 < record.LOG_FORMAT_VERSION
    assert run.header.get("law_plugin") is None
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints
    assert main(["replay", str(DATA / name), "--verify"]) == 0
    assert "verify: bit-identical" in capsys.readouterr().out


@pytest.mark.parametrize("name, joints", [("heave_drift_delay_format3.mcap", 0),
                                          ("ur5e_payload_swap_delay_format3.mcap", 6)])
def test_format3_logs_read_and_verify(name, joints, capsys):
    """Written by adaptive-mj 0.1.0 before sampled-data control (format 3, no control_mode): read as
    continuous control at the physics step, and re-simulated bit for bit. Both ran with a control
    delay; the 6-joint one ran it on the Python callback then and runs it natively now."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 3 < record.LOG_FORMAT_VERSION
    assert run.header["control_mode"] == "continuous" and run.header["control_period"] == run.header["dt"]
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints
    assert main(["replay", str(DATA / name), "--verify"]) == 0
    assert "verify: bit-identical" in capsys.readouterr().out


def test_format4_header_records_the_control_mode(tmp_path):
    scn = scenario.load(scenario.SCENARIOS_DIR / "heave_tracking.toml",
                        overrides=["simulation.duration=0.1", "control.period=0.005"])
    path = tmp_path / "sampled.mcap"
    execute(scn, log_path=path)
    run = read_log(path)
    assert (run.header["log_format_version"], run.header["control_mode"], run.header["control_period"]) == \
        (4, "sampled", 0.005)


def test_multi_joint_log_round_trips(tmp_path):
    scn = scenario.load(scenario.SCENARIOS_DIR / "ur5e_payload_swap.toml",
                        overrides=["simulation.duration=0.5",
                                   "events=[{t=0.25, kind='payload_swap', payload='sphere'}]"])
    path = tmp_path / "arm.mcap"
    live = execute(scn, log_path=path).trajectory
    run = read_log(path)
    assert run.header["log_format_version"] == record.LOG_FORMAT_VERSION == 4
    assert run.header["joint_names"] == list(live.joint_names) and len(live.joint_names) == 6
    tr = run.trajectory
    every = run.header["log_every"]
    assert tr.x.shape == (len(live.t[::every]), 2, 6)
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        assert np.array_equal(getattr(tr, field), getattr(live, field)[::every]), field
    assert [label for _, label in tr.meta["events"]] == ["payload_swap payload/body = sphere (0.5 kg)"]
    # the true parameters follow the swap in the log
    assert tr.theta[0, 0] == pytest.approx(1.5) and tr.theta[-1, 0] == pytest.approx(0.5)


def test_multi_joint_replay_verify_is_bit_identical(tmp_path, capsys):
    path = tmp_path / "arm.mcap"
    assert main(["run", "ur5e_payload_swap", "-o", str(path), "--set", "simulation.duration=0.3",
                 "--set", "events=[]"]) == 0
    assert main(["replay", str(path), "--verify"]) == 0
    assert "verify: bit-identical" in capsys.readouterr().out


def test_multi_joint_log_renders_a_video_of_the_whole_arm(tmp_path):
    from PIL import Image

    path = tmp_path / "arm.mcap"
    assert main(["run", "ur5e_payload_swap", "-o", str(path), "--set", "simulation.duration=0.3",
                 "--set", "events=[]"]) == 0
    gif = tmp_path / "arm.gif"
    assert main(["replay", str(path), "--video", str(gif), "--video-fps", "10"]) == 0
    with Image.open(gif) as im:
        assert im.size == (800, 400) and im.n_frames == 3
        frame = np.asarray(im.convert("RGB"))
    assert frame[:, :400].std() > 10  # the scene is not blank

"""Formats are promises: logs written in format 1 (by adaptive-mj before multi-joint runs), format 2
(before law plugins), format 3 (before sampled-data control), format 4 (before the verdict's limits
and the embedded model's hash), format 5, format 6 (JSON rows, before CDR) and format 7 (six CDR row topics,
before the one /row topic of format 8) and format 8 (before a crash closed as "crashed", format 9) still read and
replay bit for bit; the CDR (format 8) and JSON (format 6)
encodings of one run read back the same; a multi-joint run round-trips; an altered embedded model is refused on
read."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from adaptive_mj.errors import LogFormatError
from adaptive_mj.log import record

from adaptive_mj.setup import scenario
from adaptive_mj.cli import main
from adaptive_mj.log.replay import read_log
from adaptive_mj.runs.runner import execute
from adaptive_mj.trajectory import Status

DATA = Path(__file__).parent / "data"
OTHER_MACHINE = "verify: MISMATCH before the first step"


def _verify(path: Path, capsys) -> str:
    """`replay PATH --verify`'s output, which must say bit-identical; skipped (with verify's own reason) where this
    machine's MuJoCo compiles the fixture's model to other true parameters at t = 0 than the machine that wrote it
    did (the UR5e fixtures' payload inertia, 2 ulp apart on some CPUs): no re-run there can be bit-identical,
    and the failure would be the machine's, not the format's."""
    rc = main(["replay", str(path), "--verify"])
    out = capsys.readouterr().out
    if rc != 0 and OTHER_MACHINE in out:
        pytest.skip(out.strip().splitlines()[-1])
    assert rc == 0, out.strip().splitlines()[-1]
    return out


@pytest.mark.parametrize("name", ["heave_tracking_format1.mcap", "arm_payload_swap_format1.mcap"])
def test_format1_logs_read_and_verify(name, capsys):
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 1 < record.LOG_FORMAT_VERSION
    assert run.status == "ok" and run.trajectory.joint_names == ()
    assert run.trajectory.x.ndim == 2 and run.trajectory.u.ndim == 1
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


@pytest.mark.parametrize("name, joints", [("heave_tracking_format2.mcap", 0), ("ur5e_payload_swap_format2.mcap", 6)])
def test_format2_logs_read_and_verify(name, joints, capsys):
    """Written by adaptive-mj before law plugins (format 2, no law_plugin in the header)."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 2 < record.LOG_FORMAT_VERSION
    assert run.header.get("law_plugin") is None
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints
    out = _verify(DATA / name, capsys)
    if joints:  # its payload swap at 0.15 s came mid-second: V before it was computed with the new payload then
        assert ("verify: bit-identical but for V at 14 rows before the event at t = 0.15 s, which adaptive-mj "
                "before 0.2.0 computed with the inertia after that event") in out
    else:
        assert "verify: bit-identical (" in out


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
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


@pytest.mark.parametrize("name, joints", [("heave_drift_sampled_format4.mcap", 0),
                                          ("ur5e_payload_swap_format4.mcap", 6)])
def test_format4_logs_read_and_verify(name, joints, capsys):
    """Written before format 5 (no ctrl_range, joint_limits or embedded_sha256): read without the
    saturation metrics, no hash to check, re-simulated bit for bit (the heave one sampled at 4 ms with
    a delay of 3 steps, the 6-joint one with a payload_mass event)."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 4 < record.LOG_FORMAT_VERSION
    assert "embedded_sha256" not in run.header and "ctrl_range" not in run.trajectory.meta
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


@pytest.mark.parametrize("name, joints", [("heave_drift_format5.mcap", 0), ("ur5e_payload_swap_format5.mcap", 6)])
def test_format5_logs_read_and_verify(name, joints, capsys):
    """Written before format 6 (no control_names or state_names: u one entry per joint, x the output's
    derivatives): read with u shaped as before, its hash checked, re-simulated bit for bit."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 5 < record.LOG_FORMAT_VERSION
    assert "control_names" not in run.header and run.trajectory.control_names == ()
    assert run.trajectory.u.shape == (len(run.trajectory),) + ((joints,) if joints else ())
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


def test_format6_log_reads_and_verifies(capsys):
    """Written by adaptive-mj before format 7 (JSON rows): read through its JSON channels, re-simulated bit for bit."""
    name = "heave_drift_format6.mcap"
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 6 < record.LOG_FORMAT_VERSION
    assert "encoding" not in run.header
    assert run.status == "ok" and run.trajectory.joint_names == () and len(run.trajectory) == 50
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


@pytest.mark.parametrize("name, joints, rows", [("heave_drift_format7.mcap", 0, 50),
                                                ("ur5e_payload_swap_format7.mcap", 6, 30)])
def test_format7_logs_read_and_verify(name, joints, rows, capsys):
    """Written by adaptive-mj before format 8 (six CDR row topics, one message per topic and row): read through
    its six CDR channels, re-simulated bit for bit (the heave one 1 s at 50 Hz, the 6-joint one 0.3 s at 100 Hz
    with a payload swap at 0.15 s)."""
    run = read_log(DATA / name)
    assert run.header["log_format_version"] == 7 < record.LOG_FORMAT_VERSION
    assert run.header["encoding"] == "cdr"
    assert run.status == "ok" and len(run.trajectory.joint_names) == joints and len(run.trajectory) == rows
    assert "verify: bit-identical" in _verify(DATA / name, capsys)


@pytest.mark.parametrize("name, extra", [
    ("heave_drift", ()),
    ("ur5e_payload_swap", ("simulation.duration=0.3", "events=[{t=0.15, kind='payload_swap', payload='sphere'}]"))])
def test_cdr_and_json_encodings_of_one_run_give_the_same_trajectory(tmp_path, name, extra, capsys):
    """log.encoding = "cdr" (format 8: one /row message a row) and "json" (format 6) of the same run: every array
    read back is the same, bit for bit, and both verify."""
    runs = {}
    for encoding in ("cdr", "json"):
        scn = scenario.load(scenario.SCENARIOS_DIR / f"{name}.toml",
                            overrides=["simulation.duration=1", *extra, f"log.encoding={encoding!r}"])
        path = tmp_path / f"{encoding}.mcap"
        execute(scn, log_path=path)
        runs[encoding] = read_log(path)
        assert "verify: bit-identical" in _verify(path, capsys)
    cdr, js = runs["cdr"], runs["json"]
    assert (cdr.header["log_format_version"], js.header["log_format_version"]) == (9, 6)
    assert cdr.header["encoding"] == "cdr" and "encoding" not in js.header
    for field in ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V"):
        a, b = getattr(cdr.trajectory, field), getattr(js.trajectory, field)
        assert a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes(), field
    assert cdr.trajectory.meta == js.trajectory.meta and cdr.events == js.events
    assert cdr.summary == js.summary and cdr.status == js.status


def _closed_with(path: Path) -> tuple[str, str]:
    """(status, reason) as the file itself holds them (its "status" metadata), not as read_log names them."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        (meta,) = [m.metadata for m in make_reader(f).iter_metadata() if m.name == record.STATUS_METADATA]
    return meta["status"], meta["reason"]


def test_a_format8_crash_closed_as_failed_reads_as_crashed_and_verifies(capsys):
    """Written by adaptive-mj before format 9 (a quadrotor too heavy to fly, 2 s, Python callback, rows at 50 Hz): the
    crash closed the log as "failed" with the reason "crashed at t = …"; read back, the run is "crashed" (its
    trajectory, its summary), replay's exit code is a failure's, and it re-simulates bit for bit (as "crashed")."""
    path = DATA / "quadrotor_crash_format8.mcap"
    status, reason = _closed_with(path)
    assert status == "failed" and reason.startswith("crashed at t = 0.744 s: hit the ground")
    run = read_log(path)
    assert run.header["log_format_version"] == 8 < record.LOG_FORMAT_VERSION
    assert run.status == run.trajectory.status == run.summary["status"] == Status.CRASHED
    assert run.trajectory.reason == run.summary["reason"] == reason and len(run.trajectory) == 38
    assert main(["replay", str(path), "--verify"]) == 1  # bit-identical, and the run it re-ran crashed again
    out = capsys.readouterr().out
    if OTHER_MACHINE in out:
        pytest.skip(out.strip().splitlines()[-1])
    assert "verify: bit-identical" in out and "crashed" in out


def test_a_crash_closes_as_crashed_in_format9_and_as_failed_in_the_json_encoding(tmp_path):
    """The same crash logged in CDR (format 9: status "crashed") and in JSON (format 6, byte for byte in kind: "failed"
    with the crash's reason, as every format-6 reader expects): both read back as "crashed", with the same summary."""
    runs = {}
    for encoding in ("cdr", "json"):
        scn = scenario.load(scenario.SCENARIOS_DIR / "quadrotor_lemniscate.toml",
                            overrides=["plant.payload_mass=0.05", "simulation.duration=2", "log.rate_hz=50",
                                       "simulation.python_callback=true", f"log.encoding={encoding!r}"])
        path = tmp_path / f"{encoding}.mcap"
        live = execute(scn, log_path=path)
        assert live.status == Status.CRASHED and live.summary["reason"].startswith("crashed at t = ")
        runs[encoding] = read_log(path), _closed_with(path)
    (cdr, cdr_closed), (js, js_closed) = runs["cdr"], runs["json"]
    assert (cdr.header["log_format_version"], js.header["log_format_version"]) == (9, 6)
    assert cdr_closed[0] == "crashed" and js_closed[0] == "failed" and cdr_closed[1] == js_closed[1]
    assert cdr.status == js.status == Status.CRASHED and cdr.summary == js.summary
    assert cdr.summary["status"] == "crashed"


def test_format5_and_later_headers_record_control_limits_and_the_embedded_hash(tmp_path):
    scn = scenario.load(scenario.SCENARIOS_DIR / "ur5e_payload_swap.toml",
                        overrides=["simulation.duration=0.1", "control.period=0.005", "events=[]", "log.rate_hz=1000"])
    path = tmp_path / "sampled.mcap"
    result = execute(scn, log_path=path)
    run = read_log(path)
    assert (run.header["log_format_version"], run.header["control_mode"], run.header["control_period"]) == \
        (record.LOG_FORMAT_VERSION, "sampled", 0.005)
    assert run.header["ctrl_range"] == [[-150.0] * 3 + [-28.0] * 3, [150.0] * 3 + [28.0] * 3]
    assert run.header["embedded_sha256"] == record.embedded_digest(run.model_xml, run.model_source, run.model_assets)
    # the saturation metric of a log summarised from its rows (every step logged) equals the run's own
    from adaptive_mj.report.metrics import saturation_fraction

    frac = saturation_fraction(run.trajectory)
    assert frac is not None and frac.shape == (6,)
    assert result.summary["metrics"]["saturation_fraction"] == frac.max()


def _rewrite(src: Path, dst: Path, *, attachment: str, change) -> None:
    """Copy a log record by record with one attachment's data changed (None: removed)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        messages = list(reader.iter_messages())
        metadata = list(reader.iter_metadata())
        attachments = list(reader.iter_attachments())
    with open(dst, "wb") as f:
        w = Writer(f)
        w.start(profile=header.profile, library=header.library)
        schema_ids, channel_ids = {}, {}
        for sid, schema in summary.schemas.items():
            schema_ids[sid] = w.register_schema(schema.name, schema.encoding, schema.data)
        for cid, ch in summary.channels.items():
            channel_ids[cid] = w.register_channel(ch.topic, ch.message_encoding, schema_ids[ch.schema_id], ch.metadata)
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        for a in attachments:
            data = change(a.data) if a.name == attachment else a.data
            if data is not None:
                w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        for _schema, channel, msg in messages:
            w.add_message(channel_ids[channel.id], msg.log_time, msg.data, msg.publish_time)
        w.finish()


@pytest.mark.parametrize("change", [lambda d: d.replace(b'mass="', b'mass="1', 1), lambda d: None],
                         ids=["altered", "removed"])
def test_an_altered_or_removed_embedded_model_is_refused_on_read(tmp_path, change, capsys):
    scn = scenario.load(scenario.SCENARIOS_DIR / "heave_tracking.toml", overrides=["simulation.duration=0.1"])
    good = tmp_path / "good.mcap"
    execute(scn, log_path=good)
    bad = tmp_path / "bad.mcap"
    _rewrite(good, bad, attachment=record.MODEL_SOURCE_ATTACHMENT, change=change)
    assert read_log(good).status == "ok"
    with pytest.raises(LogFormatError, match=r"bad.mcap: the embedded model does not match the log's embedded_sha256"):
        read_log(bad)
    assert main(["replay", str(bad), "--verify"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "embedded_sha256" in err[0]


def test_multi_joint_log_round_trips(tmp_path):
    scn = scenario.load(scenario.SCENARIOS_DIR / "ur5e_payload_swap.toml",
                        overrides=["simulation.duration=0.5",
                                   "events=[{t=0.25, kind='payload_swap', payload='sphere'}]"])
    path = tmp_path / "arm.mcap"
    live = execute(scn, log_path=path).trajectory
    run = read_log(path)
    assert run.header["log_format_version"] == record.LOG_FORMAT_VERSION == 9
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


def test_a_v_difference_is_explained_only_where_the_old_flush_got_v_wrong():
    """verify._v_before_event: rows before an event in the same simulated second (earlier versions
    computed their V at the flush after the event) are a known difference; any other row is not."""
    from types import SimpleNamespace

    from adaptive_mj.runs.verify import _v_before_event

    rerun = SimpleNamespace(meta={"dt": 0.001, "events": [(1.25, "payload_swap")]})
    steps = np.arange(300) * 10  # logged every 10th step, t = 0 .. 2.99 s
    differ = np.zeros(300, dtype=bool)
    differ[101:125] = True  # t = 1.01 .. 1.24 s: before the event, in its second
    assert "24 rows before the event at t = 1.25 s" in _v_before_event(differ, steps, rerun)
    differ[99] = True  # t = 0.99 s: flushed before the event, so it was right then
    assert _v_before_event(differ, steps, rerun) == ""
    differ[99], differ[130] = False, True  # after the event
    assert _v_before_event(differ, steps, rerun) == ""


def test_verify_names_a_model_that_compiles_to_other_parameters():
    """A log whose true parameters at t = 0 differ from the re-run's (as when another CPU compiled its model)
    is refused before the first step, with both numbers and the distance in ulp, not as a mismatch of the
    control at some row."""
    from adaptive_mj.runs import verify as verify_mod

    run = read_log(DATA / "heave_tracking_format1.mcap")
    theta = run.trajectory.theta
    bumped = theta.copy()
    bumped[0, 1] = np.nextafter(bumped[0, 1], np.inf)
    import dataclasses

    ok, message = verify_mod.verify(dataclasses.replace(run, trajectory=dataclasses.replace(run.trajectory,
                                                                                             theta=bumped)))
    assert not ok and message.startswith(OTHER_MACHINE)
    assert f"parameter 1: log {float(bumped[0, 1])!r} vs re-run {float(theta[0, 1])!r}, 1 ulp" in message


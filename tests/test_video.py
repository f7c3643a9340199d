"""Video of a logged run (adaptive_mj.report.video): headless frames that are not blank and
follow the logged motion, MP4 and GIF files that decode, the replay --video command,
and one-line errors for what cannot be rendered."""
import os
import subprocess
import sys
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.errors import AdaptiveMJError, LogFormatError
from adaptive_mj.log.replay import read_log
from adaptive_mj.report.video import frame_rows, iter_frames, parse_size, render_log, scene_width

REPO = Path(__file__).resolve().parents[1]
SIZE = (256, 128)   # small frames keep the software renderer fast


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Short real runs: the heave vehicle, the arm with a payload swap mid-run, a twin-only plant."""
    d = tmp_path_factory.mktemp("video_logs")
    runs = {
        "heave": ["heave_tracking", "--set", "simulation.duration=0.5", "--set", "success.tail_rms=inf"],
        "arm": ["arm_payload_swap", "--set", "simulation.duration=0.5",
                "--set", "events=[{t=0.25, kind='payload_mass', value=2.0}]"],
        "twin": ["lecture_first_order", "--set", "simulation.duration=0.2", "--set", "success.tail_rms=inf"],
    }
    paths = {}
    for name, args in runs.items():
        paths[name] = d / f"{name}.mcap"
        assert main(["run", args[0], "-o", str(paths[name]), *args[1:]]) == 0
    return paths


def _scene(frame):
    return frame[:, :scene_width(SIZE)].astype(float)


def _content(scene):
    """Fraction of scene pixels that stand out from their row (the backdrop is a vertical
    gradient, so each row of bare backdrop is one colour); the label rows are left out."""
    body = scene[scene.shape[0] // 6:]
    return float((np.abs(body - np.median(body, axis=1, keepdims=True)).max(axis=2) > 30).mean())


@pytest.mark.parametrize("plant", ["heave", "arm"])
def test_frames_are_not_blank_and_the_scene_moves(logs, plant):
    frames = list(iter_frames(logs[plant], fps=10, size=SIZE))
    assert len(frames) == 5                            # t = 0.0 .. 0.4 s of rows 0 .. 0.49 s
    for frame in frames:
        assert frame.shape == (SIZE[1], SIZE[0], 3) and frame.dtype == np.uint8
        assert _scene(frame).std() > 5.0               # the MuJoCo scene is not one flat colour
        assert _content(_scene(frame)) > 0.01          # and shows more than the backdrop
        assert frame[:, scene_width(SIZE):].astype(float).std() > 20.0   # the panel has plots
    # The joint moves over 0.4 s (heave: y = cos t from 1 m; arm: a sum of sines), so the
    # scene differs between the first and the last frame.
    assert np.abs(_scene(frames[0]) - _scene(frames[-1])).mean() > 1.0


def test_frame_times_are_real_time_and_show_the_latest_row():
    t = np.arange(0, 1.0, 0.01)                       # 100 Hz rows
    times, rows = frame_rows(t, 30.0)
    assert len(times) == 30 and times[1] == pytest.approx(1 / 30)
    assert np.all(t[rows] <= times + 1e-9) and np.all(times - t[rows] < 0.01)
    times, rows = frame_rows(t, 10.0, (0.5, 0.75))
    assert times[0] == 0.5 and rows[0] == 50 and len(times) == 3


@pytest.mark.parametrize("suffix", [".mp4", ".gif"])
def test_video_file_is_written_and_decodes(logs, tmp_path, suffix):
    out = tmp_path / "sub" / f"arm{suffix}"
    video = render_log(logs["arm"], out, fps=20, size=SIZE)
    assert video.path == out and out.stat().st_size > 1000
    assert video.frames == 10 and video.size == SIZE
    frames = iio.imread(out, index=None)
    assert frames.shape[0] == video.frames
    assert frames.shape[1:3] == (SIZE[1], SIZE[0])
    assert frames[0].astype(float).std() > 10.0


def test_time_range_selects_the_payload_swap(logs, tmp_path):
    video = render_log(read_log(logs["arm"]), tmp_path / "swap.gif", fps=20, size=SIZE,
                       t_range=(0.2, 0.3))
    assert video.frames == 3 and video.span == (0.2, 0.3)


def test_replay_video_command(logs, tmp_path, capsys):
    out = tmp_path / "heave.mp4"
    code = main(["replay", str(logs["heave"]), "--video", str(out), "--video-fps", "10",
                 "--video-size", "256x128"])
    assert code == 0
    assert "video: " in capsys.readouterr().out
    assert iio.imread(out, index=None).shape == (5, 128, 256, 3)


def test_replay_video_in_a_fresh_process_without_mujoco_gl(logs, tmp_path):
    """The command sets MUJOCO_GL itself: no display, no variable, still a video."""
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    out = tmp_path / "heave.gif"
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "replay", str(logs["heave"]),
                        "--video", str(out), "--video-fps", "5", "--video-size", "128x64"],
                       capture_output=True, text=True, cwd=REPO, env=env, stdin=subprocess.DEVNULL,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert iio.imread(out, index=None).shape[0] == 3


def test_twin_only_log_exits_2_with_one_line(logs, tmp_path, capsys):
    out = tmp_path / "twin.mp4"
    assert main(["replay", str(logs["twin"]), "--video", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "holds no MuJoCo model" in err and str(logs["twin"]) in err
    assert not out.exists()
    with pytest.raises(LogFormatError, match="holds no MuJoCo model"):
        next(iter_frames(logs["twin"]))


def test_bad_video_arguments(logs, tmp_path):
    with pytest.raises(AdaptiveMJError, match=r"must end in \.mp4 or \.gif, got '\.avi'"):
        render_log(logs["heave"], tmp_path / "x.avi")
    with pytest.raises(AdaptiveMJError, match="even numbers of pixels from 64 to 4096, got 33x10"):
        parse_size("33x10")
    with pytest.raises(AdaptiveMJError, match="must be WxH in pixels"):
        parse_size("big")
    assert parse_size("640x320") == (640, 320) and parse_size(None) == (800, 400)
    with pytest.raises(AdaptiveMJError, match="does not overlap the run"):
        render_log(logs["heave"], tmp_path / "x.gif", t_range=(5.0, 6.0))
    assert not (tmp_path / "x.gif").exists()


def test_the_reference_pose_shows_when_tracking_is_exact(tmp_path):
    """The arm starts on its reference (ỹ = 0): the green ghost of the reference pose is still seen,
    as a translucent shell around the body; and the estimate axes carry units."""
    log = tmp_path / "arm.mcap"
    assert main(["run", "arm_payload_swap", "-o", str(log), "--set", "simulation.duration=0.3",
                 "--set", "events=[]"]) == 0
    frame = next(iter(iter_frames(log, fps=10, size=SIZE))).astype(int)
    scene = frame[:, :scene_width(SIZE)]
    green = (scene[..., 1] > scene[..., 0] + 40) & (scene[..., 1] > scene[..., 2] + 20)
    assert green.sum() > 100, green.sum()
    from adaptive_mj.report import video

    labels = []
    real = video._Panel.__init__

    def spy(self, traj, rows, **kw):
        real(self, traj, rows, **kw)
        labels.extend(text.get_text() for text in self._labels)  # each axis's name, inside its corner

    video._Panel.__init__ = spy
    try:
        next(iter(iter_frames(log, fps=10, size=SIZE)))
    finally:
        video._Panel.__init__ = real
    assert "J [kg m²]" in labels and "g_sin [N m]" in labels, labels


def test_gif_plays_in_real_time(logs, tmp_path):
    """GIF delays are whole centiseconds: at 30 fps they alternate 30/40 ms so that the video lasts
    the simulated time to within 10 ms (not 30 ms frames, which would play 10 % fast)."""
    from PIL import Image

    video = render_log(logs["heave"], tmp_path / "h.gif", fps=30, size=SIZE)
    with Image.open(video.path) as im:
        durations = []
        for i in range(im.n_frames):
            im.seek(i)
            durations.append(im.info["duration"])
    assert len(durations) == video.frames
    assert abs(sum(durations) / 1000.0 - video.frames / 30.0) <= 0.010
    assert set(durations) <= {30, 40}

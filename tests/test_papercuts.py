"""Papercuts from a new user's trial (issue 22, item 9): each fixed where a user met it."""
import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from adaptive_mj.cli import gl_library_missing, main
from adaptive_mj.errors import AdaptiveMJError

REPO = Path(__file__).resolve().parents[1]

# a user's arm as menagerie writes them: the links' geoms in group 3 (collision), the payload in group 0
ARM_IN_GROUP_3 = """<mujoco><worldbody><geom type="plane" size="1 1 .1"/>
<body name="link"><joint type="hinge"/><geom type="capsule" size=".05" fromto="0 0 0 .5 0 0" group="3"/>
<geom type="box" size=".02 .02 .02" group="3"/>
<body name="payload" pos=".5 0 0"><geom type="sphere" size=".1"/></body></body></worldbody></mujoco>"""


# ------------------------------------------------------------------ video: geom groups
def test_video_draws_the_groups_that_hold_a_bodys_geoms():
    from adaptive_mj.report.video import parse_groups, visible_groups

    model = mujoco.MjModel.from_xml_string(ARM_IN_GROUP_3)
    assert visible_groups(model).tolist() == [1, 1, 1, 1, 0, 0]  # MuJoCo's default 0-2, and the arm's 3
    both = mujoco.MjModel.from_xml_string(ARM_IN_GROUP_3.replace('size=".02 .02 .02" group="3"',
                                                                 'size=".02 .02 .02" group="2"'))
    assert visible_groups(both).tolist() == [1, 1, 1, 0, 0, 0]  # a visual geom in group 2: collision stays hidden
    assert visible_groups(model, [0, 4]).tolist() == [1, 0, 0, 0, 1, 0]
    assert parse_groups("0,3") == [0, 3] and parse_groups(None) is None
    with pytest.raises(AdaptiveMJError, match=r"--video-groups '0,9': expected geom groups 0\.\.5"):
        parse_groups("0,9")


def test_video_groups_reach_the_renderer(tmp_path):
    from adaptive_mj.report.video import iter_frames, scene_width

    log = tmp_path / "arm.mcap"
    assert main(["run", "arm_payload_swap", "-o", str(log), "--set", "simulation.duration=0.2",
                 "--set", "events=[]", "--set", "success.tail_rms=inf"]) == 0
    size = (256, 128)
    default = next(iter(iter_frames(log, fps=10, size=size)))[:, :scene_width(size)].astype(float)
    nothing = next(iter(iter_frames(log, fps=10, size=size, groups=[5])))[:, :scene_width(size)].astype(float)
    assert np.abs(default - nothing).mean() > 1.0  # group 5 holds no geom: the arm and its ghost are gone
    assert main(["replay", str(log), "--video", str(tmp_path / "v.gif"), "--video-groups", "x"]) == 2


# ------------------------------------------------------------------ MUJOCO_GL without its library
def test_a_gl_backend_without_its_library_is_one_line():
    def missing(name):
        raise OSError(f"lib{name}.so: cannot open shared object file")

    assert gl_library_missing("osmesa", load=missing) == (
        "MUJOCO_GL=osmesa needs the OSMesa library (libOSMesa.so), which is not installed: install the Debian "
        "package libosmesa6 (apt-get install libosmesa6), or use MUJOCO_GL=egl")
    assert "Debian package libegl1" in gl_library_missing("egl", load=missing)
    assert gl_library_missing("osmesa", load=lambda name: None) is None
    assert gl_library_missing("glfw", load=missing) is None and gl_library_missing(None, load=missing) is None


def _osmesa_loads() -> bool:
    return gl_library_missing("osmesa") is None


@pytest.mark.skipif(_osmesa_loads(), reason="this machine has libOSMesa: the failure cannot be seen here")
def test_mujoco_gl_osmesa_without_osmesa_exits_2_with_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "run", "heave_tracking", "-o", str(tmp_path / "h.mcap")],
                       capture_output=True, text=True, env=dict(os.environ, MUJOCO_GL="osmesa", PYTHONPATH=str(REPO)),
                       timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [r.stderr.strip()] and "apt-get install libosmesa6" in r.stderr
    assert not (tmp_path / "h.mcap").exists()


# ------------------------------------------------------------------ sweep: seeds, units
def test_seeds_note_counts_a_noise_disturbance_as_randomness():
    from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
    from adaptive_mj.study.sweep import sweep_notes

    arm6 = load(SCENARIOS_DIR / "ur5e_identification.toml")
    assert re.match(r"--seeds 3 on a scenario without noise .*the 3 runs of each point are identical",
                    sweep_notes(arm6, ["law.kd"], 3)[0])
    noisy = load(SCENARIOS_DIR / "ur5e_identification.toml",
                 overrides=["disturbance={kind='noise', magnitude=0.5}"])
    assert sweep_notes(noisy, ["law.kd"], 3) == []  # band-limited torque noise is drawn from the seed


def test_sweep_axes_carry_units_and_parameter_errors_come_relative_too():
    from adaptive_mj.study.sweep import flat_metrics, metric_label

    assert metric_label("rms_tracking_error_tail", "manipulator") == "rms_tracking_error_tail [rad]"
    assert metric_label("control_rms", "arm") == "control_rms [N m]"
    assert metric_label("param_error_final.b", "heave") == "param_error_final.b [kg/m]"
    assert metric_label("param_error_final.payload/body.m", "manipulator") == "param_error_final.payload/body.m [kg]"
    assert metric_label("param_error_relative_final.J", "arm") == "param_error_relative_final.J [-] (p̂/p − 1)"
    summary = {"metrics": {"rms_tracking_error": 0.1, "param_error_final": {"d": -3.7, "c": 0.5}},
               "final": {"theta": {"d": 37.0, "c": 0.0}, "theta_hat": {"d": 33.3, "c": 0.5}}}
    row = flat_metrics(summary)
    assert row["param_error_final.d"] == -3.7 and row["param_error_relative_final.d"] == pytest.approx(-0.1)
    assert row["param_error_relative_final.c"] is None  # no relative error of a parameter whose truth is 0


def test_a_sweep_plots_a_relative_parameter_error(tmp_path):
    out = tmp_path / "s"
    assert main(["sweep", "heave_tracking", "--grid", "law.k=100,200", "--set", "simulation.duration=1",
                 "--set", "success.tail_rms=inf", "--metric", "param_error_relative_final.d", "-o", str(out),
                 "--jobs", "1"]) == 0
    import csv

    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for r in rows:  # d̂/d − 1 from the same row's absolute error and the model's d (37 kg, README)
        assert float(r["param_error_relative_final.d"]) == pytest.approx(float(r["param_error_final.d"]) / 37.0,
                                                                         rel=0.01)
    assert "mean param_error_relative_final.d [-] (p̂/p − 1)" in (out / "report.md").read_text()


# ------------------------------------------------------------------ bench figures and tables
def test_a_recovery_that_was_not_needed_is_not_zero_seconds():
    from adaptive_mj.study import analysis
    from adaptive_mj.study.bench_catalogue import _recovery

    thr = analysis.SWAP_THRESHOLD
    assert _recovery(None, 0.07) == "never"
    assert _recovery(0.0, 0.5 * thr) == f"not needed (peak < {thr} rad)"
    assert _recovery(5.694, 0.0198) == "5.69 s"
    t = np.linspace(0.0, 2.0, 201)
    quiet = np.full_like(t, 0.5 * thr)  # never above the threshold after the event at t = 1 s
    assert analysis.settle_time(t, quiet < thr, 1.0) == 0.0 and _recovery(0.0, float(quiet.max())).startswith("not")


# ------------------------------------------------------------------ video panel on a 6-joint arm
def test_the_video_panel_shows_every_estimate_of_a_six_joint_arm_without_overlapping_labels(tmp_path):
    from adaptive_mj.report import video

    log = tmp_path / "ur5e.mcap"
    assert main(["run", "ur5e_identification", "-o", str(log), "--set", "simulation.duration=0.2",
                 "--set", "success.tail_rms=inf"]) in (0, 1)
    panels = []
    real = video._Panel.__init__

    def spy(self, traj, rows, **kw):
        real(self, traj, rows, **kw)
        panels.append((self, traj))

    video._Panel.__init__ = spy
    try:
        next(iter(video.iter_frames(log, fps=10, size=(800, 400))))
    finally:
        video._Panel.__init__ = real
    (panel, traj), = panels
    assert len(traj.names) == 10  # the payload's m, m·c (3), inertia (6)
    assert [t.get_text() for t in panel._labels] == ["|q̃| [rad]", "mass [kg]", "m·c [kg m]", "inertia [kg m²]"]
    assert len(panel._lines) == 1 + 2 * 10  # the error, and each estimate with its true value
    assert_labels_inside_their_axes(panel)


def assert_labels_inside_their_axes(panel):
    """Each axis's name lies inside that axis (so names cannot run into each other) and tick labels are not
    cut off at the panel's left edge."""
    renderer = panel._canvas.get_renderer()
    for ax, text in zip(panel._fig.axes, panel._labels, strict=True):
        box, frame = text.get_window_extent(renderer), ax.get_window_extent(renderer)
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1 + 0.5
        lo, hi = sorted(ax.get_ylim())
        ticks = [t.get_window_extent(renderer) for t in ax.get_yticklabels()
                 if t.get_text() and lo <= t.get_position()[1] <= hi]  # the ticks drawn (inside the limits)
        assert ticks and min(t.x0 for t in ticks) >= 0


def test_the_small_gif_panel_of_the_one_joint_arm_keeps_its_names_apart(tmp_path):
    """The bench's payload-swap GIF is 480 x 240 with five axes: the names used to overlap."""
    from adaptive_mj.report import video

    log = tmp_path / "arm.mcap"
    assert main(["run", "arm_payload_swap", "-o", str(log), "--set", "simulation.duration=0.2",
                 "--set", "events=[]", "--set", "success.tail_rms=inf"]) == 0
    panels = []
    real = video._Panel.__init__

    def spy(self, traj, rows, **kw):
        real(self, traj, rows, **kw)
        panels.append(self)

    video._Panel.__init__ = spy
    try:
        next(iter(video.iter_frames(log, fps=15, size=(480, 240))))
    finally:
        video._Panel.__init__ = real
    (panel,) = panels
    assert [t.get_text() for t in panel._labels] == ["ỹ [rad]", "J [kg m²]", "b [N m s/rad]", "g_sin [N m]",
                                                     "g_cos [N m]"]
    assert_labels_inside_their_axes(panel)


def test_the_chattering_panel_shows_where_u_chatters():
    """Section 4's bottom panel: the 0.5 s where u's high-frequency part moves most, not the run's last 0.5 s."""
    from adaptive_mj.study import analysis
    from adaptive_mj.trajectory import Trajectory

    dt = 1e-3
    t = np.arange(0.0, 3.0, dt)
    u = np.cos(t)
    burst = (t >= 1.2) & (t < 1.7)
    u[burst] += 0.5 * np.sign(np.sin(2 * np.pi * 200 * t[burst]))  # a 200 Hz switching stretch
    n = len(t)
    traj = Trajectory(t=t, x=np.zeros((n, 2)), u=u, s=np.zeros(n), ref=np.zeros((n, 3)), theta_hat=np.zeros((n, 0)),
                      theta=np.zeros((n, 0)), V=np.zeros(n), names=(), meta={"dt": dt})
    ch = analysis.chattering(traj)
    assert len(ch["window_t"]) == 500 and 1.15 <= ch["window_t"][0] <= 1.25
    quiet = analysis.chattering(dataclasses.replace(traj, u=np.cos(t)))
    assert quiet["window_t"][-1] == t[-1]  # nothing chatters: the last 0.5 s, as before


def test_a_studys_decimated_rows_end_on_the_runs_final_row():
    """The bench reads "final" values from a run's rows at the logging rate: those rows end on the full-rate
    run's last row, so they are the summary's final values (docs/METRICS.md), not those up to 9 ms before."""
    from adaptive_mj.study.job import RunSpec, run_job

    result = run_job(RunSpec(REPO / "scenarios" / "heave_tracking.toml", ("simulation.duration=0.555",)))
    traj, final = result.trajectory, result.summary["final"]
    assert traj.meta["log_every"] == 10 and len(traj.t) == 57  # rows 0, 10, ..., 550, and 554
    assert traj.t[-1] == pytest.approx(0.554) and np.all(np.diff(traj.t) > 0)
    assert [float(v) for v in traj.theta_hat[-1]] == [final["theta_hat"][n] for n in traj.names]

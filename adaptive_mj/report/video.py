"""Video of a logged run, rendered headless from the log alone.

The log carries the exact MJCF that was compiled (docs/LOG_FORMAT.md), so a
run can be watched without the repo that made it: the model is compiled from
the log, posed at every frame from the logged state (y, y_dot: /row.state, /state before format 8), and
drawn by `mujoco.Renderer` beside a panel with the tracking error ỹ = y_d - y
and each estimate θ̂_i against its true value θ_i, up to the current time.
A translucent green copy of the moving bodies shows the reference pose y_d.

    render_log("logs/run.mcap", "logs/run.mp4")                 # whole run, real time
    render_log(log, "swap.gif", fps=15, size=(480, 240), t_range=(18.0, 24.0))

Rendering needs no display and no GPU: MUJOCO_GL=egl (the default set here,
Mesa's software rasteriser on a machine without a GPU) or MUJOCO_GL=osmesa
(needs the Debian package libosmesa6). MP4 is encoded by the ffmpeg binary
that the imageio-ffmpeg wheel bundles; GIF by Pillow.
"""
from __future__ import annotations

import contextlib
import importlib
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Generator, Iterator, Sequence

import numpy as np

from adaptive_mj.errors import AdaptiveMJError, LogFormatError
from adaptive_mj.trajectory import Trajectory

# Before mujoco is imported: mujoco picks its OpenGL backend at import time.
# If something imported mujoco earlier without MUJOCO_GL, _headless_gl() below
# still gives the renderer a context of this backend.
os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402 (after MUJOCO_GL is set, see above)

from adaptive_mj.log.replay import LoggedRun, read_log  # noqa: E402 (after MUJOCO_GL too, should it import mujoco)
from adaptive_mj.plants.mujoco_plant import spec_from_text  # noqa: E402 (after MUJOCO_GL too: it imports mujoco)

#: Frames per second [1/s] when none is given (frames of simulation time, played in real time).
DEFAULT_FPS = 30.0
#: Whole frame (width, height) [pixels]: the MuJoCo scene on the left half,
#: the panel on the right half.
DEFAULT_SIZE = (800, 400)
FORMATS = (".mp4", ".gif")

_MAX_SIDE = 4096            # [pixels]
_GHOST_RGBA = (0.1, 0.85, 0.3, 0.3)     # the reference pose: translucent green (the body shows through it)
#: Panel line colours (RGB in 0..1): tracking error, estimate, true value.
PANEL_COLORS = {"error": (0.84, 0.15, 0.16), "estimate": (0.12, 0.47, 0.71), "true": (0.0, 0.0, 0.0)}
_GHOST_SCALE = 1.08         # grown: a translucent green shell that stays visible around the body when tracking is exact
_SHADOW_SIZE = 1024         # [texels]
_SKY_RGB = ([0.62, 0.74, 0.86], [0.16, 0.2, 0.28])   # backdrop gradient, top and bottom
_EVENT_SHOWN_S = 3.0        # how long an event's label stays in the panel [s]
_HEADLESS_MODULES = {"egl": "mujoco.egl", "osmesa": "mujoco.osmesa"}


@dataclass(frozen=True)
class Video:
    """A written video: frames at fps [1/s], size (width, height) [pixels],
    span (t0, t1) of simulation time shown [s], wall time spent [s]."""

    path: Path
    frames: int
    fps: float
    size: tuple[int, int]
    span: tuple[float, float]
    wall_s: float

    @property
    def render_rate(self) -> float:
        """Frames rendered and encoded per wall-clock second."""
        return self.frames / self.wall_s if self.wall_s > 0 else math.inf


def parse_size(size: tuple[int, int] | str | None) -> tuple[int, int]:
    """(width, height) from a tuple or a "WxH" string (None: DEFAULT_SIZE).
    Both must be even (H.264 in yuv420p needs it) and in 64..4096."""
    if size is None:
        return DEFAULT_SIZE
    if isinstance(size, str):
        parts = size.lower().split("x")
        try:
            w, h = (int(p) for p in parts)
        except ValueError:
            raise AdaptiveMJError(f"video size must be WxH in pixels, e.g. 800x400, got {size!r}") from None
    else:
        w, h = (int(v) for v in size)
    if not (64 <= w <= _MAX_SIDE and 64 <= h <= _MAX_SIDE and w % 2 == 0 and h % 2 == 0):
        raise AdaptiveMJError(f"video size must be even numbers of pixels from 64 to {_MAX_SIDE}, "
                              f"got {w}x{h}")
    return w, h


def scene_width(size: tuple[int, int]) -> int:
    """Width [pixels] of the MuJoCo scene, the left part of a frame of this size."""
    return size[0] // 2


def frame_rows(t: np.ndarray, fps: float, t_range: tuple[float, float] | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """(frame times (F,) [s], row index (F,) shown in each frame).

    Frames are 1/fps apart in simulation time (real time), from t_range[0]
    (default: the first row) to t_range[1] (default: the last row); each shows
    the latest logged row at or before its time."""
    if len(t) == 0:
        raise LogFormatError("the log has no rows to render")
    if not (math.isfinite(fps) and fps > 0):
        raise AdaptiveMJError(f"video fps must be a number > 0, got {fps!r}")
    t0, t1 = (float(t[0]), float(t[-1])) if t_range is None else (float(t_range[0]), float(t_range[1]))
    t0, t1 = max(t0, float(t[0])), min(t1, float(t[-1]))
    if not t1 >= t0:
        raise AdaptiveMJError(f"video time range {t_range} does not overlap the run "
                              f"({t[0]:.3f} to {t[-1]:.3f} s)")
    n = int(math.floor((t1 - t0) * fps + 1e-9)) + 1
    times = t0 + np.arange(n) / fps
    rows = np.searchsorted(t, times + 1e-9, side="right") - 1
    return times, np.clip(rows, 0, len(t) - 1)


# -- the MuJoCo scene ---------------------------------------------------------------------------

def _model(logged: LoggedRun, where: str) -> mujoco.MjModel:
    """The log's model: model_source with its assets (what was compiled), else model.xml,
    with a gradient backdrop added when it has no skybox."""
    xml, assets = logged.model_source, dict(logged.model_assets)
    if xml is None:
        xml, assets = logged.model_xml, {}
    if xml is None:
        raise LogFormatError(f"{where}: the log holds no MuJoCo model (scenario "
                             f"{logged.header.get('scenario_name', '?')!r} ran without one), "
                             f"so there is nothing to render; --video needs a run of a MuJoCo plant")
    try:
        spec = spec_from_text(xml, assets)
        if not any(tex.type == mujoco.mjtTexture.mjTEXTURE_SKYBOX for tex in spec.textures):
            # A backdrop instead of black; it only changes how the model looks.
            spec.add_texture(name="adaptive_mj_video_sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
                             builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT, rgb1=_SKY_RGB[0],
                             rgb2=_SKY_RGB[1], width=256, height=1536)
        model = spec.compile()
    except ValueError as exc:
        raise LogFormatError(f"{where}: the log's model does not compile: {str(exc).strip()}") from None
    joints = logged.trajectory.joint_names
    if logged.trajectory.control_names or logged.header.get("state_names"):
        raise LogFormatError(f"{where}: replay --video draws 1-DOF plants and arms; a run of named state rows (a "
                             "quadrotor) has no video yet: use --plot, or open the log in Foxglove")
    if joints and model.nv == len(joints):
        return model  # a manipulator run: the whole arm, q (m,) per row
    if model.njnt != 1 or model.nv != 1:
        raise LogFormatError(f"{where}: the log's model has {model.njnt} joints and nv={model.nv}, "
                             f"expected the single joint of a 1-DOF plant")
    return model


def _qpos_addresses(model: mujoco.MjModel) -> np.ndarray:
    """(nv,) qpos address of each dof's joint (hinge/slide: one each)."""
    return np.array([model.jnt_qposadr[model.dof_jntid[j]] for j in range(model.nv)])


def _free_camera(model: mujoco.MjModel, q_values: np.ndarray, aspect: float) -> mujoco.MjvCamera:
    """A free camera that keeps every moving geom in view over the joint positions q_values.

    It looks along a hinge's axis (the motion is then in the image plane) or
    horizontally across a slide joint's axis, tilted 12 degrees down."""
    data = mujoco.MjData(model)
    moving = np.flatnonzero(model.body_weldid[model.geom_bodyid] != 0)
    multi = model.nv > 1
    qadr = _qpos_addresses(model) if multi else int(model.jnt_qposadr[0])
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    axis = np.array([0.0, 1.0, 0.0])
    samples = (q_values[np.linspace(0, len(q_values) - 1, 41).astype(int)] if multi
               else np.unique(np.quantile(q_values, np.linspace(0.0, 1.0, 41))))
    for q in samples:
        data.qpos[qadr] = q
        mujoco.mj_kinematics(model, data)
        axis = data.xaxis[0].copy()
        r = model.geom_rbound[moving, None]
        lo = np.minimum(lo, (data.geom_xpos[moving] - r).min(axis=0, initial=np.inf))
        hi = np.maximum(hi, (data.geom_xpos[moving] + r).max(axis=0, initial=-np.inf))
    if not np.all(np.isfinite(lo)):     # no moving geom: frame the whole model
        lo = model.stat.center - model.stat.extent
        hi = model.stat.center + model.stat.extent
    if multi:  # an arm: a three-quarter view
        forward = np.array([1.0, 1.0, 0.6])
    elif model.jnt_type[0] == mujoco.mjtJoint.mjJNT_HINGE:
        forward = axis
    else:                                # across the slide axis, horizontally if possible
        forward = np.cross(axis, [0.0, 0.0, 1.0])
        if np.linalg.norm(forward) < 1e-6:
            forward = np.array([0.0, 1.0, 0.0])
    forward = forward / np.linalg.norm(forward)
    if forward[1] < 0 or (forward[1] == 0 and forward[0] < 0):
        forward = -forward               # like MuJoCo's default view, from -y towards +y
    azimuth = math.degrees(math.atan2(forward[1], forward[0]))
    elevation = float(np.clip(math.degrees(math.asin(np.clip(forward[2], -1, 1))) - 12.0, -80.0, 80.0))
    az, el = math.radians(azimuth), math.radians(elevation)
    fwd = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    center = 0.5 * (lo + hi)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]) - center
    half_w, half_h, half_d = (np.abs(corners @ v).max() for v in (right, up, fwd))
    tan_v = math.tan(math.radians(model.vis.global_.fovy) / 2.0)
    distance = 1.15 * max(half_h / tan_v, half_w / (tan_v * aspect), 1e-3) + half_d

    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = center
    camera.distance = distance
    camera.azimuth = azimuth
    camera.elevation = elevation
    return camera


def visible_groups(model: mujoco.MjModel, groups: Sequence[int] | None = None) -> np.ndarray:
    """(6,) uint8 mjvOption.geomgroup for the video: `groups` if given, else MuJoCo's default groups (0, 1, 2)
    and the groups of every body whose geoms all lie outside them (menagerie arms keep their collision
    geoms in group 3 and have no visual ones: MuJoCo's default would show only the payload)."""
    shown = np.zeros(mujoco.mjNGROUP, dtype=np.uint8)
    if groups is not None:
        for g in groups:
            if not 0 <= int(g) < mujoco.mjNGROUP:
                raise AdaptiveMJError(f"video geom group {g}: expected 0..{mujoco.mjNGROUP - 1}")
            shown[int(g)] = 1
        return shown
    shown[:] = mujoco.MjvOption().geomgroup
    by_body: dict[int, set[int]] = {}
    for body, group in zip(model.geom_bodyid, model.geom_group, strict=True):
        by_body.setdefault(int(body), set()).add(int(group))
    for body, body_groups in by_body.items():
        if body and not any(shown[g] for g in body_groups if 0 <= g < mujoco.mjNGROUP):
            for g in body_groups:
                if 0 <= g < mujoco.mjNGROUP:
                    shown[g] = 1
    return shown


def parse_groups(text: str | None) -> list[int] | None:
    """--video-groups "0,3" -> [0, 3] (None: chosen from the model, visible_groups)."""
    if text is None:
        return None
    try:
        groups = [int(g) for g in text.split(",") if g.strip()]
    except ValueError:
        groups = []
    if not groups or not all(0 <= g < mujoco.mjNGROUP for g in groups):
        raise AdaptiveMJError(f"--video-groups {text!r}: expected geom groups 0..{mujoco.mjNGROUP - 1} separated by "
                              "commas, e.g. 0,3")
    return groups


@contextlib.contextmanager
def _headless_gl() -> Iterator[None]:
    """Inside the block, mujoco.Renderer gets an OpenGL context of the MUJOCO_GL backend.

    mujoco chooses its context class when it is imported. A process that
    imported mujoco before MUJOCO_GL was set (a test session, a bench worker)
    got GLFW, which needs a display; for egl and osmesa the matching class is
    swapped in while the renderer is made, and the choice restored after.
    """
    from mujoco.rendering.classic import gl_context

    backend = os.environ.get("MUJOCO_GL", "").strip().lower()
    wanted = _HEADLESS_MODULES.get(backend)
    current = getattr(gl_context, "GLContext", None)
    if wanted is None or (current is not None and current.__module__ == wanted):
        yield
        return
    gl_context.GLContext = importlib.import_module(wanted).GLContext
    try:
        yield
    finally:
        gl_context.GLContext = current


def _renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), width)
    model.vis.global_.offheight = max(int(model.vis.global_.offheight), height)
    # MuJoCo's default 4096² shadow map makes software rendering about 6x slower.
    model.vis.quality.shadowsize = min(int(model.vis.quality.shadowsize), _SHADOW_SIZE)
    backend = os.environ.get("MUJOCO_GL", "")
    try:
        with _headless_gl():
            return mujoco.Renderer(model, height=height, width=width)
    except Exception as exc:  # EGL/OSMesa/GLFW raise several types
        raise AdaptiveMJError(
            f"cannot open a headless OpenGL context with MUJOCO_GL={backend!r} "
            f"({type(exc).__name__}: {str(exc).strip() or 'no detail'}); try MUJOCO_GL=egl, or "
            f"MUJOCO_GL=osmesa with the Debian package libosmesa6") from None


# -- the panel ----------------------------------------------------------------------------------

#: An arm's parameters by unit: what the panel's axis of that unit is called.
_QUANTITY = {"kg": "mass", "kg m": "m·c", "kg m²": "inertia", "N m s/rad": "damping", "N m": "Coulomb"}


def panel_groups(names: tuple[str, ...], plant_kind: str | None) -> list[tuple[str, list[int]]]:
    """The panel's estimate axes: (y label, indices into names). A 1-DOF plant: one axis per parameter,
    "J [kg m²]". An arm (plant_kind "manipulator"): one axis per quantity, all its parameters in it (a
    payload's 10: "mass [kg]", "m·c [kg m]", "inertia [kg m²]"), so every estimate is shown."""
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    kind = units.lookup(plant_kind)
    if kind is None or not kind.group_params_by_unit:
        return [(f"{n} [{units.param_unit(plant_kind, n)}]" if units.param_unit(plant_kind, n) else n, [i])
                for i, n in enumerate(names)]
    by_unit: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        by_unit.setdefault(units.param_unit(plant_kind, n), []).append(i)
    return [(f"{_QUANTITY.get(u, 'other')} [{u}]" if u else "other", members) for u, members in by_unit.items()]


class _Panel:
    """ỹ and each estimate against its true value, drawn up to the current row.

    The axes are drawn once; each frame restores them and draws only the
    growing lines and the time text (matplotlib blitting on the Agg canvas)."""

    def __init__(self, traj: Trajectory, rows: np.ndarray, *, width: int, height: int,
                 unit: str, title: str, plant_kind: str | None = None):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        dpi = 100
        self._fig = fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi)
        self._canvas = FigureCanvasAgg(fig)
        names = traj.names
        groups = panel_groups(names, plant_kind)
        font = 7.0 * float(np.clip(min(width, height) / 400.0, 0.7, 1.6))   # [pt]
        px = font * dpi / 72.0                                                # one line [pixels]
        axes = fig.subplots(1 + len(groups), 1, sharex=True, squeeze=False)[:, 0]
        # room on the left for the tick labels (the axes' names are inside them)
        fig.subplots_adjust(left=min(0.4, 5.0 * px / width), right=1 - 1.2 * px / width,
                            top=1 - 3.4 * px / height, bottom=3.0 * px / height, hspace=0.4)
        fig.text(0.5, 1 - 0.4 * px / height, title, ha="center", va="top", fontsize=font + 1,
                 weight="bold")
        self._time_text = fig.text(0.5, 1 - 1.9 * px / height, "", ha="center", va="top",
                                   fontsize=font, animated=True)

        i0, i1 = int(rows[0]), int(rows[-1])
        stride = max(1, math.ceil((i1 - i0 + 1) / (2 * width)))   # about 2 points per pixel
        keep = np.arange(i0, i1 + 1, stride)
        if keep[-1] != i1:
            keep = np.append(keep, i1)
        self._t = traj.t[keep]
        error = np.linalg.norm(traj.joint_errors, axis=1) if traj.joint_names else traj.y_tilde
        series = [(axes[0], error[keep], dict(color=PANEL_COLORS["error"], lw=1.0))]
        for g, (_, members) in enumerate(groups):
            for j, i in enumerate(members):  # one colour per parameter of a group; one group: the fixed pair
                est = PANEL_COLORS["estimate"] if len(members) == 1 else f"C{j % 10}"
                true = PANEL_COLORS["true"] if len(members) == 1 else est
                series.append((axes[1 + g], traj.theta[keep, i], dict(color=true, lw=0.9, ls="--")))
                series.append((axes[1 + g], traj.theta_hat[keep, i], dict(color=est, lw=1.1)))
        self._lines = []
        for ax, y, style in series:
            (line,) = ax.plot([], [], animated=True, **style)
            self._lines.append((line, y))
        for ax in axes:
            ys = np.concatenate([y for a, y, _ in series if a is ax])
            ys = ys[np.isfinite(ys)]
            lo, hi = (float(ys.min()), float(ys.max())) if ys.size else (-1.0, 1.0)
            # An estimate that sits on its true value gets a span of 10% of it, not 1e-10.
            floor = 0.05 * max(abs(lo), abs(hi)) if ax is not axes[0] else 0.0
            half = max(0.54 * (hi - lo), floor, 1e-12)
            mid = 0.5 * (lo + hi)
            ax.set_ylim(mid - half, mid + half)
            ax.set_xlim(traj.t[i0], traj.t[i1] if i1 > i0 else traj.t[i0] + 1e-3)
            ax.ticklabel_format(axis="y", useOffset=False)
            ax.locator_params(axis="y", nbins=3)
            ax.tick_params(labelsize=font - 1, length=2, pad=1)
            ax.yaxis.get_offset_text().set_fontsize(font - 1)
            ax.grid(alpha=0.3, lw=0.5)
        # each axis names its quantity inside its top-left corner, horizontally: a rotated y label longer than a
        # short axis runs into its neighbours' (5 axes in a 240-pixel GIF)
        self._labels = [self._label(axes[0], f"|q̃| [{unit}]" if traj.joint_names else f"ỹ [{unit}]", font)]
        for g, (label, _) in enumerate(groups):
            self._labels.append(self._label(axes[1 + g], label, font))
        if names:
            axes[1].plot([], [], color=PANEL_COLORS["estimate"], lw=1.1, label="estimate")
            axes[1].plot([], [], color=PANEL_COLORS["true"], lw=0.9, ls="--", label="true")
            axes[1].legend(fontsize=font - 1, loc="upper right", handlelength=1.5, frameon=False,
                           ncol=2, borderpad=0.1)
        axes[-1].set_xlabel("time t [s]", fontsize=font, labelpad=1)
        self._events = [(te, label) for te, label in traj.meta.get("events", [])
                        if traj.t[i0] <= te <= traj.t[i1]]
        for te, _ in self._events:
            for ax in axes:
                ax.axvline(te, color="0.5", lw=0.8, ls=":")
        self._canvas.draw()
        self._background = self._canvas.copy_from_bbox(fig.bbox)

    @staticmethod
    def _label(ax, text: str, font: float):
        return ax.text(0.006, 0.96, text, transform=ax.transAxes, ha="left", va="top", fontsize=font - 0.5,
                       bbox=dict(facecolor="white", edgecolor="none", alpha=0.75, pad=0.6), zorder=5)

    def image(self, t_now: float) -> np.ndarray:
        """(height, width, 3) uint8: the panel with the data up to t_now [s]."""
        canvas = self._canvas
        canvas.restore_region(self._background)
        k = int(np.searchsorted(self._t, t_now + 1e-9, side="right"))
        for line, y in self._lines:
            line.set_data(self._t[:k], y[:k])
            line.axes.draw_artist(line)
        text = f"t = {t_now:6.2f} s"
        recent = [label for te, label in self._events if 0.0 <= t_now - te <= _EVENT_SHOWN_S]
        if recent:
            text += f"   event: {recent[-1]}"
        self._time_text.set_text(text)
        self._fig.draw_artist(self._time_text)
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()


class _Label:
    """A line of text drawn into the top-left corner of the scene image."""

    def __init__(self, text: str, *, height: int):
        from PIL import ImageFont

        self._text = text
        self._font = ImageFont.load_default(size=max(9, round(height / 30)))

    def __call__(self, image: np.ndarray) -> np.ndarray:
        from PIL import Image, ImageDraw

        picture = Image.fromarray(image)
        ImageDraw.Draw(picture).text((6, 4), self._text, fill=(255, 255, 255), font=self._font,
                                     stroke_width=1, stroke_fill=(40, 40, 40))
        return np.asarray(picture)


# -- frames and files ---------------------------------------------------------------------------

def _logged(log: str | os.PathLike | LoggedRun) -> tuple[LoggedRun, str]:
    if isinstance(log, LoggedRun):
        return log, str(log.header.get("scenario_name", "log"))
    if not Path(log).is_file():
        raise LogFormatError(f"{log}: no such log file")
    return read_log(log), os.fspath(log)


def iter_frames(log: str | os.PathLike | LoggedRun, *, fps: float = DEFAULT_FPS,
                size: tuple[int, int] | str | None = None,
                t_range: tuple[float, float] | None = None,
                groups: Sequence[int] | None = None) -> Generator[np.ndarray, None, None]:
    """Yield the video's frames, (height, width, 3) uint8 RGB, one per 1/fps of simulation time.

    log: a log path or a LoggedRun. size: (width, height) or "WxH"; the MuJoCo
    scene fills the left scene_width(size) pixels, the panel the rest.
    t_range: (t0, t1) [s] of simulation time to show (default: the whole run).
    Raises LogFormatError (when iteration starts) for a log without a MuJoCo
    model or without rows. Closing the iterator closes the renderer.
    groups: the geom groups drawn (default: visible_groups of the model).
    """
    logged, where = _logged(log)
    return _frames(logged, where, fps=fps, size=parse_size(size), t_range=t_range, groups=groups)


def _frames(logged: LoggedRun, where: str, *, fps: float, size: tuple[int, int],
            t_range: tuple[float, float] | None,
            groups: Sequence[int] | None = None) -> Generator[np.ndarray, None, None]:
    width, height = size
    model = _model(logged, where)
    traj = logged.trajectory
    if len(traj) == 0:
        raise LogFormatError(f"{where}: the log has no rows to render")
    times, rows = frame_rows(traj.t, fps, t_range)
    scene_w = scene_width((width, height))
    unit = "rad" if model.jnt_type[0] == mujoco.mjtJoint.mjJNT_HINGE else "m"
    title = str(logged.header.get("scenario_name", where))
    panel_traj = traj  # every estimate: an arm's in one axis per quantity (panel_groups)
    from adaptive_mj.plants import kinds as units  # the units each plant kind declares

    kind = units.kind_of(logged.scenario_text or "") or (
        "manipulator" if traj.joint_names else ("arm" if unit == "rad" else "heave"))
    panel = _Panel(panel_traj, rows, width=width - scene_w, height=height, unit=unit, title=title, plant_kind=kind)
    shown = traj.q[rows[0]:rows[-1] + 1]
    camera = _free_camera(model, np.concatenate([shown, traj.ref[rows[0]:rows[-1] + 1, 0]]),
                          aspect=scene_w / height)

    data, ghost = mujoco.MjData(model), mujoco.MjData(model)
    qadr: np.ndarray | int  # the joints' qpos and dof addresses: every joint of an arm, or the one joint
    dadr: np.ndarray | int
    if traj.joint_names:  # the whole arm; the reference pose as a ghost of the whole arm
        qadr, dadr = _qpos_addresses(model), np.arange(model.nv)
    else:
        qadr, dadr = int(model.jnt_qposadr[0]), int(model.jnt_dofadr[0])
    option, perturb = mujoco.MjvOption(), mujoco.MjvPerturb()
    option.geomgroup[:] = visible_groups(model, groups)
    label = _Label("green: reference pose q_d" if traj.joint_names else "green: reference y_d", height=height)
    renderer = _renderer(model, scene_w, height)
    try:
        for t_frame, i in zip(times, rows, strict=True):
            data.qpos[qadr] = traj.x[i, 0]
            data.qvel[dadr] = traj.x[i, 1] if traj.x.shape[1] > 1 else 0.0  # (m,) for an arm
            data.time = traj.t[i]
            mujoco.mj_forward(model, data)
            ghost.qpos[qadr] = traj.ref[i, 0]
            mujoco.mj_kinematics(model, ghost)
            renderer.update_scene(data, camera=camera, scene_option=option)
            scene = renderer.scene
            first = scene.ngeom
            mujoco.mjv_addGeoms(model, ghost, option, perturb, mujoco.mjtCatBit.mjCAT_DYNAMIC, scene)
            for g in range(first, scene.ngeom):
                scene.geoms[g].rgba[:] = _GHOST_RGBA
                scene.geoms[g].size[:] *= _GHOST_SCALE
            yield np.concatenate([label(renderer.render()), panel.image(float(t_frame))], axis=1)
    finally:
        renderer.close()


class _Mp4:
    def __init__(self, path: Path, fps: float):
        import imageio.v2 as imageio

        self._writer = imageio.get_writer(path, format="FFMPEG", mode="I", fps=fps, codec="libx264",
                                          pixelformat="yuv420p", quality=7, macro_block_size=2,
                                          ffmpeg_log_level="error")

    def append(self, frame: np.ndarray) -> None:
        self._writer.append_data(frame)

    def close(self) -> None:
        self._writer.close()


class _Gif:
    """One palette for all frames (no flicker): the panel's line colours, black and white,
    and the rest from the first frame. Frames are kept (1 byte per pixel) and written at close,
    with delays that alternate between whole centiseconds so the GIF plays in real time."""

    def __init__(self, path: Path, fps: float):
        self._path, self._fps = path, fps
        self._frames: list = []
        self._palette = None

    def _make_palette(self, image):
        from PIL import Image

        fixed = [tuple(round(255 * c) for c in rgb) for rgb in PANEL_COLORS.values()]
        fixed += [(0, 0, 0), (255, 255, 255)]
        rest = image.quantize(colors=256 - len(fixed), method=Image.Quantize.MEDIANCUT)
        palette = Image.new("P", (1, 1))
        palette.putpalette([v for rgb in fixed for v in rgb]
                           + rest.getpalette()[:3 * (256 - len(fixed))])
        return palette

    def append(self, frame: np.ndarray) -> None:
        from PIL import Image

        image = Image.fromarray(frame)
        if self._palette is None:
            self._palette = self._make_palette(image)
        self._frames.append(image.quantize(palette=self._palette, dither=Image.Dither.NONE))

    def close(self) -> None:
        if not self._frames:
            return
        ends = np.round(np.arange(1, len(self._frames) + 1) * 100.0 / self._fps)   # [cs]
        delays = (10 * np.diff(ends, prepend=0.0)).astype(int).tolist()               # [ms]
        self._frames[0].save(self._path, save_all=True, append_images=self._frames[1:],
                             duration=delays, loop=0)


def render_log(log: str | os.PathLike | LoggedRun, out: str | os.PathLike, *,
               fps: float | None = None, size: tuple[int, int] | str | None = None,
               t_range: tuple[float, float] | None = None, groups: Sequence[int] | None = None) -> Video:
    """Render a logged run to out (.mp4 or .gif); see iter_frames for the arguments.

    fps: frames per second of simulation time, played in real time (default
    DEFAULT_FPS = 30). The parent folder is created. A GIF keeps its frames in
    memory until it is written (width*height bytes each): use it for short clips.
    For a short GIF of the payload swap (the bench report), e.g.:
        render_log(log, "swap.gif", fps=15, size=(480, 240), t_range=(18.0, 24.0))
    """
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in FORMATS:
        raise AdaptiveMJError(f"{out}: a video file must end in .mp4 or .gif, got {out.suffix or 'no suffix'!r}")
    fps = DEFAULT_FPS if fps is None else float(fps)
    width, height = parse_size(size)
    logged, where = _logged(log)
    frames = _frames(logged, where, fps=fps, size=(width, height), t_range=t_range, groups=groups)
    t = logged.trajectory.t
    span = (float(t[0]), float(t[-1])) if len(t) else (0.0, 0.0)
    if len(t) and t_range is not None:
        span = (max(span[0], float(t_range[0])), min(span[1], float(t_range[1])))
    out.parent.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    count = 0
    writer = (_Mp4 if suffix == ".mp4" else _Gif)(out, fps)
    try:
        for frame in frames:
            writer.append(frame)
            count += 1
        writer.close()
    except BaseException:
        frames.close()
        with contextlib.suppress(Exception):
            writer.close()
        out.unlink(missing_ok=True)
        raise
    return Video(path=out, frames=count, fps=fps, size=(width, height), span=span,
                 wall_s=time.perf_counter() - start)

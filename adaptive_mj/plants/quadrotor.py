"""The quadrotor (models/quadrotor.xml): a free rigid body in MuJoCo's air, four rotor thrusts along its z axis,
an unknown payload (rigid, or on a cable) and the flight laws of adaptive_mj.laws.geometric and laws.l1.

How the loop sees it (the plant protocol, adaptive_mj.plants.protocol):
  axes        x, y, z: the output is the position p (3,) [m] in the world frame (z up)
  order 4     p is the flat output of a quadrotor: of relative degree 4 to the body moments (Mellinger & Kumar
              2011). The state x (4, 3) is the full rigid-body state in the form a flight law reads it:
              x[0] = p [m], x[1] = v = p' [m/s] (world), x[2] = φ [rad] the attitude as a rotation vector
              (R = exp(φ^), body to world), x[3] = Ω [rad/s] the body rate in the body frame (MuJoCo's free joint
              keeps its angular velocity in the local frame). Rows 2 and 3 are not p'' and p''' (state_names says
              which they are); the reference is [p_d, p_d', p_d'', p_d''', p_d''''] (4 + 1 rows).
  controls    the four rotor thrusts [N] (control_names: the actuators' names), limited to [0, T_max] each
  θ (13,)     m [kg], the vehicle's mass with its payload; J [kg m²] its inertia about their common centre of
              mass in the body frame (Jxx, Jyy, Jzz, Jxy, Jxz, Jyz; a cable payload counted hanging straight
              down); d [N] a constant external force in the world frame (dx, dy, dz; an external_force event's);
              τ [N m] a constant external torque (tx, ty, tz; world frame, the law's estimate is in the body
              frame: the same at level flight)
              Every number comes from the compiled model (`truth`), none is typed.

A crash ends the run with status "crashed" (Status.CRASHED; `termination`, asked after every physics step;
`crash_check`): the vehicle down to its ground clearance (the height at which it would rest level on the ground
with its payload) after it has been airborne (AIRBORNE_RISE above where it started), its centre below the ground
plane, or a tilt past plant.crash_tilt. The check reads the body's height and attitude only (no contact list), so
the compiled callback makes the same one. Its events (wind, a rotor's efficiency, an external force, a
payload released) are below.
"""
from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterator

import mujoco
import numpy as np

from adaptive_mj.data import MODELS
from adaptive_mj.errors import ModelError
from adaptive_mj.keys import Key
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants import BuiltPlant, ModelSource
from adaptive_mj.plants import events as ev
from adaptive_mj.plants import plant_keys, quadrotor_kernel
from adaptive_mj.plants.mujoco_kernel import MujocoKernel
from adaptive_mj.plants.airframe import Airframe, rotor_drag_into
from adaptive_mj.plants.kinds import Draw, PlantKind, ScoreTask, StressPlant, register
from adaptive_mj.plants.study_spec import LEAK_TIME, Stressor, StudyContext, box_table, surface_noise, theta_table
from adaptive_mj.plants.mujoco_plant import (BodyEdits, ModelClock, compiled_control, control_callback, new_warnings,
                                             release_data, run_data, scratch_data)
from adaptive_mj.trajectory import CRASH_REASON_PREFIX

MODEL_PATH = MODELS / "quadrotor.xml"
BODY = "quad"  # the flying body's name in the model
AXES = ("x", "y", "z")
STATE_NAMES = ("p", "v", "phi", "omega")
INERTIA_NAMES = ("Jxx", "Jyy", "Jzz", "Jxy", "Jxz", "Jyz")
PARAM_NAMES = ("m",) + INERTIA_NAMES + ("dx", "dy", "dz", "tx", "ty", "tz")
PARAM_UNITS = {"m": "kg", **{n: "kg m²" for n in INERTIA_NAMES}, "dx": "N", "dy": "N", "dz": "N", "tx": "N m",
               "ty": "N m", "tz": "N m"}
CRASH_TILT_DEG = 80.0  # plant.crash_tilt's default [deg]
TAIL_SATURATION = 0.2  # the largest fraction of a run's tail with a rotor at a limit (success.tail_saturation)
OSCILLATION = 1.0  # [rad/s] the largest sustained oscillation of the body rate over the tail (success.oscillation)
AIRBORNE_RISE = 0.05  # [m] above its start the vehicle counts as airborne: down to the ground after is a crash


_DRAG: list = []


def drag_kernel() -> Callable:
    """airframe.rotor_drag_into compiled by numba (cached on disk), or the plain function where numba is missing:
    the same arithmetic as the native callback's (plants.quadrotor_kernel)."""
    if not _DRAG:
        try:
            import functools

            import numba

            from adaptive_mj.numba_util import jit_tree

            _DRAG.append(jit_tree(rotor_drag_into, functools.partial(numba.njit, cache=True), tag="_drag"))
        except ImportError:  # pragma: no cover - numba is a dependency; a bare checkout still runs, slowly
            _DRAG.append(rotor_drag_into)
    return _DRAG[0]


def rotvec_into(qw, qx, qy, qz, out):
    """out (3,) = φ = angle · axis of the unit quaternion (w, x, y, z), the angle taken the shorter way round
    (in [−π, π], as MuJoCo's mju_quat2Vel): plain scalar code, so the Python step and the compiled callback
    measure the same bits."""
    n = math.sqrt(qx * qx + qy * qy + qz * qz)
    if n < 1e-15:
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0
        return
    angle = 2.0 * math.atan2(n, qw)
    if angle > math.pi:
        angle -= 2.0 * math.pi
    k = angle / n
    out[0] = qx * k
    out[1] = qy * k
    out[2] = qz * k


def measure_into(qpos, qvel, qadr, dadr, x):
    """x (4, 3) = [p; v; φ; Ω] of the free joint at qpos[qadr:qadr + 7], qvel[dadr:dadr + 6] (plain code: the
    compiled callback runs it too)."""
    for i in range(3):
        x[0, i] = qpos[qadr + i]
        x[1, i] = qvel[dadr + i]
        x[3, i] = qvel[dadr + 3 + i]
    rotvec_into(qpos[qadr + 3], qpos[qadr + 4], qpos[qadr + 5], qpos[qadr + 6], x[2])


def rotation_vector(quat: np.ndarray) -> np.ndarray:
    """(3,) φ of the unit quaternion (w, x, y, z) [rad] (rotvec_into)."""
    out = np.zeros(3)
    rotvec_into(float(quat[0]), float(quat[1]), float(quat[2]), float(quat[3]), out)
    return out


def quaternion(phi: np.ndarray) -> np.ndarray:
    """(4,) the unit quaternion (w, x, y, z) of rotation vector φ (3,) [rad]."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    q = np.array([1.0, 0.0, 0.0, 0.0])
    if angle > 0:
        mujoco.mju_axisAngle2Quat(q, phi / angle, angle)
    return q


NO_CRASH, CRASH_TILT_CODE, CRASH_BELOW, CRASH_GROUND = 0, 1, 2, 3


def crash_check(z, qw, qx, qy, qz, airborne, z0, clearance, cos_tilt):
    """(code, value, airborne) after a physics step, from the body's height z [m] and attitude quaternion: a tilt
    past the bound (cos of the tilt = R[2, 2] = w² − x² − y² + z² as mju_quat2Mat writes it, below cos_tilt; value:
    that cosine), the centre below the ground plane (value: z), or, once airborne, the vehicle down to its ground
    clearance (value: z); NO_CRASH otherwise. airborne: risen AIRBORNE_RISE above its start. Plain scalar code: the
    Python step and the compiled callback both run it."""
    r22 = qw * qw - qx * qx - qy * qy + qz * qz
    if r22 < cos_tilt:
        return CRASH_TILT_CODE, r22, airborne
    if z < 0.0:
        return CRASH_BELOW, z, airborne
    if airborne and z <= clearance:
        return CRASH_GROUND, z, airborne
    return NO_CRASH, 0.0, airborne or z > z0 + AIRBORNE_RISE


def crash_text(code: int, value: float, t: float, crash_tilt: float, speed: float) -> str:
    """The reason a crash gives (crash_check's code and value at time t [s]; speed [m/s] the body's): "crashed at
    t = … s: …" (trajectory.CRASH_REASON_PREFIX, which replay reads older logs' crashes by)."""
    when = f"{CRASH_REASON_PREFIX} t = {t:.4g} s"
    if code == CRASH_TILT_CODE:
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, value))))
        return f"{when}: tilted {tilt:.1f} deg, past plant.crash_tilt = {crash_tilt:g} deg"
    if code == CRASH_BELOW:
        return f"{when}: the body's centre is {-value:.3g} m below the ground plane"
    return f"{when}: hit the ground at {speed:.3g} m/s (its centre {value:.3g} m up)"


def ground_clearance(model: mujoco.MjModel, root: int) -> float:
    """[m] how high the body's origin sits when the vehicle rests level on the ground plane (z = 0): the deepest
    point below it of the colliding geoms of its subtree at the model's qpos0 (a cable payload hanging straight
    down). Spheres, capsules, ellipsoids, boxes and cylinders by their extent along −z."""
    data = scratch_data(model)
    mujoco.mj_resetData(model, data)
    mujoco.mj_kinematics(model, data)
    bodies = set(subtree_bodies(model, root))
    z0, deepest = float(data.xpos[root][2]), 0.0
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in bodies or not (model.geom_contype[g] or model.geom_conaffinity[g]):
            continue
        Rz = data.geom_xmat[g].reshape(3, 3)[2]  # the world z row: each local axis' z component
        size, kind = model.geom_size[g], model.geom_type[g]
        T = mujoco.mjtGeom
        if kind == T.mjGEOM_SPHERE:
            ext = size[0]
        elif kind == T.mjGEOM_CAPSULE:
            ext = size[0] + abs(Rz[2]) * size[1]
        elif kind == T.mjGEOM_ELLIPSOID:
            ext = math.sqrt(sum((Rz[i] * size[i]) ** 2 for i in range(3)))
        elif kind == T.mjGEOM_BOX:
            ext = sum(abs(Rz[i]) * size[i] for i in range(3))
        elif kind == T.mjGEOM_CYLINDER:
            ext = abs(Rz[2]) * size[1] + size[0] * math.sqrt(max(0.0, 1.0 - Rz[2] ** 2))
        else:
            ext = float(model.geom_rbound[g])
        deepest = max(deepest, z0 - (float(data.geom_xpos[g][2]) - ext))
    return deepest


def subtree_bodies(model: mujoco.MjModel, root: int) -> list[int]:
    """The ids of `root` and every body below it."""
    out = [root]
    for b in range(root + 1, model.nbody):
        parent = b
        while parent > root:
            parent = int(model.body_parentid[parent])
        if parent == root:
            out.append(b)
    return out


def rigid_inertia(model: mujoco.MjModel, root: int) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], J (3, 3) [kg m²], c (3,) [m]): the subtree of `root` as one rigid body at the model's qpos0
    (a cable payload hanging straight down), its inertia about its centre of mass in root's frame and that
    centre's offset c from root's origin in root's frame. Parallel-axis sums of MuJoCo's own body inertias at
    their principal frames (mj_kinematics on a scratch MjData)."""
    data = scratch_data(model)
    mujoco.mj_resetData(model, data)
    mujoco.mj_kinematics(model, data)
    bodies = subtree_bodies(model, root)
    mass = float(sum(model.body_mass[b] for b in bodies))
    if not mass > 0:
        raise ModelError(f"body {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, root)!r} has no mass")
    com = sum(model.body_mass[b] * data.xipos[b] for b in bodies) / mass
    J = np.zeros((3, 3))
    for b in bodies:
        Ri = data.ximat[b].reshape(3, 3)
        r = data.xipos[b] - com
        J += Ri @ np.diag(model.body_inertia[b]) @ Ri.T + model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    Rb = data.xmat[root].reshape(3, 3)
    return mass, Rb.T @ J @ Rb, Rb.T @ (com - data.xpos[root])


@dataclass(frozen=True)
class QuadrotorSpec:
    """plant.* keys of kind "quadrotor" beyond the shared ones: crash_tilt [deg], the tilt past which the run ends
    crashed; rotor_time_constant τ [s] of a first-order lag on every rotor's thrust that the laws do not model
    (None: the model's own, RotorPy's τ_m = 0.005 s on the bundled quadrotor; 0: no lag); wind (3,) [m/s] the air's
    velocity from t = 0 (None: the model's)."""

    crash_tilt: float = CRASH_TILT_DEG
    rotor_time_constant: float | None = None
    wind: tuple[float, float, float] | None = None


class QuadrotorPlant(ModelClock, BodyEdits):
    """The MuJoCo quadrotor (see the module docstring): a Plant (adaptive_mj.plants.protocol) with the position
    axes as its joint axis, four named controls and a crash check."""

    order = 4
    names = PARAM_NAMES
    joint_names = AXES
    joint_shape = (3,)
    state_names = STATE_NAMES
    joint_limits: np.ndarray | None = None
    first_contact: tuple[float, str] | None = None
    native_owner: object | None = None
    compiled_loop: str | None = "adaptive_mj.sim.native_mujoco"  # protocol.Plant.compiled_loop
    mujoco_kernel: ClassVar[MujocoKernel] = quadrotor_kernel.KERNEL  # its kernel spec (plants/quadrotor_kernel.py)
    disturbance: Callable[[float], float] | None = None  # the protocol's; a quadrotor's are events

    def __init__(self, model: mujoco.MjModel, *, where: str = "quadrotor model", crash_tilt: float = CRASH_TILT_DEG):
        self.model, self.where = model, where
        try:
            self.airframe = Airframe.of_model(model, BODY)
        except ValueError as exc:
            raise ModelError(f"{where}: {exc}") from None
        self.data = run_data(model)
        self.body = self.airframe.body
        self.subtree = frozenset(subtree_bodies(model, self.body))
        acts = self.airframe.actuators
        self.control_names = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, int(a)) or f"rotor{i + 1}"
                                   for i, a in enumerate(acts))
        self.ctrl_range = (np.array(model.actuator_ctrlrange[acts, 0], dtype=float),
                           np.array(model.actuator_ctrlrange[acts, 1], dtype=float))
        self.crash_tilt = float(crash_tilt)
        self.force_offset = 0.0  # the protocol's scalar offset: unused (external_force is this plant's)
        self.external_force = np.zeros(3)  # [N] world frame, held over every step
        self.external_torque = np.zeros(3)  # [N m] world frame
        self._theta: np.ndarray | None = None
        self._crash: str | None = None
        self._airborne = False
        self._warnings0 = self.data.warning.number.copy()
        self._warning_total0 = int(self._warnings0.sum())
        self.clearance = ground_clearance(model, self.body)
        self.cos_tilt = math.cos(math.radians(self.crash_tilt))

    # --- the protocol's members --------------------------------------------------------
    def set_state(self, x0) -> None:
        """x0 (4, 3): p, v, φ, Ω (see the module docstring); the time restarts at 0."""
        x0 = np.asarray(x0, dtype=float).reshape(4, 3)
        m, d, af = self.model, self.data, self.airframe
        mujoco.mj_resetData(m, d)
        self._warnings0 = d.warning.number.copy()
        self._warning_total0 = int(self._warnings0.sum())
        d.qpos[af.qpos:af.qpos + 3] = x0[0]
        d.qpos[af.qpos + 3:af.qpos + 7] = quaternion(x0[2])
        d.qvel[af.qvel:af.qvel + 3] = x0[1]
        d.qvel[af.qvel + 3:af.qvel + 6] = x0[3]
        self._trim_rotors()
        with control_callback(None):
            mujoco.mj_forward(m, d)
        self._crash = None
        self._z0 = float(x0[0, 2])
        # in the air from the start (AIRBORNE_RISE above where it would rest), or once it has risen that much
        self._airborne = self._z0 > self.clearance + AIRBORNE_RISE

    def _trim_rotors(self) -> None:
        """Lagged rotors (a filter's activation) start at the thrusts that hold the vehicle's weight level, as
        RotorPy's vehicle starts at its hover rotor speed: act = the allocation's inverse of [m g, 0, 0, 0] (m the
        true mass with the payload), clipped into [0, T_max], over each rotor's gain (a weakened rotor's efficiency)
        -- not at zero thrust, which would drop a vehicle that starts on its reference."""
        af, m, d = self.airframe, self.model, self.data
        if not np.any(af.act >= 0):
            return
        weight = float(self.true_theta()[0]) * float(-m.opt.gravity[2])
        trim = af.thrusts(weight, np.zeros(3))
        for i, adr in enumerate(af.act):
            if adr >= 0:
                d.act[adr] = trim[i] / m.actuator_gainprm[af.actuators[i], 0]

    def measure(self, d: mujoco.MjData, x: np.ndarray) -> None:
        """Fill x (4, 3) from MjData (inside the control callback)."""
        measure_into(d.qpos, d.qvel, self.airframe.qpos, self.airframe.qvel, x)

    def observe(self) -> np.ndarray:
        x = np.empty((4, 3))
        self.measure(self.data, x)
        return x

    def true_theta(self) -> np.ndarray:
        """(13,) [m, Jxx, Jyy, Jzz, Jxy, Jxz, Jyz, dx, dy, dz, tx, ty, tz] from the compiled model and the external
        force and torque as they are now."""
        if self._theta is None:
            mass, J, _ = rigid_inertia(self.model, self.body)
            inertia = [J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2]]
            self._theta = np.array([mass, *inertia, *self.external_force, *self.external_torque], dtype=float)
        return self._theta

    def model_changed(self) -> None:
        self._theta = None

    @contextlib.contextmanager
    def controlled_by(self, policy) -> Iterator[None]:
        """policy(t, x (4, 3)) -> the four thrusts (4,) [N], inside MuJoCo's control callback (each RK4 stage); then
        the rotors' drag at that stage's state and thrusts into qfrc_applied (apply_rotor_drag), which MuJoCo adds
        to the stage's forces after the callback returns."""
        acts, measure, drag = self.airframe.actuators, self.measure, self.apply_rotor_drag
        x = np.empty((4, 3))

        def callback(m, d):
            measure(d, x)
            d.ctrl[acts] = policy(d.time, x)
            drag(d)

        with control_callback(callback):
            yield

    def apply_rotor_drag(self, d: mujoco.MjData) -> None:
        """RotorPy's rotor drag (airframe.rotor_drag_into, compiled as the native callback compiles it) at d's state,
        controls and the model's wind, into d.qfrc_applied's free-joint entries; nothing where the model declares
        no rotor drag. Called inside the control callback, after the controls are written."""
        if self.airframe.has_drag:
            self._rotor_drag_into(d, d.qfrc_applied)

    def _rotor_drag_into(self, d: mujoco.MjData, qfrc: np.ndarray) -> None:
        af, m = self.airframe, self.model
        drag_kernel()(d.qvel, af.qvel, d.xmat[af.body], d.ctrl, d.act, m.actuator_gainprm, af.actuators, af.act,
                      self.ctrl_range[0], self.ctrl_range[1], af.rotors, m.opt.wind, af.drag, qfrc)

    def rotor_wrench(self, d: mujoco.MjData | None = None) -> np.ndarray:
        """(6,) the rotor drag at d's state and thrusts (default: the plant's MjData) as the free joint's generalized
        force: the force [N] in the world frame, the moment [N m] about the body's origin in the body frame
        (airframe.rotor_drag_into); d is left as it was."""
        out = np.zeros(self.model.nv)
        if self.airframe.has_drag:
            self._rotor_drag_into(self.data if d is None else d, out)
        return out[self.airframe.qvel:self.airframe.qvel + 6].copy()

    def step(self) -> None:
        """One mj_step with the external force and torque held; then the crash check."""
        d = self.data
        d.xfrc_applied[self.body, :3] = self.external_force
        d.xfrc_applied[self.body, 3:] = self.external_torque
        mujoco.mj_step(self.model, d)
        self._check_crash()

    def instability(self) -> str | None:
        return new_warnings(self.data, self._warning_total0, self._warnings0)

    def crashed(self, text: str, *, airborne: bool) -> None:
        """The compiled callback found a crash (adaptive_mj.plants.quadrotor_kernel): termination() says so from now
        on."""
        self._crash, self._airborne = text, airborne

    # --- the native path's (adaptive_mj.plants.quadrotor_kernel) ------------------------------
    @contextlib.contextmanager
    def controlled_natively(self, cfunc) -> Iterator[None]:
        with compiled_control(cfunc):
            yield

    def native_prestep(self) -> None:
        """The external force and torque held in xfrc_applied (events change them between chunks only)."""
        self.data.xfrc_applied[self.body, :3] = self.external_force
        self.data.xfrc_applied[self.body, 3:] = self.external_torque

    def native_poststep(self) -> None:
        return None

    def step_native(self, nstep: int) -> None:
        self.native_prestep()
        mujoco.mj_step(self.model, self.data, nstep=nstep)

    def termination(self) -> str | None:
        """The crash that ends the run as crashed (Status.CRASHED; "crashed at t = … s: …"), or None."""
        return self._crash

    def unmodelled_drag(self) -> float | None:
        return None

    def release(self) -> None:
        """The run is over: its MjData to the spare ones (as MujocoPlant.release; not while a native run's context
        still points at it)."""
        data = self.__dict__.pop("data", None)
        if data is not None and self.native_owner is None:
            release_data(self.model, data)

    def preflight_lines(self) -> list[str]:
        """What the pre-flight check says before the first step (adaptive_mj.sim.preflight): a vehicle whose weight
        with its payload is more than its rotors lift in all cannot hover, whatever the law."""
        m, g = float(self.true_theta()[0]), float(-self.model.opt.gravity[2])
        lift = float(np.sum(self.airframe.thrust_max * self.model.actuator_gainprm[self.airframe.actuators, 0]))
        if m * g < lift:
            return []
        return [f"pre-flight: the vehicle with its payload weighs {1000 * m:.4g} g and its rotors lift "
                f"{1000 * lift / g:.4g} g in all: it cannot hover, whatever the law (a payload below "
                f"{max(0.0, lift / g - (m - self._payload_mass())):.3g} kg could: plant.payload_mass)"]

    def rotor_lag(self) -> float:
        """[s] the rotors' first-order lag τ_m as the compiled model has it (the largest of the four actuators'
        filter time constants, dynprm[0] of dyntype "filter"; 0 for rotors without dynamics): the pre-flight
        check's attitude loop (adaptive_mj.sim.preflight.attitude_margins)."""
        m, acts = self.model, self.airframe.actuators
        lags = [float(m.actuator_dynprm[a, 0]) for a in acts if m.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_FILTER]
        return max(lags, default=0.0)

    def _payload_mass(self) -> float:
        """[kg] the mass below the airframe's own body (its payload's)."""
        return float(self.true_theta()[0] - self.model.body_mass[self.body])

    def nominal_theta(self) -> np.ndarray:
        """(13,) what a law knows of the vehicle untold (its estimates' default): the bare airframe's own mass and
        inertia (the body "quad" without its payload), no external force or torque."""
        m, b, J = self.model, self.body, self.airframe.inertia
        return np.array([m.body_mass[b], J[0, 0], J[1, 1], J[2, 2], J[0, 1], J[0, 2], J[1, 2], 0.0, 0.0, 0.0, 0.0, 0.0,
                         0.0])

    def estimate_problem(self, theta: np.ndarray) -> str | None:
        """Why a law cannot start from estimates `theta` (13,) (the flight laws divide by m̂ and solve with Ĵ), or
        None: m̂ > 0 and Ĵ positive definite."""
        if not theta[0] > 0:
            return f"m must be > 0 [kg] (the flight laws divide by it), got {theta[0]:g}"
        xx, yy, zz, xy, xz, yz = theta[1:7]
        J = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.all(np.isfinite(J)) or np.linalg.eigvalsh(J).min() <= 0:
            return (f"Jxx .. Jyz must make a positive definite inertia [kg m²] (the attitude loop solves with it), got "
                    f"eigenvalues {', '.join(f'{v:.3g}' for v in np.linalg.eigvalsh(np.nan_to_num(J)))}")
        return None

    def state_on_reference(self, ref0: np.ndarray) -> np.ndarray:
        """(4, 3) the state a run starting on the reference starts in: at p_d(0) with velocity p_d'(0), level (φ =
        0) and not turning (Ω = 0). ref0 (5, 3): the reference at t = 0."""
        return np.vstack([ref0[0], ref0[1], np.zeros(3), np.zeros(3)])

    def mass_matrices(self, q: np.ndarray) -> np.ndarray:
        """(N, 3, 3) m I [kg]: the translational inertia the position laws' V = ½ m sᵀs weighs s by."""
        n = np.asarray(q).shape[0]
        return np.broadcast_to(self.true_theta()[0] * np.eye(3), (n, 3, 3)).copy()

    # --- crashes -----------------------------------------------------------------------
    def _check_crash(self) -> None:
        if self._crash is not None:
            return
        d, af = self.data, self.airframe
        q = d.qpos
        code, value, self._airborne = crash_check(q[af.qpos + 2], q[af.qpos + 3], q[af.qpos + 4], q[af.qpos + 5],
                                                  q[af.qpos + 6], self._airborne, self._z0, self.clearance,
                                                  self.cos_tilt)
        if code != NO_CRASH:
            v = d.qvel
            vx, vy, vz = v[af.qvel], v[af.qvel + 1], v[af.qvel + 2]
            speed = (vx * vx + vy * vy + vz * vz) ** 0.5
            self._crash = crash_text(code, value, float(d.time), self.crash_tilt, speed)

    # --- what events change ------------------------------------------------------------
    def release_payload(self, name: str) -> None:
        """The payload body `name` (and its subtree) let go: their mass and inertia removed, their geoms no longer
        colliding nor drawn. The bodies stay in the model as massless frames: MuJoCo cannot remove a body from a
        compiled model mid-run, and a massless frame exerts no force."""
        m = self.model
        for b in subtree_bodies(m, self.body_id(name)):
            m.body_mass[b] = 0.0
            m.body_inertia[b] = 0.0
            for g in range(m.ngeom):
                if m.geom_bodyid[g] == b:
                    m.geom_contype[g] = m.geom_conaffinity[g] = 0
                    m.geom_rgba[g, 3] = 0.0
        mujoco.mj_setConst(m, scratch_data(m))
        self.clearance = ground_clearance(m, self.body)  # the bare vehicle's (the released geoms collide no more)
        self.model_changed()

    def jointed(self, name: str) -> bool:
        """Whether body `name` or a body below it moves on a joint of its own (a cable payload)."""
        m = self.model
        return any(int(m.body_jntnum[b]) > 0 for b in subtree_bodies(m, self.body_id(name)))

    def set_payload_point(self, name: str, mass: float, offset) -> None:
        """The rigid payload body `name` becomes a point mass `mass` [kg] (0: none) at `offset` (3,) [m] from the
        vehicle's centre of mass in the vehicle's body frame (the payload body hangs on the vehicle's body, unrotated,
        as plant.payload attaches it); its geoms stay as they are."""
        m, b = self.model, self.body_id(name)
        root, at, pos = self.body_id(BODY), b, np.zeros(3)  # the payload body's origin in the vehicle's frame
        while at != root:
            if at == 0 or int(m.body_jntnum[at]) > 0 or not np.allclose(m.body_quat[at], (1.0, 0.0, 0.0, 0.0)):
                raise ModelError(f"{self.where}: a point payload needs body {name!r} fixed, unrotated, on {BODY!r}")
            pos += m.body_pos[at]
            at = int(m.body_parentid[at])
        ipos = np.asarray(offset, dtype=float) + m.body_ipos[root] - pos
        self.set_body_inertial(name, mass=float(mass), ipos=ipos, iquat=(1.0, 0.0, 0.0, 0.0), inertia=(0.0, 0.0, 0.0))

    def scale_rotor(self, rotor: int, factor: float) -> None:
        """Rotor `rotor` (1 to 4) gives `factor` times the thrust commanded (a damaged propeller, a weak motor)."""
        a = int(self.airframe.actuators[rotor - 1])
        self.model.actuator_gainprm[a, 0] *= factor

    def set_wind(self, velocity) -> None:
        """The air's velocity [m/s] (3,) in the world frame (MuJoCo's opt.wind)."""
        self.model.opt.wind[:] = velocity

    def add_force(self, force, torque) -> None:
        """Adds a constant external force [N] and torque [N m] (world frame) on the body from now on."""
        self.external_force = self.external_force + np.asarray(force, dtype=float)
        self.external_torque = self.external_torque + np.asarray(torque, dtype=float)
        self.model_changed()


def load(path: str | Path = MODEL_PATH, **kwargs) -> QuadrotorPlant:
    """The bundled quadrotor (or a user's MJCF with a free body named "quad" and four site rotors)."""
    from adaptive_mj.plants.mujoco_plant import compile_xml_path

    return QuadrotorPlant(compile_xml_path(path), where=str(path), **kwargs)


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> ModelSource | None:
    """plant.model with plant.payload attached at plant.site: the arms' composition (arm.model_source)."""
    from adaptive_mj.plants import arm

    return arm.model_source(scn)


def _edit(spec: QuadrotorSpec):
    """The MjSpec edit of plant.rotor_time_constant: every rotor a first-order filter of τ (MuJoCo's actuator
    dynamics: act' = (ctrl − act)/τ, thrust = act), or with τ = 0 no lag (thrust = ctrl)."""
    tau = spec.rotor_time_constant

    def edit(s: mujoco.MjSpec) -> tuple[str, ...]:
        for a in s.actuators:
            if tau == 0:
                a.dyntype = mujoco.mjtDyn.mjDYN_NONE
            else:
                a.dyntype = mujoco.mjtDyn.mjDYN_FILTER
                a.dynprm[0] = tau
        if tau == 0:
            return ("every rotor's lag taken off: thrust = the control (plant.rotor_time_constant = 0)",)
        return (f"every rotor given a first-order lag of {tau:g} s (plant.rotor_time_constant)",)

    return edit if tau is not None else None


def from_scenario(scn, source: ModelSource | None) -> BuiltPlant:
    """plant.kind = "quadrotor": the quadrotor of plant.model with plant.payload, its rotors lagged by
    plant.rotor_time_constant, in the wind plant.wind."""
    from adaptive_mj.plants.mujoco_plant import compile_for_scenario_with

    spec = scn.plant.kind_spec or QuadrotorSpec()
    edit = _edit(spec)
    key = None if edit is None else ("rotor lag", spec.rotor_time_constant)
    model, xml, notes = compile_for_scenario_with(scn, source, edit=edit, edit_key=key)
    if spec.wind is not None:
        model.opt.wind[:] = spec.wind
    plant = QuadrotorPlant(model, where=str(scn.plant.model), crash_tilt=spec.crash_tilt)
    return BuiltPlant(plant, xml, tuple(notes or ()))


def _own_keys(t, fields) -> dict:
    """plant.crash_tilt, plant.rotor_time_constant, plant.wind."""
    wind = t.numbers("wind", None)
    if wind is not None and len(wind) != 3:
        raise t.fail("wind", "3 numbers [m/s] (x, y, z)", list(wind))
    spec = QuadrotorSpec(crash_tilt=t.number("crash_tilt", CRASH_TILT_DEG, gt=0),
                         rotor_time_constant=t.number("rotor_time_constant", None, ge=0),
                         wind=None if wind is None else (float(wind[0]), float(wind[1]), float(wind[2])))
    if not spec.crash_tilt <= 180:
        raise t.fail("crash_tilt", "an angle in (0, 180] deg", spec.crash_tilt)
    return {"kind_spec": spec}


CRASH_TILT = Key("crash_tilt", "number", "deg", CRASH_TILT_DEG, "(0, 180]",
                 "the tilt past which the run ends crashed")
ROTOR_TIME_CONSTANT = Key("rotor_time_constant", "number", "s", None, ">= 0",
                          "a first-order lag on every rotor's thrust, unknown to the laws; 0: none (default: the "
                          "model's, 0.005 s on the bundled quadrotor)")
WIND = Key("wind", "array [x, y, z]", "m/s", None, "3 numbers",
           "the air's velocity from t = 0, felt through the rotors' drag (default: the model's opt.wind)")


# --- its references -------------------------------------------------------------------
REFERENCE_KINDS = ("hover", "lemniscate", "motion_primitive")


def read_reference(t):
    """[reference] of a quadrotor: kind "hover" (center [m]; from start [m] over rise_time [s] when start is given:
    a take-off) or "lemniscate" (the same, plus amplitude A [m], omega [rad/s], t0 [s]: the figure-eight x = A
    sin(ω(t − t0)), y = (A/2) sin(2ω(t − t0)) about center from t0 on); adaptive_mj.reference.Flight. Kind
    "motion_primitive": AdaptiveQuadBench's random motion primitive (adaptive_mj.reference.MotionPrimitive), from
    rest at center [m] to center + position [m] with velocity [m/s] and acceleration [m/s²] at duration [s];
    adaptive_mj.study.flight draws them from a seed."""
    from adaptive_mj.specs import ReferenceSpec

    kind = t.string("kind", choices=REFERENCE_KINDS)
    if kind == "motion_primitive":
        params = {"center": t.numbers("center", (0.0, 0.0, 5.0), length=3),
                  **{k: t.numbers(k, (0.0, 0.0, 0.0), length=3) for k in ("position", "velocity", "acceleration")},
                  "duration": t.number("duration", 5.0, gt=0)}
        t.finish()
        return ReferenceSpec(kind=kind, params=params)
    params = {"center": t.numbers("center", (0.0, 0.0, 1.0), length=3), "start": t.numbers("start", None, length=3),
              "rise_time": t.number("rise_time", 2.0, gt=0)}
    if kind == "lemniscate":
        params.update(amplitude=t.number("amplitude", 0.5, gt=0), omega=t.number("omega", 1.0, gt=0),
                      t0=t.number("t0", 0.0, ge=0))
    t.finish()
    return ReferenceSpec(kind=kind, params=params)


def build_reference(spec):
    """The Flight (or MotionPrimitive) reference of a [reference] read by read_reference."""
    from adaptive_mj.reference import Flight, MotionPrimitive

    p = spec.params
    if spec.kind == "motion_primitive":
        return MotionPrimitive(center=tuple(p["center"]), position=tuple(p["position"]),
                               velocity=tuple(p["velocity"]), acceleration=tuple(p["acceleration"]),
                               duration=p["duration"])
    return Flight(center=tuple(p["center"]), amplitude=p.get("amplitude", 0.0), omega=p.get("omega", 1.0),
                  start=None if p["start"] is None else tuple(p["start"]), rise_time=p["rise_time"],
                  t0=p.get("t0", 0.0))


# --- its events -----------------------------------------------------------------------
def _vector(name: str):
    def read(t):
        v = t.numbers(name, None)
        if v is None:
            return (0.0, 0.0, 0.0)
        if len(v) != 3:
            raise t.fail(name, "3 numbers (x, y, z)", list(v))
        return tuple(float(a) for a in v)

    return read


def _wind(e, scn, source) -> ev.Event:
    w = e.params["velocity"]
    return ev.Event(e.t, f"wind {list(w)} m/s", lambda plant: plant.set_wind(w))


def _rotor(e, scn, source) -> ev.Event:
    r = e.params["rotor"]
    return ev.Event(e.t, f"rotor {r} thrust x {e.value:g}", lambda plant: plant.scale_rotor(r, e.value))


def _force(e, scn, source) -> ev.Event:
    f, tq = e.params["force"], e.params["torque"]
    return ev.Event(e.t, f"external force {list(f)} N, torque {list(tq)} N m", lambda plant: plant.add_force(f, tq))


def _release(e, scn, source) -> ev.Event:
    return ev.Event(e.t, f"payload released: {e.body}", lambda plant: plant.release_payload(e.body))


def _rotor_number(t) -> int:
    r = t.integer("rotor", 1, ge=1)
    if r > 4:
        raise t.fail("rotor", "a rotor number 1 to 4", r)
    return r


#: the largest rotor efficiency an event may set: AdaptiveQuadBench draws each rotor's efficiency 1 ± U(0, I), I
#: capped at 0.6 (aqb/config/randomization_config.py at ee7df29, l. 174-176 and 276): a rotor up to 1.6 times as strong
ROTOR_EFFICIENCY_MAX = 2.0


def _rotor_on_load(t, plant, fields) -> None:
    """A rotor's efficiency is a factor in (0, ROTOR_EFFICIENCY_MAX] (below 1 a weakened rotor, above a stronger one;
    the value rule has checked > 0)."""
    v = t.data.get("value")
    if isinstance(v, (int, float)) and v > ROTOR_EFFICIENCY_MAX:
        raise t.fail("value", f"a thrust factor in (0, {ROTOR_EFFICIENCY_MAX:g}] (below 1 a weakened rotor)", v)


def _payload_point(e, scn, source) -> ev.Event:
    off = e.params["offset"]
    return ev.Event(e.t, f"payload point mass {e.value:g} kg at {list(off)} m",
                    lambda plant: plant.set_payload_point(e.body, e.value, off))


def _payload_point_on_load(t, plant, fields) -> None:
    """The mass is >= 0 [kg] (0: the payload detached; the value rule "any" has read a number)."""
    v = t.data.get("value")
    if isinstance(v, (int, float)) and v < 0:
        raise t.fail("value", "a mass >= 0 [kg]", v)


def _point_check(scn, e, plant, source) -> None:
    """The payload exists and is rigid (a point mass on a body hanging on a joint would not be where it says)."""
    from adaptive_mj.errors import ScenarioError

    ev.payload_body_check(scn, e, plant, source)
    if plant.jointed(e.body):
        raise ScenarioError(f"{scn.source}: events: payload_point makes a rigid payload a point mass, and {e.body!r} "
                            f"hangs on a joint (plant.payload = {scn.plant.payload!r}): attach a rigid one (quad_box)")


WIND_EVENT = ev.EventKind("wind", _wind, value="none",
                          fields=(ev.EventField("velocity", _vector("velocity"), "the air's velocity [m/s]"),),
                          doc="sets the wind (MuJoCo's opt.wind, felt through the rotors' drag) to velocity [m/s] "
                              "from t on: a gust is two events")
ROTOR_EFFICIENCY = ev.EventKind("rotor_efficiency", _rotor, fields=(
    ev.EventField("rotor", _rotor_number, "the rotor (1 to 4)"),), on_load=_rotor_on_load,
    doc="rotor's thrust becomes value (0 < value <= 2) times what is commanded, from t on")
PAYLOAD_POINT = ev.EventKind("payload_point", _payload_point, value="any", fields=(
    ev.BODY, ev.EventField("offset", _vector("offset"), "[m] (x, y, z) from the vehicle's centre of mass, body frame")),
    on_load=_payload_point_on_load, on_build=_point_check,
    doc="makes the payload body a point mass of value [kg] (>= 0; 0: detached) at offset [m] from the vehicle's "
        "centre of mass (body frame) from t on: AdaptiveQuadBench's payload (aqb/config/randomization_config.py)")
EXTERNAL_FORCE = ev.EventKind("external_force", _force, value="none", fields=(
    ev.EventField("force", _vector("force"), "[N] (x, y, z), world frame"),
    ev.EventField("torque", _vector("torque"), "[N m] (x, y, z), world frame")),
    doc="adds a constant force [N] and torque [N m] (world frame) on the vehicle from t on")
def _release_check(scn, e, plant, source) -> None:
    """The payload exists, and is rigid: MuJoCo cannot take the mass of a body on a joint away mid-run (its joint's
    inertia would vanish)."""
    from adaptive_mj.errors import ScenarioError

    ev.payload_body_check(scn, e, plant, source)
    if plant.jointed(e.body):
        raise ScenarioError(f"{scn.source}: events: payload_release lets go of a rigid payload, and {e.body!r} hangs "
                            f"on a joint (plant.payload = {scn.plant.payload!r}): MuJoCo cannot take a jointed body's "
                            "mass away mid-run; release a rigid payload (quad_box), or set its mass (payload_mass)")


PAYLOAD_RELEASE = ev.EventKind("payload_release", _release, value="none", on_build=_release_check,
                               doc="lets the payload body go at t (its mass and inertia removed)")


@dataclass(frozen=True)
class Disturbance:
    """A disturbance raised to failure: name, unit, overrides(v) the scenario keys that apply intensity v, the range
    [lo, hi] searched, step > 0: intensities are whole multiples of step (the delay: physics steps)."""

    name: str
    unit: str
    overrides: Callable[[float], list[str]]
    lo: float
    hi: float
    step: float = 0.0
    doc: str = ""

    def text(self, v: float | None) -> str:
        if v is None:
            return "n/a"
        if self.unit == "%":
            return f"{100 * v:.3g} %"
        return f"{v:.3g} {self.unit}".strip()

    def stressor(self) -> Stressor:
        """As the breaking-point search's stressor (its intensities, range and step)."""
        return Stressor(self.name, self.overrides, self.lo, self.hi, unit=self.unit, step=self.step)


def _event(text: str) -> list[str]:
    return [f"events=[{text}]"]


#: AdaptiveQuadBench's disturbances (arXiv 2510.03471) on this vehicle: the flight study's (adaptive_mj.study.flight)
#: and the breaking-point study's (study_stressors)
DISTURBANCES = (
    Disturbance("wind", "m/s", lambda v: [f"plant.wind=[{v!r}, 0.0, 0.0]"], 0.5, 40.0,
                doc="a steady wind along x (felt through RotorPy's rotor drag)"),
    Disturbance("force", "N", lambda v: _event(f"{{t=0.0, kind='external_force', force=[{v!r}, 0.0, 0.0]}}"),
                0.003, 1.0, doc="a constant force along x on the body (the vehicle weighs 0.29 N)"),
    Disturbance("torque", "N m", lambda v: _event(f"{{t=0.0, kind='external_force', torque=[{v!r}, 0.0, 0.0]}}"),
                1e-5, 1e-2, doc="a constant torque about x (a rotor's thrust gives at most 4.4e-3 N m about x)"),
    Disturbance("payload", "kg", lambda v: ["plant.payload='quad_box'", f"plant.payload_mass={v!r}"], 0.002, 0.028,
                doc="a rigid payload under the body, unknown to the laws (the rotors lift 58.6 g in all: the range "
                    "stops below the 28.6 g that leave the 30 g vehicle no thrust to spare)"),
    Disturbance("rotor loss", "%",
                lambda v: _event(f"{{t=1.0, kind='rotor_efficiency', rotor=1, value={1.0 - v!r}}}"), 0.02, 0.95,
                doc="rotor 1 loses this fraction of its thrust at t = 1 s"),
)
PAYLOAD_AT = 1.0  # [s] when the breaking-point study's payload stressor adds its mass (as the rotor loss starts)


def study_laws(ctx: StudyContext, composite: bool) -> list[tuple[str, list[str]]]:
    """The quadrotor's laws in the breaking-point study (kinds.StressPlant.laws; no composite row): the geometric
    adaptive law, with its inertia adapted too (law.adapt_inertia), with each modification (the dead-zone at 3 σ of
    ‖s‖ under the nominal noise, σ- and e-modification leaking toward the true θ in study_spec.LEAK_TIME on the
    mass, the box [θ/2, 2θ] on the mass and the inertia's diagonal), L1 augmentation, and the geometric baseline
    holding the true parameters (law.nominal = 'model')."""
    gamma1 = float(ctx.gamma[0])  # the mass estimate's stiffness
    assert ctx.lam is not None  # the row's scenario sets law.lam (λ of ‖s‖'s noise)
    sig_s = surface_noise(3, float(ctx.lam), ctx.nominal_noise)  # the noise in ‖s‖, s = e_v + λ e_x (3 axes)
    theta0 = theta_table(ctx.law_names, ctx.theta, quoted=True)
    return [("adaptive", []),
            ("adaptive_inertia", ["law.adapt_inertia=true"]),
            ("dead_zone", [f"law.dead_zone={{width={3.0 * sig_s!r}}}"]),
            ("sigma", [f"law.sigma={gamma1 / LEAK_TIME!r}", f"law.theta0={theta0}"]),
            ("e_modification", [f"law.e_modification={gamma1 / (LEAK_TIME * sig_s)!r}", f"law.theta0={theta0}"]),
            ("projection", [f"law.projection={box_table(ctx.law_names, ctx.theta, quoted=True)}"]),
            ("l1_geometric", ["law.kind='l1_geometric'"]),
            ("geometric", ["law.kind='geometric'", "law.nominal='model'"])]


def study_stressors(ctx: StudyContext, duration: float) -> list[Stressor]:
    """The quadrotor's stressors in the breaking-point study (kinds.StressPlant.stressors): noise σ_p [m] (σ_v =
    10 σ_p per second), and AdaptiveQuadBench's disturbances (DISTURBANCES: a steady wind, a constant force and
    torque, mass v [kg] added to the payload at PAYLOAD_AT up to the most the rotors lift, one rotor's thrust loss
    as a fraction)."""
    out = [Stressor("noise σ_y", lambda v: [f"noise.std={{p={v!r}, v={10 * v!r}}}"], 1e-4, 0.1,
                    unit=ctx.output_unit)]
    for d in DISTURBANCES:
        if d.name == "payload":  # mass added to the payload at 1 s (the estimates are the truth at the start)
            m0 = float(ctx.theta[0] - ctx.plant.nominal_theta()[0])  # the payload's mass [kg], from the model
            out.append(Stressor("payload added", _payload_added(m0), 0.001, d.hi - m0, unit=d.unit))
        else:
            out.append(replace(d.stressor(), unit="fraction" if d.unit == "%" else d.unit))
    return out


def study_hold(plant: Any, start: Any) -> str:
    """score --scenario's hold task on a quadrotor: a hover at its reference's start y_d(0) (3,) [m] (a template:
    {{ }} is one brace, as the scorecard's tasks are written)."""
    center = ", ".join(repr(float(v)) for v in np.asarray(start, dtype=float).reshape(3))
    return f"reference={{{{kind='hover', center=[{center}]}}}}"


def _payload_added(m0: float) -> Callable[[float], list[str]]:
    """The payload's mass m0 + v [kg] from PAYLOAD_AT on (a payload_mass event)."""
    return lambda v: [f"events=[{{t={PAYLOAD_AT!r}, kind='payload_mass', value={m0 + v!r}}}]"]


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "quadrotor"
KIND = register(PlantKind(
    "quadrotor", __name__, frozenset({Form.AIRFRAME}), output_unit="m", control_unit="N", params=PARAM_UNITS,
    default_model="quadrotor", default_law="geometric_adaptive",
    doc=("a quadrotor, RotorPy's Crazyflie or AdaptiveQuadBench's 0.826 kg vehicle (rotor drag, motor lag), with an "
         "unknown payload"),
    keys=plant_keys.keys(CRASH_TILT, ROTOR_TIME_CONSTANT, WIND, payload=True, default_payload=None),
    reader=plant_keys.SharedReader(backend=("mujoco", "a free body flown in MuJoCo with RotorPy's rotor drag"),
                                   body=_own_keys),
    events={ev.PAYLOAD_MASS: "mujoco", ev.PAYLOAD_SWAP: "mujoco", PAYLOAD_RELEASE: "mujoco",
            ROTOR_EFFICIENCY: "mujoco", WIND_EVENT: "mujoco", EXTERNAL_FORCE: "mujoco", PAYLOAD_POINT: "mujoco"},
    order=lambda plant, law_order: 4, starts_on_reference=True, sections=("quadrotor",),
    # the breaking-point study and the scorecard: the bundled lemniscate with its 10 g payload, its scenario's own
    # bound on the tail RMS (2 cm: ‖p̃‖'s RMS / √3; the geometric law at the true parameters flies it with 15.3 mm
    # without noise, most of it the rotor drag it has no integral action against: 2.2 mm under σ_p = 1 mm, σ_v = 1
    # cm/s in MuJoCo's former ellipsoid fluid model, before issue 52); a crash fails the run whatever its tail
    tail_bound=0.02, nominal_noise=1e-3,
    # its runs' stability criteria (success.tail_saturation, success.oscillation; docs/SCENARIOS.md, "Verdict"):
    # measured on the stress study's lemniscate (issue 52), every stable run spends at most 0.04 % of its tail with a
    # rotor at a limit and its body rate's largest line above 1 Hz is at most 0.08 rad/s (a control delay of 11
    # steps); every limit cycle of the attitude loop (12 to 20 steps) 79 to 100 % and 5.4 to 12 rad/s
    tail_saturation=TAIL_SATURATION, oscillation=OSCILLATION,
    stress=StressPlant("quadrotor", "quadrotor_lemniscate", (), noise_signals=("p", "v"),
                       label="the quadrotor: the RMS over x, y and z, ‖p̃‖'s RMS / √3",
                       laws=study_laws, stressors=study_stressors, hold=study_hold,
                       tasks=(ScoreTask("tracking", "quadrotor_lemniscate", (),
                                        draws=(Draw("reference.amplitude", 0.75, 1.25),
                                               Draw("reference.omega", 0.75, 1.25))),
                              ScoreTask("change", "quadrotor_lemniscate",
                                        ("law.initial_estimates='model'",
                                         "events=[{{t={half}, kind='payload_release'}}]"),
                                        extras=("change_response",)),
                              ScoreTask("hold", "quadrotor_hover_payload", ("law.initial_estimates='model'",),
                                        extras=("estimate_drift",)))),
    noise_signals=STATE_NAMES, reference_reader=read_reference, reference_builder=build_reference))

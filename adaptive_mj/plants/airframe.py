"""A multirotor as MuJoCo compiles it (models/quadrotor.xml): its mass, inertia, rotor layout and thrust limits
read from the compiled model, the allocation between rotor thrusts and the body's collective thrust and
moments, and the rigid-body state a flight controller reads (issue 33: the plant's physics, before its plant
kind). Every number is derived from the model, none typed.

Frames: world z up; body x forward, z along the thrust. The state is p (3,) [m] and v (3,) [m/s] in the world
frame, R (3, 3) the body-to-world rotation, Ω (3,) [rad/s] in the body frame (MuJoCo's free joint keeps its
angular velocity in the local frame).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class Airframe:
    """body: the flying body's id; qpos, qvel: its free joint's addresses; mass [kg] (its subtree: a rigid payload
    welded to it included); inertia (3, 3) [kg m²] the body's own about its centre of mass in the body frame;
    rotors (4, 3) the rotor sites' positions in the body frame [m]; yaw (4,) each rotor's reaction torque per unit
    thrust about body z [m]; thrust_max (4,) [N]; actuators (4,) their ids; allocation (4, 4): [f, M_x, M_y, M_z] =
    allocation @ thrusts [N, N m]."""

    body: int
    qpos: int
    qvel: int
    mass: float
    inertia: np.ndarray
    rotors: np.ndarray
    yaw: np.ndarray
    thrust_max: np.ndarray
    actuators: np.ndarray
    allocation: np.ndarray
    act: np.ndarray
    drag: np.ndarray

    @property
    def has_drag(self) -> bool:
        """Whether the model declares rotor drag (its k_eta > 0 and k_d or k_z > 0)."""
        return bool(self.drag[0] > 0 and (self.drag[1] > 0 or self.drag[2] > 0))

    @classmethod
    def of_model(cls, model: mujoco.MjModel, body: str = "quad") -> "Airframe":
        """The airframe of `body` (a free body whose actuators are site motors along its z axis). mass: the
        subtree's (what gravity pulls); inertia: the body's own inertia matrix in its frame, rotated from
        MuJoCo's principal axes (a welded payload's inertia is the law's unknown, not included here)."""
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
        if b < 0:
            raise ValueError(f"the model has no body {body!r}")
        j = int(model.body_jntadr[b])
        if j < 0 or model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            raise ValueError(f"body {body!r} has no free joint: not a flying body")
        acts = [a for a in range(model.nu) if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_SITE
                and model.site_bodyid[model.actuator_trnid[a, 0]] == b]
        if len(acts) != 4:
            raise ValueError(f"body {body!r} has {len(acts)} site actuators; a quadrotor has 4")
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, model.body_iquat[b])
        Ri = rot.reshape(3, 3)
        inertia = Ri @ np.diag(model.body_inertia[b]) @ Ri.T
        rotors, yaw, tmax = [], [], []
        for a in acts:
            site = model.actuator_trnid[a, 0]
            srot = np.zeros(9)
            mujoco.mju_quat2Mat(srot, model.site_quat[site])
            S = srot.reshape(3, 3)
            gear = model.actuator_gear[a]
            force, torque = S @ gear[:3], S @ gear[3:]
            if not np.allclose(force, [0.0, 0.0, 1.0]) or not np.allclose(torque[:2], 0.0):
                raise ValueError(f"actuator {a} does not push along the body's z axis")
            rotors.append(model.site_pos[site].copy())
            yaw.append(float(torque[2]))
            tmax.append(float(model.actuator_ctrlrange[a, 1]))
        r = np.asarray(rotors)
        A = np.vstack([np.ones(4), r[:, 1], -r[:, 0], np.asarray(yaw)])  # M = Σ r_i × (0, 0, f_i) + yaw_i f_i e_z
        act = np.array([int(model.actuator_actadr[a]) if model.actuator_dyntype[a] != mujoco.mjtDyn.mjDYN_NONE
                        else -1 for a in acts], dtype=np.int64)
        for a, adr in zip(acts, act, strict=True):
            if adr >= 0 and (model.actuator_dyntype[a] != mujoco.mjtDyn.mjDYN_FILTER or model.actuator_actearly[a]):
                raise ValueError(f"actuator {a}: a rotor's dynamics must be none or a first-order filter "
                                 "(dyntype=\"filter\", actearly false)")
        return cls(b, int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j]), float(model.body_subtreemass[b]),
                   inertia, r, np.asarray(yaw), np.asarray(tmax), np.asarray(acts, dtype=np.int64), A, act,
                   rotor_coefficients(model))

    def state(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(p, v, R, Ω) of the free body: world position [m] and velocity [m/s], body-to-world R, body rate
        [rad/s]."""
        q = data.qpos[self.qpos:self.qpos + 7]
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, q[3:7])
        qv = data.qvel[self.qvel:self.qvel + 6]
        return q[:3].copy(), qv[:3].copy(), R.reshape(3, 3), qv[3:6].copy()

    def thrusts(self, f: float, M: np.ndarray) -> np.ndarray:
        """(4,) rotor thrusts [N] that give collective thrust f [N] and body moments M (3,) [N m], clipped into
        [0, thrust_max] (the allocation's exact inverse before clipping)."""
        return np.clip(np.linalg.solve(self.allocation, np.concatenate([[f], M])), 0.0, self.thrust_max)

    def apply(self, data: mujoco.MjData, thrusts: np.ndarray) -> None:
        """Write rotor thrusts (4,) [N] into the actuators' controls."""
        data.ctrl[self.actuators] = thrusts


DRAG_NAMES = ("k_eta", "k_d", "k_z")  # the model's <numeric> rotor coefficients (models/quadrotor.xml)


def rotor_coefficients(model: mujoco.MjModel) -> np.ndarray:
    """(3,) [k_eta, k_d, k_z] from the model's <custom><numeric> of those names: k_eta [N/(rad/s)²] the thrust
    coefficient (thrust = k_eta ω²), k_d and k_z [N/(rad m/s²)] RotorPy's rotor drag coefficients. Zeros (no rotor
    drag) where the model declares none; a model declaring some must declare k_eta > 0."""
    out = np.zeros(3)
    found = False
    for i, name in enumerate(DRAG_NAMES):
        n = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_NUMERIC, name)
        if n >= 0:
            found = True
            out[i] = float(model.numeric_data[model.numeric_adr[n]])
    if found and not (out[0] > 0 and out[1] >= 0 and out[2] >= 0):
        raise ValueError(f"rotor drag needs <numeric> k_eta > 0 and k_d, k_z >= 0, got {list(out)}")
    return out


def rotor_drag_into(qvel, dadr, xmat, ctrl, act, gainprm, acts, actadr, lo, hi, rotors, wind, drag, qfrc):
    """RotorPy's rotor drag (rotorpy/vehicles/multirotor.py, Multirotor.compute_body_wrench, at 9b760b8), written
    as the free joint's generalized force into qfrc[dadr:dadr + 6]: with the body's air-relative velocity in the
    body frame b = Rᵀ(v − wind) and each hub's u_i = b + Ω × r_i, rotor i's drag (its "H force") acts at its hub,

        H_i = −ω_i (k_d u_x, k_d u_y, k_z u_z),   ω_i = √(T_i / k_eta),

    and the wrench is F = Σ H_i (qfrc[dadr:dadr + 3] = R F, world frame [N]) and the moment about the body's origin
    Σ r_i × H_i (qfrc[dadr + 3:dadr + 6], body frame [N m]: the free joint's rotational dofs are the body's axes), as
    RotorPy sums r_i × (T_i + H_i) about its centre of mass. T_i [N] is the rotor's thrust now: gain · act (a
    lagged rotor, actadr[i] >= 0) or gain · ctrl clamped into [lo, hi] (what MuJoCo applies in the stage).

    qvel (nv,) [m/s, rad/s]; xmat (9,) the body's rotation, row-major (MjData.xmat[body]); ctrl (nu,), act (na,),
    gainprm (nu, 10) MuJoCo's; acts (4,), actadr (4,) the rotors' actuator ids and activation addresses; lo, hi
    (4,) [N]; rotors (4, 3) the hubs in the body frame [m]; wind (3,) [m/s] the air's velocity, world frame;
    drag (3,) [k_eta, k_d, k_z]. Plain scalar code: the Python callback runs it compiled by numba as the native
    callback does, so the two paths apply the same bits. At zero airspeed and rate it is exactly zero."""
    ax, ay, az = qvel[dadr] - wind[0], qvel[dadr + 1] - wind[1], qvel[dadr + 2] - wind[2]
    bx = xmat[0] * ax + xmat[3] * ay + xmat[6] * az
    by = xmat[1] * ax + xmat[4] * ay + xmat[7] * az
    bz = xmat[2] * ax + xmat[5] * ay + xmat[8] * az
    wx, wy, wz = qvel[dadr + 3], qvel[dadr + 4], qvel[dadr + 5]
    k_eta, k_d, k_z = drag[0], drag[1], drag[2]
    fx = fy = fz = mx = my = mz = 0.0
    for i in range(4):
        a = acts[i]
        if actadr[i] >= 0:
            c = act[actadr[i]]
        else:
            c = min(max(ctrl[a], lo[i]), hi[i])
        thrust = gainprm[a, 0] * c
        w = math.sqrt(thrust / k_eta) if thrust > 0.0 else 0.0
        rx, ry, rz = rotors[i, 0], rotors[i, 1], rotors[i, 2]
        ux = bx + (wy * rz - wz * ry)
        uy = by + (wz * rx - wx * rz)
        uz = bz + (wx * ry - wy * rx)
        hx, hy, hz = -w * k_d * ux, -w * k_d * uy, -w * k_z * uz
        fx += hx
        fy += hy
        fz += hz
        mx += ry * hz - rz * hy
        my += rz * hx - rx * hz
        mz += rx * hy - ry * hx
    qfrc[dadr] = xmat[0] * fx + xmat[1] * fy + xmat[2] * fz
    qfrc[dadr + 1] = xmat[3] * fx + xmat[4] * fy + xmat[5] * fz
    qfrc[dadr + 2] = xmat[6] * fx + xmat[7] * fy + xmat[8] * fz
    qfrc[dadr + 3] = mx
    qfrc[dadr + 4] = my
    qfrc[dadr + 5] = mz

"""A multirotor as MuJoCo compiles it (models/quadrotor.xml): its mass, inertia, rotor layout and thrust limits
read from the compiled model, the allocation between rotor thrusts and the body's collective thrust and
moments, and the rigid-body state a flight controller reads (issue 33: the plant's physics, before its plant
kind). Every number is derived from the model, none typed.

Frames: world z up; body x forward, z along the thrust. The state is p (3,) [m] and v (3,) [m/s] in the world
frame, R (3, 3) the body-to-world rotation, Ω (3,) [rad/s] in the body frame (MuJoCo's free joint keeps its
angular velocity in the local frame).
"""
from __future__ import annotations

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
        return cls(b, int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j]), float(model.body_subtreemass[b]),
                   inertia, r, np.asarray(yaw), np.asarray(tmax), np.asarray(acts), A)

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

"""Disturbance torques on an arm's joints, τ_d(t) (m,) [N m, or N on a slide joint], added by the
plant to the joints (MuJoCo's qfrc_applied) and held over each physics step, as a 1-DOF plant
holds its disturbance force. No mujoco here: the plant applies what this computes.

Kinds (magnitude a_j per joint):
    constant   τ_d,j = a_j
    step       τ_d,j = a_j for t >= t0, else 0
    sine       τ_d,j = a_j sin(ω t + φ)
    noise      band-limited noise of standard deviation a_j: white noise through a first-order
               low-pass of bandwidth f_b, discretised exactly at the physics step h,
                   τ_k = β τ_{k-1} + sqrt(1 - β²) a w_k,   β = exp(-2π f_b h),  w_k ~ N(0, 1)
               started from its stationary distribution (τ_0 = a w_0), drawn from its own
               generator so the measurement noise's stream is the same with or without it.

`rows(t)` gives the torques of consecutive steps, evaluated row by row with the same scalar
arithmetic whether the Python loop asks for one step or the compiled loop for a chunk, so both
paths apply the same numbers.
"""
from __future__ import annotations

import math

import numpy as np

KINDS = ("constant", "step", "sine", "noise")


class JointDisturbance:
    """τ_d(t) on m joints. magnitude: (m,) a_j; t0 [s]; omega [rad/s]; phase [rad]; bandwidth_hz
    f_b (kind "noise"); dt: the physics step h [s]; rng: the generator of kind "noise"."""

    def __init__(self, kind: str, magnitude, *, t0: float = 0.0, omega: float = 1.0, phase: float = 0.0,
                 bandwidth_hz: float = 10.0, dt: float = 0.001, rng: np.random.Generator | None = None):
        if kind not in KINDS:
            raise ValueError(f"disturbance kind must be one of {KINDS}, got {kind!r}")
        self.kind, self.magnitude = kind, np.asarray(magnitude, dtype=float).copy()
        self.t0, self.omega, self.phase = float(t0), float(omega), float(phase)
        self.beta = math.exp(-2.0 * math.pi * bandwidth_hz * dt)
        self.gain = math.sqrt(1.0 - self.beta * self.beta)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.state: np.ndarray | None = None  # kind "noise": the last step's τ_d

    def rows(self, t: np.ndarray) -> np.ndarray:
        """(len(t), m) τ_d at the starts t (consecutive physics steps) [N m]; advances kind "noise"."""
        t = np.asarray(t, dtype=float)
        out = np.empty((t.shape[0], self.magnitude.shape[0]))
        a = self.magnitude
        if self.kind == "constant":
            out[:] = a
        elif self.kind == "step":
            for k in range(t.shape[0]):
                out[k] = a if t[k] >= self.t0 else 0.0
        elif self.kind == "sine":
            for k in range(t.shape[0]):
                out[k] = a * math.sin(self.omega * float(t[k]) + self.phase)
        else:
            w = self.rng.normal(size=out.shape)
            for k in range(t.shape[0]):
                self.state = a * w[k] if self.state is None else self.beta * self.state + self.gain * (a * w[k])
                out[k] = self.state
        return out

    def __call__(self, t: float) -> np.ndarray:
        """(m,) τ_d at one step's start t [s] (advances kind "noise" by one step)."""
        return self.rows(np.array([t]))[0]

    def describe(self) -> dict:
        """For a trajectory's meta."""
        out: dict = {"kind": self.kind, "magnitude": self.magnitude.tolist()}
        if self.kind == "step":
            out["t0"] = self.t0
        if self.kind == "sine":
            out.update(omega=self.omega, phase=self.phase)
        if self.kind == "noise":
            out["beta"] = self.beta
        return out

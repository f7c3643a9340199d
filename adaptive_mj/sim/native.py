"""The native closed loop: the same `laws.sliding.sliding_law` (and the plant's
regressor functions) compiled with numba into a C control callback, which
MuJoCo calls without the GIL; physics advances with mj_step(m, d, nstep)
in chunks, and Python only works between chunks (events, noise, logging,
divergence checks).

What the callback does at every call is exactly what loop._Controller does
in Python: measure [q, q'] (+ noise), give the law the RK4 stage estimate,
clamp u, and after the last stage advance θ̂ once with the RK4 weights. The
references at the stage times t_k + c_i h are evaluated in Python, vectorised,
before each chunk (MuJoCo's stage times are reproduced bit for bit).

Used automatically by loop.run for MuJoCo plants of order 2 whose law has
`native_params` (the sliding laws, and law plugins: their function is compiled the same
way, see adaptive_mj.laws.plugin); other laws and plants run in Python.
tests/test_native.py shows the two paths agree to 1e-12.

The callback finds its buffers through one module-level table of addresses
(CTX), so it is compiled once per process and regressor, not per run. Only
one native run can be active per process (MuJoCo's control callback is a
process-wide global anyway).
"""
from __future__ import annotations

import math

import numpy as np

from adaptive_mj.laws.common import clip_into, modify_rate
from adaptive_mj.laws.sliding import sliding_law, sliding_terms
from adaptive_mj.sim.numba_util import pointer, with_globals as _with_globals

_CTX = np.zeros(16, dtype=np.int64)  # buffer addresses, see _bind
_W = np.zeros(40)  # scalars shared with the callback, see W_* below
W_STAGE, W_ROW, W_NSTAGES, W_H, W_LO, W_HI, W_QADR, W_DADR, W_ACT, W_K, W_ADAPT, W_DZW, W_DZS, W_KR, W_PHI, \
    W_T, W_N, W_NTH = range(18)
W_INC, W_WEIGHTS = 20, 24  # 4 slots each
W_SIGMA, W_EMOD = 28, 29
W_DELAY, W_STEPK, W_HELD = 30, 31, 32  # control delay D [steps], steps run, the control held over a step
_cache: dict = {}




def compiled(form, plugin=None):
    """The cfunc for one regressor and law (cached by the functions' code and closure values).

    plugin: None for the built-in sliding laws (laws.sliding.sliding_law), or a plugin's law
    function (adaptive_mj.laws.plugin: law(x, ref, theta, phi, f, h, params, rate) -> (u, s)),
    compiled with numba the same way."""
    fns = (form.phi, form.f, form.h) + ((plugin,) if plugin is not None else ())
    key = tuple((fn.__code__, tuple(c.cell_contents for c in (fn.__closure__ or ()))) for fn in fns)
    if key in _cache:
        return _cache[key]
    import numba
    from numba import carray, types

    fptr, iptr = pointer(types.float64), pointer(types.int64)
    ctx_addr, w_addr = _CTX.ctypes.data, _W.ctypes.data
    phi_fn, f_fn, h_fn = numba.njit(form.phi), numba.njit(form.f), numba.njit(form.h)
    clip = numba.njit(clip_into)
    if plugin is None:
        sliding = numba.njit(_with_globals(sliding_law, sliding_terms=numba.njit(sliding_terms),
                                           modify_rate=numba.njit(modify_rate)))

        @numba.njit
        def law(x, r, th, W, coeffs, gamma, theta0, lower, upper, params, rate):
            u, s, _ = sliding(x, r, th, coeffs, W[W_K], gamma, W[W_ADAPT] > 0.5, W[W_DZW], W[W_DZS] > 0.5,
                              W[W_KR], W[W_PHI], W[W_SIGMA], W[W_EMOD], theta0, lower, upper, phi_fn, f_fn, h_fn,
                              rate)
            return u, s
    else:
        user = numba.njit(plugin)

        @numba.njit
        def law(x, r, th, W, coeffs, gamma, theta0, lower, upper, params, rate):
            u, s = user(x, r, th, phi_fn(x), f_fn(x), h_fn(x), params, rate)
            if W[W_ADAPT] < 0.5:
                for j in range(rate.shape[0]):
                    rate[j] = 0.0
            return float(u), float(s)

    @numba.cfunc(types.void(types.voidptr, types.voidptr), nogil=True)
    def callback(m, d):
        W = carray(fptr(w_addr), 40)
        ctx = carray(iptr(ctx_addr), 16)
        stage, row, nst = int(W[W_STAGE]), int(W[W_ROW]), int(W[W_NSTAGES])
        if stage >= nst:  # a call outside mj_step's stages (e.g. mj_forward): leave ctrl as it is
            return
        n, nth = int(W[W_N]), int(W[W_NTH])
        qpos, qvel, ctrl = carray(fptr(ctx[0]), 1 + int(W[W_QADR])), carray(fptr(ctx[1]), 1 + int(W[W_DADR])), \
            carray(fptr(ctx[2]), 1 + int(W[W_ACT]))
        ref = carray(fptr(ctx[3]), 1 << 30)
        noise = carray(fptr(ctx[4]), 1 << 30)
        rec = carray(fptr(ctx[5]), 1 << 30)
        theta = carray(fptr(ctx[6]), nth)
        rsum = carray(fptr(ctx[7]), nth)
        prev = carray(fptr(ctx[8]), nth)
        coeffs = carray(fptr(ctx[9]), n)
        gamma = carray(fptr(ctx[10]), nth)
        theta0, lower, upper = carray(fptr(ctx[11]), nth), carray(fptr(ctx[12]), nth), carray(fptr(ctx[13]), nth)
        h = W[W_H]
        x = np.empty(n)
        x[0] = qpos[int(W[W_QADR])] + noise[row * n]
        x[1] = qvel[int(W[W_DADR])] + noise[row * n + 1]
        r0 = (row * nst + stage) * (n + 1)
        r = ref[r0:r0 + n + 1]
        th = np.empty(nth)
        for j in range(nth):
            th[j] = theta[j] + (h * W[W_INC + stage]) * prev[j] if stage > 0 else theta[j]
        clip(th, lower, upper)  # projection: the stage estimate stays in the box too
        rate = np.zeros(nth)
        u, s = law(x, r, th, W, coeffs, gamma, theta0, lower, upper, carray(fptr(ctx[15]), 1 << 30), rate)
        u = min(max(u, W[W_LO]), W[W_HI])
        delay = int(W[W_DELAY])
        if delay > 0:  # apply the stage-0 control of D steps ago, held over the step (zero before)
            if stage == 0:
                ring = carray(fptr(ctx[14]), delay + 1)
                k = int(W[W_STEPK])
                ring[k % (delay + 1)] = u
                W[W_HELD] = ring[(k - delay) % (delay + 1)] if k >= delay else 0.0
            u = W[W_HELD]
        ctrl[int(W[W_ACT])] = u
        for j in range(nth):
            rsum[j] += W[W_WEIGHTS + stage] * rate[j]
            prev[j] = rate[j]
        if stage == 0:  # the step's row: t, true x, u, s, ref, theta_hat
            ncol = 1 + n + 2 + (n + 1) + nth
            o = row * ncol
            rec[o] = W[W_T]
            rec[o + 1] = qpos[int(W[W_QADR])]
            rec[o + 2] = qvel[int(W[W_DADR])]
            rec[o + 1 + n] = u
            rec[o + 2 + n] = s
            for i in range(n + 1):
                rec[o + 3 + n + i] = r[i]
            for j in range(nth):
                rec[o + 4 + 2 * n + j] = theta[j]
        stage += 1
        if stage == nst:  # end of the physics step: advance the estimates once
            for j in range(nth):
                theta[j] = theta[j] + h * rsum[j]
                rsum[j] = 0.0
            clip(theta, lower, upper)
            W[W_ROW] = row + 1
            W[W_STEPK] = W[W_STEPK] + 1.0
            W[W_T] = W[W_T] + h
            stage = 0
        W[W_STAGE] = stage

    _cache[key] = callback
    return callback


def supported(plant, law) -> bool:
    """Native path: a MuJoCo plant of order 2 (its state is [q, q'], which the callback reads
    directly), a sliding law, no time-varying disturbance (held per step in Python)."""
    return (hasattr(plant, "step_native") and getattr(plant, "form", None) is not None and plant.form.order == 2
            and hasattr(law, "native_params") and getattr(law, "native", True)
            and plant.stages in (1, 4) and plant.disturbance is None)


class NativeController:
    """Owns the buffers of one native run and steps the plant chunk by chunk."""


    def __init__(self, plant, law, reference, theta_hat0, max_rows: int, *, delay: int = 0):
        self.plant, self.law, self.reference = plant, law, reference
        self.delay = int(delay)
        self.ring = np.zeros(self.delay + 1)  # the last D + 1 stage-0 controls
        self.steps = 0
        p = law.native_params()
        self.callback = compiled(plant.form, plugin=p.get("plugin_law"))
        self.params = np.ascontiguousarray(p.get("plugin_params", np.zeros(1)), dtype=float)
        n, nth = plant.form.order, len(law.names)
        self.n, self.nth = n, nth
        self.nst = plant.stages
        self.ncol = 1 + n + 2 + (n + 1) + nth
        self.theta = np.array(theta_hat0, dtype=float)
        self.rsum = np.zeros(nth)
        self.prev = np.zeros(nth)
        self.coeffs = np.ascontiguousarray(p["coeffs"], dtype=float)
        self.gamma = np.ascontiguousarray(p["gamma"], dtype=float)
        self.theta0 = np.ascontiguousarray(p["theta0"], dtype=float)
        self.lower = np.ascontiguousarray(p["lower"], dtype=float)
        self.upper = np.ascontiguousarray(p["upper"], dtype=float)
        self.ref = np.zeros(max_rows * self.nst * (n + 1))
        self.noise = np.zeros(max_rows * n)
        self.rec = np.zeros(max_rows * self.ncol)
        lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (-math.inf, math.inf)
        from adaptive_mj.sim.loop import TABLEAU

        inc, weights = TABLEAU[self.nst]
        self.stage_offsets = np.asarray(inc)  # RK4: c_i = a_i (see loop.TABLEAU)
        W = _W
        W[:] = 0.0
        W[W_NSTAGES], W[W_H], W[W_LO], W[W_HI] = self.nst, plant.dt, lo, hi
        W[W_QADR], W[W_DADR], W[W_ACT] = plant._qadr, plant._dadr, plant.actuator_id
        W[W_K], W[W_ADAPT], W[W_DZW], W[W_DZS] = p["k"], float(p["adapt"]), p["dz_width"], float(p["dz_on_s"])
        W[W_KR], W[W_PHI], W[W_N], W[W_NTH] = p["K"], p["boundary_layer"], n, nth
        W[W_SIGMA], W[W_EMOD] = p["sigma"], p["e_mod"]
        W[W_DELAY] = self.delay
        W[W_INC:W_INC + len(inc)] = inc
        W[W_WEIGHTS:W_WEIGHTS + len(weights)] = weights
        d = plant.data
        for i, arr in enumerate((d.qpos, d.qvel, d.ctrl, self.ref, self.noise, self.rec, self.theta, self.rsum,
                                 self.prev, self.coeffs, self.gamma, self.theta0, self.lower, self.upper,
                                 self.ring, self.params)):
            _CTX[i] = arr.ctypes.data

    def chunk(self, rows: int, noise: np.ndarray | None):
        """Step `rows` physics steps; return (t, x, u, s, ref, theta_hat) rows, each (rows, ...)."""
        plant, n, nst, h = self.plant, self.n, self.nst, self.plant.dt
        t = np.empty(rows)
        t[0] = plant.time
        for i in range(1, rows):  # MuJoCo's own time accumulation, bit for bit
            t[i] = t[i - 1] + h
        stage_t = t[:, None] + h * self.stage_offsets[None, :]
        refs = self.reference(stage_t.ravel(), n)  # (n+1, rows*nst)
        self.ref[: refs.size] = refs.T.ravel()
        if noise is not None:
            self.noise[: rows * n] = noise.ravel()
        else:
            self.noise[: rows * n] = 0.0
        _W[W_STAGE], _W[W_ROW], _W[W_T], _W[W_STEPK] = 0.0, 0.0, t[0], float(self.steps)
        plant.step_native(rows)
        self.steps += rows
        if int(_W[W_ROW]) != rows:
            raise RuntimeError(f"native callback ran {int(_W[W_ROW])} steps, expected {rows}")
        rec = self.rec[: rows * self.ncol].reshape(rows, self.ncol)
        x = rec[:, 1:1 + n].copy()
        u = rec[:, 1 + n].copy()
        s = rec[:, 2 + n].copy()
        ref = rec[:, 3 + n:4 + 2 * n].copy()
        theta_hat = rec[:, 4 + 2 * n:].copy()
        return rec[:, 0].copy(), x, u, s, ref, theta_hat

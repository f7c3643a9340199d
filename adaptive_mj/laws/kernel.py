"""A law's compiled form, declared beside its kind: the kernel spec the analytic chunk engine
(adaptive_mj.sim.native_chunk) compiles into its closed loop. No numba and no adaptive_mj.sim here (laws/ is below
sim/ in the import-linter layers): only the spec and the pieces a kernel is written with.

A law object declares its kernel with ``chunk_kernel(order)`` (laws.protocol.Law; the default: None, the Python
path): a `LawKernel`, or None where it has no compiled form on a plant of that output order. The built-in ones sit
in their kinds' modules (laws.mrac.mrac_kernel, laws.first_order.first_order_kernel, laws.sliding.sliding_kernel,
laws.plugin.plugin_kernel); the engine finds them through the law object, with no list of law classes.

A kernel has one signature,

    kernel(x, r, th, g, a, lower, upper, rate) -> (u, s)

x (n,) the measured state, r (n+1,) the reference, th (n_theta,) the stage estimate, g the law's gains record (a
numpy record of `LawKernel.dtype`, read by field name), a the law's arrays end to end (`LawKernel.arrays`, the
layout its kernel reads), lower and upper the projection box (n_theta,), rate (n_theta,) out: θ̂' written there.
It is plain array code over scalar loops, the arithmetic the law's Python __call__ runs, so that both paths give
the same rows bit for bit.

What a kernel calls that the engine binds per variant are this module's placeholders, which a kernel imports by
name: `phi_fn`, `f_fn`, `h_fn` (the law's ModelForm: `LawKernel.form`) and `user_law` (a plain-array law function
in the law-plugin form, law(x, ref, theta, phi, f, h, params, rate) -> (u, s): `LawKernel.user_law`, which a
plugin's law and a built-in laws.plugin.KernelLaw give alike). The engine compiles the kernel with those globals
replaced (adaptive_mj.numba_util.jit_tree's `replace`); called unbound, each says so.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from adaptive_mj.form import ModelForm


@dataclass(frozen=True)
class LawKernel:
    """A law as the chunk engine compiles it: `fn` its kernel (the module docstring's signature), `dtype` and
    `gains` its gains record ((1,) of that dtype), `arrays` its arrays end to end, its box (`lower`, `upper`,
    (n_theta,) each), the `form` its φ, f, h come from (None: a kernel that calls none, MRAC's), `user_law` the
    law-plugin-form function it calls (None: none), `what`, the law in words for the compile note, and `psi`, MRAC's
    matched terms ψ(x) (None: none), bound as psi_fn."""

    fn: Callable
    dtype: np.dtype
    gains: np.ndarray
    arrays: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    form: ModelForm | None = None
    user_law: Callable | None = None
    what: str = ""
    psi: Callable | None = None  # MRAC's matched nonlinear terms ψ(x) (plain array code), bound as psi_fn


def f64(a) -> np.ndarray:
    """a as a C-contiguous float64 array (what the compiled code reads through an address)."""
    return np.ascontiguousarray(a, dtype=np.float64)


# --- what the engine binds per variant (numba_util.jit_tree's `replace`); unbound, they say so -------------------
def phi_fn(x):
    """φ(x) of the law's form (bound per variant)."""
    raise NotImplementedError("the chunk engine binds the law's form (adaptive_mj.sim.native_chunk.compiled)")


def f_fn(x):
    """f(x) of the law's form (bound per variant)."""
    raise NotImplementedError("the chunk engine binds the law's form (adaptive_mj.sim.native_chunk.compiled)")


def h_fn(x):
    """h(x) of the law's form (bound per variant)."""
    raise NotImplementedError("the chunk engine binds the law's form (adaptive_mj.sim.native_chunk.compiled)")


def psi_fn(x):
    """ψ(x) of MRAC's matched nonlinear terms (bound per variant: LawKernel.psi)."""
    raise NotImplementedError("the chunk engine binds the law's matched terms (adaptive_mj.sim.native_chunk.compiled)")


def user_law(x, r, th, phi, f, h, params, rate):
    """A law function in the law-plugin form (bound per variant: LawKernel.user_law)."""
    raise NotImplementedError("the chunk engine binds the law function (adaptive_mj.sim.native_chunk.compiled)")


def form_arrays(a, n, nth):
    """A form law's arrays (a = [the surface's coefficients (n), Γ (n_theta), θ₀ (n_theta), a law function's
    parameters]) as (coefficients, Γ, θ₀, parameters)."""
    return a[0:n], a[n:n + nth], a[n + nth:n + 2 * nth], a[n + 2 * nth:]


def form_law_arrays(coeffs, gamma, theta0, params=None) -> np.ndarray:
    """The arrays end to end that `form_arrays` reads back: coefficients (n,), Γ, θ₀ (n_theta,), parameters."""
    rest = [] if params is None else [f64(params).reshape(-1)]
    return np.concatenate([f64(coeffs).reshape(-1), f64(gamma), f64(theta0), *rest])

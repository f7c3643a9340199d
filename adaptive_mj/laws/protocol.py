"""The law interface: what the closed loop (adaptive_mj.sim), the dm_env front end and the log ask
of a law object, as a typing.Protocol (checked by mypy in .ci/run).

Every law satisfies `Law`: the built-in ones, a law plugin's `laws.plugin.PluginLaw`, and a user's
own object passed to ``adaptive_mj.run`` or ``adaptive_mj.env.load(law=...)``. A class that names
`Law` as its base inherits the defaults of the optional members, so a law in plain Python writes
only the four required ones (docs/ADDING_A_LAW.md).

Required:
  order        n, the order of the plant's output dynamics it controls (2 for a manipulator)
  names        (n_theta,) parameter names, in θ order
  law(t, x, ref, theta_hat) -> LawStep
               t [s]; x (n,) measured [y, y', ..., y^(n-1)], or (2, m) [q; q̇] on a plant of m
               joints; ref (n+1,) [y_d, ..., y_d^(n)], or (3, m); theta_hat (n_theta,) estimates
  lyapunov(s, theta_hat, theta, *, M=None) -> (N,) V per row
               s (N,) or (N, m); theta_hat, theta (N, n_theta); M (N, m, m) the plant's
               joint-space inertia at each row [kg m²], given on a plant with joints only
Optional (the default in brackets):
  bounds       (lower, upper), each (n_theta,): the projection box every stage estimate and every
               θ̂_{k+1} is clipped into [None: no box]
  has_filters  the law keeps filter state between calls (composite adaptation) [False]; the loop
               then calls, under continuous control only:
  reset()      when the controller is made (a new run) [nothing]
  step_begins(x)  at each physics step's start, with the measured state x (n,) [nothing]
  step_ends(xs, us, weights, h)  after each step: the stage states (n,) and applied controls the
               law saw, the integrator's weights b_i and the step h [s] [nothing]
  installed    where a law plugin comes from (adaptive_mj.plugins.Installed; the log records it)
               [None: not a plugin]
  native       a compiled control callback can run it (adaptive_mj.plants.one_dof_kernel for 1-DOF plants,
               manipulator_kernel for Slotine–Li) [False: the Python callback]
  native_params()  the numbers that callback takes (a dict, by name; a 1-DOF law's scalar gains as one
               record under "gains", read by field name: laws.sliding.SlidingGains, laws.plugin.PluginGains)
               [none: raises]
  chunk_kernel(order)  the law's compiled form in the analytic chunk engine (adaptive_mj.sim.native_chunk) on a
               plant of output order `order`: a laws.kernel.LawKernel, its kernel declared beside the law's kind
               (laws.mrac, laws.first_order, laws.sliding, laws.plugin's KernelLaw), or None [None: the Python
               path]
  adapt        the estimates move (False: a fixed-parameter baseline) [True]
  feedback()   the law's feedback on its tracking error, as the pre-flight check
               (adaptive_mj.sim.preflight) and the analyses (adaptive_mj.study.analysis) read it: a
               SurfaceFeedback (a 1-DOF law on its sliding variable s), a JointFeedback (a law of m
               joints: K_D and Λ), or None where it declares none (the pre-flight then does not check
               the run) [None]
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from adaptive_mj.laws.common import LawStep
from adaptive_mj.laws.kernel import LawKernel
from adaptive_mj.plugins import Installed

Box = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class SurfaceFeedback:
    """A 1-DOF law's feedback on its sliding variable s (s = x̃ for the first-order law).

    k: the gain on s in u [u per unit of s] (V' = -k s² in the ideal case); lam: λ of the surface
    s = (d/dt + λ)^(n-1) ỹ [1/s], None where s is the tracking error itself; effective: the gain of the
    linearised velocity feedback the pre-flight check scales by h(x)/d (k, plus K/Φ under robust
    sliding); surface_rate: what the surface adds to the loop's fastest mode, (n - 1) λ [1/s];
    keys: the scenario keys that set `effective`, as the pre-flight's fix names them."""

    k: float
    lam: float | None
    effective: float
    surface_rate: float
    keys: str


@dataclass(frozen=True)
class JointFeedback:
    """A law of m joints' feedback on s = q̃' + Λ q̃: kd K_D (m,) [N m s/rad] (V' = -sᵀ K_D s in the ideal
    case), lam Λ (m,) [1/s]."""

    kd: np.ndarray
    lam: np.ndarray


@dataclass(frozen=True)
class AirframeFeedback:
    """A flight law's attitude feedback M = −k_R e_R − k_Ω Ω (+ Ω × ĴΩ): kR [N m/rad], kW [N m s/rad]; the
    pre-flight check reads the attitude loop's fastest mode J ë + k_Ω ė + k_R e = 0 on each principal axis of the
    plant's true inertia."""

    kR: float
    kW: float


Feedback = SurfaceFeedback | JointFeedback | AirframeFeedback


class Law(Protocol):
    """A control law with adaptation (see the module docstring for every member)."""

    order: int
    names: tuple[str, ...]

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep: ...

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray: ...

    # --- optional members, with their defaults ---------------------------------------------
    has_filters: bool = False
    installed: Installed[object] | None = None
    native: bool = False
    adapt: bool = True

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) (n_theta,) of the projection, or None."""
        return None

    # (the defaults' bodies `return None` and `raise TypeError`, not `pass` or NotImplementedError:
    # a type checker takes a protocol member with such a trivial body for one a law must write)
    def reset(self) -> None:
        """Forget any state kept between calls (a new run)."""
        return None

    def step_begins(self, x: np.ndarray) -> None:
        """A physics step starts; x (n,): the measured state the law sees at its first stage."""
        return None

    def step_ends(self, xs: list, us: list, weights, h: float) -> None:
        """A physics step is done: its stage states and controls, the integrator's weights, h [s]."""
        return None

    def native_params(self) -> dict[str, Any]:
        """The numbers the compiled callback takes (asked only when `native`)."""
        raise TypeError(f"{type(self).__name__} has no compiled form (its native is False)")

    def chunk_kernel(self, order: int) -> LawKernel | None:
        """The law's compiled form in the analytic chunk engine on a plant of output order `order`, or None."""
        return None

    def feedback(self) -> Feedback | None:
        """The law's feedback gains (SurfaceFeedback, JointFeedback), or None where it declares none."""
        return None

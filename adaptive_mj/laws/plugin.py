"""Users' own laws, installed as packages: the entry-point group ``adaptive_mj.laws``.

A package registers a ``LawPlugin`` (a law over the 1-DOF model form) or a ``JointLawPlugin`` (a law over
a multi-joint rigid-body tree) under a name, in its pyproject.toml:

    [project.entry-points."adaptive_mj.laws"]
    my_emod = "my_emod_law:LAW"

and a scenario names it: ``law.kind = "my_emod"`` (or ``adaptive-mj run SCENARIO --law my_emod`` on any
scenario whose plant offers the form the law serves: adaptive_mj.laws.kinds). Nothing in a scenario imports
code: the law must be installed (docs/ADDING_A_LAW.md walks through two complete packages).

Each law is plain functions over arrays and floats, so that it can be compiled with numba into MuJoCo's
native control callback (adaptive_mj.plants.one_dof_kernel, .manipulator_kernel, built by
adaptive_mj.sim.native_mujoco) and run at built-in speed:

1-DOF (``LawPlugin``, the shape of the built-in ``laws.sliding.sliding_law``):

    law(x, ref, theta, phi, f, h, params, rate) -> (u, s)

      x (n,) measured state [y, y', ...]; ref (n+1,) [y_d, ..., y_d^(n)];
      theta (n_theta,) estimates θ̂ = [d̂, p̂...] (the plant's ModelForm order);
      phi (n_p,), f, h: the plant's known functions at x (d y^(n) = f + φᵀp + h u);
      params (n_params,): the law's declared keys, in declaration order [their units]; a per-parameter key
        (Param(per_parameter=True)) takes n_theta slots, in θ order;
      rate (n_theta,): write θ̂' here; return the control u [N or N m] and s.

Multi-joint (``JointLawPlugin``), over the plant's regressor Y(q, v, w, a) π + τ_known = M(q) a + C(q, v) w
+ g(q) + D v, evaluated at the point the law asks for, on the live MuJoCo kinematics of the measured q:

    point(x, ref, params, v, w, a)                       write v, w, a (m,) [rad/s, rad/s, rad/s²]
    law(x, ref, theta, Y, tau_known, params, u, s, rate) write u (m,) [N m], s (m,), rate (n_theta,)

      x (2, m) measured [q; q̇]; ref (3, m) [q_d; q̇_d; q̈_d]; theta (n_theta,) π̂ (the plant's parameter
      order, `list --plants` / the log's names); Y (m, n_theta), tau_known (m,) at (q, v, w, a).

Either may declare ``lyapunov(s, theta_hat, theta, params, M) -> V (N,)`` (plain numpy, vectorised over N
rows: s (N,) or (N, m), theta_hat and theta (N, n_theta), M (N, m, m) the plant's inertia at each row or
None on a 1-DOF plant); without it V is logged as NaN. ``gain`` names a per-parameter key that is Γ (the
adaptation stiffness, θ̂' = Γ⁻¹ ...), which the shared modifications divide by.

Either may declare ``feedback(params) -> SurfaceFeedback | JointFeedback`` (adaptive_mj.laws.protocol; params:
{key: value}, a float or, for a per-parameter key, an (n_theta,) array): its velocity feedback, which the
pre-flight check (adaptive_mj.sim.preflight) scales into the loop's fastest mode, so that a run past the sampled
loop's stability limit is warned of as a built-in law's is. Without it the check is skipped. Either way a study
runs every probe and judges it by its outcome (adaptive_mj.study.job.RECORD_PREFLIGHT).

What every plugin gets, as the built-in laws do (adaptive_mj.laws.common.plugin_rate, after the plugin wrote
its rate, on both paths): law.dead_zone (on |s| / ‖s‖ or the tracking error), law.sigma,
law.e_modification, law.theta0 and law.projection, unless the plugin declares a key of that name itself.
Its keys are declared with types and ranges (``Param``) and validated like built-in keys. The log records
the plugin's name, distribution, version and a hash of its source; ``replay --verify`` says when the
installed plugin differs or is missing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from adaptive_mj.errors import PluginError
from adaptive_mj.form import ModelForm
from adaptive_mj.laws.common import (NO_MODIFICATION, DeadZone, DeadZoneOn, LawStep, Modification, as_gamma,
                                     Gains, plugin_rate, record_dtype)
from adaptive_mj.laws.kernel import LawKernel, f64, f_fn, form_arrays, form_law_arrays, h_fn, phi_fn, user_law
from adaptive_mj.laws.protocol import Box, Feedback, Law
from adaptive_mj.plugins import Installed, discover

ENTRY_POINT_GROUP = "adaptive_mj.laws"


@dataclass(frozen=True)
class Param:
    """A scenario key of a plugin law: law.<name> = number. default None: required;
    gt / ge: the range (exclusive / inclusive lower bound); unit and doc for `list --laws`.
    per_parameter: one number per estimated parameter, given as a number (the same for all) or a table
    {parameter name = number} in the plant's parameter order; it takes n_theta slots of params."""

    name: str
    default: float | None = None
    gt: float | None = None
    ge: float | None = None
    unit: str = ""
    doc: str = ""
    per_parameter: bool = False

    def describe(self) -> str:
        """`name [unit] = default` as `list --laws` shows it (`name[θ]` for a per-parameter key)."""
        text = self.name + ("[θ]" if self.per_parameter else "") + (f" [{self.unit}]" if self.unit else "")
        return text + ("" if self.default is None else f" = {self.default:g}")


@dataclass(frozen=True)
class LawPlugin:
    """What a package registers for a 1-DOF law: its law function (module docstring), its keys, whether it
    adapts (a fixed-parameter law: θ̂ stays at law.initial_estimates / law.nominal), its Lyapunov function
    (or None: V logged as NaN), the per-parameter key that is Γ (or None: Γ = 1 for the shared leakage), the
    plant forms it serves (adaptive_mj.laws.kinds.Form values) and the orders n of the plants it is written
    for (None: any; a compiled law has no bounds checks, so an order-2 law that reads ref[2] must say (2,))."""

    law: Callable
    params: tuple[Param, ...] = ()
    adapts: bool = True
    doc: str = ""
    lyapunov: Callable | None = None
    gain: str | None = None
    forms: tuple[str, ...] = ("model",)
    orders: tuple[int, ...] | None = None  # the plant orders n the law is written for (None: any)
    feedback: Callable[[dict[str, Any]], Feedback] | None = None  # for the pre-flight check (module docstring)

    def __post_init__(self):
        names = [p.name for p in self.params]
        if self.gain is not None and not any(p.name == self.gain and p.per_parameter for p in self.params):
            raise ValueError(f"gain {self.gain!r} must name a per-parameter Param (params: {', '.join(names)})")
        if len(set(names)) != len(names):
            raise ValueError(f"params declares a key twice: {', '.join(names)}")
        allowed = self._allowed_forms()
        if not self.forms or not set(self.forms) <= set(allowed):
            raise ValueError(f"{type(self).__name__}.forms must be {allowed!r} (a law over MRAC's state form is "
                             f"not a plugin yet), got {self.forms!r}")

    def _allowed_forms(self) -> tuple[str, ...]:
        """The forms this kind of plugin's functions are called in (the model form's phi, f, h)."""
        return ("model",)

    def named(self, params: np.ndarray, n_theta: int) -> dict[str, Any]:
        """The params array the law function takes, by key: a float each, an (n_theta,) array for a per-parameter
        key."""
        out: dict[str, Any] = {}
        for p in self.params:
            where = self.layout(n_theta)[p.name]
            out[p.name] = np.array(params[where]) if p.per_parameter else float(params[where][0])
        return out

    def describe_keys(self) -> str:
        """Its keys as `list --laws` shows them."""
        return ", ".join(p.describe() for p in self.params)

    def layout(self, n_theta: int) -> dict[str, slice]:
        """Where each key lies in the params array the law function takes: {name: slice} (a per-parameter
        key takes n_theta slots, in θ order)."""
        out, at = {}, 0
        for p in self.params:
            width = n_theta if p.per_parameter else 1
            out[p.name] = slice(at, at + width)
            at += width
        return out


@dataclass(frozen=True)
class JointLawPlugin(LawPlugin):
    """What a package registers for a multi-joint law: `point` chooses where the plant's regressor is
    evaluated, `law` computes the torques, s and the rate from it (module docstring)."""

    point: Callable | None = None
    forms: tuple[str, ...] = ("rigid_body",)
    orders: tuple[int, ...] | None = (2,)

    def _allowed_forms(self) -> tuple[str, ...]:
        """A multi-joint law is called with the rigid-body form's regressor."""
        return ("rigid_body",)

    def __post_init__(self):
        super().__post_init__()
        if self.point is None:
            raise ValueError("a JointLawPlugin needs point(x, ref, params, v, w, a): where the regressor is evaluated")


def installed() -> dict[str, Installed[LawPlugin]]:
    """Every law registered under ENTRY_POINT_GROUP, by name (adaptive_mj.plugins.discover)."""
    return discover(ENTRY_POINT_GROUP, LawPlugin, "law", lambda p: p.law)


@dataclass(frozen=True)
class Shared:
    """The shared modifications a plugin's rate goes through (laws.common.plugin_rate): the dead-zone width
    [unit of its signal] and whether its signal is s (else the tracking error), σ [1/s], ν, θ₀, the box
    (lower, upper) and Γ (each (n_theta,))."""

    dz_width: float
    dz_on_s: bool
    sigma: float
    e_mod: float
    theta0: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    gamma: np.ndarray

    @classmethod
    def of(cls, n_theta: int, *, gamma=None, dead_zone: DeadZone | None = None,
           modification: Modification | None = None) -> "Shared":
        """From the law's Γ (None: ones), dead-zone and modification (its θ₀ already resolved by the builder)."""
        g = np.ones(n_theta) if gamma is None else as_gamma(gamma, n_theta)
        sigma, e_mod, theta0, lower, upper = (modification or NO_MODIFICATION).arrays(n_theta, gamma=g)
        return cls(0.0 if dead_zone is None else float(dead_zone.width),
                   dead_zone is None or dead_zone.on is DeadZoneOn.S, sigma, e_mod, theta0, lower, upper, g)


@dataclass(frozen=True)
class PluginGains(Gains):
    """The scalars of the shared modifications a compiled 1-DOF plugin law reads by name
    (adaptive_mj.plants.one_dof_kernel reads them as fields of a PLUGIN_GAINS record, through its address): the
    dead-zone's width and whether its signal is |s| (else |ỹ|), σ, ν, and whether the law adapts
    (laws.common.plugin_rate)."""

    dz_width: float
    sigma: float
    e_mod: float
    adapt: bool
    dz_on_s: bool


PLUGIN_GAINS = record_dtype(PluginGains)


class _PluginBase(Law):
    """What the 1-DOF and the multi-joint kernel laws share (a plugin's, and a built-in kind's written to the
    plugin interface): the declaration (a LawPlugin), its params, the shared modifications, the Lyapunov hook and
    the native flag."""

    installed: Installed[LawPlugin] | None = None  # where a plugin comes from; None: a built-in kind's
    native = True  # set False to force the Python callback (simulation.python_callback)

    def _setup(self, plugin: LawPlugin, names, params: np.ndarray, shared: Shared | None,
               modification: Modification | None, *, kind: str, installed: Installed[LawPlugin] | None = None):
        self.installed = installed
        self.plugin = plugin
        self.kind = kind
        self.names = tuple(names)
        self.params = np.ascontiguousarray(params, dtype=float)
        self.adapt = bool(self.plugin.adapts)
        self.shared = shared if shared is not None else Shared.of(len(self.names))
        self.modification = modification or NO_MODIFICATION

    @property
    def bounds(self) -> Box | None:
        """(lower, upper) of law.projection, or None."""
        return self.modification.box(len(self.names), self.shared.gamma) if self.adapt else None

    def _error(self, t: float, exc: Exception) -> PluginError:
        inst = self.installed
        who = (f"law plugin {inst.name!r} ({inst.distribution} {inst.version})" if inst is not None
               else f"law kind {self.kind!r}")
        return PluginError(f"{who} raised at t = {t:.6g} s: {type(exc).__name__}: {exc}")

    def _shared_rate(self, rate: np.ndarray, theta_hat: np.ndarray, s_abs: float, e_abs: float) -> None:
        sh = self.shared
        plugin_rate(rate, theta_hat, s_abs, s_abs if sh.dz_on_s else e_abs, self.adapt, sh.dz_width, sh.sigma,
                    sh.e_mod, sh.theta0, sh.gamma, sh.lower, sh.upper)

    def gains(self) -> PluginGains:
        """The shared modifications' scalars, by name."""
        sh = self.shared
        return PluginGains(dz_width=sh.dz_width, sigma=sh.sigma, e_mod=sh.e_mod, adapt=self.adapt, dz_on_s=sh.dz_on_s)

    def native_params(self) -> dict[str, Any]:
        """Its parameters, "gains" (the PLUGIN_GAINS record of `gains()`) and the shared modifications' arrays by
        name (a multi-joint plugin's, for adaptive_mj.plants.manipulator_kernel; PluginLaw's own for the 1-DOF)."""
        sh = self.shared
        return {"plugin_params": self.params, "gains": self.gains().record(), "theta0": sh.theta0,
                "lower": sh.lower, "upper": sh.upper, "gamma": sh.gamma}

    def feedback(self) -> Feedback | None:
        """The plugin's declared velocity feedback (LawPlugin.feedback) at its keys' values, or None."""
        fn = self.plugin.feedback
        return None if fn is None else fn(self.plugin.named(self.params, len(self.names)))

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """The plugin's declared V (LawPlugin.lyapunov), or NaN when it declares none (the log's V says so)."""
        fn = self.plugin.lyapunov
        if fn is None:
            return np.full(np.shape(s)[:1], np.nan)
        return np.asarray(fn(np.asarray(s, dtype=float), np.asarray(theta_hat, dtype=float),
                             np.asarray(theta, dtype=float), self.params, M), dtype=float)


def plugin_kernel(x, r, th, g, a, lower, upper, rate):
    """A 1-DOF law function in the plugin form (laws.kernel.user_law: law(x, ref, theta, phi, f, h, params, rate)
    -> (u, s), a plugin's or a built-in KernelLaw's) as the chunk engine compiles it (laws.kernel's signature),
    then the shared modifications every such law gets (laws.common.plugin_rate), as KernelLaw does in Python; g a
    PLUGIN_GAINS record, a = [zeros (n), Γ, θ₀, the law's params] (laws.kernel.form_arrays)."""
    _, gamma, theta0, params = form_arrays(a, x.shape[0], th.shape[0])
    u, s = user_law(x, r, th, phi_fn(x), f_fn(x), h_fn(x), params, rate)
    s_abs = abs(s)
    signal = s_abs if g.dz_on_s else abs(r[0] - x[0])
    plugin_rate(rate, th, s_abs, signal, g.adapt, g.dz_width, g.sigma, g.e_mod, theta0, gamma, lower, upper)
    return float(u), float(s)


class KernelLaw(_PluginBase):
    """A 1-DOF law whose law is a plain-array function in the plugin form (a LawPlugin's `law`: the module
    docstring), with the loop's law interface (laws.protocol.Law) and the shared modifications every plugin gets.
    A built-in law kind's builder returns one (docs/ADDING_A_LAW.md): it runs compiled as a plugin's law does, in
    MuJoCo's 1-DOF callback (``native_params``: "plugin_law", adaptive_mj.plants.one_dof_kernel) and in the
    analytic chunk engine (``chunk_kernel``: plugin_kernel). PluginLaw is the same law of an installed plugin.

    plugin: the declaration (its law, keys, adapts, lyapunov, gain, feedback); form: the plant's ModelForm; params:
    the declared keys' values laid out as LawPlugin.layout says; kind: its law.kind (for messages)."""

    def __init__(self, plugin: LawPlugin, form: ModelForm, params: np.ndarray, *, kind: str,
                 shared: Shared | None = None, modification: Modification | None = None,
                 installed: Installed[LawPlugin] | None = None):
        if isinstance(plugin, JointLawPlugin):
            raise TypeError("a JointLawPlugin's law is a JointKernelLaw's (a plant of joints), not a 1-DOF KernelLaw")
        self._setup(plugin, form.names, params, shared, modification, kind=kind, installed=installed)
        self.form = form
        self.order = form.order

    def native_params(self) -> dict[str, Any]:
        """What adaptive_mj.plants.one_dof_kernel needs: the function and its parameters, "gains" (the PLUGIN_GAINS
        record of `gains()`) and the shared modifications' arrays by name (coeffs: the sliding law's, unused)."""
        sh = self.shared
        return {"plugin_law": self.plugin.law, "plugin_params": self.params, "gains": self.gains().record(),
                "coeffs": np.zeros(self.order), "gamma": sh.gamma, "theta0": sh.theta0, "lower": sh.lower,
                "upper": sh.upper}

    def chunk_kernel(self, order: int) -> LawKernel | None:
        """Its compiled form in the analytic chunk engine (laws.kernel: plugin_kernel over the function and
        `native_params`) on a plant of its form's order; None on another, or when its `native` is off."""
        if not self.native or self.form.order != order:
            return None
        p = self.native_params()
        fn = self.plugin.law
        who = (f"law plugin {fn.__module__}.{fn.__qualname__}" if self.installed is not None
               else f"law kind {self.kind!r} ({fn.__module__}.{fn.__qualname__})")
        return LawKernel(plugin_kernel, PLUGIN_GAINS, p["gains"],
                         form_law_arrays(f64(p["coeffs"]).reshape(-1)[:self.order], p["gamma"], p["theta0"],
                                         p["plugin_params"]),
                         f64(p["lower"]), f64(p["upper"]), self.form, fn, what=who)

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        form = self.form
        rate = np.zeros(len(self.names))
        try:
            u, s = self.plugin.law(x, ref, theta_hat, form.phi(x), form.f(x), form.h(x), self.params, rate)
        except Exception as exc:  # the plugin's own code: one line naming it, not a traceback
            raise self._error(t, exc) from exc
        self._shared_rate(rate, theta_hat, abs(float(s)), abs(float(ref[0] - x[0])))
        return LawStep(float(u), rate, float(s), math.nan)


class PluginLaw(KernelLaw):
    """An installed plugin's law on a 1-DOF plant (a KernelLaw of its LawPlugin; `installed` says where it comes
    from, which the log records); ``native_params`` hands the function and its parameters to the native callback
    (adaptive_mj.plants.one_dof_kernel), ``chunk_kernel`` to the analytic chunk engine."""

    def __init__(self, installed: Installed[LawPlugin], form: ModelForm, params: np.ndarray, *,
                 shared: Shared | None = None, modification: Modification | None = None):
        super().__init__(installed.plugin, form, params, kind=installed.name, shared=shared, modification=modification,
                         installed=installed)


class JointKernelLaw(_PluginBase):
    """A JointLawPlugin's law on a plant of m joints (adaptive_mj.plants.manipulator), with the loop's law
    interface; regressor(v, w, a) -> (Y (m, n_theta), τ_known (m,)) is the plant's, at its current q. A built-in
    kind's (installed None) and an installed plugin's (JointPluginLaw) run compiled alike: the arm callback
    (adaptive_mj.plants.manipulator_kernel) compiles the functions native_params hands it (docs/ADDING_A_LAW.md)."""

    order = 2
    native = True  # plain array code: compiled into the arm callback (plants.manipulator_kernel.plugin_functions)

    def __init__(self, plugin: LawPlugin, regressor, names, m: int, params: np.ndarray, *, kind: str,
                 shared: Shared | None = None, modification: Modification | None = None,
                 installed: Installed[LawPlugin] | None = None):
        if not isinstance(plugin, JointLawPlugin):
            raise TypeError("a JointKernelLaw's declaration is a JointLawPlugin (point and law)")
        self._setup(plugin, names, params, shared, modification, kind=kind, installed=installed)
        self.regressor = regressor
        self.m = int(m)

    def native_params(self) -> dict[str, Any]:
        """Its parameters, "gains" and the shared modifications' arrays (_PluginBase.native_params), and the
        functions: "plugin_law" and "plugin_point" (adaptive_mj.plants.manipulator_kernel)."""
        plugin = self.plugin
        assert isinstance(plugin, JointLawPlugin)
        return {**super().native_params(), "plugin_law": plugin.law, "plugin_point": plugin.point}

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        plugin, m = self.plugin, self.m
        assert isinstance(plugin, JointLawPlugin) and plugin.point is not None
        v, w, a = np.zeros(m), np.zeros(m), np.zeros(m)
        u, s, rate = np.zeros(m), np.zeros(m), np.zeros(len(self.names))
        try:
            plugin.point(x, ref, self.params, v, w, a)
            Y, tau_known = self.regressor(v, w, a)
            plugin.law(x, ref, theta_hat, Y, tau_known, self.params, u, s, rate)
        except Exception as exc:  # the plugin's own code: one line naming it, not a traceback
            raise self._error(t, exc) from exc
        self._shared_rate(rate, theta_hat, joint_norm(s), tracking_error_norm(x, ref))
        return LawStep(u, rate, s, a)


class JointPluginLaw(JointKernelLaw):
    """An installed JointLawPlugin's law (a JointKernelLaw of it; `installed` says where it comes from, which the
    log records); ``native_params`` hands the functions and parameters to adaptive_mj.plants.manipulator_kernel."""

    native = True

    def __init__(self, installed: Installed[LawPlugin], regressor, names, m: int, params: np.ndarray, *,
                 shared: Shared | None = None, modification: Modification | None = None):
        super().__init__(installed.plugin, regressor, names, m, params, kind=installed.name, shared=shared,
                         modification=modification, installed=installed)


def joint_norm(v) -> float:
    """‖v‖ as a plain sum of squares (the compiled callback's order of operations, not np.linalg.norm's)."""
    acc = 0.0
    for j in range(v.shape[0]):
        acc += v[j] * v[j]
    return math.sqrt(acc)


def tracking_error_norm(x, ref) -> float:
    """‖q̃‖ = ‖q_d − q‖ of x (2, m) and ref (3, m), as a plain sum of squares (compiled the same way)."""
    acc = 0.0
    for j in range(x.shape[1]):
        e = ref[0, j] - x[0, j]
        acc += e * e
    return math.sqrt(acc)

"""Users' own laws, installed as packages: the entry-point group ``adaptive_mj.laws``.

A package registers a ``LawPlugin`` under a name, in its pyproject.toml:

    [project.entry-points."adaptive_mj.laws"]
    my_emod = "my_emod_law:LAW"

and a scenario names it: ``law.kind = "my_emod"``. Nothing in a scenario imports code:
the law must be installed (docs/ADDING_A_LAW.md walks through a complete package).

The law is one plain function over arrays and floats, the shape of the built-in
``laws.sliding.sliding_law``, so that it can be compiled with numba into MuJoCo's
native control callback (adaptive_mj.sim.native) and run at built-in speed:

    law(x, ref, theta, phi, f, h, params, rate) -> (u, s)

      x (n,) measured state [y, y', ...]; ref (n+1,) [y_d, ..., y_d^(n)];
      theta (n_theta,) estimates θ̂ = [d̂, p̂...] (the plant's ModelForm order);
      phi (n_p,), f, h: the plant's known functions at x (d y^(n) = f + φᵀp + h u);
      params (n_params,): the law's declared keys, in declaration order [their units];
      rate (n_theta,): write θ̂' here; return the control u [N or N m] and s.

Its keys are declared with types and ranges (``Param``) and validated like built-in
keys. The log records the plugin's name, distribution, version and a hash of its
source; ``replay --verify`` says when the installed plugin differs or is missing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.laws.common import LawStep
from adaptive_mj.laws.protocol import Law
from adaptive_mj.plugins import Installed, discover

ENTRY_POINT_GROUP = "adaptive_mj.laws"


@dataclass(frozen=True)
class Param:
    """A scenario key of a plugin law: law.<name> = number. default None: required;
    gt / ge: the range (exclusive / inclusive lower bound); unit and doc for `list --laws`."""

    name: str
    default: float | None = None
    gt: float | None = None
    ge: float | None = None
    unit: str = ""
    doc: str = ""


@dataclass(frozen=True)
class LawPlugin:
    """What a package registers: its law function (module docstring), its keys, and whether
    it adapts (a fixed-parameter law: θ̂ stays at law.initial_estimates / law.nominal)."""

    law: Callable
    params: tuple[Param, ...] = ()
    adapts: bool = True
    doc: str = ""


def installed() -> dict[str, Installed[LawPlugin]]:
    """Every law registered under ENTRY_POINT_GROUP, by name (adaptive_mj.plugins.discover)."""
    return discover(ENTRY_POINT_GROUP, LawPlugin, "law", lambda p: p.law)


class PluginLaw(Law):
    """A plugin's law on a 1-DOF plant, with the loop's law interface (laws.protocol.Law);
    ``native_params`` hands the function and its parameters to the native callback
    (adaptive_mj.sim.native)."""

    installed: Installed[LawPlugin]

    def __init__(self, installed: Installed[LawPlugin], form: ModelForm, params: np.ndarray):
        self.installed = installed
        self.plugin = installed.plugin
        self.form = form
        self.order = form.order
        self.names = form.names
        self.params = np.ascontiguousarray(params, dtype=float)
        self.adapt = bool(self.plugin.adapts)

    native = True  # set False to force the Python callback (simulation.python_callback)

    def native_params(self) -> dict[str, Any]:
        """What adaptive_mj.sim.native needs: the function and its parameters (the sliding-law
        slots are neutral: no projection, no leakage)."""
        n = len(self.names)
        return {"plugin_law": self.plugin.law, "plugin_params": self.params, "coeffs": np.zeros(self.order),
                "k": 0.0, "gamma": np.ones(n), "adapt": self.adapt, "dz_width": 0.0, "dz_on_s": True, "K": 0.0,
                "boundary_layer": 1.0, "sigma": 0.0, "e_mod": 0.0, "theta0": np.zeros(n),
                "lower": np.full(n, -np.inf), "upper": np.full(n, np.inf)}

    def __call__(self, t: float, x: np.ndarray, ref: np.ndarray, theta_hat: np.ndarray) -> LawStep:
        form = self.form
        rate = np.zeros(len(self.names))
        u, s = self.plugin.law(x, ref, theta_hat, form.phi(x), form.f(x), form.h(x), self.params, rate)
        if not self.adapt:
            rate[:] = 0.0
        return LawStep(float(u), rate, float(s), math.nan)

    def lyapunov(self, s, theta_hat, theta, *, M: np.ndarray | None = None) -> np.ndarray:
        """A plugin declares no Lyapunov function: NaN (the log's V column says so)."""
        return np.full(np.shape(s), np.nan)

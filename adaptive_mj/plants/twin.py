"""The analytic twin: the same equation d y^(n) = f + phi p + h u integrated
without MuJoCo, with the same true parameters and the same law object.

Integrators mirror MuJoCo's so a twin and its MuJoCo plant can be compared
step for step:
  "rk4":   classic Runge-Kutta 4; the policy is evaluated at t, t+h/2,
           t+h/2, t+h exactly like MuJoCo's control callback under RK4.
  "euler": semi-implicit Euler like MuJoCo's (highest derivative first,
           then each lower one with the freshly updated value). MuJoCo's
           Euler also treats joint damping implicitly; the twin does not.

It also hosts the lecture's first-order example x' = sin x - a x + b x² + u.
"""
from __future__ import annotations

import enum
from typing import TYPE_CHECKING, Callable

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.plants import BuiltPlant
from adaptive_mj.plants.analytic import AnalyticKernel, AnalyticPlant
from adaptive_mj.plants.protocol import Plant, Policy
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants.kinds import PlantKind, first_order, register
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Key, Table
from adaptive_mj.numba_util import scalar_power

if TYPE_CHECKING:
    from adaptive_mj.plants.mujoco_plant import MujocoPlant


class Integrator(enum.Enum):
    RK4 = "rk4"
    EULER = "euler"


def twin_params(plant: TwinPlant) -> tuple:
    """(θ (n_theta,) of the form the twin integrates, d_known: the form has d = 1): what twin_rate reads."""
    return np.ascontiguousarray(plant.form_theta, dtype=np.float64), plant.form.d_name is None


# The plant form's functions twin_rate calls, bound per plant (KERNEL.functions); unbound, they say so.
def plant_phi(x):
    raise NotImplementedError("twin_rate runs with the plant's form bound (KERNEL.functions)")


def plant_f(x):
    raise NotImplementedError("twin_rate runs with the plant's form bound (KERNEL.functions)")


def plant_h(x):
    raise NotImplementedError("twin_rate runs with the plant's form bound (KERNEL.functions)")


def twin_rate(p, x, u, force, out):
    """out (n,) = x' of the twin at state x (n,) under u and the external force [N or N m]: x[1:], then
    y^(n) = (f + φ·p + h u + force) / d (ModelForm.highest_derivative, its operations in its order: φ·p summed
    from 0 with no fused multiply-add, as form.plain_dot sums it; θ = [d, p] or, d_known, θ = p and d = 1), the
    plant's form (plant_phi, plant_f, plant_h)."""
    theta, d_known = p
    n = x.shape[0]
    for i in range(n - 1):
        out[i] = x[i + 1]
    first = 0 if d_known else 1
    d = 1.0 if d_known else theta[0]
    phi = plant_phi(x)
    dot = 0.0
    for j in range(phi.shape[0]):
        dot += phi[j] * theta[first + j]
    out[n - 1] = (plant_f(x) + dot + plant_h(x) * u + force) / d


def twin_state(p, x, y):
    """y (n,) = x: the law sees the twin's state."""
    for i in range(x.shape[0]):
        y[i] = x[i]


MAX_ORDER = 3  # the twin's order n at most in the compiled chunk (the heave vehicle's lag is order 3)


def _form_functions(plant: TwinPlant) -> dict:
    form = plant.form
    return {"plant_phi": form.phi, "plant_f": form.f, "plant_h": form.h}


def _compiled_supports(plant: TwinPlant) -> bool:
    return plant.stages in (1, 4) and plant.order <= MAX_ORDER


#: the twin's dynamics, for both paths (plants.analytic.AnalyticKernel)
KERNEL = AnalyticKernel("twin", params=twin_params, rate=twin_rate, observe=twin_state, functions=_form_functions,
                        supports=_compiled_supports)


class TwinPlant(AnalyticPlant):
    """form: the plant's structure; theta: (n_theta,) true parameters;
    dt: step [s]; ctrl_range: (lo, hi) or None; x0: (n,) initial state.
    A FormPlant (adaptive_mj.plants.protocol)."""

    joint_shape: tuple[int, ...] = ()  # 1-DOF: scalar y and u
    joint_names: tuple[str, ...] = ()
    first_contact: tuple[float, str] | None = None  # no contacts in the analytic twin
    joint_limits: np.ndarray | None = None  # a 1-DOF plant's joint is not limited
    kernel = KERNEL

    def __init__(self, form: ModelForm, theta, *, dt: float, integrator: Integrator = Integrator.RK4,
                 ctrl_range: tuple[float, float] | None = None, x0=None):
        self.form = form
        self._theta = np.array(theta, dtype=float)
        self.dt = float(dt)
        self.integrator = Integrator(integrator)
        self.ctrl_range = ctrl_range
        self.x = np.zeros(form.order) if x0 is None else np.array(x0, dtype=float)
        self._policy: Policy | None = None
        self.force_offset = 0.0  # constant external force, enters like h*u [N or N*m]
        self.disturbance: Callable[[float], float] | None = None  # t -> external force, at each step's start
        self.init_steps(form.order)

    @property
    def order(self) -> int:
        """n: the order of the form."""
        return self.form.order

    @property
    def names(self) -> tuple[str, ...]:
        """Names of θ, as the form orders them."""
        return self.form.names

    @property
    def stages(self) -> int:
        """Policy calls per step: 4 under RK4, else 1."""
        return 4 if self.integrator is Integrator.RK4 else 1

    def set_state(self, x0) -> None:
        self.x = np.array(x0, dtype=float)
        self.restart()

    def observe(self) -> np.ndarray:
        return self.x.copy()

    def true_theta(self) -> np.ndarray:
        return self._theta

    def set_true_theta(self, theta) -> None:
        """Change the true parameters (an event on the twin)."""
        self._theta = np.array(theta, dtype=float)

    @property
    def form_theta(self) -> np.ndarray:
        """(n_theta,) θ of the form this plant integrates (its true parameters; a subclass may name others)."""
        return self._theta


def lecture_first_order_form() -> ModelForm:
    """x' = sin x + [-x, x²] . [a, b] + u  (lecture: x' = sin x - a x + b x² + u)."""
    return ModelForm(
        order=1,
        p_names=("a", "b"),
        phi=lambda x: np.array([-x[0], x[0] * x[0]]),
        f=lambda x: float(np.sin(x[0])),
        d_name=None,
    )


def sin_squared_form() -> ModelForm:
    """The lecture's phase-space example: x' = sin²(x) p + u (one unknown p, f = 0). sin² is numpy's scalar
    power (numba_util.scalar_power: the C library's pow, which the compiled loop calls too)."""
    return ModelForm(order=1, p_names=("p",), phi=lambda x: np.array([scalar_power(np.sin(x[0]), 2)]), d_name=None)


def twin_of(plant: MujocoPlant, *, integrator: Integrator | None = None) -> TwinPlant:
    """A twin with the MuJoCo plant's form, true theta, timestep, limits and state."""
    import mujoco  # only the bridge from a MuJoCo plant needs it

    if integrator is None:
        rk4 = plant.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
        integrator = Integrator.RK4 if rk4 else Integrator.EULER
    return TwinPlant(plant.form, plant.true_theta().copy(), dt=plant.dt, integrator=integrator,
                     ctrl_range=plant.ctrl_range, x0=plant.observe())


# --- built from a scenario ------------------------------------------------------
def scenario_integrator(scn) -> Integrator:
    return Integrator.RK4 if scn.simulation.integrator == "rk4" else Integrator.EULER


def from_theta(scn, form: ModelForm) -> TwinPlant:
    """The twin of `form` with the scenario's plant.theta, timestep (default 1 ms),
    integrator and plant.ctrl_range."""
    p, sim = scn.plant, scn.simulation
    dt = sim.timestep if sim.timestep is not None else 0.001
    return TwinPlant(form, list(p.theta.values()), dt=dt, integrator=scenario_integrator(scn),
                     ctrl_range=p.ctrl_range)


def as_backend(scn, plant: MujocoPlant) -> Plant:
    """`plant` itself, or its twin when plant.backend = "twin" (with plant.ctrl_range if given)."""
    p = scn.plant
    if p.backend != "twin":
        return plant
    twin = twin_of(plant, integrator=scenario_integrator(scn))
    if p.ctrl_range is not None:
        twin.ctrl_range = p.ctrl_range
    return twin


def model_source(scn) -> None:
    """plant.kind = "first_order" has no model."""
    return None


def from_scenario(scn, source) -> BuiltPlant:
    """plant.kind = "first_order": the lecture's x' = sin x - a x + b x² + u (or the
    phase-space example x' = sin²x p + u with plant.regressor = "sin_squared")."""
    form = sin_squared_form() if scn.plant.regressor == "sin_squared" else lecture_first_order_form()
    return BuiltPlant(from_theta(scn, form))


# --- its scenario keys -----------------------------------------------------------
#: plant.regressor: the form of each (its θ names are plant.theta's keys)
FORMS: dict[str, Callable[[], ModelForm]] = {"lecture": lecture_first_order_form, "sin_squared": sin_squared_form}
REGRESSOR = Key("regressor", "string", default="lecture", bounds="one of 'lecture', 'sin_squared'",
                doc="x' = sin x - a x + b x² + u (θ = a, b) or x' = sin²(x) p + u (θ = p)")


def theta_names(t: Table) -> tuple[str, ...]:
    """plant.theta's keys, in order: those of plant.regressor's form (an unknown one: the lecture's)."""
    raw = t.data.get("regressor", "lecture")
    return FORMS.get(raw if isinstance(raw, str) else "lecture", lecture_first_order_form)().names


def _regressor(t: Table, fields: dict) -> dict:
    """plant.regressor (read after plant.ctrl_range)."""
    return {"regressor": t.string("regressor", "lecture", choices=tuple(FORMS))}


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "first_order"
KIND = register(PlantKind(
    "first_order", __name__, frozenset({Form.MODEL}), output_unit="-", control_unit="-",
    params={"a": "-", "b": "-", "p": "-"},
    default_model=None, doc="the lecture's first-order plant x' = f + phi p + u",
    default_law="first_order_adaptive",
    keys=tuple(k for k in plant_keys.keys(REGRESSOR) if k.name != "model"),
    reader=plant_keys.SharedReader(backend=("twin", "it is not a mechanical system"), theta=theta_names,
                                   theta_positive=False, theta_example="{a = 2, b = 1.5}", late=_regressor),
    events={ev.CONSTANT_FORCE: None}, order=first_order, sections=("first-order", "phase space"),
    lyapunov_unit="-"))

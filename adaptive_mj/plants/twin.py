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

import contextlib
import enum
from typing import TYPE_CHECKING, Callable, Iterator

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.plants import BuiltPlant
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


class PythonStepped:
    """What the plants stepped without MuJoCo (the twin, the linear plant) share: no MuJoCo warnings, a control
    policy (t, x) -> u installed for the length of a run (protocol.Plant.controlled_by), and the hook of a
    compiled loop. `compiled_loop` names the module of the plant's compiled closed loop (its `supported(plant,
    law)` and `Controller`: adaptive_mj.sim.native_analytic for the linear plant under MRAC's Lyapunov rule,
    adaptive_mj.sim.native_twin for the twin under the first-order or a sliding law); loop._native_controller
    asks it whether it runs this plant under the run's law, and then drives it chunk by chunk through
    controlled_natively/step_native like a MuJoCo plant. Every other run is stepped here, in Python (`step`)."""

    _policy: Policy | None = None
    _advance: Callable[[int], None] | None = None  # the compiled loop's chunk (controlled_natively)
    compiled_loop: str | None = None  # the module of this plant's compiled loop, or None: none

    def instability(self) -> str | None:
        return None

    def termination(self) -> str | None:
        """None: an analytic plant does not crash (protocol.Plant.termination)."""
        return None

    def unmodelled_drag(self) -> float | None:
        """None: the twin integrates its own form, nothing acts outside it."""
        return None

    def release(self) -> None:
        """Nothing to hand back (no MjData)."""
        return None

    @contextlib.contextmanager
    def controlled_by(self, policy: Policy) -> Iterator[None]:
        self._policy = policy
        try:
            yield
        finally:
            self._policy = None

    @contextlib.contextmanager
    def controlled_natively(self, advance: Callable[[int], None]) -> Iterator[None]:
        """For the length of a compiled run: step_native(n) calls advance(n) (the compiled loop's controller,
        which steps this plant n steps in one compiled call)."""
        self._advance = advance
        try:
            yield
        finally:
            self._advance = None

    def step_native(self, nstep: int) -> None:
        """nstep physics steps under the compiled loop (controlled_natively): the same steps as `step`, bit for
        bit (tests/test_native_analytic.py, tests/test_native_twin.py)."""
        if self._advance is None:
            raise RuntimeError(f"{type(self).__name__}.step_native outside controlled_natively(advance)")
        self._advance(nstep)


class TwinPlant(PythonStepped):
    """form: the plant's structure; theta: (n_theta,) true parameters;
    dt: step [s]; ctrl_range: (lo, hi) or None; x0: (n,) initial state.
    A FormPlant (adaptive_mj.plants.protocol)."""

    joint_shape: tuple[int, ...] = ()  # 1-DOF: scalar y and u
    joint_names: tuple[str, ...] = ()
    first_contact: tuple[float, str] | None = None  # no contacts in the analytic twin
    joint_limits: np.ndarray | None = None  # a 1-DOF plant's joint is not limited
    compiled_loop: str | None = "adaptive_mj.sim.native_twin"

    def __init__(self, form: ModelForm, theta, *, dt: float, integrator: Integrator = Integrator.RK4,
                 ctrl_range: tuple[float, float] | None = None, x0=None):
        self.form = form
        self._theta = np.array(theta, dtype=float)
        self.dt = float(dt)
        self.integrator = Integrator(integrator)
        self.ctrl_range = ctrl_range
        self.x = np.zeros(form.order) if x0 is None else np.array(x0, dtype=float)
        self._t = 0.0
        self._step_index = 0
        self._policy: Policy | None = None
        self.force_offset = 0.0  # constant external force, enters like h*u [N or N*m]
        self.disturbance: Callable[[float], float] | None = None  # t -> external force, at each step's start
        self._force = 0.0

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

    @property
    def time(self) -> float:
        return self._t

    def set_state(self, x0) -> None:
        self.x = np.array(x0, dtype=float)
        self._t = 0.0
        self._step_index = 0

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

    def moved_to(self, t: float, steps: int) -> None:
        """The compiled loop (adaptive_mj.sim.native_twin) stepped `steps` steps and left the time at t [s]."""
        self._t = t
        self._step_index += steps

    def _rate(self, t: float, x: np.ndarray) -> np.ndarray:
        if self._policy is None:
            raise RuntimeError("TwinPlant.step outside controlled_by(policy)")
        u = self._policy(t, x)
        if self.ctrl_range is not None:
            u = min(max(u, self.ctrl_range[0]), self.ctrl_range[1])
        dx = np.empty_like(x)
        dx[:-1] = x[1:]
        dx[-1] = self.form.highest_derivative(x, u, self._theta, external=self._force)
        return dx

    def step(self) -> None:
        h, t, x = self.dt, self._t, self.x
        self._force = self.force_offset + (self.disturbance(t) if self.disturbance is not None else 0.0)
        if self.integrator is Integrator.RK4:
            k1 = self._rate(t, x)
            k2 = self._rate(t + h / 2, x + h / 2 * k1)
            k3 = self._rate(t + h / 2, x + h / 2 * k2)
            k4 = self._rate(t + h, x + h * k3)
            self.x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        else:
            dx = self._rate(t, x)
            new = x.copy()
            new[-1] = x[-1] + h * dx[-1]
            for i in range(len(x) - 2, -1, -1):
                new[i] = x[i] + h * new[i + 1]
            self.x = new
        # time as MuJoCo keeps it: one addition of h per step
        self._t = t + h
        self._step_index += 1


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

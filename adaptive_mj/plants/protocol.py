"""The plant interface: what the closed loop (adaptive_mj.sim), the scenario builder
(adaptive_mj.setup.build) and the dm_env front end ask of a plant object, as typing.Protocols
(checked by mypy in .ci/run). The bundled plants (plants.mujoco_plant.MujocoPlant and its heave
and arm subclasses, plants.twin.TwinPlant, plants.manipulator.ManipulatorPlant) satisfy them, and
so must a plant plugin's plant (a MujocoPlant subclass does).

`Plant`, every plant (x is (n,) on a 1-DOF plant, (n, m) on a plant of m joints):
  order        n: the order of the output dynamics (2 for a manipulator: x = [q; q̇])
  names        (n_theta,) names of the true parameters, in true_theta()'s order
  dt           the physics step [s]
  time         the simulation time [s]
  stages       control-callback calls per physics step: 4 under RK4, 1 under a one-stage integrator
  ctrl_range   (lo, hi) control limits [N or N m], floats, or (m,) arrays of joint torques on a
               plant of m joints; None: unlimited
  force_offset a constant external generalised force [N or N m] held over every step (an event
               adds to it)
  disturbance  t [s] -> external force [N or N m] evaluated at each step's start, or None
  joint_shape  () on a 1-DOF plant (scalar y and u: a FormPlant), (m,) on a plant of m joints (a
               JointPlant)
  joint_names  () on a 1-DOF plant, else the m joint names
  first_contact  (t [s], text) of the first contact in the run, or None (always, on a 1-DOF plant)
  joint_limits (m, 2) joint ranges [rad or m] (±inf where unlimited), or None (a 1-DOF plant: unlimited)
  set_state(x0)  x0: the initial state, shaped like observe(); the time restarts at 0
  observe()    the true state now [m or rad, and their derivatives]
  true_theta() (n_theta,) the true parameters
  controlled_by(policy)  a context manager: policy(t, x) -> u runs at every evaluation of the
               dynamics (MuJoCo's control callback, or the twin's integrator stages)
  step()       advance one physics step
  instability()  text of a numerical instability since set_state (a MuJoCo warning), or None
Optional (a plant that names Plant as its base inherits the default in brackets):
  unmodelled_drag()  c_v [N s/m]: a viscous drag −c_v y' that acts on the plant but is absent from its
               regressor (the heave vehicle's in water, on its order-2 form), or None where the plant has none
               it knows of (the Lyapunov analysis: adaptive_mj.study.analysis) [None]
  release()    the run is over: hand back what the plant holds for the next run's plant (a MujocoPlant's
               MjData: MujocoPlant.release) [nothing]
  termination()  text of why the run must end now because the vehicle crashed (a quadrotor: "crashed at t = …"),
               or None; asked after every chunk of physics steps (adaptive_mj.sim.driver: every step on the Python
               path; a compiled callback says at which step of its chunk); the run, or adaptive_mj.env's episode,
               ends with status "crashed" [None]
  compiled_loop  the module of the plant's compiled closed loop, which gives `supported(plant, law)` and
               `Controller` (adaptive_mj.sim.native_mujoco for every MuJoCo kind, which declares its
               `mujoco_kernel`; native_chunk
               for every plants.analytic.AnalyticPlant); adaptive_mj.sim.loop dispatches on it [None: the
               Python path only]
Optional, read where present (getattr: control_shape below; a plant without them is as in brackets):
  control_names  the k actuators' names where u is not one entry per joint (a quadrotor: 4 rotor thrusts on
               3 position axes; u is then (k,)) [(): u is shaped like joint_shape]
  state_names  a name per row of x where the rows are not the output's derivatives (a quadrotor's x is
               [p; v; φ; Ω]: the log names its fields by them) [(): y, y', ...]

`FormPlant`, a 1-DOF plant or twin (joint_shape ()):
  form         the ModelForm d y^(n) = f(x) + φ(x)ᵀp + h(x) u the 1-DOF laws are built on

`JointPlant`, a plant of m joints (joint_shape (m,)):
  m            the number of joints
  regressor(v, w, a) -> (Y (m, n_theta), τ_known (m,)) at the current configuration
  mass_matrices(q)  (N, m, m) joint-space inertia [kg m²] at rows q (N, m)
  update_kinematics()  bring what the regressor reads to the current q (a law evaluated outside
               the control callback)

`NativePlant`, a MuJoCo plant a compiled control callback can drive (adaptive_mj.sim.native_mujoco):
  model, data  its MjModel and MjData
  native_owner the native controller whose context its MjData points at, or None
  controlled_natively(cfunc)  a context manager: the compiled cfunc is MuJoCo's control callback
  step_native(nstep)  nstep physics steps in one mj_step call
"""
from __future__ import annotations

from typing import Any, Callable, ContextManager, Protocol, TypeGuard

import numpy as np

from adaptive_mj.form import ModelForm

# (lo, hi) control limits: floats on a 1-DOF plant, (m,) arrays on a plant of m joints
CtrlRange = tuple[float, float] | tuple[np.ndarray, np.ndarray]
# policy(t, x) -> u: t [s], x the measured state, u the control (a float, or (m,) torques)
Policy = Callable[[float, np.ndarray], Any]


class Plant(Protocol):
    """What every plant offers the closed loop (see the module docstring for every member)."""

    @property
    def order(self) -> int: ...

    @property
    def names(self) -> tuple[str, ...]: ...

    @property
    def dt(self) -> float: ...

    @property
    def time(self) -> float: ...

    @property
    def stages(self) -> int: ...

    @property
    def joint_shape(self) -> tuple[int, ...]: ...

    @property
    def joint_names(self) -> tuple[str, ...]: ...

    @property
    def first_contact(self) -> tuple[float, str] | None: ...

    @property
    def joint_limits(self) -> np.ndarray | None: ...

    @property
    def ctrl_range(self) -> CtrlRange | None: ...

    force_offset: float
    disturbance: Callable[[float], float] | None

    def set_state(self, x0) -> None: ...

    def observe(self) -> np.ndarray: ...

    def true_theta(self) -> np.ndarray: ...

    def controlled_by(self, policy: Policy) -> ContextManager[None]: ...

    def step(self) -> None: ...

    def instability(self) -> str | None: ...

    # --- optional members, with their defaults (a plant that names Plant as its base inherits them;
    # the bodies `return None`, not `...`: a type checker takes a trivial body for one a plant must write)
    def unmodelled_drag(self) -> float | None:
        """c_v [N s/m] of a viscous drag the regressor leaves out, or None."""
        return None

    def release(self) -> None:
        """The run is over: hand back what the plant holds for the next run's plant."""
        return None

    def termination(self) -> str | None:
        """Why the run must end now because the vehicle crashed, or None (asked after every chunk of steps)."""
        return None

    @property
    def compiled_loop(self) -> str | None:
        """The module of the plant's compiled closed loop (its `supported(plant, law)` and `Controller`), or None."""
        return None


class FormPlant(Plant, Protocol):
    """A 1-DOF plant or twin: its structure is a ModelForm."""

    @property
    def form(self) -> ModelForm: ...


class JointPlant(Plant, Protocol):
    """A plant of m joints (a manipulator)."""

    @property
    def m(self) -> int: ...

    @property
    def regressor(self) -> Callable[[Any, Any, Any], tuple[np.ndarray, np.ndarray]]: ...

    def mass_matrices(self, q: np.ndarray) -> np.ndarray: ...

    def update_kinematics(self) -> None: ...


class NativePlant(Plant, Protocol):
    """A MuJoCo plant that a compiled control callback can drive."""

    model: Any  # mujoco.MjModel (the bindings carry no type information)
    data: Any  # mujoco.MjData
    native_owner: object | None

    def controlled_natively(self, cfunc) -> ContextManager[None]: ...

    def step_native(self, nstep: int) -> None: ...

    def native_prestep(self) -> None:
        """What step_native does to data before mj_step (a batch driver steps the state elsewhere)."""
        ...

    def native_poststep(self) -> None:
        """What step_native does after mj_step."""
        ...


def control_shape(plant: Plant) -> tuple[int, ...]:
    """The shape of the plant's control u: (k,) for k named actuators (control_names), else joint_shape."""
    names = getattr(plant, "control_names", ())
    return (len(names),) if names else tuple(plant.joint_shape)


def has_joints(plant: Plant) -> TypeGuard[JointPlant]:
    """Whether the plant has a joint axis (joint_shape (m,)): it is then a JointPlant."""
    return bool(plant.joint_shape)


def has_form(plant: Plant) -> TypeGuard[FormPlant]:
    """Whether the plant is a 1-DOF plant or twin (joint_shape ()): it is then a FormPlant."""
    return not plant.joint_shape

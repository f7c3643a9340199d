"""The heave vehicle (models/heave_vehicle.xml): the lecture's underwater vehicle

    d y'' + b y'|y'| + c g = u

on a slide joint along world z, where (all read from the compiled model)
  d = body mass + joint armature (added mass)              [kg]
  b = ½ rho * sum_i A_i |a_i|³  (inertia-box quadratic drag)  [kg/m]
      A_i: area of the equivalent box face normal to principal axis i,
      a_i: joint axis in the principal frame (A_z = bx*by for motion along z).
      MuJoCo's drag acts per box axis, F_i = -½ rho A_i |v_i| v_i, and
      v_i = a_i v, so along the joint F = -½ rho sum_i A_i |a_i|³ |v| v.
  c = body mass * (1 - gravcomp)  (net weight / g; gravcomp = rho V / m)  [kg]
  g = gravity along the joint axis                          [m/s²]

The regressor: phi(x) = [-y'|y'|, -g], p = (b, c), f = 0, h = actuator gear.
MuJoCo's fluid model also has a viscous term 3*pi*viscosity*mean(box)*v that
this regressor does not model; ``unmodelled_linear_drag`` reports it.

With a first-order thruster lag (actuator dyntype "filter", time constant tau:
tau F' = gear*u - F) the plant has order 3. Differentiating
d y'' = -b y'|y'| - c g + F and substituting F gives

    tau d y^(3) = -2 tau b |y'| y'' - d y'' - b y'|y'| - c g + gear*u

so theta = (tau_d, tau_b, d, b, c) and phi = [-2|y'|y'', -y'', -y'|y'|, -g].
The order-3 plant measures y'' as a perfect accelerometer would: from the
current thrust, passive, bias and applied forces (MuJoCo's qacc is one step
stale inside the control callback).
"""
from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj.data import MODELS
from adaptive_mj.errors import ModelError
from adaptive_mj.form import ModelForm
from adaptive_mj.plants import BuiltPlant, ModelSource
from adaptive_mj.plants.mujoco_plant import (MujocoPlant, compile_for_scenario, compile_xml_path,
                                             find_joint_and_actuator, read_model_file, scratch_data)
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants.kinds import ESTIMATES_DRAW, Draw, PlantKind, ScoreTask, StressPlant, register
from adaptive_mj.plants import sliding_study
from adaptive_mj.plants.study_spec import Stressor, StudyContext, hold_constant
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Key, Table
from adaptive_mj.specs import PlantSpec

MODEL_PATH = MODELS / "heave_vehicle.xml"
THETA_NAMES = ("d", "b", "c")
THETA_NAMES_LAG = ("tau_d", "tau_b", "d", "b", "c")


def _vehicle(model, joint_id: int) -> tuple[int, np.ndarray, np.ndarray]:
    """(body id, joint axis in the body's principal-inertia frame (3,), equivalent box sides (3,) [m])."""
    body = int(model.jnt_bodyid[joint_id])
    scratch = scratch_data(model)
    scratch.qpos[:] = 0
    mujoco.mj_kinematics(model, scratch)
    axis_local = scratch.ximat[body].reshape(3, 3).T @ scratch.xaxis[joint_id]
    m = model.body_mass[body]
    Ix, Iy, Iz = model.body_inertia[body]
    sides = np.sqrt(np.maximum(0.0, 6.0 / m * np.array([Iy + Iz - Ix, Ix + Iz - Iy, Ix + Iy - Iz])))
    return body, axis_local, sides


def gravity_along_axis(model, joint_id: int) -> float:
    """g [m/s²] as it enters c*g: minus gravity projected on the (upward) joint axis."""
    scratch = scratch_data(model)
    mujoco.mj_kinematics(model, scratch)
    return float(-model.opt.gravity @ scratch.xaxis[joint_id])


def thruster_time_constant(model: mujoco.MjModel, actuator_id: int = 0) -> float:
    """tau [s] of a filter actuator; 0 for a direct-drive motor."""
    if model.actuator_dyntype[actuator_id] == mujoco.mjtDyn.mjDYN_FILTER:
        return float(model.actuator_dynprm[actuator_id, 0])
    return 0.0


def true_theta_lag(model: mujoco.MjModel, joint_id: int = 0, actuator_id: int = 0) -> np.ndarray:
    """(5,) true [tau*d, tau*b, d, b, c] of the order-3 plant with thruster lag tau [s]."""
    d, b, c = true_theta(model, joint_id)
    tau = thruster_time_constant(model, actuator_id)
    return np.array([tau * d, tau * b, d, b, c])


def true_theta(model: mujoco.MjModel, joint_id: int = 0) -> np.ndarray:
    """(3,) true [d, b, c] from the compiled model: d [kg], b [kg/m], c [kg]."""
    body, a, box = _vehicle(model, joint_id)
    m = float(model.body_mass[body])
    d = m + float(model.dof_armature[model.jnt_dofadr[joint_id]])
    faces = np.array([box[1] * box[2], box[0] * box[2], box[0] * box[1]])
    b = 0.5 * float(model.opt.density) * float(faces @ np.abs(a) ** 3)
    c = m * (1.0 - float(model.body_gravcomp[body]))
    return np.array([d, b, c])


def unmodelled_linear_drag(model: mujoco.MjModel, joint_id: int = 0) -> float:
    """Viscous drag coefficient 3*pi*viscosity*mean(box sides) [N*s/m] (not in the regressor)."""
    _, _, box = _vehicle(model, joint_id)
    return 3.0 * np.pi * float(model.opt.viscosity) * float(np.mean(box))


def heave_form(g: float, gear: float = 1.0) -> ModelForm:
    """The lecture's regressor for d y'' = -b y'|y'| - c g + gear*u."""

    def phi(x):
        return np.array([-x[1] * abs(x[1]), -g])

    return ModelForm(order=2, p_names=("b", "c"), phi=phi, h=lambda x: gear, d_name="d")


def heave_lag_form(g: float, gear: float = 1.0) -> ModelForm:
    """Order-3 regressor of the vehicle with thruster lag (see the module docstring)."""

    def phi(x):
        v, a = x[1], x[2]
        return np.array([-2.0 * abs(v) * a, -a, -v * abs(v), -g])

    return ModelForm(order=3, p_names=("tau_b", "d", "b", "c"), phi=phi, h=lambda x: gear, d_name="tau_d")


class HeavePlant(MujocoPlant):
    """The MuJoCo heave vehicle. Fluid density changes keep buoyancy consistent.

    order: 2 (the lecture's plant; a thruster lag, if the actuator has one, is
    then unmodelled) or 3 (needs a filter actuator; state [y, y', y''])."""

    def __init__(self, model: mujoco.MjModel, *, joint: str | None = None,
                 actuator: str | None = None, where: str = "heave model", order: int = 2):
        j, a = find_joint_and_actuator(model, joint=joint, actuator=actuator,
                                       joint_type=mujoco.mjtJoint.mjJNT_SLIDE, where=where, allow_filter=True)
        self.lag = thruster_time_constant(model, a)
        if order not in (2, 3):
            raise ModelError(f"{where}: the heave plant has order 2 or 3, got {order}")
        if order == 3 and self.lag <= 0:
            raise ModelError(f"{where}: an order-3 heave plant needs a thruster lag "
                             "(plant.thruster_time_constant > 0)")
        g = gravity_along_axis(model, j)
        if g <= 0:
            raise ModelError(f"{where}: the slide joint must point up against gravity "
                             f"(gravity along the axis is {-g} m/s²)")
        body = int(model.jnt_bodyid[j])
        if model.opt.density <= 0:
            raise ModelError(f"{where}: option density must be > 0 for fluid drag, got {model.opt.density}")
        # displaced volume, derived once from the buoyancy written in the model
        self.volume = float(model.body_gravcomp[body] * model.body_mass[body] / model.opt.density)
        self.body_id = body
        self.g = g
        gear = float(model.actuator_gear[a, 0])
        if order == 3:
            form, theta_fn = heave_lag_form(g, gear), (lambda m: true_theta_lag(m, j, a))
        else:
            form, theta_fn = heave_form(g, gear), (lambda m: true_theta(m, j))
        self._act_adr = int(model.actuator_actadr[a]) if self.lag > 0 else -1
        super().__init__(model, joint_id=j, actuator_id=a, form=form, theta_fn=theta_fn, where=where)

    def unmodelled_drag(self) -> float | None:
        """unmodelled_linear_drag's c_v [N s/m] on the lecture's order-2 form in a viscous fluid; None in an inviscid
        one, or on the order-3 form."""
        if self.form.order != 2 or self.model.opt.viscosity == 0:
            return None
        return unmodelled_linear_drag(self.model)

    def _thrust_per_act(self) -> float:
        m, a = self.model, self.actuator_id
        return float(m.actuator_gear[a, 0] * m.actuator_gainprm[a, 0])

    @property
    def native_third_state(self) -> tuple[int, int] | None:
        """(the thrust state's address in act, the body's id) for order 3: the compiled callback computes y'' as
        `measure` does (adaptive_mj.plants.one_dof_kernel._acceleration); None for order 2."""
        return (self._act_adr, self.body_id) if self.form.order == 3 and self._act_adr >= 0 else None

    def measure(self, d, x) -> None:
        """[y, y'] or, for order 3, [y, y', y''] with y'' from the current forces."""
        super().measure(d, x)
        if x.size == 3:
            m, dof = self.model, self._dadr
            force = (self._thrust_per_act() * d.act[self._act_adr] + d.qfrc_passive[dof]
                     - d.qfrc_bias[dof] + d.qfrc_applied[dof])
            x[2] = force / (m.body_mass[self.body_id] + m.dof_armature[dof])

    def set_state(self, x0) -> None:
        """x0: [y, y'] or [y, y', y''] (order 3). With a thruster lag the thrust
        starts at the value that gives y'' (0 when not given): d y'' + b y'|y'| + c g."""
        super().set_state(x0)
        if self._act_adr >= 0:
            d, b, c = true_theta(self.model, self.joint_id)
            v = float(x0[1])
            acc = float(x0[2]) if len(x0) > 2 else 0.0
            thrust = d * acc + b * v * abs(v) + c * self.g - self.force_offset
            self.data.act[self._act_adr] = thrust / self._thrust_per_act()

    def set_fluid_density(self, rho: float) -> None:
        """New water density [kg/m³]: changes drag b and buoyancy (gravcomp = rho V / m), hence c."""
        m = self.model
        m.opt.density = rho
        m.body_gravcomp[self.body_id] = rho * self.volume / m.body_mass[self.body_id]
        self.model_changed()


def load(path: str | Path = MODEL_PATH, **kwargs) -> HeavePlant:
    """Compile an MJCF heave model and wrap it (joint/actuator by name or the only one)."""
    return HeavePlant(compile_xml_path(path), where=str(path), **kwargs)


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> ModelSource | None:
    """plant.model's text; None for a twin given plant.theta (no model)."""
    if scn.plant.backend == "twin" and scn.plant.theta is not None:
        return None
    return read_model_file(scn)


def from_scenario(scn, source: ModelSource | None) -> BuiltPlant:
    """plant.kind = "heave": the vehicle of plant.model (joint, actuator, density,
    thruster_time_constant: the actuator becomes a first-order filter), or its twin."""
    from adaptive_mj.plants import twin

    p = scn.plant
    if p.backend == "twin" and p.theta is not None:
        return BuiltPlant(twin.from_theta(scn, heave_form(p.g)))
    lag = p.thruster_time_constant

    def thruster_lag(spec):
        if lag is not None:
            for act in spec.actuators:
                act.dyntype = mujoco.mjtDyn.mjDYN_FILTER
                act.dynprm[0] = lag

    model, model_xml = compile_for_scenario(scn, source, edit=thruster_lag, edit_key=("thruster_lag", lag))
    plant = HeavePlant(model, joint=p.joint, actuator=p.actuator, where=str(p.model), order=scn.law.order or 2)
    if p.density is not None:
        plant.set_fluid_density(p.density)
    return BuiltPlant(twin.as_backend(scn, plant), model_xml)


# --- its scenario keys -----------------------------------------------------------
THRUSTER_TIME_CONSTANT = Key("thruster_time_constant", "number", "s", None, "> 0",
                             "first-order thruster lag τ (the actuator becomes a filter); with law.order = 3 the "
                             "plant is of order 3", when="built from a model")


def theta_names(t: Table) -> tuple[str, ...]:
    """plant.theta's keys, in order: the second-order form's θ names (d, b, c)."""
    return heave_form(9.81).names


def _thruster_lag(t: Table, fields: dict) -> dict:
    """plant.thruster_time_constant τ [s]: only on a vehicle built from a model (not a twin given theta)."""
    lag = t.number("thruster_time_constant", None, gt=0)
    if lag is not None and fields["theta"] is not None:
        raise t.fail("thruster_time_constant", f"absent unless plant.kind = 'heave' {THRUSTER_TIME_CONSTANT.when}",
                     lag)
    return {"thruster_time_constant": lag}


def order(plant: PlantSpec, law_order: object) -> int:
    """n: 3 with a thruster lag and law.order = 3 (the lag modelled: θ = τd, τb, d, b, c), else 2."""
    return 3 if law_order == 3 and plant.thruster_time_constant is not None else 2


def _fluid_density(e, scn, source) -> ev.Event:
    return ev.Event(e.t, f"fluid density x {e.value}",
                    lambda plant: plant.set_fluid_density(plant.model.opt.density * e.value))


#: [[events]] kind "fluid_density_scale": the water's density times value from t on
FLUID_DENSITY_SCALE = ev.EventKind("fluid_density_scale", _fluid_density,
                                   doc="multiplies the fluid density by value from t on")


def study_stressors(ctx: StudyContext, duration: float) -> list[Stressor]:
    """The heave vehicle's stressors in the breaking-point study (kinds.StressPlant.stressors): the 1-DOF ones
    (sliding_study.stressors) and an unmodelled thruster lag τ [s] (plant.thruster_time_constant)."""
    return [*sliding_study.stressors(ctx),
            Stressor("lag τ", lambda v: [f"plant.thruster_time_constant={v!r}"], 1e-3, 1.0, unit="s")]


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "heave"
KIND = register(PlantKind(
    "heave", __name__, frozenset({Form.MODEL}), output_unit="m", control_unit="N",
    params={"d": "kg", "b": "kg/m", "c": "kg", "tau_d": "kg s", "tau_b": "kg s/m"},
    default_model="heave_vehicle", doc="1-DOF heave vehicle in water, d y'' + b y'|y'| + c g = u",
    tail_bound=0.01, nominal_noise=5e-4,
    keys=plant_keys.keys(THRUSTER_TIME_CONSTANT),
    reader=plant_keys.SharedReader(theta=theta_names, late=_thruster_lag),
    events={FLUID_DENSITY_SCALE: "mujoco", ev.CONSTANT_FORCE: None}, order=order,
    orders_text="2, or 3 with plant.thruster_time_constant",
    stress=StressPlant("heave", "heave_tracking", ("simulation.initial_state='reference'",),
                       disturbance=(1.0, 1000.0), composite="{gain=3e-4, filter=1.0}",
                       laws=sliding_study.laws, stressors=study_stressors, hold=hold_constant,
                       tasks=(ScoreTask("tracking", "heave_tracking", ("simulation.initial_state='reference'",),
                                        draws=(Draw("reference.amplitude", 0.75, 1.25),
                                               Draw("reference.omega", 0.75, 1.25),
                                               Draw("reference.phase", 0.0, 2 * math.pi, add=True),
                                               ESTIMATES_DRAW)),
                              ScoreTask("change", "heave_tracking",
                                        ("simulation.initial_state='reference'", "law.initial_estimates='model'",
                                         "events=[{{t={half}, kind='fluid_density_scale', value=1.1}}]"),
                                        extras=("change_response",)),
                              ScoreTask("hold", "heave_drift", (), noise_scale=0.0, extras=("estimate_drift",)))),
    sections=("Lyapunov", "2nd order", "n-th order", "drift", "excitation", "failure")))

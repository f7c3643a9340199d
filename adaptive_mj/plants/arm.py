"""A 1-DOF arm: one actuated hinge, any orientation of the hinge axis.

    J q'' = -b q' - g_sin sin q - g_cos cos q + gear*u

theta = (J, b, g_sin, g_cos), read from the compiled model:
  J      moment of inertia of everything the hinge moves, about the hinge
         axis, plus joint armature                            [kg*m²]
  b      viscous joint damping                                [N*m*s/rad]
  g_sin, g_cos  gravity torque amplitudes                     [N*m]
         With r the centre of mass of each moving body relative to the hinge
         anchor at q = 0, r_perp its part normal to the axis a, and
         F = m (1 - gravcomp) g_vec its weight:
         g_cos = -sum a.(r_perp x F),  g_sin = -sum a.((a x r_perp) x F).
Because gravity enters through both sin q and cos q, the model's choice of
q = 0 (hanging, horizontal, anything) does not matter.

The regressor: phi(x) = [-q', -sin q, -cos q], p = (b, g_sin, g_cos), f = 0,
h = actuator gear. The payload's mass and inertia are the unknowns.
"""
from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj.data import MODELS, PAYLOADS
from adaptive_mj.errors import ModelError, ScenarioError
from adaptive_mj.form import ModelForm
from adaptive_mj.plants import BuiltPlant, ModelSource
from adaptive_mj.plants.attach import compose
from adaptive_mj.plants.mujoco_plant import (BodyEdits, MujocoPlant, compile_for_scenario, compile_xml_path,
                                             find_joint_and_actuator, scratch_data, spec_from_text, with_userdata)
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants.kinds import ESTIMATES_DRAW, Draw, PlantKind, ScoreTask, StressPlant, register
from adaptive_mj.plants import sliding_study
from adaptive_mj.plants.study_spec import Stressor, StudyContext, hold_constant, payload_ratio
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Table

MODEL_PATH = MODELS / "pendulum_arm.xml"
THETA_NAMES = ("J", "b", "g_sin", "g_cos")


def _moved_bodies(model, joint_id: int) -> list[int]:
    """Bodies whose pose depends on the joint: the joint's body and its descendants."""
    root = int(model.jnt_bodyid[joint_id])
    out = []
    for i in range(model.nbody):
        j = i
        while j != 0 and j != root:
            j = int(model.body_parentid[j])
        if j == root:
            out.append(i)
    return out


def true_theta(model: mujoco.MjModel, joint_id: int = 0) -> np.ndarray:
    """(4,) true [J, b, g_sin, g_cos] from masses, inertias and kinematics at q = 0."""
    data = scratch_data(model)
    data.qpos[:] = 0.0
    mujoco.mj_kinematics(model, data)
    a = data.xaxis[joint_id].copy()
    anchor = data.xanchor[joint_id]
    J = float(model.dof_armature[model.jnt_dofadr[joint_id]])
    g_sin = g_cos = 0.0
    for i in _moved_bodies(model, joint_id):
        m = float(model.body_mass[i])
        R = data.ximat[i].reshape(3, 3)
        a_body = R.T @ a
        r = data.xipos[i] - anchor
        r_perp = r - (a @ r) * a
        J += float(a_body @ (model.body_inertia[i] * a_body)) + m * float(r_perp @ r_perp)
        F = m * (1.0 - float(model.body_gravcomp[i])) * model.opt.gravity
        g_cos -= float(a @ np.cross(r_perp, F))
        g_sin -= float(a @ np.cross(np.cross(a, r_perp), F))
    b = float(model.dof_damping[model.jnt_dofadr[joint_id]])
    return np.array([J, b, g_sin, g_cos])


def arm_form(gear: float = 1.0) -> ModelForm:
    """Regressor for J q'' = -b q' - g_sin sin q - g_cos cos q + gear*u."""

    def phi(x):
        q = x[0]
        return np.array([-x[1], -np.sin(q), -np.cos(q)])

    return ModelForm(order=2, p_names=("b", "g_sin", "g_cos"), phi=phi, h=lambda x: gear, d_name="J")


def build_arm_xml(*, arm: str | Path = MODEL_PATH, payload: str | Path | None = "sphere",
                  payload_mass: float | None = None, site: str = "tip") -> tuple[str, dict]:
    """Attach a payload MJCF at `site`; return (xml, assets), the text MuJoCo compiles (and a log
    embeds) and the files it reads (adaptive_mj.plants.attach: MuJoCo's own attach, no PyMJCF).

    payload: a name in models/payloads/ (without .xml), a path, or None.
    payload_mass: total payload mass [kg]; the payload's geom masses are scaled
    to it (inertia scales with them). The payload's names get the prefix "payload/".
    """
    arm = Path(arm)
    if not arm.is_file():
        raise ModelError(f"{arm}: model file not found")
    ppath = None
    if payload is not None:
        ppath = Path(payload) if Path(payload).suffix == ".xml" else PAYLOADS / f"{payload}.xml"
        if not ppath.is_file():
            choices = sorted(p.stem for p in PAYLOADS.glob("*.xml"))
            raise ModelError(f"{ppath}: payload file not found (bundled payloads: {choices})")
    return compose(arm, ppath, payload_mass=payload_mass, site=site)


def compile_arm(**kwargs) -> mujoco.MjModel:
    """build_arm_xml(...) compiled to an MjModel."""
    xml, assets = build_arm_xml(**kwargs)
    try:
        return with_userdata(spec_from_text(xml, assets)).compile()
    except ValueError as exc:
        raise ModelError(f"{kwargs.get('arm', MODEL_PATH)}: MuJoCo could not compile the model: "
                         f"{str(exc).strip()}") from None


class ArmPlant(BodyEdits, MujocoPlant):
    """The MuJoCo arm. Body masses may change mid-run (payload swap)."""

    def __init__(self, model: mujoco.MjModel, *, joint: str | None = None,
                 actuator: str | None = None, where: str = "arm model"):
        j, a = find_joint_and_actuator(model, joint=joint, actuator=actuator,
                                       joint_type=mujoco.mjtJoint.mjJNT_HINGE, where=where)
        super().__init__(model, joint_id=j, actuator_id=a,
                         form=arm_form(float(model.actuator_gear[a, 0])),
                         theta_fn=lambda m: true_theta(m, j), where=where)

    def holding_controls(self, q: np.ndarray) -> np.ndarray:
        """(N, 1) the control u (torque = gear·u, the units of ctrl_range) that holds the arm still at the joint
        angles q (N, 1) [rad]: MuJoCo's qfrc_bias - qfrc_passive at zero velocity (gravity, less springs) over the
        gear (the pre-flight's gravity check)."""
        m = self.model
        d = scratch_data(m)
        gear = float(m.actuator_gear[self._act, 0])
        q = np.asarray(q, dtype=float).reshape(-1)
        out = np.empty((len(q), 1))
        for i, qi in enumerate(q):
            d.qpos[self._qadr] = qi
            d.qvel[:] = 0.0
            mujoco.mj_fwdPosition(m, d)
            mujoco.mj_fwdVelocity(m, d)
            out[i, 0] = (d.qfrc_bias[self._dadr] - d.qfrc_passive[self._dadr]) / gear
        return out


def load(path: str | Path = MODEL_PATH, *, payload: str | Path | None = "sphere",
         payload_mass: float | None = None, site: str = "tip", **kwargs) -> ArmPlant:
    """The bundled arm (or a user's MJCF) with a payload attached at `site`."""
    model = compile_arm(arm=path, payload=payload, payload_mass=payload_mass, site=site)
    return ArmPlant(model, where=str(path), **kwargs)


def load_bare(path: str | Path, **kwargs) -> ArmPlant:
    """A user's arm MJCF as it is, with no payload attached."""
    return ArmPlant(compile_xml_path(path), where=str(path), **kwargs)


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> ModelSource | None:
    """plant.model with plant.payload attached at plant.site (build_arm_xml; also the
    manipulator's); None for a twin given plant.theta (no model)."""
    p = scn.plant
    if p.backend == "twin" and p.theta is not None:
        return None
    xml, assets = build_arm_xml(arm=p.model, payload=p.payload, payload_mass=p.payload_mass, site=p.site)
    return ModelSource(xml, dict(assets))


def from_scenario(scn, source: ModelSource | None) -> BuiltPlant:
    """plant.kind = "arm": the pendulum arm of plant.model (joint, actuator), or its twin."""
    from adaptive_mj.plants import twin

    p = scn.plant
    if p.backend == "twin" and p.theta is not None:
        return BuiltPlant(twin.from_theta(scn, arm_form()))
    model, model_xml = compile_for_scenario(scn, source)
    plant = ArmPlant(model, joint=p.joint, actuator=p.actuator, where=str(p.model))
    return BuiltPlant(twin.as_backend(scn, plant), model_xml)


def theta_names(t: Table) -> tuple[str, ...]:
    """plant.theta's keys, in order: the arm form's θ names (J, b, g_sin, g_cos)."""
    return arm_form().names


def study_stressors(ctx: StudyContext, duration: float) -> list[Stressor]:
    """The 1-DOF arm's stressors in the breaking-point study (kinds.StressPlant.stressors): the 1-DOF ones
    (sliding_study.stressors) and the payload's mass × ratio at half the run (the scenario sets
    plant.payload_mass)."""
    if ctx.payload_mass is None:  # the bundled arm_payload_swap sets it
        raise ScenarioError(f"{ctx.scenario}: the payload ratio stressor needs plant.payload_mass")
    return [*sliding_study.stressors(ctx), payload_ratio(ctx.payload_mass, duration)]


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "arm"
KIND = register(PlantKind(
    "arm", __name__, frozenset({Form.MODEL}), output_unit="rad", control_unit="N m",
    params={"J": "kg m²", "b": "N m s/rad", "g_sin": "N m", "g_cos": "N m"},
    default_model="pendulum_arm", doc="a 1-DOF arm with an unknown payload (MuJoCo's attach)",
    tail_bound=0.05, nominal_noise=5e-4,
    keys=plant_keys.keys(payload=True, default_payload="sphere"),
    reader=plant_keys.SharedReader(theta=theta_names),
    events={ev.PAYLOAD_MASS: "mujoco", ev.CONSTANT_FORCE: None},
    stress=StressPlant("arm", "arm_payload_swap", ("events=[]",), composite="{gain=1.0, filter=2.0}",
                       laws=sliding_study.laws, stressors=study_stressors, hold=hold_constant,
                       tasks=(ScoreTask("tracking", "arm_payload_swap", ("events=[]",),
                                        draws=(Draw("plant.payload_mass", 0.5, 2.0),
                                               Draw("reference.amplitudes", 0.75, 1.25),
                                               Draw("reference.omegas", 0.75, 1.25),
                                               Draw("reference.phases", 0.0, 2 * math.pi, each=True, add=True),
                                               ESTIMATES_DRAW)),
                              ScoreTask("change", "arm_payload_swap",
                                        ("events=[{{t={half}, kind='payload_mass', value={payload_x4}}}]",),
                                        extras=("change_response",)),
                              ScoreTask("hold", "arm_payload_swap",
                                        ("events=[]", "reference={{kind='constant', value=0.5}}"), noise_scale=2.0,
                                        extras=("estimate_drift",)))),
    sections=("payload swap",)))

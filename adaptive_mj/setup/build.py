"""Scenario -> the objects of a run: plant, law, reference, initial estimates,
noise, events. One call per box of the data flow; nothing here steps physics.

The model is compiled from an XML *string* (`model_source`) so that a log
can carry that exact string and `replay --verify` recompiles a bit-identical
model without the repo that made it.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from adaptive_mj import reference as refs
from adaptive_mj.errors import ModelError, ScenarioError
from adaptive_mj.laws import (DeadZone, DeadZoneOn, FirstOrderAdaptiveLaw, FixedNominalLaw,
                              RobustSlidingLaw, SlidingAdaptiveLaw)
from adaptive_mj.sim.loop import Event
from adaptive_mj.setup.scenario import STATE_SIGNALS, Scenario


@dataclass(frozen=True)
class ModelSource:
    """The exact MJCF text compiled for a run, and its assets (name -> bytes)."""

    xml: str
    assets: dict


@dataclass
class Setup:
    """Everything `loop.run` needs, built from a scenario."""

    plant: object
    law: object
    reference: object
    theta_hat0: np.ndarray
    noise_std: np.ndarray | None
    rng: np.random.Generator
    events: list[Event]
    source: ModelSource | None
    model_xml: str | None = None  # the compiled model as MJCF (the log's model.xml)
    notes: tuple[str, ...] = ()  # model edits made for the run (servo_to_torque), shown and logged


def model_source(scn: Scenario) -> ModelSource | None:
    """Read (heave) or compose with PyMJCF (arm + payload) the MJCF text to compile."""
    p = scn.plant
    if p.kind == "first_order" or (p.backend == "twin" and p.theta is not None):
        return None
    if p.kind in ("arm", "manipulator"):
        from adaptive_mj.plants import arm

        xml, assets = arm.build_arm_xml(arm=p.model, payload=p.payload, payload_mass=p.payload_mass, site=p.site)
        return ModelSource(xml, dict(assets))
    if not p.model.is_file():
        raise ModelError(f"{scn.source}: plant.model {str(p.model)!r} not found")
    return ModelSource(p.model.read_text(encoding="utf-8"), {})


def build(scn: Scenario, *, source: ModelSource | None = None) -> Setup:
    """Build a run's objects. `source` replaces the model files (used by replay --verify)."""
    if source is None:
        source = model_source(scn)
    if scn.plant.kind == "manipulator":
        return _manipulator_setup(scn, source)
    reference = _reference(scn)
    plant, model_xml = _plant(scn, source, reference)
    for e in scn.events:
        if e.kind == "payload_mass":
            if scn.plant.payload is None and e.body.startswith("payload/"):
                raise ScenarioError(f"{scn.source}: events: a payload_mass event on {e.body!r} needs a payload "
                                    "(plant.payload is 'none'); attach one or name a body of your model with "
                                    "events[].body")
            plant.body_id(e.body)  # a missing body fails now, not mid-run
    order = plant.form.order
    law = _law(scn, plant.form)
    names = law.names
    theta_hat0 = _estimates(scn, names, plant)
    std = None
    if scn.noise.std:
        std = np.array([scn.noise.std.get(sig, 0.0) for sig in STATE_SIGNALS[:order]])
    rng = np.random.default_rng(scn.noise.seed)
    plant.disturbance = _disturbance(scn)
    return Setup(plant=plant, law=law, reference=reference, theta_hat0=theta_hat0, noise_std=std,
                 rng=rng, events=[_event(e) for e in scn.events], source=source, model_xml=model_xml)


def _compile(scn: Scenario, source: ModelSource, edit=None):
    """(model, compiled MJCF text). A thruster lag turns the actuator into a first-order filter."""
    import mujoco

    from adaptive_mj.plants.mujoco_plant import compile_spec

    lag = scn.plant.thruster_time_constant

    def thruster_lag(spec):
        if lag is not None:
            for act in spec.actuators:
                act.dyntype = mujoco.mjtDyn.mjDYN_FILTER
                act.dynprm[0] = lag

    edit = edit or thruster_lag

    model, xml = compile_spec(source.xml, source.assets, where=str(scn.plant.model), edit=edit)
    sim = scn.simulation
    model.opt.integrator = {
        "rk4": mujoco.mjtIntegrator.mjINT_RK4,
        "euler": mujoco.mjtIntegrator.mjINT_EULER,
        "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
        "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
    }[sim.integrator]
    if sim.timestep is not None:
        model.opt.timestep = sim.timestep
    elif model.opt.timestep > sim.duration:
        raise ScenarioError(f"{scn.source}: the model's timestep {model.opt.timestep} is larger than "
                            f"simulation.duration {sim.duration}")
    if scn.plant.viscosity is not None:
        model.opt.viscosity = scn.plant.viscosity
    return model, xml


def _plant(scn: Scenario, source: ModelSource | None, reference):
    from adaptive_mj.plants import twin

    p, sim = scn.plant, scn.simulation
    dt = sim.timestep if sim.timestep is not None else 0.001
    integrator = twin.Integrator.RK4 if sim.integrator == "rk4" else twin.Integrator.EULER
    model_xml = None
    if p.kind == "first_order":
        form = twin.sin_squared_form() if p.regressor == "sin_squared" else twin.lecture_first_order_form()
        plant = twin.TwinPlant(form, list(p.theta.values()), dt=dt, integrator=integrator, ctrl_range=p.ctrl_range)
    elif p.backend == "twin" and p.theta is not None:
        if p.kind == "heave":
            from adaptive_mj.plants.heave import heave_form

            form = heave_form(p.g)
        else:
            from adaptive_mj.plants.arm import arm_form

            form = arm_form()
        plant = twin.TwinPlant(form, list(p.theta.values()), dt=dt, integrator=integrator, ctrl_range=p.ctrl_range)
    else:
        model, model_xml = _compile(scn, source)
        where = str(p.model)
        if p.kind == "heave":
            from adaptive_mj.plants.heave import HeavePlant

            plant = HeavePlant(model, joint=p.joint, actuator=p.actuator, where=where,
                               order=scn.law.order or 2)
            if p.density is not None:
                plant.set_fluid_density(p.density)
        else:
            from adaptive_mj.plants.arm import ArmPlant

            plant = ArmPlant(model, joint=p.joint, actuator=p.actuator, where=where)
        if p.backend == "twin":
            plant = twin.twin_of(plant, integrator=integrator)
            if p.ctrl_range is not None:
                plant.ctrl_range = p.ctrl_range
    n = plant.form.order
    if sim.initial_state == "reference":
        x0 = tuple(float(v) for v in reference(0.0, n)[:n])
    else:
        x0 = sim.initial_state if sim.initial_state is not None else (0.0,) * n
    plant.set_state(x0)
    return plant, model_xml


def _named(scn: Scenario, key: str, values, names: tuple[str, ...], plant=None) -> np.ndarray:
    if values == "model":
        return np.array(plant.true_theta(), dtype=float)
    if tuple(values) != names:
        raise ScenarioError(f"{scn.source}: {key} must have the keys {', '.join(names)} in that order, "
                            f"got {', '.join(values) or 'none'}")
    return np.array(list(values.values()), dtype=float)


def _law(scn: Scenario, form):
    L = scn.law
    try:
        if L.kind == "first_order_adaptive":
            gamma = _gamma(scn, form.names)
            return FirstOrderAdaptiveLaw(form, k=L.k, gamma=gamma, dead_zone=_dead_zone(L))
        if L.kind == "sliding_adaptive":
            return SlidingAdaptiveLaw(form, lam=L.lam, k=L.k, gamma=_gamma(scn, form.names),
                                      dead_zone=_dead_zone(L))
        if L.kind == "fixed_nominal":
            return FixedNominalLaw(form, lam=L.lam, k=L.k)
        return RobustSlidingLaw(form, lam=L.lam, k=L.k, K=L.K, boundary_layer=L.boundary_layer)
    except ScenarioError:
        raise
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: law: {exc}") from None


def _gamma(scn: Scenario, names):
    g = scn.law.gamma
    return _named(scn, "law.gamma", g, names) if isinstance(g, dict) else g


def _dead_zone(L) -> DeadZone | None:
    if L.dead_zone is None:
        return None
    return DeadZone(L.dead_zone.width, DeadZoneOn(L.dead_zone.on))


def _estimates(scn: Scenario, names, plant) -> np.ndarray:
    """theta_hat(0). Baselines hold law.nominal (else law.initial_estimates); adaptive laws
    start from law.initial_estimates (else law.nominal, else zeros)."""
    L = scn.law
    first, second = ("nominal", "initial_estimates")
    if L.kind not in ("fixed_nominal", "robust_sliding", "computed_torque", "pd_gravity"):
        first, second = second, first
    for key in (first, second):
        values = getattr(L, key)
        if values is not None:
            return _named(scn, f"law.{key}", values, names, plant)
    return np.zeros(len(names))


def _reference(scn: Scenario):
    r = scn.reference
    cls = {"constant": refs.Constant, "cosine": refs.Cosine, "sine": refs.Sine,
           "sum_of_sines": refs.SumOfSines, "smooth_step": refs.SmoothStep}[r.kind]
    return cls(**r.params)


def _disturbance(scn: Scenario):
    d = scn.disturbance
    if d.kind == "none" or d.magnitude == 0.0:
        return None
    if d.kind == "constant":
        return lambda t: d.magnitude
    if d.kind == "step":
        return lambda t: d.magnitude if t >= d.t0 else 0.0
    return lambda t: d.magnitude * float(np.sin(d.omega * t + d.phase))


def _event(e, scn: Scenario | None = None) -> Event:
    if e.kind == "payload_swap":
        inertial = _payload_inertial(scn, e.payload)
        return Event(e.t, f"payload_swap {e.body} = {e.payload} ({inertial['mass']:g} kg)",
                     lambda plant, e=e: plant.set_body_inertial(e.body, **inertial))
    if e.kind == "payload_mass":
        return Event(e.t, f"payload_mass {e.body} = {e.value} kg",
                     lambda plant, e=e: plant.set_body_mass(e.body, e.value))
    if e.kind == "fluid_density_scale":
        return Event(e.t, f"fluid density x {e.value}",
                     lambda plant, e=e: plant.set_fluid_density(plant.model.opt.density * e.value))

    def add_force(plant, e=e):
        plant.force_offset += e.value

    return Event(e.t, f"constant force {e.value:+g}", add_force)


# --------------------------------------------------------------------------
# manipulators
def _manipulator_setup(scn: Scenario, source: ModelSource) -> Setup:
    from adaptive_mj.laws.slotine_li import Mode, SlotineLiLaw
    from adaptive_mj.plants.manipulator import ManipulatorPlant, servo_to_torque

    p = scn.plant
    notes: list[str] = []

    def edit(spec):
        if p.manipulator.servo_to_torque:
            try:
                notes.extend(servo_to_torque(spec))
            except ModelError as exc:
                raise ScenarioError(f"{scn.source}: plant.servo_to_torque: {exc}") from None

    model, model_xml = _compile(scn, source, edit=edit)
    where = str(p.model)
    plant = ManipulatorPlant(model, unknown=p.manipulator.unknown, joint_params=p.manipulator.joint_params,
                             base=p.manipulator.base_parameters, where=where, notes=tuple(notes))
    reference = _joint_reference(scn, model, plant.joint_names)
    plant.set_state(reference(0.0, 2)[:2])
    L = scn.law
    lam = _per_joint(scn, "law.lambda", L.lam_joints if L.lam_joints is not None else L.lam, plant.joint_names)
    kd = _per_joint(scn, "law.kd", L.kd, plant.joint_names)
    mode = {"slotine_li": Mode.ADAPTIVE, "computed_torque": Mode.COMPUTED_TORQUE,
            "pd_gravity": Mode.PD_GRAVITY}[L.kind]
    try:
        law = SlotineLiLaw(plant.regressor, plant.names, plant.m, lam=lam, kd=kd,
                           gamma=_gamma(scn, plant.names) if L.gamma is not None else 1.0,
                           dead_zone=_dead_zone(L), mode=mode)
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: law: {exc}") from None
    theta_hat0 = _estimates(scn, plant.names, plant)
    for e in scn.events:
        plant.body_id(e.body)  # a missing body fails now, not mid-run
        if e.kind == "payload_swap":
            _payload_inertial(scn, e.payload)
    return Setup(plant=plant, law=law, reference=reference, theta_hat0=theta_hat0, noise_std=None,
                 rng=np.random.default_rng(scn.noise.seed), events=[_event(e, scn) for e in scn.events],
                 source=source, model_xml=model_xml, notes=tuple(notes))


def _per_joint(scn: Scenario, key: str, value, joints: tuple[str, ...]) -> np.ndarray:
    if not isinstance(value, dict):
        return np.full(len(joints), float(value))
    unknown = [j for j in value if j not in joints]
    if unknown:
        raise ScenarioError(f"{scn.source}: {key} names joint {unknown[0]!r}, which the model does not have "
                            f"(joints: {', '.join(joints)})")
    missing = [j for j in joints if j not in value]
    if missing:
        raise ScenarioError(f"{scn.source}: {key} must give every joint a value, missing {', '.join(missing)}")
    return np.array([value[j] for j in joints], dtype=float)


def _pose(scn: Scenario, key: str, value, model, joints: tuple[str, ...], base: np.ndarray) -> np.ndarray:
    """(m,) joint positions: a keyframe name, or a table {joint: position} over `base`."""
    import mujoco

    qadr = [model.jnt_qposadr[model.dof_jntid[j]] for j in range(model.nv)]
    if isinstance(value, str):
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, value)
        if k < 0:
            keys = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_KEY, i) for i in range(model.nkey)]
            raise ScenarioError(f"{scn.source}: {key} names keyframe {value!r}, which the model does not have "
                                f"(keyframes: {keys})")
        return np.array(model.key_qpos[k][qadr], dtype=float)
    out = base.copy()
    for name, v in value.items():
        if name not in joints:
            raise ScenarioError(f"{scn.source}: {key} names joint {name!r}, which the model does not have "
                                f"(joints: {', '.join(joints)})")
        out[joints.index(name)] = v
    return out


def _joint_reference(scn: Scenario, model, joints: tuple[str, ...]):
    r = scn.reference
    qadr = [model.jnt_qposadr[model.dof_jntid[j]] for j in range(model.nv)]
    qpos0 = np.array(model.qpos0[qadr], dtype=float)
    if r.kind == "joint_waypoints":
        points, prev = [], qpos0
        for i, w in enumerate(r.params["waypoints"]):
            prev = _pose(scn, f"reference.waypoints[{i}]", w, model, joints, prev)
            points.append(tuple(prev))
        try:
            return refs.JointWaypoints(waypoints=tuple(points), durations=tuple(r.params["durations"]),
                                       t0=r.params["t0"], cycle=r.params["cycle"])
        except ValueError as exc:
            raise ScenarioError(f"{scn.source}: reference: {exc}") from None
    center = qpos0 if r.params["center"] is None else _pose(scn, "reference.center", r.params["center"], model,
                                                              joints, qpos0)
    terms = {}
    for key in ("amplitudes", "omegas", "phases"):
        v = r.params[key]
        if v is None:
            terms[key] = None
        elif isinstance(v, dict):
            _per_joint_names(scn, f"reference.{key}", v, joints)
            terms[key] = tuple(tuple(v.get(j, ())) for j in joints)
        else:
            terms[key] = tuple(tuple(v) for _ in joints)
    if terms["phases"] is None:
        terms["phases"] = tuple(tuple(0.0 for _ in a) for a in terms["amplitudes"])
    try:
        return refs.JointSumOfSines(center=tuple(center), amplitudes=terms["amplitudes"], omegas=terms["omegas"],
                                    phases=terms["phases"])
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: reference: {exc}") from None


def _per_joint_names(scn: Scenario, key: str, value: dict, joints: tuple[str, ...]) -> None:
    for name in value:
        if name not in joints:
            raise ScenarioError(f"{scn.source}: {key} names joint {name!r}, which the model does not have "
                                f"(joints: {', '.join(joints)})")


def _payload_inertial(scn: Scenario, payload: str) -> dict:
    """mass, ipos, iquat, inertia of the body named "body" of a payload file (compiled alone)."""
    import mujoco

    from adaptive_mj.plants.arm import PAYLOADS
    from adaptive_mj.plants.mujoco_plant import compile_xml_path

    path = Path(payload) if Path(payload).suffix == ".xml" else PAYLOADS / f"{payload}.xml"
    if not path.is_file():
        choices = sorted(p.stem for p in PAYLOADS.glob("*.xml"))
        raise ScenarioError(f"{scn.source}: events: payload {payload!r} not found (bundled payloads: {choices})")
    model = compile_xml_path(path)
    b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "body")
    if b < 0:
        raise ScenarioError(f"{scn.source}: events: payload {payload!r} has no body named 'body'")
    return {"mass": float(model.body_mass[b]), "ipos": model.body_ipos[b].copy(),
            "iquat": model.body_iquat[b].copy(), "inertia": model.body_inertia[b].copy()}

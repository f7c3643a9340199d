"""Scenario -> the objects of a run: plant, law, reference, initial estimates,
noise, events. One call per box of the data flow; nothing here steps physics.

The model is compiled from an XML *string* (`model_source`) so that a log
can carry that exact string and `replay --verify` recompiles a bit-identical
model without the repo that made it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from adaptive_mj import reference as refs
from adaptive_mj.errors import ModelError, ScenarioError
from adaptive_mj.laws import (DeadZone, DeadZoneOn, FirstOrderAdaptiveLaw, FixedNominalLaw,
                              RobustSlidingLaw, SlidingAdaptiveLaw)
from adaptive_mj.loop import Event
from adaptive_mj.scenario import STATE_SIGNALS, Scenario


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


def model_source(scn: Scenario) -> ModelSource | None:
    """Read (heave) or compose with PyMJCF (arm + payload) the MJCF text to compile."""
    p = scn.plant
    if p.kind == "first_order" or (p.backend == "twin" and p.theta is not None):
        return None
    if p.kind == "arm":
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


def _compile(scn: Scenario, source: ModelSource):
    """(model, compiled MJCF text). A thruster lag turns the actuator into a first-order filter."""
    import mujoco

    from adaptive_mj.plants.mujoco_plant import compile_spec

    lag = scn.plant.thruster_time_constant

    def edit(spec):
        if lag is not None:
            for act in spec.actuators:
                act.dyntype = mujoco.mjtDyn.mjDYN_FILTER
                act.dynprm[0] = lag

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
    if L.kind not in ("fixed_nominal", "robust_sliding"):
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


def _event(e) -> Event:
    if e.kind == "payload_mass":
        return Event(e.t, f"payload_mass {e.body} = {e.value} kg",
                     lambda plant, e=e: plant.set_body_mass(e.body, e.value))
    if e.kind == "fluid_density_scale":
        return Event(e.t, f"fluid density x {e.value}",
                     lambda plant, e=e: plant.set_fluid_density(plant.model.opt.density * e.value))

    def add_force(plant, e=e):
        plant.force_offset += e.value

    return Event(e.t, f"constant force {e.value:+g}", add_force)

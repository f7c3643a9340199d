"""Scenario -> the objects of a run: plant, law, reference, initial estimates,
noise, events. One call per box of the data flow; nothing here steps physics.
Each plant kind builds itself (``plant_kinds()``: its module's ``model_source``
and ``from_scenario``), and each law kind too (its ``build`` in the law-kind registry,
adaptive_mj.laws.kinds, called with a `LawContext`: the scenario and the plant as the law sees it).

The model is compiled from an XML *string* (`model_source`) so that a log
can carry that exact string and `replay --verify` recompiles a bit-identical
model without the repo that made it.
"""
from __future__ import annotations

import math
import os

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, cast

import numpy as np

from adaptive_mj import reference as refs
from adaptive_mj.errors import ScenarioError
from adaptive_mj.form import ModelForm
from adaptive_mj.laws import DeadZone, DeadZoneOn, Law, Modification
from adaptive_mj.laws import kinds as law_kinds
from adaptive_mj.laws import pseudo_inertia
from adaptive_mj.laws.sliding import surface_noise_std
from adaptive_mj.plants import ModelSource
from adaptive_mj.plants import regressor_kernel as rk
from adaptive_mj.plants.protocol import CtrlRange, JointPlant, Plant, control_shape, has_form, has_joints
from adaptive_mj.setup.scenario import (JOINT_REFERENCE_KINDS, JOINT_SIGNALS, STATE_SIGNALS, EventSpec, LawSpec,
                                       Scenario)
from adaptive_mj.sensors import Sensors
from adaptive_mj.plants import Event, plant_order
from adaptive_mj.plants import kinds as plant_kinds_registry
from adaptive_mj.plants.events import swap_key

if TYPE_CHECKING:
    from adaptive_mj.plants.manipulator import ManipulatorPlant
    from adaptive_mj.plants.protocol import NativePlant


@dataclass
class Setup:
    """Everything `loop.run` needs, built from a scenario. plant and law: the protocols of
    adaptive_mj.plants.protocol and adaptive_mj.laws.protocol; reference(t, order) -> (order+1, ...)."""

    plant: Plant
    law: Law
    reference: Callable[[float | np.ndarray, int], np.ndarray]
    theta_hat0: np.ndarray
    noise_std: np.ndarray | None
    rng: np.random.Generator
    events: list[Event]
    source: ModelSource | None
    model_xml: str | None = None  # the compiled model as MJCF (the log's model.xml)
    notes: tuple[str, ...] = ()  # model edits made for the run (servo_to_torque), shown and logged
    sensors: Sensors | None = None  # an arm's encoders and velocity estimate (None: the law sees x + noise)


def plant_kinds(kind: str | None = None) -> dict:
    """plant.kind -> what builds it (``model_source(scn)``, ``from_scenario(scn, source)``): the
    bundled kinds' modules, and installed plant plugins (adaptive_mj.plants.plugin) when `kind` is
    not a bundled one."""
    from adaptive_mj.plants.kinds import built_in

    kinds = {name: k.builder() for name, k in built_in().items()}
    if kind is not None and kind not in kinds:
        from adaptive_mj.plants.plugin import installed

        kinds.update({name: inst.plugin for name, inst in installed().items()})
    return kinds


def model_source(scn: Scenario) -> ModelSource | None:
    """The MJCF text to compile (read, or composed with PyMJCF), or None for a model-free twin."""
    return plant_kinds(scn.plant.kind)[scn.plant.kind].model_source(scn)


def build(scn: Scenario, *, source: ModelSource | None = None) -> Setup:
    """Build a run's objects. `source` replaces the model files (used by replay --verify)."""
    kind = plant_kinds(scn.plant.kind)[scn.plant.kind]
    if source is None:
        check_payload_file(scn)  # a bad plant.payload is one line, before PyMJCF reads it
        source = kind.model_source(scn)
    source = with_event_payloads(scn, source)  # every payload_swap file read and checked before anything runs
    built = kind.from_scenario(scn, source)
    plant = built.plant
    for e in scn.events:
        _check_event(scn, e, plant, source)  # a missing body or payload fails now, not mid-run
    reference = _reference(scn, plant)
    order = plant_order(plant)
    plant.set_state(_initial_state(scn, reference, order, plant))
    names = tuple(plant.names)
    theta_hat0 = _estimates(scn, names, plant)
    problem = getattr(plant, "estimate_problem", None)  # a plant whose laws need estimates of some sign (a quadrotor)
    if problem is not None and (why := problem(theta_hat0)) is not None:
        key = "law.nominal" if scn.law.nominal is not None and scn.law.initial_estimates is None else \
            "law.initial_estimates"
        raise ScenarioError(f"{scn.source}: {key}: {why}")
    law = _law(scn, plant, _modification(scn, names, theta_hat0))
    check_run_memory(scn, plant, law)
    std = None
    sensors = None
    state_names = tuple(getattr(plant, "state_names", ()))
    if state_names:  # named state rows (a quadrotor's p, v, phi, omega): one σ per row, the same on every axis
        if scn.noise.std:
            std = np.array([[float(scn.noise.std.get(sig, 0.0))] * len(plant.joint_names) for sig in state_names])
    elif has_joints(plant):
        joints = tuple(plant.joint_names)
        if scn.noise.std:
            std = np.array([_per_joint(scn, f"noise.std.{sig}", scn.noise.std.get(sig, 0.0), joints)
                            for sig in JOINT_SIGNALS])
        sensors = _sensors(scn, plant)
        _arm_disturbance(scn, plant)
    else:
        if scn.noise.std:
            std = np.array([scn.noise.std.get(sig, 0.0) for sig in STATE_SIGNALS[:order]])
        plant.disturbance = _disturbance(scn)
    rng = np.random.default_rng(scn.noise.seed)
    return Setup(plant=plant, law=law, reference=reference, theta_hat0=theta_hat0, noise_std=std,
                 rng=rng, events=[_event(e, scn, source) for e in scn.events], source=source,
                 model_xml=built.model_xml, sensors=sensors,
                 notes=(*built.notes, *([scn.simulation.integrator_note] if scn.simulation.integrator_note else [])))


def row_bytes(plant: Plant, law: Law) -> int:
    """Bytes a run holds in memory for each physics step (adaptive_mj.sim.loop.Rows: t, x, u, s, ref, θ̂, V as
    float64; the true θ is kept per event, not per step)."""
    order, js, nth = plant_order(plant), int(np.prod(plant.joint_shape)), len(law.names)
    return 8 * (1 + order * js + int(np.prod(control_shape(plant))) + js + (order + 1) * js + nth + 1)


def machine_memory() -> int | None:
    """This machine's physical memory [bytes] (None where the OS does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _size(n: float) -> str:
    for unit, scale in (("EiB", 2.0**60), ("PiB", 2.0**50), ("TiB", 2.0**40), ("GiB", 2.0**30), ("MiB", 2.0**20)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n / 2.0**10:.3g} KiB"


def check_run_memory(scn: Scenario, plant: Plant, law: Law, *, memory: int | None = None) -> None:
    """A ScenarioError, before anything runs, when simulation.duration / timestep asks for more physics steps
    than this machine's memory can hold rows for (a run keeps one row a step, row_bytes, until it ends; numpy
    would stop it with an allocation traceback). memory: the limit [bytes] (default machine_memory(); without
    one, only numpy's own limit on an array's size, 2^63 bytes)."""
    dt, duration = float(plant.dt), float(scn.simulation.duration)
    steps = duration / dt
    row = row_bytes(plant, law)
    limit = memory if memory is not None else machine_memory()
    limit_bytes = float(limit) if limit is not None else 2.0**63
    need = steps * row
    if need <= limit_bytes:
        return
    shown = f"{steps:.3g}" if math.isfinite(steps) else "more than 1e308"
    where = f"this machine's memory, {_size(limit_bytes)}" if limit is not None else "numpy's largest array"
    raise ScenarioError(
        f"{scn.source}: simulation.duration / simulation.timestep must ask for at most "
        f"{math.floor(limit_bytes / row):.3g} physics steps ({where}, at {row} bytes held per step), got "
        f"{duration:g} s / {dt:g} s = {shown} steps, which would need "
        f"{_size(need) if math.isfinite(need) else 'more than 1e308 bytes'}: shorten simulation.duration or "
        "lengthen simulation.timestep")


def check(scn: Scenario, sources: dict | None = None) -> None:
    """Build everything a run of `scn` reads (model and payload files, the names and keyframes it
    refers to, the law), stepping nothing: a study checks each of its runs with it before any runs.
    Raises the one-line ScenarioError or ModelError the run itself would. sources: a cache of
    model sources by [plant] section (a model_source depends on nothing else), so grid points
    that share a plant read and compose its files once."""
    if sources is None:
        build(scn)
        return
    key = repr(scn.plant)
    if key not in sources:
        check_payload_file(scn)
        sources[key] = plant_kinds(scn.plant.kind)[scn.plant.kind].model_source(scn)
    build(scn, source=sources[key])


def _initial_state(scn: Scenario, reference, order: int, plant: Plant | None = None) -> np.ndarray:
    """x0: (n,) or (n, m); on the reference [y_d(0), ..., y_d^(n-1)(0)], given, or zeros."""
    x0 = scn.simulation.initial_state
    if x0 == "reference":
        ref0 = np.asarray(reference(0.0, order), dtype=float)
        on = getattr(plant, "state_on_reference", None)  # a plant whose state rows are not y's derivatives
        return np.asarray(on(ref0) if on is not None else ref0[:order], dtype=float)
    return np.asarray(x0 if x0 is not None else (0.0,) * order, dtype=float)


def check_payload_file(scn: Scenario) -> None:
    """plant.payload (arm, manipulator on MuJoCo): found, and a payload MJCF with mass
    (adaptive_mj.plants.payload.check_text), else one line naming the file."""
    from adaptive_mj.plants import payload as pl

    p = scn.plant
    if p.payload is None or not p.payload_paths or (p.backend == "twin" and p.theta is not None):
        return
    path = pl.locate(p.payload, p.payload_paths, where=scn.source, key="plant.payload")
    text = pl.read(path)
    if (str(path), text) in _payloads_checked:  # a study's runs share a payload: compiled once per process
        return
    pl.check_text(text, path, on_disk=True)
    _payloads_checked.add((str(path), text))


#: (path, text) of the payload files check_payload_file has passed in this process (it compiles each, ~1 ms)
_payloads_checked: set[tuple[str, str]] = set()


def with_event_payloads(scn: Scenario, source: ModelSource | None) -> ModelSource | None:
    """`source` with the text of every payload_swap file as an asset (payload.ASSET_PREFIX + the name
    as written), read and checked now; a source that already carries one (a log's) keeps it."""
    from adaptive_mj.plants import payload as pl

    swaps = [e for e in scn.events if e.payload is not None]  # a payload field: payload_swap's
    if source is None or not swaps:
        return source
    assets = dict(source.assets)
    for e in swaps:
        assert e.payload is not None  # swaps holds only events with a payload
        key = pl.ASSET_PREFIX + e.payload
        if key in assets:
            continue
        path = pl.locate(e.payload, e.payload_paths, where=scn.source, key=swap_key(e))
        text = pl.read(path)
        pl.swap_inertial(pl.check_text(text, path, on_disk=True), path)
        assets[key] = text.encode("utf-8")
    return ModelSource(source.xml, assets)


def _check_event(scn: Scenario, e: EventSpec, plant: Plant, source: ModelSource | None = None) -> None:
    """An event's own check before anything runs (its kind's EventKind.on_build: a missing body or payload)."""
    kind = plant_kinds_registry.event_kind(e.kind)
    if kind is not None and kind.on_build is not None:
        kind.on_build(scn, e, plant, source)


def _named(scn: Scenario, key: str, values: dict[str, float] | str, names: tuple[str, ...],
           plant: Plant | None = None) -> np.ndarray:
    if values == "model":
        assert plant is not None  # "model" is an estimate table's value, read with the plant (_estimates)
        return np.array(plant.true_theta(), dtype=float)
    if tuple(values) != names:
        raise ScenarioError(f"{scn.source}: {key} must have the keys {', '.join(names)} in that order, "
                            f"got {', '.join(values) or 'none'}")
    assert isinstance(values, dict)  # the one string value is "model" (scenario._estimate_table)
    return np.array(list(values.values()), dtype=float)


def _law(scn: Scenario, plant: Plant, modification: Modification | None = None) -> Law:
    """The law of law.kind for `plant`, built by its kind (adaptive_mj.laws.kinds; a law plugin: `_plugin`); a
    law's own ValueError becomes a one-line ScenarioError."""
    kind = law_kinds.built_in().get(scn.law.kind)
    try:
        if kind is None or kind.build is None:
            return _plugin(scn, plant, modification)
        return kind.build(LawContext(scn, plant, modification))
    except ScenarioError:
        raise
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: law: {exc}") from None


@dataclass(frozen=True)
class LawContext:
    """What a law kind's builder sees (adaptive_mj.laws.kinds.BuildContext): the scenario, the shared
    modifications and the plant through the form the law serves (the scenario checked that it offers it)."""

    scenario: Scenario
    plant: Plant
    modification: Modification | None

    @property
    def law(self) -> LawSpec:
        return self.scenario.law

    def model_form(self) -> ModelForm:
        assert has_form(self.plant)  # a law of the model form: the scenario checked that the plant offers it
        return self.plant.form

    def rigid_body(self) -> law_kinds.RigidBody:
        plant = self.plant
        assert has_joints(plant)  # a rigid-body law: the scenario checked that the plant offers the form
        return law_kinds.RigidBody(plant.regressor, plant.names, plant.m, tuple(plant.joint_names))

    def mrac_state(self) -> law_kinds.MracState:
        return _mrac_state(self.scenario, self.plant)

    def airframe(self) -> law_kinds.AirframeView:
        af = getattr(self.plant, "airframe", None)  # a plant offering Form.AIRFRAME (plants.quadrotor) has one
        assert af is not None, "a law of the airframe form on a plant without an airframe"
        g = float(-cast("NativePlant", self.plant).model.opt.gravity[2])
        return law_kinds.AirframeView(af.allocation.copy(), af.thrust_max.copy(), g, tuple(self.plant.names))

    def gamma(self, names: tuple[str, ...]) -> np.ndarray | float | None:
        return _gamma(self.scenario, names)

    def dead_zone(self) -> DeadZone | None:
        return _dead_zone(self.scenario, self.plant)

    def saturation(self) -> CtrlRange:
        return _saturation(self.scenario, self.plant)

    def per_joint(self, key: str, value: float | dict[str, float]) -> np.ndarray:
        return _per_joint(self.scenario, key, value, tuple(self.plant.joint_names))

    def named(self, key: str, values: dict[str, float], names: tuple[str, ...]) -> np.ndarray:
        return _named(self.scenario, key, values, names)


def _mrac_state(scn: Scenario, plant: Plant) -> law_kinds.MracState:
    """The plant in MRAC's state form, as its kind declares it (PlantKind.mrac_state in the kind's module: the
    sign and size of b, the matched nonlinear terms)."""
    kind = plant_kinds_registry.lookup(scn.plant.kind)
    # a law of Form.MRAC_STATE runs only on a plant kind offering it (scenario._law), which declares mrac_state
    if kind is None or kind.mrac_state is None:
        raise ScenarioError(f"{scn.source}: plant.kind {scn.plant.kind!r} declares no MRAC state form "
                            "(plants/kinds.py: PlantKind.mrac_state)")
    return kind.mrac_state(scn, plant)


def _saturation(scn: Scenario, plant: Plant) -> CtrlRange:
    """law.saturation = "freeze": the plant's limits (lo, hi): (m,) [N m] on an arm, floats [N or N m] on a 1-DOF
    plant; they must exist."""
    if plant.ctrl_range is None:
        raise ScenarioError(f"{scn.source}: law.saturation = 'freeze' needs torque limits (the model's actuator "
                            "ctrlrange), but no actuator is limited")
    return plant.ctrl_range


def _plugin(scn: Scenario, plant: Plant, modification: Modification | None) -> Law:
    """law.kind = an installed law plugin (adaptive_mj.laws.plugin): its declared keys laid out as its params
    array (a per-parameter key: n_theta numbers in the plant's parameter order), the shared modifications,
    and the law over the plant's form (a JointLawPlugin over an arm's regressor)."""
    from adaptive_mj.laws.plugin import JointLawPlugin, JointPluginLaw, PluginLaw, Shared, installed

    inst = installed().get(scn.law.kind)
    if inst is None:
        raise ScenarioError(f"{scn.source}: law.kind {scn.law.kind!r} is not an installed law plugin")
    plugin = inst.plugin
    if has_joints(plant):
        names = tuple(plant.names)
    else:
        assert has_form(plant)  # joint_shape () when not has_joints
        names = plant.form.names
    plugin_params = scn.law.plugin_params
    assert plugin_params is not None  # set for every law plugin (scenario._plugin_law)
    values: list[float] = []
    for p in plugin.params:
        v = plugin_params[p.name]
        if not p.per_parameter:
            values.append(float(v))
        elif isinstance(v, dict):
            values += list(_named(scn, f"law.{p.name}", v, names))
        else:
            values += [float(v)] * len(names)
    params = np.array(values, dtype=float)
    gamma = params[plugin.layout(len(names))[plugin.gain]] if plugin.gain is not None else None
    shared = Shared.of(len(names), gamma=gamma, dead_zone=_dead_zone(scn, plant), modification=modification)
    if isinstance(plugin, JointLawPlugin):
        assert has_joints(plant)  # a JointLawPlugin serves only plants of joints (scenario._law: its forms)
        return JointPluginLaw(inst, plant.regressor, names, plant.m, params, shared=shared, modification=modification)
    assert has_form(plant)  # a LawPlugin serves only 1-DOF plants (scenario._law: its forms)
    return PluginLaw(inst, plant.form, params, shared=shared, modification=modification)


def _gamma(scn: Scenario, names: tuple[str, ...]) -> np.ndarray | float | None:
    g = scn.law.gamma
    return _named(scn, "law.gamma", g, names) if isinstance(g, dict) else g


def _surface_slope(scn: Scenario) -> float:
    """λ of s = ỹ' + λỹ, for a dead-zone sized from the noise in s: law.lambda, or a law plugin's (or a law
    kind's LawSpec.params) own key `lambda`; a law without one is refused in one line (its s is its own:
    adaptive-mj cannot size it)."""
    if scn.law.lam is not None:
        return scn.law.lam
    lam = (scn.law.plugin_params or scn.law.params or {}).get("lambda")
    if not isinstance(lam, (int, float)):
        raise ScenarioError(f"{scn.source}: law.dead_zone.width_in_noise_std on s needs the surface's slope, and "
                            f"law.kind = {scn.law.kind!r} declares no number key 'lambda'; give law.dead_zone.width, "
                            "or on = 'tracking_error'")
    return float(lam)


def _dead_zone(scn: Scenario, plant: Plant) -> DeadZone | None:
    """law.dead_zone; with width_in_noise_std = k, ε = k σ where σ is the standard deviation the
    noise gives the tested signal: σ_s = sqrt(Σ c_i² σ_i²) for s = Σ c_i ỹ^(i) (σ_i: noise.std of
    the i-th state component), or σ_y for the tracking error."""
    dz = scn.law.dead_zone
    if dz is None:
        return None
    if dz.width_in_noise_std is None:
        assert dz.width is not None  # law.dead_zone gives width or width_in_noise_std (scenario._dead_zone)
        return DeadZone(dz.width, DeadZoneOn(dz.on))
    if has_joints(plant):
        return DeadZone(dz.width_in_noise_std * _arm_noise_scale(scn, plant, dz.on), DeadZoneOn(dz.on))
    std = np.array([scn.noise.std.get(sig, 0.0) for sig in STATE_SIGNALS[:plant_order(plant)]])
    if not np.any(std > 0):
        raise ScenarioError(f"{scn.source}: law.dead_zone.width_in_noise_std needs noise.std (the noise its "
                            "width is a multiple of), got no noise")
    if dz.on == "s" and (scn.law.lam is not None or scn.law.plugin_params is not None or scn.law.params is not None):
        sigma = surface_noise_std(len(std), _surface_slope(scn), std)
    else:
        sigma = float(std[0])
    return DeadZone(dz.width_in_noise_std * sigma, DeadZoneOn(dz.on))


def _arm_noise_scale(scn: Scenario, plant: JointPlant, on: str) -> float:
    """σ of an arm's dead-zone signal: sqrt(Σ_j σ_s,j²) for ‖s‖ (sensors.surface_noise_std, with the
    encoders and the velocity estimate), sqrt(Σ_j σ_q,j² + Δ_j²/12) for ‖q̃‖."""
    from adaptive_mj.sensors import surface_noise_std as arm_surface_noise

    joints = tuple(plant.joint_names)
    sig_q = _per_joint(scn, "noise.std.q", scn.noise.std.get("q", 0.0), joints)
    sig_dq = _per_joint(scn, "noise.std.q_dot", scn.noise.std.get("q_dot", 0.0), joints)
    sensors = _sensors(scn, plant)
    if not (np.any(sig_q > 0) or np.any(sig_dq > 0) or (sensors is not None and np.any(sensors.quantum > 0))):
        raise ScenarioError(f"{scn.source}: law.dead_zone.width_in_noise_std needs noise.std (or encoders: "
                            "sensors.encoder_counts), the noise its width is a multiple of; got none")
    if on != "s":
        quantum = sensors.quantum if sensors is not None else 0.0
        return float(np.sqrt(np.sum(sig_q**2 + np.asarray(quantum) ** 2 / 12.0)))
    lam_value = scn.law.lam_joints if scn.law.lam_joints is not None else _surface_slope(scn)
    lam = _per_joint(scn, "law.lambda", lam_value, joints)
    period = scn.control.period if scn.control.mode == "sampled" and scn.control.period else plant.dt
    return float(np.sqrt(np.sum(arm_surface_noise(lam, sig_q, sig_dq, sensors, period) ** 2)))


def _modification(scn: Scenario, names: tuple[str, ...], theta_hat0: np.ndarray) -> Modification | None:
    """law.sigma, law.e_modification, law.theta0 and law.projection as a laws.Modification."""
    R = scn.law.robust
    if R.sigma == 0.0 and R.e_modification == 0.0 and R.projection is None:
        return None
    theta0 = _named(scn, "law.theta0", R.theta0, names) if R.theta0 is not None else np.array(theta_hat0)
    lower = upper = None
    bodies: tuple[int, ...] = ()
    if R.projection is not None:
        lower, upper = np.full(len(names), -np.inf), np.full(len(names), np.inf)
        if R.projection in ("nonnegative", "physical"):  # masses, principal inertias, armature, damping >= 0
            for i, name in enumerate(names):
                if name.rsplit(".", 1)[-1] in PHYSICAL_NONNEGATIVE:
                    lower[i] = 0.0
        elif R.projection == "consistent":  # each body's pseudo-inertia PSD; the joints' own terms >= 0
            bodies = rigid_body_starts(names)
            if not bodies:
                raise ScenarioError(f"{scn.source}: law.projection = 'consistent' keeps rigid bodies' ten "
                                    "parameters physically consistent, and the law adapts no whole body "
                                    f"(parameters: {', '.join(names)})")
            for i, name in enumerate(names):
                if name.rsplit(".", 1)[-1] in JOINT_NONNEGATIVE:
                    lower[i] = 0.0
        else:
            assert not isinstance(R.projection, str)  # law_keys.RIGID_BODY_PROJECTIONS are the presets
            for name, (lo, hi) in R.projection.items():
                if name not in names:
                    raise ScenarioError(f"{scn.source}: law.projection names parameter {name!r}, which the law "
                                        f"does not have (parameters: {', '.join(names)})")
                lower[names.index(name)], upper[names.index(name)] = lo, hi
        outside = [i for i in range(len(names)) if not lower[i] <= theta_hat0[i] <= upper[i]]
        if outside:
            i = outside[0]
            raise ScenarioError(f"{scn.source}: law.projection: the initial estimate {names[i]} = "
                                f"{theta_hat0[i]:g} is outside its box [{lower[i]:g}, {upper[i]:g}]")
        for start in bodies:
            lam = pseudo_inertia.eigenvalues(theta_hat0, (start,))[0]
            if not pseudo_inertia.is_physical(lam[0], np.sum(np.abs(lam))):
                body = names[start].rsplit(".", 1)[0]
                raise ScenarioError(f"{scn.source}: law.projection = 'consistent': the initial estimate of body "
                                    f"{body!r} is no possible body (its pseudo-inertia has the eigenvalue "
                                    f"{lam[0]:.3g} < 0); expected initial estimates with J ⪰ 0")
    return Modification(sigma=R.sigma, e_mod=R.e_modification, theta0=theta0, lower=lower, upper=upper,
                        bodies=bodies)


#: parameter-name suffixes kept >= 0 by law.projection = "nonnegative" (its older name "physical"; manipulators):
#: a convex box that every physical body satisfies (necessary, not sufficient, for physical consistency)
PHYSICAL_NONNEGATIVE = ("m", "Ixx", "Iyy", "Izz", "armature", "damping", "coulomb")
#: the joints' own parameters, kept >= 0 by law.projection = "consistent" beside the bodies' pseudo-inertias
JOINT_NONNEGATIVE = ("armature", "damping", "coulomb")


def rigid_body_starts(names: tuple[str, ...]) -> tuple[int, ...]:
    """The index of each body's m among parameter names "<body>.<p>" whose ten parameters follow it in the
    standard order (regressor_kernel.BODY_PARAM_NAMES); a body given only in part is left out."""
    std = rk.BODY_PARAM_NAMES
    out = []
    for i, name in enumerate(names):
        body, _, p = name.rpartition(".")
        if p == std[0] and i + 10 <= len(names) and all(names[i + k] == f"{body}.{std[k]}" for k in range(10)):
            out.append(i)
    return tuple(out)


def _estimates(scn: Scenario, names: tuple[str, ...], plant: Plant) -> np.ndarray:
    """theta_hat(0). Baselines hold law.nominal (else law.initial_estimates); adaptive laws
    start from law.initial_estimates (else law.nominal, else zeros)."""
    L = scn.law
    kind = law_kinds.built_in().get(L.kind)
    first, second = ("nominal", "initial_estimates")
    if kind is None or kind.adaptive:  # a law plugin, or an adaptive built-in kind
        first, second = second, first
    for key in (first, second):
        values = getattr(L, key)
        if values is not None:
            return _named(scn, f"law.{key}", values, names, plant)
    nominal = getattr(plant, "nominal_theta", None)  # what a law knows of the plant untold (a quadrotor: no payload)
    return np.array(nominal(), dtype=float) if nominal is not None else np.zeros(len(names))


def _reference(scn: Scenario, plant: Plant) -> Callable[[float | np.ndarray, int], np.ndarray]:
    r = scn.reference
    own = plant_kinds_registry.lookup(scn.plant.kind)
    if own is not None and own.reference_builder is not None:  # the kind's own references
        try:
            return own.reference_builder(r)
        except ValueError as exc:
            raise ScenarioError(f"{scn.source}: reference: {exc}") from None
    if r.kind in JOINT_REFERENCE_KINDS:
        # joint references are for plant.kind = 'manipulator' (scenario._reference), a MuJoCo plant
        return _joint_reference(scn, cast("NativePlant", plant).model, plant.joint_names)
    if r.kind == "reference_model":
        M = scn.law.mrac
        assert M is not None  # reference.kind = 'reference_model' needs law.kind = 'mrac' (scenario._validate)
        try:
            return refs.ModelResponse(alpha=M.alpha, beta=M.beta, **r.params)
        except ValueError as exc:
            raise ScenarioError(f"{scn.source}: reference: {exc}") from None
    cls = {"constant": refs.Constant, "cosine": refs.Cosine, "sine": refs.Sine,
           "sum_of_sines": refs.SumOfSines, "smooth_step": refs.SmoothStep, "waypoints": refs.Waypoints}[r.kind]
    return cls(**r.params)


def _sensors(scn: Scenario, plant: JointPlant) -> Sensors | None:
    """[sensors] of an arm as a stage.Sensors: encoder counts N -> quantum 2π/N rad (a slide joint:
    1/N m per count, i.e. counts per metre); None when ideal."""
    import mujoco

    sn = scn.sensors
    joints = tuple(plant.joint_names)
    counts = np.zeros(len(joints)) if sn.encoder_counts is None else \
        _per_joint(scn, "sensors.encoder_counts", sn.encoder_counts, joints)
    model = cast("NativePlant", plant).model  # a plant of joints is a MuJoCo plant (ManipulatorPlant, a plugin's)
    hinge = np.array([model.jnt_type[model.dof_jntid[j]] == mujoco.mjtJoint.mjJNT_HINGE
                      for j in range(len(joints))])
    quantum = np.where(counts > 0, np.where(hinge, 2.0 * np.pi, 1.0) / np.where(counts > 0, counts, 1.0), 0.0)
    out = Sensors(quantum=quantum, differentiated=sn.velocity == "differentiated", cutoff_hz=sn.velocity_cutoff_hz)
    return None if out.ideal else out


def _arm_disturbance(scn: Scenario, joint_plant: JointPlant) -> None:
    """[disturbance] on an arm: joint torques (adaptive_mj.disturbance) and unmodelled loads."""
    from adaptive_mj.disturbance import JointDisturbance

    # the joint torques and loads of [disturbance] are a manipulator's (scenario._disturbance: arm keys)
    plant = cast("ManipulatorPlant", joint_plant)
    d = scn.disturbance
    joints = tuple(plant.joint_names)
    if d.load:
        for body in d.load:
            plant.body_id(body)  # a ModelError naming the body when the model has none
        plant.loads = dict(d.load)
        plant.apply_loads()
    magnitude = _per_joint(scn, "disturbance.magnitude", d.magnitude, joints)
    if d.kind == "none" or not np.any(magnitude != 0.0):
        return
    rng = np.random.default_rng([scn.noise.seed, 1])  # its own stream: the measurement noise is unchanged
    plant.joint_disturbance = JointDisturbance(d.kind, magnitude, t0=d.t0, omega=d.omega, phase=d.phase,
                                               bandwidth_hz=d.bandwidth_hz, dt=plant.dt, rng=rng)


def _disturbance(scn: Scenario) -> Callable[[float], float] | None:
    d = scn.disturbance
    if d.kind == "none" or d.magnitude == 0.0:
        return None
    magnitude = d.magnitude
    assert not isinstance(magnitude, dict)  # a table by joint only on a manipulator (scenario._disturbance)
    if d.kind == "constant":
        return lambda t: magnitude
    if d.kind == "step":
        return lambda t: magnitude if t >= d.t0 else 0.0
    return lambda t: magnitude * float(np.sin(d.omega * t + d.phase))


def _event(e: EventSpec, scn: Scenario, source: ModelSource | None = None) -> Event:
    """The Event the loop applies, by its kind's effect builder (adaptive_mj.plants.events.EventKind.effect)."""
    kind = plant_kinds_registry.event_kind(e.kind)
    if kind is None:
        raise ScenarioError(f"{scn.source}: events: no plant kind accepts an event of kind {e.kind!r}")
    return kind.effect(e, scn, source)


# --------------------------------------------------------------------------
# manipulators: per-joint gains, poses and references


def _per_joint(scn: Scenario, key: str, value: float | dict[str, float], joints: tuple[str, ...]) -> np.ndarray:
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
    terms: dict[str, tuple[tuple[float, ...], ...] | None] = {}
    for key in ("amplitudes", "omegas", "phases"):
        v = r.params[key]
        if v is None:
            terms[key] = None
        elif isinstance(v, dict):
            _per_joint_names(scn, f"reference.{key}", v, joints)
            terms[key] = tuple(tuple(v.get(j, ())) for j in joints)
        else:
            terms[key] = tuple(tuple(v) for _ in joints)
    amplitudes, omegas = terms["amplitudes"], terms["omegas"]
    assert amplitudes is not None and omegas is not None  # required (scenario._joint_reference)
    if terms["phases"] is None:
        terms["phases"] = tuple(tuple(0.0 for _ in a) for a in amplitudes)
    try:
        return refs.JointSumOfSines(center=tuple(center), amplitudes=amplitudes, omegas=omegas,
                                    phases=terms["phases"])
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: reference: {exc}") from None


def _per_joint_names(scn: Scenario, key: str, value: dict, joints: tuple[str, ...]) -> None:
    for name in value:
        if name not in joints:
            raise ScenarioError(f"{scn.source}: {key} names joint {name!r}, which the model does not have "
                                f"(joints: {', '.join(joints)})")



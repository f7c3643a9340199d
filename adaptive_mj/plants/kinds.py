"""The plant kinds: each declares itself in its own module (`KIND = register(PlantKind(...))` beside its
`model_source` and `from_scenario`), and this registry finds them by construction: every module of the
adaptive_mj.plants package is imported once and what registered is the set of built-in kinds; installed
plant plugins (adaptive_mj.plants.plugin) join through the same PlantKind. The scenario loader, the builder,
`list --plants`, the units of every report and the law-form check read it; a new plant kind touches no
table elsewhere.

A kind declares: its name, the module that builds it, the forms a law can see it in
(adaptive_mj.laws.kinds.Form), its bundled model (None: an analytic plant), the SI units of its output, its
control and its parameters (for labels, summaries and the verdict's messages), and a line of doc; and what
a scenario may say of it: its plant.* keys as data (adaptive_mj.keys.Key) with the reader that checks them
(a function of the kind, the [plant] table and the scenario's folder, giving the PlantSpec; shared keys read by
adaptive_mj.plants.plant_keys), the [[events]] kinds it accepts (adaptive_mj.plants.events: each declared as data,
a kind's own in its module), what a law of the MRAC state form sees of it, the order of its dynamics and whether it
starts only on the reference; and what studies and reports see of it (the stress study's plant, the bench
sections that run it, how a video draws its estimates).
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping

from adaptive_mj.keys import Key, Table
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plugins import scan_built_in
from adaptive_mj.specs import PlantSpec
from adaptive_mj.plants.study_spec import BOX as _BOX

if TYPE_CHECKING:
    from adaptive_mj.laws.kinds import MracState
    from adaptive_mj.plants.events import EventKind
    from adaptive_mj.plants.study_spec import LawSet, StressorSet
    from adaptive_mj.specs import Scenario

    Reader = Callable[["PlantKind", Table, Path], PlantSpec]

#: the units of a rigid body's (and a joint's) parameters on a multi-joint plant, by the name's last part
BODY_PARAM_UNITS = {"m": "kg", "mcx": "kg m", "mcy": "kg m", "mcz": "kg m", "Ixx": "kg m²", "Ixy": "kg m²",
                    "Iyy": "kg m²", "Ixz": "kg m²", "Iyz": "kg m²", "Izz": "kg m²", "armature": "kg m²",
                    "damping": "N m s/rad", "coulomb": "N m"}


def body_param_unit(name: str) -> str:
    """Unit of a multi-joint parameter "<body>.<param>" or "<joint>.armature" (a base parameter ends in "*")."""
    return BODY_PARAM_UNITS.get(name.rstrip("*").rsplit(".", 1)[-1], "")


def second_order(plant: PlantSpec, law_order: Any) -> int:
    """The order n of a mechanical plant's dynamics (y'' = ...): 2, whatever law.order says."""
    return 2


def first_order(plant: PlantSpec, law_order: Any) -> int:
    """The order n of a first-order plant (x' = ...): 1."""
    return 1


@dataclass(frozen=True)
class Draw:
    """One quantity of a scorecard task drawn afresh for every seed, the same draw for every law on that seed (a
    paired comparison): `key`, a scenario key of the task's scenario (reference.*, plant.*), whose value there (a
    number, or the numbers of a list or a table) is multiplied by a factor drawn uniformly from [lo, hi], or with
    `add`, has a number drawn from [lo, hi] added (e.g. a phase [rad]); each: a draw per number (else one for them
    all). The key "law.initial_estimates" draws each parameter's factor on its truth in the task's scenario as
    bundled (from the compiled model, before any other draw: a drawn payload changes the truth, not the box a
    projection baseline sets about the scenario's)."""

    key: str
    lo: float
    hi: float
    each: bool = False
    add: bool = False


#: each parameter's initial estimate drawn between half and twice its truth: within the projection baselines' box
#: (adaptive_mj.plants.study_spec.BOX), so no baseline starts outside its own set
ESTIMATES_DRAW = Draw("law.initial_estimates", *_BOX)


@dataclass(frozen=True)
class ScoreTask:
    """One task of the scorecard (adaptive_mj.study.score_suite) on a plant kind's row, one run per seed: a bundled
    scenario and its overrides, as templates over the plant's derived numbers ({half}: half the run [s];
    {theta_half}: half the true θ as a law.initial_estimates table; {payload_x4}: four times the scenario's
    plant.payload_mass [kg]; {{ }}: one brace); noise_scale: the plant's nominal noise times this (0: the
    scenario's own noise); extras: the analyses the task reads (adaptive_mj.study.job.EXTRAS); draws: what each
    seed draws of the task (Draw), applied after the overrides (none: a seed draws only the noise)."""

    name: str
    scenario: str
    overrides: tuple[str, ...]
    noise_scale: float = 1.0
    extras: tuple[str, ...] = ()
    draws: tuple[Draw, ...] = ()


@dataclass(frozen=True)
class StressPlant:
    """A plant kind's row in the breaking-point study (adaptive_mj.study.stress), everything the study judges it by
    but its failure bound and nominal noise (PlantKind.tail_bound, .nominal_noise): name (its label, e.g. "ur5e"),
    the bundled scenario it runs (without ".toml"), and the overrides that make it a stress run beyond the
    duration, the estimates at the truth and the nominal noise (e.g. "events=[]"; each plant's own);
    noise_signals: the measured signals the nominal noise σ_y [output unit] and 10 σ_y [per s] are on; label,
    disturbance, composite: see each; laws: its laws, `laws(ctx, composite)` -> [(label, overrides)], and
    stressors: its own stressors, `stressors(ctx, duration [s])` -> [Stressor] (the study adds the delay and the
    control period, the same on every plant), each a function of the row's adaptive_mj.plants.study_spec
    StudyContext (its numbers from the compiled model) declared beside the kind (the 1-DOF sliding family:
    adaptive_mj.plants.sliding_study); tasks: the scorecard's tracking, change and hold tasks on this plant
    (ScoreTask)."""

    name: str
    scenario: str
    overrides: tuple[str, ...] = ()
    noise_signals: tuple[str, str] = ("y", "y_dot")
    label: str = ""  # how the report names it beside its failure bound (default: name)
    disturbance: tuple[float, float] = (0.1, 100.0)  # the sinusoidal disturbance's range [control unit]
    composite: str | None = None  # law.composite of the composite law (None: no composite row)
    tasks: tuple[ScoreTask, ...] = ()  # the scorecard's tasks on this plant (none: not scored)
    laws: LawSet = field(kw_only=True)
    stressors: StressorSet = field(kw_only=True)
    # score --scenario's hold task on a user's scenario of this kind: the built plant and its reference's start
    # y_d(0) (a float, or (m,) on m joints or axes) -> the override that holds it (adaptive_mj.plants.study_spec)
    hold: "Callable[[Any, Any], str]" = field(kw_only=True)


@dataclass(frozen=True)
class PlantKind:
    """A plant kind (see the module docstring). params: {parameter name: unit}; param_unit: a function of the
    name instead (a multi-joint plant, whose parameter names depend on its model)."""

    name: str
    module: str
    forms: frozenset[Form]
    output_unit: str
    control_unit: str
    params: Mapping[str, str] = field(default_factory=dict)
    default_model: str | None = None
    doc: str = ""
    param_unit: Callable[[str], str] | None = None
    default_law: str = "sliding_adaptive"  # the law.kind of a scenario that names none
    # what studies judge it by: the tail RMS tracking error above which a run has failed [output unit] (on a
    # multi-joint plant the RMS over its joints), and the nominal measurement noise σ_y [output unit] of the
    # stress study (σ of ẏ is 10 σ_y per second); None: not in the stress study
    tail_bound: float | None = None
    nominal_noise: float | None = None
    # the stability criteria of its runs' verdict where the scenario's [success] leaves them unset (SuccessSpec
    # .tail_saturation, .oscillation; adaptive_mj.setup.success): the largest fraction of the tail's rows with any
    # actuator at a limit, and the largest sustained oscillation of the body rate [rad/s]; None: not judged
    tail_saturation: float | None = None
    oscillation: float | None = None
    origin: str = "built in"
    # what a scenario may say of it: its plant.* keys (shared ones too, as this kind reads them), the reader
    # (None: no built-in reader, a plant plugin's keys are read from its plugin); [[events]] kinds it accepts
    # (adaptive_mj.plants.events.EventKind, declared in its own module or shared), each with the backend it
    # needs (None: any); the order n of its dynamics from the PlantSpec and the raw
    # law.order; starts_on_reference: simulation.initial_state may only be "reference" (its default)
    keys: tuple[Key, ...] = ()
    reader: "Reader | None" = None
    events: Mapping[EventKind, str | None] = field(default_factory=dict)
    order: Callable[[PlantSpec, Any], int] = second_order
    # how a message words the law.order values it allows (e.g. "2, or 3 with plant.thruster_time_constant"; None:
    # the order n alone); its reader copies it into the PlantSpec (PlantSpec.orders_text) for the law readers
    orders_text: str | None = None
    starts_on_reference: bool = False
    # what studies and reports see of it: its row in the stress study (None: not in it), the bench sections
    # that run it (their titles, for the plant's units in their tables), and whether a video's estimate panel
    # groups its parameters by unit (a multi-joint plant: many parameters, one axis per unit)
    stress: StressPlant | None = None
    sections: tuple[str, ...] = ()
    group_params_by_unit: bool = False
    # what a law of Form.MRAC_STATE sees of it (the scenario, the built plant -> laws.kinds.MracState: the sign
    # and size of b, the matched nonlinear terms); None: it does not offer that form
    mrac_state: Callable[[Scenario, Any], MracState] | None = None
    # the unit of a run's Lyapunov function V on its axes (the plant's energy, J; "-" on a dimensionless plant)
    lyapunov_unit: str = "J"
    # a kind whose state rows are named (a quadrotor's p, v, phi, omega: the plant's state_names): its measured
    # signals for noise.std (each a number [its row's unit], the same on every axis), its own [reference] reader
    # (the [reference] table -> a ReferenceSpec; None: the shared 1-DOF or joint kinds) and builder (the spec
    # -> reference(t, order))
    noise_signals: tuple[str, ...] = ()
    reference_reader: Callable[[Table], Any] | None = None
    reference_builder: Callable[[Any], Any] | None = None
    # simulation.timestep when a scenario of this kind gives none and its plant has no model to take it from [s]
    # (a process whose time constants are hours steps in seconds, not the 1 ms of a mechanical plant)
    default_timestep: float = 0.001

    @property
    def rigid_body(self) -> bool:
        """Whether it is a multi-joint plant (offers Form.RIGID_BODY): joint-space noise, disturbance, sensors
        and references."""
        return Form.RIGID_BODY in self.forms

    def key_names(self) -> tuple[str, ...]:
        """The names of its declared plant.* keys, in order."""
        return tuple(k.name for k in self.keys)

    def read(self, t: Table, base_dir: Path) -> PlantSpec:
        """Its [plant] table `t` (plant.kind already this kind's name) checked into a PlantSpec; base_dir: the
        scenario's folder (relative model and payload paths)."""
        if self.reader is None:
            raise ValueError(f"plant kind {self.name!r} has no key reader (plants/kinds.py: PlantKind.reader)")
        spec = self.reader(self, t, base_dir)
        return spec if self.orders_text is None else replace(spec, orders_text=self.orders_text)

    def unit_of(self, name: str) -> str:
        """Unit of parameter `name` ('' when not declared)."""
        return self.param_unit(name) if self.param_unit is not None else self.params.get(name, "")

    def builder(self):
        """What builds it: an object with ``model_source(scn)`` and ``from_scenario(scn, source)``."""
        return importlib.import_module(self.module)


_BUILT_IN: dict[str, PlantKind] = {}
_SCANNED = False


def register(kind: PlantKind) -> PlantKind:
    """Called by a plant module at import: adds its kind to the built-in registry (a name once)."""
    if kind.name in _BUILT_IN and _BUILT_IN[kind.name] != kind:
        raise ValueError(f"plant kind {kind.name!r} registered twice ({_BUILT_IN[kind.name].module}, {kind.module})")
    _BUILT_IN[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Removes a kind registered at run time (a test's toy kind); a built-in kind's module still holds it."""
    _BUILT_IN.pop(name, None)


def built_in() -> dict[str, PlantKind]:
    """The built-in plant kinds by name, in the order their modules register (every module of the package is
    imported once: a kind is found by its own module, not by a list)."""
    global _SCANNED
    if not _SCANNED:
        scan_built_in("adaptive_mj.plants", _BUILT_IN, ORDER)  # sorted once; later calls copy it
        _SCANNED = True
    return dict(_BUILT_IN)


#: the order the built-in kinds are listed in (a kind missing here comes last): the lecture's order
ORDER = ("heave", "arm", "first_order", "manipulator", "ship", "linear", "wing_rock", "process", "quadrotor")


#: the order [[events]] kinds are listed in (`events[i].kind must be one of ...`); a kind's own event kind
#: missing here comes last, in the order the plant kinds declare them
EVENT_ORDER = ("payload_mass", "payload_swap", "fluid_density_scale", "constant_force", "loading", "thrust_scale",
               "flight_condition")


def event_kinds() -> tuple[str, ...]:
    """Every [[events]] kind some built-in plant kind accepts (PlantKind.events), in EVENT_ORDER."""
    names = list(dict.fromkeys(e.name for k in built_in().values() for e in k.events))
    return tuple(sorted(names, key=lambda e: EVENT_ORDER.index(e) if e in EVENT_ORDER else len(EVENT_ORDER)))


def event_kind(name: str) -> EventKind | None:
    """The [[events]] kind called `name` that a built-in plant kind accepts (adaptive_mj.plants.events), or
    None."""
    for k in built_in().values():
        for e in k.events:
            if e.name == name:
                return e
    return None


def accepting(event: str) -> tuple[tuple[str, ...], str | None]:
    """The built-in plant kinds that accept [[events]] kind `event` (in the registry's order) and the backend
    it needs (None: any; the first accepting kind's word, as they agree)."""
    found = [(k.name, backend) for k in built_in().values() for e, backend in k.events.items() if e.name == event]
    return tuple(n for n, _ in found), (found[0][1] if found else None)


def declaring(key: str) -> tuple[PlantKind, ...]:
    """The built-in plant kinds that declare plant.`key` (in the registry's order)."""
    return tuple(k for k in built_in().values() if key in k.key_names())


def plugin_kind(name: str, installed) -> PlantKind:
    """The PlantKind of an installed plant plugin (its units dict: output, control and parameter units)."""
    units = dict(installed.plugin.units)
    output, control = units.pop("output", ""), units.pop("control", "")
    return PlantKind(name, "", frozenset({Form.MODEL}), output, control, units, None, installed.plugin.doc,
                     origin=f"plugin from {installed.distribution} {installed.version} "
                            f"(source {installed.source_sha256[:12]})")


def all_kinds(*, plugins: bool = True) -> dict[str, PlantKind]:
    """Every plant kind by name: the built-in ones, then the installed plugins (when `plugins`)."""
    kinds = built_in()
    if plugins:
        from adaptive_mj.plants.plugin import installed

        for name, inst in sorted(installed().items()):
            kinds.setdefault(name, plugin_kind(name, inst))
    return kinds


def lookup(name: str | None) -> PlantKind | None:
    """The kind called `name` (built in, else an installed plugin), or None."""
    if not name:
        return None
    kinds = built_in()
    return kinds[name] if name in kinds else all_kinds().get(name)


def forms(name: str) -> frozenset[Form]:
    """The forms plant kind `name` offers (an unknown kind: the model form, as a plant plugin)."""
    kind = lookup(name)
    return kind.forms if kind is not None else frozenset({Form.MODEL})


def is_rigid_body(name: str | None) -> bool:
    """Whether plant kind `name` is a multi-joint plant (offers Form.RIGID_BODY; an unknown kind: no)."""
    kind = lookup(name)
    return kind is not None and kind.rigid_body


def output_unit(name: str | None) -> str:
    """SI unit of the kind's output y ('' when unknown)."""
    kind = lookup(name)
    return kind.output_unit if kind is not None else ""


def control_unit(name: str | None) -> str:
    """SI unit of the kind's control u ('' when unknown)."""
    kind = lookup(name)
    return kind.control_unit if kind is not None else ""


def lyapunov_unit(name: str | None) -> str:
    """Unit of a run's Lyapunov function V on plant kind `name` (PlantKind.lyapunov_unit; an unknown kind: J, as
    a plant plugin's; none: '')."""
    if not name:
        return ""
    kind = lookup(name)
    return kind.lyapunov_unit if kind is not None else "J"


def param_unit(name: str | None, param: str) -> str:
    """SI unit of parameter `param` of plant kind `name` ('' when unknown)."""
    kind = lookup(name)
    return kind.unit_of(param) if kind is not None else ""


def kind_of(scenario_text: str) -> str | None:
    """plant.kind of a scenario's TOML text (e.g. from a log), or None if it cannot be read or is not a kind
    this installation knows."""
    import tomllib

    try:
        kind = tomllib.loads(scenario_text).get("plant", {}).get("kind")
    except (tomllib.TOMLDecodeError, AttributeError):
        return None
    return kind if isinstance(kind, str) and lookup(kind) is not None else None


def docs_table() -> str:
    """The built-in law kinds and the forms the plant kinds offer, as docs/SCENARIOS.md shows them
    (tests/test_law_kinds.py keeps the two equal)."""
    from adaptive_mj.laws.kinds import BUILT_IN

    lines = ["| law.kind | serves | adapts | what it is |", "|---|---|---|---|"]
    for k in BUILT_IN.values():
        served = ", ".join(f"`{f.value}`" for f in sorted(k.forms, key=lambda f: f.value))
        lines.append(f"| `{k.name}` | {served} | {'yes' if k.adaptive else 'no'} | {k.doc} |")
    offers = ", ".join(f"`{p.name}`: " + ", ".join(f"`{f.value}`" for f in sorted(p.forms, key=lambda f: f.value))
                       for p in built_in().values())
    lines += ["", f"Plant kinds offer: {offers}; a plant plugin offers `model`."]
    return "\n".join(lines)


def plants_table() -> str:
    """The built-in plant kinds and the built-in laws that serve each (laws.kinds.serving: by form, and a law
    made for some plant kinds only on those), as the README shows them (tests/test_law_kinds.py keeps the two
    equal): the adaptive laws, then the baselines."""
    from adaptive_mj.laws.kinds import BUILT_IN, serving

    lines = ["| plant.kind | what it is | adaptive laws | baselines |", "|---|---|---|---|"]
    for p in built_in().values():
        laws = serving(p.name, p.forms, BUILT_IN)
        adaptive = ", ".join(f"`{n}`" for n in laws if BUILT_IN[n].adaptive)
        fixed = ", ".join(f"`{n}`" for n in laws if not BUILT_IN[n].adaptive)
        doc = p.doc.replace("|", "\\|")  # a | in a formula is no column
        lines.append(f"| `{p.name}` | {doc} | {adaptive} | {fixed} |")
    return "\n".join(lines)


if __name__ == "__main__":  # `python -m adaptive_mj.plants.kinds`: the law-kinds block of docs/SCENARIOS.md
    from adaptive_mj.plants.kinds import docs_table as table  # the registry the plant modules fill, not __main__'s

    print(table())
    print("\n(the README's plants block:)\n")
    from adaptive_mj.plants.kinds import plants_table

    print(plants_table())

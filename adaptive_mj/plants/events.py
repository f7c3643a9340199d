"""The [[events]] kinds: each is declared as data (`EventKind`: its name, the fields it takes, its value rule,
its effect builder and its checks) in the module of the plant kind that owns it, or here when several plant
kinds share it (constant_force, payload_mass, payload_swap). A plant kind accepts an event kind by
referencing it (PlantKind.events: {EventKind: the backend it needs}); the scenario loader
(adaptive_mj.setup.scenario._events) reads an event through its kind's declaration and the builder
(adaptive_mj.setup.build) calls its effect builder and check. A new event kind (a quadrotor's rotor
efficiency, a wind gust) lands in its plant kind's module and touches no table elsewhere.

An event's fields are read in the order its kind declares them (`EventField`). A field named like an attribute
of adaptive_mj.specs.EventSpec (body, payload, W, l_delta) goes there; any other goes to EventSpec.params.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

from adaptive_mj.errors import ScenarioError
from adaptive_mj.plants import Event, ModelSource

if TYPE_CHECKING:
    from adaptive_mj.keys import Table
    from adaptive_mj.plants.protocol import Plant
    from adaptive_mj.specs import EventSpec, PlantSpec, Scenario

#: an event kind's effect builder: (the event, the scenario, the run's model source) -> the Event the loop
#: applies (its label is what the log shows)
Effect = Callable[["EventSpec", "Scenario", "ModelSource | None"], Event]
#: a check when the scenario is loaded: (the event's table, the plant, the fields read) -> None or a ScenarioError
LoadCheck = Callable[["Table", "PlantSpec", "dict[str, Any]"], None]
#: a check when the run is built, before anything runs: (the scenario, the event, the plant, the model source)
BuildCheck = Callable[["Scenario", "EventSpec", Any, "ModelSource | None"], None]


@dataclass(frozen=True)
class EventField:
    """A field of an [[events]] table beyond t, kind and value: its name and how it is read (the event's
    table -> its value; a default when absent, if the field has one)."""

    name: str
    read: Callable[["Table"], Any]
    doc: str = ""


#: events[i].body: the body an event changes (default "payload/body"); every bundled kind takes it
BODY = EventField("body", lambda t: t.string("body", "payload/body"), "the body the event changes")

#: the value rules: "positive" (events[i].value > 0, required), "any" (a number, required), "none" (no value;
#: EventSpec.value is 0.0)
VALUE_RULES = ("positive", "any", "none")


@dataclass(frozen=True, eq=False)
class EventKind:
    """An [[events]] kind (see the module docstring): name; effect, its effect builder; value, its value rule
    (VALUE_RULES); fields, what else it takes, in the order they are read; on_load and on_build, its checks
    (None: none); doc, a line for `list --plants`; overrides, the scenario keys whose value it replaces from t on
    (e.g. "plant.payload_mass": a sweep over one of them notes the event), and sets, what it sets them to, as a
    message says it (e.g. "2.5 kg"). Compared by identity (a plant kind references it)."""

    name: str
    effect: Effect
    value: str = "positive"
    fields: tuple[EventField, ...] = (BODY,)
    on_load: LoadCheck | None = None
    on_build: BuildCheck | None = None
    doc: str = ""
    overrides: tuple[str, ...] = ()
    sets: Callable[["EventSpec"], str] | None = None

    def __post_init__(self) -> None:
        if self.value not in VALUE_RULES:
            raise ValueError(f"event kind {self.name!r}: value must be one of {VALUE_RULES}, got {self.value!r}")

    def read_value(self, t: Table) -> float:
        """events[i].value by the value rule."""
        if self.value == "none":
            return 0.0
        return t.number("value", gt=0 if self.value == "positive" else None)

    def read_fields(self, t: Table) -> dict[str, Any]:
        """Its fields, read in the order declared."""
        return {f.name: f.read(t) for f in self.fields}


# --------------------------------------------------------------------------
# the event kinds several plant kinds share


def _constant_force(e: EventSpec, scn: Scenario, source: ModelSource | None) -> Event:
    def add_force(plant: Plant, e: EventSpec = e) -> None:
        plant.force_offset += e.value

    return Event(e.t, f"constant force {e.value:+g}", add_force)


CONSTANT_FORCE = EventKind("constant_force", _constant_force, value="any",
                           doc="adds value to the force (or torque) offset on the plant from t on")


def swap_key(e: EventSpec) -> str:
    """How a payload_swap's payload is named in its messages."""
    return f"the payload_swap event at t={e.t:g} s: payload"


def payload_inertial(scn: Scenario, e: EventSpec, source: ModelSource | None) -> dict:
    """mass, ipos, iquat, inertia of the body named "body" of a payload_swap's file, compiled alone:
    the text the run's source carries (adaptive_mj.setup.build.with_event_payloads; a log's), else the file
    found now."""
    from adaptive_mj.plants import payload as pl

    assert e.payload is not None  # payload_swap events name their payload (PAYLOAD is required)
    data = (source.assets if source is not None else {}).get(pl.ASSET_PREFIX + e.payload)
    if data is not None:
        path = Path(f"{e.payload} (embedded)")
        return pl.swap_inertial(pl.check_text(bytes(data).decode("utf-8"), path, on_disk=False), path)
    path = pl.locate(e.payload, e.payload_paths, where=scn.source, key=swap_key(e))
    return pl.swap_inertial(pl.check_text(pl.read(path), path, on_disk=True), path)


def _payload_on_load(t: Table, plant: PlantSpec, fields: dict[str, Any]) -> None:
    """On a multi-joint plant (a plant kind offering the rigid-body form) the payload is known when the
    scenario is read: an event on a payload body needs one."""
    from adaptive_mj.plants import kinds

    if kinds.is_rigid_body(plant.kind) and plant.payload is None \
            and fields["body"].startswith("payload/"):
        raise t.fail("kind", "an event on a payload body needs plant.payload (it is 'none')", t.data.get("kind"))


def _payload_on_build(scn: Scenario, e: EventSpec, plant: Any, source: ModelSource | None) -> None:
    """The body exists (and a payload is attached when it is a payload body); a payload_swap's file is
    found and checked."""
    if scn.plant.payload is None and e.body.startswith("payload/"):
        raise ScenarioError(f"{scn.source}: events: a {e.kind} event on {e.body!r} needs a payload "
                            "(plant.payload is 'none'); attach one or name a body of your model with "
                            "events[].body")
    plant.body_id(e.body)  # a plant kind accepting a payload event has bodies (ArmPlant, ManipulatorPlant)
    if e.payload is not None:
        payload_inertial(scn, e, source)


#: the check of an event on a payload body when the run is built (the body exists; a payload is attached), for a
#: plant kind's own payload event (the quadrotor's payload_release)
payload_body_check = _payload_on_build


def _payload_mass(e: EventSpec, scn: Scenario, source: ModelSource | None) -> Event:
    return Event(e.t, f"payload_mass {e.body} = {e.value} kg", lambda plant: plant.set_body_mass(e.body, e.value))


def _payload_swap(e: EventSpec, scn: Scenario, source: ModelSource | None) -> Event:
    inertial = payload_inertial(scn, e, source)
    return Event(e.t, f"payload_swap {e.body} = {e.payload} ({inertial['mass']:g} kg)",
                 lambda plant: plant.set_body_inertial(e.body, **inertial))


#: events[i].payload: the payload file a payload_swap attaches (name in models/payloads or a path)
PAYLOAD = EventField("payload", lambda t: t.string("payload"), "the payload file (models/payloads or a path)")

PAYLOAD_MASS = EventKind("payload_mass", _payload_mass, on_load=_payload_on_load, on_build=_payload_on_build,
                         doc="sets the mass of body [kg] from t on",
                         overrides=("plant.payload_mass",), sets=lambda e: f"{e.value:g} kg")
PAYLOAD_SWAP = EventKind("payload_swap", _payload_swap, value="none", fields=(BODY, PAYLOAD),
                         on_load=_payload_on_load, on_build=_payload_on_build,
                         doc="gives body the inertia of another payload file from t on",
                         overrides=("plant.payload_mass",), sets=lambda e: f"payload {e.payload!r}")

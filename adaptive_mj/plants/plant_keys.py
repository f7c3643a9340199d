"""The plant.* keys many plant kinds share, declared as data (adaptive_mj.keys.Key), and the readers every kind's
own reader calls: `SharedReader`, the reader of the kinds built from a MuJoCo model or its analytic twin
(kind, backend, model, joint, actuator, the payload keys, theta, g, density, viscosity, ctrl_range; the kind's
own keys by its hooks), and `read_analytic`, the head of an analytic plant's table (kind, backend = "twin",
ctrl_range). A key another kind of the shared reader declares is refused by name on a kind that does not:
``plant.payload must be absent unless plant.kind = 'arm' or 'manipulator'``.

Each kind's module declares its keys (`keys(...)` below with its own) and its reader; docs/SCENARIOS.md's
[plant] tables document them (tests/test_plant_kinds.py keeps the two equal).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, cast

from adaptive_mj.data import MODELS
from adaptive_mj.errors import ScenarioError
from adaptive_mj.keys import Key, Table
from adaptive_mj.plants import kinds as registry
from adaptive_mj.specs import PlantSpec

BACKENDS = ("mujoco", "twin")

KIND = Key("kind", "string", doc="a built-in plant kind or an installed plant plugin", required=True)
BACKEND = Key("backend", "string", default="mujoco", bounds="one of 'mujoco', 'twin'",
              doc="MuJoCo physics or the analytic twin")
MODEL = Key("model", "string", doc="a name in models/ or a path to an MJCF (relative to the scenario file); "
                                   "default: the kind's bundled model")
JOINT = Key("joint", "string", doc="the joint's name in the model (default: the only one)")
ACTUATOR = Key("actuator", "string", doc="the actuator's name in the model (default: the only one)")
PAYLOAD = Key("payload", "string", doc="a payload file (a name in models/payloads or a path ending in .xml), "
                                       "or 'none'")
PAYLOAD_MASS = Key("payload_mass", "number", "kg", bounds="> 0", doc="total payload mass (default: the file's)")
SITE = Key("site", "string", default="tip", doc="where the payload is attached")
THETA = Key("theta", "table {parameter = number}", doc="twin only: the true parameters, in the kind's order")
G = Key("g", "number", "m/s²", 9.81, "> 0", "gravity (a twin given plant.theta)")
DENSITY = Key("density", "number", "kg/m³", None, ">= 0", "fluid density (default: the model's)")
VISCOSITY = Key("viscosity", "number", "Pa s", None, ">= 0", "fluid viscosity (default: the model's)")
CTRL_RANGE = Key("ctrl_range", "array [lo, hi]", "", None, "lo < hi", "actuator limits (default: the model's)")
ANALYTIC_BACKEND = Key("backend", "string", default="twin", bounds="one of 'twin'", doc="the analytic backend only")

#: the payload keys (arm, manipulator)
PAYLOAD_KEYS = (PAYLOAD, PAYLOAD_MASS, SITE)


def keys(*own: Key, payload: bool = False, default_payload: str | None = None) -> tuple[Key, ...]:
    """The plant.* keys of a kind read by SharedReader: the shared ones (the payload keys when `payload`, the
    payload file's default `default_payload`, None: 'none'), then its own."""
    payload_keys = (dataclasses.replace(PAYLOAD, default=default_payload),) + PAYLOAD_KEYS[1:]
    head = (KIND, BACKEND, MODEL, JOINT, ACTUATOR) + (payload_keys if payload else ())
    return head + (THETA, G, DENSITY, VISCOSITY, CTRL_RANGE) + own


def analytic_keys(*own: Key) -> tuple[Key, ...]:
    """The plant.* keys of an analytic kind (read_analytic): kind, backend, ctrl_range, then its own."""
    return (KIND, ANALYTIC_BACKEND, CTRL_RANGE) + own


def resolve_model(name: str, base_dir: Path) -> Path:
    """A bundled model name ("heave_vehicle") or a path relative to the scenario file."""
    if "/" not in name and not name.endswith(".xml"):
        return MODELS / f"{name}.xml"
    p = Path(name)
    return p if p.is_absolute() else (base_dir / p)


def payload_paths(name: str | None, base_dir: Path) -> tuple[Path, ...]:
    """Where a payload file is looked for (adaptive_mj.plants.payload.candidates); checked in build."""
    from adaptive_mj.plants.payload import candidates

    return () if name is None else candidates(name, base_dir)


def resolve_payload(name: str | None, base_dir: Path) -> tuple[str | None, tuple[Path, ...]]:
    """plant.payload: a bundled name as it is; a path as the first place it is found (next to the
    scenario, then the current directory), else the first place looked; and the places looked."""
    from adaptive_mj.plants.payload import is_bundled

    paths = payload_paths(name, base_dir)
    if name is None or is_bundled(name):
        return name, paths
    return str(next((p for p in paths if p.is_file()), paths[0])), paths


def ctrl_range(t: Table) -> tuple[float, float] | None:
    """plant.ctrl_range: [lo, hi] with lo < hi [the control's unit], or None."""
    ctrl = cast("tuple[float, float] | None", t.numbers("ctrl_range", None, length=2))  # length=2: a pair
    if ctrl is not None and not ctrl[0] < ctrl[1]:
        raise t.fail("ctrl_range", "[lo, hi] with lo < hi", list(ctrl))
    return ctrl


def joint_values(t: Table, name: str) -> float | dict[str, float]:
    """A number for every joint, or a table {joint = number}."""
    if isinstance(t.get(name), dict):
        sub = t.table(name)
        return {key: sub.number(key) for key in sub.data}
    return t.number(name)


def refuse_foreign(t: Table, kind: registry.PlantKind) -> None:
    """Refuses, by name, a key of another kind of the shared reader that `kind` does not declare:
    "plant.<key> must be absent unless plant.kind = 'a' or 'b'" (and the key's condition, Key.when)."""
    own = set(kind.key_names())
    for other in registry.built_in().values():
        if not isinstance(other.reader, SharedReader):
            continue
        for key in other.keys:
            if key.name in t.data and key.name not in own:
                names = " or ".join(repr(k.name) for k in registry.declaring(key.name))
                raise t.fail(key.name, f"absent unless plant.kind = {names}" + (f" {key.when}" if key.when else ""),
                             t.data[key.name])


Hook = Callable[[Table, dict], dict]


@dataclass(frozen=True)
class SharedReader:
    """The reader of a kind built from a MuJoCo model or its analytic twin (PlantKind.reader): the shared
    keys in their order, with the kind's own rules. backend: (the only backend, why), checked once read;
    theta: the names plant.theta must have, in order, from the table (None: no twin given theta);
    theta_positive: its first parameter > 0; theta_example: plant.theta is required, e.g. "{a = 2}";
    body: reads the kind's own keys after the payload keys (and the refusal of other kinds' keys), late:
    after ctrl_range; each gets the fields read so far and gives PlantSpec fields."""

    backend: tuple[str, str] | None = None
    theta: Callable[[Table], tuple[str, ...]] | None = None
    theta_positive: bool = True
    theta_example: str | None = None
    body: Hook | None = None
    late: Hook | None = None

    def __call__(self, kind: registry.PlantKind, t: Table, base_dir: Path) -> PlantSpec:
        fields = self._head(kind, t, base_dir)
        refuse_foreign(t, kind)
        if self.body is not None:
            fields.update(self.body(t, fields))
        fields["theta"] = self._theta(kind, t, fields["backend"])
        fields.update(g=t.number("g", 9.81, gt=0), density=t.number("density", None, ge=0),
                      viscosity=t.number("viscosity", None, ge=0), ctrl_range=ctrl_range(t))
        if self.late is not None:
            fields.update(self.late(t, fields))
        t.finish()
        return PlantSpec(kind=kind.name, **fields)

    def _head(self, kind: registry.PlantKind, t: Table, base_dir: Path) -> dict[str, Any]:
        """kind, backend, model, joint, actuator and the payload keys (read on every kind, refused after)."""
        t.string("kind")
        backend = t.string("backend", "mujoco", choices=BACKENDS)
        if self.backend is not None and backend != self.backend[0]:
            raise t.fail("backend", f"{self.backend[0]!r} for plant.kind = {kind.name!r} ({self.backend[1]})", backend)
        model_name = t.string("model", kind.default_model)
        model = None if model_name is None else resolve_model(model_name, base_dir)
        if "model" in t.data and "model" not in kind.key_names():
            raise t.fail("model", f"absent for plant.kind = {kind.name!r}", model_name)
        joint, actuator = t.string("joint", None), t.string("actuator", None)
        declared = {k.name: k for k in kind.keys}
        payload = t.string("payload", declared["payload"].default if "payload" in declared else None)
        payload, paths = resolve_payload(None if payload == "none" else payload, base_dir)
        return dict(backend=backend, model=model, joint=joint, actuator=actuator, payload=payload,
                    payload_mass=t.number("payload_mass", None, gt=0), site=t.string("site", "tip"),
                    payload_paths=paths)

    def _theta(self, kind: registry.PlantKind, t: Table, backend: str) -> dict[str, float] | None:
        """plant.theta: a twin's true parameters, named as the kind's form names them, in that order."""
        theta = t.named_numbers("theta", None)
        if theta is not None and backend != "twin":
            raise t.fail("theta", "absent for backend 'mujoco' (true parameters come from the compiled model)", theta)
        if self.theta_example is not None and theta is None:
            raise ScenarioError(f"{t.where}: plant.theta is required for plant.kind = {kind.name!r} "
                                f"(e.g. {self.theta_example})")
        if theta is None:
            return None
        if self.theta is None:
            raise t.fail("theta", f"absent for plant.kind = {kind.name!r}", theta)
        expected = self.theta(t)
        if tuple(theta) != expected:
            raise t.fail("theta", f"a table with keys {', '.join(expected)} in that order", list(theta))
        if self.theta_positive and theta[expected[0]] <= 0:
            raise t.fail(f"theta.{expected[0]}", "> 0", theta[expected[0]])
        return theta


def read_analytic(t: Table) -> dict[str, Any]:
    """The head of an analytic plant's table: plant.kind, plant.backend ("twin", the only one) and
    plant.ctrl_range; the PlantSpec fields of a plant without a model."""
    t.string("kind")
    backend = t.string("backend", "twin", choices=("twin",))
    return dict(backend=backend, model=None, joint=None, actuator=None, payload=None, payload_mass=None,
                site="tip", theta=None, g=9.81, density=None, viscosity=None, ctrl_range=ctrl_range(t))

"""The plant kinds: each declares itself in its own module (`KIND = register(PlantKind(...))` beside its
`model_source` and `from_scenario`), and this registry finds them by construction: every module of the
adaptive_mj.plants package is imported once and what registered is the set of built-in kinds; installed
plant plugins (adaptive_mj.plants.plugin) join through the same PlantKind. The scenario loader, the builder,
`list --plants`, the units of every report and the law-form check read it; a new plant kind touches no
table elsewhere.

A kind declares: its name, the module that builds it, the forms a law can see it in
(adaptive_mj.laws.kinds.Form), its bundled model (None: an analytic plant), the SI units of its output, its
control and its parameters (for labels, summaries and the verdict's messages), and a line of doc.
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass, field
from typing import Callable, Mapping

from adaptive_mj.laws.kinds import Form

#: the units of a rigid body's (and a joint's) parameters on a multi-joint plant, by the name's last part
BODY_PARAM_UNITS = {"m": "kg", "mcx": "kg m", "mcy": "kg m", "mcz": "kg m", "Ixx": "kg m²", "Ixy": "kg m²",
                    "Iyy": "kg m²", "Ixz": "kg m²", "Iyz": "kg m²", "Izz": "kg m²", "armature": "kg m²",
                    "damping": "N m s/rad", "coulomb": "N m"}


def body_param_unit(name: str) -> str:
    """Unit of a multi-joint parameter "<body>.<param>" or "<joint>.armature" (a base parameter ends in "*")."""
    return BODY_PARAM_UNITS.get(name.rstrip("*").rsplit(".", 1)[-1], "")


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
    origin: str = "built in"

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


def built_in() -> dict[str, PlantKind]:
    """The built-in plant kinds by name, in the order their modules register (every module of the package is
    imported once: a kind is found by its own module, not by a list)."""
    global _SCANNED
    if not _SCANNED:
        import adaptive_mj.plants as package

        for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
            importlib.import_module(f"{package.__name__}.{info.name}")
        ordered = sorted(_BUILT_IN.items(), key=lambda kv: ORDER.index(kv[0]) if kv[0] in ORDER else len(ORDER))
        _BUILT_IN.clear()
        _BUILT_IN.update(ordered)  # sorted once; every later call copies it (a lookup per report label)
        _SCANNED = True
    return dict(_BUILT_IN)


#: the order the built-in kinds are listed in (a kind missing here comes last): the lecture's order
ORDER = ("heave", "arm", "first_order", "manipulator", "ship", "linear", "wing_rock")


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


def output_unit(name: str | None) -> str:
    """SI unit of the kind's output y ('' when unknown)."""
    kind = lookup(name)
    return kind.output_unit if kind is not None else ""


def control_unit(name: str | None) -> str:
    """SI unit of the kind's control u ('' when unknown)."""
    kind = lookup(name)
    return kind.control_unit if kind is not None else ""


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

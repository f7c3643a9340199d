"""SI units of each plant kind's output, control and parameters (for labels and summaries)."""
from __future__ import annotations

OUTPUT = {"heave": "m", "arm": "rad", "first_order": "-"}
CONTROL = {"heave": "N", "arm": "N m", "first_order": "-"}
PARAMS = {
    "heave": {"d": "kg", "b": "kg/m", "c": "kg", "tau_d": "kg s", "tau_b": "kg s/m"},
    "arm": {"J": "kg m²", "b": "N m s/rad", "g_sin": "N m", "g_cos": "N m"},
    "first_order": {"a": "-", "b": "-", "p": "-"},
}


def param(kind: str | None, name: str) -> str:
    """Unit of parameter `name` of a plant kind ('' when unknown)."""
    return PARAMS.get(kind or "", {}).get(name, "")


def plant_kind_of(scenario_text: str) -> str | None:
    """plant.kind of a scenario's TOML text (e.g. from a log), or None if it cannot be read."""
    import tomllib

    try:
        kind = tomllib.loads(scenario_text).get("plant", {}).get("kind")
    except (tomllib.TOMLDecodeError, AttributeError):
        return None
    return kind if kind in OUTPUT else None

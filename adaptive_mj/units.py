"""SI units of each plant kind's output, control and parameters (for labels and summaries)."""
from __future__ import annotations

# manipulator: rad (hinges) or m; ship: the heading, and the control is the commanded rudder angle
OUTPUT = {"heave": "m", "arm": "rad", "first_order": "-", "manipulator": "rad", "ship": "rad"}
CONTROL = {"heave": "N", "arm": "N m", "first_order": "-", "manipulator": "N m", "ship": "rad"}
OUTPUT.update({"linear": "-", "wing_rock": "rad"})  # the analytic plants (issue 21): y of a transfer function; roll
CONTROL.update({"linear": "-", "wing_rock": "-"})  # u of a transfer function; the aileron input (|u| <= 1.75)
_BODY_PARAM_UNITS = {"m": "kg", "mcx": "kg m", "mcy": "kg m", "mcz": "kg m", "Ixx": "kg m²", "Ixy": "kg m²",
                     "Iyy": "kg m²", "Ixz": "kg m²", "Iyz": "kg m²", "Izz": "kg m²", "armature": "kg m²",
                     "damping": "N m s/rad", "coulomb": "N m"}
PARAMS = {
    "heave": {"d": "kg", "b": "kg/m", "c": "kg", "tau_d": "kg s", "tau_b": "kg s/m"},
    "arm": {"J": "kg m²", "b": "N m s/rad", "g_sin": "N m", "g_cos": "N m"},
    "first_order": {"a": "-", "b": "-", "p": "-"},
    "ship": {"T_over_K": "s²", "one_over_K": "s", "alpha_over_K": "s³", "rudder_bias": "rad"},
}


def param(kind: str | None, name: str) -> str:
    """Unit of parameter `name` of a plant kind ('' when unknown)."""
    if kind == "manipulator":  # "<body>.<param>" or "<joint>.armature"; a base parameter ends in "*"
        return _BODY_PARAM_UNITS.get(name.rstrip("*").rsplit(".", 1)[-1], "")
    return PARAMS.get(kind or "", {}).get(name, "")


def plant_kind_of(scenario_text: str) -> str | None:
    """plant.kind of a scenario's TOML text (e.g. from a log), or None if it cannot be read."""
    import tomllib

    try:
        kind = tomllib.loads(scenario_text).get("plant", {}).get("kind")
    except (tomllib.TOMLDecodeError, AttributeError):
        return None
    return kind if kind in OUTPUT else None

"""The [law] keys every law kind shares, declared (adaptive_mj.keys.Key) and read once: law.kind, law.order,
law.gamma, law.dead_zone, law.initial_estimates, law.nominal, the robust modifications (law.sigma,
law.e_modification, law.theta0, law.projection, law.composite) and law.saturation. A law kind's own module
lists the ones it takes beside its own keys and calls these readers from its key reader
(adaptive_mj.laws.kinds.Reader); a law plugin's keys take them through adaptive_mj.setup.scenario. No mujoco
here; the key reference is docs/SCENARIOS.md.
"""
from __future__ import annotations

import dataclasses

from adaptive_mj.errors import ScenarioError
from adaptive_mj.keys import Key, Table
from adaptive_mj.specs import DeadZoneSpec, PlantSpec, RobustSpec

DEAD_ZONE_ON = ("s", "tracking_error")
SATURATION_MODES = ("ignore", "freeze")

KIND = Key("kind", "string", doc="the law kind (adaptive_mj.laws.kinds); default: the plant kind's")
ORDER = Key("order", "integer", default=None,
            doc="n of s = (d/dt + λ)^(n−1) ỹ: the plant's (2; first_order and linear 1; 3 on a heave vehicle "
                "with plant.thruster_time_constant)")
GAMMA = Key("gamma", "number or table {parameter = number}", bounds="> 0",
            doc="adaptation gain γ (θ̂' ∝ 1/γ), one for all parameters or per parameter in θ order")
GAMMA_REQUIRED = dataclasses.replace(GAMMA, required=True)  # an adaptive kind's
DEAD_ZONE = Key("dead_zone", "table {width or width_in_noise_std, on}",
                doc="adaptation off while |s| (or |ỹ|, on = 'tracking_error') < width")
INITIAL_ESTIMATES = Key("initial_estimates", "table {parameter = number} or 'model'",
                        doc="θ̂(0); 'model': the true θ of the compiled model at t = 0 (default: nominal, else 0)")
NOMINAL = Key("nominal", "table {parameter = number} or 'model'",
              doc="a baseline's fixed θ̂ (default: initial_estimates)")
ROBUST = (
    Key("sigma", "number", default=0.0, bounds=">= 0", doc="σ-modification: θ̂' = … − σ Γ⁻¹ (θ̂ − θ₀)"),
    Key("e_modification", "number", default=0.0, bounds=">= 0", doc="e-modification: θ̂' = … − ν |s| Γ⁻¹ (θ̂ − θ₀)"),
    Key("theta0", "table {parameter = number}", doc="the prior θ₀ both leakages pull toward (default: θ̂(0))"),
    Key("projection", "table {parameter = [lower, upper]}", doc="box projection of θ̂ (inf allowed); on an arm "
        "also 'consistent' (each body's pseudo-inertia kept PSD) or 'nonnegative' (a box; 'physical' its older name)"),
    Key("composite", "table {gain, filter}",
        doc="composite adaptation: gain κ > 0 and filter λ_f > 0 [1/s] (sliding_adaptive only)"),
)
SATURATION = Key("saturation", "string", default="ignore", bounds="one of 'ignore', 'freeze'",
                     doc="'freeze': no adaptation while the law's u is outside the actuator's range")


def read_order(t: Table, plant: PlantSpec, order: int) -> int:
    """law.order: the plant's order n (a heave vehicle with a thruster lag: 2 or 3); the message words the
    values allowed as the plant kind declares them (PlantSpec.orders_text, else n)."""
    law_order = t.integer("order", order, ge=1)
    if law_order != order:
        allowed = plant.orders_text if plant.orders_text is not None else str(order)
        raise t.fail("order", f"{allowed} for plant.kind = {plant.kind!r}", law_order)
    return law_order


def read_gamma(t: Table) -> float | dict[str, float] | None:
    """law.gamma: a number > 0, a table {parameter = number > 0}, or None when absent."""
    v = t.get("gamma", None)
    if v is None:
        return None
    if isinstance(v, dict):
        return t.named_numbers("gamma", gt=0)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise t.fail("gamma", "a number > 0, or a table {parameter = number > 0}", v)
    return t.number("gamma", gt=0)


def required(t: Table, value: object, keys: str, kind: str) -> None:
    """A one-line ScenarioError "law.<keys> is required for law.kind = <kind>" when value is None."""
    if value is None:
        raise ScenarioError(f"{t.where}: {keys} is required for law.kind = {kind!r}")


def read_dead_zone(t: Table) -> DeadZoneSpec | None:
    """law.dead_zone = {width, on} or {width_in_noise_std, on}, or None."""
    dz = t.table("dead_zone", None)
    if dz is None:
        return None
    if "width_in_noise_std" in dz.data:
        if "width" in dz.data:
            raise dz.fail("width", "absent when law.dead_zone.width_in_noise_std is given", dz.data["width"])
        spec = DeadZoneSpec(width=None, on=dz.string("on", "s", choices=DEAD_ZONE_ON),
                            width_in_noise_std=dz.number("width_in_noise_std", gt=0))
    else:
        spec = DeadZoneSpec(width=dz.number("width", ge=0), on=dz.string("on", "s", choices=DEAD_ZONE_ON))
    dz.finish()
    return spec


def read_estimates(t: Table, name: str) -> dict[str, float] | str | None:
    """A table {name = value}, or the string "model": the true values of the compiled model at t = 0."""
    if isinstance(t.data.get(name), str):
        return t.string(name, choices=("model",))
    return t.named_numbers(name, None)


#: the words law.projection may be on a plant of rigid bodies (the arms) instead of a table:
#:   "consistent"   each adapted body's ten parameters kept physically consistent (its pseudo-inertia PSD, projected
#:                  in the metric of Γ: adaptive_mj.laws.pseudo_inertia), armature, damping and friction >= 0;
#:   "nonnegative"  a box: masses, the principal moments about the body origin, armature, damping and friction
#:                  >= 0 (cheaper; necessary, not sufficient: an estimate in it may be no possible body);
#:   "physical"     the older name of "nonnegative" (scenarios and logs written before "consistent" existed).
RIGID_BODY_PROJECTIONS = ("consistent", "nonnegative", "physical")


def read_robust(t: Table, kind: str, *, adaptive: bool, composite: bool, presets: tuple[str, ...]) -> RobustSpec:
    """law.sigma, law.e_modification, law.theta0, law.projection, law.composite: checked for every
    law; the baselines ignore them (as they ignore gamma and dead_zone), so law.kind = a baseline
    turns any adaptive scenario into its baseline. presets: the words law.projection may be instead
    of a table (RIGID_BODY_PROJECTIONS on a multi-joint plant)."""
    sigma = t.number("sigma", 0.0, ge=0)
    e_mod = t.number("e_modification", 0.0, ge=0)
    theta0 = t.named_numbers("theta0", None)
    projection = _projection(t, presets)
    gain = filt = None
    if "composite" in t.data and adaptive and not composite:
        raise t.fail("composite", f"absent for law.kind = {kind!r} (composite adaptation is implemented for "
                                  "law.kind = 'sliding_adaptive')", t.data["composite"])
    c = t.table("composite", None)
    if c is not None:
        gain, filt = c.number("gain", gt=0), c.number("filter", gt=0)
        c.finish()
    if not adaptive:
        return RobustSpec()
    return RobustSpec(sigma=sigma, e_modification=e_mod, theta0=theta0, projection=projection,
                      composite_gain=gain, composite_filter=filt)


def _projection(t: Table, presets: tuple[str, ...]) -> dict[str, tuple[float, float]] | str | None:
    """law.projection: {parameter = [lower, upper]} (inf allowed), one of `presets`, or None."""
    if isinstance(t.data.get("projection"), str):
        if not presets:
            raise t.fail("projection", "a table {parameter = [lower, upper]}", t.data["projection"])
        return t.string("projection", choices=presets)
    box = t.table("projection", None)
    if box is None:
        return None
    projection = {}
    for name in box.data:
        lo, hi = box.numbers_with_inf(name, length=2)
        if not lo <= hi:
            raise box.fail(name, "[lower, upper] with lower <= upper", [lo, hi])
        projection[name] = (lo, hi)
    box.finish(tuple(box.data))
    return projection


def read_saturation(t: Table) -> str:
    """law.saturation: "ignore" or "freeze" (the kind says whether it takes "freeze")."""
    return t.string("saturation", "ignore", choices=SATURATION_MODES)

"""plant.kind = "process": a heated stirred tank, the lecture's fourth motivating example (process control:
parameters that "vary from batch to batch", working conditions that are "usually time-varying").

The energy balance of the stirred-tank heating process (Seborg, Edgar, Mellichamp & Doyle, *Process Dynamics
and Control*, 4th ed., Wiley 2016, section 2.4.1, "Stirred-tank heating process: constant holdup"), with one more
heat flow, the loss through the tank's wall to its surroundings:

    ρ V C dT/dt = w C (T_i − T) + U A (T_a − T) + Q

T the tank's (well-mixed) temperature [°C], the output y; Q the heater's power [W], the control u, in
[0, Q_max] (a heater cannot cool); ρ the liquid's density [kg/m³], V the holdup [m³], C its specific heat
[J/(kg K)], w the mass flow through the tank [kg/s] (fed at T_i [°C]), U A the wall's conductance [W/K] to
surroundings at T_a [°C]. Gathered, it is the lecture's first-order form with an unknown leading coefficient,

    d ẏ = −a y + b + u,      φ(y) = [−y, 1],  p = [a, b],  f = 0,  h = 1,

    d = ρ V C       [J/K]   the heat capacity of the holdup
    a = w C + U A   [W/K]   the conductance to the feed and the surroundings
    b = w C T_i + U A T_a   [W]   the heat those bring at T = 0 °C

θ = [d, a, b] (the ModelForm's order: d, then p), derived from the physical parameters by `Tank.theta` (nothing
typed twice). All three change with a batch: its holdup V, its feed temperature T_i and flow w, and the wall's
conductance U A (the wetted area, fouling); the [[events]] kind "batch" sets them from t on.

Analytic (MuJoCo has no chemistry): the tank is a TwinPlant (plants.twin) of this form, RK4 at the scenario's
timestep, so the lecture's sliding laws (at n = 1: s = ỹ, u = d̂ ẏ_d − φ p̂ + k ỹ, p̂' = −φ s/γ, d̂' = ẏ_d s/γ: the
first-order law with the unknown d adapted too) run on it compiled, through the analytic chunk engine
(adaptive_mj.sim.native_chunk, with the twin's kernel), and `fixed_nominal` (the same law, θ̂ frozen) is the
fixed-gain baseline. Under MRAC (law.kind = "mrac", order 1) the true parameters are MRAC's ideal gains, the
heat b a matched constant term (MracTank), compiled through the same engine (ψ = 1 compiled in).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.form import ModelForm
from adaptive_mj.keys import Key, Table
from adaptive_mj.laws.kinds import Form, MracState
from adaptive_mj.plants import BuiltPlant
from adaptive_mj.plants import events as ev
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants.kinds import PlantKind, first_order, register
from adaptive_mj.plants.protocol import Plant
from adaptive_mj.plants.twin import TwinPlant, scenario_integrator
from adaptive_mj.specs import PlantSpec, Scenario

#: the default tank: a few hundred litres of water, a moderate throughput, an insulated wall
WATER_DENSITY = 1000.0  # ρ [kg/m³]
WATER_HEAT_CAPACITY = 4184.0  # C [J/(kg K)]
HEATER_POWER = 60e3  # Q_max [W]: the heater's rating (ctrl_range [0, Q_max])


@dataclass(frozen=True)
class Tank:
    """The physical parameters of the heated tank (SI; temperatures in °C).

    volume: V, the holdup [m³]; flow: w, the mass flow through it [kg/s]; feed_temperature: T_i [°C];
    ua: U A, the wall's conductance to the surroundings [W/K]; ambient_temperature: T_a [°C]; density: ρ
    [kg/m³]; heat_capacity: C [J/(kg K)]."""

    volume: float = 0.3
    flow: float = 0.1
    feed_temperature: float = 15.0
    ua: float = 25.0
    ambient_temperature: float = 20.0
    density: float = WATER_DENSITY
    heat_capacity: float = WATER_HEAT_CAPACITY

    @property
    def d(self) -> float:
        """ρ V C [J/K]: the holdup's heat capacity."""
        return self.density * self.volume * self.heat_capacity

    @property
    def a(self) -> float:
        """w C + U A [W/K]."""
        return self.flow * self.heat_capacity + self.ua

    @property
    def b(self) -> float:
        """w C T_i + U A T_a [W]."""
        return self.flow * self.heat_capacity * self.feed_temperature + self.ua * self.ambient_temperature

    def theta(self) -> np.ndarray:
        """θ = [d, a, b] (3,) of `form()` [J/K, W/K, W]."""
        return np.array([self.d, self.a, self.b])

    def steady_temperature(self, power: float) -> float:
        """T_ss [°C] = (b + Q)/a under a constant heater power Q [W]."""
        return (self.b + power) / self.a

    def time_constant(self) -> float:
        """d/a [s]: the open-loop time constant."""
        return self.d / self.a


def regressor(x: np.ndarray) -> np.ndarray:
    """φ(x) (2,) = [−T, 1] at x = [T] [°C]."""
    return np.array([-x[0], 1.0])


def form() -> ModelForm:
    """d ẏ = φ(y)·[a, b] + u (f = 0, h = 1): the energy balance in the lecture's form."""
    return ModelForm(order=1, p_names=("a", "b"), phi=regressor, d_name="d")


class TankPlant(TwinPlant):
    """The heated tank: a TwinPlant of `form()` whose true θ follows from its Tank; a batch (new_batch) gives it
    new physical parameters from then on. dt: step [s]; ctrl_range: the heater's [0, Q_max] [W]."""

    def __init__(self, tank: Tank, *, dt: float, integrator, ctrl_range: tuple[float, float] | None):
        super().__init__(form(), tank.theta(), dt=dt, integrator=integrator, ctrl_range=ctrl_range)
        self.tank = tank

    def new_batch(self, **changes: float) -> None:
        """From now on the tank's physical parameters are its Tank with `changes` (names of Tank's fields); the
        temperature carries over."""
        self.tank = replace(self.tank, **changes)
        self.set_true_theta(self.tank.theta())


class MracTank(TankPlant):
    """The tank as direct MRAC (law.kind = "mrac", order 1) sees it: ẏ = −(a/d) y + (1/d)(u + b), the heat b a
    matched constant term ψ = 1; its true parameters are MRAC's ideal gains [k_y, k_r, k_heat] for the law's
    reference model (alpha, beta), recomputed after a batch. Compiled through the analytic chunk engine like the
    tank under the sliding laws (MRAC with its matched term: laws.mrac.mrac_psi_kernel)."""

    def __init__(self, tank: Tank, *, alpha, beta: float, dt: float, integrator,
                 ctrl_range: tuple[float, float] | None):
        super().__init__(tank, dt=dt, integrator=integrator, ctrl_range=ctrl_range)
        self.alpha, self.beta = np.asarray(alpha, dtype=float), float(beta)

    @property
    def names(self) -> tuple[str, ...]:
        from adaptive_mj.laws.mrac import gain_names

        return gain_names(1, MATCHED)

    def true_theta(self) -> np.ndarray:
        from adaptive_mj.laws.mrac import ideal_gains

        t = self.tank
        return ideal_gains([-t.a / t.d], 1.0 / t.d, [t.b / t.d], self.alpha, self.beta)


MATCHED = ("heat",)  # MRAC's matched term: the constant heat b (ψ = 1)


def matched_terms(x: np.ndarray) -> np.ndarray:
    """ψ(x) (1,) = [1]: MRAC's matched term (the heat b enters like the heater's power)."""
    return np.ones(1)


# --- built from a scenario ------------------------------------------------------
@dataclass(frozen=True)
class ProcessSpec:
    """plant.* keys of kind "process" (PlantSpec.kind_spec): the tank's physical parameters at t = 0."""

    tank: Tank


def model_source(scn) -> None:
    """plant.kind = "process" has no model."""
    return None


def from_scenario(scn, source) -> BuiltPlant:
    """plant.kind = "process": the tank of plant.volume, .flow, .feed_temperature, .ua, .ambient_temperature,
    .liquid_density and .heat_capacity; the heater plant.ctrl_range (default [0, 60 kW]); RK4 (or Euler) at
    simulation.timestep (this kind's default, KIND.default_timestep = 2 s: the tank's time constant
    ρVC/(wC + UA) is tens of minutes)."""
    p, sim, L = scn.plant, scn.simulation, scn.law
    spec = p.kind_spec if isinstance(p.kind_spec, ProcessSpec) else ProcessSpec(Tank())
    dt = sim.timestep if sim.timestep is not None else KIND.default_timestep  # the loader sets it from the kind
    ctrl = p.ctrl_range if p.ctrl_range is not None else (0.0, HEATER_POWER)
    integrator = scenario_integrator(scn)
    if L.mrac is not None:  # a law of the MRAC state form (law.kind = "mrac": its reference model)
        return BuiltPlant(MracTank(spec.tank, alpha=L.mrac.alpha, beta=L.mrac.beta, dt=dt, integrator=integrator,
                                   ctrl_range=ctrl))
    return BuiltPlant(TankPlant(spec.tank, dt=dt, integrator=integrator, ctrl_range=ctrl))


def mrac_state(scn: Scenario, plant: Plant) -> MracState:
    """The tank as MRAC sees it (Form.MRAC_STATE): b = 1/(ρ V C) at t = 0 (its sign, positive, is what the law
    knows), the constant heat as the matched term."""
    assert scn.law.order is not None  # set for a law of this form (its reader)
    spec = scn.plant.kind_spec if isinstance(scn.plant.kind_spec, ProcessSpec) else ProcessSpec(Tank())
    return MracState(scn.law.order, 1.0 / spec.tank.d, matched_terms, MATCHED, tuple(plant.names))


# --- its scenario keys -----------------------------------------------------------
_DEFAULT = Tank()
#: the tank's keys: (key, the Tank field it sets, its bound: "> 0", ">= 0" or "" (any number))
_TANK_KEYS = (
    (Key("volume", "number", "m³", _DEFAULT.volume, "> 0", "V, the holdup"), "volume", "> 0"),
    (Key("flow", "number", "kg/s", _DEFAULT.flow, ">= 0", "w, the mass flow through the tank"), "flow", ">= 0"),
    (Key("feed_temperature", "number", "°C", _DEFAULT.feed_temperature, "", "T_i, the feed's temperature"),
     "feed_temperature", ""),
    (Key("ua", "number", "W/K", _DEFAULT.ua, ">= 0", "U A, the wall's conductance to the surroundings"), "ua",
     ">= 0"),
    (Key("ambient_temperature", "number", "°C", _DEFAULT.ambient_temperature, "", "T_a, the surroundings'"),
     "ambient_temperature", ""),
    (Key("liquid_density", "number", "kg/m³", _DEFAULT.density, "> 0", "ρ, the liquid's density (water)"),
     "density", "> 0"),
    (Key("heat_capacity", "number", "J/(kg K)", _DEFAULT.heat_capacity, "> 0",
         "C, the liquid's specific heat (water)"), "heat_capacity", "> 0"),
)
KEYS = plant_keys.analytic_keys(*(k for k, _, _ in _TANK_KEYS))


def _number(t: Table, name: str, default: float | None, bound: str) -> float | None:
    """A tank key by its bound (see _TANK_KEYS)."""
    return t.number(name, default, gt=0 if bound == "> 0" else None, ge=0 if bound == ">= 0" else None)


def _check_flows(t: Table, tank: Tank) -> None:
    """w C + U A > 0: some heat must leave the tank (else it has no steady state under any heater power)."""
    if tank.a <= 0:
        raise t.fail("ua", "> 0 when plant.flow is 0 (heat must leave the tank)", tank.ua)


def read_keys(kind: PlantKind, t: Table, base_dir) -> PlantSpec:
    """plant.* of kind "process" (analytic, twin backend): the tank's physical parameters."""
    head = plant_keys.read_analytic(t)
    values = {field: _number(t, key.name, key.default, bound) for key, field, bound in _TANK_KEYS}
    tank = Tank(**{field: float(v) for field, v in values.items() if v is not None})  # every key has a default
    _check_flows(t, tank)
    t.finish()
    return PlantSpec(kind=kind.name, **head, kind_spec=ProcessSpec(tank))


# --- its events -----------------------------------------------------------------------
#: the fields a batch may set (those of the tank's keys that describe a batch; the liquid stays the same)
BATCH_FIELDS = ("volume", "flow", "feed_temperature", "ua")


def _batch_field(key: Key, bound: str) -> ev.EventField:
    return ev.EventField(key.name, lambda t: _number(t, key.name, None, bound),
                         f"{key.doc} [{key.unit}] from t on (default: unchanged)")


def _batch_on_load(t: Table, plant: PlantSpec, fields_read: dict) -> None:
    """A batch changes something, and leaves heat a way out (w C + U A > 0 with the fields it keeps)."""
    if all(fields_read[name] is None for name in BATCH_FIELDS):
        raise ScenarioError(f"{t.where}: {t.key('kind')} = 'batch' needs at least one of "
                            + ", ".join(t.key(name) for name in BATCH_FIELDS))
    if fields_read["flow"] == 0 and fields_read["ua"] == 0:
        raise t.fail("ua", "> 0 when flow is 0 (heat must leave the tank)", 0.0)


def _batch(e, scn, source) -> ev.Event:
    changes = {name: float(e.params[name]) for name in BATCH_FIELDS if e.params.get(name) is not None}
    label = "batch: " + ", ".join(f"{name} = {value:g}" for name, value in changes.items())
    return ev.Event(e.t, label, lambda plant: plant.new_batch(**changes))


_BY_FIELD = {field: (key, bound) for key, field, bound in _TANK_KEYS}
#: [[events]] kind "batch": a new batch's holdup, feed temperature, flow and wall conductance from t on
BATCH = ev.EventKind(
    "batch", _batch, value="none", fields=tuple(_batch_field(*_BY_FIELD[name]) for name in BATCH_FIELDS),
    on_load=_batch_on_load,
    doc="a new batch: the tank's volume, flow, feed_temperature and ua from t on (each optional)")

#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "process"
KIND = register(PlantKind(
    "process", __name__, frozenset({Form.MODEL, Form.MRAC_STATE}), output_unit="°C", control_unit="W",
    params={"d": "J/K", "a": "W/K", "b": "W"},
    default_model=None, doc="a heated stirred tank (Seborg et al.'s energy balance) whose batches change",
    keys=KEYS, reader=read_keys, events={ev.CONSTANT_FORCE: None, BATCH: None}, order=first_order,
    mrac_state=mrac_state, sections=(), default_timestep=2.0))

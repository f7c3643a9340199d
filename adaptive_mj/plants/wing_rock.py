"""plant.kind = "wing_rock": the roll dynamics of a slender delta wing in wing rock, an analytic
nonlinear plant stepped like the twin (plants.twin.TwinPlant: RK4 at the scenario's timestep, the
policy at each stage).

    x1' = x2,   x2' = Wᵀ[x1, x2, |x1| x2, |x2| x2, x1³] + L_δ u,    |u| <= 1.75

x1 the roll angle [rad], x2 the roll rate [rad/s], u the aileron input. W: Elzebda, Nayfeh and
Mook's coefficients at 25° angle of attack (J. Aircraft 26(8), 1989), the set MRAC papers use
(Cho et al., IEEE TAC 2018, quote them ×1000). L_δ = 1 as in those papers.

For the lecture's laws it is the ModelForm d x1'' = φ(x)ᵀp + u with d = 1/L_δ and p = W/L_δ
(θ = [d, p], names d, w_x1, w_x2, w_ax1x2, w_ax2x2, w_x1cube). For MRAC (law.kind = "mrac",
order 2) the true parameters are its ideal gains for the law's reference model, with the linear
terms of W in k_x and the three nonlinear ones as matched terms ψ.
"""
from __future__ import annotations

import numpy as np

from adaptive_mj.form import ModelForm
from adaptive_mj.plants import BuiltPlant
from adaptive_mj.plants.twin import TwinPlant, scenario_integrator
from adaptive_mj.laws.kinds import Form, MracState
from adaptive_mj.plants.kinds import PlantKind, register
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Key, Table
from adaptive_mj.specs import PlantSpec, Scenario, WingRockSpec
from adaptive_mj.plants.protocol import Plant

#: Elzebda, Nayfeh and Mook (1989), 25° angle of attack: [x1, x2, |x1| x2, |x2| x2, x1³]
W_ELZEBDA_25 = 1e-3 * np.array([-18.59521, 15.162375, -62.45153, 9.54708, 21.45291])
L_DELTA = 1.0  # control effectiveness [1/s² per unit input], as in the MRAC papers
INPUT_LIMIT = 1.75  # |u| <= 1.75
TERMS = ("x1", "x2", "ax1x2", "ax2x2", "x1cube")  # the regressor's terms, in W's order
NONLINEAR = TERMS[2:]  # MRAC's matched terms ψ (the linear ones are in k_x)


def regressor(x: np.ndarray) -> np.ndarray:
    """φ(x) (5,) = [x1, x2, |x1| x2, |x2| x2, x1³]."""
    x1, x2 = float(x[0]), float(x[1])
    return np.array([x1, x2, abs(x1) * x2, abs(x2) * x2, x1 * x1 * x1])


def nonlinear_terms(x: np.ndarray) -> np.ndarray:
    """ψ(x) (3,) = [|x1| x2, |x2| x2, x1³]: MRAC's matched terms."""
    x1, x2 = float(x[0]), float(x[1])
    return np.array([abs(x1) * x2, abs(x2) * x2, x1 * x1 * x1])


def form() -> ModelForm:
    """d x1'' = φ(x)ᵀp + u, d = 1/L_δ, p = W/L_δ."""
    return ModelForm(order=2, p_names=tuple(f"w_{t}" for t in TERMS), phi=regressor, d_name="d")


def form_theta(W, l_delta: float) -> np.ndarray:
    """θ = [1/L_δ, W/L_δ] (6,) of `form()`."""
    return np.concatenate([[1.0 / l_delta], np.asarray(W, dtype=float) / l_delta])


class MracWingRock(TwinPlant):
    """The wing-rock twin whose true parameters are MRAC's ideal gains (law coordinates): the
    reference model's alpha (2,) and beta; a flight-condition event (set_true_theta with form θ)
    moves them."""

    def __init__(self, theta, *, alpha, beta: float, dt: float, integrator, ctrl_range):
        super().__init__(form(), theta, dt=dt, integrator=integrator, ctrl_range=ctrl_range)
        self.alpha, self.beta = np.asarray(alpha, dtype=float), float(beta)

    @property
    def names(self) -> tuple[str, ...]:
        from adaptive_mj.laws.mrac import gain_names

        return gain_names(2, NONLINEAR)

    def true_theta(self) -> np.ndarray:
        from adaptive_mj.laws.mrac import ideal_gains

        d, p = self.form.split(self._theta)  # p = W/L_δ, d = 1/L_δ
        b = 1.0 / float(d)
        W = np.asarray(p) * b
        return ideal_gains(W[:2], b, W[2:], self.alpha, self.beta)


def model_source(scn) -> None:
    """plant.kind = "wing_rock" has no model."""
    return None


def from_scenario(scn, source) -> BuiltPlant:
    """plant.kind = "wing_rock": W (plant.W, default Elzebda's 25° set), L_δ (plant.l_delta), the
    input limit (plant.ctrl_range, default ±1.75); RK4 at simulation.timestep (default 1 ms)."""
    p, sim, L = scn.plant, scn.simulation, scn.law
    wr = p.wing_rock
    dt = sim.timestep if sim.timestep is not None else 0.001
    ctrl = p.ctrl_range if p.ctrl_range is not None else (-INPUT_LIMIT, INPUT_LIMIT)
    theta = form_theta(wr.W, wr.l_delta)
    integrator = scenario_integrator(scn)
    if L.mrac is not None:  # a law of the MRAC state form (law.kind = "mrac": its reference model)
        return BuiltPlant(MracWingRock(theta, alpha=L.mrac.alpha, beta=L.mrac.beta, dt=dt, integrator=integrator,
                                       ctrl_range=ctrl))
    return BuiltPlant(TwinPlant(form(), theta, dt=dt, integrator=integrator, ctrl_range=ctrl))


# --- its scenario keys -----------------------------------------------------------
WING_ROCK_W = (-18.59521e-3, 15.162375e-3, -62.45153e-3, 9.54708e-3, 21.45291e-3)  # Elzebda et al., 25°
KEYS = plant_keys.analytic_keys(
    Key("W", "array of 5 numbers", default=WING_ROCK_W,
        doc="roll-moment coefficients of [x1, x2, |x1| x2, |x2| x2, x1³] (default Elzebda's 25° set)"),
    Key("l_delta", "number", default=1.0, bounds="non-zero", doc="L_δ, the control effectiveness"))


def read_keys(kind: PlantKind, t: Table, base_dir) -> PlantSpec:
    """plant.* of kind "wing_rock" (analytic, twin backend): W (5,) and l_delta."""
    head = plant_keys.read_analytic(t)
    wing_rock = WingRockSpec(W=t.numbers("W", WING_ROCK_W, length=5), l_delta=t.number("l_delta", 1.0))
    if wing_rock.l_delta == 0:
        raise t.fail("l_delta", "non-zero", 0.0)
    t.finish()
    return PlantSpec(kind=kind.name, **head, wing_rock=wing_rock)


def mrac_state(scn: Scenario, plant: Plant) -> MracState:
    """The wing rock as MRAC sees it (Form.MRAC_STATE): b = L_δ, the nonlinear terms of its regressor as
    matched terms."""
    assert scn.law.order is not None and scn.plant.wing_rock is not None  # set by the readers
    return MracState(scn.law.order, scn.plant.wing_rock.l_delta, nonlinear_terms, NONLINEAR, tuple(plant.names))


def _read_l_delta(t: Table) -> float | None:
    l_delta = t.number("l_delta", None)
    if l_delta == 0:
        raise t.fail("l_delta", "non-zero", l_delta)
    return l_delta


def _flight_condition(e, scn, source) -> ev.Event:
    # flight_condition events are on plant.kind = 'wing_rock' (its reader sets plant.wing_rock), with W
    assert scn.plant.wing_rock is not None and e.W is not None
    l_delta = e.l_delta if e.l_delta is not None else scn.plant.wing_rock.l_delta
    theta = form_theta(e.W, l_delta)
    return ev.Event(e.t, f"flight condition W = {list(e.W)}, L_delta = {l_delta:g}",
                    lambda plant: plant.set_true_theta(theta))


#: [[events]] kind "flight_condition": the wing-rock coefficients W (5,) and optionally L_δ from t on
FLIGHT_CONDITION = ev.EventKind(
    "flight_condition", _flight_condition, value="none",
    fields=(ev.EventField("W", lambda t: t.numbers("W", length=5), "the wing-rock coefficients (5,) from t on"),
            ev.EventField("l_delta", _read_l_delta, "L_delta from t on (default: plant.l_delta)"), ev.BODY),
    doc="changes the flight condition (W, L_delta) from t on")

#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "wing_rock"
KIND = register(PlantKind(
    "wing_rock", __name__, frozenset({Form.MODEL, Form.MRAC_STATE}), output_unit="rad", control_unit="-",
    params={},
    default_model=None, doc="wing rock of a slender delta wing", keys=KEYS, reader=read_keys,
    events={ev.CONSTANT_FORCE: None, FLIGHT_CONDITION: "twin"}, mrac_state=mrac_state, sections=("wing rock",)))

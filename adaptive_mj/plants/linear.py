"""plant.kind = "linear": an analytic linear plant, a transfer function (or A, B, C) with an
optional input delay, stepped without MuJoCo (the analytic twin's sibling, plants.twin).

    x' = A x + B u(t - τ),   y = C x

Written in a scenario as the modelled part num/den (a first-order factor b/(s - a): what MRAC
assumes) times an optional unmodelled factor (plant.unmodelled_num/den, DC gain 1 in Rohrs'
example), realised in controllable canonical form; or as the whole plant's matrices plant.A, B, C
(num/den then only name the modelled part the law is designed for). The law sees y only (order 1:
x_law = [y]).

Integration: classic RK4 at the scenario's timestep h. The policy is evaluated at the four
stages t, t+h/2, t+h/2, t+h (so a law's estimates integrate exactly as on the twin). Without a
delay each stage's control drives that stage; with plant.input_delay = τ = D h (D whole steps)
the plant is driven over step k by the control computed at stage 0 of step k - D, held over the
step (zero before t = τ): an exact delay line of D steps on a zero-order-held input.

Compiled: under MRAC with the Lyapunov rule (laws.mrac) the run is stepped by adaptive_mj.sim.native_analytic,
one numba function per chunk of steps that runs this integration, its delay line and the law's stages
(stage.control_stage) with the same arithmetic in the same order, bit for bit (tests/test_native_analytic.py):
loop._run_native calls step_native(n). The MIT rule (its sensitivity filter), simulation.python_callback = true,
and any law the compiled loop does not know take the Python path: `step`, the policy called at each stage.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.form import plain_dot
from adaptive_mj.plants import BuiltPlant
from adaptive_mj.plants.protocol import Plant, Policy
from adaptive_mj.plants.twin import PythonStepped
from adaptive_mj.laws.kinds import Form, MracState
from adaptive_mj.plants.kinds import PlantKind, first_order, register
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Key, Table
from adaptive_mj.specs import LinearSpec, PlantSpec, Scenario


def canonical(num, den) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A (n, n), B (n,), C (n,)) of the strictly proper num/den (highest power first), in
    controllable canonical form."""
    num = np.trim_zeros(np.asarray(num, dtype=float), "f")
    den = np.trim_zeros(np.asarray(den, dtype=float), "f")
    n = den.shape[0] - 1
    if n < 1 or num.shape[0] > n:
        raise ValueError(f"the transfer function must be strictly proper (deg num < deg den), "
                         f"got num {num.tolist()} and den {den.tolist()}")
    A = np.zeros((n, n))
    A[:-1, 1:] = np.eye(n - 1)
    A[-1, :] = -den[1:][::-1] / den[0]
    B = np.zeros(n)
    B[-1] = 1.0 / den[0]
    C = np.zeros(n)
    C[:num.shape[0]] = num[::-1]
    return A, B, C


def first_order_part(num, den) -> tuple[float, float]:
    """(a, b) of the modelled part b/(s - a): num one coefficient, den two."""
    num, den = np.trim_zeros(np.asarray(num, dtype=float), "f"), np.trim_zeros(np.asarray(den, dtype=float), "f")
    if num.shape != (1,) or den.shape != (2,):
        raise ValueError(f"the modelled part must be first order, b/(s - a), got num {num.tolist()} "
                         f"and den {den.tolist()}")
    return float(-den[1] / den[0]), float(num[0] / den[0])


class LinearPlant(PythonStepped):
    """x' = A x + B u(t - D dt), y = C x (see the module docstring). A FormPlant-like 1-DOF plant
    whose law-facing state is [y] (order 1) and whose "true parameters" are given by the caller in
    the law's coordinates (names, theta: MRAC's ideal gains for the modelled part).

    A (n, n), B (n,), C (n,); dt: step [s]; delay_steps: D >= 0; ctrl_range: (lo, hi) or None."""

    joint_shape: tuple[int, ...] = ()
    joint_names: tuple[str, ...] = ()
    first_contact: tuple[float, str] | None = None
    compiled_loop = "adaptive_mj.sim.native_analytic"
    joint_limits: np.ndarray | None = None  # a 1-DOF plant's joint is not limited
    order = 1
    stages = 4

    def __init__(self, A, B, C, *, dt: float, names: tuple[str, ...], theta, delay_steps: int = 0,
                 ctrl_range: tuple[float, float] | None = None):
        self.A, self.B, self.C = (np.array(v, dtype=float) for v in (A, B, C))
        self.dt = float(dt)
        self.names = tuple(names)
        self._theta = np.array(theta, dtype=float)
        if delay_steps < 0:
            raise ValueError(f"delay_steps must be >= 0, got {delay_steps}")
        self.delay_steps = int(delay_steps)
        self.ctrl_range = ctrl_range
        self.force_offset = 0.0  # a constant input disturbance, added to u
        self.disturbance: Callable[[float], float] | None = None
        self.x = np.zeros(self.A.shape[0])
        self._t = 0.0
        self._policy: Policy | None = None
        self._ring = np.zeros(self.delay_steps + 1)  # the stage-0 controls of the last D + 1 steps
        self._k = 0
        self._force = 0.0  # the input disturbance held over the current step

    @property
    def form(self):
        raise AttributeError("a linear plant has no ModelForm: law.kind = 'mrac' is its law")

    @property
    def time(self) -> float:
        return self._t

    def set_state(self, x0) -> None:
        """x0: [y0]; the internal state is the least-norm x with C x = y0."""
        y0 = float(np.asarray(x0, dtype=float).reshape(-1)[0])
        self.x = y0 * self.C / float(self.C @ self.C)
        self._t, self._k = 0.0, 0
        self._ring[:] = 0.0

    def observe(self) -> np.ndarray:
        return np.array([plain_dot(self.C, self.x)])  # the compiled loop's sum (native_analytic.output)

    def true_theta(self) -> np.ndarray:
        return self._theta

    def _control(self, t: float, x: np.ndarray) -> float:
        if self._policy is None:
            raise RuntimeError("LinearPlant.step outside controlled_by(policy)")
        u = float(self._policy(t, np.array([plain_dot(self.C, x)])))
        if self.ctrl_range is not None:
            u = min(max(u, self.ctrl_range[0]), self.ctrl_range[1])
        return u

    def _rate(self, x: np.ndarray, u: float) -> np.ndarray:
        return self.A @ x + self.B * (u + self._force)

    def step(self) -> None:
        h, t, x = self.dt, self._t, self.x
        self._force = self.force_offset + (self.disturbance(t) if self.disturbance is not None else 0.0)
        u0 = self._control(t, x)
        if self.delay_steps == 0:
            k1 = self._rate(x, u0)
            k2 = self._rate(x + h / 2 * k1, self._control(t + h / 2, x + h / 2 * k1))
            k3 = self._rate(x + h / 2 * k2, self._control(t + h / 2, x + h / 2 * k2))
            k4 = self._rate(x + h * k3, self._control(t + h, x + h * k3))
        else:
            D = self.delay_steps
            self._ring[self._k % (D + 1)] = u0
            held = self._ring[(self._k - D) % (D + 1)] if self._k >= D else 0.0
            k1 = self._rate(x, held)
            self._control(t + h / 2, x + h / 2 * k1)  # the law's stages (its estimates integrate by RK4)
            k2 = self._rate(x + h / 2 * k1, held)
            self._control(t + h / 2, x + h / 2 * k2)
            k3 = self._rate(x + h / 2 * k2, held)
            self._control(t + h, x + h * k3)
            k4 = self._rate(x + h * k3, held)
        self.x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        self._t = t + h
        self._k += 1


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> None:
    """plant.kind = "linear" has no model."""
    return None


def from_scenario(scn, source) -> BuiltPlant:
    """plant.kind = "linear": num/den (times unmodelled_num/den, or the whole plant as A, B, C), input_delay
    [s], ctrl_range; the
    true parameters are MRAC's ideal gains for the modelled part and the law's reference model."""
    from adaptive_mj.laws.mrac import gain_names, ideal_gains

    p, sim, L = scn.plant, scn.simulation, scn.law
    lin = p.linear
    dt = sim.timestep if sim.timestep is not None else 0.001
    try:
        a, b = first_order_part(lin.num, lin.den)
        if lin.A is not None:
            A, B, C = np.array(lin.A, dtype=float), np.array(lin.B, dtype=float), np.array(lin.C, dtype=float)
            if not np.any(C):
                raise ValueError("plant.C must not be all zeros")
        else:
            num, den = np.polymul(lin.num, lin.unmodelled_num), np.polymul(lin.den, lin.unmodelled_den)
            A, B, C = canonical(num, den)
    except ValueError as exc:
        raise ScenarioError(f"{scn.source}: plant: {exc}") from None
    steps = lin.input_delay / dt
    D = int(round(steps))
    if abs(steps - D) > 1e-9 * max(1.0, steps):
        raise ScenarioError(f"{scn.source}: plant.input_delay must be a whole number of timesteps "
                            f"({dt:g} s), got {lin.input_delay:g} s")
    theta = ideal_gains([a], b, [], L.mrac.alpha, L.mrac.beta)
    return BuiltPlant(LinearPlant(A, B, C, dt=dt, names=gain_names(1), theta=theta, delay_steps=D,
                                  ctrl_range=p.ctrl_range))


def nominal_b(scn) -> float:
    """b of the modelled part b/(s - a) (its sign is MRAC's known sign; |b| enters V)."""
    return first_order_part(scn.plant.linear.num, scn.plant.linear.den)[1]


# --- its scenario keys -----------------------------------------------------------
KEYS = plant_keys.analytic_keys(
    Key("num", "array of numbers", doc="the modelled part's numerator b (highest power first)", required=True),
    Key("den", "array of numbers", doc="the modelled part's denominator s - a (highest power first)", required=True),
    Key("unmodelled_num", "array of numbers", default=(1.0,), doc="the unmodelled factor's numerator"),
    Key("unmodelled_den", "array of numbers", default=(1.0,), doc="the unmodelled factor's denominator"),
    Key("input_delay", "number", "s", 0.0, ">= 0", "input delay τ, a whole number of timesteps"),
    Key("A", "array of n arrays of n numbers", doc="the whole plant x' = A x + B u, y = C x (rows)"),
    Key("B", "array of n numbers", doc="see A"),
    Key("C", "array of n numbers", doc="see A"))


def state_space(t: Table) -> dict:
    """plant.A, plant.B, plant.C: all three or none; A square (n, n), B and C (n,); not with
    unmodelled_num/den (the matrices are the whole plant)."""
    given = [k for k in ("A", "B", "C") if k in t.data]
    if not given:
        return {}
    if len(given) != 3:
        missing = next(k for k in ("A", "B", "C") if k not in t.data)
        raise t.fail(missing, "given with plant.A, plant.B and plant.C together", None)
    for key in ("unmodelled_num", "unmodelled_den"):
        if key in t.data:
            raise t.fail(key, "absent when plant.A, B and C give the whole plant", t.data[key])
    rows = t.get("A")
    if not isinstance(rows, list) or not rows or any(not isinstance(r, list) or len(r) != len(rows) for r in rows):
        raise t.fail("A", "a square array of arrays (rows)", rows)
    sub = Table({f"A[{i}]": r for i, r in enumerate(rows)}, t.prefix, t.where)
    A = tuple(sub.numbers(f"A[{i}]", length=len(rows)) for i in range(len(rows)))
    return {"A": A, "B": t.numbers("B", length=len(rows)), "C": t.numbers("C", length=len(rows))}


def read_keys(kind: PlantKind, t: Table, base_dir) -> PlantSpec:
    """plant.* of kind "linear" (analytic, twin backend): num/den, the unmodelled factor, input_delay [s] or
    the state space A, B, C."""
    head = plant_keys.read_analytic(t)
    linear = LinearSpec(num=t.numbers("num"), den=t.numbers("den"),
                        unmodelled_num=t.numbers("unmodelled_num", (1.0,)),
                        unmodelled_den=t.numbers("unmodelled_den", (1.0,)),
                        input_delay=t.number("input_delay", 0.0, ge=0), **state_space(t))
    for key in ("den", "unmodelled_den"):
        if not any(getattr(linear, key)):
            raise t.fail(key, "a polynomial with a non-zero coefficient", list(getattr(linear, key)))
    t.finish()
    return PlantSpec(kind=kind.name, **head, linear=linear)


def mrac_state(scn: Scenario, plant: Plant) -> MracState:
    """The linear plant as MRAC sees it (Form.MRAC_STATE): b from its modelled part (nominal_b), no matched
    nonlinear terms."""
    assert scn.law.order is not None  # set for a law of this form (its reader)
    return MracState(scn.law.order, nominal_b(scn), None, (), tuple(plant.names))


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "linear"
KIND = register(PlantKind(
    "linear", __name__, frozenset({Form.MRAC_STATE}), output_unit="-", control_unit="-",
    params={},
    default_model=None, doc="a linear plant with unmodelled dynamics",
    default_law="mrac", keys=KEYS, reader=read_keys, events={ev.CONSTANT_FORCE: None}, order=first_order,
    mrac_state=mrac_state,
    sections=("MRAC delay", "Rohrs")))

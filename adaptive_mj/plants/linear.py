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

The step is plants.analytic.analytic_step with this kind's kernel (KERNEL: linear_rate, linear_output), on both
paths. Compiled: under MRAC with the Lyapunov rule (laws.mrac) the run is stepped by the analytic chunk engine
(adaptive_mj.sim.native_chunk), one numba function per chunk of steps that runs the same analytic_step and the
law's stages (stage.control_stage), bit for bit (tests/test_native_analytic.py): the step driver
(adaptive_mj.sim.driver) calls step_native(n). The MIT rule (its sensitivity filter),
simulation.python_callback = true, and any law the engine does not compile take the Python path: `step`, the
policy called at each stage.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from adaptive_mj.errors import ScenarioError
from adaptive_mj.plants import BuiltPlant
from adaptive_mj.plants.protocol import Plant, Policy
from adaptive_mj.plants.analytic import AnalyticKernel, AnalyticPlant
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


def linear_params(plant: LinearPlant) -> tuple:
    """(A (n_x, n_x), B (n_x,), C (n_x,)): what linear_rate and linear_output read."""
    return plant.A, plant.B, plant.C


def linear_rate(p, x, u, force, out):
    """out (n_x,) = A x + B (u + force): A x as numpy's A @ x (np.dot: the BLAS matrix-vector product, the same
    call compiled; `gemv_agrees` checks the two agree on the run's A), then B (u + force) added entry by entry."""
    A, B = p[0], p[1]
    np.dot(A, x, out)
    for i in range(x.shape[0]):
        out[i] = out[i] + B[i] * (u + force)


def linear_output(p, x, y):
    """y (1,) = [C x], summed from 0 in order with no fused multiply-add (form.plain_dot's sum)."""
    C = p[2]
    acc = 0.0
    for i in range(x.shape[0]):
        acc += C[i] * x[i]
    y[0] = acc


MAX_STATES = 8  # the order n_x of a plant the compiled chunk runs, at most


def compiled_supports(plant: LinearPlant) -> bool:
    """The compiled chunk runs a plant of order n_x <= MAX_STATES with RK4 on a machine where numba's
    matrix-vector product is numpy's (gemv_agrees)."""
    return plant.stages == 4 and plant.A.shape[0] <= MAX_STATES and gemv_agrees(np.ascontiguousarray(plant.A))


_GEMV: dict = {}


def gemv_agrees(A: np.ndarray) -> bool:
    """Whether numba's np.dot(A, x) (the compiled chunk's A x) gives numpy's np.dot(A, x) bit for bit on this
    machine (both call a BLAS, not necessarily the same library), on a few vectors of this A (the answer kept per
    A: a study's runs of one plant ask once)."""
    known = _GEMV.setdefault("agrees", {})
    key = (A.shape, A.tobytes())
    if key not in known:
        if "gemv" not in _GEMV:
            import numba

            _GEMV["gemv"] = numba.njit(cache=True)(_gemv)
        rng = np.random.default_rng(0)
        ours, theirs = np.empty(A.shape[0]), np.empty(A.shape[0])
        agree = True
        for _ in range(16):
            v = rng.normal(size=A.shape[0]) * 10.0 ** rng.integers(-3, 4, size=A.shape[0])
            _GEMV["gemv"](A, v, ours)
            _gemv(A, v, theirs)
            agree = agree and np.array_equal(ours, theirs)
        known[key] = agree
    return known[key]


def _gemv(A, x, out):
    np.dot(A, x, out)


#: the linear plant's dynamics, for both paths (plants.analytic.AnalyticKernel)
KERNEL = AnalyticKernel("linear", params=linear_params, rate=linear_rate, observe=linear_output,
                        supports=compiled_supports)


class LinearPlant(AnalyticPlant):
    """x' = A x + B u(t - D dt), y = C x (see the module docstring). A FormPlant-like 1-DOF plant
    whose law-facing state is [y] (order 1) and whose "true parameters" are given by the caller in
    the law's coordinates (names, theta: MRAC's ideal gains for the modelled part).

    A (n, n), B (n,), C (n,); dt: step [s]; delay_steps: D >= 0; ctrl_range: (lo, hi) or None."""

    kernel = KERNEL
    joint_shape: tuple[int, ...] = ()
    joint_names: tuple[str, ...] = ()
    first_contact: tuple[float, str] | None = None
    joint_limits: np.ndarray | None = None  # a 1-DOF plant's joint is not limited
    order = 1

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
        self._policy: Policy | None = None
        self.init_steps(1)

    @property
    def form(self):
        raise AttributeError("a linear plant has no ModelForm: law.kind = 'mrac' is its law")

    def set_state(self, x0) -> None:
        """x0: [y0]; the internal state is the least-norm x with C x = y0."""
        y0 = float(np.asarray(x0, dtype=float).reshape(-1)[0])
        self.x = y0 * self.C / float(self.C @ self.C)
        self.restart()

    def observe(self) -> np.ndarray:
        y = np.empty(1)
        linear_output(linear_params(self), self.x, y)
        return y

    def true_theta(self) -> np.ndarray:
        return self._theta


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

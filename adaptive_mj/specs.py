"""The validated scenario as frozen dataclasses (what adaptive_mj.setup.scenario returns, and what each
plant kind's and law kind's key reader builds: adaptive_mj.plants.kinds, adaptive_mj.laws.kinds). Plain data:
nothing here reads a file or imports another adaptive_mj module. The key reference is docs/SCENARIOS.md."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

@dataclass(frozen=True)
class PlantSpec:
    kind: str
    backend: str
    model: Path | None
    joint: str | None
    actuator: str | None
    payload: str | None
    payload_mass: float | None
    site: str
    theta: dict[str, float] | None
    g: float
    density: float | None
    viscosity: float | None
    ctrl_range: tuple[float, float] | None
    thruster_time_constant: float | None = None  # heave: first-order thruster lag tau [s]
    regressor: str = "lecture"  # first_order: "lecture" (sin x - a x + b x²) or "sin_squared"
    manipulator: "ManipulatorSpec | None" = None  # kind = "manipulator" only
    # kind = an installed plant plugin: its declared keys (a per-parameter key: {parameter = number})
    plugin_params: dict[str, float | dict[str, float]] | None = None
    payload_paths: tuple[Path, ...] = ()  # where plant.payload was looked for (see EventSpec.payload_paths)
    linear: "LinearSpec | None" = None  # kind = "linear" only
    wing_rock: "WingRockSpec | None" = None  # kind = "wing_rock" only
    # a plant kind's own keys without a field here (its reader's frozen dataclass or a mapping; None: none): a
    # new kind's module reads and builds it, nothing else needs a field (adaptive_mj.plants.kinds)
    kind_spec: object | None = None
    # law.order's allowed values as the plant kind words them (PlantKind.orders_text, set when its reader reads the
    # [plant] table; None: the order n alone), for the law readers' message (adaptive_mj.laws.law_keys.read_order);
    # a copy of the kind's declaration, so neither repr nor equality shows it
    orders_text: str | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class LinearSpec:
    """plant.* keys of kind "linear": the modelled part num/den (b/(s - a), highest power first), the
    unmodelled factor unmodelled_num/unmodelled_den (default 1/1), input_delay τ [s] (whole timesteps)."""

    num: tuple[float, ...]
    den: tuple[float, ...]
    unmodelled_num: tuple[float, ...] = (1.0,)
    unmodelled_den: tuple[float, ...] = (1.0,)
    input_delay: float = 0.0
    # the whole plant as x' = A x + B u, y = C x instead of the product num/den · unmodelled (A (n, n) as
    # rows, B and C (n,)); num/den still name the modelled part the law is designed for
    A: tuple[tuple[float, ...], ...] | None = None
    B: tuple[float, ...] | None = None
    C: tuple[float, ...] | None = None


@dataclass(frozen=True)
class WingRockSpec:
    """plant.* keys of kind "wing_rock": W (5,) the roll-moment coefficients of [x1, x2, |x1|x2, |x2|x2,
    x1³] (default Elzebda's 25° set) and l_delta L_δ, the control effectiveness (default 1)."""

    W: tuple[float, ...]
    l_delta: float


@dataclass(frozen=True)
class ManipulatorSpec:
    """plant.* keys of a manipulator: which parameters are unknown, and model edits.

    unknown: "payload", "all" or body names; joint_params: armature and damping unknown;
    base_parameters: reduce to a base (identifiable) set; servo_to_torque: rebuild
    position servos as torque motors limited to their forcerange; forcerange: the limit
    [N m or N] for servos whose model gives none, one number or {joint or actuator = number}.
    """

    unknown: str | tuple[str, ...]
    joint_params: bool
    base_parameters: bool
    servo_to_torque: bool
    forcerange: float | dict[str, float] | None = None
    # plant.fixed_joints: joints welded at their reference position, with the tendons, joint equalities and
    # actuators that use them (a gripper's fingers; plants.manipulator.fix_joints)
    fixed_joints: tuple[str, ...] = ()
    # joint friction and actuator lag (plant.damping, .frictionloss, .actuator_lag: a number for every
    # joint or {joint = number}; None keeps the model's), and the regressor's friction columns
    friction: "JointFrictionSpec" = field(default_factory=lambda: JointFrictionSpec())


@dataclass(frozen=True)
class JointFrictionSpec:
    """plant.* keys of a manipulator's friction and actuators: damping [N m s/rad], frictionloss (MuJoCo's
    dry friction [N m]) and actuator_lag (first-order, T [s]) set on the model, each a number for every
    joint or {joint = number} (None: the model's own); friction_params: each joint's damping and
    Coulomb friction unknown to the law, the Coulomb column tanh(q̇ / coulomb_smoothing) [rad/s]."""

    damping: float | dict[str, float] | None = None
    frictionloss: float | dict[str, float] | None = None
    actuator_lag: float | dict[str, float] | None = None
    torque_limit: float | dict[str, float] | None = None  # |τ| <= L [N m] on each joint's motor
    friction_params: bool = False
    coulomb_smoothing: float = 0.01  # = plants.regressor_kernel.DEFAULT_COULOMB_SMOOTHING


@dataclass(frozen=True)
class SimulationSpec:
    integrator: str
    timestep: float | None
    duration: float
    initial_state: tuple[float, ...] | str | None  # or "reference"
    state_bound: float
    control_delay: int = 0  # whole physics steps between computing a control and applying it
    python_callback: bool = False  # force the Python control callback (debugging a law), not the native one
    # what the run says of its integrator against the model's own (setup.scenario: kept when the scenario names
    # none, said when the scenario's replaces it); "" when nothing is to be said
    integrator_note: str = ""


@dataclass(frozen=True)
class SuccessSpec:
    """[success]: the criteria of the run's verdict (docs/SCENARIOS.md, "Verdict").

    tail_rms: bound on each joint's tail RMS tracking error [m or rad]; None = the default,
    tail_fraction x the reference's half-range over the run on that joint, at least tail_floor.
    param_error: bound on |θ̂_i - θ_i| / |θ_i| at the end, for every parameter (a number) or the
    named ones (a table); None = not judged. saturation: the largest fraction of the run any one
    actuator may spend at its limit. preflight: what a failed pre-flight check does when the sampled loop's
    fastest mode is past the integrator's or the hold's stability limit (adaptive_mj.sim.preflight): "warn" (one
    line, the run goes on), "refuse" (`run --strict`: no run) or "record" (the run goes on, the check's result in
    its summary only: a study's runs, which are judged by their outcome whatever the law). physical: the run
    fails when the final estimate of a body's ten standard parameters is no possible body (a negative mass, a
    pseudo-inertia that is not positive semidefinite: report.metrics.body_identification). tail_saturation: the
    largest fraction of the tail's rows in which any actuator may sit at a limit; oscillation [rad/s]: the largest
    sustained oscillation of the body rate over the tail (report.metrics.rate_oscillation; a plant with a body rate,
    the quadrotor); None: the plant kind's own (PlantKind.tail_saturation, .oscillation; the quadrotor's 0.2 and
    1 rad/s), not judged where it declares none."""

    tail_rms: float | None = None
    tail_fraction: float = 0.05
    tail_floor: float = 0.01
    param_error: float | dict[str, float] | None = None
    saturation: float = 0.2
    preflight: str = "warn"
    physical: bool = False
    tail_saturation: float | None = None
    oscillation: float | None = None


PREFLIGHT_ACTIONS = ("warn", "refuse", "record")


@dataclass(frozen=True)
class ControlSpec:
    """[control]: when the law runs. mode "continuous" (at every integrator stage: the lecture's
    continuous-time law) or "sampled" (once per period [s], a whole multiple of the physics timestep,
    None = the timestep; the output held by a zero-order hold, hold = "zoh")."""

    mode: str = "continuous"
    period: float | None = None
    hold: str = "zoh"


@dataclass(frozen=True)
class ReferenceSpec:
    kind: str
    params: dict[str, Any]


@dataclass(frozen=True)
class DeadZoneSpec:
    width: float | None  # None: width_in_noise_std times the noise std of the signal
    on: str
    width_in_noise_std: float | None = None  # ε = k σ (σ_s from noise.std and the surface)


@dataclass(frozen=True)
class RobustSpec:
    """The robust modifications of an adaptive law (docs/SCENARIOS.md, law.sigma ...)."""

    sigma: float = 0.0
    e_modification: float = 0.0
    theta0: dict[str, float] | None = None  # the leakage's prior; None: the initial estimates
    projection: dict[str, tuple[float, float]] | str | None = None  # {name: (lo, hi)} or a RIGID_BODY_PROJECTIONS word
    composite_gain: float | None = None  # composite adaptation: κ
    composite_filter: float | None = None  # its filter λ_f [1/s]


@dataclass(frozen=True)
class LawSpec:
    kind: str
    order: int | None
    lam: float | None
    k: float
    gamma: float | dict[str, float] | None
    dead_zone: DeadZoneSpec | None
    initial_estimates: dict[str, float] | str | None  # or "model": true theta at t = 0
    nominal: dict[str, float] | str | None
    K: float | None
    boundary_layer: float | None
    kd: float | dict[str, float] | None = None  # manipulator laws: K_D, scalar or per joint
    lam_joints: dict[str, float] | None = None  # manipulator laws: Λ per joint (else lam for all)
    robust: RobustSpec = RobustSpec()  # σ/e-modification, projection, composite adaptation
    plugin_params: dict[str, Any] | None = None  # a law plugin's declared keys (law.kind = its name)
    saturation: str = "ignore"  # manipulator law: "freeze" = saturation-aware adaptation
    mrac: "MracSpec | None" = None  # law.kind = "mrac" only
    # a law kind's own keys that no field above holds ({key: value}, as its reader checked them; None: none):
    # a new built-in kind's keys land here without a field of their own (adaptive_mj.laws.kinds)
    params: dict[str, Any] | None = None


@dataclass(frozen=True)
class MracSpec:
    """law.* keys of kind "mrac": the reference model y_m^(n) + α_{n-1}y_m^(n-1) + ... + α_0 y_m = β r
    (alpha = law.model [α_0, ...], beta = law.model_gain, default α_0: unit DC gain) and the rule
    ("lyapunov" or "mit")."""

    alpha: tuple[float, ...]
    beta: float
    rule: str = "lyapunov"


@dataclass(frozen=True)
class NoiseSpec:
    """[noise]: std {signal: σ} (an arm's q and q_dot: a number for every joint, or {joint: σ});
    seed: of the run's generator."""

    std: dict[str, Any]
    seed: int


@dataclass(frozen=True)
class SensorSpec:
    """[sensors] (plant.kind = "manipulator"): encoder_counts per revolution (a number, or {joint:
    counts}; None: not quantised); velocity "measured" or "differentiated" (a filtered finite
    difference of the measured positions); velocity_cutoff_hz: that filter's cut-off [Hz]."""

    encoder_counts: float | dict[str, float] | None = None
    velocity: str = "measured"
    velocity_cutoff_hz: float = 50.0


@dataclass(frozen=True)
class DisturbanceSpec:
    """[disturbance]: a force [N or N m] (1-DOF), or on an arm torques per joint (magnitude a number
    or {joint: value}; kind "noise": band-limited noise of std magnitude and bandwidth_hz) and
    unmodelled loads {body: mass [kg]}."""

    kind: str
    magnitude: float | dict[str, float]
    t0: float
    omega: float
    phase: float
    bandwidth_hz: float = 10.0
    load: dict[str, float] | None = None


@dataclass(frozen=True, repr=False)
class EventSpec:
    """An [[events]] entry, read by its kind's declaration (adaptive_mj.plants.events.EventKind)."""

    t: float
    kind: str
    value: float
    body: str = "payload/body"  # the body the event changes (events[i].body)
    payload: str | None = None  # payload_swap: the payload file (name in models/payloads or path), as written
    # payload_swap: where the file was looked for, in order (bundled: models/payloads; a relative path: next to
    # the scenario, then the current directory); the first that exists is used (adaptive_mj.plants.payload)
    payload_paths: tuple[Path, ...] = ()
    W: tuple[float, ...] | None = None  # flight_condition: the wing-rock coefficients from t on
    l_delta: float | None = None  # flight_condition: L_δ from t on
    # the fields an event kind declares beyond these (a plant kind's own event kind: e.g. a gust's direction)
    params: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        """The dataclass repr; params only when an event kind declares fields of its own."""
        shown = [(f.name, getattr(self, f.name)) for f in fields(self) if f.name != "params" or self.params]
        return f"EventSpec({', '.join(f'{name}={value!r}' for name, value in shown)})"


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. `source` is the file (or "<string>"), `text` its TOML."""

    name: str
    description: str
    plant: PlantSpec
    simulation: SimulationSpec
    reference: ReferenceSpec
    law: LawSpec
    noise: NoiseSpec
    disturbance: DisturbanceSpec
    events: tuple[EventSpec, ...]
    log_rate_hz: float
    source: str
    text: str
    overrides: tuple[str, ...] = field(default=())
    control: ControlSpec = ControlSpec()
    success: SuccessSpec = SuccessSpec()
    sensors: SensorSpec = SensorSpec()
    log_encoding: str = "cdr"  # [log] encoding: rows in CDR, one /row message each (format 8), or JSON (format 6)

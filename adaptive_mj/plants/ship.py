"""The ship (models/ship.xml): a hull in the horizontal plane in MuJoCo's fluid, a constant-thrust
propeller and a servo-driven rudder; output the heading psi [rad], input the commanded rudder angle
delta [rad] (the steering gear's set-point, clamped to +-35 deg by its ctrlrange, its rate limited
by the servo's torque limit: see the model's header).

The autopilot's model is Nomoto's with Norrbin's nonlinearity (adaptive_mj.plants.nomoto):

    T psi'' + psi' + alpha psi'³ = K (delta + delta_b)

The "true" K, T, alpha, delta_b are not typed anywhere: `identify` records the compiled model's own
responses to rudder steps (from a straight course at the cruise speed, +-5, 10, 20, 35 deg, with
the plant's constant yaw moment applied) and fits them (nomoto.fit). They change when the model does
(loading: hull mass and inertia; speed: the propeller's thrust) and when the constant yaw moment
(a wind) does, so the plant refits then. The true theta is the fit's [T/K, 1/K, alpha/K, delta_b].
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj.data import MODELS
from adaptive_mj.errors import ModelError
from adaptive_mj.plants import BuiltPlant, ModelSource
from adaptive_mj.plants.mujoco_plant import (BodyEdits, MujocoPlant, compile_for_scenario, compile_xml_path,
                                             control_callback, read_model_file, scale_body_mass)
from adaptive_mj.plants.nomoto import NomotoFit, fit, nomoto_form
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants.kinds import PlantKind, register
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev

MODEL_PATH = MODELS / "ship.xml"
HEADING_JOINT, RUDDER_JOINT, SURGE_JOINT, SWAY_JOINT = "yaw", "rudder", "x", "y"
STEERING_GEAR, PROPELLER, HULL = "steering_gear", "propeller", "hull"
STEP_ANGLES = np.radians([5.0, 10.0, 20.0, 35.0, -5.0, -10.0, -20.0, -35.0])  # rudder steps of the fit [rad]
STEP_DURATION = 40.0  # [s] per step response (over 5 T at half the design speed)
FIT_SAMPLE = 0.1  # [s] between the samples the fit compares
# [s] the shortest physics step the step responses are integrated at: a model with a shorter one is identified at
# this one (K, T and alpha fitted at 10, 5 and 2 ms agree to 1e-8; a 1e-9 s step must not take hours to fit)
FIT_MIN_TIMESTEP = 0.005
_FITS: dict[bytes, NomotoFit] = {}  # memo: fingerprint of the model and the yaw moment -> its fit


def _id(model, objtype, name: str, kind: str, where: str) -> int:
    i = mujoco.mj_name2id(model, objtype, name)
    if i < 0:
        raise ModelError(f"{where}: the ship model needs a {kind} named {name!r}")
    return i


def cruise_speed(model: mujoco.MjModel, where: str = "ship model") -> float:
    """U [m/s]: the straight-line speed at which the fluid's resistance balances the propeller's thrust
    (bisection on the hull's surge force, rudder amidships, no yaw)."""
    data = mujoco.MjData(model)
    jx = model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, SURGE_JOINT)]

    def net(u: float) -> float:
        data.qvel[:] = 0.0
        data.qvel[jx] = u
        with control_callback(None):
            mujoco.mj_forward(model, data)
        return float(data.qfrc_actuator[jx] + data.qfrc_passive[jx])

    lo, hi = 0.0, 1.0
    if net(lo) <= 0:
        return 0.0
    while net(hi) > 0:
        lo, hi = hi, 2.0 * hi
        if hi > 1e3:
            raise ModelError(f"{where}: no speed balances the propeller's thrust below 1000 m/s (is there water: "
                             f"option density {model.opt.density:g} kg/m³?)")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if net(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def step_responses(model: mujoco.MjModel, *, angles=STEP_ANGLES, duration: float = STEP_DURATION,
                   yaw_moment: float = 0.0, where: str = "ship model") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The hull's responses to rudder steps, one per angle, each from a straight course at the cruise
    speed with the rudder amidships, the steering gear commanded to the angle at t = 0 and the constant
    yaw moment [N m] applied throughout. Returns (t (N,) [s], delta (R, N) the rudder stock's angle
    [rad], r (R, N) the yaw rate [rad/s]), every physics step (N = duration / timestep + 1; the step is
    FIT_MIN_TIMESTEP when the model's is shorter)."""
    import copy

    from mujoco import rollout

    ids = _ids(model, where)
    if model.opt.timestep < FIT_MIN_TIMESTEP:
        model = copy.copy(model)
        model.opt.timestep = FIT_MIN_TIMESTEP
    data = mujoco.MjData(model)
    data.qvel[ids["surge"]] = cruise_speed(model, where)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, x0, spec)
    nstep = int(round(duration / model.opt.timestep))
    cspec = mujoco.mjtState.mjSTATE_CTRL | mujoco.mjtState.mjSTATE_QFRC_APPLIED
    control = np.zeros((len(angles), nstep, model.nu + model.nv))
    control[:, :, ids["gear"]] = np.asarray(angles)[:, None]
    control[:, :, model.nu + ids["yaw"]] = yaw_moment
    with control_callback(None):  # a run's callback must not drive these scratch rollouts
        state, _ = rollout.rollout(model, data, x0, control, control_spec=cspec)
    qpos, qvel = 1, 1 + model.nq  # the full-physics state: time, qpos, qvel, act, ...
    delta = np.concatenate([np.zeros((len(angles), 1)), state[:, :, qpos + ids["rudder_q"]]], axis=1)
    r = np.concatenate([np.zeros((len(angles), 1)), state[:, :, qvel + ids["yaw"]]], axis=1)
    return np.arange(nstep + 1) * model.opt.timestep, delta, r


FIT_TOLERANCE = 0.1  # the largest yaw-rate residual RMS, as a fraction of the peak yaw rate, taken as a fit


def identify(model: mujoco.MjModel, *, yaw_moment: float = 0.0, where: str = "ship model") -> NomotoFit:
    """K, T, alpha, delta_b of the compiled model at its cruise speed, fitted to its own rudder steps
    (step_responses, sampled every FIT_SAMPLE s). Remembered per model and moment in this process.
    A ModelError naming `where` when the responses are no Nomoto model's (a ship that does not move or
    turn, a rudder servo the timestep cannot integrate): residual over FIT_TOLERANCE of the peak."""
    return _identified(model, yaw_moment, where)


def _identified(model: mujoco.MjModel, yaw_moment: float, where: str) -> NomotoFit:
    key = _fingerprint(model, yaw_moment)
    if key not in _FITS:
        t, delta, r = step_responses(model, yaw_moment=yaw_moment, where=where)
        h = float(t[1] - t[0])
        every = max(1, int(round(FIT_SAMPLE / h)))
        f = fit(delta[:, ::every], r[:, ::every], every * h) if np.all(np.isfinite(r)) else None
        if f is None or not (f.K > 0 and f.T > 0 and f.peak > 1e-6 and f.rms <= FIT_TOLERANCE * f.peak):
            what = "non-finite yaw rates" if f is None else (
                f"K = {f.K:.3g} 1/s, T = {f.T:.3g} s, residual {f.rms:.3g} rad/s for a peak yaw rate of "
                f"{f.peak:.3g} rad/s")
            raise ModelError(f"{where}: the hull's rudder-step responses are not those of a steerable ship ({what}); "
                             "the hull must move and its rudder turn it, at a timestep that integrates the steering "
                             f"gear (0.01 s does; this model's is {model.opt.timestep:g} s)")
        _FITS[key] = f
    return _FITS[key]


def _fingerprint(model: mujoco.MjModel, yaw_moment: float) -> bytes:
    h = hashlib.sha256()
    for arr in (model.body_mass, model.body_inertia, model.body_ipos, model.dof_armature, model.dof_damping,
                model.geom_size, model.geom_pos, model.geom_fluid, model.actuator_biasprm, model.actuator_gainprm,
                model.actuator_forcerange, model.actuator_ctrlrange, model.jnt_axis,
                np.array([model.opt.density, model.opt.viscosity, model.opt.timestep, float(model.opt.integrator),
                          yaw_moment])):
        h.update(np.ascontiguousarray(arr, dtype=float).tobytes())
    return h.digest()


def _ids(model: mujoco.MjModel, where: str) -> dict[str, int]:
    """Addresses the plant uses: dofs of yaw, surge and the rudder, the rudder's qpos, the actuators."""
    J, A, B = mujoco.mjtObj.mjOBJ_JOINT, mujoco.mjtObj.mjOBJ_ACTUATOR, mujoco.mjtObj.mjOBJ_BODY
    yaw, rudder = _id(model, J, HEADING_JOINT, "hinge joint", where), _id(model, J, RUDDER_JOINT, "hinge joint", where)
    surge, sway = _id(model, J, SURGE_JOINT, "slide joint", where), _id(model, J, SWAY_JOINT, "slide joint", where)
    return {"yaw_joint": yaw, "yaw": int(model.jnt_dofadr[yaw]), "surge": int(model.jnt_dofadr[surge]),
            "sway": int(model.jnt_dofadr[sway]), "rudder_q": int(model.jnt_qposadr[rudder]),
            "gear": _id(model, A, STEERING_GEAR, "position actuator", where),
            "propeller": _id(model, A, PROPELLER, "actuator", where), "hull": _id(model, B, HULL, "body", where)}


class ShipPlant(BodyEdits, MujocoPlant):
    """The MuJoCo ship: psi and psi' of the yaw hinge are the law's state, the steering gear's set-point
    its control. It starts every run on a straight course at the cruise speed (set_state); its loading
    (hull mass and inertia) and the propeller's thrust may change mid-run, and a constant yaw moment
    (force_offset [N m]: wind, events' constant_force) enters the fitted rudder bias."""

    def __init__(self, model: mujoco.MjModel, *, where: str = "ship model"):
        ids = _ids(model, where)
        if model.opt.density <= 0:
            raise ModelError(f"{where}: option density must be > 0 (the ship floats in MuJoCo's fluid), got "
                             f"{model.opt.density}")
        self.ids = ids
        super().__init__(model, joint_id=ids["yaw_joint"], actuator_id=ids["gear"], form=nomoto_form(),
                         theta_fn=lambda m: identify(m, where=where).theta, where=where)
        self._theta_moment = 0.0
        self.true_theta()  # fitted now: a model that is no steerable ship is refused before any run starts

    # --- the truth, refitted when the model or the constant moment changes -----------
    def nomoto(self) -> NomotoFit:
        """The current fit (K, T, alpha, delta_b) for this model and constant yaw moment."""
        return _identified(self.model, self.force_offset, self.where)

    def speed(self) -> float:
        """Cruise speed [m/s] of the model as it is now (no fit needed)."""
        return cruise_speed(self.model, self.where)

    def true_theta(self) -> np.ndarray:
        """[T/K, 1/K, alpha/K, delta_b] of the current fit (refitted after a model change or a new moment)."""
        if self._theta is None or self._theta_moment != self.force_offset:
            self._theta = self.nomoto().theta
            self._theta_moment = self.force_offset
        return self._theta

    # --- state -------------------------------------------------------------------------
    def set_state(self, x0) -> None:
        """x0: [psi, psi'] [rad, rad/s]; the hull moves at the cruise speed along psi, rudder amidships."""
        super().set_state(x0)
        u = self.speed()
        self.data.qvel[self.ids["surge"]] = u * np.cos(float(x0[0]))
        self.data.qvel[self.ids["sway"]] = u * np.sin(float(x0[0]))

    def set_loading(self, factor: float) -> None:
        """Loading: the hull's mass and inertia times factor (cargo spread like the hull's own mass; the
        hull's shape, hence the water's forces and the added mass, unchanged). mj_setConst runs on a
        scratch MjData (scale_body_mass), so no stale compile-time inertia stays behind."""
        b = self.ids["hull"]
        scale_body_mass(self.model, b, float(self.model.body_mass[b]) * factor)
        self.model_changed()

    def set_thrust_scale(self, factor: float) -> None:
        """Propeller thrust times factor (a new engine order): the cruise speed, K and T move with it."""
        self.model.actuator_biasprm[self.ids["propeller"], 0] *= factor
        self.model_changed()


def load(path: str | Path = MODEL_PATH) -> ShipPlant:
    """Compile the ship MJCF and wrap it."""
    return ShipPlant(compile_xml_path(path), where=str(path))


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> ModelSource | None:
    """plant.model's text."""
    return read_model_file(scn)


def from_scenario(scn, source: ModelSource | None) -> BuiltPlant:
    """plant.kind = "ship": the ship of plant.model (MuJoCo only: its truth is a fit to the model), in water of
    plant.density when given."""
    model, model_xml = compile_for_scenario(scn, source)
    if scn.plant.density is not None:
        model.opt.density = scn.plant.density
    return BuiltPlant(ShipPlant(model, where=str(scn.plant.model)), model_xml)


def _loading(e, scn, source) -> ev.Event:
    return ev.Event(e.t, f"loading: hull mass and inertia x {e.value}", lambda plant: plant.set_loading(e.value))


def _thrust_scale(e, scn, source) -> ev.Event:
    return ev.Event(e.t, f"propeller thrust x {e.value}", lambda plant: plant.set_thrust_scale(e.value))


#: [[events]] kinds of the ship: its loading (hull mass and inertia) and its propeller's thrust, times value
LOADING = ev.EventKind("loading", _loading, doc="multiplies the hull's mass and inertia by value from t on")
THRUST_SCALE = ev.EventKind("thrust_scale", _thrust_scale, doc="multiplies the propeller's thrust by value from t on")

#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "ship"
KIND = register(PlantKind(
    "ship", __name__, frozenset({Form.MODEL}), output_unit="rad", control_unit="rad",
    params={"T_over_K": "s²", "one_over_K": "s", "alpha_over_K": "s³", "rudder_bias": "rad"},
    default_model="ship", doc="a model-scale hull in MuJoCo's fluid, steered by its rudder",
    keys=plant_keys.keys(),
    reader=plant_keys.SharedReader(backend=("mujoco", "its true Nomoto parameters are fitted to the MuJoCo model")),
    events={ev.CONSTANT_FORCE: None, LOADING: "mujoco", THRUST_SCALE: "mujoco"}, sections=("ship",)))

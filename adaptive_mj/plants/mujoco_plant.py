"""What every MuJoCo plant shares: compile, find the joint and actuator, run
the policy inside MuJoCo's control callback, step, detect instability.

MuJoCo's control callback is one C global for the whole process, so it is
installed only inside ``control_callback`` and the previous one is restored
afterwards, even on error. Models are compiled before it is installed.
"""
from __future__ import annotations

import contextlib
import copy
import operator
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterator

import mujoco
import numpy as np

from adaptive_mj.errors import AdaptiveMJError, ModelError, ScenarioError
from adaptive_mj.form import ModelForm
from adaptive_mj.plants import ModelSource, one_dof_kernel
from adaptive_mj.plants.mujoco_kernel import MujocoKernel

Policy = Callable[[float, np.ndarray], float]

# mjData.userdata slots every plant's model is compiled with: slot 0 holds the address of the
# compiled control callback's context block (adaptive_mj.sim.native_context), so the callback
# finds its run's state through the MjData it is given and no address is compiled into it.
USERDATA_SLOTS = 1


def with_userdata(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """The spec with at least USERDATA_SLOTS userdata numbers (see above); returns spec."""
    spec.nuserdata = max(int(spec.nuserdata), USERDATA_SLOTS)
    return spec


@contextlib.contextmanager
def control_callback(fn) -> Iterator[None]:
    """Install fn as mjcb_control for the duration of the block, then restore the previous one."""
    previous = mujoco.get_mjcb_control()
    mujoco.set_mjcb_control(fn)
    try:
        yield
    finally:
        mujoco.set_mjcb_control(previous)


_NO_TIMER: list = []


def no_timer():
    """A compiled (numba cfunc) mjcb_time that returns 0: MuJoCo's timer callback, called twice around each of the
    pipeline's timed stages (about 100-200 calls a 1-DOF RK4 step). Installed in its place, MuJoCo's own clock is
    not read and mjData.timer stays zero; nothing else in the physics reads it. Compiled once per process."""
    if not _NO_TIMER:
        import numba
        from numba import types

        @numba.cfunc(types.float64(), nogil=True, cache=True)
        def zero_time():
            return 0.0

        _NO_TIMER.append(zero_time)
    return _NO_TIMER[0]


@contextlib.contextmanager
def timers_off(off: bool = True) -> Iterator[None]:
    """MuJoCo's profiling timers off for the block (mjcb_time = no_timer; off=False: left as they are), then the
    previous mjcb_time restored. Reading the clock cost 11-38 % of a bare RK4 step on the project's machine (heave
    vehicle 8.5 -> 5.3 µs a step, UR5e 14.6 -> 13.2 µs; docs/PERFORMANCE.md); only mjData.timer reads it."""
    if not off:
        yield
        return
    previous = mujoco.get_mjcb_time()
    mujoco.set_mjcb_time(no_timer().ctypes)
    try:
        yield
    finally:
        mujoco.set_mjcb_time(previous)


@contextlib.contextmanager
def compiled_control(cfunc) -> Iterator[None]:
    """Install a compiled (numba cfunc) control callback for the block, with MuJoCo's profiling timers off
    (timers_off: mjData.timer is not used here; the physics is the same bit for bit, tests/test_native.py). Both
    callbacks are restored afterwards."""
    with timers_off(), control_callback(cfunc.ctypes):
        yield


def compile_xml_path(path: str | Path) -> mujoco.MjModel:
    """Compile an MJCF file, turning MuJoCo's errors into a ModelError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: model file not found")
    try:
        return with_userdata(mujoco.MjSpec.from_file(str(path))).compile()
    except ValueError as exc:  # MuJoCo raises ValueError with its own message
        raise ModelError(f"{path}: MuJoCo could not compile the model: {str(exc).strip()}") from None


def _find(model, objtype, kind: str, name: str | None, count: int, where: str) -> int:
    if name is not None:
        idx = mujoco.mj_name2id(model, objtype, name)
        if idx < 0:
            names = [mujoco.mj_id2name(model, objtype, i) for i in range(count)]
            raise ModelError(f"{where}: no {kind} named {name!r} (the model has {names})")
        return idx
    if count != 1:
        raise ModelError(f"{where}: the model has {count} {kind}s; name the one to use")
    return 0


def joint_words(joint_type) -> str:
    """'hinge joint', 'slide joint', 'ball joint', 'free joint' (not MuJoCo's enum name)."""
    return mujoco.mjtJoint(joint_type).name.removeprefix("mjJNT_").lower() + " joint"


def find_joint_and_actuator(model, *, joint: str | None, actuator: str | None,
                            joint_type: mujoco.mjtJoint, where: str,
                            allow_filter: bool = False) -> tuple[int, int]:
    """Joint and actuator ids by name, or automatically when the model has only one.

    Checks: the joint has the wanted type and is the model's only degree of
    freedom, and the actuator is a direct-drive motor (gain fixed, no bias, no
    activation dynamics, or a first-order filter when allow_filter) on that joint.
    """
    want = joint_words(joint_type)
    if model.nv != 1:  # first: whether this plant can use the model at all, and what to use instead
        raise ModelError(f"{where}: this plant is one {want} driven by one motor (1 degree of freedom), the "
                         f"model has {model.nv}; for a multi-joint arm use plant.kind = \"manipulator\"")
    j = _find(model, mujoco.mjtObj.mjOBJ_JOINT, "joint", joint, model.njnt, where)
    a = _find(model, mujoco.mjtObj.mjOBJ_ACTUATOR, "actuator", actuator, model.nu, where)
    jname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
    if model.jnt_type[j] != joint_type:
        raise ModelError(f"{where}: joint {jname!r} must be a {want}, got a "
                         f"{joint_words(mujoco.mjtJoint(model.jnt_type[j]))}")
    aname = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
    if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or model.actuator_trnid[a, 0] != j:
        raise ModelError(f"{where}: actuator {aname!r} must drive joint {jname!r}")
    dyn_ok = [int(mujoco.mjtDyn.mjDYN_NONE)] + ([int(mujoco.mjtDyn.mjDYN_FILTER)] if allow_filter else [])
    if (model.actuator_gaintype[a] != mujoco.mjtGain.mjGAIN_FIXED
            or model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_NONE
            or int(model.actuator_dyntype[a]) not in dyn_ok):
        raise ModelError(f"{where}: actuator {aname!r} must be a <motor> (fixed gain, no bias, no dynamics)")
    gear = float(model.actuator_gear[a, 0])
    if not (np.isfinite(gear) and gear != 0):
        raise ModelError(f"{where}: actuator {aname or f'#{a}'!r} has gear {gear:g}; the force on the joint is "
                         "gear * ctrl, so the law needs a finite, nonzero gear (set gear, e.g. gear=\"1\")")
    if model.jnt_stiffness[j] != 0 or model.dof_frictionloss[model.jnt_dofadr[j]] != 0:
        raise ModelError(f"{where}: joint {jname!r} has stiffness or frictionloss, "
                         "which the regressor does not cover; set them to 0")
    return j, a


class ModelClock:
    """What every MuJoCo plant class reads of its compiled model and its run's MjData (`model`, `data`): the
    physics step, the integrator's stages, the time."""

    model: mujoco.MjModel
    data: mujoco.MjData

    @property
    def dt(self) -> float:
        """Physics step [s], read from the model (it may be edited after the plant is made)."""
        return float(self.model.opt.timestep)

    @property
    def stages(self) -> int:
        """Control-callback calls per mj_step: 4 under RK4, else 1."""
        return 4 if self.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4 else 1

    @property
    def time(self) -> float:
        return float(self.data.time)

    def termination(self) -> str | None:
        """None: the plant does not crash (protocol.Plant.termination)."""
        return None


class BodyEdits:
    """What the MuJoCo plants whose events change a body share (`model`, `where` for messages, and their own
    `model_changed()`): a body by name, a payload's mass, or its whole inertial at once."""

    model: mujoco.MjModel
    where: str

    # the plant's own: call after editing MjModel fields at run time (what it derived from them is recomputed);
    # annotated only, so that a plant class's own (MujocoPlant.model_changed) is the one found whatever the order
    model_changed: Callable[[], None]

    def body_id(self, name: str) -> int:
        idx = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, name)
        if idx < 0:
            raise ModelError(f"{self.where}: no body named {name!r}")
        return idx

    def set_body_mass(self, name: str, mass: float) -> None:
        """Set a body's mass [kg], scaling its inertia with it (same shape, denser; scale_body_mass, which runs
        mj_setConst so that "simple" bodies update too)."""
        scale_body_mass(self.model, self.body_id(name), mass)
        self.model_changed()

    def set_body_inertial(self, name: str, *, mass: float, ipos, iquat, inertia) -> None:
        """Replace a body's mass [kg], centre of mass (3,) [m], inertia frame quaternion (4,) and principal inertia
        (3,) [kg m²] together (a payload swap; the geoms stay)."""
        m, b = self.model, self.body_id(name)
        m.body_mass[b], m.body_ipos[b], m.body_iquat[b], m.body_inertia[b] = mass, ipos, iquat, inertia
        mujoco.mj_setConst(m, scratch_data(m))
        self.model_changed()


class MujocoPlant(ModelClock):
    """A 1-DOF MuJoCo model driven through one actuator: a FormPlant and a NativePlant
    (adaptive_mj.plants.protocol).

    The specific plants (heave, arm) give the form and the true-parameter
    function; this class owns MjData, stepping and the control callback.
    """

    joint_shape: tuple[int, ...] = ()  # 1-DOF: scalar y and u
    joint_names: tuple[str, ...] = ()
    first_contact: tuple[float, str] | None = None  # contacts are not tracked on a 1-DOF plant
    joint_limits: np.ndarray | None = None  # a 1-DOF plant's joint is not limited
    native_owner: object | None = None  # the native controller whose context data points at
    compiled_loop: str | None = "adaptive_mj.sim.native_mujoco"  # its compiled callback (protocol.Plant.compiled_loop)
    mujoco_kernel: ClassVar[MujocoKernel] = one_dof_kernel.KERNEL  # the kind's kernel spec (plants/one_dof_kernel.py)

    def __init__(self, model: mujoco.MjModel, *, joint_id: int, actuator_id: int, form: ModelForm,
                 theta_fn: Callable[[mujoco.MjModel], np.ndarray], where: str):
        self.model = model
        self.data = run_data(model)
        self.form = form
        self.where = where
        self._theta_fn = theta_fn
        self._qadr = int(model.jnt_qposadr[joint_id])
        self._dadr = int(model.jnt_dofadr[joint_id])
        self._act = int(actuator_id)
        self.joint_id = joint_id
        self.actuator_id = actuator_id
        self.ctrl_range: tuple[float, float] | None = None
        if model.actuator_ctrllimited[self._act]:
            lo, hi = model.actuator_ctrlrange[self._act]
            self.ctrl_range = (float(lo), float(hi))
        self._theta: np.ndarray | None = None
        self.force_offset = 0.0  # constant external generalized force [N or N*m]
        self.disturbance: Callable[[float], float] | None = None  # t -> external force, at each step's start
        self._warnings0 = self._warning_counts()
        self._warning_total0 = int(self._warnings0.sum())

    # --- state -------------------------------------------------------------
    @property
    def order(self) -> int:
        """n: the order of the form (2, or 3 for the heave vehicle with thruster lag)."""
        return self.form.order

    @property
    def names(self) -> tuple[str, ...]:
        """Names of θ, as the form orders them."""
        return self.form.names

    def set_state(self, x0) -> None:
        """x0: (2,) [q, q'] initial joint position [m or rad] and velocity."""
        mujoco.mj_resetData(self.model, self.data)
        self._warnings0 = self._warning_counts()
        self._warning_total0 = int(self._warnings0.sum())
        self.data.qpos[self._qadr] = x0[0]
        self.data.qvel[self._dadr] = x0[1]

    def measure(self, d: mujoco.MjData, x: np.ndarray) -> None:
        """Fill x (n,) with the law's state from MjData: here [q, q'].

        Called inside the control callback, where position- and velocity-
        dependent quantities are current. Plants of higher order override it.
        """
        x[0] = d.qpos[self._qadr]
        x[1] = d.qvel[self._dadr]

    @property
    def native_third_state(self) -> tuple[int, int] | None:
        """Where the compiled 1-DOF callback (adaptive_mj.plants.one_dof_kernel) reads a third state as `measure`
        does: (the thrust state's address in act, the body's id) on the heave vehicle with its thruster lag; None
        elsewhere."""
        return None

    def observe(self) -> np.ndarray:
        """(n,) the law's state now, computed as the control callback would see it."""
        x = np.empty(self.form.order)
        if x.size > 2:  # needs forces at the current state, without firing the control callback
            mujoco.mj_fwdPosition(self.model, self.data)
            mujoco.mj_fwdVelocity(self.model, self.data)
        self.measure(self.data, x)
        return x

    def true_theta(self) -> np.ndarray:
        """True theta from the compiled model (cached until the model is changed)."""
        if self._theta is None:
            self._theta = np.asarray(self._theta_fn(self.model), dtype=float)
        return self._theta

    def model_changed(self) -> None:
        """Call after editing MjModel fields at run time: true theta is recomputed."""
        self._theta = None

    # --- stepping ----------------------------------------------------------
    @contextlib.contextmanager
    def controlled_by(self, policy: Policy) -> Iterator[None]:
        """Run policy(t, x) -> u inside MuJoCo's control callback (each RK4 stage too)."""
        act, measure = self._act, self.measure
        x = np.empty(self.form.order)

        def callback(m, d):
            measure(d, x)
            d.ctrl[act] = policy(d.time, x)

        with control_callback(callback):
            yield

    @contextlib.contextmanager
    def controlled_natively(self, cfunc) -> Iterator[None]:
        """Install a compiled (numba cfunc) control callback for the block (see adaptive_mj.plants.one_dof_kernel)."""
        with compiled_control(cfunc):
            yield

    def step_native(self, nstep: int) -> None:
        """nstep physics steps in one mj_step call, the constant external force held throughout."""
        self.native_prestep()
        mujoco.mj_step(self.model, self.data, nstep=nstep)

    def native_prestep(self) -> None:
        self.data.qfrc_applied[self._dadr] = self.force_offset

    def native_poststep(self) -> None:
        pass

    def step(self) -> None:
        """One mj_step; the external force (offset + disturbance(t)) is held over the step."""
        d = self.data
        force = self.force_offset
        if self.disturbance is not None:
            force += self.disturbance(d.time)
        d.qfrc_applied[self._dadr] = force
        mujoco.mj_step(self.model, d)

    def _warning_counts(self) -> np.ndarray:
        return self.data.warning.number.copy()

    def instability(self) -> str | None:
        """A MuJoCo warning raised since the plant was made, as text, or None."""
        return new_warnings(self.data, self._warning_total0, self._warnings0)

    def unmodelled_drag(self) -> float | None:
        """The viscous drag coefficient absent from the regressor [N s/m] (plants.protocol), where a plant knows it."""
        return None

    def release(self) -> None:
        """The run is over: its MjData goes to the spare ones of its layout (release_data), for the next
        plant of that layout made inside reusing_run_data() to take instead of a new one. The plant has
        no MjData after this (any use of it fails loudly, never on another run's state)."""
        data = self.__dict__.pop("data", None)
        if data is not None and self.native_owner is None:
            release_data(self.model, data)


def new_warnings(data: mujoco.MjData, total0: int, counts0: np.ndarray) -> str | None:
    """MuJoCo warnings raised since the counts were (total0, counts0), as text, or None."""
    if int(data.warning.number.sum()) == total0:
        return None
    new = np.nonzero(data.warning.number > counts0)[0]
    if new.size == 0:
        return None
    return "MuJoCo warning " + ", ".join(mujoco.mjtWarning(int(i)).name for i in new)


def scale_body_mass(model: mujoco.MjModel, body: int, mass: float) -> None:
    """Set a body's mass [kg], its inertia scaled with it (same shape, denser).

    mj_setConst runs on a scratch MjData afterwards, so "simple" bodies (whose
    inertia is otherwise a compile-time constant) update too.
    """
    scale = mass / model.body_mass[body]
    model.body_mass[body] = mass
    model.body_inertia[body] *= scale
    mujoco.mj_setConst(model, scratch_data(model))


#: the most model layouts scratch_data keeps an MjData for
CACHE_SIZE = 8
#: the most compiled models compile_spec keeps (a payload-mass grid of up to this many masses compiles each once)
COMPILED_CACHE_SIZE = 32
_sizes: tuple[tuple[str, ...], Callable[[mujoco.MjModel], tuple[int, ...]]] | None = None  # names, getter
_scratch: OrderedDict[tuple, mujoco.MjData] = OrderedDict()


def layout(model: mujoco.MjModel) -> tuple[tuple[str, int], ...]:
    """The model's sizes (nq, nv, nbody, ngeom, narena, ...: MjModel's integer attributes named n*), which
    fix MjData's layout: two models with the same sizes give MjData the same arrays and buffer, so one
    model's MjData serves the other's (mujoco.batch's mjb_setModels refuses models that differ here)."""
    global _sizes
    if _sizes is None:
        names = tuple(name for name in sorted(dir(model)) if name.startswith("n") and not name.startswith("name")
                      and isinstance(getattr(model, name), int))
        _sizes = (names, operator.attrgetter(*names))  # all ~100 sizes in one call (a Python loop cost 50 µs)
    names, sizes_of = _sizes
    return tuple(zip(names, sizes_of(model), strict=True))


def scratch_data(model: mujoco.MjModel) -> mujoco.MjData:
    """An MjData for scratch work on `model` (kinematics at q0, mj_setConst), reset for it (mj_resetData:
    qpos = qpos0, everything else as a new MjData). Made once per model layout (see layout) and reused: a
    new MjData costs ~0.33 ms of Python-binding setup (measured on the heave vehicle, against 2 µs for the
    reset), several times per run otherwise, and a study's runs each have their own copy of one model.
    Never a run's own MjData; not for use from two threads at once."""
    key = layout(model)
    data = _scratch.get(key)
    if data is None:
        data = _scratch[key] = mujoco.MjData(model)
        while len(_scratch) > CACHE_SIZE:
            _scratch.popitem(last=False)
    else:
        _scratch.move_to_end(key)
    mujoco.mj_resetData(model, data)
    return data


#: the most spare MjData release_data keeps per model layout
SPARE_PER_LAYOUT = 4
_spare: OrderedDict[tuple, list[mujoco.MjData]] = OrderedDict()


_reuse_depth = 0  # > 0 inside reusing_run_data()


@contextlib.contextmanager
def reusing_run_data() -> Iterator[None]:
    """Plants made in the block may take a spare MjData (run_data). For runner.start only: its plants are
    handed back when the run ends (runner.Started) and its code always passes the plant's own model with
    the MjData; a reused MjData's `.model` (the Python binding's reference) is still the model it was
    made for, which code that reads `data.model` (dm_control's Physics, adaptive_mj.env) must not see."""
    global _reuse_depth
    _reuse_depth += 1
    try:
        yield
    finally:
        _reuse_depth -= 1


def run_data(model: mujoco.MjModel) -> mujoco.MjData:
    """A run's own MjData for `model`: inside reusing_run_data(), a spare one of its layout that an ended
    run released (release_data), reset for this model (mj_resetData: qpos = qpos0, mocap from the model,
    everything else zero, as in a new MjData; MuJoCo reads no value of its buffer it did not write
    first); otherwise, or with none spare, or for a model with engine plugins (whose instances are made
    with the MjData), a new one. A study's runs in one process each save the ~0.3 ms of Python-binding
    setup a new MjData costs (scratch_data); tests/test_build_cache.py shows a run on a reused MjData
    gives the same rows."""
    if _reuse_depth > 0 and model.nplugin == 0:
        spare = _spare.get(layout(model))
        if spare:
            data = spare.pop()
            mujoco.mj_resetData(model, data)
            return data
    return mujoco.MjData(model)


def release_data(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Keep an ended run's MjData (of `model`'s layout) for run_data; the caller holds no reference to it."""
    if model.nplugin != 0:
        return
    key = layout(model)
    spare = _spare.setdefault(key, [])
    _spare.move_to_end(key)
    if len(spare) < SPARE_PER_LAYOUT:
        spare.append(data)
    while len(_spare) > CACHE_SIZE:
        _spare.popitem(last=False)


def spec_from_text(xml: str, assets: dict | None = None) -> mujoco.MjSpec:
    """MjSpec of MJCF text and its assets. MjSpec.from_string reads files that <model file=...> and
    <include file=...> name from `include`, meshes and textures from `assets`: both get the dict
    (an attached payload is an asset, adaptive_mj.plants.attach)."""
    return mujoco.MjSpec.from_string(xml, include=assets or None, assets=assets or None)


_compiled: OrderedDict[tuple, tuple[mujoco.MjModel, str, Any]] = OrderedDict()


def compile_spec(xml: str, assets: dict | None = None, *, where: str, edit=None,
                 edit_key: tuple | None = None) -> tuple[mujoco.MjModel, str]:
    """Compile MJCF text through MjSpec, optionally editing the spec first.

    Returns the model and the compiled model as MJCF text (the log's model.xml).
    MuJoCo's own message is passed on in a ModelError naming `where`.

    The compiled model is kept (the last COMPILED_CACHE_SIZE texts) and the next call with the same text, assets
    and edit returns a copy of it (mj_copyModel: the same numbers; a study's runs of one model compile it
    once per process, 0.17 ms per copy against 1.2 ms to parse, compile and write the heave vehicle's
    XML). An `edit` is cached only when the caller names what it does in `edit_key` (a tuple of values
    that determine it): an edit without a key compiles every time.
    """
    model, text, _ = compile_spec_with(xml, assets, where=where, edit=edit, edit_key=edit_key)
    return model, text


def compile_spec_with(xml: str, assets: dict | None = None, *, where: str, edit=None,
                      edit_key: tuple | None = None) -> tuple[mujoco.MjModel, str, Any]:
    """compile_spec, and what edit(spec) returned (None without an edit): kept with the compiled model, so
    a compile the cache answers gives the edit's result too (an edit's notes, say) without running it."""
    key = None
    if edit is None or edit_key is not None:
        key = (xml, tuple(sorted((k, bytes(v) if not isinstance(v, str) else v) for k, v in (assets or {}).items())),
               edit_key)
        hit = _compiled.get(key)
        if hit is not None:
            _compiled.move_to_end(key)
            return copy.copy(hit[0]), hit[1], copy.deepcopy(hit[2])
    model, text, result = _compile_spec(xml, assets, where=where, edit=edit)
    if key is not None:
        _compiled[key] = (copy.copy(model), text, copy.deepcopy(result))
        while len(_compiled) > COMPILED_CACHE_SIZE:
            _compiled.popitem(last=False)
    return model, text, result


def _compile_spec(xml: str, assets: dict | None, *, where: str, edit) -> tuple[mujoco.MjModel, str, Any]:
    result = None
    try:
        spec = spec_from_text(xml, assets)
        if edit is not None:
            result = edit(spec)
        model = with_userdata(spec).compile()
    except AdaptiveMJError:  # edit's own one-line refusal (servo_to_torque), not MuJoCo's
        raise
    except ValueError as exc:
        raise ModelError(f"{where}: MuJoCo could not compile the model: {str(exc).strip()}") from None
    return model, spec.to_xml(), result


INTEGRATORS = {
    "rk4": mujoco.mjtIntegrator.mjINT_RK4,
    "euler": mujoco.mjtIntegrator.mjINT_EULER,
    "implicitfast": mujoco.mjtIntegrator.mjINT_IMPLICITFAST,
    "implicit": mujoco.mjtIntegrator.mjINT_IMPLICIT,
}


def read_mjcf(path: Path, what: str = "model") -> str:
    """An MJCF file's text; an unreadable, empty or binary file is a one-line ModelError naming it."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot read the {what} file: {exc.strerror or exc}") from None
    if not data.strip():
        raise ModelError(f"{path}: empty {what} file ({len(data)} bytes), expected an MJCF model (<mujoco>...)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = None
    if text is None or "\x00" in text:
        raise ModelError(f"{path}: not a text file (binary data, starts with {data[:8]!r}), expected an MJCF "
                         "model (<mujoco>...)")
    return text


def read_model_file(scn) -> ModelSource:
    """plant.model's text, as compiled (a plant kind's model_source for a single MJCF file)."""
    p = scn.plant
    if not p.model.is_file():
        raise ModelError(f"{scn.source}: plant.model {str(p.model)!r} not found")
    return ModelSource(read_mjcf(p.model), {})


def compile_for_scenario(scn, source: ModelSource | None, *, edit=None,
                         edit_key: tuple | None = None) -> tuple[mujoco.MjModel, str]:
    """(model, compiled MJCF text) with the scenario's simulation options applied:
    integrator, timestep (checked against the duration) and plant.viscosity.
    edit(spec), if given, changes the MjSpec before it is compiled (edit_key: see compile_spec).
    source None (a model-free twin's) has nothing to compile: a ModelError."""
    model, xml, _ = compile_for_scenario_with(scn, source, edit=edit, edit_key=edit_key)
    return model, xml


def compile_for_scenario_with(scn, source: ModelSource | None, *, edit=None,
                              edit_key: tuple | None = None) -> tuple[mujoco.MjModel, str, Any]:
    """compile_for_scenario, and what edit(spec) returned (compile_spec_with)."""
    if source is None:
        raise ModelError(f"{scn.plant.model}: no model text to compile")
    model, xml, result = compile_spec_with(source.xml, source.assets, where=str(scn.plant.model), edit=edit,
                                           edit_key=edit_key)
    sim = scn.simulation
    model.opt.integrator = INTEGRATORS[sim.integrator]
    if sim.timestep is not None:
        model.opt.timestep = sim.timestep
    elif model.opt.timestep > sim.duration:
        raise ScenarioError(f"{scn.source}: the model's timestep {model.opt.timestep} is larger than "
                            f"simulation.duration {sim.duration}")
    if scn.plant.viscosity is not None:
        model.opt.viscosity = scn.plant.viscosity
    skip_empty_constraints(model)
    return model, xml, result


def constraint_free(model: mujoco.MjModel) -> bool:
    """Whether no constraint can ever arise in `model`: no equality constraint, no flex, no joint or tendon
    limit, no friction loss, and no contact (contacts disabled, or no explicit pair and no two geoms on different
    bodies whose contype and conaffinity bits meet; MuJoCo never collides two geoms of one body). Conservative: a
    pair MuJoCo would filter out otherwise (parent and child, exclusions) still counts as possible."""
    flags = int(model.opt.disableflags)
    if flags & int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT):
        return True
    if model.neq or model.nflex or np.any(model.jnt_limited) or np.any(model.dof_frictionloss):
        return False
    if model.ntendon and (np.any(model.tendon_limited) or np.any(model.tendon_frictionloss)):
        return False
    if flags & int(mujoco.mjtDisableBit.mjDSBL_CONTACT):
        return True
    if model.npair:
        return False
    ct, ca, body = model.geom_contype, model.geom_conaffinity, model.geom_bodyid
    meet = ((ct[:, None] & ca[None, :]) | (ca[:, None] & ct[None, :])) != 0
    return not np.any(meet & (body[:, None] != body[None, :]))


def skip_empty_constraints(model: mujoco.MjModel) -> bool:
    """Where no constraint can arise (constraint_free), switch MuJoCo's constraint pipeline off (mjDSBL_CONSTRAINT):
    collision detection, constraint assembly and the solver then do not run to find nothing, and every step is
    the same bit for bit (qacc = qacc_smooth either way), 20-25 % faster on the heave vehicle and the UR5e. True
    where it did. The compiled model's text (a log's model.xml) is the model as written: replaying it does the
    same."""
    if not constraint_free(model):
        return False
    model.opt.disableflags = int(model.opt.disableflags) | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    return True

"""A manipulator: any MJCF whose moving part is a tree of hinge and slide joints, each
driven by its own torque motor (models/ur5e_arm.xml is the bundled one).

    M(q) q̈ + C(q, q̇) q̇ + g(q) + D q̇ + f_c = τ,        τ_j = gear_j ctrl_j

The law's parameters π are the standard 10 inertial parameters of each unknown body
(adaptive_mj.plants.regressor_kernel.BODY_PARAM_NAMES: m, m·c, inertia about the body
origin, in the body frame), optionally the joints' armature and damping (joint_params),
optionally their viscous damping and Coulomb friction (friction_params), and
optionally reduced to a base (identifiable) set. Everything known is computed from the
compiled model and enters as the known torque τ_known, so

    Y(q, q̇, q̇_r, q̈_r) π + τ_known = M q̈_r + C(q, q̇) q̇_r + g + armature·q̈_r + D q̇ (+ F_c tanh(q̇ / ε))

exactly (tests/test_manipulator.py checks it against mj_inverse).

What the regressor leaves out, on purpose (plant.frictionloss, plant.actuator_lag): MuJoCo's
joint frictionloss f_c is dry friction enforced as a (soft) constraint, bounded by the
frictionloss F_c and opposing the motion; it is unmodelled unless the regressor has Coulomb
columns (friction_params), and even then only approximately: the column is F_c tanh(q̇ / ε),
which equals F_c sign(q̇) for |q̇| ≳ 3ε but cannot describe sticking (q̇ = 0 with |f_c| < F_c)
or the constraint's own softness. A first-order actuator lag (MuJoCo's filter dynamics,
τ_applied' = (τ_commanded - τ_applied) / T, see set_actuator_lag) makes the regressor's
τ = gear·ctrl the commanded torque while the plant feels the lagged one. The regressor is
evaluated on the MjData of the current evaluation of the dynamics (the control
callback's stage), where MuJoCo's kinematics (cdof, xpos, xmat, subtree_com, cinert)
are current.
"""
from __future__ import annotations

import contextlib
import functools
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Iterator

import mujoco
import numpy as np

from adaptive_mj.disturbance import JointDisturbance

from adaptive_mj.errors import ModelError
from adaptive_mj.numba_util import jit_tree, with_globals as _with_globals
from adaptive_mj.plants import regressor_kernel as rk
from adaptive_mj.plants import BuiltPlant, ModelSource, manipulator_kernel
from adaptive_mj.plants.mujoco_kernel import MujocoKernel
from adaptive_mj.plants.mujoco_plant import (BodyEdits, ModelClock, compile_for_scenario_with, compiled_control,
                                             control_callback, new_warnings, scratch_data)
from adaptive_mj.plants.protocol import Policy
from adaptive_mj.laws.kinds import Form
from adaptive_mj.plants.kinds import Draw, PlantKind, ScoreTask, StressPlant, body_param_unit, register
from adaptive_mj.plants.study_spec import (LEAK_TIME, Stressor, StudyContext, hold_joints, payload_ratio,
                                           sine_disturbance, surface_noise, theta_table)
from adaptive_mj.plants import plant_keys
from adaptive_mj.plants import events as ev
from adaptive_mj.keys import Key, Table
from adaptive_mj.specs import JointFrictionSpec, ManipulatorSpec


def _name(model, objtype, i: int) -> str:
    return mujoco.mj_id2name(model, objtype, i) or f"#{i}"


LAG_DYNTYPES = (mujoco.mjtDyn.mjDYN_FILTER, mujoco.mjtDyn.mjDYN_FILTEREXACT)


def _is_lag(model, a: int) -> bool:
    """Actuator a has a first-order lag (filter or filterexact, time constant dynprm[0] > 0): the one
    actuator dynamics the plant accepts (plant.actuator_lag; unmodelled by the regressor)."""
    return int(model.actuator_dyntype[a]) in {int(d) for d in LAG_DYNTYPES} and bool(model.actuator_dynprm[a, 0] > 0)


def check_supported(model: mujoco.MjModel, where: str) -> None:
    """Refuse, in one line, everything the manipulator regressor does not cover (refusals): every reason at once,
    numbered, each with its fix."""
    reasons = refusals(model)
    if reasons:
        raise ModelError(refusal_text(where, reasons))


def refusal_text(where: str, reasons: list[str]) -> str:
    """One line: `where` cannot be driven as a manipulator, and why (each reason with its fix)."""
    if len(reasons) == 1:
        return f"{where}: {reasons[0]}"
    return (f"{where}: cannot be driven as a manipulator, for {len(reasons)} reasons: "
            + "; ".join(f"({i}) {r}" for i, r in enumerate(reasons, 1)))


def _toml_names(names) -> str:
    return "[" + ", ".join(f'"{n}"' for n in names) + "]"


def refusals(model: mujoco.MjModel) -> list[str]:  # noqa: C901 (one check per unsupported feature)
    """What the manipulator regressor does not cover in `model`, each reason with its fix ([] when it covers all).
    Unactuated joints, and the tendons and equality constraints among them (a gripper's fingers), get one fix:
    plant.fixed_joints (fix_joints), printed as it pastes."""
    out: list[str] = []
    jname = functools.partial(_name, model, mujoco.mjtObj.mjOBJ_JOINT)
    for j in range(model.njnt):
        t = mujoco.mjtJoint(model.jnt_type[j])
        if t not in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            kind = t.name.removeprefix("mjJNT_").lower()
            out.append(f"joint {jname(j)!r} is a {kind} joint; the manipulator plant supports only hinge and slide "
                       "joints on a fixed base (replace it, or weld a floating base to the world)")
        elif model.jnt_stiffness[j] != 0:
            out.append(f"joint {jname(j)!r} has stiffness {model.jnt_stiffness[j]:g}, which the regressor does not "
                       "cover; set it to 0")
    if model.nv == 0:
        return [*out, "the model has no joints; the manipulator plant needs a tree of hinge/slide joints"]
    # dof_frictionloss is accepted: MuJoCo's dry friction (a constraint), unmodelled unless the layout has
    # Coulomb columns (friction_params), see the module docstring
    for j in np.nonzero(np.any(model.dof_dampingpoly != 0, axis=1))[0][:1]:
        out.append(f"joint {jname(model.dof_jntid[j])!r} has nonlinear damping (polynomial terms "
                   f"{model.dof_dampingpoly[j].tolist()}); the regressor covers linear damping only; give damping "
                   "one value")
    driven = np.full(model.nv, -1)
    actuators: list[str] = []
    for a in range(model.nu):
        aname = _name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_TENDON:  # a tendon's actuator goes with its tendon
                actuators.append(f"actuator {aname!r} does not drive a joint directly (site or coupled "
                                 "transmission); the manipulator plant needs one motor per joint")
            continue
        if (model.actuator_gaintype[a] != mujoco.mjtGain.mjGAIN_FIXED
                or model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_NONE
                or not (model.actuator_dyntype[a] == mujoco.mjtDyn.mjDYN_NONE or _is_lag(model, a))):
            actuators.append(f"actuator {aname!r} is not a torque <motor> (it has a bias, a gain function or "
                             "dynamics, e.g. a position servo); set plant.servo_to_torque = true to rebuild servos "
                             "as torque motors limited to their forcerange")
        elif model.actuator_gainprm[a, 0] != 1.0:
            actuators.append(f"actuator {aname!r} has gain {model.actuator_gainprm[a, 0]:g}; the manipulator plant "
                             "needs torque = gear * ctrl (a <motor>, or gainprm 1)")
        dof = int(model.jnt_dofadr[model.actuator_trnid[a, 0]])
        if driven[dof] >= 0:
            actuators.append(f"joint {jname(model.dof_jntid[dof])!r} is driven by more than one actuator; the "
                             "manipulator plant needs exactly one each")
        driven[dof] = a
    unactuated = [jname(model.dof_jntid[j]) for j in range(model.nv) if driven[j] < 0]
    coupled = sorted({jname(j) for j in _tendon_joints(model) | _equality_joints(model)}
                     - {jname(model.dof_jntid[j]) for j in range(model.nv) if driven[j] >= 0})
    fixable = list(dict.fromkeys([*unactuated, *coupled]))
    fix = (f" (if they are a gripper's: --set 'plant.fixed_joints={_toml_names(fixable)}' welds them at their "
           "reference position and drops the tendons, equality constraints and actuators that use them)"
           if fixable else "")
    if model.ntendon:
        out.append(f"the model has {model.ntendon} tendon(s); the manipulator plant needs each joint driven by its "
                   "own motor, with no tendons" + fix)
    if model.neq:
        out.append(f"the model has {model.neq} equality constraint(s), which the regressor does not cover; remove "
                   "them" + fix)
    if np.any(model.body_gravcomp != 0):
        out.append("gravcomp is set on a body; the manipulator regressor models full gravity; set gravcomp to 0")
    if model.opt.density != 0 or model.opt.viscosity != 0:
        out.append("fluid forces (option density/viscosity) are not covered by the manipulator regressor; set them "
                   "to 0")
    out.extend(actuators)
    if unactuated:
        out.append(f"joint(s) {unactuated} have no actuator; the manipulator plant needs every joint actuated (add "
                   "a <motor>, or fix the unactuated joints" + (fix.replace(" (if they are", ": if they are")[:-1]
                                                                if fix else "") + ")")
    gear = model.actuator_gear[:, 0]
    bad_gear = [f"{_name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a)!r} (gear {gear[a]:g})" for a in range(model.nu)
                if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and not (np.isfinite(gear[a])
                                                                                  and gear[a] != 0)]
    if bad_gear:
        out.append(f"actuator(s) {', '.join(bad_gear)} cannot drive their joint: the joint torque is gear * ctrl, so "
                   "the law's torque needs a finite, nonzero gear (set gear, e.g. gear=\"1\")")
    return out


def _tendon_joints(model: mujoco.MjModel) -> set[int]:
    """The joints (ids) the model's fixed tendons couple."""
    out = set()
    for t in range(model.ntendon):
        for w in range(model.tendon_adr[t], model.tendon_adr[t] + model.tendon_num[t]):
            if model.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT:
                out.add(int(model.wrap_objid[w]))
    return out


def _equality_joints(model: mujoco.MjModel) -> set[int]:
    """The joints (ids) the model's joint equality constraints tie."""
    out: set[int] = set()
    for e in range(model.neq):
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            out.update(int(i) for i in (model.eq_obj1id[e], model.eq_obj2id[e]) if i >= 0)
    return out


def fix_joints(spec, names: tuple[str, ...]) -> list[str]:
    """plant.fixed_joints: each named joint removed from `spec` (its body welded to its parent at the joint's
    reference position), with the tendons that wrap it, the joint equality constraints that name it and the
    actuators that drive it or those tendons (a gripper's fingers, their coupling and their motor). Returns the
    note saying what was removed; a name the model does not have is a ModelError naming the key and the joints."""
    if not names:
        return []
    model = spec.compile()
    jid = {mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j): j for j in range(model.njnt)}
    unknown = [n for n in names if n not in jid]
    if unknown:
        raise ModelError(f"plant.fixed_joints: no joint named {unknown[0]!r} in the model (its joints: "
                         f"{[n for n in jid if n]})")
    fixed = {jid[n] for n in names}
    tendons = [t for t in range(model.ntendon)
               if any(model.wrap_type[w] == mujoco.mjtWrap.mjWRAP_JOINT and int(model.wrap_objid[w]) in fixed
                      for w in range(model.tendon_adr[t], model.tendon_adr[t] + model.tendon_num[t]))]
    eqs = [e for e in range(model.neq) if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT
           and ({int(model.eq_obj1id[e]), int(model.eq_obj2id[e])} & fixed)]
    acts = [a for a in range(model.nu)
            if (model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT and int(model.actuator_trnid[a, 0]) in fixed)
            or (model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON and int(model.actuator_trnid[a, 0])
                in tendons)]
    # spec.actuators / equalities / tendons are in the compiled model's order; delete the users first
    for element in ([spec.actuators[a] for a in acts] + [spec.equalities[e] for e in eqs]
                    + [spec.tendons[t] for t in tendons] + [spec.joint(n) for n in names]):
        spec.delete(element)
    named = functools.partial(_name, model)
    parts = [f"joint(s) {list(names)} fixed at their reference position"]
    if tendons:
        parts.append(f"tendon(s) {[named(mujoco.mjtObj.mjOBJ_TENDON, t) for t in tendons]}")
    if eqs:
        parts.append(f"{len(eqs)} equality constraint(s)")
    if acts:
        parts.append(f"actuator(s) {[named(mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in acts]}")
    return ["plant.fixed_joints: " + parts[0] + (" (removed with them: " + ", ".join(parts[1:]) + ")"
                                                 if len(parts) > 1 else "")]


def _is_servo(act) -> bool:
    return not (act.biastype == mujoco.mjtBias.mjBIAS_NONE and act.gaintype == mujoco.mjtGain.mjGAIN_FIXED
                and act.dyntype == mujoco.mjtDyn.mjDYN_NONE)


def _model_forcerange(act) -> tuple[float, float] | None:
    lo, hi = (float(v) for v in act.forcerange)
    limited = act.forcelimited == mujoco.mjtLimited.mjLIMITED_TRUE or (
        act.forcelimited == mujoco.mjtLimited.mjLIMITED_AUTO and lo < hi)
    return (lo, hi) if limited and lo < hi else None


def servo_to_torque(spec, forcerange: float | dict[str, float] | None = None) -> list[str]:
    """Rebuild position servos (<position>, or <general> with an affine bias) as torque motors.

    Each becomes gain 1, no bias, no dynamics, its control range set to its force limit:
    `forcerange` (plant.forcerange: one limit L [N m or N] for every servo, or a table
    {joint or actuator name: L}) where it gives one, as [-L, L], else the servo's own
    forcerange. A servo with neither is never turned into an unlimited motor: one ModelError
    names every such actuator. Returns one line per converted actuator.
    """
    servos = [act for act in spec.actuators if _is_servo(act)]
    table = forcerange if isinstance(forcerange, dict) else None
    if table is not None:
        known = {n for act in servos for n in (act.name, act.target) if n}
        stray = [k for k in table if k not in known]
        if stray:
            shown = ", ".join(f"{act.name or '#' + str(i)!r} (joint {act.target!r})" for i, act in enumerate(servos))
            raise ModelError(f"plant.forcerange names {', '.join(repr(k) for k in stray)}, which is no servo's "
                             f"joint or actuator name (servos: {shown or 'none'})")
    limits: list[tuple[float, float, str]] = []
    missing = []
    for i, act in enumerate(servos):
        given = table.get(act.name, table.get(act.target)) if table is not None else forcerange
        if isinstance(given, (int, float)):
            limits.append((-float(given), float(given), " from plant.forcerange"))
            continue
        own = _model_forcerange(act)
        if own is None:
            missing.append(f"{act.name or '#' + str(i)!r} (joint {act.target!r})")
            limits.append((0.0, 0.0, ""))
        else:
            limits.append((own[0], own[1], ""))
    if missing:
        raise ModelError(f"plant.servo_to_torque: {len(missing)} servo(s) have no forcerange to limit the torque "
                         f"motor each becomes: {', '.join(missing)}; give plant.forcerange = L (|tau| <= L [N m] "
                         "on every joint) or a table {joint = L, ...}, or a forcerange in the MJCF")
    rebuilt = []
    for act, (lo, hi, whence) in zip(servos, limits, strict=True):
        act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
        act.gainprm = np.zeros_like(act.gainprm)
        act.gainprm[0] = 1.0
        act.biastype = mujoco.mjtBias.mjBIAS_NONE
        act.biasprm = np.zeros_like(act.biasprm)
        act.dyntype = mujoco.mjtDyn.mjDYN_NONE
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [lo, hi]
        if whence:
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [lo, hi]
        rebuilt.append(f"{act.name!r} |tau| <= [{lo:g}, {hi:g}] N*m" + whence)
    # one note for the run, not one per servo (a Menagerie arm has seven)
    return ["plant.servo_to_torque: servo(s) rebuilt as torque motors: " + ", ".join(rebuilt)] if rebuilt else []


# --- joint friction and actuator lag, as MjSpec edits (plant.damping, .frictionloss, .actuator_lag) ---
def _by_joint(spec, key: str, value) -> list[tuple[Any, float]]:
    """(joint, value) pairs: a number for every joint, or a table {joint name: number} (others unchanged)."""
    joints = list(spec.joints)
    if not isinstance(value, dict):
        return [(j, float(value)) for j in joints]
    names = [j.name for j in joints]
    unknown = [n for n in value if n not in names]
    if unknown:
        raise ModelError(f"{key} names joint {unknown[0]!r}, which the model does not have "
                         f"(joints: {', '.join(names)})")
    return [(j, float(value[j.name])) for j in joints if j.name in value]


def set_joint_friction(spec, *, damping=None, frictionloss=None) -> None:
    """Set joint damping [N m s/rad or N s/m] and frictionloss (dry friction [N m or N]), each a number
    for every joint or a table {joint: value}, on the spec; None leaves the model's values."""
    for joint, v in _by_joint(spec, "plant.damping", damping) if damping is not None else ():
        coefs = np.array(joint.damping, dtype=float)  # [linear, polynomial terms]: the linear one
        coefs[0] = v
        joint.damping = coefs
    for joint, v in _by_joint(spec, "plant.frictionloss", frictionloss) if frictionloss is not None else ():
        joint.frictionloss = v


def set_actuator_lag(spec, lag, *, exact: bool = True) -> None:
    """Give each joint's motor a first-order lag of time constant T [s]: act' = (ctrl - act) / T,
    force = gain·act, so a held ctrl gives τ(t) = τ_c (1 - e^{-t/T}). exact: MuJoCo's filterexact
    dynamics (act advanced by the exact exponential over a step), for the one-stage integrators
    (Euler, implicit, implicitfast); else filter, for RK4: MuJoCo 3.17's RK4 applies filterexact's
    exponential to its stage-averaged act' and is then only first-order accurate (measured: 0.94 %
    of τ_c at h/T = 0.05, as Euler with filter), while filter under RK4 is fourth-order (2e-8 of
    τ_c; tests/test_joint_friction.py). lag: a number for every actuator, or a table {joint: T} for
    the motors of those joints; T = 0 leaves a motor without dynamics."""
    if lag is None:
        return
    for joint, T in _by_joint(spec, "plant.actuator_lag", lag):
        acts = [a for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target == joint.name]
        if not acts and isinstance(lag, dict):
            raise ModelError(f"plant.actuator_lag names joint {joint.name!r}, which no actuator drives")
        for act in acts if T > 0 else ():
            if act.dyntype not in (mujoco.mjtDyn.mjDYN_NONE,) + LAG_DYNTYPES:
                raise ModelError(f"plant.actuator_lag: actuator {act.name!r} already has dynamics "
                                 f"({mujoco.mjtDyn(act.dyntype).name}); the lag needs a torque motor")
            act.dyntype = mujoco.mjtDyn.mjDYN_FILTEREXACT if exact else mujoco.mjtDyn.mjDYN_FILTER
            act.dynprm = np.zeros_like(act.dynprm)
            act.dynprm[0] = T


def set_torque_limit(spec, limit) -> None:
    """Limit each joint's motor to |τ| <= L [N m or N] (plant.torque_limit: a number for every joint or
    a table {joint: L}): ctrlrange = [-L, L] / |gear|, ctrllimited. The law's torques are clamped to it
    (and law.saturation = "freeze" reads it)."""
    if limit is None:
        return
    for joint, L in _by_joint(spec, "plant.torque_limit", limit):
        acts = [a for a in spec.actuators if a.trntype == mujoco.mjtTrn.mjTRN_JOINT and a.target == joint.name]
        if not acts:
            raise ModelError(f"plant.torque_limit names joint {joint.name!r}, which no actuator drives")
        for act in acts:
            g = abs(float(act.gear[0]))
            if not g > 0:
                raise ModelError(f"plant.torque_limit: actuator {act.name!r} has gear {act.gear[0]:g}")
            act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.ctrlrange = [-L / g, L / g]


@dataclass(frozen=True)
class ParamLayout:
    """Which parameters are unknown, and their names.

    bodies: unknown body ids; joints: whether armature and damping are unknown; friction:
    whether damping and Coulomb friction are unknown; coulomb_smoothing: ε [rad/s or m/s] of
    the Coulomb column tanh(q̇ / ε); names: (n_standard,) names "<body>.<param>", then
    "<joint>.armature" (joints), "<joint>.damping" (joints or friction), "<joint>.coulomb"
    (friction), each block over every joint.
    """

    bodies: tuple[int, ...]
    joints: bool
    names: tuple[str, ...]
    friction: bool = False
    coulomb_smoothing: float = rk.DEFAULT_COULOMB_SMOOTHING

    def joint_terms(self) -> tuple[str, ...]:
        """The per-joint parameter kinds, in the order of their blocks of columns."""
        return tuple(n for n, on in (("armature", self.joints), ("damping", self.joints or self.friction),
                                     ("coulomb", self.friction)) if on)


def moving_bodies(model) -> list[int]:
    """Bodies with at least one joint between them and the world."""
    out = []
    for b in range(1, model.nbody):
        x = b
        while x > 0 and model.body_dofnum[x] == 0:
            x = int(model.body_parentid[x])
        if x > 0:
            out.append(b)
    return out


def param_layout(model, unknown, *, joints: bool, where: str, friction: bool = False,
                 coulomb_smoothing: float = rk.DEFAULT_COULOMB_SMOOTHING) -> ParamLayout:
    """unknown: "payload" (bodies named payload/... with mass), "all" (every moving body with mass;
    a massless body, such as the frame PyMJCF attaches a payload with, has no parameters to
    identify) or a list of body names. joints: armature and damping unknown; friction: damping and
    Coulomb friction unknown (Coulomb column tanh(q̇ / coulomb_smoothing))."""
    if not (np.isfinite(coulomb_smoothing) and coulomb_smoothing > 0):
        raise ModelError(f"{where}: the Coulomb smoothing must be finite and > 0, got {coulomb_smoothing!r}")
    moving = moving_bodies(model)
    if unknown == "all":
        bodies = [b for b in moving if model.body_mass[b] > 0]
    elif unknown == "payload":
        bodies = [b for b in moving if _name(model, mujoco.mjtObj.mjOBJ_BODY, b).startswith("payload/")
                  and model.body_mass[b] > 0]
        if not bodies:
            raise ModelError(f"{where}: plant.unknown = 'payload' but the model has no payload body; attach one "
                             "(plant.payload) or name the unknown bodies (plant.unknown = [\"link\", ...])")
    else:
        bodies = []
        for name in unknown:
            b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
            if b < 0:
                raise ModelError(f"{where}: plant.unknown names body {name!r}, which the model does not have "
                                 f"(moving bodies: {[_name(model, mujoco.mjtObj.mjOBJ_BODY, i) for i in moving]})")
            if b not in moving:
                raise ModelError(f"{where}: plant.unknown names body {name!r}, which no joint moves; its "
                                 "parameters do not enter the dynamics")
            bodies.append(b)
        bodies = sorted(set(bodies))
    names = [f"{_name(model, mujoco.mjtObj.mjOBJ_BODY, b)}.{p}" for b in bodies for p in rk.BODY_PARAM_NAMES]
    layout = ParamLayout(tuple(bodies), bool(joints), (), bool(friction), float(coulomb_smoothing))
    for jn in layout.joint_terms():
        names += [f"{_name(model, mujoco.mjtObj.mjOBJ_JOINT, model.dof_jntid[j])}.{jn}" for j in range(model.nv)]
    return dataclasses.replace(layout, names=tuple(names))


def standard_params(model, layout: ParamLayout) -> np.ndarray:
    """(n_standard,) true π from the compiled model: body_mass, body_ipos, body_inertia,
    body_iquat (and dof_armature, dof_damping, dof_frictionloss as the Coulomb amplitude)."""
    out = []
    R = np.empty(9)
    for b in layout.bodies:
        mujoco.mju_quat2Mat(R, model.body_iquat[b])
        out.append(rk.body_params(float(model.body_mass[b]), model.body_ipos[b], model.body_inertia[b],
                                  R.reshape(3, 3)))
    fields = {"armature": model.dof_armature, "damping": model.dof_damping, "coulomb": model.dof_frictionloss}
    out += [np.array(fields[jn], dtype=float) for jn in layout.joint_terms()]
    return np.concatenate(out) if out else np.zeros(0)


class Regressor:
    """Y(q, q̇, q̇_r, q̈_r) and τ_known on a live MjData (see regressor_kernel.regressor).

    Call as regressor(v, w, a) -> (Y (nv, n_params), tau_known (nv,)); the returned
    arrays are reused buffers. With a base-parameter map B (n_standard, n_base),
    Y_base = Y_standard B.
    """

    def __init__(self, model, data, layout: ParamLayout, base_map: np.ndarray | None = None):
        self.model, self.data, self.layout = model, data, layout
        nb, nv = model.nbody, model.nv
        self.body_col = np.full(nb, -1, dtype=np.int64)
        self.body_known = np.zeros(nb, dtype=np.int64)
        for b in moving_bodies(model):
            self.body_known[b] = 1
        for i, b in enumerate(layout.bodies):
            self.body_col[b] = 10 * i
            self.body_known[b] = 0
        n_body_cols = 10 * len(layout.bodies)
        cols = {jn: np.full(nv, -1, dtype=np.int64) for jn in ("armature", "damping", "coulomb")}
        for i, jn in enumerate(layout.joint_terms()):
            cols[jn] = np.arange(n_body_cols + i * nv, n_body_cols + (i + 1) * nv, dtype=np.int64)
        self.col_arm, self.col_damp, self.col_coul = cols["armature"], cols["damping"], cols["coulomb"]
        self.coulomb_eps = float(layout.coulomb_smoothing)
        self.n_standard = len(layout.names)
        self.base_map = base_map
        self.Y_std = np.zeros((nv, self.n_standard))
        self.tau_known = np.zeros(nv)
        self.parent = np.asarray(model.body_parentid, dtype=np.int64)
        self.dofadr = np.asarray(model.body_dofadr, dtype=np.int64)
        self.dofnum = np.asarray(model.body_dofnum, dtype=np.int64)
        self.rootid = np.asarray(model.body_rootid, dtype=np.int64)
        self._kernel = kernel()
        # the O(n) form (torque, rate): its work buffers
        self._scratch = np.zeros(rk.RNE_SCRATCH * nb)
        self._pi = np.zeros(max(self.n_standard, 1))
        self._rate_std = np.zeros(max(self.n_standard, 1))
        self._tau = np.zeros(nv)

    @property
    def base_map(self) -> np.ndarray | None:
        """B (n_standard, n_base) of the base parameters, or None (the law's parameters are the standard ones)."""
        return self._base_map

    @base_map.setter
    def base_map(self, B: np.ndarray | None) -> None:
        self._base_map = B
        n = len(self.layout.names)
        self.base_columns = base_map_columns(B, n, B.shape[1]) if B is not None else base_map_columns(None, n, n)

    def torque(self, v, w, a, theta) -> np.ndarray:
        """Y(q, v, w, a) θ + τ_known (nv,) in O(n), without forming Y (regressor_kernel.rne_law_torque; θ the law's
        parameters, base ones with a base map). A reused buffer; `rate` after it reads its forward pass."""
        m, d, bc = self.model, self.data, self.base_columns
        torque_kernel()(*self.static_args(), d.cdof, d.xpos, d.xmat, d.subtree_com, d.cinert, m.opt.gravity,
                        np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(w, dtype=float),
                        np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(theta, dtype=float),
                        int(self._base_map is not None), bc["bptr"], bc["bidx"], bc["bval"], self._pi, self._tau,
                        self._scratch)
        return self._tau

    def rate(self, v, a, s, out: np.ndarray) -> np.ndarray:
        """out (n_params,) = Y(q, v, w, a)ᵀ s in O(n) (regressor_kernel.rne_law_rate), right after `torque` at the
        same state and the same v, w, a."""
        d, bc = self.data, self.base_columns
        rate_kernel()(self.parent, self.dofadr, self.dofnum, self.rootid, self.body_col, self.col_arm, self.col_damp,
                      self.col_coul, self.coulomb_eps, d.cdof, d.xpos, d.xmat, d.subtree_com,
                      np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(a, dtype=float),
                      np.ascontiguousarray(s, dtype=float), int(self._base_map is not None), bc["bptr"], bc["bidx"],
                      bc["bval"], self._rate_std, out, self._scratch)
        return out

    def static_args(self):
        """The model arrays the kernel takes, in its order (also used by adaptive_mj.plants.one_dof_kernel)."""
        m = self.model
        return (self.parent, self.dofadr, self.dofnum, self.rootid, self.body_col, self.body_known,
                self.col_arm, self.col_damp, self.col_coul, m.dof_armature, m.dof_damping, self.coulomb_eps)

    def __call__(self, v, w, a):
        m, d = self.model, self.data
        self._kernel(*self.static_args(), d.cdof, d.xpos, d.xmat, d.subtree_com, d.cinert, m.opt.gravity,
                     np.ascontiguousarray(v, dtype=float), np.ascontiguousarray(w, dtype=float),
                     np.ascontiguousarray(a, dtype=float), self.Y_std, self.tau_known)
        if self.base_map is None:
            return self.Y_std, self.tau_known
        return self.Y_std @ self.base_map, self.tau_known


def base_map_columns(B, nstd: int, nth: int) -> dict:
    """The base map B (nstd, nth) by columns, its nonzero entries only (B is a column selection):
    {bptr, bidx, bval, need} as the compiled kernels read them (B None: the identity's need, no entries)."""
    if B is None:
        return {"need": np.ones(max(nstd, 1), dtype=np.int64), "bptr": np.zeros(1, dtype=np.int64),
                "bidx": np.zeros(1, dtype=np.int64), "bval": np.zeros(1)}
    B = np.asarray(B, dtype=float)
    if B.shape != (nstd, nth):
        raise ValueError(f"base map of shape {B.shape}, expected {(nstd, nth)}")
    rows_, vals, ptr = [], [], [0]
    for c in range(nth):
        nz = np.nonzero(B[:, c])[0]
        rows_ += nz.tolist()
        vals += B[nz, c].tolist()
        ptr.append(len(rows_))
    return {"bptr": np.asarray(ptr, dtype=np.int64), "bidx": np.asarray(rows_ or [0], dtype=np.int64),
            "bval": np.asarray(vals or [0.0], dtype=float), "need": np.any(B != 0, axis=1).astype(np.int64)}


_RNE: dict[str, Any] = {}


def torque_kernel():
    """regressor_kernel.rne_law_torque compiled with numba (once per process)."""
    if "torque" not in _RNE:
        import numba

        _RNE["torque"] = jit_tree(rk.rne_law_torque, numba.njit)
    return _RNE["torque"]


def rate_kernel():
    """regressor_kernel.rne_law_rate compiled with numba (once per process)."""
    if "rate" not in _RNE:
        import numba

        _RNE["rate"] = jit_tree(rk.rne_law_rate, numba.njit)
    return _RNE["rate"]


_KERNEL = None


def kernel():
    """regressor_kernel.regressor compiled with numba (once per process), or the Python source."""
    global _KERNEL
    if _KERNEL is None:
        try:
            import numba

            helpers = {name: numba.njit(getattr(rk, name)) for name in
                       ("cinert_of_params", "_inert_mul", "_cross_force_add", "_cross_motion_add")}
            helpers["_body_force"] = numba.njit(_with_globals(rk._body_force, **helpers))
            helpers["_project"] = numba.njit(rk._project)
            helpers["_project_col"] = numba.njit(rk._project_col)
            _KERNEL = numba.njit(_with_globals(rk.regressor, **helpers))
        except ImportError:  # pragma: no cover - numba is a dependency
            _KERNEL = rk.regressor
    return _KERNEL


def base_parameters(regressor: "Regressor", *, samples: int = 30, seed: int = 0, rtol: float = 1e-9):
    """A base (identifiable) parameter set, found numerically (Gautier's method).

    Y is sampled at `samples` random states (q, q̇, q̇_r, q̈_r ~ N(0, 1)); a QR
    decomposition with column pivoting picks independent columns Y_1 (the rest, Y_2,
    are dependent: Y_2 = Y_1 K exactly), so Y π = Y_1 (π_1 + K π_2).

    Returns (B, P, names): B (n_standard, n_base) selects Y_1 = Y B; P (n_base,
    n_standard) gives π_base = P π; names: each base parameter is named after its
    independent column, with "+" where dependent ones are regrouped into it.
    """
    import scipy.linalg

    model = regressor.model
    data = scratch_data(model)
    scratch = Regressor(model, data, regressor.layout)
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(samples):
        data.qpos[:] = rng.uniform(-np.pi, np.pi, model.nq)
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        Y, _ = scratch(rng.normal(size=model.nv), rng.normal(size=model.nv), rng.normal(size=model.nv))
        rows.append(Y.copy())
    W = np.vstack(rows)
    _, R, piv = scipy.linalg.qr(W, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > rtol * diag[0])) if diag.size and diag[0] > 0 else 0
    indep = np.sort(piv[:rank])
    dep = np.setdiff1d(np.arange(W.shape[1]), indep)
    K = np.linalg.lstsq(W[:, indep], W[:, dep], rcond=None)[0] if dep.size else np.zeros((rank, 0))
    K[np.abs(K) < 1e-10] = 0.0
    n_std = W.shape[1]
    B = np.zeros((n_std, rank))
    B[indep, np.arange(rank)] = 1.0
    P = np.zeros((rank, n_std))
    P[np.arange(rank), indep] = 1.0
    P[:, dep] = K
    std = regressor.layout.names
    names = tuple(std[c] + ("*" if np.any(K[i]) else "") for i, c in enumerate(indep))
    return B, P, names


def plant_dofs(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(qpos address, actuator id, gear) per dof, dof order."""
    qadr = np.array([model.jnt_qposadr[model.dof_jntid[j]] for j in range(model.nv)], dtype=np.int64)
    act = np.full(model.nv, -1, dtype=np.int64)
    for a in range(model.nu):
        act[model.jnt_dofadr[model.actuator_trnid[a, 0]]] = a
    gear = np.array([model.actuator_gear[a, 0] for a in act], dtype=float)
    return qadr, act, gear


class ManipulatorPlant(ModelClock, BodyEdits):
    """A MuJoCo arm of m = nv joints under joint torques (see the module docstring).

    model: compiled, checked by check_supported. unknown: "payload", "all" or body
    names; joint_params: armature and damping unknown too; friction_params: damping and
    Coulomb friction unknown too (Coulomb column tanh(q̇ / coulomb_smoothing), ε in rad/s
    or m/s); base: reduce π to a base set. The loop's interface with a joint axis (a JointPlant and a NativePlant,
    adaptive_mj.plants.protocol): the state is x (2, m) = [q; q̇] [rad or m; per s], the
    input τ (m,) [N m or N].
    """

    order = 2
    compiled_loop: str | None = "adaptive_mj.sim.native_mujoco"  # protocol.Plant.compiled_loop
    mujoco_kernel: ClassVar[MujocoKernel] = manipulator_kernel.KERNEL  # its kernel spec (plants/manipulator_kernel.py)
    native_owner: object | None = None  # the native controller whose context data points at

    def __init__(self, model: mujoco.MjModel, *, unknown="payload", joint_params: bool = False,
                 base: bool = False, where: str = "manipulator model", notes: tuple[str, ...] = (),
                 friction_params: bool = False, coulomb_smoothing: float = rk.DEFAULT_COULOMB_SMOOTHING):
        check_supported(model, where)
        self.model = model
        self.data = mujoco.MjData(model)
        self.where = where
        self.notes = tuple(notes)
        self.m = int(model.nv)
        self.joint_shape = (self.m,)
        self.joint_names = tuple(_name(model, mujoco.mjtObj.mjOBJ_JOINT, model.dof_jntid[j]) for j in range(self.m))
        self._qadr, self._act, self._gear = plant_dofs(model)
        self.layout = param_layout(model, unknown, joints=joint_params, where=where, friction=friction_params,
                                   coulomb_smoothing=coulomb_smoothing)
        self.regressor = Regressor(model, self.data, self.layout)
        self.base_map: np.ndarray | None = None
        self.base_projection: np.ndarray | None = None
        self.names = self.layout.names
        if base:
            B, P, names = base_parameters(self.regressor)
            self.regressor.base_map, self.base_map, self.base_projection, self.names = B, B, P, names
        lo = np.full(self.m, -np.inf)
        hi = np.full(self.m, np.inf)
        for j, a in enumerate(self._act):
            if model.actuator_ctrllimited[a]:
                c0, c1 = model.actuator_ctrlrange[a] * self._gear[j]
                lo[j], hi[j] = min(c0, c1), max(c0, c1)
        self.ctrl_range = (lo, hi) if np.isfinite(lo).any() or np.isfinite(hi).any() else None
        self._theta: np.ndarray | None = None
        self.force_offset = 0.0
        self.disturbance: Callable[[float], float] | None = None  # unused: an arm's are per joint
        self.joint_disturbance: JointDisturbance | None = None  # t -> τ_d (m,), held over a step
        self.loads: dict[str, float] = {}  # unmodelled loads: body name -> mass [kg], its weight at the CoM
        self.first_contact: tuple[float, str] | None = None  # (t, text) of the first contact seen, see step()
        self._warning_total0 = int(self.data.warning.number.sum())
        self._warnings0 = self.data.warning.number.copy()
        self._full_index: np.ndarray | None = None  # full_mass's map from mjData.M to the dense M

    # --- state -------------------------------------------------------------
    def set_state(self, x0) -> None:
        """x0: (2, m) [q; q̇] initial joint positions [rad or m] and velocities."""
        x0 = np.asarray(x0, dtype=float).reshape(2, self.m)
        mujoco.mj_resetData(self.model, self.data)
        self._warnings0 = self.data.warning.number.copy()
        self._warning_total0 = int(self._warnings0.sum())
        self.data.qpos[self._qadr] = x0[0]
        self.data.qvel[:] = x0[1]
        self.first_contact = None
        self.apply_loads()

    def apply_loads(self) -> None:
        """Each unmodelled load's weight m g [N] on its body's centre of mass (MuJoCo's xfrc_applied,
        world frame): a point mass the regressor does not know (its inertia left out)."""
        self.data.xfrc_applied[:] = 0.0
        for name, mass in self.loads.items():
            self.data.xfrc_applied[self.body_id(name), :3] = mass * self.model.opt.gravity

    def measure(self, d, x: np.ndarray) -> None:
        x[0] = d.qpos[self._qadr]
        x[1] = d.qvel

    def observe(self) -> np.ndarray:
        x = np.empty((2, self.m))
        self.measure(self.data, x)
        return x

    def update_kinematics(self) -> None:
        """Bring the position-dependent quantities the regressor reads (xpos, xmat, cdof,
        subtree_com, cinert) to the current q, for a law evaluated outside the control
        callback (dm_env's law_policy). Physics is unchanged: mj_step recomputes them."""
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_comPos(self.model, self.data)

    def true_theta(self) -> np.ndarray:
        """(n_params,) true π (standard, or base = P π) from the compiled model, re-read after events."""
        if self._theta is None:
            pi = standard_params(self.model, self.layout)
            self._theta = pi if self.base_projection is None else self.base_projection @ pi
        return self._theta

    def model_changed(self) -> None:
        self._theta = None

    @property
    def joint_limits(self) -> np.ndarray:
        """(m, 2) [lo, hi] of each joint's range [rad or m]; ±inf where the joint is not limited."""
        out = np.tile([-np.inf, np.inf], (self.m, 1))
        for j in range(self.m):
            jid = self.model.dof_jntid[j]
            if self.model.jnt_limited[jid]:
                out[j] = self.model.jnt_range[jid]
        return out

    def full_mass(self, sparse: np.ndarray) -> np.ndarray:
        """(N, m, m) dense M from rows (N, nM) of MuJoCo's sparse mjData.M, as mj_fullM writes it (each entry
        copied to its place and its mirror, zeros elsewhere: the same numbers)."""
        if self._full_index is None:
            d = scratch_data(self.model)
            d.M[:] = np.arange(1.0, self.model.nM + 1.0)  # mj_fullM of the entries' own numbers: where each goes
            where = np.zeros((self.m, self.m))
            mujoco.mj_fullM(self.model, d, where)
            self._full_index = where.astype(np.int64) - 1
        index = self._full_index
        out = np.take(sparse, np.maximum(index, 0).ravel(), axis=1).reshape(len(sparse), self.m, self.m)
        out[:, index < 0] = 0.0
        return out

    def mass_matrices(self, q: np.ndarray) -> np.ndarray:
        """(N, m, m) joint-space inertia M(q) (armature included) at rows q (N, m)."""
        d = scratch_data(self.model)
        out = np.empty((len(q), self.m, self.m))
        for i, qi in enumerate(q):
            d.qpos[self._qadr] = qi
            mujoco.mj_kinematics(self.model, d)
            mujoco.mj_comPos(self.model, d)
            mujoco.mj_crb(self.model, d)
            mujoco.mj_fullM(self.model, d, out[i])
        return out

    def holding_controls(self, q: np.ndarray) -> np.ndarray:
        """(N, m) the joint torques [N·m, N on a slide] that hold the arm still at rows q (N, m): MuJoCo's
        qfrc_bias - qfrc_passive at zero velocity (gravity, less springs and gravity compensation), in the
        units of ctrl_range (the pre-flight's gravity check)."""
        d = scratch_data(self.model)
        out = np.empty((len(q), self.m))
        for i, qi in enumerate(q):
            d.qpos[self._qadr] = qi
            d.qvel[:] = 0.0
            mujoco.mj_fwdPosition(self.model, d)
            mujoco.mj_fwdVelocity(self.model, d)
            out[i] = d.qfrc_bias - d.qfrc_passive
        return out

    def regressor_rows(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """(N, m, n_theta) the regressor Y(q, q̇, q̇, q̈) of the law's parameters (base ones with a base map) at rows
        (q, q̇, q̈) (N, m): what the motion excites (report.identification, along the reference); a scratch
        MjData, the run's untouched."""
        d = scratch_data(self.model)
        reg = Regressor(self.model, d, self.layout, self.base_map)
        out = np.empty((len(q), self.m, len(self.names)))
        for i in range(len(q)):
            d.qpos[self._qadr], d.qvel[:] = q[i], qd[i]
            mujoco.mj_fwdPosition(self.model, d)
            out[i] = reg(qd[i], qd[i], qdd[i])[0]
        return out

    def following_controls(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """(N, m) the joint torques [N·m, N on a slide] that make the arm follow rows (q, q̇, q̈) (N, m) exactly:
        MuJoCo's inverse dynamics (mj_inverse's qfrc_inverse: M q̈ + bias − passive), in the units of ctrl_range
        (the pre-flight's check that the reference asks what the motors can give)."""
        d = scratch_data(self.model)
        out = np.empty((len(q), self.m))
        for i in range(len(q)):
            d.qpos[self._qadr], d.qvel[:], d.qacc[:] = q[i], qd[i], qdd[i]  # m = nv joints, in dof order
            mujoco.mj_inverse(self.model, d)
            out[i] = d.qfrc_inverse
        return out

    # --- stepping ----------------------------------------------------------
    @contextlib.contextmanager
    def controlled_by(self, policy: Policy) -> Iterator[None]:
        """Run policy(t, x) -> τ (m,) inside MuJoCo's control callback (each RK4 stage too)."""
        act, gear, measure = self._act, self._gear, self.measure
        x = np.empty((2, self.m))

        def callback(m, d):
            measure(d, x)
            d.ctrl[act] = policy(d.time, x) / gear

        with control_callback(callback):
            yield

    @contextlib.contextmanager
    def controlled_natively(self, cfunc) -> Iterator[None]:
        with compiled_control(cfunc):
            yield

    def step_native(self, nstep: int) -> None:
        mujoco.mj_step(self.model, self.data, nstep=nstep)
        self._note_contact()

    def native_prestep(self) -> None:
        pass

    def native_poststep(self) -> None:
        self._note_contact()

    def step(self) -> None:
        if self.joint_disturbance is not None:  # held over the step (the native callback writes it per stage)
            self.data.qfrc_applied[:] = self.joint_disturbance(self.data.time)
        mujoco.mj_step(self.model, self.data)
        self._note_contact()

    def _note_contact(self) -> None:
        if self.first_contact is None and self.data.ncon > 0:
            c = self.data.contact[0]
            g1 = _name(self.model, mujoco.mjtObj.mjOBJ_GEOM, c.geom1)
            g2 = _name(self.model, mujoco.mjtObj.mjOBJ_GEOM, c.geom2)
            self.first_contact = (self.time, f"contact between geoms {g1!r} and {g2!r}")

    def instability(self) -> str | None:
        """A MuJoCo warning raised since the state was set, as text, or None."""
        return new_warnings(self.data, self._warning_total0, self._warnings0)

    def unmodelled_drag(self) -> float | None:
        """None: no drag the regressor leaves out is known (plants.protocol)."""
        return None

    def release(self) -> None:
        """Nothing handed back: its MjData is its own (no spare pool of its layout)."""
        return None

    # --- events ------------------------------------------------------------


# --- built from a scenario ------------------------------------------------------
def model_source(scn) -> ModelSource | None:
    """plant.model with plant.payload attached at plant.site (as for the 1-DOF arm). A model with no such site is
    refused with every other reason the plant would refuse it for in the same line (refusals of the bare arm,
    after plant.fixed_joints and plant.servo_to_torque), not one reason per attempt."""
    from adaptive_mj.plants import arm

    try:
        return arm.model_source(scn)
    except ModelError as exc:
        p = scn.plant
        where = str(p.model)
        text = str(exc)
        if p.payload is None or not text.startswith(f"{where}: "):
            raise
        others = _bare_refusals(scn)
        if not others:
            raise
        raise ModelError(refusal_text(where, [text[len(where) + 2:], *others])) from None


def _bare_refusals(scn) -> list[str]:
    """refusals of plant.model without its payload, after the scenario's model edits ([] where it cannot be
    compiled: the payload's error is said alone)."""
    from adaptive_mj.plants.arm import build_arm_xml

    p = scn.plant
    try:
        xml, assets = build_arm_xml(arm=p.model, payload=None, payload_mass=None, site=p.site)
        spec = mujoco.MjSpec.from_string(xml, assets=dict(assets))
        fix_joints(spec, p.manipulator.fixed_joints)
        if p.manipulator.servo_to_torque:
            servo_to_torque(spec, p.manipulator.forcerange)
        return refusals(spec.compile())
    except (ModelError, ValueError):
        return []


def from_scenario(scn, source: ModelSource | None) -> BuiltPlant:
    """plant.kind = "manipulator": the arm of plant.model, its unknown bodies, joint
    parameters and base set as the scenario says; with plant.servo_to_torque its
    position servos rebuilt as torque motors first (reported in the notes); then
    plant.damping, .frictionloss and .actuator_lag set on the joints and motors."""
    from adaptive_mj.errors import ScenarioError

    p = scn.plant
    fr = p.manipulator.friction
    exact = scn.simulation.integrator != "rk4"

    def edit(spec) -> tuple[list[str], list[str]]:
        """(notes, refusals) of the edit; returned, not only said, so that a compile the cache answers
        (compile_spec_with) gives them as well."""
        notes: list[str] = []
        try:  # first: the fixed joints' actuators are no servos to rebuild
            notes.extend(fix_joints(spec, p.manipulator.fixed_joints))
        except ModelError as exc:
            return notes, [f"{scn.source}: {exc}"]
        if p.manipulator.servo_to_torque:
            try:
                notes.extend(servo_to_torque(spec, p.manipulator.forcerange))
            except ModelError as exc:
                raise ScenarioError(f"{scn.source}: {exc}") from None
        try:  # joint friction and actuator lag (after servo_to_torque: a lag goes on the rebuilt motor)
            set_joint_friction(spec, damping=fr.damping, frictionloss=fr.frictionloss)
            set_actuator_lag(spec, fr.actuator_lag, exact=exact)
            set_torque_limit(spec, fr.torque_limit)
        except ModelError as exc:  # said after compiling, as a scenario error (not as MuJoCo's)
            return notes, [f"{scn.source}: {exc}"]
        return notes, []

    # what the edit does is fixed by these values (repr: some are dicts {joint: number})
    key = ("manipulator", repr((p.manipulator.fixed_joints, p.manipulator.servo_to_torque, p.manipulator.forcerange,
                                fr.damping,
                                fr.frictionloss, fr.actuator_lag, fr.torque_limit, exact)), scn.source)
    model, model_xml, (notes, bad_keys) = compile_for_scenario_with(scn, source, edit=edit, edit_key=key)
    if bad_keys:
        raise ScenarioError(bad_keys[0])
    plant = ManipulatorPlant(model, unknown=p.manipulator.unknown, joint_params=p.manipulator.joint_params,
                             base=p.manipulator.base_parameters, where=str(p.model), notes=tuple(notes),
                             friction_params=fr.friction_params, coulomb_smoothing=fr.coulomb_smoothing)
    return BuiltPlant(plant, model_xml, tuple(notes))


# --- its scenario keys -----------------------------------------------------------
_PER_JOINT = "number, or table {joint = number}"
OWN_KEYS = (
    Key("unknown", "'payload', 'all' or array of body names", doc="whose parameters the law estimates "
        "(default: 'payload' with a payload, else 'all')"),
    Key("joint_params", "boolean", default=False, doc="also estimate each joint's armature and damping"),
    Key("base_parameters", "boolean", default=False, doc="reduce the parameters to a base (identifiable) set"),
    Key("servo_to_torque", "boolean", default=False, doc="rebuild position servos as torque motors"),
    Key("fixed_joints", "array of joint names", default=(), doc="joints welded at their reference position, with "
        "the tendons, equalities and actuators that use them (a gripper's fingers)"),
    Key("forcerange", "number, or table {joint or actuator = number}", "N m", None, "> 0",
        "with servo_to_torque: the rebuilt servos' torque limit"),
    Key("damping", _PER_JOINT, "N m s/rad", None, ">= 0", "viscous joint damping (default: the model's)"),
    Key("frictionloss", _PER_JOINT, "N m", None, ">= 0", "dry joint friction (default: the model's)"),
    Key("actuator_lag", _PER_JOINT, "s", None, ">= 0", "a first-order lag T on the joint's motor"),
    Key("torque_limit", _PER_JOINT, "N m", None, "> 0", "|τ| <= L on the joint's motor (default: the model's)"),
    Key("friction_params", "boolean", default=False, doc="also estimate each joint's damping and Coulomb friction"),
    Key("coulomb_smoothing", "number", "rad/s", 0.01, "> 0", "with friction_params: ε of the column tanh(q'/ε)"))
FRICTION_KEYS = ("damping", "frictionloss", "actuator_lag", "torque_limit", "friction_params", "coulomb_smoothing")


def _own_keys(t: Table, fields: dict) -> dict:
    """A manipulator's own plant.* keys (after the payload keys): MuJoCo only, which parameters are unknown,
    model edits, joint friction."""
    if fields["backend"] != "mujoco":
        raise t.fail("backend", "'mujoco' for plant.kind = 'manipulator' (its truth is the MuJoCo model)",
                     fields["backend"])
    if fields["payload_mass"] is not None and fields["payload"] is None:
        raise t.fail("payload_mass", "absent when plant.payload is 'none'", fields["payload_mass"])
    return {"manipulator": joint_friction(t, manipulator_keys(t, fields["payload"]))}


def manipulator_keys(t: Table, payload: str | None) -> ManipulatorSpec:
    """plant.unknown, .joint_params, .base_parameters, .servo_to_torque and .forcerange."""
    raw = t.get("unknown", "payload" if payload is not None else "all")
    if isinstance(raw, list):
        if not raw or not all(isinstance(v, str) and v for v in raw):
            raise t.fail("unknown", "'payload', 'all' or a non-empty array of body names", raw)
        unknown: str | tuple[str, ...] = tuple(raw)
    else:
        unknown = t.string("unknown", "payload" if payload is not None else "all", choices=("payload", "all"))
        if unknown == "payload" and payload is None:
            raise t.fail("unknown", "'all' or an array of body names when there is no payload (plant.payload "
                                    "is 'none')", unknown)
    servo = t.boolean("servo_to_torque", False)
    fixed = t.get("fixed_joints", [])
    if not isinstance(fixed, list) or not all(isinstance(v, str) and v for v in fixed):
        raise t.fail("fixed_joints", "an array of joint names", fixed)
    return ManipulatorSpec(unknown=unknown, joint_params=t.boolean("joint_params", False),
                           base_parameters=t.boolean("base_parameters", False),
                           servo_to_torque=servo, forcerange=forcerange(t, servo), fixed_joints=tuple(fixed))


def forcerange(t: Table, servo_to_torque: bool) -> float | dict[str, float] | None:
    """plant.forcerange: |tau| limit [N m or N] for servos without a forcerange, one number for every
    joint or a table {joint or actuator name = number} (names are checked against the model in build)."""
    raw = t.get("forcerange", None)
    if raw is None:
        return None
    if not servo_to_torque:
        raise t.fail("forcerange", "absent unless plant.servo_to_torque = true (it limits the rebuilt servos)",
                     raw)
    if isinstance(raw, dict):
        if not raw:
            raise t.fail("forcerange", "a number > 0 or a non-empty table {joint = number > 0}", raw)
        return t.named_numbers("forcerange", gt=0)
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise t.fail("forcerange", "a number > 0 or a table {joint = number > 0}", raw)
    return t.number("forcerange", gt=0)


def _per_joint(t: Table, key: str, bound: str) -> float | dict[str, float]:
    """plant.<key>: a number for every joint or {joint = number}, each >= 0 (bound ">= 0") or > 0."""
    v = plant_keys.joint_values(t, key)
    for j, x in (v.items() if isinstance(v, dict) else [("", v)]):
        if not (x >= 0 if bound == ">= 0" else x > 0):
            raise t.fail(key + (f".{j}" if j else ""), bound if bound == ">= 0" else "> 0 [N m]", x)
    return v


def joint_friction(t: Table, spec: ManipulatorSpec) -> ManipulatorSpec:
    """plant.damping, .frictionloss, .actuator_lag, .torque_limit, .friction_params, .coulomb_smoothing into
    spec.friction (joint names are checked against the model in build)."""
    values: dict[str, Any] = {key: _per_joint(t, key, ">= 0") for key in ("damping", "frictionloss", "actuator_lag")
                              if key in t.data}
    if "torque_limit" in t.data:
        values["torque_limit"] = _per_joint(t, "torque_limit", "> 0")
    friction_params = t.boolean("friction_params", False)
    eps = t.number("coulomb_smoothing", 0.01, gt=0)
    if "coulomb_smoothing" in t.data and not friction_params:
        raise t.fail("coulomb_smoothing", "absent unless plant.friction_params = true (it shapes the Coulomb "
                                          "column)", eps)
    return dataclasses.replace(spec, friction=JointFrictionSpec(**values, friction_params=friction_params,
                                                                 coulomb_smoothing=eps))


def study_laws(ctx: StudyContext, composite: bool) -> list[tuple[str, list[str]]]:
    """The 6-joint arm's laws in the breaking-point study (kinds.StressPlant.laws; no composite row): Slotine–Li
    with each modification (the dead-zone sized from the nominal noise, σ- and e-modification leaking toward the
    true θ in study_spec.LEAK_TIME on the first parameter, the nonnegative box, saturation-aware adaptation), and
    its two baselines with the true parameters (computed torque, PD + gravity)."""
    gamma1 = float(ctx.gamma[0])
    assert ctx.lam is not None  # the row's scenario sets law.lam (Λ of ‖s‖'s noise)
    sig_s = surface_noise(6, float(ctx.lam), ctx.nominal_noise)  # noise in ‖s‖ (6 joints)
    theta0 = theta_table(ctx.law_names, ctx.theta, quoted=True)
    return [("adaptive", []),
            ("dead_zone", ["law.dead_zone={width_in_noise_std=3.0}"]),
            ("sigma", [f"law.sigma={gamma1 / LEAK_TIME!r}", f"law.theta0={theta0}"]),
            ("e_modification", [f"law.e_modification={gamma1 / (LEAK_TIME * sig_s)!r}", f"law.theta0={theta0}"]),
            ("projection", ["law.projection='physical'"]),
            ("saturation_freeze", ["law.saturation='freeze'"]),
            ("computed_torque", ["law.kind='computed_torque'", "law.nominal='model'"]),
            ("pd_gravity", ["law.kind='pd_gravity'", "law.nominal='model'"])]


def study_stressors(ctx: StudyContext, duration: float) -> list[Stressor]:
    """The 6-joint arm's stressors in the breaking-point study (kinds.StressPlant.stressors): noise σ_q [rad] (σ_q'
    = 10 σ_q per second), encoder resolution Δ [rad] (counts = 2π/Δ), a differentiated velocity's filter time
    constant τ = 1/(2π f_c) [s], the sinusoidal torque on every joint, actuator lag [s], the motors' torque limits
    (from the compiled model) divided by a factor, and the payload's mass (θ's first, from the compiled model) ×
    ratio at half the run."""
    sig = ctx.nominal_noise
    plant = ctx.plant
    limits = dict(zip(plant.joint_names, np.asarray(plant.ctrl_range[1], dtype=float).tolist(), strict=True))

    def torque_limit(v: float) -> list[str]:  # the model's limits divided by v
        return ["plant.torque_limit={" + ", ".join(f"{j}={L / v!r}" for j, L in limits.items()) + "}"]

    return [Stressor("noise σ_y", lambda v: [f"noise.std={{q={v!r}, q_dot={10 * v!r}}}"], 1e-5, 0.1, unit="rad"),
            Stressor("encoder Δ", lambda v: [f"sensors={{encoder_counts={2 * math.pi / v!r}}}"], 1e-5, 0.5,
                     unit="rad"),
            Stressor("velocity filter τ",
                     lambda v: [f"noise.std={{q={sig!r}}}",
                                f"sensors={{velocity='differentiated', velocity_cutoff_hz={1 / (2 * math.pi * v)!r}}}"],
                     1e-3, 0.5, unit="s"),  # from f_c = 159 Hz: a shorter τ passes more encoder noise (the
            # stress is not monotone there: 0.1 ms failed for the plain law where 7 ms passed), a longer more lag
            sine_disturbance(ctx),
            # from one physics step: a lag much shorter than the step is stiff for an explicit integrator (RK4:
            # h/τ < 2.785), a failure of the numerics, not of the loop
            Stressor("lag τ", lambda v: [f"plant.actuator_lag={v!r}"], 1e-3, 1.0, unit="s"),
            Stressor("torque limit ÷", torque_limit, 1.0, 100.0, unit="÷"),
            payload_ratio(float(ctx.theta[0]), duration)]


#: this plant kind, registered (adaptive_mj.plants.kinds): plant.kind = "manipulator"
KIND = register(PlantKind(
    "manipulator", __name__, frozenset({Form.RIGID_BODY}), output_unit="rad", control_unit="N m",
    params={},
    default_model="ur5e_arm", doc="any MJCF arm of hinge/slide joints under Slotine-Li", param_unit=body_param_unit,
    default_law="slotine_li",
    tail_bound=0.01, nominal_noise=1e-4,
    keys=plant_keys.keys(*OWN_KEYS, payload=True),
    reader=plant_keys.SharedReader(body=_own_keys),
    events={ev.PAYLOAD_MASS: "mujoco", ev.PAYLOAD_SWAP: "mujoco"}, starts_on_reference=True,
    group_params_by_unit=True, stress=StressPlant(
        "ur5e", "ur5e_identification", noise_signals=("q", "q_dot"), disturbance=(0.1, 1000.0),
        laws=study_laws, stressors=study_stressors, hold=hold_joints,
        label="the 6-joint arm: the RMS over its joints and the tail's rows, ‖q̃‖'s RMS / √6",
        tasks=(ScoreTask("tracking", "ur5e_identification", (),
                         draws=(Draw("reference.amplitudes", 0.75, 1.25), Draw("reference.omegas", 0.75, 1.25))),
               ScoreTask("change", "ur5e_payload_swap",
                         ("law.initial_estimates='model'",
                          "events=[{{t={half}, kind='payload_swap', payload='sphere'}}]"),
                         extras=("change_response",)),
               ScoreTask("hold", "ur5e_drift", (), noise_scale=0.0, extras=("estimate_drift",)))),
    sections=("manipulator",)))

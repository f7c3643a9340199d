"""Scenario files (scenarios/*.toml) loaded into frozen dataclasses.

Validation is strict and happens once, before any simulation: unknown keys,
wrong types, non-finite numbers and out-of-range values are rejected with a
ScenarioError whose message names the file, the key, what was expected and
what came, e.g.  ``scenarios/x.toml: law.gamma must be > 0, got -1``.
The full key reference is docs/SCENARIOS.md.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from adaptive_mj.data import MODELS as MODELS_DIR, SCENARIOS as SCENARIOS_DIR
from adaptive_mj.errors import ScenarioError
from adaptive_mj.keys import _MISSING, Table as _Table, _Missing, _show, _suggest  # noqa: F401 (re-exported)
from adaptive_mj.keys import joint_values as _joint_values
from adaptive_mj.laws import kinds as law_kinds
from adaptive_mj.laws.law_keys import (DEAD_ZONE_ON, read_dead_zone as _dead_zone,  # noqa: F401 (re-exported)
                                       read_estimates as _estimate_table, read_gamma as _gamma,
                                       read_robust as _robust)
from adaptive_mj.specs import (ControlSpec, DeadZoneSpec, DisturbanceSpec, EventSpec, JointFrictionSpec,  # noqa: F401
                               LawSpec, LinearSpec, ManipulatorSpec, MracSpec, NoiseSpec, PlantSpec, ReferenceSpec,
                               RobustSpec, Scenario, SensorSpec, SimulationSpec, SuccessSpec, WingRockSpec,
                               PREFLIGHT_ACTIONS)

if TYPE_CHECKING:
    from adaptive_mj.laws.plugin import LawPlugin
    from adaptive_mj.plants.kinds import PlantKind
    from adaptive_mj.plants.plugin import PlantPlugin
    from adaptive_mj.plugins import Installed

SCHEMA_VERSION = 1

ANALYTIC_PLANT_KINDS = ("linear", "wing_rock")  # analytic plants (adaptive_mj.plants.linear, .wing_rock)


def _plant_kinds() -> dict[str, PlantKind]:
    """The built-in plant kinds, as their modules register them (adaptive_mj.plants.kinds)."""
    from adaptive_mj.plants.kinds import built_in

    return built_in()


PLANT_KINDS = tuple(_plant_kinds())  # the built-in plant.kind values, from the registry
BACKENDS = ("mujoco", "twin")
INTEGRATORS = ("rk4", "euler", "implicitfast", "implicit")
REFERENCE_KINDS = ("constant", "cosine", "sine", "sum_of_sines", "smooth_step", "waypoints", "reference_model")
JOINT_REFERENCE_KINDS = ("joint_sum_of_sines", "joint_waypoints")

def _law_kinds(form: str) -> tuple[str, ...]:
    return tuple(k.name for k in law_kinds.built_in().values() if law_kinds.Form(form) in k.forms)


LAW_KINDS = _law_kinds("model") + _law_kinds("mrac_state")  # the built-in law kinds of 1-DOF plants, from the registry
MANIPULATOR_LAW_KINDS = _law_kinds("rigid_body")  # those of multi-joint plants
DISTURBANCE_KINDS = ("none", "constant", "step", "sine")
ARM_DISTURBANCE_KINDS = DISTURBANCE_KINDS + ("noise",)  # per joint torques (adaptive_mj.disturbance)
EVENT_KINDS = ("payload_mass", "payload_swap", "fluid_density_scale", "constant_force", "loading", "thrust_scale",
               "flight_condition")
DEFAULT_MODEL = {k.name: k.default_model for k in _plant_kinds().values() if k.default_model is not None}
STATE_SIGNALS = ("y", "y_dot", "y_ddot")
JOINT_SIGNALS = ("q", "q_dot")  # an arm's measured signals (noise.std)
REGRESSORS = ("lecture", "sin_squared")
FIRST_ORDER_PARAMS = {"lecture": ("a", "b"), "sin_squared": ("p",)}



# --------------------------------------------------------------------------
def load(path: str | Path, *, overrides: list[str] | tuple[str, ...] = (), seed: int | None = None,
         keep: bool = False) -> Scenario:
    """Read, override (``key=value`` dotted paths) and validate a scenario file (keep: see `loads`)."""
    path = Path(path)
    where = str(path)
    if not path.is_file():
        raise ScenarioError(f"{where}: scenario file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{where}: cannot read the scenario file: {exc}") from None
    return loads(text, where=where, base_dir=path.parent, default_name=path.stem,
                 overrides=overrides, seed=seed, keep=keep)


def loads(text: str, *, where: str = "<string>", base_dir: Path | None = None, default_name: str = "scenario",
          overrides: list[str] | tuple[str, ...] = (), seed: int | None = None, keep: bool = False) -> Scenario:
    """Validate scenario TOML text (see `load`).

    keep: for a study's runs (adaptive_mj.study.job), which load the same text with the same overrides
    thousands of times, each with its own seed. The scenario validated without the seed is kept (per
    text, overrides, where, base_dir and current directory; `_validated`) and the seed is set on a copy,
    which is what validating with it gives (noise.seed is the only field it sets). Validation looks at
    files (which candidate payload or model path exists) and at the installed plugins: a kept scenario
    does not see those change during the study, as a payload file is checked once per process too.
    Anything unusual (a validation error, a seed that is not a plain int >= 0, no current directory)
    takes the full path, so every error reads as before."""
    overrides = tuple(overrides)
    if keep and (seed is None or (type(seed) is int and seed >= 0)):
        try:
            base = _validated(text, where, None if base_dir is None else str(base_dir), default_name, overrides,
                              str(Path.cwd()))
        except (ScenarioError, OSError, TypeError):
            pass
        else:
            return base if seed is None else dataclasses.replace(base, noise=dataclasses.replace(base.noise, seed=seed))
    return _loads(text, where=where, base_dir=base_dir, default_name=default_name, overrides=overrides, seed=seed)


@functools.lru_cache(maxsize=256)
def _validated(text: str, where: str, base_dir: str | None, default_name: str, overrides: tuple[str, ...],
               cwd: str) -> Scenario:
    """loads without a seed, kept for the next run of a study (see loads). cwd is part of the key: a
    relative path in an override is resolved against it. Scenario is frozen, and nothing changes one."""
    return _loads(text, where=where, base_dir=None if base_dir is None else Path(base_dir),
                  default_name=default_name, overrides=overrides, seed=None)


def _loads(text: str, *, where: str, base_dir: Path | None, default_name: str, overrides: tuple[str, ...],
           seed: int | None) -> Scenario:
    """Parse, override and validate (loads, without the cache)."""
    try:
        doc = copy.deepcopy(_parsed(text))
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where}: TOML syntax error: {exc}") from None
    for expr in sorted(overrides, key=lambda e: not is_law_swap(e)):  # a swap first: the law.* keys go into it
        apply_override(doc, expr, where=where)
    if any(e.strip().startswith("law.") for e in overrides):
        _scoped_law_keys(doc)
    _model_from_command_line(doc, overrides, base_dir, where)
    if seed is not None:
        doc.setdefault("noise", {})
        if not isinstance(doc["noise"], dict):
            raise ScenarioError(f"{where}: noise must be a table, got {_show(doc['noise'])}")
        doc["noise"]["seed"] = seed
    return _validate(doc, where=where, base_dir=base_dir or Path.cwd(), default_name=default_name,
                     text=text, overrides=tuple(overrides))


_KEY_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
# A scenario name goes into log file and folder names: one path component, not hidden.
_NAME_RE = re.compile(r"[^./\\\x00-\x1f\x7f][^/\\\x00-\x1f\x7f]{0,99}")


@functools.lru_cache(maxsize=64)
def _parsed(text: str) -> dict[str, Any]:
    """TOML text parsed, kept for the next run of a study (the same file and --set values, thousands of
    times): callers take a deep copy, since overrides edit the document."""
    return tomllib.loads(text)


def parse_value(raw: str, *, what: str) -> Any:
    """A TOML value (number, bool, string, array, inline table); a bare word is a string."""
    try:
        return copy.deepcopy(_parsed(f"v = {raw}")["v"])
    except tomllib.TOMLDecodeError:
        if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_./-]*", raw):
            return raw
        raise ScenarioError(f"{what}: value {raw!r} is not a TOML value "
                            "(expected a number, true/false, a string, an array or an inline table)") from None


#: the [law] keys a law swap keeps: what the scenario knows of θ at the start and the order of the dynamics the
#: law sees (the plant's, not the law's)
SWAP_KEEPS = ("initial_estimates", "nominal", "order")


def law_swap(kind: str) -> str:
    """The override that swaps a scenario's law for `kind` (`run --law`, `sweep --grid law.kind=a,b`): the
    whole [law] table replaced by {kind} (the law's own defaults), keeping SWAP_KEEPS, plus the law.* keys
    given with --set (applied after it whatever their order; `law.<kind>.<key>` only when that law runs:
    _scoped_law_keys). A swap to the law the scenario already names keeps its table. The log records it with
    the other overrides."""
    return f"law={kind}"


def is_law_swap(expr: str) -> bool:
    """Whether an override is a law swap (`law=NAME`, not `law={...}` or `law.key=...`)."""
    key, _, raw = expr.partition("=")
    return key.strip() == "law" and bool(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.-]*", raw.strip().strip("'\"")))


def _scoped_law_keys(doc: dict) -> None:
    """`--set law.<kind>.<key>=v` (a sub-table of [law] named after a law kind): the keys of the law that runs,
    merged into [law]; another law's scoped keys dropped. So one sweep over law.kind can give each law its own
    gains (`--grid law.kind=sliding_adaptive,emod --set law.emod.gamma_d=0.0025`)."""
    law = doc.get("law")
    if not isinstance(law, dict):
        return
    tables = law_kinds.table_keys()  # [law] keys a law kind declares may be a table: never a law's scoped keys
    candidates = [k for k, v in law.items() if isinstance(v, dict) and k not in tables]
    if not candidates:
        return
    names = set(law_kinds.built_in())
    if any(k not in names for k in candidates):
        from adaptive_mj.laws.plugin import installed

        names |= set(installed())
    running = law.get("kind")
    for k in candidates:
        if k in names:
            scoped = law.pop(k)
            if k == running:
                law.update(scoped)


def apply_override(doc: dict, expr: str, *, where: str) -> None:
    """Apply ``section.key=value`` to the parsed document (before validation); ``law=NAME`` swaps the law
    (law_swap)."""
    what = f"--set {expr!r}"
    if "=" not in expr:
        raise ScenarioError(f"{what}: expected key=value, e.g. law.k=50")
    key, raw = (part.strip() for part in expr.split("=", 1))
    if is_law_swap(expr):
        law = doc.get("law")
        old = law if isinstance(law, dict) else {}
        kind = raw.strip("'\"")
        if old.get("kind") != kind:  # a swap to the scenario's own law keeps its table
            doc["law"] = {"kind": kind, **{k: old[k] for k in SWAP_KEEPS if k in old}}
        return
    if not _KEY_RE.match(key):
        raise ScenarioError(f"{what}: key {key!r} must be a dotted path like law.gamma")
    value = parse_value(raw, what=what)
    *parents, last = key.split(".")
    node = doc
    for i, part in enumerate(parents):
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise ScenarioError(f"{what}: {'.'.join(parents[:i + 1])} is not a table in {where}")
        node = nxt
    node[last] = value


def _validate(doc: dict, *, where: str, base_dir: Path, default_name: str, text: str,
              overrides: tuple[str, ...]) -> Scenario:
    top = _Table(doc, "", where)
    version = top.integer("schema_version")
    if version != SCHEMA_VERSION:
        raise top.fail("schema_version", f"{SCHEMA_VERSION} (this adaptive-mj reads version {SCHEMA_VERSION})", version)
    name = top.string("name", default_name)
    if "name" in doc and not _NAME_RE.fullmatch(name):
        raise top.fail("name", "a plain name of 1 to 100 characters for log files (no '/', '\\', "
                               "control characters or leading '.')", name)
    description = top.string("description", "")

    plant = _plant(top.table("plant"), base_dir)
    order = _order(doc, plant, where)
    sim = _simulation(top.table("simulation"), plant, order)
    reference = _reference(top.table("reference"), plant)
    law = _law(top.table("law"), plant, order)
    if reference.kind == "reference_model" and law.mrac is None:  # the reference model is MRAC's (law.model)
        raise ScenarioError(f"{where}: reference.kind = 'reference_model' needs law.kind = 'mrac' (its model is "
                            f"law.model), got law.kind = {law.kind!r}")
    arm = plant.kind == "manipulator"
    noise = _noise(top.table("noise", {}), order, arm=arm)
    disturbance = _disturbance(top.table("disturbance", {}), arm=arm)
    sensors = _sensors(top.table("sensors", {}), arm=arm)
    if sensors.velocity == "differentiated" and "q_dot" in noise.std:
        raise ScenarioError(f"{where}: noise.std.q_dot is for sensors.velocity = 'measured'; a differentiated "
                            "velocity takes its noise from the positions (noise.std.q, sensors.encoder_counts)")
    events = _events(top.get("events", []), top, plant, sim, base_dir)
    control = _control(top.table("control", {}), sim)
    success = _success(top.table("success", {}))
    log = top.table("log", {})
    log_rate = log.number("rate_hz", 100.0, gt=0)
    log.finish()
    top.finish()
    return Scenario(name=name, description=description, plant=plant, simulation=sim, reference=reference,
                    law=law, noise=noise, disturbance=disturbance, events=events, log_rate_hz=log_rate,
                    source=where, text=text, overrides=overrides, control=control, success=success,
                    sensors=sensors)


def _model_from_command_line(doc: dict, overrides: tuple[str, ...], base_dir: Path | None, where: str) -> None:
    """A plant.model path given with --set is the user's, typed from where they stand: resolve it
    against the current directory first, then next to the scenario; neither is an error naming both."""
    if not any(expr.split("=", 1)[0].strip() == "plant.model" for expr in overrides):
        return
    plant = doc.get("plant")
    name = plant.get("model") if isinstance(plant, dict) else None
    if not isinstance(name, str) or not (name.endswith(".xml") or "/" in name) or Path(name).is_absolute():
        return
    here, there = Path.cwd() / name, (base_dir or Path.cwd()) / name
    if here.is_file():
        assert isinstance(plant, dict)  # name is a str above only when plant is a table
        plant["model"] = str(here.resolve())
    elif not there.is_file():
        raise ScenarioError(f"{where}: plant.model {name!r} (from --set) not found in the current directory "
                            f"({here}) nor next to the scenario ({there})")


def _resolve_model(name: str, base_dir: Path) -> Path:
    """A bundled model name ("heave_vehicle") or a path relative to the scenario file."""
    if "/" not in name and not name.endswith(".xml"):
        return MODELS_DIR / f"{name}.xml"
    p = Path(name)
    return p if p.is_absolute() else (base_dir / p)


def _plant(t: _Table, base_dir: Path) -> PlantSpec:  # noqa: C901 (one branch per plant kind; split in issue 19)
    raw_kind = t.data.get("kind")
    if raw_kind in ANALYTIC_PLANT_KINDS:
        return _analytic_plant(t, raw_kind)
    plugins: dict[str, Installed[PlantPlugin]] = {}
    if isinstance(raw_kind, str) and raw_kind not in PLANT_KINDS:
        from adaptive_mj.plants.plugin import installed

        plugins = installed()
        if raw_kind in plugins:
            return _plugin_plant(t, raw_kind, plugins[raw_kind], base_dir)
    kind = t.string("kind", choices=PLANT_KINDS + tuple(sorted(plugins)))
    backend = t.string("backend", "mujoco", choices=BACKENDS)
    if kind == "first_order" and backend != "twin":
        raise t.fail("backend", "'twin' for plant.kind = 'first_order' (it is not a mechanical system)", backend)
    if kind == "ship" and backend != "mujoco":
        raise t.fail("backend", "'mujoco' for plant.kind = 'ship' (its true Nomoto parameters are fitted to the "
                                "MuJoCo model)", backend)
    model_name = t.string("model", DEFAULT_MODEL.get(kind))
    model = None if model_name is None else _resolve_model(model_name, base_dir)
    if kind == "first_order" and "model" in t.data:
        raise t.fail("model", "absent for plant.kind = 'first_order'", model_name)
    joint = t.string("joint", None)
    actuator = t.string("actuator", None)
    payload = t.string("payload", "sphere" if kind == "arm" else None)
    if payload == "none":
        payload = None
    payload, payload_paths = _resolve_payload(payload, base_dir)
    payload_mass = t.number("payload_mass", None, gt=0)
    site = t.string("site", "tip")
    if kind not in ("arm", "manipulator"):
        for key in ("payload", "payload_mass", "site"):
            if key in t.data:
                raise t.fail(key, "absent unless plant.kind = 'arm' or 'manipulator'", t.data[key])
    manipulator = None
    if kind == "manipulator":
        if backend != "mujoco":
            raise t.fail("backend", "'mujoco' for plant.kind = 'manipulator' (its truth is the MuJoCo model)", backend)
        if payload_mass is not None and payload is None:
            raise t.fail("payload_mass", "absent when plant.payload is 'none'", payload_mass)
        manipulator = _manipulator(t, payload)
    else:
        for key in ("unknown", "joint_params", "base_parameters", "servo_to_torque", "forcerange"):
            if key in t.data:
                raise t.fail(key, "absent unless plant.kind = 'manipulator'", t.data[key])
    manipulator = _joint_friction(t, kind, manipulator)
    theta = t.named_numbers("theta", None)
    if theta is not None and backend != "twin":
        raise t.fail("theta", "absent for backend 'mujoco' (true parameters come from the compiled model)", theta)
    if kind == "first_order" and theta is None:
        raise ScenarioError(f"{t.where}: plant.theta is required for plant.kind = 'first_order' "
                            "(e.g. {a = 2, b = 1.5})")
    if theta is not None:
        regressor = t.data.get("regressor", "lecture")
        regressor = regressor if isinstance(regressor, str) else "lecture"  # its type is checked below
        expected = {"heave": ("d", "b", "c"), "arm": ("J", "b", "g_sin", "g_cos"),
                    "first_order": FIRST_ORDER_PARAMS.get(regressor, ("a", "b"))}[kind]
        if tuple(theta) != expected:
            raise t.fail("theta", f"a table with keys {', '.join(expected)} in that order", list(theta))
        if kind != "first_order" and theta[expected[0]] <= 0:
            raise t.fail(f"theta.{expected[0]}", "> 0", theta[expected[0]])
    g = t.number("g", 9.81, gt=0)
    density = t.number("density", None, ge=0)
    viscosity = t.number("viscosity", None, ge=0)
    # length=2: a pair [lo, hi] when given
    ctrl = cast("tuple[float, float] | None", t.numbers("ctrl_range", None, length=2))
    if ctrl is not None and not ctrl[0] < ctrl[1]:
        raise t.fail("ctrl_range", "[lo, hi] with lo < hi", list(ctrl))
    lag = t.number("thruster_time_constant", None, gt=0)
    if lag is not None and (kind != "heave" or theta is not None):
        raise t.fail("thruster_time_constant", "absent unless plant.kind = 'heave' built from a model", lag)
    regressor = t.string("regressor", "lecture", choices=REGRESSORS)
    if "regressor" in t.data and kind != "first_order":
        raise t.fail("regressor", "absent unless plant.kind = 'first_order'", regressor)
    t.finish()
    return PlantSpec(kind=kind, backend=backend, model=model, joint=joint, actuator=actuator, payload=payload,
                     payload_mass=payload_mass, site=site, theta=theta, g=g, density=density,
                     viscosity=viscosity, ctrl_range=ctrl, thruster_time_constant=lag, regressor=regressor,
                     manipulator=manipulator, payload_paths=payload_paths)


WING_ROCK_W = (-18.59521e-3, 15.162375e-3, -62.45153e-3, 9.54708e-3, 21.45291e-3)  # Elzebda et al., 25°


def _analytic_plant(t: _Table, kind: str) -> PlantSpec:
    """plant.kind = "linear" or "wing_rock": analytic plants on the twin backend (no model)."""
    t.string("kind")
    backend = t.string("backend", "twin", choices=("twin",))
    # length=2: a pair [lo, hi] when given
    ctrl = cast("tuple[float, float] | None", t.numbers("ctrl_range", None, length=2))
    if ctrl is not None and not ctrl[0] < ctrl[1]:
        raise t.fail("ctrl_range", "[lo, hi] with lo < hi", list(ctrl))
    linear = wing_rock = None
    if kind == "linear":
        linear = LinearSpec(num=t.numbers("num"), den=t.numbers("den"),
                            unmodelled_num=t.numbers("unmodelled_num", (1.0,)),
                            unmodelled_den=t.numbers("unmodelled_den", (1.0,)),
                            input_delay=t.number("input_delay", 0.0, ge=0), **_state_space(t))
        for key in ("den", "unmodelled_den"):
            if not any(getattr(linear, key)):
                raise t.fail(key, "a polynomial with a non-zero coefficient", list(getattr(linear, key)))
    else:
        wing_rock = WingRockSpec(W=t.numbers("W", WING_ROCK_W, length=5), l_delta=t.number("l_delta", 1.0))
        if wing_rock.l_delta == 0:
            raise t.fail("l_delta", "non-zero", 0.0)
    t.finish()
    return PlantSpec(kind=kind, backend=backend, model=None, joint=None, actuator=None, payload=None,
                     payload_mass=None, site="tip", theta=None, g=9.81, density=None, viscosity=None,
                     ctrl_range=ctrl, linear=linear, wing_rock=wing_rock)


def _state_space(t: _Table) -> dict:
    """plant.A, plant.B, plant.C (kind "linear"): all three or none; A square, B and C of its size; not
    with unmodelled_num/den (the matrices are the whole plant)."""
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
    sub = _Table({f"A[{i}]": r for i, r in enumerate(rows)}, t.prefix, t.where)
    A = tuple(sub.numbers(f"A[{i}]", length=len(rows)) for i in range(len(rows)))
    return {"A": A, "B": t.numbers("B", length=len(rows)), "C": t.numbers("C", length=len(rows))}


def _payload_paths(name: str | None, base_dir: Path) -> tuple[Path, ...]:
    """Where a payload file is looked for (adaptive_mj.plants.payload.candidates); checked in build."""
    from adaptive_mj.plants.payload import candidates

    return () if name is None else candidates(name, base_dir)


def _resolve_payload(name: str | None, base_dir: Path) -> tuple[str | None, tuple[Path, ...]]:
    """plant.payload: a bundled name as it is; a path as the first place it is found (next to the
    scenario, then the current directory), else the first place looked; and the places looked."""
    from adaptive_mj.plants.payload import is_bundled

    paths = _payload_paths(name, base_dir)
    if name is None or is_bundled(name):
        return name, paths
    return str(next((p for p in paths if p.is_file()), paths[0])), paths



def _plugin_params(t: _Table, inst: Installed[PlantPlugin] | Installed[LawPlugin], section: str,
                   kind: str) -> dict[str, float | dict[str, float]]:
    """A plugin's declared keys read from its table (section "plant" or "law"), each checked against
    its declared range; a key without a default must be given. A per-parameter key (Param.per_parameter)
    is a number or a table {parameter = number}, each entry in range (its names are checked against the
    plant's parameters when the law is built)."""
    params: dict[str, float | dict[str, float]] = {}
    for p in inst.plugin.params:
        if getattr(p, "per_parameter", False) and isinstance(t.data.get(p.name), dict):
            sub = t.table(p.name)
            params[p.name] = {name: sub.number(name, gt=p.gt, ge=p.ge) for name in sub.data}
            sub.finish(tuple(sub.data))
            continue
        value = t.number(p.name, p.default, gt=p.gt, ge=p.ge)
        if value is None:
            raise ScenarioError(f"{t.where}: {section}.{p.name} is required for {section}.kind = {kind!r} "
                                f"({inst.distribution} {inst.version})" + (f": {p.doc}" if p.doc else ""))
        params[p.name] = value
    return params


def _plugin_plant(t: _Table, kind: str, inst: Installed[PlantPlugin], base_dir: Path) -> PlantSpec:
    """plant.kind = an installed plant plugin: plant.model (default: the plugin's own MJCF),
    plant.viscosity, and the plugin's declared keys."""
    t.string("kind")
    backend = t.string("backend", "mujoco", choices=("mujoco",))
    model = _resolve_model(t.string("model", str(inst.plugin.model)), base_dir)
    viscosity = t.number("viscosity", None, ge=0)
    params = _plugin_params(t, inst, "plant", kind)
    t.finish()
    return PlantSpec(kind=kind, backend=backend, model=model, joint=None, actuator=None, payload=None,
                     payload_mass=None, site="tip", theta=None, g=9.81, density=None, viscosity=viscosity,
                     ctrl_range=None, plugin_params=params)


def _manipulator(t: _Table, payload: str | None) -> ManipulatorSpec:
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
    return ManipulatorSpec(unknown=unknown, joint_params=t.boolean("joint_params", False),
                           base_parameters=t.boolean("base_parameters", False),
                           servo_to_torque=servo, forcerange=_forcerange(t, servo))


def _forcerange(t: _Table, servo_to_torque: bool) -> float | dict[str, float] | None:
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


FRICTION_KEYS = ("damping", "frictionloss", "actuator_lag", "torque_limit", "friction_params", "coulomb_smoothing")


def _joint_friction(t: _Table, kind: str, spec: "ManipulatorSpec | None") -> "ManipulatorSpec | None":
    """plant.damping, .frictionloss, .actuator_lag, .friction_params, .coulomb_smoothing of a manipulator
    into spec.friction (joint names are checked against the model in build); refused on other kinds."""
    if spec is None:
        for key in FRICTION_KEYS:
            if key in t.data:
                raise t.fail(key, "absent unless plant.kind = 'manipulator'", t.data[key])
        return None
    values: dict[str, Any] = {}
    for key in ("damping", "frictionloss", "actuator_lag"):
        if key not in t.data:
            continue
        v = _joint_values(t, key, arrays=False)
        for j, x in (v.items() if isinstance(v, dict) else [("", v)]):
            if not x >= 0:
                raise t.fail(key + (f".{j}" if j else ""), ">= 0", x)
        values[key] = v
    if "torque_limit" in t.data:
        v = _joint_values(t, "torque_limit", arrays=False)
        for j, x in (v.items() if isinstance(v, dict) else [("", v)]):
            if not x > 0:
                raise t.fail("torque_limit" + (f".{j}" if j else ""), "> 0 [N m]", x)
        values["torque_limit"] = v
    friction_params = t.boolean("friction_params", False)
    eps = t.number("coulomb_smoothing", 0.01, gt=0)
    if "coulomb_smoothing" in t.data and not friction_params:
        raise t.fail("coulomb_smoothing", "absent unless plant.friction_params = true (it shapes the Coulomb "
                                          "column)", eps)
    import dataclasses

    return dataclasses.replace(spec, friction=JointFrictionSpec(**values, friction_params=friction_params,
                                                                 coulomb_smoothing=eps))


def _order(doc: dict, plant: PlantSpec, where: str) -> int:
    """n: 1 for first_order; 2, or 3 for a heave vehicle with a thruster lag and law.order = 3."""
    if plant.kind in ("first_order", "linear"):
        return 1
    law = doc.get("law")
    order = law.get("order", 2) if isinstance(law, dict) else 2
    if order == 3 and plant.thruster_time_constant is not None:
        return 3
    return 2


def _simulation(t: _Table, plant: PlantSpec, order: int) -> SimulationSpec:
    allowed = INTEGRATORS if plant.backend == "mujoco" else ("rk4", "euler")
    integrator = t.string("integrator", "rk4", choices=allowed)
    timestep = t.number("timestep", 0.001 if plant.model is None else None, gt=0)
    duration = t.number("duration", gt=0)
    if timestep is not None and timestep > duration:
        raise t.fail("timestep", f"<= simulation.duration ({duration})", timestep)
    x0: tuple[float, ...] | str | None
    if plant.kind == "manipulator":  # starts on the reference (joint positions and velocities)
        x0 = t.string("initial_state", "reference", choices=("reference",))
    elif t.data.get("initial_state") == "reference":
        x0 = t.string("initial_state")  # start on the reference: x0 = [y_d(0), ..., y_d^(n-1)(0)]
    else:
        x0 = t.numbers("initial_state", None, length=order)
    bound = t.number("state_bound", math.inf, gt=0, allow_inf=True)
    delay = t.integer("control_delay", 0, ge=0)
    python_callback = t.boolean("python_callback", False)
    t.finish()
    return SimulationSpec(integrator=integrator, timestep=timestep, duration=duration, initial_state=x0,
                          state_bound=bound, control_delay=delay, python_callback=python_callback)


def _control(t: _Table, sim: SimulationSpec) -> ControlSpec:
    period = t.number("period", None, gt=0)
    mode = t.string("mode", "continuous" if period is None else "sampled", choices=("continuous", "sampled"))
    hold = t.string("hold", "zoh", choices=("zoh",))
    if mode == "continuous" and period is not None and period != sim.timestep:
        raise t.fail("period", "left out under control.mode = 'continuous' (the law runs at every integrator "
                               "stage); set control.mode = 'sampled' for a sampled-data controller", period)
    if period is not None and period > sim.duration:
        raise t.fail("period", f"<= simulation.duration ({sim.duration})", period)
    t.finish()
    return ControlSpec(mode=mode, period=period, hold=hold)


def _success(t: _Table) -> SuccessSpec:
    d = SuccessSpec()
    raw = t.data.get("param_error")
    if isinstance(raw, dict):
        param_error: float | dict[str, float] | None = t.named_numbers("param_error", gt=0)
    else:
        param_error = t.number("param_error", None, gt=0)
    spec = SuccessSpec(tail_rms=t.number("tail_rms", None, gt=0, allow_inf=True),
                       tail_fraction=t.number("tail_fraction", d.tail_fraction, gt=0),
                       tail_floor=t.number("tail_floor", d.tail_floor, gt=0),
                       param_error=param_error,
                       saturation=t.number("saturation", d.saturation, ge=0),
                       preflight=t.string("preflight", d.preflight, choices=PREFLIGHT_ACTIONS))
    if spec.saturation > 1:
        raise t.fail("saturation", "a fraction of the run's time in [0, 1]", spec.saturation)
    t.finish()
    return spec


_REFERENCE_KEYS: dict[str, dict[str, float | None]] = {
    "constant": {"value": 0.0},
    "cosine": {"amplitude": 1.0, "omega": 1.0, "phase": 0.0, "offset": 0.0},
    "sine": {"amplitude": 1.0, "omega": 1.0, "phase": 0.0, "offset": 0.0},
    "sum_of_sines": {"amplitudes": None, "omegas": None, "phases": None, "offset": 0.0},
    "smooth_step": {"start": 0.0, "end": 1.0, "t0": 1.0, "rise_time": 2.0},
}


def _joint_reference(t: _Table, kind: str) -> ReferenceSpec:
    """Joint-space references; joint names and keyframes are resolved against the model in build."""
    params: dict[str, Any] = {}
    if kind == "joint_sum_of_sines":
        center = t.get("center", None)
        params["center"] = center if center is None or isinstance(center, str) else _joint_values(
            t, "center", arrays=False)
        if isinstance(params["center"], float):
            raise t.fail("center", "a keyframe name or a table {joint = position}", center)
        for key in ("amplitudes", "omegas", "phases"):
            params[key] = _joint_values(t, key, arrays=True) if (key in t.data or key != "phases") else None
    else:
        raw = t.get("waypoints")
        if not isinstance(raw, list) or len(raw) < 2:
            raise t.fail("waypoints", "an array of at least 2 poses (keyframe names or tables {joint = position})",
                         raw)
        points: list[str | dict[str, float]] = []
        for i, item in enumerate(raw):
            if isinstance(item, str):
                points.append(item)
            elif isinstance(item, dict):
                sub = _Table(item, f"{t.prefix}waypoints[{i}].", t.where)
                points.append({key: sub.number(key) for key in item})
            else:
                raise t.fail(f"waypoints[{i}]", "a keyframe name or a table {joint = position}", item)
        params["waypoints"] = tuple(points)
        params["durations"] = t.numbers("durations")
        if len(params["durations"]) != len(points) - 1 or any(d <= 0 for d in params["durations"]):
            raise t.fail("durations", f"{len(points) - 1} move times > 0 [s] (one per move)",
                         list(params["durations"]))
        params["t0"] = t.number("t0", 0.0, ge=0)
        params["cycle"] = t.boolean("cycle", False)
    t.finish()
    return ReferenceSpec(kind=kind, params=params)


def _reference(t: _Table, plant: PlantSpec) -> ReferenceSpec:
    if plant.kind == "manipulator":
        kind = t.string("kind", choices=JOINT_REFERENCE_KINDS)
        return _joint_reference(t, kind)
    kind = t.string("kind", choices=REFERENCE_KINDS)
    if kind == "waypoints":
        return _waypoints(t)
    if kind == "reference_model":
        return _model_reference(t)
    params: dict[str, Any] = {}
    for key, default in _REFERENCE_KEYS[kind].items():
        if key in ("amplitudes", "omegas", "phases"):
            params[key] = t.numbers(key, None if key == "phases" else _MISSING)
        else:
            params[key] = t.number(key, default, gt=0 if key in ("omega", "rise_time") else None)
    if kind == "sum_of_sines":
        n = len(params["amplitudes"])
        if params["phases"] is None:
            params["phases"] = (0.0,) * n
        if not (len(params["omegas"]) == len(params["phases"]) == n) or n == 0:
            raise t.fail("omegas", f"as many entries as reference.amplitudes ({n})", list(params["omegas"]))
    t.finish()
    return ReferenceSpec(kind=kind, params=params)


def _waypoints(t: _Table) -> ReferenceSpec:
    """reference.kind = "waypoints" (1-DOF): set-points joined by C⁴ smooth steps (reference.Waypoints)."""
    points = t.numbers("waypoints")
    if len(points) < 2:
        raise t.fail("waypoints", "an array of at least 2 set-points", list(points))
    durations = t.numbers("durations")
    if len(durations) != len(points) - 1 or any(d <= 0 for d in durations):
        raise t.fail("durations", f"{len(points) - 1} move times > 0 [s] (one per move)", list(durations))
    params = {"waypoints": points, "durations": durations, "t0": t.number("t0", 0.0, ge=0)}
    t.finish()
    return ReferenceSpec(kind="waypoints", params=params)


def _model_reference(t: _Table) -> ReferenceSpec:
    """reference.kind = "reference_model": the command r = offset + Σ amplitudes_i sin(omegas_i t + phases_i)
    through MRAC's reference model (law.model, law.model_gain), from rest."""
    amplitudes = t.numbers("amplitudes", ())
    n = len(amplitudes)
    omegas = t.numbers("omegas", (), length=n)
    phases = t.numbers("phases", (0.0,) * n, length=n)
    if any(w <= 0 for w in omegas):
        raise t.fail("omegas", "frequencies > 0 [rad/s]", list(omegas))
    params = {"offset": t.number("offset", 0.0), "amplitudes": amplitudes, "omegas": omegas, "phases": phases}
    t.finish()
    return ReferenceSpec(kind="reference_model", params=params)


def _law(t: _Table, plant: PlantSpec, order: int) -> LawSpec:
    """[law]: its kind looked up in the law-kind registry (adaptive_mj.laws.kinds: the built-in kinds and the
    installed plugins), refused in one line when it serves none of the plant's forms, then its own keys, read
    by the kind's reader (a plugin's: _plugin_law)."""
    from adaptive_mj.plants import kinds as plant_kinds

    built_in = law_kinds.built_in()
    raw_kind = t.data.get("kind")
    plugins: dict[str, Installed[LawPlugin]] = {}
    if isinstance(raw_kind, str) and raw_kind not in built_in:
        from adaptive_mj.laws.plugin import installed

        plugins = installed()
    known = {**built_in, **{n: law_kinds.plugin_kind(n, i) for n, i in sorted(plugins.items())}}
    plant_kind = plant_kinds.lookup(plant.kind)
    offered = plant_kind.forms if plant_kind is not None else frozenset({law_kinds.Form.MODEL})
    kind = t.string("kind", plant_kind.default_law if plant_kind is not None else "sliding_adaptive",
                    choices=tuple(known))
    if not known[kind].forms & offered:  # refused: the message names every law that serves, plugins too
        raise ScenarioError(f"{t.where}: {law_kinds.refusal(known[kind], plant.kind, offered, law_kinds.all_kinds())}")
    if kind in plugins:
        return _plugin_law(t, kind, plugins[kind], plant, order)
    misfit = law_kinds.misfit(known[kind], plant.kind)
    if misfit is not None:
        raise t.fail("kind", misfit, kind)
    read = known[kind].read
    assert read is not None  # every built-in kind declares its reader (adaptive_mj.laws.kinds.LawKind)
    return read(t, kind, plant, order)


def _plugin_law(t: _Table, kind: str, inst: Installed[LawPlugin], plant: PlantSpec, order: int) -> LawSpec:
    """law.kind = an installed plugin: its declared keys (adaptive_mj.laws.plugin.Param), checked
    like built-in ones, plus initial_estimates and nominal, and the shared modifications (law.dead_zone,
    law.sigma, law.e_modification, law.theta0, law.projection) where the plugin declares no key of that name."""
    t.string("kind")
    law_order = t.integer("order", order, ge=1)
    if law_order != order:
        raise t.fail("order", f"{order} for plant.kind = {plant.kind!r}", law_order)
    orders = inst.plugin.orders
    if orders is not None and order not in orders:
        raise ScenarioError(f"{t.where}: law.kind = {kind!r} is written for plants of order "
                            f"{' or '.join(map(str, orders))}; plant.kind = {plant.kind!r} here is of order {order}")
    params = _plugin_params(t, inst, "law", kind)
    initial = _estimate_table(t, "initial_estimates")
    nominal = _estimate_table(t, "nominal")
    own = set(params)
    dead_zone = _dead_zone(t) if "dead_zone" not in own else None
    robust = RobustSpec()
    if not own & {"sigma", "e_modification", "theta0", "projection"}:
        presets = ("physical",) if plant.kind == "manipulator" else ()
        robust = _robust(t, kind, adaptive=bool(inst.plugin.adapts), composite=False, presets=presets)
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=None, dead_zone=dead_zone,
                   initial_estimates=initial, nominal=nominal, K=None, boundary_layer=None, plugin_params=params,
                   robust=robust)


def _noise(t: _Table, order: int, *, arm: bool = False) -> NoiseSpec:
    signals = JOINT_SIGNALS if arm else STATE_SIGNALS[:order]
    raw = t.get("std", None)
    std: dict[str, Any] = {}
    if raw is not None:
        sub = t.table("std")
        for key in raw:
            if key not in signals:
                raise ScenarioError(f"{t.where}: unknown key 'noise.std.{key}' (measured signals: "
                                    f"{', '.join(signals)})")
            std[key] = _joint_values(sub, key, arrays=False) if arm else sub.number(key)
            for j, v in (std[key].items() if isinstance(std[key], dict) else [("", std[key])]):
                if v < 0:
                    raise sub.fail(key + (f".{j}" if j else ""), ">= 0", v)
    seed = t.integer("seed", 0, ge=0)
    t.finish()
    return NoiseSpec(std=std, seed=seed)


def _disturbance(t: _Table, *, arm: bool = False) -> DisturbanceSpec:
    kinds = ARM_DISTURBANCE_KINDS if arm else DISTURBANCE_KINDS
    kind = t.string("kind", "none", choices=kinds)
    magnitude = _joint_values(t, "magnitude", arrays=False) if arm and "magnitude" in t.data \
        else t.number("magnitude", 0.0)
    bandwidth = t.number("bandwidth_hz", 10.0, gt=0) if arm else 10.0
    load = None
    if "load" in t.data:
        if not arm:
            raise t.fail("load", "absent unless plant.kind = 'manipulator'", t.data["load"])
        load = t.named_numbers("load", gt=0)
    spec = DisturbanceSpec(kind=kind, magnitude=magnitude, t0=t.number("t0", 0.0, ge=0),
                           omega=t.number("omega", 1.0, gt=0), phase=t.number("phase", 0.0), bandwidth_hz=bandwidth,
                           load=load)
    t.finish()
    return spec


def _sensors(t: _Table, *, arm: bool) -> SensorSpec:
    if t.data and not arm:
        raise ScenarioError(f"{t.where}: [sensors] ({', '.join(repr(k) for k in t.data)}) is for plant.kind = "
                            "'manipulator'; a 1-DOF plant's sensors are noise.std")
    counts = _joint_values(t, "encoder_counts", arrays=False) if "encoder_counts" in t.data else None
    for j, v in (counts.items() if isinstance(counts, dict) else [("", counts)] if counts is not None else []):
        if not v >= 1:
            raise t.fail("encoder_counts" + (f".{j}" if j else ""), "a count per revolution >= 1", v)
    spec = SensorSpec(encoder_counts=counts,
                      velocity=t.string("velocity", "measured", choices=("measured", "differentiated")),
                      velocity_cutoff_hz=t.number("velocity_cutoff_hz", 50.0, gt=0, allow_inf=True))
    t.finish()
    return spec


def _events(raw: Any, top: _Table, plant: PlantSpec, sim: SimulationSpec, base_dir: Path) -> tuple[EventSpec, ...]:
    if not isinstance(raw, list):
        raise top.fail("events", "an array of tables ([[events]])", raw)
    out: list[EventSpec] = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict):
            raise top.fail(f"events[{i}]", "a table", item)
        t = _Table(item, f"events[{i}].", top.where)
        time = t.number("t", ge=0)
        if time > sim.duration:
            raise t.fail("t", f"<= simulation.duration ({sim.duration})", time)
        kind = t.string("kind", choices=EVENT_KINDS)
        value = 0.0 if kind in ("payload_swap", "flight_condition") else \
            t.number("value", gt=0 if kind != "constant_force" else None)
        W = t.numbers("W", length=5) if kind == "flight_condition" else None
        l_delta = t.number("l_delta", None) if kind == "flight_condition" else None
        if l_delta == 0:
            raise t.fail("l_delta", "non-zero", l_delta)
        body = t.string("body", "payload/body")
        payload = t.string("payload") if kind == "payload_swap" else None
        needs = {"payload_mass": (("arm", "manipulator"), "mujoco"), "fluid_density_scale": (("heave",), "mujoco"),
                 "payload_swap": (("manipulator",), "mujoco"),
                 "constant_force": (("heave", "arm", "first_order", "ship", "linear", "wing_rock"), plant.backend),
                 "loading": (("ship",), "mujoco"), "thrust_scale": (("ship",), "mujoco"),
                 "flight_condition": (("wing_rock",), "twin")}.get(kind)
        if needs and (plant.kind not in needs[0] or plant.backend != needs[1]):
            kinds = " or ".join(repr(k) for k in needs[0])
            raise t.fail("kind", f"used only with plant.kind = {kinds} on backend {needs[1]!r}", kind)
        if kind in ("payload_mass", "payload_swap") and plant.kind == "manipulator" and plant.payload is None \
                and body.startswith("payload/"):
            raise t.fail("kind", "an event on a payload body needs plant.payload (it is 'none')", kind)
        t.finish()
        out.append(EventSpec(t=time, kind=kind, value=value, body=body, payload=payload,
                             payload_paths=_payload_paths(payload, base_dir), W=W, l_delta=l_delta))
    return tuple(sorted(out, key=lambda e: e.t))


def bundled() -> list[Path]:
    """The bundled scenario files, sorted by name."""
    return sorted(SCENARIOS_DIR.glob("*.toml"))

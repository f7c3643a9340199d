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
from typing import TYPE_CHECKING, Any

from adaptive_mj.data import SCENARIOS as SCENARIOS_DIR
from adaptive_mj.errors import ScenarioError
from adaptive_mj.plants import kinds as _kinds
from adaptive_mj.plants.plant_keys import BACKENDS, SharedReader, payload_paths, resolve_model as _resolve_model  # noqa: F401
from adaptive_mj.plants.twin import FORMS as _FIRST_ORDER_FORMS
from adaptive_mj.plants.wing_rock import WING_ROCK_W  # noqa: F401 (re-exported)
from adaptive_mj.keys import _MISSING, Table as _Table, _Missing, _show, _suggest  # noqa: F401 (re-exported)
from adaptive_mj.keys import joint_values as _joint_values
from adaptive_mj.laws import kinds as law_kinds
from adaptive_mj.laws.law_keys import (DEAD_ZONE_ON, RIGID_BODY_PROJECTIONS, read_dead_zone as _dead_zone,  # noqa: F401 (re-exported)
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

# analytic plants (their own readers, no model: adaptive_mj.plants.linear, .wing_rock), from the registry
ANALYTIC_PLANT_KINDS = tuple(k.name for k in _kinds.built_in().values()
                             if k.reader is not None and not isinstance(k.reader, SharedReader))


def _plant_kinds() -> dict[str, PlantKind]:
    """The built-in plant kinds, as their modules register them (adaptive_mj.plants.kinds)."""
    from adaptive_mj.plants.kinds import built_in

    return built_in()


PLANT_KINDS = tuple(_plant_kinds())  # the built-in plant.kind values, from the registry
INTEGRATORS = ("rk4", "euler", "implicitfast", "implicit")
REFERENCE_KINDS = ("constant", "cosine", "sine", "sum_of_sines", "smooth_step", "waypoints", "reference_model")
JOINT_REFERENCE_KINDS = ("joint_sum_of_sines", "joint_waypoints")

def _law_kinds(form: str) -> tuple[str, ...]:
    return tuple(k.name for k in law_kinds.built_in().values() if law_kinds.Form(form) in k.forms)


LAW_KINDS = _law_kinds("model") + _law_kinds("mrac_state")  # the built-in law kinds of 1-DOF plants, from the registry
MANIPULATOR_LAW_KINDS = _law_kinds("rigid_body")  # those of multi-joint plants
DISTURBANCE_KINDS = ("none", "constant", "step", "sine")
ARM_DISTURBANCE_KINDS = DISTURBANCE_KINDS + ("noise",)  # per joint torques (adaptive_mj.disturbance)
EVENT_KINDS = _kinds.event_kinds()  # what the built-in plant kinds accept (PlantKind.events), from the registry
DEFAULT_MODEL = {k.name: k.default_model for k in _plant_kinds().values() if k.default_model is not None}
STATE_SIGNALS = ("y", "y_dot", "y_ddot")
JOINT_SIGNALS = ("q", "q_dot")  # an arm's measured signals (noise.std)
REGRESSORS = tuple(_FIRST_ORDER_FORMS)  # plant.regressor of kind "first_order" (adaptive_mj.plants.twin)
FIRST_ORDER_PARAMS = {name: form().names for name, form in _FIRST_ORDER_FORMS.items()}



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
    arm = _rigid_body(plant)  # a multi-joint plant: joint-space noise, disturbance and sensors
    own = _kinds.lookup(plant.kind)
    noise = _noise(top.table("noise", {}), order, arm=arm, signals=own.noise_signals if own is not None else ())
    disturbance = _disturbance(top.table("disturbance", {}), arm=arm)
    if own is not None and own.noise_signals and disturbance.kind != "none":
        raise ScenarioError(f"{where}: [disturbance] is for the 1-DOF plants and the arms; plant.kind = {plant.kind!r} "
                            "takes its disturbances as [[events]] (kind = 'external_force', 'wind')")
    sensors = _sensors(top.table("sensors", {}), arm=arm)
    if sensors.velocity == "differentiated" and "q_dot" in noise.std:
        raise ScenarioError(f"{where}: noise.std.q_dot is for sensors.velocity = 'measured'; a differentiated "
                            "velocity takes its noise from the positions (noise.std.q, sensors.encoder_counts)")
    events = _events(top.get("events", []), top, plant, sim, base_dir)
    control = _control(top.table("control", {}), sim)
    success = _success(top.table("success", {}))
    log = top.table("log", {})
    log_rate = log.number("rate_hz", 100.0, gt=0)
    log_encoding = log.string("encoding", "cdr", choices=("cdr", "json"))  # record.ENCODINGS
    log.finish()
    top.finish()
    return Scenario(name=name, description=description, plant=plant, simulation=sim, reference=reference,
                    law=law, noise=noise, disturbance=disturbance, events=events, log_rate_hz=log_rate,
                    log_encoding=log_encoding,
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


def _plant(t: _Table, base_dir: Path) -> PlantSpec:
    """[plant]: its kind looked up in the plant-kind registry (adaptive_mj.plants.kinds), which reads the
    kind's own keys (PlantKind.read), else an installed plant plugin's; an unknown kind is refused naming
    every kind there is."""
    from adaptive_mj.plants import kinds as plant_kinds

    raw_kind = t.data.get("kind")
    kind = plant_kinds.built_in().get(raw_kind) if isinstance(raw_kind, str) else None
    if kind is not None and kind.reader is not None:
        return kind.read(t, base_dir)
    plugins: dict[str, Installed[PlantPlugin]] = {}
    if isinstance(raw_kind, str):
        from adaptive_mj.plants.plugin import installed

        plugins = installed()
        if raw_kind in plugins:
            return _plugin_plant(t, raw_kind, plugins[raw_kind], base_dir)
    t.string("kind", choices=tuple(plant_kinds.built_in()) + tuple(sorted(plugins)))
    raise ScenarioError(f"{t.where}: plant.kind {raw_kind!r} has no key reader")  # a kind registered without one


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


def _order(doc: dict, plant: PlantSpec, where: str) -> int:
    """n, the order of the plant's dynamics: its kind's (PlantKind.order) from the plant and law.order."""
    from adaptive_mj.plants import kinds as plant_kinds

    law = doc.get("law")
    law_order = law.get("order", 2) if isinstance(law, dict) else 2
    kind = plant_kinds.lookup(plant.kind)
    return kind.order(plant, law_order) if kind is not None else plant_kinds.second_order(plant, law_order)


def _simulation(t: _Table, plant: PlantSpec, order: int) -> SimulationSpec:
    from adaptive_mj.plants import kinds as plant_kinds

    kind = plant_kinds.lookup(plant.kind)
    allowed = INTEGRATORS if plant.backend == "mujoco" else ("rk4", "euler")
    own = model_integrator(plant.model) if plant.backend == "mujoco" and plant.model is not None else None
    integrator = t.string("integrator", own or "rk4", choices=allowed)
    note = ""
    if own is not None and integrator != own:
        note = f"simulation.integrator = {integrator!r} replaces the model's own {own!r}"
    elif own is not None and "integrator" not in t.data and own != "rk4":
        note = (f"simulation.integrator: the model's own {own!r} (the scenario names none; without one in the "
                "model: 'rk4')")
    default_dt = (kind.default_timestep if kind is not None else 0.001) if plant.model is None else None
    timestep = t.number("timestep", default_dt, gt=0)
    duration = t.number("duration", gt=0)
    if timestep is not None and timestep > duration:
        raise t.fail("timestep", f"<= simulation.duration ({duration})", timestep)
    x0: tuple[float, ...] | str | None
    if kind is not None and kind.starts_on_reference:  # e.g. a manipulator's joint positions and velocities
        x0 = t.string("initial_state", "reference", choices=("reference",))
    elif t.data.get("initial_state") == "reference":
        x0 = t.string("initial_state")  # start on the reference: x0 = [y_d(0), ..., y_d^(n-1)(0)]
    else:
        x0 = t.numbers("initial_state", None, length=order)
    bound = t.number("state_bound", math.inf, gt=0, allow_inf=True)
    raw_delay = t.data.get("control_delay")
    if isinstance(raw_delay, float):  # a delay in seconds: say the unit, and the steps it would be
        steps = f"; {raw_delay:g} s is {raw_delay / timestep:.6g} steps of {timestep:g} s" if timestep else ""
        raise t.fail("control_delay", f"a whole number of physics steps (not seconds){steps}", raw_delay)
    delay = t.integer("control_delay", 0, ge=0)
    python_callback = t.boolean("python_callback", False)
    t.finish()
    return SimulationSpec(integrator=integrator, timestep=timestep, duration=duration, initial_state=x0,
                          state_bound=bound, control_delay=delay, python_callback=python_callback,
                          integrator_note=note)


_OPTION_INTEGRATOR = re.compile(r"<option\b[^>]*?\bintegrator\s*=\s*[\"']([A-Za-z0-9]+)[\"']", re.IGNORECASE)


def model_integrator(model: Path | str) -> str | None:
    """The integrator the MJCF file `model` declares in its <option> (as simulation.integrator names it: "rk4",
    "euler", "implicit", "implicitfast"), or None where it declares none (MuJoCo's default, Euler, is then not
    taken: the scenario's default "rk4" is) or cannot be read. Read once per file version."""
    path = Path(model)
    try:
        st = path.stat()
    except OSError:
        return None
    return _declared_integrator(str(path), (st.st_mtime_ns, st.st_size))


@functools.lru_cache(maxsize=64)
def _declared_integrator(path: str, stamp: tuple[int, int]) -> str | None:
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    found = _OPTION_INTEGRATOR.search(text)
    name = found.group(1).lower() if found else None
    return name if name in INTEGRATORS else None


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
                       preflight=t.string("preflight", d.preflight, choices=PREFLIGHT_ACTIONS),
                       physical=t.boolean("physical", d.physical),
                       tail_saturation=t.number("tail_saturation", d.tail_saturation, ge=0),
                       oscillation=t.number("oscillation", d.oscillation, gt=0, allow_inf=True))
    if spec.saturation > 1:
        raise t.fail("saturation", "a fraction of the run's time in [0, 1]", spec.saturation)
    if spec.tail_saturation is not None and spec.tail_saturation > 1:
        raise t.fail("tail_saturation", "a fraction of the tail's rows in [0, 1]", spec.tail_saturation)
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


def _rigid_body(plant: PlantSpec) -> bool:
    """Whether the plant's kind is a multi-joint plant (offers the rigid-body form: PlantKind.rigid_body)."""
    return _kinds.is_rigid_body(plant.kind)


def _rigid_body_kinds() -> str:
    """The plant kinds that offer the rigid-body form, for messages: "'manipulator'"."""
    return " or ".join(repr(k.name) for k in _kinds.built_in().values() if k.rigid_body)


def _reference(t: _Table, plant: PlantSpec) -> ReferenceSpec:
    own = _kinds.lookup(plant.kind)
    if own is not None and own.reference_reader is not None:  # the kind's own references (a quadrotor's flight)
        return own.reference_reader(t)
    if _rigid_body(plant):  # joint references
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
        presets = RIGID_BODY_PROJECTIONS if _rigid_body(plant) else ()  # these need bodies' parameters
        robust = _robust(t, kind, adaptive=bool(inst.plugin.adapts), composite=False, presets=presets)
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=None, dead_zone=dead_zone,
                   initial_estimates=initial, nominal=nominal, K=None, boundary_layer=None, plugin_params=params,
                   robust=robust)


def _noise(t: _Table, order: int, *, arm: bool = False, signals: tuple[str, ...] = ()) -> NoiseSpec:
    signals = signals or (JOINT_SIGNALS if arm else STATE_SIGNALS[:order])
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
            raise t.fail("load", f"absent unless plant.kind = {_rigid_body_kinds()}", t.data["load"])
        load = t.named_numbers("load", gt=0)
    spec = DisturbanceSpec(kind=kind, magnitude=magnitude, t0=t.number("t0", 0.0, ge=0),
                           omega=t.number("omega", 1.0, gt=0), phase=t.number("phase", 0.0), bandwidth_hz=bandwidth,
                           load=load)
    t.finish()
    return spec


def _sensors(t: _Table, *, arm: bool) -> SensorSpec:
    if t.data and not arm:
        raise ScenarioError(f"{t.where}: [sensors] ({', '.join(repr(k) for k in t.data)}) is for plant.kind = "
                            f"{_rigid_body_kinds()}; a 1-DOF plant's sensors are noise.std")
    counts = _joint_values(t, "encoder_counts", arrays=False) if "encoder_counts" in t.data else None
    for j, v in (counts.items() if isinstance(counts, dict) else [("", counts)] if counts is not None else []):
        if not v >= 1:
            raise t.fail("encoder_counts" + (f".{j}" if j else ""), "a count per revolution >= 1", v)
    spec = SensorSpec(encoder_counts=counts,
                      velocity=t.string("velocity", "measured", choices=("measured", "differentiated")),
                      velocity_cutoff_hz=t.number("velocity_cutoff_hz", 50.0, gt=0, allow_inf=True))
    t.finish()
    return spec


def _accepted(t: _Table, kind: str, plant: PlantSpec) -> None:
    """Refuses an event of `kind` on a plant kind that does not accept it (PlantKind.events) or on another
    backend than the one it needs."""
    from adaptive_mj.plants import kinds as plant_kinds

    names, backend = plant_kinds.accepting(kind)
    backend = plant.backend if backend is None else backend
    if plant.kind not in names or plant.backend != backend:
        raise t.fail("kind", f"used only with plant.kind = {' or '.join(repr(k) for k in names)} on backend "
                             f"{backend!r}", kind)


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
        kind = t.string("kind", choices=_event_kinds())
        event_kind = _kinds.event_kind(kind)
        assert event_kind is not None  # kind is one the plant kinds accept (its choices)
        value = event_kind.read_value(t)  # its value rule, then its fields in the order it declares them
        fields = event_kind.read_fields(t)
        _accepted(t, kind, plant)
        if event_kind.on_load is not None:
            event_kind.on_load(t, plant, fields)
        t.finish()
        own = {k: v for k, v in fields.items() if k in _EVENT_SPEC_FIELDS}
        params = {k: v for k, v in fields.items() if k not in _EVENT_SPEC_FIELDS}
        out.append(EventSpec(t=time, kind=kind, value=value, **own,
                             payload_paths=payload_paths(own.get("payload"), base_dir), params=params))
    return tuple(sorted(out, key=lambda e: e.t))


#: the fields of an [[events]] table that EventSpec holds by name (body, payload, W, l_delta); an event kind's
#: other fields go to EventSpec.params
_EVENT_SPEC_FIELDS = frozenset(f.name for f in dataclasses.fields(EventSpec)) - {"t", "kind", "value", "params",
                                                                                 "payload_paths"}


def _event_kinds() -> tuple[str, ...]:
    """The [[events]] kinds the plant kinds accept (adaptive_mj.plants.kinds.event_kinds)."""
    from adaptive_mj.plants.kinds import event_kinds

    return event_kinds()


def bundled() -> list[Path]:
    """The bundled scenario files, sorted by name."""
    return sorted(SCENARIOS_DIR.glob("*.toml"))

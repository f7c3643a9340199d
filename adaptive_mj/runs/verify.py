"""replay --verify: re-simulate a log from what it holds (its scenario text,
overrides, seed and exact model source) and compare bit for bit."""
from __future__ import annotations

import numpy as np

from adaptive_mj.setup import scenario as sc
from adaptive_mj.plants import ModelSource
from adaptive_mj.runs.runner import execute

_FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")
#: the law kinds that formed Y whole in a log without a law_evaluation header (laws.slotine_li's kinds)
REGRESSOR_BEFORE = ("slotine_li", "computed_torque", "pd_gravity")


def _flight_gains_before_rotor_drag(scn, logged) -> list[str]:
    """A quadrotor log written before issue 52 (its embedded model declares no rotor drag, <numeric name="k_eta">,
    and flies in MuJoCo's ellipsoid fluid: the bundled model of then): the overrides that give its flight law the
    position gains it had by default then (laws.flight.former_gain_overrides), for the keys its scenario and
    overrides left to the default. The model it embeds already gives the air and the rotors of then."""
    import tomllib

    from adaptive_mj.laws.flight import former_gain_overrides

    source = logged.model_source
    if scn.plant.kind != "quadrotor" or source is None or 'name="k_eta"' in source \
            or 'fluidshape="ellipsoid"' not in source:
        return []
    set_keys = set(tomllib.loads(logged.scenario_text).get("law", {}))
    for o in logged.overrides:
        name, _, value = o.partition("=")
        name = name.strip()
        if name.startswith("law."):
            set_keys.add(name[4:].split(".")[0])
        elif name == "law":  # the whole table replaced: its keys
            set_keys |= set(tomllib.loads(f"law = {value}")["law"])
    return former_gain_overrides(scn.law.kind, set_keys)


def _flight_kinds() -> set[str]:
    """The flight law kinds (laws.flight's): a quadrotor log of one without a law_evaluation header (its
    allocation) ran "exact_clip"."""
    from adaptive_mj.laws import flight

    return {k.name for k in (flight.GEOMETRIC, flight.GEOMETRIC_ADAPTIVE, flight.L1_GEOMETRIC)}


def _rerun_scenario(logged):
    """The scenario the re-run flies: the log's text, overrides and seed, plus what keeps an older log's run as it
    was (a law's evaluation, a flight law's former gains)."""
    header = logged.header

    def load(extra):
        return sc.loads(logged.scenario_text, where=f"{header.get('scenario_source', 'log')} (from the log)",
                        default_name=header["scenario_name"], overrides=[*logged.overrides, *extra],
                        seed=int(header["seed"]))

    scn = load([])
    extra = []
    if "law_evaluation" not in header and scn.law.kind in REGRESSOR_BEFORE:
        # written before the O(n) Slotine–Li (laws.slotine_li, law.evaluation): that run formed Y whole, and
        # the O(n) form's numbers differ from it in the last bits, so the re-run forms Y whole too
        extra.append("law.evaluation='regressor'")
    extra += _flight_gains_before_rotor_drag(scn, logged)
    if scn.plant.kind == "quadrotor" and not header.get("law_evaluation") and scn.law.kind in _flight_kinds():
        # written before law.allocation (issue 52): the flight laws inverted exactly and clipped each rotor
        extra.append("law.allocation='exact_clip'")
    return load(extra) if extra else scn


def verify(logged) -> tuple[bool, str]:
    """(identical?, one-line message). Compares every logged row with the re-run's same step."""
    header = logged.header
    note = ""
    from adaptive_mj.laws import plugin as law_plugins
    from adaptive_mj.plants import plugin as plant_plugins

    for what, registry in (("law", law_plugins), ("plant", plant_plugins)):
        plugin = header.get(f"{what}_plugin")  # format 3: the run's law or plant came from a plugin
        if not plugin:
            continue
        inst = registry.installed().get(plugin["name"])
        if inst is None:
            return False, (f"verify: cannot re-simulate: the log's {what} plugin {plugin['name']!r} "
                           f"({plugin['distribution']} {plugin['version']}) is not installed; install that "
                           "version and verify again")
        if inst.describe() != plugin:
            note += (f"; note: the installed {what} plugin {plugin['name']!r} ({inst.distribution} {inst.version}, "
                     f"source {inst.source_sha256[:12]}) differs from the log's ({plugin['distribution']} "
                     f"{plugin['version']}, source {plugin['source_sha256'][:12]})")
    scn = _rerun_scenario(logged)
    source = None
    if logged.model_source is not None:
        source = ModelSource(logged.model_source, dict(logged.model_assets))
    else:
        from adaptive_mj.setup.build import model_source

        if model_source(scn) is not None:  # a log from before format 2 embeds no model source
            note += ("; note: the log embeds no model source: re-simulated against the model files on disk "
                     "as the scenario names them now")
    rerun = execute(scn, source=source).trajectory
    logged_traj = logged.trajectory
    every = int(header.get("log_every", 1))
    rows = np.arange(len(logged_traj)) * every
    if len(logged_traj) and rows[-1] >= len(rerun):
        return False, f"verify: MISMATCH: the log has more rows than the re-run ({len(rerun)} steps){note}"
    if len(logged_traj) and not np.array_equal(logged_traj.theta[0], rerun.theta[0]):
        return False, _parameters_differ(logged_traj.theta[0], rerun.theta[0], note)
    v_note = ""
    for name in _FIELDS:
        a = getattr(logged_traj, name)
        b = getattr(rerun, name)[rows]
        if not np.array_equal(a, b, equal_nan=True):  # NaN = NaN: a plugin law declares no V
            differ = (a != b) & ~(np.isnan(a) & np.isnan(b))
            if name == "V" and logged_traj.joint_names:
                v_note = _v_before_event(differ, rows, rerun)
                if v_note:
                    continue
            bad = np.argwhere(differ)[0]
            i = int(bad[0])
            return False, (f"verify: MISMATCH in {name} at row {i} (t={logged_traj.t[i]!r}): "
                           f"log {a[tuple(bad)]!r} vs re-run {b[tuple(bad)]!r}{note}")
    if v_note:
        return True, (f"verify: bit-identical but for V at {v_note} ({len(logged_traj)} logged rows of {len(rerun)} "
                      f"steps re-simulated){note}")
    return True, f"verify: bit-identical ({len(logged_traj)} logged rows of {len(rerun)} steps re-simulated){note}"


def _v_before_event(differ: np.ndarray, steps: np.ndarray, rerun) -> str:
    """A note when the only V rows that differ are those an earlier adaptive-mj got wrong, else "": a
    multi-joint run's V = ½ sᵀ M(q) s + ... was computed when rows were flushed (each simulated second),
    with the model as it was then, so rows before an event that changed the inertia (a payload swap)
    and in the same second took M after it. Since 0.2.0 each row's M is the one of its own step (the
    native callback records MuJoCo's; the Python path flushes before an event). x, u, s, θ̂ and θ are
    compared as ever."""
    per_flush = max(1, round(1.0 / float(rerun.meta["dt"])))
    events = [t for t, _ in rerun.meta.get("events", [])]
    event_steps = [int(round(t / float(rerun.meta["dt"]))) for t in events]
    rows = np.nonzero(differ)[0]
    for k in steps[rows]:
        if not any(k < e and k // per_flush == e // per_flush for e in event_steps):
            return ""
    when = ", ".join(f"{t:.6g}" for t in events)
    return (f"{len(rows)} rows before the event at t = {when} s, which adaptive-mj before 0.2.0 computed with the "
            "inertia after that event (docs/LOG_FORMAT.md)")


def _parameters_differ(logged: np.ndarray, rerun: np.ndarray, note: str) -> str:
    """The message when the true parameters at t = 0 already differ: nothing has been controlled yet, so the
    log's model itself gives other numbers on this machine (MuJoCo's compiled inertias, or the BLAS that turns
    them into parameters, round differently on another CPU class), and no re-run here can be bit-identical."""
    i = int(np.argwhere(logged != rerun)[0][0])
    ulps = abs(float(logged[i]) - float(rerun[i])) / float(np.spacing(abs(float(logged[i])) or 1.0))
    return (f"verify: MISMATCH before the first step: the true parameters the log's model gives at t = 0 differ "
            f"on this machine (parameter {i}: log {float(logged[i])!r} vs re-run {float(rerun[i])!r}, "
            f"{ulps:.3g} ulp), so the model compiles to other numbers here than on the machine that wrote the log: "
            f"a re-run is bit-identical on that machine's CPU class, not on this one{note}")


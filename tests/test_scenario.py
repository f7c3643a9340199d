"""Scenario validation: every rule rejects bad input with a message naming
the file, the key, what was expected and what came."""
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.errors import AdaptiveMJError, ModelError, ScenarioError
from adaptive_mj.study.sweep import DOCUMENTED_KEYS, to_toml

GOOD = """
schema_version = 1
[plant]
kind = "heave"
backend = "mujoco"
[simulation]
duration = 2.0
timestep = 0.001
initial_state = [1.0, 0.0]
[reference]
kind = "cosine"
[law]
kind = "sliding_adaptive"
lambda = 5.0
k = 200.0
gamma = { d = 0.0025, b = 0.002, c = 0.5 }
"""


def write(tmp_path, text, name="bad.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def load_text(tmp_path, text, **kw):
    return sc.load(write(tmp_path, text), **kw)


def test_good_scenario_loads(tmp_path):
    s = load_text(tmp_path, GOOD)
    assert s.name == "bad" and s.plant.kind == "heave" and s.law.gamma == {"d": 0.0025, "b": 0.002, "c": 0.5}
    assert s.simulation.initial_state == (1.0, 0.0)


@pytest.mark.parametrize("path", sc.bundled(), ids=lambda p: p.stem)
def test_bundled_scenarios_validate_and_build(path):
    s = sc.load(path)
    setup = build(s)
    assert setup.theta_hat0.shape == (len(setup.law.names),)


def test_toml_syntax_error_names_line(tmp_path):
    with pytest.raises(ScenarioError, match=r"bad\.toml: TOML syntax error: .*line 3"):
        load_text(tmp_path, "schema_version = 1\n[plant]\nkind = \n")


@pytest.mark.parametrize("edit, pattern", [
    (("[law]", "[law]\nkk = 3"), r"bad\.toml: unknown key 'law\.kk' \(did you mean 'k'\?\)"),
    (("[reference]", "[referense]\nkind='cosine'\n[reference]"), r"bad\.toml: unknown key 'referense'"),
    (("k = 200.0", 'k = "fast"'), r"bad\.toml: law\.k must be a number, got 'fast'"),
    (("k = 200.0", "k = nan"), r"bad\.toml: law\.k must be a finite number, got nan"),
    (("k = 200.0", "k = inf"), r"bad\.toml: law\.k must be a finite number, got inf"),
    (("lambda = 5.0", "lambda = -1.0"), r"bad\.toml: law\.lambda must be > 0, got -1\.0"),
    (("c = 0.5", "c = 0.0"), r"bad\.toml: law\.gamma\.c must be > 0, got 0\.0"),
    (("gamma = { d = 0.0025, b = 0.002, c = 0.5 }", "gamma = -1"), r"law\.gamma must be > 0, got -1"),
    (("timestep = 0.001", "timestep = 0.0"), r"simulation\.timestep must be > 0, got 0\.0"),
    (("timestep = 0.001", "timestep = 5.0"),
     r"simulation\.timestep must be <= simulation\.duration \(2\.0\), got 5\.0"),
    (("duration = 2.0", "duration = 0"), r"simulation\.duration must be > 0, got 0"),
    (("duration = 2.0", "duration = -3.0"), r"simulation\.duration must be > 0, got -3\.0"),
    (("initial_state = [1.0, 0.0]", "initial_state = [1.0]"),
     r"simulation\.initial_state must be an array of 2 numbers"),
    (('kind = "cosine"', 'kind = "square"'), r"reference\.kind must be one of 'constant', .*got 'square'"),
    (('kind = "sliding_adaptive"', 'kind = "mpc"'), r"law\.kind must be one of .*got 'mpc'"),
    (("schema_version = 1", "schema_version = 7"), r"schema_version must be 1 .*got 7"),
    (("schema_version = 1", ""), r"schema_version is required but missing"),
    (('backend = "mujoco"', 'backend = "mujoco"\npayload_mass = 1.0'),
     r"plant\.payload_mass must be absent unless plant\.kind = 'arm'"),
    (('backend = "mujoco"', 'backend = "mujoco"\ntheta = {d=1.0, b=1.0, c=1.0}'),
     r"plant\.theta must be absent for backend 'mujoco'"),
    (("[law]", "[noise]\nstd = { y = -0.1 }\n[law]"), r"noise\.std\.y must be >= 0, got -0\.1"),
    (("[law]", "[noise]\nstd = { z = 0.1 }\n[law]"), r"unknown key 'noise\.std\.z'"),
    (("[law]", "[[events]]\nt = 3.0\nkind = 'constant_force'\nvalue = 1.0\n[law]"),
     r"events\[0\]\.t must be <= simulation\.duration \(2\.0\), got 3\.0"),
    (("[law]", "[[events]]\nt = 1.0\nkind = 'payload_mass'\nvalue = 1.0\n[law]"),
     r"events\[0\]\.kind must be used only with plant\.kind = 'arm'"),
    (("[law]", "[log]\nrate_hz = 0\n[law]"), r"log\.rate_hz must be > 0, got 0"),
])
def test_invalid_scenarios_name_key_expected_and_got(tmp_path, edit, pattern):
    old, new = edit
    assert old in GOOD
    with pytest.raises(ScenarioError, match=pattern) as err:
        load_text(tmp_path, GOOD.replace(old, new, 1))
    assert str(err.value).startswith(str(tmp_path / "bad.toml"))
    assert "\n" not in str(err.value)


def test_mass_must_be_positive(tmp_path):
    arm = GOOD.replace('kind = "heave"', 'kind = "arm"\npayload_mass = 0.0')
    with pytest.raises(ScenarioError, match=r"plant\.payload_mass must be > 0, got 0\.0"):
        load_text(tmp_path, arm)
    ev = GOOD.replace('kind = "heave"', 'kind = "arm"').replace(
        "[law]", "[[events]]\nt = 1.0\nkind = 'payload_mass'\nvalue = -2.0\n[law]")
    with pytest.raises(ScenarioError, match=r"events\[0\]\.value must be > 0, got -2\.0"):
        load_text(tmp_path, ev)


def test_gamma_keys_must_match_parameters(tmp_path):
    s = load_text(tmp_path, GOOD.replace("gamma = { d = 0.0025, b = 0.002, c = 0.5 }", "gamma = { d = 1.0, b = 1.0 }"))
    with pytest.raises(ScenarioError, match=r"law\.gamma must have the keys d, b, c in that order, got d, b"):
        build(s)


def test_missing_model_file(tmp_path):
    s = load_text(tmp_path, GOOD.replace('backend = "mujoco"', 'backend = "mujoco"\nmodel = "no_such_model"'))
    with pytest.raises(ModelError, match=r"no_such_model\.xml.* not found"):
        build(s)


def test_model_that_fails_to_compile_passes_mujoco_message(tmp_path):
    (tmp_path / "broken.xml").write_text("<mujoco><worldbody><body><geom type='sphere'/></body></worldbody></mujoco2>")
    s = load_text(tmp_path, GOOD.replace('backend = "mujoco"', 'backend = "mujoco"\nmodel = "broken.xml"'))
    with pytest.raises(ModelError, match=r"broken\.xml: MuJoCo could not compile the model: .+"):
        build(s)


def test_model_without_the_needed_joint(tmp_path):
    (tmp_path / "nojoint.xml").write_text(
        "<mujoco><option density='1000'/><worldbody><body><geom type='box' size='.1 .1 .1' mass='1'/>"
        "</body></worldbody></mujoco>")
    s = load_text(tmp_path, GOOD.replace('backend = "mujoco"', 'backend = "mujoco"\nmodel = "nojoint.xml"'))
    with pytest.raises(ModelError, match=r"nojoint\.xml: this plant is one slide joint driven by one motor \(1 degree "
                                         r"of freedom\), the model has 0"):
        build(s)
    s = load_text(tmp_path, GOOD.replace('backend = "mujoco"', 'backend = "mujoco"\njoint = "lift"'))
    with pytest.raises(ModelError, match=r"no joint named 'lift' \(the model has \['heave'\]\)"):
        build(s)


@pytest.mark.parametrize("expr, pattern", [
    ("law.k", r"--set 'law\.k': expected key=value"),
    ("law..k=3", r"key 'law\.\.k' must be a dotted path"),
    ("law.k=[1,", r"value '\[1,' is not a TOML value"),
])
def test_malformed_set_expression(tmp_path, expr, pattern):
    with pytest.raises(ScenarioError, match=pattern):
        load_text(tmp_path, GOOD, overrides=[expr])


def test_set_and_seed_override(tmp_path):
    s = load_text(tmp_path, GOOD, overrides=["law.k=50", "reference.kind=sine", "noise.std={y=0.001}"], seed=7)
    assert s.law.k == 50.0 and s.reference.kind == "sine" and s.noise.seed == 7
    assert s.noise.std == {"y": 0.001}
    with pytest.raises(ScenarioError, match=r"law\.k must be >= 0, got -5"):
        load_text(tmp_path, GOOD, overrides=["law.k=-5"])


def test_initial_state_reference_and_model_estimates(tmp_path):
    text = GOOD.replace("initial_state = [1.0, 0.0]", 'initial_state = "reference"').replace(
        "[law]", "[law]\ninitial_estimates = \"model\"")
    setup = build(load_text(tmp_path, text))
    np.testing.assert_array_equal(setup.theta_hat0, setup.plant.true_theta())
    np.testing.assert_array_equal(setup.plant.observe(), [1.0, 0.0])  # cos(0), -sin(0)


# -- fuzzing: random documents and values raise only the project's own errors --------------------

# Every key the validator reads, dotted, and the words it accepts, so random documents often get
# past the first check and reach the deeper ones.
_KEYS = sorted({f"{section}.{key}" for section, keys in DOCUMENTED_KEYS.items() for key in keys}
               | {f"reference.{key}" for keys in sc._REFERENCE_KEYS.values() for key in keys}
               | {"reference.kind", "name", "description", "schema_version", "events"})
_WORDS = sorted(set(sc.PLANT_KINDS + sc.BACKENDS + sc.INTEGRATORS + sc.REFERENCE_KINDS + sc.LAW_KINDS
                    + sc.DEAD_ZONE_ON + sc.DISTURBANCE_KINDS + sc.EVENT_KINDS + sc.REGRESSORS + sc.STATE_SIGNALS
                    + ("model", "reference", "heave_vehicle", "pendulum_arm", "sphere", "none", "tip",
                       "payload/body", "heave", "thrust", "d", "b", "c", "J", "g_sin", "g_cos", "a", "p")))
_LEAVES = sorted({k.rsplit(".", 1)[-1] for k in _KEYS} | {"t", "kind", "value", "body", "width", "on"} | set(_WORDS))

_names = st.sampled_from(_LEAVES) | st.text(st.characters(codec="utf-8"), min_size=1, max_size=5)
_scalars = st.one_of(
    st.booleans(),
    st.integers(-3, 5),
    st.integers(-2**63, 2**63 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, 0.001, 2.0, 100.0]),
    st.sampled_from(_WORDS),
    st.text(st.characters(codec="utf-8"), max_size=8),
)
_values = st.recursive(_scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_names, inner, max_size=4),
                       max_leaves=10)
# Values of the key's own type, often in range: they get past the type checks to the range and
# consistency checks, and to build() (model compile, joint and actuator look-up, law construction).
_CHOICES = {"plant.kind": sc.PLANT_KINDS, "plant.backend": sc.BACKENDS, "simulation.integrator": sc.INTEGRATORS,
            "reference.kind": sc.REFERENCE_KINDS, "law.kind": sc.LAW_KINDS, "law.dead_zone.on": sc.DEAD_ZONE_ON,
            "disturbance.kind": sc.DISTURBANCE_KINDS, "plant.regressor": sc.REGRESSORS,
            "plant.payload": ("sphere", "none", "nope"), "plant.model": ("heave_vehicle", "pendulum_arm", "nope"),
            "plant.joint": ("heave", "shoulder", "nope"), "plant.actuator": ("thrust", "nope"),
            "plant.site": ("tip", "nope"), "name": ("x", "a b", "../x"), "description": ("", "d")}
_INTS = {"schema_version": st.integers(0, 2), "noise.seed": st.integers(-1, 2**64), "law.order": st.integers(0, 4)}
_ARRAYS = {"plant.ctrl_range", "simulation.initial_state", "reference.amplitudes", "reference.omegas",
           "reference.phases"}
_small = st.floats(-1.0, 100.0) | st.sampled_from([0.0, 1e-9, 1e6])
_thetas = st.one_of(*[st.fixed_dictionaries({n: _small for n in names})
                      for names in (("d", "b", "c"), ("J", "b", "g_sin", "g_cos"), ("a", "b"), ("p",))])
_TABLES = {"plant.theta": _thetas, "law.gamma": _thetas | _small, "law.nominal": _thetas | st.just("model"),
           "law.initial_estimates": _thetas | st.just("model"),
           "noise.std": st.dictionaries(st.sampled_from(sc.STATE_SIGNALS), _small, max_size=3),
           "law.dead_zone": st.fixed_dictionaries({"width": _small}, optional={"on": st.sampled_from(sc.DEAD_ZONE_ON)})}


def _typed(key: str):
    if key in _CHOICES:
        return st.sampled_from(_CHOICES[key])
    if key in _INTS:
        return _INTS[key]
    if key in _ARRAYS:
        return st.lists(st.floats(-2.0, 5.0), min_size=1, max_size=3) | st.just("reference")
    if key in _TABLES:
        return _TABLES[key]
    if key == "events":
        return _events
    return _small
_events = st.lists(st.fixed_dictionaries(
    {"t": st.floats(-1.0, 30.0) | _scalars, "kind": st.sampled_from(sc.EVENT_KINDS) | _scalars},
    optional={"value": st.floats(-3.0, 3.0) | _scalars, "body": st.sampled_from(["payload/body", "nope"]),
              "extra": _scalars}), max_size=3)
_changes = st.lists(st.sampled_from(_KEYS).flatmap(lambda k: st.tuples(st.just(k), st.one_of(_typed(k), _typed(k),
                                                                                        _values))),
                   min_size=1, max_size=3)
_FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _load_and_build(text: str, overrides=(), tmp_path=None):
    """Load (and, when valid, build) a scenario; only AdaptiveMJError may come out."""
    try:
        scn = sc.loads(text, where="fuzz.toml", base_dir=Path(tmp_path or "."), overrides=list(overrides))
        build(scn)
    except AdaptiveMJError as exc:
        assert str(exc) and "\n" not in str(exc).strip() or "MuJoCo" in str(exc)


@_FUZZ
@given(path=st.sampled_from(sc.bundled()),
       changes=_changes)
def test_fuzz_random_values_for_the_real_keys(path, changes):
    _load_and_build(path.read_text(), [f"{key}={to_toml(value)}" for key, value in changes])


@_FUZZ
@given(doc=st.dictionaries(st.sampled_from(_KEYS + ["plant", "simulation", "law", "reference", "noise", "log"])
                           | _names, _values, max_size=12))
def test_fuzz_random_documents(doc):
    tables: dict = {}
    for key, value in doc.items():  # dotted keys become nested tables
        *parents, last = key.split(".") if sc._KEY_RE.match(key) else [key]
        node = tables
        for part in parents:
            node = node.setdefault(part, {}) if isinstance(node.get(part, {}), dict) else {}
        node[last] = value
    text = "\n".join(f"{json.dumps(k)} = {to_toml(v)}" for k, v in tables.items())
    _load_and_build(text)


@_FUZZ
@given(text=st.text(max_size=200) | st.binary(max_size=200).map(lambda b: b.decode("latin-1")))
def test_fuzz_random_text(text):
    _load_and_build(text)


@_FUZZ
@given(exprs=st.lists(st.text(max_size=30), min_size=1, max_size=3))
def test_fuzz_random_set_expressions(exprs):
    _load_and_build(GOOD, exprs)

"""The plant-kind registry (adaptive_mj.plants.kinds): each kind owns its plant.* keys, declared as data and read by
its own reader; the keys are documented in docs/SCENARIOS.md; a kind registered at run time through the same
`register` loads a scenario with no table elsewhere touched."""
import copy
import re
import tomllib
from pathlib import Path

import pytest

from adaptive_mj.errors import ScenarioError
from adaptive_mj.keys import Key, Table
from adaptive_mj.plants import events, heave, kinds, plant_keys
from adaptive_mj.setup import scenario as sc

REPO = Path(__file__).resolve().parents[1]
PROBES = ("__probe__", 1.0, True, [1.0, 2.0], {"x": 1.0})


def _plant_docs() -> str:
    """docs/SCENARIOS.md's [plant] tables (## [plant], ### [plant] (manipulator)) and its `plant.<key>` rows."""
    text = (REPO / "docs" / "SCENARIOS.md").read_text()
    tables = re.findall(r"^#+ \[plant\][^\n]*\n(.*?)(?=^#)", text, re.S | re.M)
    rows = [line for line in text.splitlines() if line.startswith("|") and "`plant." in line]
    return "\n".join(tables + rows)


def _tables() -> dict[str, list[tuple[Path, dict]]]:
    """The bundled scenarios' [plant] tables by plant kind."""
    out: dict[str, list[tuple[Path, dict]]] = {}
    for path in sc.bundled():
        plant = tomllib.loads(path.read_text())["plant"]
        out.setdefault(plant["kind"], []).append((path, plant))
    return out


def _read(kind: kinds.PlantKind, path: Path, plant: dict) -> Table:
    """The kind's reader over a [plant] table; the Table (its `used` keys) after it."""
    t = Table(copy.deepcopy(plant), "plant.", str(path))
    kind.read(t, path.parent)
    return t


def _refused(kind: kinds.PlantKind, path: Path, plant: dict, key: str) -> bool:
    """Whether kind's reader refuses plant.`key` by name (unknown, or absent for/unless a plant kind), given any
    of the probe values in an otherwise valid bundled table (a value of the wrong type may be refused as such
    first)."""
    for probe in PROBES:
        try:
            _read(kind, path, {**plant, key: probe})
        except ScenarioError as exc:
            msg = str(exc)
            if (f"unknown key 'plant.{key}'" in msg or f"plant.{key} must be absent unless plant.kind" in msg
                    or f"plant.{key} must be absent for plant.kind" in msg):
                return True
    return False


def test_every_built_in_kind_has_a_reader_and_a_bundled_scenario():
    tables = _tables()
    for name, kind in kinds.built_in().items():
        assert kind.reader is not None and kind.keys, name
        assert name in tables, f"plant kind {name!r}: no bundled scenario"


def test_every_key_a_reader_reads_is_declared_and_documented_in_scenarios_md():
    """A key a kind's reader reads (on every bundled scenario of it) is one of its declared Keys, or one it
    refuses by name (another kind's, read to be refused), and each declared key is in docs/SCENARIOS.md's [plant]
    tables: a key added in code but not in the docs fails here."""
    docs = _plant_docs()
    for name, cases in _tables().items():
        kind = kinds.built_in()[name]
        for path, plant in cases:
            for key in _read(kind, path, plant).used - set(kind.key_names()):
                assert _refused(kind, path, plant, key), (name, path.name, key)
        for key in kind.key_names():
            assert f"`{key}`" in docs or f"`plant.{key}`" in docs, f"plant.{key} ({name}) not in docs/SCENARIOS.md"


def test_each_kind_accepts_exactly_its_declared_keys():
    """Each declared key is read (given a wrong value, the error is about its value, not that it does not
    belong); every other kind's key, and an unknown one, is refused by name."""
    everything = {k for kind in kinds.built_in().values() for k in kind.key_names()} | {"bogus"}
    for name, cases in _tables().items():
        kind = kinds.built_in()[name]
        path, plant = cases[0]
        accepted = {key for key in everything if not _refused(kind, path, plant, key)}
        assert accepted == set(kind.key_names()), name


def test_event_kinds_come_from_the_plant_kinds():
    assert set(sc.EVENT_KINDS) == {e.name for k in kinds.built_in().values() for e in k.events}
    assert kinds.accepting("payload_mass") == (("arm", "manipulator", "quadrotor"), "mujoco")
    assert kinds.accepting("constant_force")[1] is None


TOY_GAIN = Key("toy_gain", "number", "N", 1.0, "> 0", "a toy kind's own key")


def _toy_late(t: Table, fields: dict) -> dict:
    """The toy kind's own key, into the generic PlantSpec.kind_spec."""
    return {"kind_spec": {"toy_gain": t.number("toy_gain", 1.0, gt=0)}}


@pytest.fixture
def toy_kind():
    """A plant kind registered at run time: the heave vehicle's module and model under another name, with a key
    of its own, accepting constant_force events."""
    kind = kinds.register(kinds.PlantKind(
        "toy_heave", heave.__name__, heave.KIND.forms, output_unit="m", control_unit="N", params=heave.KIND.params,
        default_model="heave_vehicle", doc="a toy kind (tests)",
        keys=plant_keys.keys(TOY_GAIN), reader=plant_keys.SharedReader(theta=heave.theta_names, late=_toy_late),
        events={events.CONSTANT_FORCE: None}))
    yield kind
    kinds.unregister("toy_heave")


def test_a_kind_registered_at_run_time_loads_and_builds_with_no_table_elsewhere(toy_kind):
    from adaptive_mj.setup.build import build

    text = (sc.SCENARIOS_DIR / "heave_tracking.toml").read_text()
    scn = sc.loads(text, overrides=["plant.kind='toy_heave'", "plant.toy_gain=2.5",
                                    "events=[{t=1.0, kind='constant_force', value=-3.0}]"])
    assert scn.plant.kind == "toy_heave" and scn.plant.kind_spec == {"toy_gain": 2.5}
    assert scn.law.kind == toy_kind.default_law and scn.events[0].kind == "constant_force"
    assert build(scn).law.names == build(sc.loads(text)).law.names  # the heave module builds it
    with pytest.raises(ScenarioError, match=r"plant\.toy_gain must be absent unless plant\.kind = 'toy_heave'"):
        sc.loads(text, overrides=["plant.toy_gain=2.5"])
    with pytest.raises(ScenarioError, match=r"plant\.toy_gain must be > 0"):
        sc.loads(text, overrides=["plant.kind='toy_heave'", "plant.toy_gain=-1"])
    with pytest.raises(ScenarioError, match=r"used only with plant\.kind = 'heave' on backend 'mujoco'"):
        sc.loads(text, overrides=["plant.kind='toy_heave'", "events=[{t=1.0, kind='fluid_density_scale', value=2}]"])


def test_list_plants_shows_each_kind_s_declared_keys_and_events(capsys):
    """`list --plants` shows each built-in kind's plant.* keys with units and defaults from its declaration
    (keys.Key.describe, as `list --laws` does) and the [[events]] kinds it accepts."""
    from adaptive_mj.cli import main

    assert main(["list", "--plants"]) == 0
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line and line[0] != "("}
    assert set(lines) == set(kinds.built_in())
    for name, kind in kinds.built_in().items():
        keys = ", ".join(k.describe() for k in kind.keys if k.name != "kind")
        assert f"; keys: {keys}; events: {', '.join(e.name for e in kind.events)}" in lines[name], name
    assert "thruster_time_constant [s]" in lines["heave"] and "g [m/s²] = 9.81" in lines["heave"]
    assert "coulomb_smoothing [rad/s] = 0.01" in lines["manipulator"]


GUSTS: list[tuple[float, float, float]] = []  # (t, value, direction) of each wind_gust the toy plant received


def _gust(e, scn, source):
    """A toy event kind's effect: a force of value along its own field `direction` (±1), recorded."""
    direction = e.params["direction"]

    def apply(plant):
        GUSTS.append((plant.time, e.value, direction))
        plant.force_offset += direction * e.value

    return events.Event(e.t, f"wind gust {direction * e.value:+g} N", apply)


def _direction(t: Table) -> float:
    d = t.number("direction", 1.0)
    if d not in (-1.0, 1.0):
        raise t.fail("direction", "1 or -1", d)
    return d


WIND_GUST = events.EventKind("wind_gust", _gust, value="positive",
                             fields=(events.EventField("direction", _direction, "+1 up, -1 down"),),
                             doc="a toy gust (tests)")


@pytest.fixture
def gusty_kind():
    """A toy plant kind (the heave module under another name) bringing a toy event kind of its own, both
    registered at run time through the same register: no table of event kinds edited."""
    kind = kinds.register(kinds.PlantKind(
        "gusty_heave", heave.__name__, heave.KIND.forms, output_unit="m", control_unit="N", params=heave.KIND.params,
        default_model="heave_vehicle", doc="a toy kind with a toy event kind (tests)",
        keys=plant_keys.keys(), reader=plant_keys.SharedReader(theta=heave.theta_names),
        events={WIND_GUST: None, events.CONSTANT_FORCE: None}))
    GUSTS.clear()
    yield kind
    kinds.unregister("gusty_heave")


def test_a_plant_kind_brings_its_own_event_kind_with_no_table_elsewhere(gusty_kind):
    from adaptive_mj.setup.build import build
    from adaptive_mj.runs.runner import execute

    text = (sc.SCENARIOS_DIR / "heave_tracking.toml").read_text()
    gust = ["plant.kind='gusty_heave'", "simulation.duration=0.05",
            "events=[{t=0.02, kind='wind_gust', value=3.0, direction=-1.0}]"]
    scn = sc.loads(text, overrides=gust)
    assert "wind_gust" in kinds.event_kinds() and kinds.accepting("wind_gust") == (("gusty_heave",), None)
    e = scn.events[0]
    assert (e.kind, e.value, e.params) == ("wind_gust", 3.0, {"direction": -1.0})
    assert "params={'direction': -1.0}" in repr(e)  # shown only when a kind has fields of its own
    assert "params" not in repr(sc.loads(text, overrides=["events=[{t=0.02, kind='constant_force', value=1.0}]"])
                                .events[0])
    assert build(scn).events[0].label == "wind gust -3 N"
    result = execute(scn)
    assert [(v, d) for _, v, d in GUSTS] == [(3.0, -1.0)] and abs(GUSTS[0][0] - 0.02) <= 0.002
    assert result.trajectory.meta["events"] == [(pytest.approx(GUSTS[0][0]), "wind gust -3 N")]
    # its value rule and its own field are checked like a built-in kind's; another plant kind refuses it
    with pytest.raises(ScenarioError, match=r"events\[0\]\.value must be > 0, got -3\.0"):
        sc.loads(text, overrides=gust[:2] + ["events=[{t=0.02, kind='wind_gust', value=-3.0}]"])
    with pytest.raises(ScenarioError, match=r"events\[0\]\.direction must be 1 or -1, got 2\.0"):
        sc.loads(text, overrides=gust[:2] + ["events=[{t=0.02, kind='wind_gust', value=3.0, direction=2.0}]"])
    with pytest.raises(ScenarioError, match=r"events\[0\]\.kind must be used only with plant\.kind = "
                                            r"'gusty_heave' on backend 'mujoco'"):
        sc.loads(text, overrides=["events=[{t=0.02, kind='wind_gust', value=3.0}]"])
    with pytest.raises(ScenarioError, match=r"events\[0\]\.body"):  # it declares no body field
        sc.loads(text, overrides=gust[:2] + ["events=[{t=0.02, kind='wind_gust', value=3.0, body='x'}]"])
    sc.loads(text, overrides=gust[:2] + ["events=[{t=0.02, kind='constant_force', value=3.0}]"])
    kinds.unregister("gusty_heave")
    assert "wind_gust" not in kinds.event_kinds()


def test_what_a_law_sees_of_a_plant_comes_from_its_kind():
    """MRAC's state form (b, the matched terms) is declared by exactly the kinds that offer it; the joint-space
    keys (noise, disturbance, sensors, references) go with the rigid-body form."""
    from adaptive_mj.laws.kinds import Form

    for k in kinds.built_in().values():
        assert (k.mrac_state is not None) == (Form.MRAC_STATE in k.forms), k.name
        assert k.rigid_body == (Form.RIGID_BODY in k.forms) == kinds.is_rigid_body(k.name), k.name


def test_messages_and_units_that_differ_by_kind_come_from_its_declaration():
    """law.order's allowed values (PlantKind.orders_text, carried by the PlantSpec to the law readers), the unit
    of V on a run's plot (PlantKind.lyapunov_unit) and the keys an event overrides (EventKind.overrides, which a
    sweep over plant.payload_mass notes) are declared, not found by a kind's name."""
    from adaptive_mj.study.sweep import sweep_notes

    heave_scn = sc.load(REPO / "scenarios" / "heave_tracking.toml")
    assert heave_scn.plant.orders_text == heave.KIND.orders_text
    assert "orders_text" not in repr(heave_scn.plant)
    with pytest.raises(ScenarioError, match=r"law\.order must be 2, or 3 with plant\.thruster_time_constant for "
                                            r"plant\.kind = 'heave', got 4"):
        sc.load(REPO / "scenarios" / "heave_tracking.toml", overrides=["law.order=4"])
    with pytest.raises(ScenarioError, match=r"law\.order must be 1 for plant\.kind = 'first_order', got 2"):
        sc.load(REPO / "scenarios" / "lecture_first_order.toml", overrides=["law.order=2"])
    assert {k.name: kinds.lyapunov_unit(k.name) for k in kinds.built_in().values()} == {
        k.name: "-" if k.name == "first_order" else "J" for k in kinds.built_in().values()}
    assert kinds.lyapunov_unit(None) == ""
    assert {e.name for k in kinds.built_in().values() for e in k.events if "plant.payload_mass" in e.overrides} \
        == {"payload_mass", "payload_swap"}
    swap = sc.load(REPO / "scenarios" / "ur5e_payload_swap.toml")
    assert any("sets it to payload 'sphere'" in n for n in sweep_notes(swap, ["plant.payload_mass"], 1))

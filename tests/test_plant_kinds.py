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
from adaptive_mj.plants import heave, kinds, plant_keys
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
    assert set(sc.EVENT_KINDS) == {e for k in kinds.built_in().values() for e in k.events}
    assert kinds.accepting("payload_mass") == (("arm", "manipulator"), "mujoco")
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
        events={"constant_force": None}))
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

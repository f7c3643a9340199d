"""The law-kind registry (adaptive_mj.laws.kinds): the forms each law serves and each plant offers, the
scenario loader's refusal in one line, the docs' table generated from it, and the law swap (law=NAME)."""
import re
from pathlib import Path

import pytest

from adaptive_mj.errors import ScenarioError
from adaptive_mj.laws import kinds
from adaptive_mj.plants import kinds as plant_kinds
from adaptive_mj.setup import scenario as sc

REPO = Path(__file__).resolve().parents[1]


def test_scenarios_md_shows_the_registry_table():
    text = (REPO / "docs" / "SCENARIOS.md").read_text()
    block = re.search(r"<!-- law-kinds -->\n(.*?)\n<!-- /law-kinds -->", text, re.S)
    assert block is not None and block.group(1) == plant_kinds.docs_table(), (
        "docs/SCENARIOS.md's law-kinds block is not the registry's: write `python -m adaptive_mj.plants.kinds`'s "
        "output between its <!-- law-kinds --> markers")


def test_the_readme_shows_the_registry_s_plants_and_the_laws_that_serve_them():
    text = (REPO / "README.md").read_text()
    block = re.search(r"<!-- plants-laws -->\n(.*?)\n<!-- /plants-laws -->", text, re.S)
    assert block is not None and block.group(1) == plant_kinds.plants_table(), (
        "the README's plants-laws block is not the registry's: write plant_kinds.plants_table() (printed by "
        "`python -m adaptive_mj.plants.kinds`) between its <!-- plants-laws --> markers")
    assert "| `process` |" in block.group(1) and "`mrac`" in block.group(1)  # every kind, each law where it serves


def test_the_readme_is_a_front_door():
    """Issue 53: the first command within the first 40 lines, at most about 1,500 words."""
    text = (REPO / "README.md").read_text()
    first = next(i for i, line in enumerate(text.splitlines()) if line.startswith("python3 -m venv"))
    assert first < 40 and len(text.split()) <= 1500, (first, len(text.split()))


def test_every_built_in_law_kind_is_documented_with_its_keys_table():
    """Each built-in kind is named in docs/SCENARIOS.md's [law] tables (a kind added to the registry but not
    to the docs fails here)."""
    text = (REPO / "docs" / "SCENARIOS.md").read_text()
    law_tables = "\n".join(re.findall(r"\| `kind` \|[^\n]*", text))
    for name in kinds.BUILT_IN:
        assert f"`{name}`" in law_tables or f"`law.kind` | `{name}`" in text, name


@pytest.mark.parametrize("plant, kind", [("heave_tracking", "slotine_li"), ("ur5e_drift", "sliding_adaptive"),
                                         ("mrac_time_delay", "sliding_adaptive"), ("ur5e_drift", "mrac")])
def test_a_law_offered_to_a_plant_it_does_not_serve_is_refused_in_one_line(plant, kind):
    with pytest.raises(ScenarioError) as exc:
        sc.load(sc.SCENARIOS_DIR / f"{plant}.toml", overrides=[sc.law_swap(kind)])
    msg = str(exc.value)
    assert "\n" not in msg and f"law.kind = {kind!r} serves" in msg and "offers" in msg and "laws that serve it" in msg
    scn = sc.load(sc.SCENARIOS_DIR / f"{plant}.toml")
    served = kinds.serving(scn.plant.kind, plant_kinds.forms(scn.plant.kind), kinds.BUILT_IN)
    assert all(f"{name}" in msg for name in served)


def test_each_plant_kind_is_served_by_its_bundled_scenarios_laws():
    for path in sc.bundled():
        scn = sc.load(path)
        assert kinds.refusal(kinds.BUILT_IN[scn.law.kind], scn.plant.kind, plant_kinds.forms(scn.plant.kind),
                             kinds.BUILT_IN) is None, path.name


def test_law_swap_replaces_the_table_keeps_the_prior_and_takes_scoped_keys():
    path = sc.SCENARIOS_DIR / "heave_tracking.toml"
    base = sc.load(path)
    # a swap to a baseline: the adaptive law's gamma is gone (it would be refused by a law that lacks it)
    with pytest.raises(ScenarioError, match=r"law\.lambda is required but missing"):
        sc.load(path, overrides=[sc.law_swap("fixed_nominal")])
    swapped = sc.load(path, overrides=["law.lambda=3.0", sc.law_swap("fixed_nominal"), "law.k=10.0"])
    assert swapped.law.kind == "fixed_nominal" and swapped.law.lam == 3.0 and swapped.law.k == 10.0
    assert swapped.law.gamma is None and swapped.law.initial_estimates == base.law.initial_estimates
    # the scenario's own law: its table kept; keys scoped to another law dropped, to this one merged
    same = sc.load(path, overrides=[sc.law_swap("sliding_adaptive"), "law.fixed_nominal.k=1.0",
                                    "law.sliding_adaptive.k=123.0"])
    assert same.law.kind == "sliding_adaptive" and same.law.k == 123.0 and same.law.gamma == base.law.gamma
    assert sc.is_law_swap("law=emod") and sc.is_law_swap("law='emod'")
    assert not sc.is_law_swap("law={kind='emod'}") and not sc.is_law_swap("law.kind=emod")


def test_a_plugin_that_raises_is_one_line_naming_it():
    """A plugin's own code raising (an index past its arrays, say) comes out as errors.PluginError naming the
    plugin, where it comes from and when, not as a traceback from inside adaptive-mj."""
    import numpy as np

    from adaptive_mj.errors import PluginError
    from adaptive_mj.form import ModelForm
    from adaptive_mj.laws.plugin import LawPlugin, PluginLaw
    from adaptive_mj.plugins import Installed

    def bad(x, ref, theta, phi, f, h, params, rate):
        return ref[7], 0.0

    inst = Installed("bad", LawPlugin(law=bad), "bad-law", "1.2.3", "0" * 64)
    law = PluginLaw(inst, ModelForm(order=2, p_names=("b",), phi=lambda x: np.array([x[1]])), np.zeros(0))
    with pytest.raises(PluginError, match=r"^law plugin 'bad' \(bad-law 1\.2\.3\) raised at t = 0\.5 s: IndexError: "):
        law(0.5, np.zeros(2), np.zeros(3), np.zeros(2))


def test_a_plugin_written_for_another_order_is_refused():
    from adaptive_mj.laws.plugin import LawPlugin, Param
    from adaptive_mj.plugins import Installed

    inst = Installed("o2", LawPlugin(law=lambda *a: (0.0, 0.0), params=(Param("k", default=1.0),), orders=(2,)),
                     "o2-law", "0.1", "0" * 64)
    t = sc._Table({"kind": "o2"}, "law.", "x.toml")
    plant = sc.load(sc.SCENARIOS_DIR / "lecture_first_order.toml").plant
    with pytest.raises(ScenarioError, match=r"law.kind = 'o2' is written for plants of order 2; plant.kind = "
                                            r"'first_order' here is of order 1"):
        sc._plugin_law(t, "o2", inst, plant, 1)


# Each built-in law kind on a bundled scenario of a plant it serves, with the keys it requires
# each built-in kind's own example (LawKind.example: a bundled scenario and overrides), so a new kind brings its
# case with its module and no table here changes
LAW_CASES = {name: (k.example[0], list(k.example[1])) for name, k in kinds.BUILT_IN.items() if k.example is not None}


def test_every_key_a_law_kind_reads_is_documented(monkeypatch):
    """The keys each built-in law kind's loader asks for (every _Table.get of its [law] table and sub-tables,
    present or not) appear in docs/SCENARIOS.md: a key added in code but not in the docs fails here."""
    assert set(LAW_CASES) == set(kinds.BUILT_IN), "every built-in law kind declares LawKind.example"
    tables: list = []
    real_init = sc._Table.__init__

    def spy(self, data, prefix, where):
        real_init(self, data, prefix, where)
        tables.append(self)

    monkeypatch.setattr(sc._Table, "__init__", spy)
    docs = (REPO / "docs" / "SCENARIOS.md").read_text()
    for kind, (scenario, over) in LAW_CASES.items():
        tables.clear()
        scn = sc.load(sc.SCENARIOS_DIR / f"{scenario}.toml", overrides=over)
        assert scn.law.kind == kind
        named = tuple(f"law.{k}." for k in kinds.table_keys() if k not in ("dead_zone", "composite"))
        keys = {t.key(name) for t in tables if t.prefix.startswith("law.") and not t.prefix.startswith(named)
                for name in t.used}  # (a table keyed by parameter or joint names is not a key of the law)
        for key in sorted(keys):
            short = key.removeprefix("law.")
            documented = f"`{short}`" in docs or f"`{key}`" in docs or f"`{short.rsplit('.', 1)[-1]}`" in docs
            assert documented, f"{kind}: {key} is read by the loader but not in docs/SCENARIOS.md"


def test_a_noise_sized_dead_zone_on_s_takes_a_plugins_lambda_or_says_it_cannot():
    """width_in_noise_std on s needs the surface's slope: law.lambda, or a plugin's own `lambda` key; without
    one, one line (it was a TypeError from float(None) on an arm)."""
    import dataclasses

    from adaptive_mj.setup import build

    scn = sc.load(sc.SCENARIOS_DIR / "heave_drift.toml")
    plugin_law = dataclasses.replace(scn.law, kind="mine", lam=None, plugin_params={"lambda": 7.0, "k": 1.0})
    assert build._surface_slope(dataclasses.replace(scn, law=plugin_law)) == 7.0
    no_slope = dataclasses.replace(plugin_law, plugin_params={"k": 1.0})
    with pytest.raises(ScenarioError, match=r"width_in_noise_std on s needs the surface's slope, and law.kind = "
                                            r"'mine' declares no number key 'lambda'"):
        build._surface_slope(dataclasses.replace(scn, law=no_slope))


def test_a_plugin_declares_only_the_form_its_functions_are_called_in():
    from adaptive_mj.laws.plugin import JointLawPlugin, LawPlugin

    with pytest.raises(ValueError, match=r"LawPlugin.forms must be \('model',\) .*got \('mrac_state',\)"):
        LawPlugin(law=print, forms=("mrac_state",))
    with pytest.raises(ValueError, match=r"JointLawPlugin.forms must be \('rigid_body',\)"):
        JointLawPlugin(law=print, point=print, forms=("model",))
    with pytest.raises(ValueError, match=r"a JointLawPlugin needs point"):
        JointLawPlugin(law=print)
    with pytest.raises(ValueError, match=r"gain 'g' must name a per-parameter Param"):
        LawPlugin(law=print, gain="g")


def _law_tables_read(monkeypatch, scenario: str, over: list[str]) -> set[str]:
    """The keys of [law] itself (not of its sub-tables) the loader asked for, present or not."""
    tables: list = []
    real_init = sc._Table.__init__

    def spy(self, data, prefix, where):
        real_init(self, data, prefix, where)
        tables.append(self)

    monkeypatch.setattr(sc._Table, "__init__", spy)
    sc.load(sc.SCENARIOS_DIR / f"{scenario}.toml", overrides=over)
    monkeypatch.undo()
    return {name for t in tables if t.prefix == "law." for name in t.used}


@pytest.mark.parametrize("kind", sorted(LAW_CASES))
def test_each_law_kind_reads_exactly_the_keys_it_declares(monkeypatch, kind):
    """A built-in kind's declared keys (LawKind.keys: what `list --laws` shows) are the keys its reader takes: a
    key read but not declared, or declared but not read, fails here."""
    scenario, over = LAW_CASES[kind]
    declared = {k.name for k in kinds.built_in()[kind].keys}
    assert len(declared) == len(kinds.built_in()[kind].keys), f"{kind}: a key declared twice"
    read = _law_tables_read(monkeypatch, scenario, over)
    assert read - declared == set(), f"{kind}: read but not declared"
    assert declared - read == set(), f"{kind}: declared but not read"


def test_every_built_in_law_kind_registers_itself_with_keys_a_reader_and_a_builder():
    for name, kind in kinds.built_in().items():
        assert kind.read is not None and kind.build is not None and kind.keys, name
        assert kind.module.startswith("adaptive_mj.laws."), name
    assert set(kinds.table_keys()) == {"gamma", "initial_estimates", "nominal", "theta0", "projection", "dead_zone",
                                   "composite", "lambda", "kd"}


TOY_LAW = '''"""A toy law kind for tests/test_law_kinds.py: fixed-gain PD over the model form,
u = (kp ỹ + kv ỹ') / h(x), with keys of its own (law.kp [u/m], law.kv [u s/m]) that no LawSpec field
holds: LawSpec.params."""
import numpy as np

from adaptive_mj.keys import Key
from adaptive_mj.laws import law_keys as shared
from adaptive_mj.laws.common import LawStep
from adaptive_mj.laws.kinds import Form, LawKind, register
from adaptive_mj.laws.protocol import Law
from adaptive_mj.specs import LawSpec


class ToyPD(Law):
    def __init__(self, form, *, kp, kv):
        self.form, self.order, self.names, self.kp, self.kv = form, form.order, form.names, kp, kv

    def __call__(self, t, x, ref, theta_hat):
        e, de = ref[0] - x[0], ref[1] - x[1]
        return LawStep((self.kp * e + self.kv * de) / self.form.h(x), np.zeros(len(self.names)), e, 0.0)

    def lyapunov(self, s, theta_hat, theta, *, M=None):
        return 0.5 * np.asarray(s, dtype=float) ** 2


def read(t, kind, plant, order):
    law_order = shared.read_order(t, plant, order)
    params = {"kp": t.number("kp", gt=0), "kv": t.number("kv", 10.0, ge=0)}
    initial = shared.read_estimates(t, "initial_estimates")
    t.finish()
    return LawSpec(kind=kind, order=law_order, lam=None, k=0.0, gamma=None, dead_zone=None, initial_estimates=initial,
                   nominal=None, K=None, boundary_layer=None, params=params)


def build(ctx):
    return ToyPD(ctx.model_form(), **ctx.law.params)


KIND = register(LawKind(
    "toy_pd", frozenset({Form.MODEL}), False, "fixed-gain PD (a test's toy)",
    keys=(shared.KIND, shared.ORDER, Key("kp", "number", unit="u/m", bounds="> 0", required=True),
          Key("kv", "number", unit="u s/m", default=10.0, bounds=">= 0"), shared.INITIAL_ESTIMATES),
    read=read, build=build, module=__name__))
'''


def test_a_new_law_kind_lands_by_its_own_module_alone(tmp_path, monkeypatch):
    """Acceptance by construction: a law kind in a module of its own (its law, keys, reader and builder, and its
    register call) is loaded, listed and run, with no table elsewhere touched."""
    import importlib.util

    import numpy as np

    from adaptive_mj.runs.runner import execute

    monkeypatch.setattr(kinds, "_BUILT_IN", kinds.built_in())  # the toy leaves the registry with the test
    path = tmp_path / "toy_pd_law.py"
    path.write_text(TOY_LAW)
    spec = importlib.util.spec_from_file_location("toy_pd_law", path)
    assert spec is not None and spec.loader is not None
    spec.loader.exec_module(importlib.util.module_from_spec(spec))
    assert "toy_pd" in kinds.BUILT_IN and "toy_pd" in kinds.serving("heave", frozenset({kinds.Form.MODEL}),
                                                                     kinds.built_in())
    scn = sc.load(sc.SCENARIOS_DIR / "heave_tracking.toml",
                  overrides=[sc.law_swap("toy_pd"), "law.kp=400.0", "simulation.duration=0.05",
                             "simulation.python_callback=true"])
    assert scn.law.kind == "toy_pd" and scn.law.params == {"kp": 400.0, "kv": 10.0}
    with pytest.raises(ScenarioError, match=r"law\.kv must be >= 0"):
        sc.load(sc.SCENARIOS_DIR / "heave_tracking.toml", overrides=[sc.law_swap("toy_pd"), "law.kp=1.0", "law.kv=-1"])
    with pytest.raises(ScenarioError, match=r"law\.kind = 'toy_pd' serves the 1-DOF model form"):
        sc.load(sc.SCENARIOS_DIR / "ur5e_drift.toml", overrides=[sc.law_swap("toy_pd")])
    result = execute(scn)
    assert result.summary["status"].value == "ok" and result.summary["steps"] == 50
    assert "the law ToyPD" in result.summary["preflight"]["note"]  # the toy's law object is what ran
    assert np.all(np.isfinite(result.trajectory.u))


def test_every_built_in_kind_has_its_place_in_the_order():
    """The docs' tables list the kinds in ORDER; a kind missing there would be listed in the order the modules
    happened to be imported (a test importing the quadrotor first moved it ahead of process control)."""
    assert set(kinds.built_in()) <= set(kinds.ORDER)
    assert set(plant_kinds.built_in()) <= set(plant_kinds.ORDER)

"""What a plant kind declares for the breaking-point study (issue 49, item 5): its laws and stressors on its
StressPlant, beside its keys (adaptive_mj.plants.study_spec), and the study (adaptive_mj.study.stress) only calls
them: the same searches as when the study chose them by the plant's form."""
from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path

import pytest

from adaptive_mj.plants import kinds
from adaptive_mj.study import stress

STUDY_DIR = Path(stress.__file__).parent


def _rows(searches: list[stress.Search]) -> list:
    """Each search as plain data: label, scenario file, overrides, the stressor's name, range, unit, integer and
    step, the tail bound, and the stressor's overrides at its low end, high end and mid (geometric from > 0)."""
    out = []
    for s in searches:
        st = s.stressor
        mid = math.sqrt(st.lo * st.hi) if st.lo > 0 else 0.5 * (st.lo + st.hi)
        out.append([s.label, Path(s.scenario).name, list(s.overrides), st.name, repr(st.lo), repr(st.hi), st.unit,
                    st.integer, repr(st.step), repr(s.tail_bound), [st.overrides(v) for v in (st.lo, st.hi, mid)]])
    return out


_FLOAT = re.compile(r"-?\d+\.\d+(?:e[-+]?\d+)?")


def _digest(data) -> str:
    """sha256 of the data as JSON, every decimal number in it (a float, or one inside an override's text) written to
    10 significant digits: the figures derived from a compiled MuJoCo model (masses, inertias) differ in their last
    bits between CPU classes, the searches do not."""
    text = _FLOAT.sub(lambda m: f"{float(m.group()):.10g}", json.dumps(data, ensure_ascii=True))
    return hashlib.sha256(text.encode()).hexdigest()


def _bench() -> dict:
    return {k: v for k, v in stress.BENCH_SETTINGS.items() if k not in ("seeds", "steps")}


# (search count, sha256 of _rows) of each call, taken from commit e9d9e7b, before the laws and stressors moved from
# study/stress.py (chosen there by the plant's form) into each plant kind's StressPlant (there `plant_laws` was
# arm_laws=("adaptive",), which applied to the 6-joint arm alone). Retaken on 2026-12-07 with _digest's rounding (the
# first digests held the last bits of one CPU class's model figures): e9d9e7b's rows and this code's, both run here,
# were equal value for value in every call below and in the user scenarios' test. Retaken again after issue 52's
# per-axis flight gains (RotorPy's z gains): the quadrotor rows' derived dead-zone width (0.052643 -> 0.052678) and
# e-modification gain (1139.75 -> 1138.99), both computed from the loop's gains, are all that changed (16 rows of the
# composite and geometric studies, compared row by row against 47d32ef); every other row is as before.
STUDIES = {
    "composite": (lambda: stress.study(composite=True),
                  213, "65af767eddb9c858a2db7b2c457038688201f33f9093524f43f534284f94ec0d"),
    "bench": (lambda: stress.study(composite=False, **_bench()),
              106, "b3a07e9e00469c0fe2e1c58fcef610eed90f0b0a2d7ce4784fa53de422cd6676"),
    "law": (lambda: stress.study(composite=False, law="sliding_adaptive"),
            215, "5afe10dc9d5230d5b9b66dd92d289a5e06c513e8ac14a34faf41bedc8d4b8435"),
    "law_filtered": (lambda: stress.study(composite=False, duration=1.0, law="slotine_li",
                                          plant_laws={"ur5e": ("adaptive",)}),
                     151, "5ab18e7314d46d6cdd8e0ac05534bc131c2d60c779b2c173837541350a9eb1a0"),
    "geometric": (lambda: stress.study(composite=True, duration=3.0, law="geometric_adaptive"),
                  221, "478734142338d2616d99383d396e5b3211fb9f5a1b1b34897c129649192a2c6b"),
}


@pytest.mark.parametrize("name", list(STUDIES))
def test_the_study_runs_the_same_searches_as_before_the_kinds_declared_them(name):
    """Every search (its label, scenario, overrides, and its stressor's name, range, unit, step and overrides at
    three values) is as the study made it when it chose laws and stressors by the plant's form (commit e9d9e7b)."""
    make, count, digest = STUDIES[name]
    searches = make()
    assert len(searches) == count
    assert _digest(_rows(searches)) == digest


def test_a_user_s_scenario_gets_the_same_laws_and_stressors_as_before():
    """score --scenario's rows (stress.user_plant on each bundled study scenario): the same laws and stressors as at
    commit e9d9e7b."""
    users = []
    for p in stress.plants():
        u = stress.user_plant(stress.scenario_path(p.scenario))
        users.append([u.name, list(u.base), stress.laws(u, composite=True),
                      _rows([stress.Search(Path(u.scenario), u.name, u.base, st, 0.0)
                             for st in stress.stressors(u, 7.0)])])
    assert _digest(users) == "7a7aeeb810d536580040ab09520e0f55095808ce6ef2a6f26bdd1e62b2792f2a"


def test_each_studied_kind_declares_its_laws_and_stressors_and_the_study_only_calls_them():
    """stress.laws and stress.stressors are the row's own functions of its context, the latter followed by the
    delay and the control period on the row's physics step."""
    for p in stress.plants(4.0):
        row = kinds.built_in()[p.kind].stress
        assert row is not None
        ctx = stress.context(p)
        assert stress.laws(p, composite=True) == row.laws(ctx, True)
        own = row.stressors(ctx, 4.0)
        common = stress.stressors(p, 4.0)[len(own):]
        assert [st.name for st in stress.stressors(p, 4.0)][:len(own)] == [st.name for st in own]
        assert [st.name for st in common] == ["delay", stress.PERIOD]
        assert common[1].lo == common[1].step == ctx.dt


def test_nothing_in_the_study_chooses_laws_or_stressors_by_plant_kind_or_form():
    """No study module tests a plant's form or kind to pick its laws or stressors (the kinds declare them)."""
    for path in sorted(STUDY_DIR.glob("*.py")):
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"_on_joints|_on_airframe|OWN_STRESSORS|_arm_laws|_airframe_laws", text), path.name
    assert "Form." not in (STUDY_DIR / "stress.py").read_text(encoding="utf-8")


def test_a_user_s_quadrotor_scenario_is_held_by_a_hover_at_its_start(tmp_path):
    """score --scenario on a quadrotor: the hold task is the kind's declared hold (StressPlant.hold), a hover at the
    reference's start y_d(0), and that override loads; the 1-DOF arm's is a constant at its y_d(0)."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build
    from adaptive_mj.study.score import scenario_row

    text = (sc.SCENARIOS_DIR / "quadrotor_lemniscate.toml").read_text().replace(
        'payload = "quad_box"', 'payload = "quad_box"\npayload_mass = 0.01')
    path = tmp_path / "my_quad.toml"
    path.write_text(text)
    hold = {t.name: t for t in scenario_row(path, 5.0).tasks}["hold"]
    start = build(sc.load(path)).reference(0.0, 0)[0]
    assert start[0] == 0.0 and start[2] == 1.0  # the figure-eight starts at its center
    held = hold.overrides[-1].replace("{{", "{").replace("}}", "}")
    assert held == "reference={kind='hover', center=[" + ", ".join(repr(float(v)) for v in start) + "]}"
    scn = sc.load(path, overrides=[*hold.overrides[:-1], held])
    assert scn.reference.kind == "hover" and list(build(scn).reference(3.0, 0)[0]) == list(start)
    arm = sc.SCENARIOS_DIR / "arm_payload_swap.toml"
    y0 = float(build(sc.load(arm)).reference(0.0, 0)[0])
    assert {t.name: t for t in scenario_row(arm, 5.0).tasks}["hold"].overrides[-1] == (
        f"reference={{{{kind='constant', value={y0!r}}}}}")

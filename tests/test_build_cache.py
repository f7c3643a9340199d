"""What a study's runs share inside one process (issue 20: the per-run Python cost): the compiled model
kept per MJCF text and edit, one scratch MjData per model layout, the parsed scenario text, the step times
by cumulative sum, and the whole-chunk divergence check. Each must give exactly what it replaced."""
from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from adaptive_mj.data import MODELS, SCENARIOS
from adaptive_mj.plants import arm, heave
from adaptive_mj.plants.mujoco_plant import compile_spec, layout, scratch_data
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim import loop
from adaptive_mj.sim.stage import step_times

HEAVE_XML = (MODELS / "heave_vehicle.xml").read_text()


def _arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    return {name: np.array(getattr(model, name)) for name in dir(model)
            if not name.startswith("_") and isinstance(getattr(model, name), np.ndarray)}


def _same_model(a: mujoco.MjModel, b: mujoco.MjModel) -> None:
    arrays_a, arrays_b = _arrays(a), _arrays(b)
    assert arrays_a.keys() == arrays_b.keys()
    for name, value in arrays_a.items():
        np.testing.assert_array_equal(value, arrays_b[name], err_msg=name)
    assert layout(a) == layout(b)


def test_compile_cache_gives_a_copy_equal_to_a_fresh_compile():
    first, xml1 = compile_spec(HEAVE_XML, where="heave")
    first.body_mass[1] = 99.0  # the caller's own model: editing it leaves the cache alone
    second, xml2 = compile_spec(HEAVE_XML, where="heave")
    assert second is not first and xml1 == xml2
    assert second.body_mass[1] != 99.0
    fresh = mujoco.MjSpec.from_string(HEAVE_XML)
    fresh.nuserdata = 1
    _same_model(second, fresh.compile())


def test_compile_cache_keys_an_edit_by_its_key_and_never_caches_an_unkeyed_one():
    calls = []

    def lag(tau):
        def edit(spec):
            calls.append(tau)
            for act in spec.actuators:
                act.dyntype = mujoco.mjtDyn.mjDYN_FILTER
                act.dynprm[0] = tau
        return edit

    a, _ = compile_spec(HEAVE_XML, where="heave", edit=lag(0.05), edit_key=("lag", 0.05))
    b, _ = compile_spec(HEAVE_XML, where="heave", edit=lag(0.05), edit_key=("lag", 0.05))
    c, _ = compile_spec(HEAVE_XML, where="heave", edit=lag(0.2), edit_key=("lag", 0.2))
    assert calls == [0.05, 0.2]  # the second 0.05 came from the cache
    assert a.actuator_dynprm[0, 0] == b.actuator_dynprm[0, 0] == 0.05 and c.actuator_dynprm[0, 0] == 0.2
    compile_spec(HEAVE_XML, where="heave", edit=lag(0.05))
    compile_spec(HEAVE_XML, where="heave", edit=lag(0.05))
    assert calls == [0.05, 0.2, 0.05, 0.05]  # no key: compiled each time


def test_scratch_data_serves_every_model_of_a_layout_and_gives_what_a_new_mjdata_gives(monkeypatch):
    model = compile_spec(HEAVE_XML, where="heave")[0]
    other = compile_spec(HEAVE_XML, where="heave")[0]
    other.qpos0[0] = 0.3  # same layout, other numbers
    data = scratch_data(model)
    data.qpos[0] = 7.0
    data.time = 3.0
    assert scratch_data(other) is data  # one MjData per layout
    assert data.qpos[0] == 0.3 and data.time == 0.0  # reset for the model it is asked for
    pendulum = arm.compile_arm()
    assert scratch_data(pendulum) is not data
    # true θ through a used scratch equals the one a new MjData gives, bit for bit
    mujoco.mj_step(pendulum, scratch_data(pendulum), nstep=10)
    scratch_data(pendulum).qpos[:] = 1.0
    theta_arm, theta_heave = arm.true_theta(pendulum), heave.true_theta(other)
    monkeypatch.setattr(arm, "scratch_data", mujoco.MjData)
    monkeypatch.setattr(heave, "scratch_data", mujoco.MjData)
    np.testing.assert_array_equal(theta_arm, arm.true_theta(pendulum))
    np.testing.assert_array_equal(theta_heave, heave.true_theta(other))


@pytest.mark.parametrize("t0, h, rows", [(0.0, 1e-3, 5000), (12.345, 1e-3, 999), (0.1, 2.5e-4, 4000),
                                         (7.0, 0.002, 1)])
def test_step_times_are_mujocos_accumulated_times_bit_for_bit(t0, h, rows):
    model = compile_spec(HEAVE_XML, where="heave")[0]
    model.opt.timestep = h
    data = mujoco.MjData(model)
    data.time = t0
    seen = np.empty(rows)
    for i in range(rows):
        seen[i] = data.time
        mujoco.mj_step(model, data)
    np.testing.assert_array_equal(step_times(t0, h, rows), seen)


def test_parsed_scenario_text_is_not_shared_between_runs():
    path = SCENARIOS / "heave_drift.toml"
    a = sc.load(path, overrides=["law.k=123"])
    b = sc.load(path)
    assert a.law.k == 123 and b.law.k != 123
    table = "law.gamma={ d = 1.0, b = 2.0, c = 3.0 }"  # a parsed value that is a dict, twice
    first, again = sc.load(path, overrides=[table]), sc.load(path, overrides=[table])
    assert first.law.gamma == again.law.gamma
    assert sc.load(path).law.gamma == b.law.gamma


@pytest.mark.parametrize("bad", ["nan_x", "inf_u", "bound", "nan_theta_next", "none"])
def test_whole_chunk_divergence_check_agrees_with_the_row_by_row_one(bad):
    setup = build(sc.load(Path(SCENARIOS / "heave_drift.toml")))
    plant = setup.plant
    n = 50
    rng = np.random.default_rng(1)
    x, u = rng.normal(size=(n, 2)), rng.normal(size=n)
    theta_hat, theta_next = rng.normal(size=(n, 3)), rng.normal(size=3)
    bound = 10.0
    if bad == "nan_x":
        x[17, 1] = math.nan
    elif bad == "inf_u":
        u[30] = math.inf
    elif bad == "bound":
        x[40, 0] = 11.0
    elif bad == "nan_theta_next":
        theta_next[1] = math.nan
    keep, reason = loop.first_divergence(plant, x, u, theta_hat, theta_next, bound)
    expected = {"nan_x": 17, "inf_u": 31, "bound": 40, "nan_theta_next": n, "none": None}[bad]
    assert keep == expected
    assert (reason == "") == (bad == "none")

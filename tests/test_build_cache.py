"""What a study's runs share inside one process (issue 20: the per-run Python cost): the compiled model
kept per MJCF text and edit, one scratch MjData per model layout, the MjData of ended runs, the parsed and
the validated scenario text, the step times by cumulative sum, and the whole-chunk divergence check.
Each must give exactly what it replaced."""
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
from adaptive_mj.sim.driver import first_divergence
from adaptive_mj.sim.stage import step_times
from test_manipulator_runs import SERVO_ARM  # a two-link arm driven by position servos

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


def _rows(traj):
    return [traj.t, traj.x, traj.u, traj.s, traj.ref, traj.theta_hat, traj.theta, traj.V]


@pytest.mark.parametrize("name, first, short", [
    ("heave_drift", ["noise.std={y=1e-3, y_dot=1e-2}"], []),
    ("arm_payload_swap", ["simulation.duration=20.5"], ["events=[]"])])
def test_a_run_on_a_released_mjdata_gives_the_rows_of_a_new_one(name, first, short, monkeypatch):
    from adaptive_mj.plants import mujoco_plant
    from adaptive_mj.runs.runner import execute

    path = SCENARIOS / f"{name}.toml"
    scn = sc.load(path, overrides=["simulation.duration=2", *short], seed=3)
    monkeypatch.setattr(mujoco_plant, "_spare", mujoco_plant.OrderedDict())
    fresh = execute(scn)
    assert not mujoco_plant._spare or all(len(v) == 1 for v in mujoco_plant._spare.values())
    # another run first (noise, or the payload swap's mass change at 20 s): its MjData, released, serves the next
    execute(sc.load(path, overrides=first, seed=5))
    reused_data = next(iter(mujoco_plant._spare.values()))[-1]
    taken = []
    run_data = mujoco_plant.run_data
    monkeypatch.setattr(mujoco_plant, "run_data", lambda model: taken.append(run_data(model)) or taken[-1])
    again = execute(scn)
    assert taken[0] is reused_data
    assert fresh.summary["status"] == again.summary["status"] == "ok"
    for a, b in zip(_rows(fresh.trajectory), _rows(again.trajectory), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_plant_built_outside_a_run_never_takes_a_spare_mjdata(monkeypatch):
    """Only runner.start's plants reuse an ended run's MjData: whoever else builds a plant (dm_env, a user's
    build) gets a new one, whose `.model` is its own model (dm_control's Physics reads data.model)."""
    from adaptive_mj.plants import mujoco_plant
    from adaptive_mj.runs.runner import execute

    monkeypatch.setattr(mujoco_plant, "_spare", mujoco_plant.OrderedDict())
    scn = sc.load(SCENARIOS / "heave_drift.toml", overrides=["simulation.duration=0.05"])
    execute(scn)
    spare = next(iter(mujoco_plant._spare.values()))
    assert len(spare) == 1
    plant = build(scn).plant
    assert plant.data is not spare[0] and len(spare) == 1
    assert plant.data.model is plant.model


def test_a_released_plant_has_no_mjdata_left():
    setup = build(sc.load(SCENARIOS / "heave_drift.toml"))
    plant = setup.plant
    plant.release()
    with pytest.raises(AttributeError):
        plant.data.qpos  # noqa: B018 (the access is the test)


@pytest.mark.parametrize("seed", [None, 0, 7, 10**12])
@pytest.mark.parametrize("overrides", [(), ("law.k=150",), ("noise.std={y=1e-3}", "noise.seed=3")])
def test_validated_scenario_kept_per_process_equals_a_fresh_validation(seed, overrides):
    path = SCENARIOS / "heave_drift.toml"
    text = path.read_text()
    kept = sc.load(path, overrides=list(overrides), seed=seed, keep=True)
    again = sc.load(path, overrides=list(overrides), seed=seed, keep=True)
    fresh = sc._loads(text, where=str(path), base_dir=path.parent, default_name=path.stem, overrides=overrides,
                      seed=seed)
    assert kept == fresh and again == fresh
    assert kept.noise.seed == (seed if seed is not None else fresh.noise.seed)


def test_only_a_study_keeps_validated_scenarios(tmp_path, monkeypatch):
    """Outside a study (keep False: the CLI's run, a notebook) every load validates again and sees the
    files as they are now: a payload file created in the current directory after a first load (which
    fell back to the place next to the scenario) is found by the next. A study's kept scenario does not
    look again (documented in scenario.loads)."""
    (tmp_path / "s").mkdir()
    scenario = tmp_path / "s" / "arm.toml"
    scenario.write_text((SCENARIOS / "arm_payload_swap.toml").read_text())
    monkeypatch.chdir(tmp_path)
    payload = ["plant.payload='mine.xml'"]
    before = sc._validated.cache_info()
    first = sc.load(scenario, overrides=payload, seed=1)
    kept_first = sc.load(scenario, overrides=payload, seed=1, keep=True)
    (tmp_path / "mine.xml").write_text((MODELS / "payloads" / "sphere.xml").read_text())
    second = sc.load(scenario, overrides=payload, seed=1)
    kept_second = sc.load(scenario, overrides=payload, seed=1, keep=True)
    next_to_scenario = str(tmp_path / "s" / "mine.xml")
    assert first.plant.payload == kept_first.plant.payload == kept_second.plant.payload == next_to_scenario
    assert second.plant.payload == str(tmp_path / "mine.xml")
    after = sc._validated.cache_info()
    assert (after.misses - before.misses, after.hits - before.hits) == (1, 1)  # only the two kept loads


def test_validated_scenario_cache_keeps_errors_and_the_current_directory_apart(tmp_path, monkeypatch):
    path = SCENARIOS / "heave_drift.toml"
    with pytest.raises(sc.ScenarioError, match="noise.seed must be an integer >= 0, got -1"):
        sc.load(path, seed=-1, keep=True)  # not the cached path: the same error as ever
    with pytest.raises(sc.ScenarioError, match="noise must be a table"):
        sc.load(path, overrides=["noise=3"], seed=1, keep=True)
    # a model path given with --set is resolved against the current directory: another directory, another result
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    model = (MODELS / "heave_vehicle.xml").read_text()
    for sub in ("a", "b"):
        (tmp_path / sub / "mine.xml").write_text(model)
    loaded = []
    for sub in ("a", "b"):
        monkeypatch.chdir(tmp_path / sub)
        loaded.append(sc.load(path, overrides=["plant.model=mine.xml"], seed=1, keep=True).plant.model)
    assert loaded == [(tmp_path / "a" / "mine.xml").resolve(), (tmp_path / "b" / "mine.xml").resolve()]


@pytest.mark.parametrize("bad", ["nan_x", "inf_u", "bound", "nan_theta_next", "none"])
def test_the_divergence_check_keeps_the_rows_to_the_first_bad_step(bad):
    """driver.first_divergence, the one check every path runs (a compiled chunk of many steps, the Python path's
    chunk of one): the rows kept end at the first step whose next state, control or next estimate is bad."""
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
    x_next = np.concatenate([x[1:], plant.observe()[None]])
    keep, reason = first_divergence(x_next, u, np.vstack([theta_hat[1:], theta_next[None]]), bound)
    expected = {"nan_x": 17, "inf_u": 31, "bound": 40, "nan_theta_next": n, "none": None}[bad]
    assert keep == expected
    assert (reason == "") == (bad == "none")


def test_a_composed_arm_is_kept_until_a_file_it_read_changes(tmp_path):
    from adaptive_mj.plants import attach

    arm_file, payload_file = tmp_path / "arm.xml", tmp_path / "box.xml"
    arm_file.write_text((MODELS / "pendulum_arm.xml").read_text())
    payload_file.write_text((MODELS / "payloads" / "sphere.xml").read_text())
    first = attach.compose(arm_file, payload_file, payload_mass=0.7, site="tip")
    assert attach.compose(arm_file, payload_file, payload_mass=0.7, site="tip") == first
    assert first == attach._compose(arm_file, payload_file, 0.7, "tip", [])  # what composing again gives
    assert attach.compose(arm_file, payload_file, payload_mass=0.9, site="tip") != first  # another key
    unscaled = attach.compose(arm_file, payload_file, payload_mass=None, site="tip")
    text = payload_file.read_text()
    payload_file.write_text(text.replace('mass="', 'mass="9', 1)[:len(text)])  # the same size, same key
    changed = attach.compose(arm_file, payload_file, payload_mass=None, site="tip")
    assert changed != unscaled and changed == attach._compose(arm_file, payload_file, None, "tip", [])
    assert 'mass="9' in changed[1]["payload.xml"].decode()


SERVO_SCENARIO = """schema_version = 1
[plant]
kind = "manipulator"
model = "my_arm.xml"
payload = "sphere"
servo_to_torque = true
[simulation]
duration = 1.0
[reference]
kind = "joint_sum_of_sines"
center = { shoulder = 0.3, elbow = -0.6 }
amplitudes = { shoulder = [0.2], elbow = [0.2] }
omegas = { shoulder = [1.0], elbow = [1.5] }
[law]
kind = "slotine_li"
lambda = 10.0
kd = 10.0
gamma = 0.2
"""


def test_a_6_joint_edit_answered_by_the_compile_cache_gives_its_notes_and_refusals_again(tmp_path):
    """The manipulator's model edit (servo_to_torque, friction, torque limits) is cached with what it
    returned: the second build of the same scenario has the same notes, and a refused key is refused again."""
    from adaptive_mj.errors import ScenarioError

    (tmp_path / "my_arm.xml").write_text(SERVO_ARM)
    path = tmp_path / "servo.toml"
    path.write_text(SERVO_SCENARIO)
    first, second = (build(sc.load(path)) for _ in range(2))
    assert first.notes and first.notes == second.notes
    assert first.notes[0].startswith("plant.servo_to_torque: servo(s) rebuilt as torque motors: 'shoulder_servo'")
    _same_model(first.plant.model, second.plant.model)
    for _ in range(2):
        with pytest.raises(ScenarioError, match=r"plant\.torque_limit names joint 'wrist_9'"):
            build(sc.load(path, overrides=["plant.torque_limit={wrist_9=4.0}"]))


def test_sampled_reference_positions_are_kept_per_reference_and_never_shared():
    from adaptive_mj.reference import JointSumOfSines
    from adaptive_mj.setup.success import reference_positions, sampled_positions

    ref = JointSumOfSines(center=(0.1, -0.2), amplitudes=((0.3, 0.1), (0.2,)), omegas=((1.0, 2.5), (0.7,)))
    fresh = reference_positions(ref, np.linspace(0.0, 3.0, 101), 2)
    kept = sampled_positions(ref, 3.0, 101, 2)
    np.testing.assert_array_equal(kept, fresh)
    kept[:] = 0.0  # the caller's copy
    np.testing.assert_array_equal(sampled_positions(ref, 3.0, 101, 2), fresh)
    other = JointSumOfSines(center=(0.1, -0.2), amplitudes=((0.3, 0.1), (0.2,)), omegas=((1.0, 2.5), (0.8,)))
    assert not np.array_equal(sampled_positions(other, 3.0, 101, 2), fresh)

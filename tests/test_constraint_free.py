"""MuJoCo's constraint pipeline is switched off only where no constraint can arise (plants.mujoco_plant
.constraint_free), and then every step is the same bit for bit."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants.mujoco_plant import constraint_free, skip_empty_constraints
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.setup.scenario import SCENARIOS_DIR

OFF = int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)


def _model(body: str) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(f"<mujoco><worldbody>{body}</worldbody></mujoco>")


FREE = '<body><joint type="slide" axis="0 0 1"/><geom size="0.1" contype="0" conaffinity="0"/></body>'


@pytest.mark.parametrize("body, free", [
    (FREE, True),
    # two colliding geoms on one body never touch; on two bodies they may
    ('<body><joint type="slide"/><geom size="0.1"/><geom size="0.1" pos="0 0 0.1"/></body>', True),
    ('<geom type="plane" size="1 1 0.1"/><body><joint type="slide"/><geom size="0.1"/></body>', False),
    ('<body><joint type="slide" range="-1 1" limited="true"/><geom size="0.1" contype="0" conaffinity="0"/></body>',
     False),
    ('<body><joint type="slide" frictionloss="0.1"/><geom size="0.1" contype="0" conaffinity="0"/></body>', False),
    # contype of one meets conaffinity of the other
    ('<geom type="plane" size="1 1 0.1" contype="2" conaffinity="0"/>'
     '<body><joint type="slide"/><geom size="0.1" contype="0" conaffinity="2"/></body>', False),
], ids=["no_geom_collides", "one_body", "floor", "limit", "frictionloss", "bits_meet"])
def test_constraint_free(body, free):
    assert constraint_free(_model(body)) is free


@pytest.mark.parametrize("name, off", [("heave_tracking", True), ("ur5e_payload_swap", True),
                                       ("ship_loading", True), ("quadrotor_hover_payload", False)])
def test_bundled_models(name, off):
    """The heave vehicle, the UR5e (its payload's two colliding geoms are on one body) and the ship step without the
    pipeline; the quadrotor (a floor) with it."""
    plant = build(sc.load(SCENARIOS_DIR / f"{name}.toml")).plant
    assert bool(int(plant.model.opt.disableflags) & OFF) is off


@pytest.mark.parametrize("name", ["heave_thruster_n3", "ur5e_payload_swap"])
def test_steps_are_the_same_bit_for_bit(name):
    """2000 RK4 steps under a varying control with the pipeline off and on: the same state, bit for bit."""
    model = build(sc.load(SCENARIOS_DIR / f"{name}.toml")).plant.model
    states = []
    for flags in (int(model.opt.disableflags) | OFF, int(model.opt.disableflags) & ~OFF):
        model.opt.disableflags = flags
        data = mujoco.MjData(model)
        data.qvel[:] = 0.3
        for k in range(2000):
            data.ctrl[:] = np.sin(0.01 * k)
            mujoco.mj_step(model, data)
        states.append(np.concatenate([data.qpos, data.qvel, data.act, data.qacc]))
    assert np.array_equal(states[0], states[1])
    assert skip_empty_constraints(model) and int(model.opt.disableflags) & OFF

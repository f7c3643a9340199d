"""Every bundled MJCF compiles and steps cleanly; the heave file's derivation holds.

Mirrors models/: each models/*.xml on its own, and the arm with every payload
in models/payloads/ attached through adaptive_mj.plants.arm.compile_arm.
"""
from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from adaptive_mj.plants import arm, heave

MODELS = Path(__file__).resolve().parents[1] / "models"
MODEL_FILES = sorted(MODELS.glob("*.xml"))
PAYLOAD_FILES = sorted((MODELS / "payloads").glob("*.xml"))
N_STEPS = 1000


def _step_without_warnings(model: mujoco.MjModel, *, drive: bool) -> mujoco.MjData:
    """Step N_STEPS; with drive=True apply a smooth in-range control on every actuator."""
    data = mujoco.MjData(model)
    for i in range(N_STEPS):
        if drive and model.nu:
            lo, hi = model.actuator_ctrlrange.T
            limited = model.actuator_ctrllimited.astype(bool)
            amp = np.where(limited, 0.25 * (hi - lo), 1.0)
            mid = np.where(limited, 0.5 * (hi + lo), 0.0)
            data.ctrl[:] = mid + amp * np.sin(2 * np.pi * i * model.opt.timestep)
        mujoco.mj_step(model, data)
    numbers = np.array([data.warning[i].number for i in range(len(data.warning))])
    bad = {mujoco.mjtWarning(i).name: int(n) for i, n in enumerate(numbers) if n}
    assert not bad, f"MuJoCo warnings after {N_STEPS} steps: {bad}"
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    assert data.time == pytest.approx(N_STEPS * model.opt.timestep)
    return data


def test_models_found():
    names = {p.name for p in MODEL_FILES}
    assert {"heave_vehicle.xml", "pendulum_arm.xml"} <= names
    assert {"sphere.xml", "box_offset.xml"} <= {p.name for p in PAYLOAD_FILES}


@pytest.mark.parametrize("drive", [False, True], ids=["passive", "driven"])
@pytest.mark.parametrize("path", MODEL_FILES, ids=lambda p: p.name)
def test_model_compiles_and_steps_without_warning(path, drive):
    model = mujoco.MjModel.from_xml_path(str(path))
    _step_without_warnings(model, drive=drive)


@pytest.mark.parametrize("drive", [False, True], ids=["passive", "driven"])
@pytest.mark.parametrize("payload", PAYLOAD_FILES, ids=lambda p: p.stem)
def test_arm_with_payload_compiles_and_steps_without_warning(payload, drive):
    # by bundled name and by path: both spellings must give the same model
    model = arm.compile_arm(payload=payload.stem)
    by_path = arm.compile_arm(payload=str(payload))
    assert model.nbody == by_path.nbody == 4  # world, link, attachment frame, payload body
    np.testing.assert_array_equal(model.body_mass, by_path.body_mass)
    pid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "payload/body")
    assert pid >= 0
    _step_without_warnings(model, drive=drive)


def test_heave_file_derivation_is_consistent():
    """gravcomp = rho*V/m with V the hull box volume, and the vehicle is heavier than water."""
    model = mujoco.MjModel.from_xml_path(str(heave.MODEL_PATH))
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "vehicle")
    hull = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "hull")
    assert body >= 0 and hull >= 0
    assert model.geom_type[hull] == mujoco.mjtGeom.mjGEOM_BOX
    assert model.geom_bodyid[hull] == body
    v_box = 8.0 * float(np.prod(model.geom_size[hull]))  # full sides = 2 * half sizes [m^3]
    buoyant_mass = float(model.opt.density) * v_box  # rho V [kg]
    gravcomp_mass = float(model.body_gravcomp[body] * model.body_mass[body])
    assert gravcomp_mass == pytest.approx(buoyant_mass, rel=1e-12)
    # heavier than water: c = m - rho V > 0, both from the raw model and from true_theta
    assert model.body_mass[body] - buoyant_mass > 0
    c = heave.true_theta(model)[2]
    assert c > 0
    assert c == pytest.approx(model.body_mass[body] - buoyant_mass, rel=1e-12)

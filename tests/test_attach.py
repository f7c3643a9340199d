"""plants/attach.py composes arm + payload as MJCF text for MuJoCo's own attach. The model it
compiles to is the one dm_control's PyMJCF composed before (every array of the compiled MjModel,
names included, bit for bit), for the bundled arms and payloads and for an arm and payloads that
use what PyMJCF treated specially: unnamed elements, <include>, a mesh under meshdir, euler
angles under another compiler setting, a site with an orientation and a body after it."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from adaptive_mj.errors import ModelError
from adaptive_mj.plants.arm import MODELS, PAYLOADS, build_arm_xml
from adaptive_mj.plants.mujoco_plant import spec_from_text

REPO = Path(__file__).resolve().parents[1]

TET = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
INCLUDED = """<mujoco>
  <actuator><motor joint="j2" gear="2"/></actuator>
  <worldbody><body pos="1 0 0"><geom size=".05" mass=".2"/></body></worldbody>
</mujoco>"""
ARM = """<mujoco>
  <compiler meshdir="meshes"/>
  <include file="included.xml"/>
  <default><geom rgba="1 0 0 1"/><default class="big"><geom size=".1"/></default></default>
  <asset><mesh file="tet.obj"/><material name="m1" rgba="0 1 0 1"/></asset>
  <worldbody>
    <light pos="0 0 3"/>
    <body pos="0 0 1">
      <joint type="hinge" axis="0 1 0" damping=".1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -.4" size=".02" mass="1"/>
      <body pos="0 0 -.4"><joint name="j2" axis="1 0 0"/><geom type="mesh" mesh="tet" mass=".3"/>
        <site name="s0" pos="0 0 -.1"/>
      </body>
      <site name="tip" pos="0 0 -.4" euler="10 20 30"/>
      <body name="after" pos=".1 0 -.2"><joint axis="0 0 1"/><geom class="big" mass=".1"/></body>
    </body>
  </worldbody>
  <actuator><motor joint="j2"/></actuator>
</mujoco>"""
PAYLOAD = """<mujoco model="x">
  <default><geom rgba="0 0 1 1" friction="0.5 0.01 0.01"/></default>
  <asset><material name="pm" rgba="1 1 0 1"/></asset>
  <worldbody>
    <body name="body" euler="0 0 45"><geom type="box" size=".05 .03 .02" mass=".7" pos=".03 0 0" material="pm"/>
      <geom type="sphere" size=".02" mass=".2" pos="0 .05 0" euler="30 0 0"/><site pos="0 0 .1"/></body>
    <body pos="0 0 .2"><geom type="sphere" size=".01" mass=".05"/></body>
  </worldbody>
</mujoco>"""
# its own compiler setting (radian), which PyMJCF applied to the arm as well, and a mesh of its own
MESH_PAYLOAD = """<mujoco>
  <compiler meshdir="m" angle="radian"/>
  <asset><mesh file="tool.obj" scale="2 2 2"/></asset>
  <worldbody><body name="body"><geom type="mesh" mesh="tool" mass="0.9"/>
    <geom type="sphere" size=".02" mass=".1" euler="0.5 0 0"/></body></worldbody>
</mujoco>"""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("attach")
    (d / "meshes").mkdir()
    (d / "meshes" / "tet.obj").write_text(TET)
    (d / "included.xml").write_text(INCLUDED)
    (d / "arm.xml").write_text(ARM)
    (d / "payload.xml").write_text(PAYLOAD)
    (d / "p2" / "m").mkdir(parents=True)
    (d / "p2" / "m" / "tool.obj").write_text(TET)
    (d / "p2" / "mesh_payload.xml").write_text(MESH_PAYLOAD)
    return d


def _pymjcf(arm, payload, payload_mass, site):
    """The composition as adaptive-mj did it with PyMJCF (before plants/attach.py)."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from dm_control import mjcf

    root = mjcf.from_path(str(arm))
    if payload is not None:
        load = mjcf.from_path(str(payload))
        load.model = "payload"
        if payload_mass is not None:
            geoms = load.find_all("geom")
            total = sum(float(g.mass) for g in geoms)
            for g in geoms:
                g.mass = float(g.mass) * payload_mass / total
        root.find("site", site).attach(load)
    return mujoco.MjModel.from_xml_string(root.to_xml_string(), root.get_assets())


def _differences(a: mujoco.MjModel, b: mujoco.MjModel) -> list[str]:
    out = [f for f in dir(a) if not f.startswith("_") and isinstance(getattr(a, f), np.ndarray)
           and not np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)]
    out += [f"opt.{f}" for f in dir(a.opt) if not f.startswith("_")
            and not np.array_equal(getattr(a.opt, f), getattr(b.opt, f))]
    return out


def _cases(files):
    bundled = [(MODELS / arm, PAYLOADS / f"{p}.xml" if p else None, m, "tip")
               for arm in ("ur5e_arm.xml", "pendulum_arm.xml")
               for p in ("sphere", "box_offset", "tool_offset", None)
               for m in ((None, 2.3, 1 / 3) if p else (None,))]
    return bundled + [(files / "arm.xml", files / "payload.xml", None, "tip"),
                      (files / "arm.xml", files / "payload.xml", 2.5, "tip"),
                      (files / "arm.xml", PAYLOADS / "sphere.xml", None, "s0"),
                      (files / "arm.xml", files / "p2" / "mesh_payload.xml", 1.7, "tip"),
                      (files / "arm.xml", None, None, "tip")]


def test_the_compiled_model_is_pymjcfs_bit_for_bit(files):
    for arm, payload, mass, site in _cases(files):
        xml, assets = build_arm_xml(arm=arm, payload=payload, payload_mass=mass, site=site)
        want = _pymjcf(arm, payload, mass, site)
        for got in (spec_from_text(xml, assets).compile(), mujoco.MjModel.from_xml_string(xml, assets)):
            assert _differences(want, got) == [], (arm.name, payload and payload.name, mass, site)


def test_the_text_is_self_contained_and_the_same_each_time(files, tmp_path):
    """A log embeds (xml, assets): compiled anywhere, from nothing else, it is the same model."""
    xml, assets = build_arm_xml(arm=files / "arm.xml", payload=files / "p2" / "mesh_payload.xml", payload_mass=1.7)
    assert (xml, assets) == build_arm_xml(arm=files / "arm.xml", payload=files / "p2" / "mesh_payload.xml",
                                          payload_mass=1.7)
    assert str(files) not in xml and not any(str(files) in k for k in assets)
    here = Path.cwd()
    try:
        os.chdir(tmp_path)
        assert _differences(spec_from_text(xml, assets).compile(), mujoco.MjModel.from_xml_string(xml, assets)) == []
    finally:
        os.chdir(here)


@pytest.mark.parametrize("payload, kwargs, message", [
    (PAYLOAD.replace(' mass=".05"', ""), {"payload_mass": 1.0}, r"every payload geom needs a mass attribute"),
    (PAYLOAD, {"site": "flange"}, r"arm\.xml: no site named 'flange' to attach the payload to \(the model has "
                                  r"sites \['s0', 'tip'\]"),
    (MESH_PAYLOAD.replace('angle="radian"', 'angle="degree"').replace('meshdir="m" ', ""), {"arm": "radian"},
     r"p\.xml: cannot attach the payload: its <compiler> angle='degree' conflicts with the arm's angle='radian'"),
    ("<mujoco><worldbody>", {}, r"p\.xml: could not parse the MJCF: no element found"),
])
def test_errors_are_one_line_naming_the_file(files, tmp_path, payload, kwargs, message):
    arm = files / "arm.xml"
    if kwargs.pop("arm", None):
        arm = tmp_path / "arm.xml"
        arm.write_text((MODELS / "pendulum_arm.xml").read_text())
    (tmp_path / "p.xml").write_text(payload)
    if "mesh" in payload:
        (tmp_path / "m").mkdir()
        (tmp_path / "m" / "tool.obj").write_text(TET)
        (tmp_path / "p.xml").write_text(payload.replace('<compiler ', '<compiler meshdir="m" '))
    with pytest.raises(ModelError, match=message) as info:
        build_arm_xml(arm=arm, payload=tmp_path / "p.xml", **kwargs)
    assert "\n" not in str(info.value)


def test_a_6_joint_run_imports_neither_pymjcf_nor_scipy_linalg(tmp_path):
    """Start-up (issue 18): the payload is attached without dm_control, and numba's registries load
    without its BLAS probe (numba_util.load_registries), which imported all of scipy.linalg."""
    code = ("import sys\nfrom adaptive_mj.cli import main\n"
            "main(['run', 'ur5e_identification', '--set', 'simulation.duration=0.002', '-o', sys.argv[1]])\n"
            "print(sorted(m for m in ('dm_control', 'scipy.linalg') if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "run.mcap")], cwd=REPO, capture_output=True,
                         text=True, check=True, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert (tmp_path / "run.mcap").is_file()  # it ran (exit 1: 2 ms do not identify the payload)
    assert out.stdout.strip().splitlines()[-1] == "[]"

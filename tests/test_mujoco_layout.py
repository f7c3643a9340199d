"""MuJoCo's struct offsets come from its introspection (adaptive_mj.sim.mujoco_layout); a live struct's memory
agrees with them field by field, and an untested MuJoCo version is checked against a live probe first."""
from __future__ import annotations

import ctypes

import mujoco
import pytest

from adaptive_mj.sim import mujoco_layout


def test_every_array_pointer_of_a_live_mjdata_and_mjmodel_lies_where_introspection_says():
    off = mujoco_layout.introspected()
    assert mujoco_layout.scan(off) == {}
    m = mujoco.MjModel.from_xml_string(mujoco_layout._PROBE)
    d = mujoco.MjData(m)
    checked = set()
    for name in mujoco_layout.pointer_fields("mjData"):
        a = getattr(d, name, None)
        held = ctypes.c_uint64.from_address(d._address + off[name]).value
        if hasattr(a, "ctypes") and a.size and held != 0:  # 0: an arena array, allocated only during a step
            assert held == a.ctypes.data, name
            checked.add(name)
    assert len(checked) >= 60
    from adaptive_mj.sim.native_context import MUJOCO_FIELDS, Offsets

    # the fields the callbacks read, but act (the probe has no actuator state: size 0)
    assert set(Offsets._fields) - set(MUJOCO_FIELDS) - {"act"} <= checked
    g = ctypes.c_double * 3
    assert tuple(g.from_address(m._address + off["model.gravity"])) == tuple(m.opt.gravity)
    assert ctypes.c_uint64.from_address(m._address + off["model.body_mass"]).value == m.body_mass.ctypes.data


def test_the_tested_version_is_the_pinned_one():
    assert mujoco.__version__.startswith(mujoco_layout.TESTED)


def test_an_untested_version_is_checked_against_a_live_struct_and_corrected(monkeypatch):
    true = mujoco_layout.introspected()
    wrong = dict(true, qvel=true["qvel"] + 8)  # as if a field had been added before qvel
    monkeypatch.setattr(mujoco, "__version__", "9.0.0")
    monkeypatch.setattr(mujoco_layout, "introspected", lambda: dict(wrong))
    mujoco_layout.offsets.cache_clear()
    try:
        with pytest.warns(RuntimeWarning, match=r"\['qvel'\] disagree"):
            got = mujoco_layout.offsets()
        assert got["qvel"] == true["qvel"] and got == true
    finally:
        mujoco_layout.offsets.cache_clear()


def test_a_type_without_a_layout_is_named():
    from mujoco.introspect import ast_nodes

    with pytest.raises(TypeError, match="no C layout known"):
        mujoco_layout._ctype(ast_nodes.ValueType("long double"))

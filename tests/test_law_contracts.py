"""The named contracts between a law and the code that reads it: the 1-DOF laws' gains as a record whose
fields are the gains dataclass's (what the compiled callback reads by name), and the feedback gains the
pre-flight check and the analyses read through Law.feedback() instead of probing attributes."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from adaptive_mj.form import ModelForm
from adaptive_mj.laws import (DeadZone, DeadZoneOn, FirstOrderAdaptiveLaw, FixedNominalLaw, Law, Modification,
                              RobustSlidingLaw, SlidingAdaptiveLaw)
from adaptive_mj.laws.common import as_record, record_dtype
from adaptive_mj.laws.mrac import MracLaw
from adaptive_mj.laws.plugin import PLUGIN_GAINS, PluginGains
from adaptive_mj.laws.protocol import JointFeedback, SurfaceFeedback
from adaptive_mj.laws.sliding import SLIDING_GAINS, SlidingGains
from adaptive_mj.laws.slotine_li import SlotineLiLaw
from adaptive_mj.plants.heave import heave_form

FORM = heave_form(9.81)
GAMMA = [0.0025, 0.002, 0.5]


@pytest.mark.parametrize(("cls", "dtype"), [(SlidingGains, SLIDING_GAINS), (PluginGains, PLUGIN_GAINS)])
def test_a_gains_record_has_the_dataclass_fields_by_name_and_in_order(cls, dtype):
    fields = dataclasses.fields(cls)
    assert dtype.names == tuple(f.name for f in fields)
    kinds = {"float": np.float64, "bool": np.bool_}
    assert all(dtype.fields[f.name][0] == np.dtype(kinds[str(f.type)]) for f in fields)


def test_the_record_holds_the_law_s_gains_bit_for_bit():
    law = SlidingAdaptiveLaw(FORM, lam=5.0, k=200.0, gamma=GAMMA, dead_zone=DeadZone(0.1, DeadZoneOn.TRACKING_ERROR),
                             modification=Modification(sigma=0.3, e_mod=0.7), saturation=(-150.0, 150.0))
    gains = law.gains()
    record = law.native_params()["gains"]
    assert record.dtype == SLIDING_GAINS and record.shape == (1,)
    for name in SLIDING_GAINS.names:
        value = getattr(gains, name)
        assert record[0][name] == value and type(value) in (float, bool), name
    assert gains == SlidingGains(k=200.0, dz_width=0.1, K=0.0, boundary_layer=1.0, sigma=0.3, e_mod=0.7,
                                 sat_lo=-150.0, sat_hi=150.0, adapt=True, dz_on_s=False, freeze=True)
    robust = RobustSlidingLaw(FORM, lam=5.0, k=200.0, K=30.0, boundary_layer=0.005).gains()
    assert (robust.K, robust.boundary_layer, robust.adapt, robust.freeze, robust.sat_hi) == (30.0, 0.005, False,
                                                                                              False, math.inf)


def test_record_dtype_takes_scalars_only():
    @dataclasses.dataclass
    class Bad:
        k: float
        gamma: np.ndarray

    with pytest.raises(TypeError, match="Bad.gamma"):
        record_dtype(Bad)

    @dataclasses.dataclass
    class Good:
        k: float
        n: int
        on: bool

    out = as_record(Good(1.5, 3, True), record_dtype(Good))
    assert (out[0]["k"], out[0]["n"], out[0]["on"]) == (1.5, 3, True)


def test_the_native_callback_refuses_a_record_of_another_layout():
    from adaptive_mj.plants import heave
    from adaptive_mj.sim.native_mujoco import Controller as NativeController

    plant = heave.load()
    law = SlidingAdaptiveLaw(plant.form, lam=5.0, k=200.0, gamma=GAMMA)
    params = law.native_params()
    law.native_params = lambda: {**params, "gains": np.zeros(1, dtype=PLUGIN_GAINS)}  # type: ignore[method-assign]
    with pytest.raises(TypeError, match="record array of"):
        NativeController(plant, law, None, np.zeros(3), 10)


def test_feedback_is_declared_by_each_law():
    sliding = SlidingAdaptiveLaw(FORM, lam=5.0, k=200.0, gamma=GAMMA).feedback()
    assert sliding == SurfaceFeedback(k=200.0, lam=5.0, effective=200.0, surface_rate=5.0, keys="law.k")
    robust = RobustSlidingLaw(FORM, lam=5.0, k=200.0, K=30.0, boundary_layer=0.005).feedback()
    assert robust.effective == 200.0 + 30.0 / 0.005 and robust.keys == "law.k (+ law.K / law.boundary_layer)"
    assert FixedNominalLaw(FORM, lam=5.0, k=200.0).feedback().effective == 200.0
    first_order = ModelForm(order=1, p_names=("a",), phi=lambda x: np.array([x[0]]), d_name=None)
    first = FirstOrderAdaptiveLaw(first_order, k=2.0, gamma=1.0).feedback()
    assert first == SurfaceFeedback(k=2.0, lam=None, effective=2.0, surface_rate=0.0, keys="law.k")
    joints = SlotineLiLaw(lambda v, w, a: (np.zeros((2, 1)), np.zeros(2)), ("p",), 2, lam=[1.0, 2.0], kd=[3.0, 4.0])
    fb = joints.feedback()
    assert isinstance(fb, JointFeedback)
    np.testing.assert_array_equal(fb.kd, [3.0, 4.0])
    np.testing.assert_array_equal(fb.lam, [1.0, 2.0])
    mrac = MracLaw(order=1, alpha=[2.0], beta=2.0, gamma=1.0)
    assert mrac.feedback() is None and mrac.adapt  # the protocol's defaults

    class Mine(Law):
        order, names = 1, ("a",)

    assert Mine().feedback() is None and Mine().adapt

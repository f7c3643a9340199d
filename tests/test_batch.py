"""Many runs in one mujoco.batch.Batch (adaptive_mj.sim.batch): each run's rows, events and status
are those loop.run gives it alone, bit for bit, on the heave vehicle, the 1-DOF arm and the 6-joint
arm, with noise, events that change a run's own model, real-robot conditions and sampled-data
control; a run that diverges ends alone and the others go on."""
from __future__ import annotations

import numpy as np
import pytest

from adaptive_mj.setup.build import build
from adaptive_mj.setup.scenario import SCENARIOS_DIR, load
from adaptive_mj.sim.batch import run_batch
from adaptive_mj.sim.loop import run

FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")


def _spec(name: str, overrides) -> dict:
    scn = load(SCENARIOS_DIR / f"{name}.toml", overrides=list(overrides))
    s = build(scn)
    return dict(plant=s.plant, law=s.law, reference=s.reference, duration=scn.simulation.duration,
                theta_hat0=s.theta_hat0, noise_std=s.noise_std, rng=s.rng, events=s.events,
                state_bound=scn.simulation.state_bound, control_delay=scn.simulation.control_delay,
                control_mode=scn.control.mode, control_period=scn.control.period, sensors=s.sensors)


def _same(cases):
    single = [run(**_spec(n, o)) for n, o in cases]
    batched = run_batch([_spec(n, o) for n, o in cases], nthread=2)
    for a, b in zip(single, batched, strict=True):
        assert (a.status, a.reason, a.meta["events"]) == (b.status, b.reason, b.meta["events"])
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    return batched


def test_heave_runs_with_noise_and_events_match_their_single_runs():
    out = _same([("heave_tracking", ["simulation.duration=2", f"law.k={k}", f"noise.seed={sd}",
                                     "noise.std={y=0.001, y_dot=0.01}",
                                     f"events=[{{t={t}, kind='constant_force', value=20.0}}]"])
                 for k, sd, t in ((150, 0, 0.5), (250, 1, 1.2), (200, 2, 0.77))])
    assert all(tr.meta["native"] and tr.status == "ok" for tr in out)


def test_arm_runs_whose_events_change_their_own_models_match():
    """payload_mass changes one run's model mid-run: the batch steps each run on its own MjModel."""
    out = _same([("arm_payload_swap", ["simulation.duration=2", f"noise.seed={sd}",
                                       f"events=[{{t=1.0, kind='payload_mass', value={mass}}}]"])
                 for sd, mass in ((0, 2.0), (1, 0.25))])
    assert not np.array_equal(out[0].theta[-1], out[1].theta[-1])


def test_six_joint_runs_with_real_robot_conditions_and_sampled_control_match():
    base = ["simulation.duration=1.0", "events=[{t=0.5, kind='payload_swap', payload='sphere'}]",
            "noise.std={q=1e-4}", "sensors={encoder_counts=65536, velocity='differentiated'}",
            "disturbance={kind='noise', magnitude=0.5}"]
    _same([("ur5e_payload_swap", base + extra) for extra in
           ([], ["law.kd=40.0"], ["control.mode='sampled'", "control.period=0.002"])])


def test_a_diverging_run_ends_alone():
    cases = [("heave_tracking", ["simulation.duration=1", "simulation.state_bound=0.05"]),  # leaves its bound
             ("heave_tracking", ["simulation.duration=1"])]
    out = _same(cases)
    assert out[0].status == "diverged" and "beyond the bound 0.05" in out[0].reason and len(out[0].t) < 1000
    assert out[1].status == "ok" and len(out[1].t) == 1000


def test_runs_of_different_callbacks_are_refused():
    with pytest.raises(ValueError, match="different compiled callback"):
        run_batch([_spec("heave_tracking", ["simulation.duration=0.1"]),
                   _spec("arm_payload_swap", ["simulation.duration=0.1", "events=[]"])])

"""The quadrotor in the breaking-point study (`adaptive-mj stress`) and the scorecard (`adaptive-mj score`): its
laws and stressors derived from its model, a crash judged a failure, and a card that ranks the adaptive law above
the geometric baseline on robustness, with the control period n/a for L1."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from adaptive_mj.study import api, stress
from adaptive_mj.study.breaking_point import TAIL_BOUND
from adaptive_mj.study.job import RunSpec, RunOutcome
from adaptive_mj.study.job import passes
from adaptive_mj.trajectory import Status


def _row() -> stress.Plant:
    (p,) = [p for p in stress.plants(5.0) if p.name == "quadrotor"]
    return p


def test_the_quadrotor_row_has_the_flight_laws_and_disturbances_derived_from_its_model():
    p = _row()
    laws = dict(stress.laws(p, composite=False))
    assert list(laws) == ["adaptive", "adaptive_inertia", "dead_zone", "sigma", "e_modification", "projection",
                          "l1_geometric", "geometric"]
    assert laws["geometric"] == ["law.kind='geometric'", "law.nominal='model'"]  # the oracle baseline
    by = {st.name: st for st in stress.stressors(p, 5.0)}
    assert list(by) == ["noise σ_y", "wind", "force", "torque", "payload added", "rotor loss", "delay",
                        "control period"]
    # the payload's mass from the compiled model (10 g): v is added to it at 1 s, up to the 28 g the rotors lift
    added = by["payload added"]
    assert added.hi == pytest.approx(0.018, abs=1e-12)
    (event,) = added.overrides(0.005)
    assert event.startswith("events=[{t=1.0, kind='payload_mass', value=0.015")
    labels = {(s.label, s.stressor.name) for s in stress.study(composite=False, duration=5.0,
                                                              plant_names=("quadrotor",))}
    assert ("quadrotor/l1_geometric", "control period") not in labels  # L1's filters: continuous control only
    assert ("quadrotor/adaptive", "control period") in labels and len(labels) == 8 * 8 - 1
    assert stress.BENCH_SETTINGS["plant_names"] == ("heave", "arm", "ur5e")  # the bench has its own section


def test_a_crashed_run_fails_whatever_its_tail_error():
    """A crash (status "crashed", or an older row's "failed" with a crash's reason) fails whatever its figures."""
    job = RunSpec(Path("x.toml"))
    summary = {"status": "failed", "reason": "", "metrics": {"rms_tracking_error_tail": 0.001}}
    assert passes(RunOutcome(job, Status.FAILED, summary), tail_bound=TAIL_BOUND["quadrotor"])
    reason = "crashed at t = 1.2 s: tilted 85.0 deg, past plant.crash_tilt = 80 deg"
    crashed = {**summary, "status": "crashed", "reason": reason}
    older = {**summary, "reason": reason}
    for r in (RunOutcome(job, Status.CRASHED, crashed), RunOutcome(job, Status.FAILED, older)):
        run = r
        assert run.crashed and not run.completed and run.status == Status.CRASHED
        assert run.tail_error == math.inf  # the tail of a run cut short is not the run's
        assert not passes(r) and not passes(r, tail_bound=TAIL_BOUND["quadrotor"])


@pytest.fixture(scope="module")
def card(tmp_path_factory):
    return api.score("geometric_adaptive", label="mine", plants="quadrotor", against=["geometric", "l1_geometric"],
                     seeds=2, out=tmp_path_factory.mktemp("quad") / "card")


def test_the_scorecard_ranks_the_adaptive_law_above_the_geometric_baseline_on_the_quadrotor(card):
    assert card.exit_code == 0 and card.plants == ["quadrotor"]
    assert card.laws("quadrotor") == ["mine", "l1_geometric", "geometric"]  # the registry's order
    r_mine, r_geo = (card.figure("quadrotor", law, "robustness") for law in ("mine", "geometric"))
    # measured (2 seeds): R 0.58 against 0.27; the geometric law at the true parameters has no integral action, so a
    # payload's added weight alone takes it past the 2 cm bound (its margin sits near the bottom of the range: 1.10 g
    # measured with RotorPy's z gain of 0.45 N/m, whose sag Δm g / k_x,z reaches 2 cm at 0.92 g)
    assert r_mine.mean > r_geo.mean + 0.15, (r_mine, r_geo)
    assert 0.001 <= card.margin("quadrotor", "geometric", "payload added").mean < 0.0015
    assert card.margin("quadrotor", "mine", "payload added").mean > 0.01
    # every task finished without a crash, and the adaptive law met the tracking and hold bounds
    assert card.figure("quadrotor", "mine", "success").mean == 1.0
    assert card.figure("quadrotor", "mine", "tail_error").mean < TAIL_BOUND["quadrotor"]
    # L1's filters integrate in the stage states: the control period is n/a for it, not a failure
    data = card.data["plants"]["quadrotor"]["laws"]
    assert "control period" not in data["l1_geometric"]["stressors"]
    assert "control period" in data["mine"]["stressors"]
    assert "n/a" in (card.out / "scorecard.md").read_text()
    assert math.isfinite(card.figure("quadrotor", "l1_geometric", "robustness").mean)
    # the card lists what it did not run, and why: the same rule for every law
    (left,) = card.data["runs"]["not_run"]
    assert (left["plant"], left["law"], left["stressor"], left["seeds"], left["status"]) == (
        "quadrotor", "l1_geometric", "control period", 2, Status.NOT_RUN)
    assert "Not run: 1 searches of 2 seeds each (quadrotor/l1_geometric: control period): a law with filters" in \
        (card.out / "scorecard.md").read_text()


def test_stress_plants_narrows_the_study_and_refuses_an_unknown_plant_in_one_line(tmp_path):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "stress", "--plants", "quadrotr", "-o",
                        str(tmp_path / "a")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().splitlines() == [
        "adaptive-mj: error: --plants: 'quadrotr' is not a plant of the study (expected one of heave, arm, ur5e, "
        "quadrotor)"], r.stderr
    assert not (tmp_path / "a").exists()

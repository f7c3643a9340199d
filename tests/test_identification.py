"""What a run identified (adaptive_mj.report.identification, report.metrics.body_identification's physical check,
success.physical): hand-computed values and edge cases by name."""
from __future__ import annotations

import math

import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.errors import ScenarioError
from adaptive_mj.report import identification as ident
from adaptive_mj.report.metrics import body_identification
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.success import Criteria, judge

BODY = tuple(f"load.{k}" for k in ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"))


def test_relative_errors_by_hand_and_a_zero_truth_against_the_largest():
    rel = ident.relative_errors(("a", "b", "c"), [2.2, -0.5, 0.3], [2.0, -1.0, 0.0])
    assert rel["a"] == pytest.approx(0.1, rel=1e-12) and rel["b"] == pytest.approx(0.5, rel=1e-12)
    assert rel["c"] == pytest.approx(0.3 / 2.0, rel=1e-12)  # θ_c = 0: relative to max |θ| = 2
    assert math.isnan(ident.relative_errors(("a",), [1.0], [0.0])["a"])  # every truth 0: no scale
    out = ident.identification(("a", "b", "c"), [2.09, -0.5, 0.0], [2.0, -1.0, 0.0])
    assert out["identified"] == ["a", "c"] and out["off"] == ["b"] and "not_excited" not in out


def test_excitation_names_a_zero_column_and_two_columns_the_motion_cannot_tell_apart():
    t = np.linspace(0.0, 6.0, 64)
    orthogonal = np.stack([np.sin(t), np.cos(t)], axis=1)[:, None, :] * np.array([3.0, 0.01])  # units drop out
    ex = ident.excitation(orthogonal, ("p", "q"))
    assert ex["not_excited"] == [] and 0.9 < ex["index"] <= 1.0
    same = np.stack([np.sin(t), 2.0 * np.sin(t), np.cos(t)], axis=1)[:, None, :]  # p and q: one direction
    ex = ident.excitation(same, ("p", "q", "r"))
    assert ex["not_excited"] == ["p", "q"] and ex["index"] == pytest.approx(0.0, abs=1e-9)
    zero = np.stack([np.sin(t), np.zeros_like(t)], axis=1)[:, None, :]
    ex = ident.excitation(zero, ("p", "q"))
    assert ex["not_excited"] == ["q"] and ex["index"] == 0.0


def _body(m, h=(0.0, 0.0, 0.0), inertia=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)):
    return np.array([m, *h, *inertia])


def test_a_point_mass_on_the_edge_of_the_physical_set_is_a_possible_body():
    """A point mass at the origin: pseudo-inertia diag(0, 0, 0, m), smallest eigenvalue exactly 0 (the set's edge)."""
    e = body_identification(BODY, _body(2.0), _body(2.0))["load"]
    assert e["impossible"] == "" and e["not_physical"] == 0.0 and e["pseudo_inertia_min_eigenvalue"] == 0.0


def test_an_inertia_no_body_has_is_flagged_with_its_smallest_eigenvalue():
    """Ixx = 1 > Iyy + Izz = 0.2 (about the origin, no offset): Σ = ½ tr(I) − I has Σxx = 0.6 − 1 = −0.4."""
    truth = _body(1.0, inertia=(0.2, 0.0, 0.2, 0.0, 0.0, 0.2))
    bad = _body(1.0, inertia=(1.0, 0.0, 0.1, 0.0, 0.0, 0.1))
    e = body_identification(BODY, bad, truth)["load"]
    assert e["pseudo_inertia_min_eigenvalue"] == pytest.approx(-0.4, abs=1e-12) and e["not_physical"] == 1.0
    assert e["impossible"].startswith("its pseudo-inertia is not positive semidefinite (smallest eigenvalue -0.4)")
    neg = body_identification(BODY, _body(-0.5), truth)["load"]
    assert neg["impossible"] == "a negative mass (-0.5 kg)" and neg["not_physical"] == 1.0
    rows = body_identification(BODY, np.stack([truth, bad, bad, truth]), np.stack([truth] * 4))["load"]
    assert rows["not_physical"].tolist() == [0.0, 1.0, 1.0, 0.0]
    # a diverged run's estimate (inf, NaN): no eigenvalues, nothing claimed (its status says it diverged)
    gone = body_identification(BODY, np.stack([bad, np.full(10, np.inf)]), np.stack([truth] * 2))["load"]
    assert gone["not_physical"].tolist() == [1.0, 0.0] and math.isnan(gone["pseudo_inertia_min_eigenvalue"][1])


def test_success_physical_fails_a_run_whose_body_estimate_is_impossible():
    summary = {"metrics": {"rms_tracking_error_tail": 0.001,
                           "identification": {"load": {"impossible": "a negative mass (-0.5 kg)"}}}, "final": {}}
    assert judge(summary, Criteria(tail_rms=(0.01,), tail_rule="")) == []
    missed = judge(summary, Criteria(tail_rms=(0.01,), tail_rule="", physical=True))
    assert missed == ["the final estimate of body load is no possible body: a negative mass (-0.5 kg) "
                      "(success.physical)"]
    path = sc.SCENARIOS_DIR / "ur5e_identification.toml"
    assert sc.load(path, overrides=["success.physical=true"]).success.physical is True
    with pytest.raises(ScenarioError, match=r"success\.physical"):
        sc.load(path, overrides=["success.physical=1"])


def test_a_set_point_run_says_which_parameters_it_did_not_excite(tmp_path, capsys):
    """heave_drift holds y_d = 0: ψ = [y_d'', −y_d'|y_d'|, −g] has two zero columns over the tail, so d and b are
    not excited (their estimates say nothing); c, the weight's, is. A tracking run excites all three."""
    assert main(["run", "heave_drift", "-o", str(tmp_path / "a.mcap"), "--set", "simulation.duration=4",
                 "--set", "noise.std={y=0.0, y_dot=0.0}", "--json"]) in (0, 1)
    import json

    summary = json.loads(capsys.readouterr().out)
    assert summary["identification"]["not_excited"] == ["d", "b"]
    assert summary["identification"]["excitation_index"] == 0.0
    assert main(["run", "heave_tracking", "-o", str(tmp_path / "b.mcap"), "--set", "simulation.duration=4"]) == 0
    out = capsys.readouterr().out
    assert "identification (within 5 % of the truth): " in out and "every parameter excited over the tail" in out

"""Tests that catch the bugs that matter (issue 35, "Tests that would catch the bugs that matter"): each sits
where a plausible mistake would pass the rest of the suite: a verifier that stops comparing a field, an
encoder that truncates, a verdict off by one ulp at its bound, a loosened gain check, a resume that runs
finished failures again, an MIT filter that reads one RK4 stage."""
from __future__ import annotations

import dataclasses
import math
import shutil

import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.setup import scenario

FIELDS = ("t", "x", "u", "s", "ref", "theta_hat", "theta", "V")


# --- (a) replay --verify on a log with one value moved by one ulp ----------------------------------------
@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """A short 1-DOF log and a short 6-joint log, both ok (exit 0 before the nudge), written once."""
    from adaptive_mj.runs.runner import execute

    root = tmp_path_factory.mktemp("verify")
    out = {}
    for name, overrides in (("heave_tracking", ["simulation.duration=0.3", "success.tail_rms=inf"]),
                            ("ur5e_payload_swap", ["simulation.duration=0.1", "events=[]", "success.tail_rms=inf"])):
        scn = scenario.load(scenario.SCENARIOS_DIR / f"{name}.toml", overrides=overrides)
        out[name] = root / f"{name}.mcap"
        execute(scn, log_path=out[name])
    return out


def _nudged(run, field: str, row: int):
    """The LoggedRun with the last element of `field` at `row` moved one ulp up (as a bit flip in the file,
    or a re-run that rounded once differently, would leave it)."""
    values = getattr(run.trajectory, field).copy()
    cell = (row, *(n - 1 for n in values.shape[1:]))
    values[cell] = np.nextafter(values[cell], np.inf)
    assert np.sum(values != getattr(run.trajectory, field)) == 1
    return dataclasses.replace(run, trajectory=dataclasses.replace(run.trajectory, **{field: values}))


@pytest.mark.parametrize("name", ["heave_tracking", "ur5e_payload_swap"])
@pytest.mark.parametrize("field", FIELDS)
def test_replay_verify_fails_on_one_ulp_in_any_field_naming_field_and_row(logs, name, field, monkeypatch, capsys):
    """`replay --verify` on a log whose one value (field by field: t, x, u, s, ref, θ̂, θ, V) is one ulp off:
    exit 1 and "MISMATCH in <field> at row <row>"; the untouched log is bit-identical (exit 0)."""
    from adaptive_mj.log import replay

    path = logs[name]
    run = replay.read_log(path)
    row = len(run.trajectory) - 3  # not row 0: θ there is the model's own check ("before the first step")
    assert np.all(np.isfinite(getattr(run.trajectory, field)[row]))  # a NaN would stay NaN
    assert main(["replay", str(path), "--verify"]) == 0
    assert "verify: bit-identical" in capsys.readouterr().out
    monkeypatch.setattr(replay, "read_log", lambda p: _nudged(run, field, row))
    assert main(["replay", str(path), "--verify"]) == 1
    out = capsys.readouterr().out
    assert f"verify: MISMATCH in {field} at row {row} (t=" in out, out


# --- (b) the encoder rounds to the nearest count ----------------------------------------------------------
def _compiled_sense():
    import numba

    from adaptive_mj.sensors import sense

    return numba.njit(cache=False)(sense)


@pytest.mark.parametrize("path", ["python", "numba"])
def test_encoder_error_is_at_most_half_a_count_over_a_sweep_of_fractions_and_signs(path):
    """q_m = Δ round(q / Δ): over positions from -3 to 3 counts in steps of 1/64 count (fractions below,
    at and above 0.5; negative and positive), |q_m - q| <= Δ/2, and where the fraction is not exactly 0.5
    q_m is the nearest count; the Python path and the compiled callback's (the same source, numba) alike."""
    from adaptive_mj.sensors import sense

    fn = sense if path == "python" else _compiled_sense()
    delta = 2 * math.pi / 4096
    counts = np.arange(-3 * 64, 3 * 64 + 1) / 64.0  # exact binary fractions of a count
    seen = []
    for c in counts:
        q = np.array([c * delta, 0.0])
        out = np.empty((2, 2))
        fn(q, np.zeros(2), np.zeros((2, 2)), np.array([delta, 0.0]), False, True, True, 0.0, 1e-3,
           np.zeros(2), np.zeros(2), out)
        seen.append(out[0, 0])
    seen = np.array(seen)
    q = counts * delta
    assert np.all(np.abs(seen - q) <= delta / 2 * (1 + 1e-12))
    frac = counts - np.floor(counts)
    off_half = frac != 0.5
    np.testing.assert_array_equal(seen[off_half] / delta, np.round(counts[off_half]))  # nearest, both signs
    assert np.any((frac > 0.5) & (counts < 0)) and np.any((frac > 0.5) & (counts > 0))  # the sweep has both


# --- (c) verdicts on their bounds ----------------------------------------------------------------------------
def _criteria(**kw):
    from adaptive_mj.setup.success import Criteria

    return Criteria(**{"tail_rms": (0.01,), "tail_rule": "success.tail_rms", **kw})


def _summary(tail=0.0, theta_hat=None, theta=None, sat=None, per_joint=None):
    metrics = {"rms_tracking_error_tail": tail}
    if per_joint is not None:
        metrics["rms_tracking_error_tail_per_joint"] = per_joint
    if sat is not None:
        metrics["saturation_fraction"] = sat
    return {"metrics": metrics, "final": {"theta_hat": theta_hat or {}, "theta": theta or {}}}


def test_a_tail_error_exactly_at_its_bound_passes_and_one_ulp_above_fails():
    from adaptive_mj.setup.success import judge

    bound = 0.01
    assert judge(_summary(tail=bound), _criteria(tail_rms=(bound,))) == []
    above = np.nextafter(bound, np.inf)
    missed = judge(_summary(tail=above), _criteria(tail_rms=(bound,)))
    assert len(missed) == 1 and missed[0].endswith("(success.tail_rms)")
    # per joint: the joint at its bound passes, the joint one ulp above fails, named
    per_joint = {"shoulder": bound, "elbow": above}
    missed = judge(_summary(per_joint=per_joint), _criteria(tail_rms=(bound, bound)))
    assert len(missed) == 1 and "on elbow" in missed[0]


def test_a_parameter_error_exactly_at_its_bound_passes_and_one_ulp_above_fails():
    from adaptive_mj.setup.success import judge

    theta = {"m": 1.0}
    at = {"m": 1.25}  # |1.25 - 1| / 1 = 0.25 exactly
    assert judge(_summary(theta_hat=at, theta=theta), _criteria(param_error={"m": 0.25})) == []
    above = {"m": float(np.nextafter(1.25, np.inf))}
    missed = judge(_summary(theta_hat=above, theta=theta), _criteria(param_error={"m": 0.25}))
    assert len(missed) == 1 and "final error of m" in missed[0] and missed[0].endswith("(success.param_error)")
    below = {"m": float(np.nextafter(0.75, -np.inf))}  # the error on the other side of the truth
    assert len(judge(_summary(theta_hat=below, theta=theta), _criteria(param_error={"m": 0.25}))) == 1
    assert judge(_summary(theta_hat={"m": 0.75}, theta=theta), _criteria(param_error={"m": 0.25})) == []


def test_a_saturation_fraction_exactly_at_its_bound_passes_and_one_ulp_above_fails():
    from adaptive_mj.setup.success import judge

    assert judge(_summary(sat=0.25), _criteria(saturation=0.25)) == []
    missed = judge(_summary(sat=float(np.nextafter(0.25, np.inf))), _criteria(saturation=0.25))
    assert len(missed) == 1 and missed[0].endswith("(success.saturation)")


def test_a_run_whose_tail_error_is_its_bound_passes_end_to_end():
    """The bound as a scenario gives it: a run judged against success.tail_rms set to its own measured tail
    error is ok, and against the next float below, failed, naming the criterion."""
    from adaptive_mj.runs.runner import execute

    base = ["simulation.duration=0.5", "success.tail_rms=inf"]
    path = scenario.SCENARIOS_DIR / "heave_tracking.toml"
    tail = execute(scenario.load(path, overrides=base)).summary["metrics"]["rms_tracking_error_tail"]
    at = execute(scenario.load(path, overrides=[*base, f"success.tail_rms={tail!r}"])).summary
    assert at["status"] == "ok", at["reason"]
    below = float(np.nextafter(tail, -np.inf))
    under = execute(scenario.load(path, overrides=[*base, f"success.tail_rms={below!r}"])).summary
    assert under["status"] == "failed" and "(success.tail_rms)" in under["reason"]


# --- (d) the manipulator's gains must be > 0 -------------------------------------------------------------------
JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")


def _table(value_at_elbow):
    return "{" + ", ".join(f"{j}={value_at_elbow if j == 'elbow' else 5.0}" for j in JOINTS) + "}"


@pytest.mark.parametrize("override, key, got", [
    ("law.kd=0", "law.kd", "0.0"),
    ("law.lambda=0", "law.lambda", "0.0"),
    ("law.kd=-0.0", "law.kd", "-0.0"),
    (f"law.kd={_table(0.0)}", "law.kd.elbow", "0.0"),
    (f"law.lambda={_table(0.0)}", "law.lambda.elbow", "0.0"),
    (f"law.kd={_table(-1.0)}", "law.kd.elbow", "-1.0"),
])
def test_a_zero_or_negative_manipulator_gain_is_refused_in_one_line_naming_the_key(override, key, got, capsys):
    assert main(["run", "ur5e_payload_swap", "--set", override, "--set", "simulation.duration=0.1",
                 "--set", "events=[]"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert err.strip().endswith(f"ur5e_payload_swap.toml: {key} must be > 0, got {got}"), err


# --- (e) --resume keeps finished runs that failed or diverged ----------------------------------------------------
def test_resume_keeps_failed_and_diverged_runs_and_runs_only_the_missing_one(tmp_path, capsys):
    """A study of two diverged runs (state bound 0.2), one failed run (k = 2 misses the tail bound 0.1) and one ok
    run (k = 50), whose ok run's log and tables were lost: --resume runs that one only; the failed and diverged
    logs are the same files, untouched, and the table is the uninterrupted study's."""
    import os

    args = ["sweep", "lecture_first_order", "--grid", "law.k=2,50", "--grid", "state_bound=0.2,5",
            "--set", "simulation.duration=1", "--set", "success.tail_rms=0.1", "--jobs", "1"]
    full = tmp_path / "full"
    assert main([*args, "-o", str(full)]) == 1
    import csv

    with open(full / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    statuses = [r["status"] for r in table]
    assert sorted(statuses) == ["diverged", "diverged", "failed", "ok"], statuses
    study = tmp_path / "killed"
    shutil.copytree(full, study)
    for name in ("sweep.csv", "sweep.json"):
        (study / name).unlink()
    ok_log = study / table[statuses.index("ok")]["log"]
    ok_log.unlink()
    kept = {r["log"]: os.stat(study / r["log"]) for r in table if r["status"] != "ok"}
    capsys.readouterr()
    assert main([*args, "--resume", str(study)]) == 1
    assert "(3 already finished, 1 to run)" in capsys.readouterr().err
    for log, before in kept.items():
        after = os.stat(study / log)
        assert (after.st_ino, after.st_mtime_ns, after.st_size) == (before.st_ino, before.st_mtime_ns,
                                                                    before.st_size), log
    assert ok_log.is_file()
    assert (study / "sweep.csv").read_text() == (full / "sweep.csv").read_text()


# --- (f) the MIT rule's filter takes every RK4 stage -------------------------------------------------------------
def test_mit_filter_takes_the_weighted_mean_of_distinct_stage_regressors():
    """ω_f ← e^{-α_0 h} ω_f + (1 - e^{-α_0 h}) Σ b_i ω_i with a different ω at each of the four RK4 stages (and a
    non-zero ω_f to start): a filter that used one stage, or equal weights, differs."""
    from adaptive_mj.laws.mrac import MracLaw, Rule

    law = MracLaw(order=1, alpha=[3.0], beta=3.0, gamma=[0.7, 1.3], sign_b=-1.0, rule=Rule.MIT)
    law.reset()
    h, weights = 0.01, [1 / 6, 1 / 3, 1 / 3, 1 / 6]
    xs = [np.array([0.4]), np.array([-0.2]), np.array([1.1]), np.array([0.05])]
    refs = [np.array([0.1, 0.3]), np.array([0.2, -0.5]), np.array([-0.3, 0.9]), np.array([0.0, 2.0])]
    th = np.zeros(2)
    start = np.array([0.25, -0.5])
    law.omega_f = start.copy()
    law.step_begins(xs[0])
    omegas = []
    for x, ref in zip(xs, refs, strict=True):
        law(0.0, x, ref, th)
        omegas.append(law.regressor(x, ref)[0])
    assert len({tuple(o) for o in omegas}) == 4  # distinct in both components
    law.step_ends(xs, [0.0] * 4, weights, h)
    decay = math.exp(-3.0 * h)
    mean = sum(w * o for w, o in zip(weights, omegas, strict=True))
    np.testing.assert_allclose(law.omega_f, decay * start + (1 - decay) * mean, rtol=1e-14)
    for wrong in (omegas[0], omegas[-1], sum(omegas) / 4):
        assert not np.allclose(decay * start + (1 - decay) * wrong, law.omega_f, rtol=1e-9)

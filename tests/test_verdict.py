"""The verdict (issue 19 §1): [success] criteria, the pre-flight check against the step's stability
limit, saturation per joint, joint limits and identification errors in the run's own output."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from adaptive_mj.cli import main
from adaptive_mj.errors import PreflightRefused, ScenarioError
from adaptive_mj.report.metrics import body_identification
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim import preflight
from adaptive_mj.runs.runner import control_timing, execute
from adaptive_mj.sim.stage import ControlTiming

MODELS = sc.SCENARIOS_DIR.parent / "models"


def _load(name, *overrides):
    return sc.load(sc.SCENARIOS_DIR / f"{name}.toml", overrides=list(overrides))


def _check(scn):
    setup = build(scn)
    return preflight.check(setup.plant, setup.law, setup.reference, duration=scn.simulation.duration,
                           timing=control_timing(scn, setup))


# ---- the stability limits, against their defining equations ----------------------------------

def test_rk4_limit_is_where_the_rk4_multiplier_reaches_one():
    def r(z):
        return 1 + z + z ** 2 / 2 + z ** 3 / 6 + z ** 4 / 24

    x = preflight.RK4_REAL_LIMIT
    assert abs(r(-x)) == pytest.approx(1.0, abs=1e-12)
    assert abs(r(-(x - 1e-3))) < 1 < abs(r(-(x + 1e-3)))


@pytest.mark.parametrize("delay_periods", [0, 1, 2, 5, 20])
def test_delayed_hold_limit_is_where_a_root_reaches_the_unit_circle(delay_periods):
    timing = ControlTiming.of(1e-3, mode="sampled", period=1e-3, delay=delay_periods)
    h, limit, _ = preflight.step_limit(timing, stages=4)
    assert h == 1e-3

    def radius(a):  # z^(D+1) - z^D + a = 0
        coeffs = np.zeros(delay_periods + 2)
        coeffs[0], coeffs[1], coeffs[-1] = 1.0, -1.0, a
        if delay_periods == 0:
            coeffs = np.array([1.0, -1.0 + a])
        return np.abs(np.roots(coeffs)).max()

    assert radius(limit * 0.999) < 1 < radius(limit * 1.001)


def test_step_limit_by_mode_and_integrator():
    assert preflight.step_limit(ControlTiming.of(1e-3), stages=4)[1] == preflight.RK4_REAL_LIMIT
    assert preflight.step_limit(ControlTiming.of(1e-3), stages=1)[1] == 2.0
    h, limit, scheme = preflight.step_limit(ControlTiming.of(1e-3, mode="sampled", period=4e-3), stages=4)
    assert (h, limit) == (4e-3, 2.0) and "hold" in scheme
    # a delay of 6 physics steps at a period of 4 steps counts as 2 whole periods
    assert preflight.step_limit(ControlTiming.of(1e-3, mode="sampled", period=4e-3, delay=6), stages=4)[1] == \
        pytest.approx(2 * math.sin(math.pi / 10))


# ---- the check on real plants --------------------------------------------------------------------

@pytest.mark.parametrize("name", ["ur5e_identification", "ur5e_payload_swap", "arm_payload_swap", "heave_tracking",
                                  "heave_sudden_failure", "lecture_first_order"])
def test_preflight_passes_the_bundled_scenarios_at_their_gains(name):
    pre = _check(_load(name))
    assert pre.checked and pre.ok and pre.line() == ""
    assert 0 < pre.figure < pre.limit


def test_preflight_figure_is_the_generalized_eigenvalue_of_kd_and_m_along_the_reference():
    scn = _load("ur5e_identification")
    setup = build(scn)
    pre = _check(scn)
    ts = np.linspace(0, scn.simulation.duration, preflight.SAMPLES)
    q = np.array([setup.reference(t, 2)[0] for t in ts])
    M = setup.plant.mass_matrices(q)
    worst = max(np.linalg.eigvals(np.linalg.solve(Mi, 50.0 * np.eye(6))).real.max() for Mi in M) + 10.0
    assert pre.rate == pytest.approx(worst, rel=1e-9)
    assert pre.figure == pytest.approx(worst * 1e-3, rel=1e-9)


def test_preflight_fires_at_100_hz_on_the_6_joint_arm_and_names_joint_and_fixes():
    pre = _check(_load("ur5e_identification", "control.period=0.01"))
    assert pre.checked and not pre.ok and pre.limit == 2.0 and pre.figure > 2.0
    line = pre.line()
    assert f"joint {pre.joint}" in line and "law.kd = {" in line and "control.period <=" in line
    # the proposed period is inside the limit
    period = float(line.split("control.period <= ")[1].split(" s")[0])
    assert pre.rate * period < 2.0


def _user_ur5e(tmp_path, duration=1.0, extra=""):
    """The issue's new user: the UR5e file with its real torque limits and no joint armature."""
    xml = (MODELS / "ur5e_arm.xml").read_text()
    assert 'armature="0.1"' in xml
    (tmp_path / "my_ur5e.xml").write_text(xml.replace('armature="0.1"', 'armature="0"'))
    text = (sc.SCENARIOS_DIR / "ur5e_payload_swap.toml").read_text()
    text = text.replace('model = "ur5e_arm"', 'model = "my_ur5e.xml"').replace("duration = 30.0",
                                                                               f"duration = {duration}")
    text = text.split("[[events]]")[0] + extra
    path = tmp_path / "my_ur5e.toml"
    path.write_text(text)
    return path


def test_user_arm_without_armature_is_warned_then_failed_with_the_criterion_named(tmp_path, capsys):
    path = _user_ur5e(tmp_path)
    code = main(["run", str(path), "-o", str(tmp_path / "run.mcap"), "--json"])
    out, err = capsys.readouterr()
    warning = [line for line in err.splitlines() if "pre-flight" in line]
    assert len(warning) == 1 and "joint wrist_3" in warning[0] and "Fixes:" in warning[0], err
    summary = json.loads(out.splitlines()[0])
    assert code == 1 and summary["status"] == "failed", summary["reason"]
    assert "(success.tail_rms)" in summary["reason"] and "pre-flight check had warned" in summary["reason"]
    assert summary["preflight"]["ok"] is False and summary["preflight"]["joint"] == "wrist_3"
    assert summary["metrics"]["saturation_fraction"] > 0.2  # the torques sit at their limits
    assert "wrist_3" in summary["metrics"]["saturation_fraction_per_joint"]
    # the log holds the same verdict
    from adaptive_mj.log.replay import read_log

    assert read_log(tmp_path / "run.mcap").status == "failed"


def test_strict_refuses_the_user_arm_in_one_line_before_the_first_step(tmp_path, capsys):
    path = _user_ur5e(tmp_path)
    assert main(["run", str(path), "-o", str(tmp_path / "run.mcap"), "--strict"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "refused" in err[0] and "wrist_3" in err[0]
    assert not (tmp_path / "run.mcap").exists()
    with pytest.raises(PreflightRefused):
        execute(sc.load(path, overrides=["success.preflight='refuse'"]))


def test_the_suggested_kd_table_makes_the_user_arm_pass_the_preflight(tmp_path):
    """Paste the warning's first fix into the scenario, as ADDING_A_PLANT.md tells a user."""
    path = _user_ur5e(tmp_path)
    pre = _check(sc.load(path))
    assert not pre.ok and pre.fixes[0].startswith("law.kd = {")
    table = pre.fixes[0].split("law.kd = ")[1].split(" (lowered")[0]
    names = build(sc.load(path)).plant.joint_names
    assert [item.split(" = ")[0] for item in table.strip("{}").split(", ")] == list(names)  # every joint named
    fixed = _check(sc.load(path, overrides=[f"law.kd={table}"]))  # pasted as printed
    assert fixed.ok and fixed.figure < 0.95 * fixed.limit, fixed.figure
    # the armature fix, written into the model file
    import re

    assert pre.fixes[2].startswith("more armature on ")
    xml = (tmp_path / "my_ur5e.xml").read_text()
    for item in pre.fixes[2].split("more armature on ")[1].split(" [")[0].split(", "):
        joint, add = item.split(" (+")
        xml, n = re.subn(rf'(<joint name="{joint}"[^>]*?)armature="0"',
                         rf'\1armature="{float(add[:-1]) * 1.001!r}"', xml)
        assert n == 1, joint
    (tmp_path / "my_ur5e.xml").write_text(xml)
    assert _check(sc.load(path)).ok
    # and the period fix alone works too
    period = float(pre.fixes[1].split("<= ")[1].split(" s")[0])
    steps = max(1, int(period / 1e-4))
    faster = _check(sc.load(path, overrides=[f"simulation.timestep={steps * 1e-4!r}"]))
    assert faster.ok


# ---- the verdict ----------------------------------------------------------------------------------

def test_a_tail_bound_below_the_measured_error_fails_the_run_naming_both():
    scn = _load("heave_tracking", "simulation.duration=2", "success.tail_rms=1e-9")
    result = execute(scn)
    assert result.summary["status"] == "failed" == result.trajectory.status
    reason = result.summary["reason"]
    measured = result.summary["metrics"]["rms_tracking_error_tail"]
    assert f"tail RMS tracking error {measured:.3g} m > 1e-09 m (success.tail_rms)" == reason


def test_default_tail_bound_is_derived_from_the_reference():
    scn = _load("heave_tracking", "simulation.duration=20")
    result = execute(scn)
    # y_d = cos t over 20 s: half-range 1 m, 5 % of it
    assert result.summary["success"]["tail_rms"] == [pytest.approx(0.05, rel=1e-6)]
    assert result.summary["status"] == "ok"


def test_param_error_bounds_judge_the_named_parameters():
    ok = execute(_load("ur5e_identification", "simulation.duration=10",
                       "success.param_error={'payload/body.m'=0.05}"))
    assert ok.summary["status"] == "ok", ok.summary["reason"]
    bad = execute(_load("ur5e_identification", "simulation.duration=10",
                        "success.param_error={'payload/body.m'=1e-9}"))
    assert bad.summary["status"] == "failed"
    assert "final error of payload/body.m" in bad.summary["reason"] and "(success.param_error)" in bad.summary["reason"]


def test_saturation_is_measured_per_joint_against_the_limit():
    # a heave thrust limit low enough to saturate: the fraction at the limit is measured from the rows
    scn = _load("heave_tracking", "simulation.duration=2", "success.saturation=0.0")
    setup = build(scn)
    result = execute(scn)
    lo, hi = setup.plant.ctrl_range
    u = result.trajectory.u
    expected = np.mean((u <= lo + 1e-9 * max(1, abs(lo))) | (u >= hi - 1e-9 * max(1, abs(hi))))
    assert result.summary["metrics"]["saturation_fraction"] == expected


def test_demonstration_of_sudden_failure_is_a_failed_verdict_with_its_measured_saturation():
    result = execute(_load("heave_sudden_failure"))
    assert result.summary["status"] == "failed"
    assert "time at the actuator limit" in result.summary["reason"]


@pytest.mark.parametrize("override,match", [
    ("success.param_error={nope=0.1}",
     r"success.param_error.nope: not a parameter of the law \(its parameters: d, b, c\)"),
    ("success.saturation=1.5", r"success.saturation must be a fraction of the run's time in \[0, 1\], got 1.5"),
    ("success.preflight='maybe'", r"success.preflight must be one of 'warn', 'refuse', 'record', got 'maybe'"),
    ("success.tail_rms=-1", r"success.tail_rms must be > 0, got -1.0"),
    ("success.tail_rsm=1", r"unknown key 'success.tail_rsm'"),
])
def test_bad_success_keys_are_one_line_errors(override, match):
    with pytest.raises(ScenarioError, match=match):
        execute(_load("heave_tracking", "simulation.duration=0.1", override))


def test_body_identification_errors_in_percent_mm_and_kg_m2():
    names = ("p.m", "p.mcx", "p.mcy", "p.mcz", "p.Ixx", "p.Ixy", "p.Iyy", "p.Ixz", "p.Iyz", "p.Izz")
    truth = np.array([2.0, 0.2, 0.0, 0.0, 0.1, 0.0, 0.2, 0.0, 0.0, 0.3])
    est = truth.copy()
    est[0] = 2.02  # +1 %
    est[1] = 0.101 * 2.02  # c_x = 0.1 m -> 0.101 m: 1 mm
    est[4] = 0.1 + 3e-3
    out = body_identification(names, est, truth)["p"]
    assert out["mass_error_percent"] == pytest.approx(1.0, rel=1e-9)
    assert out["com_error_mm"] == pytest.approx(1.0, rel=1e-9)
    assert out["inertia_error"] == pytest.approx(3e-3, rel=1e-9)
    assert out["inertia_error_relative"] == pytest.approx(3e-3 / np.linalg.norm([0.1, 0.2, 0.3]), rel=1e-9)


def test_reference_leaving_a_joint_range_is_warned_before_the_run(tmp_path, capsys):
    xml = (MODELS / "ur5e_arm.xml").read_text()
    import re

    # limit wrist_3 to ±0.5 rad around home; the reference swings it by up to ±0.6 rad around home
    scn = _load("ur5e_identification")
    home = build(scn).reference(0.0, 2)[0]
    j = 5
    xml = re.sub(r'(<joint name="wrist_3"[^>]*?)limited="false"',
                 rf'\1limited="true" range="{home[j] - 0.5} {home[j] + 0.5}"', xml, count=1)
    assert 'limited="true"' in xml
    (tmp_path / "arm.xml").write_text(xml)
    text = (sc.SCENARIOS_DIR / "ur5e_identification.toml").read_text().replace('model = "ur5e_arm"',
                                                                               'model = "arm.xml"')
    (tmp_path / "s.toml").write_text(text.replace("duration = 30.0", "duration = 3.0"))
    assert main(["run", str(tmp_path / "s.toml"), "-o", str(tmp_path / "r.mcap"), "--json"]) in (0, 1)
    out, err = capsys.readouterr()
    assert "warning: the reference leaves wrist_3's range" in err
    summary = json.loads(out.splitlines()[0])
    assert any(w.startswith("wrist_3 reached its limit") for w in summary["warnings"]), summary["warnings"]


# ---- the gravity check on arms (issue 35): g(q_d(t)) against the torque limits before the first step --------

ARM_SHORT = ["simulation.duration=0.2", "events=[]"]


@pytest.mark.parametrize("name", ["arm_payload_swap", "ur5e_payload_swap", "ur5e_identification", "ur5e_drift"])
def test_the_bundled_arms_pass_the_gravity_check(name):
    assert _check(_load(name, *ARM_SHORT)).gravity == ""


def test_the_1dof_arms_holding_control_is_its_forms_gravity():
    """ArmPlant.holding_controls(q) = (g_sin sin q + g_cos cos q) / gear: the arm form's gravity terms (true θ of the
    compiled model), here with a 500 kg payload and the bundled gear."""
    setup = build(_load("arm_payload_swap", "plant.payload_mass=500", *ARM_SHORT))
    plant = setup.plant
    theta = dict(zip(plant.names, plant.true_theta(), strict=True))
    q = np.linspace(-2.5, 2.5, 11)
    gear = float(plant.model.actuator_gear[plant.actuator_id, 0])
    expected = (theta["g_sin"] * np.sin(q) + theta["g_cos"] * np.cos(q)) / gear
    np.testing.assert_allclose(plant.holding_controls(q[:, None])[:, 0], expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("name", ["arm_payload_swap", "ur5e_payload_swap"])
def test_a_payload_gravity_cannot_hold_is_warned_then_refused_with_strict(name, tmp_path, capsys):
    """500 kg (grams typed as kilograms) on either arm: without --strict one warning line before the run (which
    then fails, the verdict recalling the warning); with --strict exit 2, one line, before the first step, no log."""
    sets = [a for o in ("plant.payload_mass=500", *ARM_SHORT) for a in ("--set", o)]
    log = tmp_path / "run.mcap"
    assert main(["run", name, "-o", str(log), *sets, "--strict"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert "refused (success.preflight = 'refuse'): pre-flight: gravity alone at the reference needs" in err
    assert "past its actuator's limit" in err and "not the run's verdict" in err and not log.exists()
    assert main(["run", name, "-o", str(log), *sets]) == 1
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "gravity alone" in line]
    assert len(warnings) == 1 and ": warning: pre-flight: gravity alone at the reference needs" in warnings[0]
    from adaptive_mj.log.replay import read_log

    run = read_log(log)
    assert run.status == "failed" and "gravity alone" in run.trajectory.reason
    assert run.summary["preflight"]["gravity"] == warnings[0].split(": warning: ", 1)[1]
    # the right mass passes
    assert main(["run", name, "-o", str(tmp_path / "ok.mcap"), "--set", "simulation.duration=0.2",
                 "--set", "events=[]", "--strict"]) == 0
    assert "gravity" not in capsys.readouterr().err


def test_the_gravity_line_names_the_joint_and_the_numbers():
    """The UR5e with 500 kg: the joint short by the largest factor, the torque it needs at which reference sample,
    and the limit; computed from holding_controls at the reference's samples."""
    scn = _load("ur5e_payload_swap", "plant.payload_mass=500", *ARM_SHORT)
    setup = build(scn)
    line = preflight.gravity_line(setup.plant, setup.reference, scn.simulation.duration, setup.law.order)
    q = preflight._reference_positions(setup.reference, scn.simulation.duration, setup.law.order)
    need = setup.plant.holding_controls(q)
    lo, hi = setup.plant.ctrl_range
    ratio = np.maximum(need / hi, need / lo)
    i, j = np.unravel_index(np.argmax(ratio), need.shape)
    assert ratio[i, j] > 1
    assert f"needs {need[i, j]:.4g} N m on joint {setup.plant.joint_names[j]}" in line, line
    assert f"past its actuator's limit [{lo[j]:.4g}, {hi[j]:.4g}] N m" in line
    assert f"and {int((ratio > 1).any(axis=0).sum()) - 1} other joint(s) short" in line


@pytest.mark.parametrize("mass", [0.0, 9.4e-21, 1e-3 * 2.0, -0.5])
def test_a_vanished_mass_estimate_has_an_undefined_centre_of_mass_not_a_huge_one(mass, capsys):
    """unknown = "all" with projection = "physical" stops a body's m̂ at 0 (or 1e-20 kg): (m c)/m̂ is no centre of
    mass (it printed 8.45e+20 mm); the error is NaN, com_undefined says why, and the summary line says
    "undefined" with the estimate, never a number. Just above the floor (0.1 % of the true mass) it is a number."""
    names = ("p.m", "p.mcx", "p.mcy", "p.mcz", "p.Ixx", "p.Ixy", "p.Iyy", "p.Ixz", "p.Iyz", "p.Izz")
    truth = np.array([2.0, 0.2, 0.0, 0.0, 0.1, 0.0, 0.2, 0.0, 0.0, 0.3])
    est = truth.copy()
    est[0], est[1] = mass, 0.2
    out = body_identification(names, est, truth)["p"]
    assert math.isnan(out["com_error_mm"]) and out["com_undefined"] == f"undefined (estimated mass {mass:.3g} kg)"
    est[0] = np.nextafter(1e-3 * 2.0, np.inf)
    above = body_identification(names, est, truth)["p"]
    assert math.isfinite(above["com_error_mm"]) and above["com_undefined"] == ""
    from adaptive_mj.cli import _print_summary
    from adaptive_mj.report.metrics import clean_json

    summary = {"scenario": "s", "status": "ok", "reason": "", "duration": 1.0, "steps": 1,
               "metrics": {"rms_tracking_error": 0.1, "rms_tracking_error_tail": 0.1,
                           "max_abs_tracking_error_tail": 0.1, "control_rms": 1.0, "control_total_variation": 1.0,
                           "identification": {"p": out}},
               "final": {"theta_hat": {}, "theta": {}}}
    _print_summary(clean_json(summary), as_json=False, kind="manipulator")
    line = [x for x in capsys.readouterr().out.splitlines() if "identified p" in x][0]
    assert f"centre of mass undefined (estimated mass {mass:.3g} kg)," in line and "mm" not in line, line


def test_a_note_or_warning_is_one_write_of_one_whole_line(monkeypatch):
    """A study's workers share stderr; print's two writes (text, then newline) let another worker's line land
    between them, and two sweep workers' notes came out merged on one line. The command line's handler of the
    "adaptive_mj" logger writes each line whole, to the stderr of the moment."""
    import logging

    from adaptive_mj.notes import LineHandler

    writes = []

    class Stream:
        def write(self, text):
            writes.append(text)

        def flush(self):
            writes.append("<flush>")

    monkeypatch.setattr("sys.stderr", Stream())
    LineHandler().emit(logging.LogRecord("adaptive_mj", logging.INFO, "", 0, "mine.toml (0001-seed0): note: x", (),
                                         None))
    assert writes == ["mine.toml (0001-seed0): note: x\n", "<flush>"]


def test_run_scenario_says_its_warnings_through_logging_and_is_silent_by_default(capsys, caplog):
    """From Python a run's notes and warnings go through the "adaptive_mj" logger: nothing on stderr unless the
    application asks (here pytest's caplog), and the command line prints them (tested above)."""
    import logging

    from adaptive_mj.notes import log
    from adaptive_mj.study.api import run_scenario

    saved = (log.handlers[:], log.level, log.propagate)
    log.handlers[:] = [h for h in log.handlers if type(h).__name__ != "LineHandler"]  # as a fresh interpreter has
    log.setLevel(logging.NOTSET)
    log.propagate = True
    try:
        with caplog.at_level(logging.INFO, logger="adaptive_mj"):
            r = run_scenario("arm_payload_swap", set=["plant.payload_mass=500", *ARM_SHORT])
        assert r.status == "failed"
        assert capsys.readouterr().err == ""
        warned = {rec.getMessage() for rec in caplog.records if rec.levelno == logging.WARNING}  # (caplog may hold
        assert len(warned) == 1 and "gravity alone at the reference needs" in warned.pop()  # a record twice)
    finally:
        log.handlers[:], log.level, log.propagate = saved

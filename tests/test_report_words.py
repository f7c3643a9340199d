"""The report's words follow its logs (issue 36): a failure is called sudden only when its precursors are close,
identification figures are spreads over a window, a physically impossible payload estimate is counted from the
pseudo-inertia, a control-rate row tests the prediction only near its bound, and re-adaptation is claimed only
when the error came back."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from adaptive_mj.study.analysis import SUDDEN_WINDOW, failure_onset, pseudo_inertia_eigenvalues, window_spread
from adaptive_mj.study.sections import control_rate, manipulator_drift, wing_rock


def _run(t, e, u, limit=1.0):
    return SimpleNamespace(t=t, y_tilde=np.column_stack([e, 0.5 * e]), u=u,
                           meta={"ctrl_range": ([-limit, -limit], [limit, limit])})


def test_a_failure_with_early_precursors_is_not_sudden_and_one_without_them_is():
    t = np.arange(0.0, 100.0, 0.01)
    base = 1e-4
    slow = base * np.exp(np.clip(t - 60.0, 0.0, None) / 8.0)  # 5× at 72.9 s, 25× at 85.8 s, the bound (100×) at 96.8
    u = np.zeros((len(t), 2))
    u[t >= 65.0, 1] = 1.0  # a torque at its limit from 65 s
    fo = failure_onset(_run(t, slow, u), bound=100 * base, baseline_until=60.0)
    assert fo["baseline"] == pytest.approx(base)
    assert fo["saturation"] == pytest.approx(65.0)
    assert fo["x5"] == pytest.approx(60 + 8 * np.log(5), abs=0.011)
    assert fo["x25"] == pytest.approx(60 + 8 * np.log(25), abs=0.011)
    assert fo["failure"] == pytest.approx(60 + 8 * np.log(100), abs=0.011) and fo["sudden"] is False
    words = manipulator_drift._failure_words({"onset": fo}, base)
    assert "It is not sudden: torques first saturate at 65.0 s" in words and "suddenly" not in words
    burst = np.where(t < 90.0, base, base * 1e3)  # every precursor and the failure in one step
    fo = failure_onset(_run(t, burst, np.zeros((len(t), 2))), bound=100 * base, baseline_until=60.0)
    assert fo["saturation"] is None and fo["x5"] == fo["failure"] == pytest.approx(90.0) and fo["sudden"] is True
    assert f"within {SUDDEN_WINDOW:g} s before it: the failure is sudden" in manipulator_drift._failure_words(
        {"onset": fo}, base)
    calm = failure_onset(_run(t, np.full(len(t), base), np.zeros((len(t), 2))), bound=100 * base, baseline_until=60.0)
    assert calm["failure"] is None and calm["sudden"] is None


def test_the_pseudo_inertia_tells_a_possible_body_from_an_impossible_one():
    m, c, half = 1.5, np.array([0.04, 0.03, 0.07]), np.array([0.05, 0.04, 0.03])  # a solid box of half-sides `half`
    Ic = m / 3 * np.diag([half[1] ** 2 + half[2] ** 2, half[0] ** 2 + half[2] ** 2, half[0] ** 2 + half[1] ** 2])
    I0 = Ic + m * (c @ c * np.eye(3) - np.outer(c, c))  # about the body's origin
    theta = np.array([m, *(m * c), I0[0, 0], I0[0, 1], I0[1, 1], I0[0, 2], I0[1, 2], I0[2, 2]])
    eig = pseudo_inertia_eigenvalues(theta)
    assert eig.shape == (1, 1, 4) and eig.min() > 0
    bad = theta.copy()
    bad[9] = bad[4] + bad[6] + 1e-3  # Izz > Ixx + Iyy: the triangle inequality broken
    assert pseudo_inertia_eigenvalues(bad).min() < 0
    negative = theta.copy()
    negative[0] = -0.1  # a negative mass
    assert pseudo_inertia_eigenvalues(np.stack([theta, negative]))[:, 0, 0].tolist()[0] > 0 > \
        pseudo_inertia_eigenvalues(negative).min()


def test_a_swinging_estimate_reports_its_spread_not_its_last_sample():
    t = np.arange(0.0, 10.0, 0.01)
    v = 1.0 + 30.0 * np.sin(7.0 * t) ** 2  # swings between 1 and 31 in the last 2 s
    sp = window_spread(t, v, 2.0)
    assert sp["min"] == pytest.approx(1.0, abs=0.05) and sp["max"] == pytest.approx(31.0, abs=0.05)
    assert sp["last"] == v[-1] and sp["min"] < sp["mean"] < sp["max"]


def test_an_arm_run_s_summary_gives_the_tail_s_spread_of_its_identification_and_the_rate_of_its_tv(tmp_path,
                                                                                                   capsys):
    """ur5e_identification over 5 s: the estimates still swing, so the summary's tail spread is wide and holds the
    last row; the CLI prints it beside the last row, and the total variation names its rows' rate."""
    from adaptive_mj.cli import main
    from adaptive_mj.report.metrics import TAIL_FRACTION, body_identification
    from adaptive_mj.study.api import run_scenario

    res = run_scenario("ur5e_identification", set=["simulation.duration=5"], seed=0)
    tr, m = res.trajectory, res.summary["metrics"]
    e = m["identification"]["payload/body"]
    tail = e["tail"]
    assert tail["mass_error_percent"]["min"] <= e["mass_error_percent"] <= tail["mass_error_percent"]["max"]
    assert tail["com_error_mm"]["max"] - tail["com_error_mm"]["min"] > 5.0  # a swing of more than 5 mm
    rows = tr.t >= tr.t[0] + (1 - TAIL_FRACTION) * (tr.t[-1] + tr.meta["dt"] - tr.t[0])
    per_row = body_identification(tr.names, tr.theta_hat[rows], tr.theta[rows])["payload/body"]
    assert tail["inertia_error"]["mean"] == pytest.approx(float(np.mean(per_row["inertia_error"])), rel=1e-12)
    assert m["control_total_variation_rate_hz"] == pytest.approx(1.0 / tr.meta["dt"])
    assert main(["run", "ur5e_identification", "--set", "simulation.duration=1", "-o", str(tmp_path / "a.mcap")]) == 0
    out = capsys.readouterr().out
    assert "over the tail (last 25 %, mean [min, max]): mass" in out
    assert "(over the rows at 1000 Hz: a lower bound where the control moves faster)" in out


def test_control_rate_rows_far_below_the_bound_are_not_said_to_test_it():
    rows = [{"plant": "heave", "rate_hz": 100.0, "figure": 0.05, "holds": True},
            {"plant": "arm", "rate_hz": 250.0, "figure": 1.86, "holds": True},
            {"plant": "arm", "rate_hz": 100.0, "figure": 4.65, "holds": False}]
    text = control_rate._verdict(rows, [])
    assert text.startswith("2 of the 3 rows have a figure within a factor 4 of 2 and so test the prediction: arm at "
                           "250 Hz (figure 1.86, holds), arm at 100 Hz (figure 4.65, breaks); the prediction and the "
                           "measurement agree on all 2.")
    assert "The other 1 rows' figures are at most 0.05" in text and "heave at 100 Hz" not in text
    assert "agree on every row" not in text
    assert "none of them tests the prediction" in control_rate._verdict(rows[:1], [])


def test_control_rate_names_the_pre_flight_figure_beside_its_diagonal_one():
    """Section 11 printed K_D T/M_jj = 4.65 for the 6-joint arm at 100 Hz while the same run's pre-flight check warned
    μh = 4.96, with no word between them. The pre-flight's figure, recomputed here from the compiled model by its
    definition (mj_fullM, armature included, at the check's 64 points of the reference: T · (max λ(M⁻¹K_D) + max Λ)),
    is what the check prints and the section's coupled figure plus λT; the section's sentence names it beside the
    diagonal figure, and docs/GUIDE.md quotes both as they are printed."""
    from pathlib import Path

    import mujoco

    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build
    from adaptive_mj.setup.success import sampled_positions
    from adaptive_mj.sim import preflight
    from adaptive_mj.runs.runner import control_timing

    path, T = sc.SCENARIOS_DIR / "ur5e_identification.toml", 0.01  # the section's slowest rate, 100 Hz
    scn = sc.load(path, overrides=["control.mode='sampled'", f"control.period={T!r}"])
    s = build(scn)
    pre = preflight.check(s.plant, s.law, s.reference, duration=scn.simulation.duration, timing=control_timing(scn, s))
    model, data = s.plant.model, mujoco.MjData(s.plant.model)
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in s.plant.joint_names]
    qadr, dadr = model.jnt_qposadr[joints], model.jnt_dofadr[joints]
    kd = np.broadcast_to(np.asarray(s.law.kd, dtype=float), (len(joints),))
    lam = np.broadcast_to(np.asarray(s.law.lam, dtype=float), (len(joints),))
    worst = 0.0
    for q in sampled_positions(s.reference, scn.simulation.duration, preflight.SAMPLES, s.law.order):
        data.qpos[qadr] = q
        mujoco.mj_forward(model, data)
        full = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, full)
        M = full[np.ix_(dadr, dadr)]
        worst = max(worst, float(np.linalg.eigvals(np.linalg.solve(M, np.diag(kd))).real.max()))
    assert pre.figure == pytest.approx((worst + lam.max()) * T, rel=1e-9) and pre.step == T
    assert f"μh = {pre.figure:.3g} at h = {T:.3g} s" in pre.line()

    arm = control_rate.sampled_loop(path)
    diagonal = arm.figure(T)[0]
    assert arm.preflight_rate is not None and arm.coupled is not None
    assert arm.preflight_rate * T == pytest.approx(pre.figure, rel=1e-9)
    assert arm.coupled == pytest.approx(worst, rel=1e-9)  # the same points of the reference as the check's
    assert diagonal <= arm.coupled * T < pre.figure  # the Rayleigh quotient, then + λT: two figures, not one
    words = control_rate._preflight_words(arm, T)
    assert (f"its warning's μh = {pre.figure:.3g} (the coupled figure {worst * T:.3g} plus λT = {lam.max() * T:.3g}), "
            f"not the table's diagonal figure {diagonal:.3g}") in words
    readme = (Path(__file__).resolve().parents[1] / "docs" / "GUIDE.md").read_text()  # the README's guide
    assert f"(μh = {pre.figure:.3g} > 2)" in readme and f"K_D T/M_jj ({diagonal:.3g} on {arm.figure(T)[1]}" in readme
    assert f"T · (max λ(M⁻¹K_D) + max Λ) = {worst * T:.3g} + {lam.max() * T:.3g}" in readme


def test_re_adaptation_is_claimed_only_when_the_error_came_back():
    slow = wing_rock._readapt_words("sliding", {"pre": 1e-4, "post": 4e-3, "err_change": 0.53, "err_end": 0.47})
    assert "40× its value" in slow and "re-adaptation is not shown within the run" in slow
    back = wing_rock._readapt_words("mrac", {"pre": 1e-3, "post": 1.5e-3, "err_change": 0.5, "err_end": 0.05})
    assert "re-adapted within the run" in back


def test_the_6_joint_drift_run_s_onset_lists_its_precursors_well_before_the_failure():
    """ur5e_drift without a modification (150 s): measured torques at a limit from 65.6 s, 5× the baseline error at
    73.5 s, 25× at 87.5 s, the 0.01 rad bound at 98.5 s (bench of 2026-11-28): not sudden."""
    from adaptive_mj.study.api import run_scenario

    res = run_scenario("ur5e_drift")
    fo = failure_onset(res.trajectory, bound=0.01, baseline_until=60.0)
    assert fo["saturation"] < fo["x5"] < fo["x25"] < fo["failure"]
    assert fo["failure"] - fo["saturation"] > 10.0 and fo["sudden"] is False
    facts = manipulator_drift._facts(res.trajectory, np.linalg.norm(res.trajectory.theta_hat - res.trajectory.theta,
                                                                    axis=1) / np.linalg.norm(res.trajectory.theta,
                                                                                             axis=1))
    assert facts["not_psd"] > 0 and facts["moved"] > 0  # the plain law's estimate leaves the physical set


def test_a_study_s_pre_flight_warning_names_the_run_and_words_a_saturating_boundary_layer_as_linearised(capfd,
                                                                                                     tmp_path):
    """bench's robust_phi1e-5 run ended ok under a warning that said its loop "cannot be stable" and did not say
    which run it was: the line now names the run and says the figure is the linearised loop's."""
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.study.job import RunSpec, run_job

    job = RunSpec(sc.SCENARIOS_DIR / "heave_tracking.toml", tag="second_order/robust_phi1e-5",
              overrides=("law.kind=robust_sliding", "law.nominal='model'", "law.K=29.6", "law.boundary_layer=1e-05",
                         "simulation.duration=1.0"))
    r = run_job(job)
    err = capfd.readouterr().err
    (line,) = [ln for ln in err.splitlines() if "pre-flight" in ln]
    assert "heave_tracking.toml (second_order/robust_phi1e-5): warning: pre-flight:" in line
    assert "the linearised loop cannot be stable (inside the boundary layer: K/Φ = 2.96e+06 saturates" in line
    assert "the loop cannot be stable" not in line and r.status in ("ok", "failed")


def _strip_attachments(src, dst):
    """Rewrite an MCAP log without its attachments (as `mcap` tools can do to shrink a file): the same schemas,
    channels, messages and metadata."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        w = Writer(g)
        w.start(profile="", library="strip-test")
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(channel.schema_id, 0), dict(channel.metadata))
            w.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                          message.sequence)
        for meta in reader.iter_metadata():
            w.add_metadata(meta.name, dict(meta.metadata))
        w.finish()


def test_a_log_stripped_of_its_attachments_replays_its_rows_and_only_verify_refuses(tmp_path, capsys):
    from adaptive_mj.cli import main
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.study.api import run_scenario

    log = tmp_path / "run.mcap"
    run_scenario("heave_tracking", set=["simulation.duration=1.0"], log=log)
    stripped = tmp_path / "stripped.mcap"
    _strip_attachments(log, stripped)
    whole, cut = read_log(log), read_log(stripped)
    assert not whole.model_missing and cut.model_missing and cut.model_xml is None
    np.testing.assert_array_equal(cut.trajectory.x, whole.trajectory.x)
    assert cut.summary == whole.summary
    verdict = main(["replay", str(log)])  # the run's own verdict (1 s: it misses its tail bound, exit 1)
    capsys.readouterr()
    assert main(["replay", str(stripped)]) == verdict
    out = capsys.readouterr()
    assert "embedded model is missing" in out.out + out.err
    assert main(["replay", str(stripped), "--verify"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--verify needs the model the log embedded" in err[0]
    assert main(["replay", str(log), "--verify"]) == verdict  # the whole log verifies (exit: its verdict)
    assert "bit-identical" in capsys.readouterr().out


def test_a_reference_no_arm_can_follow_is_caught_before_the_run(capfd):
    """A frequency ×1e9 on the 6-joint arm made MuJoCo's step blow up at t = 0; the pre-flight check now sees it
    from inverse dynamics along the reference (FOLLOW_FACTOR × a limit) and --strict refuses it in one line; the
    bundled arm scenarios pass the same check."""
    from adaptive_mj.cli import main
    from adaptive_mj.setup import scenario as sc
    from adaptive_mj.setup.build import build
    from adaptive_mj.sim import preflight

    for path in sorted(sc.SCENARIOS_DIR.glob("*.toml")):
        scn = sc.load(path)
        if scn.plant.kind != "manipulator":
            continue
        s = build(scn)
        assert preflight.following_line(s.plant, s.reference, scn.simulation.duration) == "", path.name
        s.plant.release()
    fast = ("reference.omegas={shoulder_pan=[5e8, 1.7e9, 3.3e9], shoulder_lift=[0.6, 1.9, 3.7], elbow=[0.7, 2.3, "
            "4.1], wrist_1=[0.8, 2.9, 4.7], wrist_2=[0.9, 3.1, 5.3], wrist_3=[1.1, 3.5, 5.9]}")
    capfd.readouterr()
    assert main(["run", "ur5e_identification", "--strict", "--set", fast, "--set", "simulation.duration=1"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "following the reference asks" in err[0] and "of shoulder_pan" in err[0]
    assert "its actuator's limit 150: no law can follow this reference" in err[0]

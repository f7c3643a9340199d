"""Many runs in one mujoco.batch.Batch (adaptive_mj.sim.batch): each run's rows, events and status
are those loop.run gives it alone, bit for bit, on the heave vehicle, the 1-DOF arm and the 6-joint
arm, with noise, events that change a run's own model, real-robot conditions and sampled-data
control; a run that diverges ends alone and the others go on."""
from __future__ import annotations

import numpy as np

from adaptive_mj.cli import main
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


def _messages(path) -> list[tuple[str, int, bytes]]:
    """Every message of a log (topic, log time [ns], payload bytes): the header's attachments and
    metadata (creation time, library versions) aside, the log's content."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(ch.topic, msg.log_time, msg.data) for _, ch, msg in make_reader(f).iter_messages()]


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


def test_runs_of_different_plants_and_paths_in_one_call():
    """Runs needing different compiled callbacks are batched apart, a Python-path run runs alone: each
    still gives its single run's rows."""
    _same([("heave_tracking", ["simulation.duration=0.5"]),
           ("arm_payload_swap", ["simulation.duration=0.5", "events=[]"]),
           ("heave_tracking", ["simulation.duration=0.5", "simulation.python_callback=true"]),
           ("heave_tracking", ["simulation.duration=0.5", "law.k=100.0"])])


def test_execute_batch_gives_execute_s_summaries_and_logs(tmp_path):
    """runner.execute_batch: the verdict, the summary and every logged message are those of
    runner.execute, run by run (the log's creation time and library versions aside)."""
    from adaptive_mj.log.replay import read_log
    from adaptive_mj.runs.runner import execute, execute_batch

    scns = [load(SCENARIOS_DIR / "heave_drift.toml", overrides=["simulation.duration=3", f"law.k={k}"], seed=sd)
            for k, sd in ((150.0, 0), (250.0, 1))]
    scns.append(load(SCENARIOS_DIR / "ur5e_payload_swap.toml", overrides=[
        "simulation.duration=1", "events=[{t=0.5, kind='payload_swap', payload='sphere'}]"]))
    single = [execute(scn, log_path=tmp_path / f"single{i}.mcap") for i, scn in enumerate(scns)]
    batched = execute_batch([(scn, tmp_path / f"batch{i}.mcap") for i, scn in enumerate(scns)], nthread=2)
    for i, (a, b) in enumerate(zip(single, batched, strict=True)):
        assert a.summary == b.summary
        la, lb = read_log(tmp_path / f"single{i}.mcap"), read_log(tmp_path / f"batch{i}.mcap")
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(la.trajectory, f), getattr(lb.trajectory, f), err_msg=f)
        assert la.trajectory.status == lb.trajectory.status and la.trajectory.meta["events"] == \
            lb.trajectory.meta["events"]


def test_sweep_engine_batch_writes_the_same_table(tmp_path):
    """`sweep --engine batch` (the runs' physics in one Batch, this process) gives the table the
    process engine gives, and a log per run that replays."""
    from adaptive_mj.cli import main

    args = ["sweep", "heave_drift", "--grid", "law.k=150:250:2", "--seeds", "2", "--set", "simulation.duration=1",
            "--jobs", "2"]
    assert main([*args, "-o", str(tmp_path / "p")]) == 0
    assert main([*args, "-o", str(tmp_path / "b"), "--engine", "batch"]) == 0
    assert (tmp_path / "p" / "sweep.csv").read_text() == (tmp_path / "b" / "sweep.csv").read_text()
    logs = sorted((tmp_path / "b" / "logs").glob("*.mcap"))
    assert len(logs) == 4 and main(["replay", str(logs[0]), "--verify"]) == 0


def test_sweep_logs_summary_writes_the_table_without_logs(tmp_path):
    from adaptive_mj.cli import main

    args = ["sweep", "heave_drift", "--grid", "law.k=150,250", "--set", "simulation.duration=1", "--jobs", "2"]
    assert main([*args, "-o", str(tmp_path / "all")]) == 0
    assert main([*args, "-o", str(tmp_path / "sum"), "--logs", "summary", "--engine", "batch"]) == 0
    assert not (tmp_path / "sum" / "logs").exists() or not any((tmp_path / "sum" / "logs").iterdir())
    import csv

    full = list(csv.DictReader((tmp_path / "all" / "sweep.csv").open()))
    short = list(csv.DictReader((tmp_path / "sum" / "sweep.csv").open()))
    assert [{k: v for k, v in r.items() if k != "log"} for r in full] == \
        [{k: v for k, v in r.items() if k != "log"} for r in short]
    assert all(r["log"] == "" for r in short) and all(r["log"] for r in full)


def test_sweep_logs_summary_refuses_resume(capsys, tmp_path):
    from adaptive_mj.cli import main

    assert main(["sweep", "heave_drift", "--grid", "law.k=150,250", "--logs", "summary", "--resume",
                 str(tmp_path)]) == 2
    assert "--logs summary" in capsys.readouterr().err


def test_resume_with_the_batch_engine_finishes_a_killed_study_with_the_same_table(tmp_path, capsys):
    """--resume --engine batch on a study whose folder lost runs (missing logs, a log cut short as by
    SIGKILL, no table): only those runs run again, batched, and sweep.csv is byte-identical to the same
    study run whole on worker processes."""
    import shutil

    args = ["sweep", "heave_drift", "--grid", "law.k=100,200,300", "--seeds", "2", "--set",
            "simulation.duration=0.5"]
    full = tmp_path / "full"
    assert main([*args, "--jobs", "2", "-o", str(full)]) == 0
    study = tmp_path / "killed"
    shutil.copytree(full, study)
    (study / "sweep.csv").unlink()
    (study / "sweep.json").unlink()
    logs = sorted((study / "logs").glob("*.mcap"))
    logs[0].unlink()
    logs[3].unlink()
    data = logs[5].read_bytes()
    logs[5].write_bytes(data[: len(data) // 2])
    capsys.readouterr()
    assert main([*args, "--engine", "batch", "--jobs", "2", "--resume", str(study)]) == 0
    assert "(3 already finished, 3 to run)" in capsys.readouterr().err
    assert (study / "sweep.csv").read_text() == (full / "sweep.csv").read_text()
    for a, b in zip(sorted((full / "logs").glob("*.mcap")), sorted((study / "logs").glob("*.mcap")), strict=True):
        assert _messages(a) == _messages(b)


def test_payload_grids_on_both_arms_give_the_process_engine_s_table_and_log_messages(tmp_path):
    """A payload grid (each run's own compiled model: the payload's file or its mass) on the 1-DOF arm
    and on the 6-joint arm, with noise and a mid-run swap: `sweep --engine batch` gives the table and
    every log message the process engine gives."""
    cases = [["arm_payload_swap", "--grid", "plant.payload_mass=0.25,1.0,2.0", "--seeds", "2",
              "--set", "simulation.duration=1.5", "--set", "events=[{t=0.75, kind='payload_mass', value=1.5}]"],
             ["ur5e_payload_swap", "--grid", "plant.payload=tool_offset,box_offset,sphere",
              "--set", "simulation.duration=0.4", "--set", "events=[{t=0.2, kind='payload_swap', payload='sphere'}]",
              "--set", "noise.std={q=1e-4}"]]
    for k, args in enumerate(cases):
        p, b = tmp_path / f"p{k}", tmp_path / f"b{k}"
        assert main(["sweep", *args, "--jobs", "2", "-o", str(p)]) == 0
        assert main(["sweep", *args, "--jobs", "2", "--engine", "batch", "-o", str(b)]) == 0
        assert (p / "sweep.csv").read_text() == (b / "sweep.csv").read_text()
        logs = sorted((p / "logs").glob("*.mcap"))
        assert len(logs) == (6 if k == 0 else 3)
        for log in logs:
            assert _messages(log) == _messages(b / "logs" / log.name), log.name

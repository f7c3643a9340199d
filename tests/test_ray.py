"""The Ray backend (adaptive_mj.study.ray_backend) on a local two-node Ray cluster.

Each test drives `adaptive-mj sweep --backend ray --address ADDR` in a process of its own, as a
user would, against a cluster of two nodes (one CPU each) started once for this module with
ray.cluster_utils.Cluster. Ray is the optional extra `[ray]`; the README's test command installs
it, and under CI=true a missing Ray fails this module instead of skipping it.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from adaptive_mj.log.replay import read_log

from test_bench import small_catalogue  # noqa: F401 (a fixture: pytest finds it by name in this module)
from test_determinism import messages

if os.environ.get("CI"):
    import ray  # noqa: F401 (CI installs the [ray] extra: these tests must run there)
else:
    pytest.importorskip("ray")

REPO = Path(__file__).resolve().parents[1]
TASK_TITLE = "ray::adaptive-mj-run"  # the process title Ray gives a worker while it runs one of our tasks
SHORT = ["heave_drift", "--grid", "law.k=100,200,300", "--seeds", "2", "--set", "simulation.duration=0.5"]


@pytest.fixture(scope="module")
def cluster():
    """A head node and a worker node on this machine, one CPU each (small object stores)."""
    from ray.cluster_utils import Cluster

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "object_store_memory": 80 * 2**20,
                                                       "include_dashboard": False})
    c.add_node(num_cpus=1, object_store_memory=80 * 2**20)
    c.wait_for_nodes()
    yield c.address
    c.shutdown()


def cli(*args: str, timeout: float = 300, prefix: str = "") -> subprocess.CompletedProcess:
    env = dict(os.environ, MUJOCO_GL="egl", RAY_USAGE_STATS_ENABLED="0")
    cmd = [sys.executable, "-m", "adaptive_mj", *args]
    if prefix:
        cmd = ["bash", "-c", prefix + " exec " + " ".join(f"'{a}'" for a in cmd)]
    return subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=timeout)


def start(*args: str) -> subprocess.Popen:
    env = dict(os.environ, MUJOCO_GL="egl", RAY_USAGE_STATS_ENABLED="0")
    return subprocess.Popen([sys.executable, "-m", "adaptive_mj", *args], cwd=REPO, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def task_processes() -> dict[int, list[str]]:
    """pid -> the files it has open, for every Ray worker running one of our tasks now."""
    out = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if not (entry / "cmdline").read_bytes().startswith(TASK_TITLE.encode()):
                continue
            out[int(entry.name)] = [os.readlink(fd) for fd in (entry / "fd").iterdir()]
        except OSError:
            continue
    return out


def writer_of(name: str, *, not_pid: int | None = None, timeout: float = 120.0, written: int = 0) -> int:
    """The pid of the task process that has the log NAME.partial open (shared logs), once it holds
    more than `written` bytes."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid, files in task_processes().items():
            if pid != not_pid and any(f.endswith(name + ".partial") and _size(f) > written for f in files):
                return pid
        time.sleep(0.05)
    raise AssertionError(f"no task process wrote {name}.partial within {timeout} s")


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def same_logs(a: Path, b: Path) -> None:
    names = sorted(p.name for p in (a / "logs").glob("*.mcap"))
    assert names and names == sorted(p.name for p in (b / "logs").glob("*.mcap"))
    for name in names:
        assert messages(a / "logs" / name) == messages(b / "logs" / name), name


@pytest.fixture(scope="module")
def local_short(tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "short"
    r = cli("sweep", *SHORT, "--jobs", "2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.parametrize("logs, engine", [("bytes", "process"), ("shared", "process"), ("bytes", "batch"),
                                          ("shared", "batch")])
def test_ray_sweep_gives_the_local_table_and_logs(cluster, local_short, tmp_path, logs, engine):
    """On a 2-node cluster, both log transports, one run per task or (--engine batch) two runs per task in
    one mujoco.batch.Batch: sweep.csv byte-identical to the local backend's, every log's messages the same
    bytes, and the rows of sweep.json the same."""
    import json

    out = tmp_path / "ray"
    r = cli("sweep", *SHORT, "--backend", "ray", "--address", cluster, "--ray-logs", logs, "--engine", engine,
            "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert f"on Ray ({cluster}, logs as {logs})" in r.stderr
    assert (out / "sweep.csv").read_bytes() == (local_short / "sweep.csv").read_bytes()
    rows = [json.loads((d / "sweep.json").read_text())["rows"] for d in (out, local_short)]
    assert rows[0] == rows[1] and len(rows[0]) == 6
    same_logs(out, local_short)
    assert not list((out / "logs").glob("*.partial"))


def test_a_killed_worker_loses_no_run(cluster, tmp_path):
    """SIGKILL of the worker process running a run: the run is submitted again, the sweep completes
    with every run ok exactly once, and the logs equal the local backend's."""
    args = ["heave_tracking", "--grid", "law.k=150,250", "--seeds", "1", "--set", "simulation.duration=60"]
    out = tmp_path / "ray"
    driver = start("sweep", *args, "--backend", "ray", "--address", cluster, "--ray-logs", "shared",
                   "-o", str(out))
    victim = writer_of("0000-k=150-seed0.mcap", written=50_000)  # mid-run: rows logged
    os.kill(victim, signal.SIGKILL)
    stdout, stderr = driver.communicate(timeout=300)
    assert driver.returncode == 0, stderr
    assert "retrying 0000-k=150-seed0: attempt 2 of 4 (" in stderr, stderr
    assert "2/2 runs done, retried 1" in stderr
    rows = (out / "sweep.csv").read_text().splitlines()[1:]
    assert sorted(r.split(",")[0] for r in rows) == ["0000-k=150-seed0", "0001-k=250-seed0"]
    assert all(",ok," in r for r in rows)
    local = tmp_path / "local"
    r = cli("sweep", *args, "--jobs", "2", "-o", str(local))
    assert r.returncode == 0, r.stderr
    assert (out / "sweep.csv").read_bytes() == (local / "sweep.csv").read_bytes()
    same_logs(out, local)


def test_a_run_whose_worker_keeps_dying_is_recorded_after_the_retry_limit(cluster, tmp_path):
    """--retries 1: a run killed twice is an error naming the cause and the attempts; the other run is ok."""
    out = tmp_path / "ray"
    driver = start("sweep", "heave_tracking", "--grid", "law.k=150,250", "--set", "simulation.duration=60",
                   "--backend", "ray", "--address", cluster, "--ray-logs", "shared", "--retries", "1", "-o", str(out))
    name = "0000-k=150-seed0.mcap"
    first = writer_of(name)
    os.kill(first, signal.SIGKILL)
    second = writer_of(name, not_pid=first, written=50_000)  # rows logged: its log reads as truncated
    os.kill(second, signal.SIGKILL)
    stdout, stderr = driver.communicate(timeout=300)
    assert driver.returncode == 1, stderr
    assert "Traceback" not in stderr
    rows = (out / "sweep.csv").read_text().splitlines()[1:]
    assert len(rows) == 2 and ",ok," in rows[1]
    assert ",error,the Ray task failed (tried 2 times): WorkerCrashedError" in rows[0]
    assert f"what its last attempt wrote reads as truncated ({out / 'logs' / name})" in rows[0]
    assert read_log(out / "logs" / name).status == "truncated" and not (out / "logs" / (name + ".partial")).exists()


@pytest.mark.parametrize("signum, logs, engine", [(signal.SIGINT, "bytes", "process"),
                                                  (signal.SIGTERM, "shared", "process"),
                                                  (signal.SIGINT, "bytes", "batch")])
def test_interrupting_a_ray_sweep_closes_the_logs_and_leaves_no_task(cluster, tmp_path, signum, logs, engine):
    """SIGINT or SIGTERM to the driver: every running task stops, its log closed as "interrupted"
    (bytes: sent back and written by the driver), exit 128 + signal, and no task process is left
    running. (Ray's driver installs its own SIGTERM handler: the CLI's clean stop must win.) With
    --engine batch the 5 runs go as tasks of 2, 2 and 1: the two running tasks close 4 logs."""
    out = tmp_path / "ray"
    grid = "law.k=150,250,350" if engine == "process" else "law.k=150,250,350,450,550"
    driver = start("sweep", "heave_tracking", "--grid", grid, "--set", "simulation.duration=3000",
                   "--backend", "ray", "--address", cluster, "--ray-logs", logs, "--engine", engine, "-o", str(out))
    deadline = time.monotonic() + 120  # until both running tasks have logged rows (in their scratch folders)
    while sum(any(".mcap" in f and _size(f) > 50_000 for f in files)
              for files in task_processes().values()) < 2:
        assert time.monotonic() < deadline, "the tasks did not start logging"
        time.sleep(0.05)
    driver.send_signal(signum)
    stdout, stderr = driver.communicate(timeout=120)
    assert driver.returncode == 128 + signum, stderr
    total, ran = (3, 2) if engine == "process" else (5, 4)
    assert f"interrupted by {signal.Signals(signum).name}; 0 of {total} runs had finished" in stderr
    logs = sorted((out / "logs").glob("*.mcap"))
    assert len(logs) == ran and not list((out / "logs").glob("*.partial"))  # those that ran; the last never started
    for log in logs:
        logged = read_log(log)
        assert logged.status == "interrupted" and len(logged.trajectory.t) > 10
    deadline = time.monotonic() + 30
    while task_processes() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not task_processes()


def test_resume_on_ray_finishes_a_killed_study_with_the_same_table(cluster, local_short, tmp_path):
    """A study that lost runs (logs missing, one cut short, one left as NAME.partial by a dead worker)
    is finished on Ray by --resume: only those run again, and sweep.csv is the uninterrupted one's.
    With no --address a new Ray starts here, even with another cluster running on the machine."""
    study = tmp_path / "killed"
    shutil.copytree(local_short, study)
    for name in ("sweep.csv", "sweep.json", "rows.jsonl"):
        (study / name).unlink()
    logs = sorted((study / "logs").glob("*.mcap"))
    logs[0].unlink()
    data = logs[3].read_bytes()
    logs[3].write_bytes(data[: len(data) // 2])
    logs[5].rename(logs[5].with_name(logs[5].name + ".partial"))
    r = cli("sweep", *SHORT, "--backend", "ray", "--jobs", "2", "--resume", str(study))
    assert r.returncode == 0, r.stderr
    assert "on Ray (started here, logs as bytes)" in r.stderr
    assert "(3 already finished, 3 to run)" in r.stderr
    assert (study / "sweep.csv").read_bytes() == (local_short / "sweep.csv").read_bytes()
    same_logs(study, local_short)
    assert not list((study / "logs").glob("*.partial"))


def test_a_log_the_driver_cannot_write_is_reported_and_replays_truncated(cluster, tmp_path):
    """Logs sent back as bytes, the driver under a file-size limit: the long run's log is cut, that
    run is an error naming it, the short run is ok, the table is written (exit 1), no traceback."""
    out = tmp_path / "ray"
    r = cli("sweep", "heave_tracking", "--grid", "simulation.duration=1,20", "--set", "success.tail_rms=inf",
            "--backend", "ray", "--address",
            cluster, "-o", str(out), prefix="ulimit -f 60;")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    cut = out / "logs" / "0001-duration=20-seed0.mcap"
    assert f"{cut}: the log could not be written (File too large); what was written reads as truncated" in r.stderr
    rows = (out / "sweep.csv").read_text().splitlines()
    assert len(rows) == 3 and ",ok," in rows[1] and ",error," in rows[2]
    logged = read_log(cut)
    assert logged.status == "truncated" and len(logged.trajectory.t) >= 100


def test_ray_options_are_checked_in_one_line(tmp_path):
    r = cli("sweep", *SHORT, "--address", "auto")
    assert r.returncode == 2
    assert r.stderr.strip() == ("adaptive-mj: error: --address is for --backend ray "
                                "(this command runs on --backend local)")
    r = cli("sweep", *SHORT, "--backend", "ray", "--address", "127.0.0.1:1", "-o", str(tmp_path / "a"), timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines()[-1].startswith("adaptive-mj: error: --address '127.0.0.1:1': nothing answers "
                                                        "at 127.0.0.1:1 (")
    r = cli("sweep", *SHORT, "--backend", "ray", "--address", "headnode", "-o", str(tmp_path / "b"), timeout=60)
    assert r.returncode == 2 and "expected auto, HOST:PORT" in r.stderr
    r = cli("sweep", *SHORT, "--resume", str(tmp_path), "-o", str(tmp_path / "c"))
    assert r.returncode == 2 and f"-o {tmp_path / 'c'} cannot be combined with it" in r.stderr


def test_runs_that_fail_or_diverge_are_recorded_once_and_not_retried(cluster, tmp_path):
    """Through the Python API on the cluster: a scenario file no node has is an error naming the node
    and the remedy; a run that diverges is a result; neither is submitted again."""
    from adaptive_mj.study.parallel import Backend, RunSpec, iter_results

    retried = []
    jobs = [RunSpec(tmp_path / "nowhere.toml", tag="missing"),
            RunSpec(REPO / "scenarios" / "heave_tracking.toml", ("simulation.state_bound=0.5",
                                                            "simulation.initial_state=[1.0, 0.0]"), tag="diverges"),
            RunSpec(REPO / "scenarios" / "heave_tracking.toml", ("simulation.duration=0.2",), tag="fine")]
    results = dict(iter_results(jobs, Backend(kind="ray", address=cluster),
                                on_retry=lambda job, why: retried.append(job.tag)))
    assert sorted(results) == [0, 1, 2] and retried == []
    assert results[0].status == "error"
    assert results[0].error.startswith(f"{tmp_path / 'nowhere.toml'}: no such file on the Ray node ")
    assert "every node must see the scenarios and models at the same paths" in results[0].error
    assert results[1].status == "diverged" and results[1].summary["reason"]
    assert results[2].status == "ok" and results[2].trajectory is not None


@pytest.mark.usefixtures("small_catalogue")
def test_bench_on_ray_writes_the_local_report(cluster, tmp_path, capsys):
    """`bench --backend ray` (a reduced catalogue, in this process, on the cluster): the report, apart
    from its line of timings, summary.json and every log's messages equal the local backend's."""
    import json

    from adaptive_mj.cli import main

    ray_out, local_out = tmp_path / "ray", tmp_path / "local"
    assert main(["bench", "--quick", "-o", str(ray_out), "--backend", "ray", "--address", cluster]) == 0
    assert main(["bench", "--quick", "-o", str(local_out), "--jobs", "2"]) == 0
    reports = [(d / "report.md").read_text().splitlines() for d in (ray_out, local_out)]
    assert "one Ray task per run" in reports[0][2] and "2 worker processes" in reports[1][2]
    assert reports[0][3:] == reports[1][3:] and len(reports[0]) > 20
    summaries = [json.loads((d / "summary.json").read_text()) for d in (ray_out, local_out)]
    assert summaries[0] == summaries[1]
    same_logs(ray_out, local_out)

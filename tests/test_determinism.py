"""The same scenario and seed give byte-identical MCAP message payloads across two separate
processes (wall-clock metadata aside); another seed gives other payloads."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from mcap.reader import make_reader

REPO = Path(__file__).resolve().parents[1]


def run_in_new_process(log: Path, *args: str) -> None:
    env = dict(os.environ, MUJOCO_GL="egl", PYTHONHASHSEED="random")
    r = subprocess.run([sys.executable, "-m", "adaptive_mj", "run", "heave_drift", "-o", str(log),
                        "--set", "simulation.duration=2.0", *args], cwd=REPO, env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr


def messages(log: Path) -> list[tuple[str, int, int, bytes]]:
    """(topic, log_time, publish_time, payload) of every message, in file order."""
    with open(log, "rb") as f:
        return [(channel.topic, m.log_time, m.publish_time, m.data)
                for _, channel, m in make_reader(f).iter_messages(log_time_order=False)]


def metadata(log: Path) -> dict[str, dict[str, str]]:
    with open(log, "rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def test_same_seed_same_payloads_in_two_processes(tmp_path):
    a, b, other = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "other.mcap"
    run_in_new_process(a, "--seed", "3")
    run_in_new_process(b, "--seed", "3")
    run_in_new_process(other, "--seed", "4")

    ma, mb = messages(a), messages(b)
    assert len(ma) == 200 + 1  # one /row message per logged row (100 Hz for 2 s, format 8) and the summary
    assert ma == mb
    topics = {topic for topic, *_ in ma}
    assert topics == {"/row", "/summary"}

    meta_a, meta_b = metadata(a), metadata(b)
    for meta in (meta_a, meta_b):
        del meta["adaptive_mj"]["created_unix"]  # wall-clock time, the one thing allowed to differ
    assert meta_a == meta_b

    # the noise is the seed's: another seed gives other states (the reference is the same): a /row payload is the
    # CDR header, t, then state (y, y_dot) and reference (y_d, y_d_dot, y_d_ddot), 8 bytes each
    mo = messages(other)

    def part(msgs, first, count):
        return [(m[1], m[3][4 + 8 * first:4 + 8 * (first + count)]) for m in msgs if m[0] == "/row"]

    assert part(ma, 1, 2) != part(mo, 1, 2)
    assert part(ma, 3, 3) == part(mo, 3, 3) and part(ma, 0, 1) == part(mo, 0, 1)

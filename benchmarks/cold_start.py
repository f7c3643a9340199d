"""Cold against warm (issue 51's targets): wall seconds of what a user waits for first, each measured in fresh
processes with an empty numba cache (cold: NUMBA_CACHE_DIR a new folder) and again with that cache filled (warm),
with the ratio and the number of compiled variants the cold run left in the cache.

  run           `adaptive-mj run heave_tracking` (the scenario's full length)
  ur5e_plugin   `adaptive-mj run ur5e_identification` under the multi-joint example law plugin
                (examples/robust_sl_law, pip-installed; skipped with a note when it is not)
  bench_quick   `adaptive-mj bench --quick`                  (with --bench)
  bench         `adaptive-mj bench` (the README's main job)   (with --bench; minutes)

Targets (issue 51): cold `run heave_tracking` <= 10 s; cold first UR5e plugin run <= 20 s; cold bench <= 1.3x
warm bench. CPU seconds (user + system, the command's and its workers') are printed beside the wall seconds:
on a loaded machine they are the figures to compare. The machine's load is printed beside the figures
(os.getloadavg before and after each case): on a shared machine the figures are only comparable within one invocation.

--compile-pairs: each kind's cold compile alone (one bundled scenario per kind, a fresh process and an empty cache
each), with numba's inliner as it comes (ADAPTIVE_MJ_SHARED_INLINE_COPIES=0) and with numba_util.shared_inline_copies
(=1), one after the other: the CPU seconds compile_note says for each variant, and their ratio.

Usage: python benchmarks/cold_start.py [--bench] [--only run,ur5e_plugin,bench_quick,bench] [--compile-pairs]
       [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PLUGIN = "law={kind='robust_sl', lambda=10.0, kd=50.0, ks=0.0, gamma=0.2}"


def plugin_installed(name: str) -> bool:
    from adaptive_mj.laws.plugin import installed

    return name in installed()


CASES: dict[str, list[str]] = {
    "run": ["run", "heave_tracking"],
    "ur5e_plugin": ["run", "ur5e_identification", "--set", PLUGIN],
    "bench_quick": ["bench", "--quick"],
    "bench": ["bench"],
}


def variants(cache: Path) -> int:
    """Compiled functions in a numba cache folder: its index files (one per function, each holding its
    specialisations)."""
    return sum(1 for _ in cache.rglob("*.nbi"))


def timed(args: list[str], env: dict, out: Path) -> tuple[float, float]:
    """(wall [s], CPU [s]: user + system of the command and every process it waited for) of one command."""
    target = out if args[0] == "bench" else out.with_suffix(".mcap")  # bench: a folder; run: a log file
    cmd = [sys.executable, "-m", "adaptive_mj", *args, "-o", str(target)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    took = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode not in (0, 1):  # 1: a run or study that reports a failure still ran to its end
        raise RuntimeError(f"{' '.join(cmd)} exited {done.returncode}: {done.stderr.strip()[-400:]}")
    return took, cpu


#: one bundled scenario per compiled kind (run long enough to take the compiled path), for --compile-pairs
PAIRS = {"1-DOF callback": ["heave_tracking"],
         "arm callback": ["ur5e_payload_swap", "--set", "simulation.duration=0.5", "--set", "events=[]"],
         "quadrotor callback": ["quadrotor_lemniscate", "--set", "simulation.duration=0.5"],
         "linear MRAC chunk": ["mrac_time_delay"],
         "twin chunk": ["lecture_heave"]}
COMPILED = re.compile(r"^adaptive-mj: compiled (?P<what>.+) in (?P<wall>[0-9.]+) s \((?P<cpu>[0-9.]+) s of CPU\)")


def compile_pair(name: str) -> dict:
    """{shared: {what: CPU seconds}} of one kind's scenario compiled cold, without (0) and with (1) shared copies."""
    out: dict = {}
    for shared in ("0", "1"):
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as logs:
            env = dict(os.environ, NUMBA_CACHE_DIR=cache, ADAPTIVE_MJ_LOGS=logs, ADAPTIVE_MJ_COMPILE_NOTES="1",
                       ADAPTIVE_MJ_SHARED_INLINE_COPIES=shared)
            cmd = [sys.executable, "-m", "adaptive_mj", "run", *PAIRS[name], "-o", str(Path(logs) / "x.mcap")]
            done = subprocess.run(cmd, env=env, capture_output=True, text=True)
            out[shared] = {m["what"]: float(m["cpu"]) for m in map(COMPILED.match, done.stderr.splitlines()) if m}
    return out


def cold_warm(name: str) -> dict:
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as logs:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, ADAPTIVE_MJ_LOGS=logs)
        load0 = os.getloadavg()[0]
        cold, cold_cpu = timed(CASES[name], env, Path(logs) / "cold")
        n = variants(Path(cache))
        warm, warm_cpu = timed(CASES[name], env, Path(logs) / "warm")
        return {"cold_s": cold, "warm_s": warm, "ratio": cold / warm, "variants": n, "cold_cpu_s": cold_cpu,
                "warm_cpu_s": warm_cpu, "cpu_ratio": cold_cpu / warm_cpu,
                "load": [round(load0, 2), round(os.getloadavg()[0], 2)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bench", action="store_true", help="also `bench --quick` and `bench` (minutes)")
    ap.add_argument("--only", default="", help="comma-separated cases: " + ", ".join(CASES))
    ap.add_argument("--json", default="", help="also write the figures to this file")
    ap.add_argument("--compile-pairs", action="store_true",
                    help="each kind's cold compile with numba's inliner as it comes and with shared inline copies")
    a = ap.parse_args()
    if a.compile_pairs:
        print(f"{'variant':<100} {'CPU as numba':>12} {'CPU shared':>10} {'ratio':>6}  load (1 min)")
        pairs = {}
        for kind in PAIRS:
            pair = compile_pair(kind)
            pairs[kind] = pair
            for what, alone in pair["0"].items():
                shared = pair["1"].get(what, float("nan"))
                print(f"{what[:100]:<100} {alone:12.1f} {shared:10.1f} {shared / alone:6.2f}  {os.getloadavg()[0]:.2f}",
                      flush=True)
        if a.json:
            Path(a.json).write_text(json.dumps({"compile_pairs": pairs}, indent=1) + "\n")
        return
    names = [n for n in a.only.split(",") if n] or ["run", "ur5e_plugin"] + (["bench_quick", "bench"] if a.bench
                                                                           else [])
    unknown = [n for n in names if n not in CASES]
    if unknown:
        sys.exit(f"cold_start.py: --only: unknown case(s) {unknown}; expected some of {list(CASES)}")
    out = {"cores": os.cpu_count(), "cases": {}}
    print(f"{'case':<12} {'cold [s]':>9} {'warm [s]':>9} {'cold/warm':>9} {'variants':>8} {'CPU cold':>9} "
          f"{'CPU warm':>9} {'cold/warm':>9}  load (1 min) before, after")
    for name in names:
        if name == "ur5e_plugin" and not plugin_installed("robust_sl"):
            print(f"{name:<12} skipped: pip install examples/robust_sl_law first")
            continue
        fig = cold_warm(name)
        out["cases"][name] = fig
        print(f"{name:<12} {fig['cold_s']:9.1f} {fig['warm_s']:9.1f} {fig['ratio']:9.2f} {fig['variants']:8d} "
              f"{fig['cold_cpu_s']:9.1f} {fig['warm_cpu_s']:9.1f} {fig['cpu_ratio']:9.2f}  "
              f"{fig['load'][0]:.2f}, {fig['load'][1]:.2f}", flush=True)
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n")


if __name__ == "__main__":
    main()

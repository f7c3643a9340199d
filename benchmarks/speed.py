"""Speed benchmark: µs per physics step of bare MuJoCo stepping against the
closed loop (adaptive law in the control callback), on the heave and arm
models, in one process. Prints medians over repetitions with the spread and
the ratios. Usage: python benchmarks/speed.py [--reps 5] [--steps 20000] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj import scenario as sc
from adaptive_mj.build import build
from adaptive_mj.loop import run
from adaptive_mj.runner import execute

REPO = Path(__file__).resolve().parents[1]
CASES = {"heave": "heave_tracking", "arm": "arm_payload_swap"}


def _bare(setup, steps: int) -> float:
    m = setup.plant.model
    d = mujoco.MjData(m)
    t0 = time.perf_counter()
    mujoco.mj_step(m, d, nstep=steps)
    return (time.perf_counter() - t0) / steps * 1e6


def _loop(scn, steps: int, log: bool) -> float:
    duration = steps * 0.001
    s = sc.load(scn, overrides=[f"simulation.duration={duration}", "events=[]"])
    if log:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            execute(s, log_path=Path(tmp) / "x.mcap")
            return (time.perf_counter() - t0) / steps * 1e6
    setup = build(s)
    t0 = time.perf_counter()
    run(setup.plant, setup.law, setup.reference, duration=duration, theta_hat0=setup.theta_hat0)
    return (time.perf_counter() - t0) / steps * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = {"cores": os.cpu_count(), "steps": args.steps, "reps": args.reps, "models": {}}
    for plant, name in CASES.items():
        path = REPO / "scenarios" / f"{name}.toml"
        setup = build(sc.load(path))
        rows = {}
        for key, fn in (("a_bare_mj_step", lambda: _bare(setup, args.steps)),
                        ("b_closed_loop", lambda: _loop(path, args.steps, False)),
                        ("c_closed_loop_logged", lambda: _loop(path, args.steps, True))):
            xs = [fn() for _ in range(args.reps)]
            rows[key] = {"median_us": statistics.median(xs), "min_us": min(xs), "max_us": max(xs)}
        a = rows["a_bare_mj_step"]["median_us"]
        ratios = {f"{k[0]}/a": v["median_us"] / a for k, v in rows.items() if not k.startswith("a")}
        out["models"][plant] = {"integrator": "RK4", "us_per_step": rows, "ratios": ratios}
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"cores: {out['cores']}, {args.steps} steps x {args.reps} reps (median [min, max] µs/step)")
    for plant, res in out["models"].items():
        for key, v in res["us_per_step"].items():
            print(f"  {plant:6s} {key:22s} {v['median_us']:8.2f} [{v['min_us']:.2f}, {v['max_us']:.2f}]")
        print("  " + plant + " ratios: " + ", ".join(f"{k} = {v:.1f}" for k, v in res["ratios"].items()))


if __name__ == "__main__":
    main()

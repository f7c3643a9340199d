"""The quadrotor's when2fail and delay margins (adaptive_mj.study.flight; AdaptiveQuadBench's definitions), by
bisection: per flight law and disturbance, the largest intensity at which every seed succeeds (the margin) and
the smallest at which every seed fails (when2fail), each with the nearest value tried on its other side. A run
fails by the rule --rule names (flight.RULES): "ours" (a crash, 1 m of position error at any time, or the
stability criteria) or "aqb" (AdaptiveQuadBench's trials: an RMS position error of 5 m or more, no crash check).

    python benchmarks/flight_margins.py [--seeds 3] [--steps 8] [--jobs 2] [--rule ours] [--json]
        [-o logs/flight_margins]

Prints the table, the runs and the wall time. Every run is logged (MCAP, 20 Hz) under the output folder.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from adaptive_mj.study import flight


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=8, help="bisection rounds after the range's ends")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--rule", choices=tuple(flight.RULES), default="ours", help="what fails a run (flight.RULES)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("-o", "--output", type=Path, default=Path("logs") / "flight_margins")
    args = ap.parse_args()
    t0 = time.perf_counter()
    found = flight.margins(flight.searches(), seeds=args.seeds, steps=args.steps, logs=args.output,
                           n_jobs=args.jobs, rule=args.rule)
    wall = time.perf_counter() - t0
    runs = sum(len(s.evaluations) for s in found) * args.seeds
    if args.json:
        print(json.dumps({"seeds": args.seeds, "steps": args.steps, "rule": args.rule, "runs": runs, "wall_s": wall,
                          "rows": flight.as_rows(found)}, indent=2))
        return
    failure = (f"a crash, ‖p_d − p‖ > {flight.MAX_ERROR:g} m at any time, or the stability criteria"
               if args.rule == "ours" else f"RMS ‖p_d − p‖ >= {flight.AQB_RMS_BOUND:g} m over the run (no crash check)")
    print(f"failure ({args.rule}): {failure} in a {flight.RUN_SECONDS:g} s lemniscate; {args.seeds} seeds per "
          f"intensity; {args.steps} bisection rounds")
    print(flight.table(found))
    print(f"\n{runs} runs in {wall:.0f} s on {args.jobs} worker processes")


if __name__ == "__main__":
    main()

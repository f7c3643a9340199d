"""The quadrotor's when2fail and delay margins (adaptive_mj.study.flight; AdaptiveQuadBench's definitions), by
bisection: per airframe, flight law and disturbance, the largest intensity at which every seed succeeds (the
margin) and the smallest at which every seed fails (when2fail), each with the nearest value tried on its other
side. A run fails by the rule --rule names (flight.RULES): "ours" (a crash, 1 m of position error at any time, or
the stability criteria), "aqb" (AdaptiveQuadBench's trials: an RMS position error of 5 m or more, no crash check),
or both (one bisection per rule, sharing the runs they both ask for).

--airframe: the bundled Crazyflie on its lemniscate at RotorPy's gains, AdaptiveQuadBench's 0.826 kg vehicle on its
lemniscate at AdaptiveQuadBench's gains (flight.VEHICLES; the disturbances' ranges scaled by the vehicles' weight,
spare lift and roll authority: flight.SCALES), or both. --study delay-test runs AdaptiveQuadBench's delay test
(flight.delay_test: the delay raised by 10 ms until a trajectory's largest error passes 1 m, over a hover, a circle
and 3 rapid trajectories per seed) instead of the bisection, both runs both; each judged by the same rule(s)
(flight.DELAY_RULES for the delay test).

    python benchmarks/flight_margins.py [--airframe crazyflie|aqb|both] [--rule ours|aqb|both]
        [--study bisection|delay-test|both]
        [--seeds 3] [--steps 8] [--jobs 2] [--json] [-o logs/flight_margins]

Prints the table per rule, the runs and the wall time of each study (--json: format FORMAT). Every run is logged
(MCAP, 20 Hz) under the output folder.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from adaptive_mj.study import flight

#: the --json object's format: 2 adds the airframe (each row's and the run's), several rules ("rules": {rule:
#: rows}), the delay test's rows with each trajectory's margin, and each study's wall time
FORMAT = 2


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--airframe", choices=(*flight.VEHICLES, "both"), default="crazyflie")
    ap.add_argument("--rule", choices=(*flight.RULES, "both"), default="ours", help="what fails a run (flight.RULES)")
    ap.add_argument("--study", choices=("bisection", "delay-test", "both"), default="bisection",
                    help="the margins' bisection, AdaptiveQuadBench's delay test, or both")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=8, help="bisection rounds after the range's ends")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("-o", "--output", type=Path, default=Path("logs") / "flight_margins")
    args = ap.parse_args()
    frames = tuple(flight.VEHICLES) if args.airframe == "both" else (args.airframe,)
    rules = tuple(flight.RULES) if args.rule == "both" else (args.rule,)
    by_rule: dict[str, list[flight.Search]] = {r: [] for r in rules}
    delay: dict[str, list[flight.Search]] = {r: [] for r in rules}
    walls: dict[str, float] = {}
    runs = 0
    for frame in frames:
        if args.study in ("bisection", "both"):
            t0 = time.perf_counter()
            found = flight.margins_by_rule(flight.searches(airframe=frame), rules=rules, seeds=args.seeds,
                                           steps=args.steps, logs=args.output, n_jobs=args.jobs)
            walls[f"{frame} bisection"] = time.perf_counter() - t0
            runs += len({(s.airframe, s.law, s.disturbance.name, v) for f in found.values() for s in f
                         for v in s.evaluations}) * args.seeds
            for r in rules:
                by_rule[r] += found[r]
        if args.study in ("delay-test", "both"):
            t0 = time.perf_counter()
            scan = flight.delay_test(airframe=frame, seeds=args.seeds, logs=args.output, n_jobs=args.jobs,
                                     rules=rules)
            walls[f"{frame} delay test"] = time.perf_counter() - t0
            runs += sum(sum(len(row) for row in s.evaluations.values()) for s in scan[rules[0]])  # an upper bound
            for r in rules:
                delay[r] += scan[r]
    step = flight.AQB_DELAY_TEST.step.number
    if args.json:
        out = {r: {"rows": flight.as_rows(by_rule[r]),
                   "delay_test": [dict(row, trajectory_margins=flight.scan_margins(s, step))
                                  for s, row in zip(delay[r], flight.as_rows(delay[r]), strict=True)]}
               for r in rules}
        print(json.dumps({"format": FORMAT, "airframes": list(frames), "seeds": args.seeds, "steps": args.steps,
                          "wall_s": walls, "rules": out}, indent=2))
        return
    for r in rules:
        failure = (f"a crash, ‖p_d − p‖ > {flight.MAX_ERROR:g} m at any time, or the stability criteria"
                   if r == "ours" else
                   f"RMS ‖p_d − p‖ >= {flight.AQB_RMS_BOUND:g} m over the run (no crash check); the delay test: "
                   f"max ‖p_d − p‖ > {flight.AQB_DELAY_TEST.bound.number:g} m")
        print(f"\nfailure ({r}): {failure}; {flight.RUN_SECONDS:g} s lemniscates; {args.seeds} seeds per "
              f"intensity; {args.steps} bisection rounds")
        print(flight.table(by_rule[r] + delay[r]))
        for s in delay[r]:
            m = flight.scan_margins(s, step)
            print(f"{s.airframe} {s.law}: AdaptiveQuadBench's delay margin per trajectory (seed-major, hover, circle, "
                  f"rapid...): {', '.join(f'{v:g}' for v in m)} s; mean {sum(m) / len(m):.3g} s")
    print("\nwall time: " + "; ".join(f"{k} {v:.0f} s" for k, v in walls.items())
          + f"; about {runs} runs on {args.jobs} worker processes")


if __name__ == "__main__":
    main()

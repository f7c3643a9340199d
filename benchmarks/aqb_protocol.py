"""AdaptiveQuadBench's protocol on its own vehicle (adaptive_mj.study.flight: AQB, draw_task, protocol_jobs): per
flight law, disturbance axis and intensity (its when2fail grid, 0 to 10 in steps of 1), `--seeds` trials, each a
random 5 s motion primitive and a disturbance whose direction, switch times, rotor factors and payload offset are
drawn from the trial's seed within AdaptiveQuadBench's ranges (valmik/AdaptiveQuadBench at ee7df29,
aqb/config/randomization_config.py). Every run is judged by both failure rules (flight.RULES: "aqb", an RMS
position error of 5 m or more; "ours", a crash, 1 m of error at any time, or the stability criteria).

    python benchmarks/aqb_protocol.py [--seeds 10] [--jobs 2] [--axes wind,force,...] [--laws geometric,...]
        [--levels 0,1,2] [-o logs/aqb_protocol]

Writes aqb_protocol.json (flight.protocol_output, format flight.PROTOCOL_FORMAT: the randomisation's every range
with its source, and per rule the rows and success-rate curves) and success-<rule>.png in the output folder, and
prints the when2fail table per rule and the wall time. Every run is logged (MCAP, 20 Hz) under the folder.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from adaptive_mj.study import flight
from adaptive_mj.study.parallel import run_jobs


def _names(text: str, known) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in known]
    if bad:
        raise SystemExit(f"unknown: {', '.join(bad)}; expected some of {', '.join(known)}")
    return names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=10, help="trials per intensity (AdaptiveQuadBench's default: 100)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--axes", default=",".join(flight.AXES))
    ap.add_argument("--laws", default=",".join(flight.LAWS))
    ap.add_argument("--levels", default=None, help="intensities, comma-separated (default: 0 to 10 by 1)")
    ap.add_argument("-o", "--output", type=Path, default=Path("logs") / "aqb_protocol")
    args = ap.parse_args()
    axes, laws = _names(args.axes, flight.AXES), _names(args.laws, flight.LAWS)
    levels = ([float(v) for v in args.levels.split(",")] if args.levels else flight.protocol_levels())
    t0 = time.perf_counter()
    jobs = flight.protocol_jobs(laws, axes, levels, args.seeds, args.output)
    results = {j.tag: r for j, r in zip(jobs, run_jobs(jobs, n_jobs=args.jobs), strict=True)}
    wall = time.perf_counter() - t0
    by_rule = {rule: flight.protocol_results(laws, axes, levels, args.seeds, results, rule=rule)
               for rule in ("aqb", "ours")}
    out = flight.protocol_output(by_rule, seeds=args.seeds, levels=levels)
    out["runs"], out["wall_s"] = len(jobs), wall
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "aqb_protocol.json").write_text(json.dumps(out, indent=2))
    for rule, found in by_rule.items():
        flight.plot_success_curves(out["rules"][rule]["curves"], args.output / f"success-{rule}.png",
                                   title=f"AdaptiveQuadBench's protocol, rule {rule!r}, {args.seeds} seeds")
        print(f"\nrule {rule!r}:")
        print(flight.table(found, laws))
    print(f"\n{len(jobs)} runs in {wall:.0f} s on {args.jobs} worker processes; {args.output / 'aqb_protocol.json'}")


if __name__ == "__main__":
    main()

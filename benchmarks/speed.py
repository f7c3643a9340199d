"""Speed benchmark (issue 6): µs per physics step of bare MuJoCo stepping against
the closed loop, on the heave and arm models, in one process; sweep throughput
with 1 and 2 jobs; log size per simulated second; peak memory of a 600 s run.

  a  bare MuJoCo: mj_step(m, d, nstep=N), no control, as MuJoCo ships it (its profiling timers read the clock
     around each timed stage)
  a0 the same with MuJoCo's timers off (mjcb_time returns 0), as the native runs
     (b, c, d, f, g) step (plants.mujoco_plant.timers_off); the ratios are given against both
  b  closed loop, adaptive law in the control callback (native path), no logging
  b_py  the same law through the Python callback (the path users' own laws take)
  c  closed loop with MCAP logging at the default rate (100 Hz)
  d  closed loop with MCAP logging of every physics step
  e  the example law plugin (pip install examples/emod_law; on the UR5e examples/robust_sl_law): compiled, and
     through the Python callback; e_native/b: the plugin interface's cost against the built-in law
  f  closed loop under sampled-data control at 250 Hz (control.period = 4 ms), native path
  g  6-joint arm only: c with real-robot conditions on (REAL_CONDITIONS: encoder noise and 2^17 counts,
     differentiated velocity, band-limited joint torque noise, saturation-aware adaptation, joint
     frictionloss with Coulomb and damping columns in the regressor); against a (the model without
     friction) and against a_friction, bare stepping of the same model with its frictionloss
  start-up: wall time of `adaptive-mj run <scenario> --set simulation.duration=0.01` in a fresh
     process: the first call with an empty numba cache (it compiles the callback) and the second
     (it loads it from the cache), heave vehicle and 6-joint arm

Every figure is the median of --reps repetitions, with [min, max].
Usage: python benchmarks/speed.py [--reps 5] [--steps 20000] [--models heave,ur5e] [--no-sweep] [--no-startup] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from adaptive_mj.plants.mujoco_plant import timers_off
from adaptive_mj.setup import scenario as sc
from adaptive_mj.setup.build import build
from adaptive_mj.sim.loop import run
from adaptive_mj.study.parallel import RunSpec, run_jobs

REPO = Path(__file__).resolve().parents[1]
CASES = {"heave": "heave_tracking", "arm": "arm_payload_swap", "ur5e": "ur5e_payload_swap",
         "quadrotor": "quadrotor_lemniscate"}


def timestep(name: str) -> float:
    """The scenario's physics step [s] (1 ms but on the quadrotor: 2 ms)."""
    return float(sc.load(REPO / "scenarios" / f"{name}.toml").simulation.timestep or 0.001)


def _scenario(name: str, steps: int, extra=()):
    return sc.load(REPO / "scenarios" / f"{name}.toml",
                   overrides=[f"simulation.duration={steps * timestep(name)!r}", "events=[]", *extra])


# the 6-joint arm as a real robot sees it (row g)
REAL_CONDITIONS = ("noise.std={q=1e-4}", "sensors={encoder_counts=131072, velocity='differentiated'}",
                   "disturbance={kind='noise', magnitude=0.5}", "law.saturation='freeze'", "plant.frictionloss=0.5",
                   "plant.friction_params=true")


def bare(name: str, steps: int, extra=(), *, timers: bool = True) -> float:
    """µs per bare mj_step of the scenario's model; timers: MuJoCo's profiling timers on (mj_step as MuJoCo ships
    it) or off (mjcb_time = plants.mujoco_plant.no_timer, as the native runs step: compiled_control)."""
    setup = build(_scenario(name, steps, extra))
    m, d = setup.plant.model, setup.plant.data
    with timers_off(not timers):
        if getattr(setup.plant, "airframe", None) is not None:
            return _bare_hover(setup, steps)
        t0 = time.perf_counter()
        mujoco.mj_step(m, d, nstep=steps)
        return (time.perf_counter() - t0) / steps * 1e6


HOVER_CHUNK = 250  # [steps] of open-loop hover before the quadrotor's state is put back (0.5 s: it stays aloft)


def _bare_hover(setup, steps: int) -> float:
    """µs per mj_step of the quadrotor on its hover thrusts (m g / 4 each, the true m) from the run's initial state,
    contacts and air on as in the closed loop: in chunks of HOVER_CHUNK steps, the state put back between them
    (open loop the vehicle tips over and falls within seconds, and its ground contacts would cost more than
    flight); only the mj_step calls are timed."""
    m, d, plant = setup.plant.model, setup.plant.data, setup.plant
    d.ctrl[plant.airframe.actuators] = plant.true_theta()[0] * -m.opt.gravity[2] / 4
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    x0 = np.empty(mujoco.mj_stateSize(m, spec))
    mujoco.mj_getState(m, d, x0, spec)
    elapsed, done = 0.0, 0
    while done < steps:
        n = min(HOVER_CHUNK, steps - done)
        mujoco.mj_setState(m, d, x0, spec)
        t0 = time.perf_counter()
        mujoco.mj_step(m, d, nstep=n)
        elapsed += time.perf_counter() - t0
        done += n
    return elapsed / steps * 1e6


def loop(name: str, steps: int, native: bool, *, period: float | None = None, extra=()) -> float:
    scn = _scenario(name, steps, extra)
    setup = build(scn)
    t0 = time.perf_counter()
    run(setup.plant, setup.law, setup.reference, duration=scn.simulation.duration, theta_hat0=setup.theta_hat0,
        native=native, **({} if period is None else {"control_mode": "sampled", "control_period": period}))
    return (time.perf_counter() - t0) / steps * 1e6


def startup(name: str, reps: int) -> dict:
    """Wall seconds of a 0.01 s run through the CLI in fresh processes: the first with an empty
    numba cache (NUMBA_CACHE_DIR a new folder), then `reps` more with the cache filled."""
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as logs:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, ADAPTIVE_MJ_LOGS=logs)
        cmd = [sys.executable, "-m", "adaptive_mj", "run", name, "--set", "simulation.duration=0.01"]
        times = []
        for _ in range(1 + reps):
            t0 = time.perf_counter()
            subprocess.run(cmd, env=env, check=True, capture_output=True)
            times.append(time.perf_counter() - t0)
    return {"first": times[0], "second": med(times[1:])}


# The example law plugin (examples/emod_law, installed with pip) on each 1-DOF model: its
# native row is the issue-12 target (<= 2x bare), its Python row the path a law takes that
# numba cannot compile.
PLUGIN_LAW = {
    "heave": "law={kind='emod', lambda=5.0, k=200.0, gamma_d=0.0025, gamma_p=0.1, nu=0.01, "
             "initial_estimates={d=0.0, b=0.0, c=0.0}}",
    "arm": "law={kind='emod', lambda=10.0, k=5.0, gamma_d=0.048, gamma_p=0.02, nu=0.0, initial_estimates='model'}",
    # the multi-joint example (examples/robust_sl_law) with the scenario's own λ, K_D and Γ and k_s = 0: the same
    # arithmetic as the built-in Slotine–Li plus the plugin's call and its saturation, so e/b is the interface's cost
    "ur5e": "law={kind='robust_sl', lambda=10.0, kd=50.0, ks=0.0, gamma=0.2}",
}
PLUGIN_NAME = {"heave": "emod", "arm": "emod", "ur5e": "robust_sl"}


def plugin_installed(plant: str = "heave") -> bool:
    from adaptive_mj.laws.plugin import installed

    return PLUGIN_NAME[plant] in installed()


def plugin_loop(plant: str, steps: int, native: bool) -> float:
    scn = _scenario(CASES[plant], steps, [PLUGIN_LAW[plant]])
    setup = build(scn)
    t0 = time.perf_counter()
    traj = run(setup.plant, setup.law, setup.reference, duration=scn.simulation.duration,
               theta_hat0=setup.theta_hat0, native=native)
    assert traj.meta["native"] is native
    return (time.perf_counter() - t0) / steps * 1e6


def logged(name: str, steps: int, rate_hz: float | None, extra=()) -> tuple[float, int]:
    """Closed loop with the MCAP recorder as the sink; times run() + close() like `loop` times
    run(), so set-up (model compile, log header) is outside both. Returns (µs/step, bytes)."""
    from adaptive_mj.log.record import Recorder
    from adaptive_mj.runs.runner import log_header

    scn = _scenario(name, steps, [*([f"log.rate_hz={rate_hz!r}"] if rate_hz else []), *extra])
    setup = build(scn)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.mcap"
        recorder = Recorder(path, log_header(scn, setup))
        t0 = time.perf_counter()
        traj = run(setup.plant, setup.law, setup.reference, duration=scn.simulation.duration,
                   theta_hat0=setup.theta_hat0, sink=recorder, sink_every=max(1, round(1.0 / setup.plant.dt)),
                   noise_std=setup.noise_std, rng=setup.rng, sensors=setup.sensors)
        recorder.close(traj.status, traj.reason, {})
        el = time.perf_counter() - t0
        return el / steps * 1e6, path.stat().st_size


def med(xs):
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


SWEEP_SECONDS = 30.0  # simulated seconds per sweep run


def sweep_throughput(jobs: int, runs: int) -> float:
    """Runs per minute for `runs` logged heave runs of SWEEP_SECONDS through the sweep's own
    runner (adaptive_mj.study.parallel.run_jobs): jobs 1 runs in this process, jobs 2 in forked
    workers. The native callback is compiled once in this process beforehand (as the sweep
    command does), so neither case pays the numba compile inside the timing."""
    with tempfile.TemporaryDirectory() as tmp:
        js = [RunSpec(REPO / "scenarios" / "heave_tracking.toml", (f"simulation.duration={SWEEP_SECONDS}",), seed=i,
                  log=Path(tmp) / f"{i}.mcap") for i in range(runs)]
        t0 = time.perf_counter()
        res = run_jobs(js, n_jobs=jobs)
        el = time.perf_counter() - t0
        assert all(r.status == "ok" for r in res), [r.error for r in res]
    return runs / el * 60.0


PEAK_RSS_CODE = """
import sys, tempfile
from pathlib import Path
from adaptive_mj.setup import scenario as sc
from adaptive_mj.runs.runner import execute
scn = sc.load(sys.argv[1], overrides=['simulation.duration=600.0'])
with tempfile.TemporaryDirectory() as tmp:
    execute(scn, log_path=Path(tmp) / 'run.mcap')
# VmHWM: the peak RSS of this process's own address space (ru_maxrss would also count
# the parent's pages at fork time, which Linux carries across exec)
print(next(int(line.split()[1]) for line in open('/proc/self/status') if line.startswith('VmHWM:')))
"""


def peak_rss_600s(*, gl: str | None = None) -> float:
    """Peak RSS [MB] of a 600 s heave run at 1 kHz with default logging, in a fresh process
    started as `adaptive-mj run` would be: MUJOCO_GL unset (gl=None), or set to `gl` (then
    `import mujoco` loads that GL backend, e.g. Mesa's EGL, even though nothing renders)."""
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    if gl:
        env["MUJOCO_GL"] = gl
    out = subprocess.run([sys.executable, "-c", PEAK_RSS_CODE, str(REPO / "scenarios" / "heave_tracking.toml")],
                         capture_output=True, text=True, check=True, env=env)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--sweep-runs", type=int, default=8)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--models", default=",".join(CASES), help="which of " + ", ".join(CASES) + " (comma-separated)")
    ap.add_argument("--no-sweep", action="store_true", help="skip the sweep throughput and peak RSS figures")
    ap.add_argument("--log-encoding", choices=("cdr", "json"), default="cdr",
                    help="log.encoding of the logged rows (c, d, g): cdr (format 8, the default) or json (format 6)")
    ap.add_argument("--no-startup", action="store_true",
                    help="skip the start-up figure (a cold compile with an empty numba cache: about a minute)")
    args = ap.parse_args()
    out = {"cores": os.cpu_count(), "steps": args.steps, "reps": args.reps, "log_encoding": args.log_encoding,
           "models": {}}
    encoding = (f"log.encoding={args.log_encoding!r}",)
    for plant in args.models.split(","):
        name = CASES[plant]
        loop(name, 500, True)  # compile the native callback once (numba), outside the timing
        rows = {"a_bare": [], "a0_bare_timers_off": [], "b_closed_loop": [], "b_py_python_callback": [],
                "c_logged_100Hz": [], "d_logged_every_step": [], "f_sampled_250Hz": []}
        sizes = []
        for _ in range(args.reps):
            rows["a_bare"].append(bare(name, args.steps))
            rows["a0_bare_timers_off"].append(bare(name, args.steps, timers=False))
            rows["b_closed_loop"].append(loop(name, args.steps, True))
            rows["b_py_python_callback"].append(loop(name, max(2000, args.steps // 5), False))
            c, size = logged(name, args.steps, None, encoding)
            rows["c_logged_100Hz"].append(c)
            sizes.append(size / (args.steps * timestep(name)))
            rows["d_logged_every_step"].append(logged(name, args.steps, 1000.0, encoding)[0])
            rows["f_sampled_250Hz"].append(loop(name, args.steps, True, period=0.004))
            if plant == "quadrotor":  # the other two flight laws, compiled (the row b law is geometric_adaptive)
                rows.setdefault("b_geometric", []).append(loop(name, args.steps, True, extra=("law=geometric",)))
                rows.setdefault("b_l1_geometric", []).append(loop(name, args.steps, True, extra=("law=l1_geometric",)))
            if plant == "ur5e":
                rows.setdefault("a_friction", []).append(bare(name, args.steps, ("plant.frictionloss=0.5",)))
                rows.setdefault("g_real_conditions_logged_100Hz", []).append(
                    logged(name, args.steps, None, (*REAL_CONDITIONS, *encoding))[0])
        if plant in PLUGIN_LAW and plugin_installed(plant):
            plugin_loop(plant, 500, True)  # compile once, outside the timing
            rows["e_plugin_native"], rows["e_plugin_python"] = [], []
            for _ in range(args.reps):
                rows["e_plugin_native"].append(plugin_loop(plant, args.steps, True))
                rows["e_plugin_python"].append(plugin_loop(plant, max(2000, args.steps // 5), False))
        stats = {k: med(v) for k, v in rows.items()}
        a, a0 = stats["a_bare"]["median"], stats["a0_bare_timers_off"]["median"]
        out["models"][plant] = {
            "integrator": "RK4", "timestep": timestep(name), "us_per_step": stats,
            "ratios": {"b/a": stats["b_closed_loop"]["median"] / a,
                       "b_py/a": stats["b_py_python_callback"]["median"] / a,
                       "c/a": stats["c_logged_100Hz"]["median"] / a,
                       "d/a": stats["d_logged_every_step"]["median"] / a,
                       "f/a": stats["f_sampled_250Hz"]["median"] / a,
                       "a0/a": a0 / a, "b/a0": stats["b_closed_loop"]["median"] / a0,
                       "c/a0": stats["c_logged_100Hz"]["median"] / a0,
                       **({"b_geometric/a": stats["b_geometric"]["median"] / a,
                           "b_l1/a": stats["b_l1_geometric"]["median"] / a} if "b_geometric" in stats else {}),
                       **({"g/a": stats["g_real_conditions_logged_100Hz"]["median"] / a,
                           "g/a_friction": stats["g_real_conditions_logged_100Hz"]["median"]
                           / stats["a_friction"]["median"]} if "a_friction" in stats else {}),
                       **({"e_native/a": stats["e_plugin_native"]["median"] / a,
                           "e_python/a": stats["e_plugin_python"]["median"] / a,
                           "e_native/b": stats["e_plugin_native"]["median"] / stats["b_closed_loop"]["median"]}
                          if "e_plugin_native" in stats else {})},
            "log_bytes_per_sim_second_100Hz": statistics.median(sizes),
        }
        if plant in ("heave", "ur5e") and not args.no_startup:
            out["models"][plant]["startup_s"] = startup(name if plant == "heave" else "ur5e_identification",
                                                        max(3, args.reps))
    if args.no_sweep:
        print(json.dumps(out, indent=2)) if args.json else _print_models(out)
        return
    t1, t2 = [], []
    for _ in range(max(1, args.reps // 2)):  # interleaved, so slow spells of a shared machine hit both
        t1.append(sweep_throughput(1, args.sweep_runs))
        t2.append(sweep_throughput(2, args.sweep_runs))
    out["sweep_runs_per_minute"] = {"jobs1": med(t1), "jobs2": med(t2),
                                    "speedup": statistics.median(t2) / statistics.median(t1)}
    out["peak_rss_mb_600s_heave_logged"] = med([peak_rss_600s() for _ in range(3)])
    out["peak_rss_mb_600s_heave_logged_with_MUJOCO_GL_egl"] = peak_rss_600s(gl="egl")
    if args.json:
        print(json.dumps(out, indent=2))
        return
    _print_models(out)
    sw = out["sweep_runs_per_minute"]
    print(f"\nsweep ({args.sweep_runs} x {SWEEP_SECONDS:g} s heave runs, logged): "
          f"jobs 1 {sw['jobs1']['median']:.1f} runs/min, jobs 2 {sw['jobs2']['median']:.1f} runs/min, "
          f"speed-up {sw['speedup']:.2f}x")
    rss = out["peak_rss_mb_600s_heave_logged"]
    print(f"peak RSS of a 600 s heave run at 1 kHz with default logging: {rss['median']:.0f} MB "
          f"[{rss['min']:.0f}, {rss['max']:.0f}] (3 fresh processes, MUJOCO_GL unset); "
          f"{out['peak_rss_mb_600s_heave_logged_with_MUJOCO_GL_egl']:.0f} MB with MUJOCO_GL=egl")


def _print_models(out: dict) -> None:
    print(f"cores: {out['cores']}; {out['steps']} steps per figure; median [min, max] of {out['reps']} reps; "
          f"log.encoding = {out['log_encoding']}")
    for plant, res in out["models"].items():
        print(f"\n{plant} (RK4, {res['timestep'] * 1000:g} ms):")
        for key, v in res["us_per_step"].items():
            print(f"  {key:24s} {v['median']:8.2f} µs/step  [{v['min']:.2f}, {v['max']:.2f}]")
        print("  ratios: " + ", ".join(f"{k} = {v:.2f}" for k, v in res["ratios"].items()))
        print(f"  log size at 100 Hz: {res['log_bytes_per_sim_second_100Hz'] / 1000:.1f} kB per simulated second")
        if "startup_s" in res:
            st = res["startup_s"]
            print(f"  start-up (CLI, 0.01 s run): first call {st['first']:.2f} s (compiles), second call "
                  f"{st['second']['median']:.2f} s [{st['second']['min']:.2f}, {st['second']['max']:.2f}] (cache)")


if __name__ == "__main__":
    main()

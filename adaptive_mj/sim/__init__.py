"""The closed loop: loop.py runs a law on a plant (the law in MuJoCo's control callback, estimates integrated
with the physics), driver.py drives every path between steps (events, noise, rows, divergence, termination),
stage.py is the one order of a control step, the native*.py modules compile it (with the plant's and law's
pieces) into that callback or an analytic plant's chunk, batch.py steps many runs through mujoco.batch,
preflight.py checks a loop before it runs, interrupt.py turns SIGINT/SIGTERM into a clean stop. One scenario
end to end (build, run, judge, log) is adaptive_mj.runs, a layer above this one."""

"""Many native runs in one process on `mujoco.batch.Batch` (issue 20, first part): the runs' physics
stepped together on a thread pool, each run otherwise exactly as `loop.run` drives it.

Each run is set up by `loop.prepare` (its rows, events, noise, native controller and context) and
driven by `driver.chunks`, the generator every path drives (adaptive_mj.sim.driver): before each
chunk the run's events are applied and its callback buffers filled, then it asks for n physics
steps. Here the runs that ask for the same n are stepped together: each run's MjData state
(mjSTATE_INTEGRATION: time, qpos, qvel, act, warm start, ctrl, applied forces and `userdata`, whose
first slot points the compiled callback at the run's own context) is copied into its row of the
batch, `Batch.step(ids, nstep=n)` steps those rows on the batch's threads with the run's own
MjModel (`set_models`: events that change a model, such as a payload's mass, apply to its run
only), and the rows are copied back. MuJoCo documents `Batch` as bit-identical to stepping one
MjData per simulation, so every run gives the rows `loop.run` gives (tests/test_batch.py).

What differs from loop.run: MuJoCo's warnings (`plant.instability()`) are not seen, because the
batch steps its own MjData; a non-finite state is still caught by the divergence check, and a
simulation the batch reports failed ends its run as "diverged" with MuJoCo's message. All runs of one
batch share one control callback (the same compiled law and plant form) and one model layout.
"""
from __future__ import annotations

from collections import defaultdict
from typing import Any, Sequence

import mujoco
import mujoco.batch
import numpy as np

from adaptive_mj.errors import Interrupted
from adaptive_mj.plants.mujoco_plant import layout
from adaptive_mj.sim.driver import chunks
from adaptive_mj.sim.loop import PreparedRun, drive, prepare
from adaptive_mj.sim.native_context import ContextOwner
from adaptive_mj.trajectory import Status, Trajectory

__all__ = ["run_batch"]

_STATE = mujoco.mjtState.mjSTATE_INTEGRATION


BATCH_CHUNK = 1000  # physics steps per Batch.step call (the runs' Python work is per chunk; 1 s at 1 ms)


def run_batch(runs: Sequence[dict[str, Any]], *, nthread: int = 0, chunk: int = BATCH_CHUNK) -> list[Trajectory]:
    """Run each of `runs` (the keyword arguments of loop.run: plant, law, reference, duration,
    theta_hat0, ...; each on its own plant) with its physics stepped in one mujoco.batch.Batch of
    nthread threads (0: all CPUs), at most `chunk` physics steps per Batch.step call. Returns their
    trajectories, in order. Runs with the same compiled callback and model layout are stepped in one
    batch each; a run without a compiled callback (native False, or a law numba cannot compile) runs
    alone on the Python path, as loop.run runs it."""
    prepared: list[PreparedRun] = []
    out: list[Trajectory | None] = [None] * len(runs)
    try:
        for r in runs:
            prepared.append(prepare(**{**r, "chunk": chunk}))
        groups: dict[tuple, list[int]] = defaultdict(list)
        for i, p in enumerate(prepared):
            if p.nc is None or not p.nc.in_mujoco:  # the Python path, or an analytic plant's compiled loop
                out[i] = drive(p, runs[i]["law"], runs[i]["reference"])
            else:
                groups[(id(p.nc.callback), layout(p.nc.plant.model))].append(i)
        for ids in groups.values():
            ncs = [prepared[i].nc for i in ids]
            _drive([prepared[i] for i in ids], [nc for nc in ncs if nc is not None], nthread, out, ids)
    except KeyboardInterrupt as exc:
        raise _interrupted(exc, prepared, out) from (None if isinstance(exc, Interrupted) else exc)
    return [tr for tr in out if tr is not None]


def _interrupted(exc: KeyboardInterrupt, prepared: list[PreparedRun], out: list[Trajectory | None]) -> Interrupted:
    """A stop signal mid-batch, as errors.Interrupted carrying `trajectories`: for each run, its trajectory
    if it had ended, else its rows so far (status "interrupted", every whole row handed to its sink, as
    loop.run hands them), and None for a run not yet prepared."""
    interrupted = exc if isinstance(exc, Interrupted) else Interrupted()
    trajectories: list[Trajectory | None] = [
        tr if tr is not None or i >= len(prepared) else prepared[i].rows.stopped(str(interrupted))
        for i, tr in enumerate(out)]
    interrupted.trajectories = trajectories
    return interrupted


def _drive(prepared: list[PreparedRun], ncs: list[ContextOwner], nthread: int, out: list[Trajectory | None],
           ids: list[int]) -> None:
    """Step the runs `prepared` (of one callback and model layout) in one Batch; each run's trajectory goes
    to out[ids[i]] as it ends."""
    from adaptive_mj.plants.mujoco_plant import compiled_control

    plants = [nc.plant for nc in ncs]
    batch = mujoco.batch.Batch(plants[0].model, nsim=len(prepared), nthread=nthread)
    batch.set_models([pl.model for pl in plants])
    state = np.empty(mujoco.mj_stateSize(plants[0].model, _STATE))
    results = _Ended(prepared, out, ids)
    steps = {}
    with compiled_control(ncs[0].callback), _all_bound(ncs):
        asks: dict[int, int] = {}
        for i, p in enumerate(prepared):
            assert p.nc is not None  # every run here has its native controller (grouped by its callback above)
            steps[i] = chunks(p.plant, p.nc, p.rows, p.queue, p.noise, p.state_bound)
            _advance(steps, i, None, asks, results)
        while asks:
            groups: dict[int, list[int]] = defaultdict(list)
            for i, n in asks.items():
                groups[n].append(i)
            for n, ids in sorted(groups.items()):
                for i in ids:
                    pl = plants[i]
                    pl.native_prestep()
                    mujoco.mj_getState(pl.model, pl.data, state, _STATE)
                    batch.state[i] = state
                failed = _step(batch, ids, n)
                for i in ids:
                    pl = plants[i]
                    mujoco.mj_setState(pl.model, pl.data, batch.state[i], _STATE)
                    pl.native_poststep()
                    if i in failed:
                        results[i] = (Status.DIVERGED, failed[i])
                        asks.pop(i)
                        continue
                    _advance(steps, i, None, asks, results)


class _Ended(dict):
    """run -> (status, reason) as runs end; each ended run's trajectory is put in `out` at once, so a
    stop signal later in the batch finds it (run_batch's _interrupted)."""

    def __init__(self, prepared: list[PreparedRun], out: list[Trajectory | None], ids: list[int]):
        super().__init__()
        self.prepared, self.out, self.ids = prepared, out, ids

    def __setitem__(self, i: int, ended: tuple[Status, str]) -> None:
        super().__setitem__(i, ended)
        self.out[self.ids[i]] = self.prepared[i].result(*ended)


def _advance(steps, i: int, value, asks: dict[int, int], results: dict[int, tuple[Status, str]]) -> None:
    """Resume run i's generator: its next step count into asks, or its (status, reason) into results."""
    try:
        asks[i] = steps[i].send(value) if i in asks else next(steps[i])
    except StopIteration as done:
        asks.pop(i, None)
        results[i] = done.value


def _step(batch, ids: list[int], n: int) -> dict[int, str]:
    """Step the rows `ids` n physics steps; {row: MuJoCo's message} for the simulations that failed."""
    try:
        batch.step(ids=np.asarray(ids), nstep=n)
    except mujoco.batch.SimulationError:
        return {i: f"MuJoCo: {batch.error(i)}" for i in ids if batch.error(i)}
    return {}


class _all_bound:
    """Every run's context bound to its MjData while the batch runs (and unbound after, as loop.run's
    `with nc:` does)."""

    def __init__(self, ncs: list[ContextOwner]):
        self.ncs = ncs

    def __enter__(self):
        for nc in self.ncs:
            nc.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        for nc in self.ncs:
            nc.__exit__(*exc)

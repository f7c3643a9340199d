"""dm_env environments over the benchmark's scenarios, built on dm_control's
``control.Environment`` and a ``control.Task``.

    env = adaptive_mj.env.load("heave_tracking")            # an agent supplies u
    env = adaptive_mj.env.load("heave_tracking", law="scenario")  # the scenario's law does

The physics is the scenario's own plant: each episode calls
``adaptive_mj.setup.build.build(scenario)`` and the dm_control ``Physics`` wraps that
plant's MjModel and MjData (shared, not copied). The plant stays the only
code that knows joint and actuator ids and true parameters, and an episode is
stepped exactly as ``adaptive-mj run`` steps a run (``loop.run``): one
``plant.step()`` per physics step, the scenario's events applied at the first
step with t_k >= t_event, its disturbance held over each step, the control
written inside MuJoCo's control callback (installed only while the physics
steps, then the previous one is restored).

Episode. Starts from the scenario's initial state; every episode rebuilds the
plant, so events (payload swap, density scale, constant force) are undone
and the noise generator restarts from the seed: with the same actions,
episodes are identical. It ends (StepType.LAST) after the run's
round(duration / dt) physics steps, i.e. ceil(round(duration / dt) / n_sub_steps)
agent steps (the last one shorter when they do not divide), with discount 1.0
(a time limit, as in dm_control), or earlier when the run diverges (non-finite state,
control or estimate, |x_i| > simulation.state_bound, a MuJoCo warning) or the plant
ends it (its termination(): a crash, status "crashed"), with discount 0.0. MID steps have
discount 1.0.

Action: a ``BoundedArray`` of shape (1,) named "u" with the actuator's
ctrlrange [N or N*m]; on a manipulator (plant.kind = "manipulator", m joints)
shape (m,) named "tau", the joint torques [N*m, or N on a slide joint] in the
order of ``task.joint_shape``/the plant's joint_names, bounded per joint by
each motor's ctrlrange times its gear. Held over the control step (zero-order
hold at every RK4 stage). Finite actions outside the bounds are clipped to
them; a wrong shape or a non-finite value raises ValueError. With ``law=`` the
action is ignored (pass anything, e.g. zeros or None).

Observation (an OrderedDict of float64 arrays; J = () for 1-DOF plants, (m,) for arms):
    "state"      (n,)+J   [y, y', ...] as measured: the true state plus the
                          scenario's noise (one draw per physics step, from
                          noise.seed), exactly what the law sees in a run;
                          on an arm (2, m) = [q; q']
    "reference"  (n+1,)+J [y_d, y_d', ..., y_d^(n)] at time t
    "t"          ()       simulation time [s]
    "theta"      (n_theta,) true parameters, ordered as ``task.param_names``;
                          only with ``privileged=True``
n is the plant's order (2, or 3 with a thruster lag); y is in m (heave) or rad (arm).

Reward: -sum over the step's physics steps j of |y_d(t_j+1) - y(t_j+1)|^2 * dt,
the squared tracking error (summed over joints on an arm) of the true output
at the end of each physics step times the physics step: the integral of the
squared error over the control step by the right-endpoint rule [m^2*s or
rad^2*s]. So an episode's return is about -duration * (RMS tracking error)^2.
(It is non-finite if the state is; that step is LAST with discount 0.)

On an arm the scenario's law (Slotine-Li, computed torque or PD+gravity) is
rebuilt with every episode's plant, since it reads that plant's regressor;
``law=`` takes None or "scenario" there, and ``law_policy`` the scenario's law.

The law as the policy (``law="scenario"`` or a law object): the law runs
inside MuJoCo's control callback at every evaluation of the dynamics, with the
estimates staged through the integrator's stages and advanced once per
physics step by ``loop.Controller`` itself (loop.run's Python path, driven by ``sim.driver``; its
native numba path computes the same numbers), so an episode is step for step
the computation ``adaptive-mj run`` does: the tests find bit-identical rows.
``law_policy(env)`` (a ``LawPolicy``) is the other design: the law as an
ordinary agent that sees only observations, holds u over the control step
and advances its estimates by explicit Euler once per agent step.

Logging: with ``log=DIR`` every episode writes DIR/<scenario>-<UTC>-seed<N>.mcap
through ``record.Recorder`` with the header ``adaptive-mj run`` writes
(``runner.log_header``), rows per physics step at the scenario's log rate, and
a /summary that also says which "policy" drove it ("agent" or "law") and the
control_timestep [s]. Agent episodes log the estimates and V as NaN (an
agent has none) and s as the scenario law's sliding variable of the measured
state. A log closes with status "ok" or "diverged" at the episode's end, and
"interrupted" when the episode is cut short by reset() or env.close().
"""
from __future__ import annotations

import collections
import dataclasses
import math
import os
from pathlib import Path
import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")  # dm_control probes a GL backend on import
import dm_env  # noqa: E402 (imported after MUJOCO_GL is set above)
from dm_control import mujoco as dm_mujoco  # noqa: E402 (imported after MUJOCO_GL is set above)
from dm_control.mujoco import wrapper  # noqa: E402 (imported after MUJOCO_GL is set above)
from dm_control.rl import control  # noqa: E402 (imported after MUJOCO_GL is set above)
from dm_env import specs  # noqa: E402 (imported after MUJOCO_GL is set above)

from adaptive_mj.setup import scenario as scenario_io  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.setup.build import Setup, build  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.errors import ScenarioError  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.sim.driver import AgentSteps, Drive, PythonSteps  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.sim.loop import Controller, EventQueue, Rows, _NoiseSource, plant_order  # noqa: E402 (after MUJOCO_GL)
from adaptive_mj.report.metrics import clean_json, summary as make_summary  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.plants.manipulator import ManipulatorPlant  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.plants.mujoco_plant import MujocoPlant  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.laws.protocol import Law  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.plants.protocol import Plant, Policy, has_joints  # noqa: E402 (imported after MUJOCO_GL is set above)
from adaptive_mj.trajectory import Status, Trajectory

#: ``law=`` value that runs the scenario's own law (the one ``adaptive-mj run`` runs).
SCENARIO_LAW = "scenario"

#: Final discount of an episode that reached its time limit / that diverged.
DISCOUNT_TIME_LIMIT = 1.0
DISCOUNT_DIVERGED = 0.0


def load(scenario, *, law: Law | str | None = None, log: str | os.PathLike | None = None, seed: int | None = None,
         overrides=(), privileged: bool = False, n_sub_steps: int | None = None,
         control_timestep: float | None = None) -> TrackingEnvironment:
    """A dm_env.Environment running `scenario` (see the module docstring).

    scenario: a Scenario, a scenario file, or the name of a bundled one ("heave_tracking").
    law: None (the agent's action is the control), "scenario" (the scenario's
      law), or a law object for the scenario's plant (same parameter names as
      the scenario's law, whose initial estimates it starts from).
    log: a directory; every episode writes an MCAP log there.
    seed: noise seed (replaces noise.seed); overrides: "key=value" scenario overrides.
    privileged: also observe the true parameters ("theta").
    n_sub_steps / control_timestep [s]: physics steps per agent step (default 1, or the
      scenario's control period under control.mode = "sampled"), or the agent's step, a whole
      multiple of the physics step; not both.

    Raises ScenarioError for a scenario without a MuJoCo plant (first_order, twin backend).
    """
    scn = _scenario(scenario, overrides=tuple(overrides), seed=seed)
    setup = build(scn)
    if getattr(setup.plant, "state_names", ()):  # a quadrotor: its 4 rotors on 3 axes, x (4, 3): not yet an env
        raise ScenarioError(f"{scn.source}: adaptive_mj.env does not drive plant.kind = {scn.plant.kind!r} yet (its "
                            "controls are not one per joint); run it with adaptive-mj run or adaptive_mj.run_scenario")
    if not isinstance(setup.plant, (MujocoPlant, ManipulatorPlant)):
        raise ScenarioError(f"{scn.source}: adaptive_mj.env needs a MuJoCo plant, got plant.kind = "
                            f"{scn.plant.kind!r} with plant.backend = {scn.plant.backend!r}")
    physics = PlantPhysics.of(setup.plant)
    if n_sub_steps is not None and control_timestep is not None:
        raise ValueError("pass n_sub_steps or control_timestep, not both")
    if control_timestep is not None:
        n_sub_steps = control.compute_n_steps(control_timestep, physics.timestep())
    if n_sub_steps is None and scn.control.mode == "sampled":  # the agent acts once per control period
        from adaptive_mj.runs.runner import control_timing

        n_sub_steps = control_timing(scn, setup).steps
    n_sub_steps = 1 if n_sub_steps is None else int(n_sub_steps)
    if n_sub_steps < 1:
        raise ValueError(f"n_sub_steps must be >= 1, got {n_sub_steps}")
    if scn.simulation.control_delay and law is None:
        raise ScenarioError(f"{scn.source}: simulation.control_delay delays the scenario's law; with an agent as "
                            "the policy, delay its actions yourself (or load with law='scenario')")
    if setup.sensors is not None and law is None:
        raise ScenarioError(f"{scn.source}: [sensors] (encoders, a differentiated velocity) shape what the "
                            "scenario's law measures; an agent's observation is the state + noise.std only: remove "
                            "[sensors], or load with law='scenario'")
    task = TrackingTask(scn, setup, law=law, privileged=privileged, n_sub_steps=n_sub_steps,
                        log_dir=None if log is None else Path(log))
    # The task ends episodes itself (an exact step count; dm_control's time_limit
    # divides floats and can add a step), so the Environment has no time limit.
    return TrackingEnvironment(physics, task, n_sub_steps=n_sub_steps, legacy_step=False)


def _scenario(scenario, *, overrides: tuple[str, ...], seed: int | None) -> scenario_io.Scenario:
    if isinstance(scenario, scenario_io.Scenario):
        if not overrides and seed is None:
            return scenario
        source = Path(scenario.source)
        return scenario_io.loads(scenario.text, where=scenario.source,
                                 base_dir=source.parent if source.is_file() else None,
                                 default_name=scenario.name, overrides=(*scenario.overrides, *overrides),
                                 seed=seed)
    path = Path(scenario)
    if not path.exists() and "/" not in str(scenario):
        bundled = scenario_io.SCENARIOS_DIR / path.with_suffix(".toml").name
        if bundled.exists():
            path = bundled
    return scenario_io.load(path, overrides=overrides, seed=seed)


class TrackingEnvironment(control.Environment):
    """dm_control's Environment; close() also closes an episode log left open."""

    def close(self) -> None:
        self.task.close()


class PlantPhysics(dm_mujoco.Physics):
    """dm_control's Physics over a plant's own MjModel and MjData (shared, not copied).

    step(n) advances the current episode by n physics steps through the
    episode (events, noise, the policy in MuJoCo's control callback, logging)
    rather than calling mj_step directly, so stepping is the same as
    ``adaptive-mj run``'s.
    """

    episode: "_Episode | None" = None

    @classmethod
    def of(cls, plant: MujocoPlant | ManipulatorPlant) -> PlantPhysics:
        return cls(wrapper.MjData(plant.data))

    def use(self, plant: MujocoPlant | ManipulatorPlant) -> None:
        """Wrap another plant's model and data (a new episode's)."""
        self._reload_from_data(wrapper.MjData(plant.data))

    def step(self, nstep: int = 1) -> None:
        if self.episode is None:
            raise RuntimeError("PlantPhysics.step before an episode began (call env.reset())")
        self.episode.advance(nstep)


class TrackingTask(control.Task):
    """Track the scenario's reference; see the module docstring for specs and reward.

    law: the law (the scenario's unless one was passed; with an agent it
      only gives the logged s); drives_law: whether it supplies the control.
    param_names: names of theta (the "theta" observation, the logged estimates);
    theta_hat0: (n_theta,) the scenario's initial estimates.
    log_paths: the MCAP logs written so far, one per episode.
    """

    def __init__(self, scn: scenario_io.Scenario, setup: Setup, *, law: Law | str | None = None,
                 privileged: bool = False, n_sub_steps: int = 1, log_dir: Path | None = None):
        plant = setup.plant
        self.scenario = scn
        self.privileged = bool(privileged)
        self.n_sub_steps = int(n_sub_steps)
        self.log_dir = log_dir
        self.log_paths: list[Path] = []
        self.order = plant_order(plant)
        self.joint_shape = plant.joint_shape  # () for 1-DOF plants, (m,) for arms
        self.param_names = tuple(setup.law.names)
        self.theta_hat0 = np.array(setup.theta_hat0, dtype=float)  # (n_theta,) the law's start
        self.drives_law = law is not None  # the law, not the agent, supplies the control
        # The scenario's law is rebuilt with each episode's plant (an arm's law reads that plant's
        # regressor); a law object passed in serves every episode (1-DOF laws are pure).
        self._own_law = law is None or (isinstance(law, str) and law == SCENARIO_LAW)
        if law is None or isinstance(law, str):
            if not self._own_law:
                raise ValueError(f"law must be None, {SCENARIO_LAW!r} or a law object, got {law!r}")
            law = setup.law
        elif self.joint_shape:
            raise ValueError(f"on a manipulator, law must be None or {SCENARIO_LAW!r} (the Slotine-Li law is "
                             "built with each episode's plant, whose regressor it reads); set its gains in the "
                             "scenario's [law] table")
        elif law.order != self.order:
            raise ValueError(f"law of order {law.order} on a plant of order {self.order}")
        elif tuple(law.names) != self.param_names:
            raise ValueError(f"law parameters {tuple(law.names)} differ from the scenario's "
                             f"{self.param_names}")
        self.law = law
        lo, hi = plant.ctrl_range if plant.ctrl_range is not None else (-math.inf, math.inf)
        shape = self.joint_shape or (1,)
        self._action_spec = specs.BoundedArray(shape, np.float64, np.broadcast_to(lo, shape).astype(float),
                                               np.broadcast_to(hi, shape).astype(float),
                                               name="tau" if self.joint_shape else "u")
        fields = [("state", (self.order,) + self.joint_shape), ("reference", (self.order + 1,) + self.joint_shape),
                  ("t", ())]
        if self.privileged:
            fields.append(("theta", (len(self.param_names),)))
        self._observation_spec = collections.OrderedDict(
            (name, specs.Array(shape, np.float64, name=name)) for name, shape in fields)
        self.n_physics_steps = int(round(scn.simulation.duration / plant.dt))
        self.n_agent_steps = -(-self.n_physics_steps // self.n_sub_steps)  # per episode
        self._episode: _Episode | None = None

    # -- control.Task ---------------------------------------------------------

    def initialize_episode(self, physics: PlantPhysics) -> None:
        self.close()
        setup = build(self.scenario)
        if self._own_law:
            self.law = setup.law
        # the scenario's plant, of the kind load() accepted (a new build of the same scenario)
        assert isinstance(setup.plant, (MujocoPlant, ManipulatorPlant))
        physics.use(setup.plant)
        recorder = None
        if self.log_dir is not None:
            from adaptive_mj.log.record import Recorder
            from adaptive_mj.runs.runner import log_header, reserve_log_path

            path = reserve_log_path(self.scenario, directory=self.log_dir)
            recorder = Recorder(path, log_header(self.scenario, setup))
            self.log_paths.append(path)
        self._episode = _Episode(self.scenario, setup, law=self.law, drive=self.drives_law,
                                 n_steps=self.n_physics_steps,
                                 control_dt=self.n_sub_steps * setup.plant.dt, recorder=recorder)
        physics.episode = self._episode

    def before_step(self, action, physics) -> None:
        if self.drives_law:
            return
        spec = self._action_spec
        assert self._episode is not None  # set by initialize_episode, which dm_control's reset calls first
        u = np.asarray(action, dtype=np.float64)
        if u.shape != spec.shape:
            what = f"the joint torques tau of {', '.join(self._episode.joint_names)}" if self.joint_shape \
                else "the control u"
            raise ValueError(f"action must have shape {spec.shape} ({what}), got shape {u.shape}")
        if not np.all(np.isfinite(u)):
            raise ValueError(f"action {spec.name} must be finite, got {u.tolist()}")
        u = np.clip(u, spec.minimum, spec.maximum)
        self._episode.hold(u if self.joint_shape else float(u[0]))

    def get_observation(self, physics) -> collections.OrderedDict:
        ep = self._episode
        assert ep is not None  # set by initialize_episode, which dm_control's reset calls first
        t = ep.plant.time
        obs = collections.OrderedDict()
        obs["state"] = ep.measured_state()
        obs["reference"] = np.asarray(ep.reference(t, self.order), dtype=np.float64)
        obs["t"] = np.array(t, dtype=np.float64)
        if self.privileged:
            obs["theta"] = np.array(ep.plant.true_theta(), dtype=np.float64)
        return obs

    def get_reward(self, physics) -> float:
        assert self._episode is not None  # set by initialize_episode, which dm_control's reset calls first
        return self._episode.last_reward

    def get_termination(self, physics) -> float | None:
        ep = self._episode
        assert ep is not None  # set by initialize_episode, which dm_control's reset calls first
        if ep.status in (Status.DIVERGED, Status.CRASHED):
            return DISCOUNT_DIVERGED
        if ep.k >= ep.n_steps:
            return DISCOUNT_TIME_LIMIT
        return None

    def action_spec(self, physics) -> specs.BoundedArray:
        return self._action_spec

    def observation_spec(self, physics) -> collections.OrderedDict:
        return self._observation_spec

    # -- beyond control.Task ----------------------------------------------------

    @property
    def theta_hat(self) -> np.ndarray | None:
        """(n_theta,) the law's current estimates, or None when the agent drives."""
        ep = self._episode
        return None if ep is None or ep.controller is None else ep.controller.theta_hat.copy()

    def trajectory(self) -> Trajectory:
        """The current (or last) episode so far, one row per physics step, as ``loop.run`` returns it."""
        if self._episode is None:
            raise RuntimeError("no episode yet (call env.reset())")
        return self._episode.trajectory()

    def close(self) -> None:
        """Close the current episode's log if it is still open (status "interrupted")."""
        if self._episode is not None:
            self._episode.close_log(Status.INTERRUPTED, "the episode was cut short (reset or close)")


class _Episode:
    """One episode of a scenario: ``loop.run``'s step body, driven one agent step at a time.

    Rows are kept per physics step k: t (N,) [s], x (N, n)+J true state, u (N,)+J
    applied control, s (N,)+J, ref (N, n+1)+J, theta_hat and theta (N, n_theta),
    where J is the plant's joint shape: () for 1-DOF plants, (m,) for an arm.
    """

    def __init__(self, scn: scenario_io.Scenario, setup: Setup, *, law: Law, drive: bool, n_steps: int,
                 control_dt: float, recorder=None):
        plant: Plant = setup.plant
        self.name = scn.name
        self.scn = scn
        self.plant = plant
        self.law = law
        self.reference = setup.reference
        self.order = plant_order(plant)
        self.joint_shape = js = plant.joint_shape
        self.joint_names = plant.joint_names
        self.dt = plant.dt
        self.control_dt = control_dt
        self.n_steps = n_steps
        self.state_bound = scn.simulation.state_bound
        self.theta_hat0 = np.asarray(setup.theta_hat0, dtype=float)
        self.events = EventQueue(setup.events, plant.dt)
        self._noise = _NoiseSource(setup.noise_std, setup.rng, (self.order,) + js)
        self.controller: Controller | None = None
        self.steps: PythonSteps | AgentSteps
        if drive:  # the law: the step adaptive-mj run takes on its Python path
            from adaptive_mj.runs.runner import control_timing

            self.controller = Controller(law, setup.reference, self.theta_hat0, plant.ctrl_range, self.order,
                                         plant.stages, plant.dt, js, control_timing(scn, setup), setup.sensors)
            self.steps = PythonSteps(plant, self.controller)
            self._policy: Policy = self.controller
        else:  # the agent: its held action over the step
            self.steps = agent = AgentSteps(plant, law, setup.reference, self.theta_hat0, self.order)
            self._policy = agent.policy
        self.recorder = recorder
        self.sink_every = max(1, round(1.0 / self.dt))  # flush about once per simulated second
        # the rows, their V and the Trajectory: the loop's own (sim.loop.Rows), as adaptive-mj run keeps them; an
        # agent's episode has no law estimate (θ̂ NaN) and no V
        self.rows = Rows(plant, law, n_steps, self, self.sink_every, lyapunov=drive)
        self.status, self.reason = Status.OK, ""
        self._criteria, self._preflight, self._verdict = self._verdict_terms(scn, setup, law, drive)
        self.last_reward = 0.0
        self._ended = False
        # the run between its steps (adaptive_mj.sim.driver, as adaptive-mj run drives it), one physics step a chunk:
        # made, it has applied the events due at t = 0 and drawn the first step's noise
        self.run = Drive(plant, self.steps, self.rows, self.events, self._noise, self.state_bound)

    @property
    def k(self) -> int:
        """Physics steps taken (rows kept)."""
        return self.rows.k

    def write_rows(self, *rows) -> None:
        """The rows' sink (Rows flushes here): the episode's log while it is open."""
        if self.recorder is not None and not self.recorder.closed:
            self.recorder.write_rows(*rows)

    def write_event(self, t: float, label: str) -> None:
        """The events' sink (applied at the first step with t_k >= t_event - dt/2, before the observation at t_k,
        as loop.run applies them): the episode's log while it is open."""
        if self.recorder is not None and not self.recorder.closed:
            self.recorder.write_event(t, label)

    def hold(self, u) -> None:
        """The agent's control for the coming agent step (already clipped): a float [N or N*m],
        or (m,) joint torques [N*m or N] for an arm."""
        assert isinstance(self.steps, AgentSteps)  # the task holds an action only when the agent drives
        self.steps.u = u

    def measured_state(self) -> np.ndarray:
        """(n,)+J the state the law sees at the coming step: true state + that step's noise."""
        x = self.plant.observe()
        if self.joint_shape:  # a law called outside the callback (law_policy) reads Y at this state
            assert has_joints(self.plant)  # joint_shape (m,): a plant of joints
            self.plant.update_kinematics()
        noise = self.steps.noise
        return x + noise if noise is not None else x

    def advance(self, n_sub: int) -> None:
        """Run up to n_sub physics steps (adaptive_mj.sim.driver.Drive, one a chunk), each rewarded with
        -|y_d - y|^2 * dt at its end; stop early at the episode's end, a divergence or the plant's termination."""
        reward = 0.0
        plant = self.plant
        try:
            with plant.controlled_by(self._policy):
                for _ in range(n_sub):
                    if self.run.done:
                        break
                    self.run.advance()
                    y_tilde = np.asarray(self.reference(plant.time, 0)[0]) - plant.observe()[0]
                    reward -= float(np.sum(y_tilde * y_tilde)) * self.dt
        except BaseException as exc:
            status = Status.INTERRUPTED if isinstance(exc, KeyboardInterrupt) else Status.FAILED
            self.close_log(status, f"{type(exc).__name__}: {exc}")
            raise
        self.last_reward = reward
        if self.run.done and not self._ended:
            self._ended = True
            self.status, self.reason = self.run.status, self.run.reason
            self.steps.noise = self._noise.draw()  # what an observation after the last step sees, as after any step
            if self.status == Status.OK:  # the episode ran to its end: its verdict
                from adaptive_mj.runs.runner import verdict

                traj, self._verdict = verdict(self.scn, self.trajectory(), self._criteria, self._preflight)
                self.status, self.reason = traj.status, traj.reason
            self.close_log(self.status, self.reason)

    def _verdict_terms(self, scn: scenario_io.Scenario, setup: Setup, law: Law, drive: bool):
        """(criteria, pre-flight, None): what the episode's verdict needs, as adaptive-mj run has them
        (the pre-flight of the law that drives the plant; none for an agent's policy)."""
        from adaptive_mj.setup.success import criteria
        from adaptive_mj.sim import preflight
        from adaptive_mj.runs.runner import control_timing

        crit = criteria(scn, setup.reference, self.order, tuple(setup.law.names))
        if drive:
            pre = preflight.check(self.plant, law, setup.reference, duration=scn.simulation.duration,
                                  timing=control_timing(scn, setup))
        else:
            pre = preflight.Preflight(checked=False, note="not checked: an agent's policy drives the plant")
        return crit, pre, None

    def trajectory(self) -> Trajectory:
        """The episode so far (the rows written to the log on the way, as loop.run writes them)."""
        return self.rows.result(self.k, self.status, self.reason, {"events": list(self.events.applied)})

    def close_log(self, status: Status, reason: str) -> None:
        """Write the remaining rows and the summary, and finish the log (no-op without an open log)."""
        if self.recorder is None or self.recorder.closed:
            return
        traj = dataclasses.replace(self.trajectory(), status=status, reason=reason)  # flushes the rows
        recorder, self.recorder = self.recorder, None
        summary = clean_json(make_summary(self.name, traj))
        if self._verdict is not None:  # the same success and preflight records as adaptive-mj run
            summary.update(success=self._verdict["success"], preflight=self._verdict["preflight"])
        summary.update(policy="law" if self.controller is not None else "agent",
                       control_timestep=self.control_dt)
        recorder.close(status, reason, summary)


def law_policy(env: control.Environment, law: Law | str = SCENARIO_LAW) -> LawPolicy:
    """The scenario's law (or `law`) as an ordinary agent: policy(timestep) -> action (1,) or (m,)."""
    return LawPolicy(env, law)


class LawPolicy:
    """A law driving an environment from its observations only, like any agent.

    u = law(t, state, reference, θ̂) clipped to the action spec and held over
    the control step; θ̂ (``theta_hat``, (n_theta,)) starts at the scenario's
    initial estimates on every FIRST step and then advances by explicit Euler,
    θ̂ += control_timestep * θ̂', once per agent step. So it differs from
    ``load(..., law="scenario")`` (and ``adaptive-mj run``) only in that u is
    held over the RK4 stages and θ̂ is staged by Euler at the agent's rate.
    """

    def __init__(self, env: control.Environment, law: Law | str = SCENARIO_LAW):
        task = env.task
        if task.drives_law:
            raise ValueError("law_policy needs an environment the agent drives (load without law=)")
        self._task = task
        own: Law | None = None  # None: the task's current law, read at each call (an arm's is rebuilt per episode)
        if isinstance(law, str):
            if law != SCENARIO_LAW:
                raise ValueError(f"law must be {SCENARIO_LAW!r} or a law object, got {law!r}")
        elif task.joint_shape:
            raise ValueError(f"on a manipulator, law_policy takes {SCENARIO_LAW!r} only (the Slotine-Li law "
                             "reads the episode plant's regressor)")
        elif law.order != task.order or tuple(law.names) != task.param_names:
            raise ValueError(f"law of order {law.order} with parameters {tuple(law.names)} does not fit "
                             f"the plant (order {task.order}, parameters {task.param_names})")
        else:
            own = law
        self.law = own
        self.theta_hat0 = task.theta_hat0.copy()
        self.theta_hat = self.theta_hat0.copy()
        self._h = env.control_timestep()
        spec = env.action_spec()
        self._lo, self._hi = spec.minimum, spec.maximum

    def __call__(self, timestep: dm_env.TimeStep) -> np.ndarray:
        if timestep.first():
            self.theta_hat = self.theta_hat0.copy()
        obs = timestep.observation
        law = self.law if self.law is not None else self._task.law
        out = law(float(obs["t"]), obs["state"], obs["reference"], self.theta_hat)
        self.theta_hat = self.theta_hat + self._h * np.asarray(out.theta_hat_dot, dtype=float)
        u = np.array(out.u, dtype=np.float64).reshape(self._lo.shape)
        return np.clip(u, self._lo, self._hi)

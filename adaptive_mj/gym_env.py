"""Gymnasium environments over the benchmark's scenarios, beside the dm_env ones (adaptive_mj.env).

    from adaptive_mj import gym_env

    env = gym_env.make("heave_tracking")                   # an agent supplies u
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    env = gym_env.make("heave_tracking", law="scenario")   # the scenario's adaptive law drives

Needs the optional extra `gym` (pip install 'adaptive-mj[gym]'). A TrackingEnv wraps
adaptive_mj.env.load's dm_env environment, so the physics, the observations, the reward, the
episode's end and `law="scenario"` are the same (see that module's docstring):

- observation_space: a Dict of float64 Boxes, "state" (n,)+J, "reference" (n+1,)+J, "t" () [s], and
  "theta" (n_theta,) with privileged=True; J = () for a 1-DOF plant, (m,) for an arm.
- action_space: a Box of the actuators' ranges, (1,) u [N or N m] or (m,) joint torques tau [N m];
  ignored with law="scenario".
- reward: −∫ |y_d − y|² dt over the step [m² s or rad² s].
- terminated: the run diverged (dm_env's discount 0); truncated: it reached the scenario's duration
  (a time limit, discount 1).
- reset(seed=s): the scenario's noise seed becomes s (noise.seed), so equal seeds give equal episodes;
  without a seed, the seed of the previous reset (or of make) is kept and the episode repeats.
- info: "t" [s], "status" (ok, diverged, failed at the end of a run that missed its success criteria),
  "theta_hat" (the law's estimates with law="scenario", else absent).
"""
from __future__ import annotations

import os
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from adaptive_mj import env as dm_env_module
from adaptive_mj.errors import AdaptiveMJError

if TYPE_CHECKING:
    from adaptive_mj.laws.protocol import Law

gymnasium: ModuleType | None  # None without the optional extra
try:
    import gymnasium
    from gymnasium import spaces
except ImportError:  # the optional extra is not installed: make() says how to get it
    gymnasium = None

INSTALL = "adaptive_mj.gym_env needs gymnasium, an optional extra: pip install 'adaptive-mj[gym]'"


def make(scenario, *, law: Law | str | None = None, seed: int | None = None, overrides=(),
         privileged: bool = False, n_sub_steps: int | None = None, control_timestep: float | None = None,
         log: str | os.PathLike | None = None) -> "TrackingEnv":
    """A gymnasium.Env running `scenario`; the arguments are adaptive_mj.env.load's."""
    if gymnasium is None:
        raise AdaptiveMJError(INSTALL)
    return TrackingEnv(scenario, law=law, seed=seed, overrides=tuple(overrides), privileged=privileged,
                       n_sub_steps=n_sub_steps, control_timestep=control_timestep, log=log)


def _box(spec, *, bounded: bool) -> Any:
    if bounded:
        return spaces.Box(low=np.asarray(spec.minimum, dtype=np.float64), high=np.asarray(spec.maximum, np.float64),
                          shape=spec.shape, dtype=np.float64)
    return spaces.Box(low=-np.inf, high=np.inf, shape=spec.shape, dtype=np.float64)


class TrackingEnv(gymnasium.Env if gymnasium is not None else object):  # type: ignore[misc]  # base set at import
    """See the module docstring. `dm_env` is the wrapped adaptive_mj.env environment (its task has
    the trajectory, the estimates and the logs)."""

    metadata: dict[str, Any] = {"render_modes": []}
    render_mode = None

    def __init__(self, scenario, *, law: Law | str | None = None, seed: int | None = None,
                 overrides: tuple[str, ...] = (), privileged: bool = False, n_sub_steps: int | None = None,
                 control_timestep: float | None = None, log=None):
        self._load = dict(law=law, overrides=overrides, privileged=privileged, n_sub_steps=n_sub_steps,
                          control_timestep=control_timestep, log=log)
        self._scenario = scenario
        self._seed = seed
        self.dm_env = dm_env_module.load(scenario, seed=seed, **self._load)
        obs_spec = self.dm_env.observation_spec()
        self.observation_space = spaces.Dict({name: _box(spec, bounded=False) for name, spec in obs_spec.items()})
        self.action_space = _box(self.dm_env.action_spec(), bounded=True)

    @staticmethod
    def _obs(observation) -> dict[str, np.ndarray]:
        return {name: np.asarray(value, dtype=np.float64) for name, value in observation.items()}

    def _info(self) -> dict[str, Any]:
        task = self.dm_env.task
        episode = task._episode
        info: dict[str, Any] = {"t": float(episode.plant.time), "status": episode.status}
        if task.theta_hat is not None:
            info["theta_hat"] = task.theta_hat
        return info

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None and seed != self._seed:  # the scenario's noise seed: a new environment of it
            self.dm_env.close()
            self._seed = int(seed)
            self.dm_env = dm_env_module.load(self._scenario, seed=self._seed, **self._load)
        timestep = self.dm_env.reset()
        return self._obs(timestep.observation), self._info()

    def step(self, action):
        timestep = self.dm_env.step(action)
        last = timestep.last()
        terminated = bool(last and timestep.discount == dm_env_module.DISCOUNT_DIVERGED)
        truncated = bool(last and not terminated)
        return self._obs(timestep.observation), float(timestep.reward), terminated, truncated, self._info()

    def close(self) -> None:
        self.dm_env.close()

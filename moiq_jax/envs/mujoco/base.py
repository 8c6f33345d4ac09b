"""Gymnasium v5's MuJoCo locomotion tasks, written once for two physics backends.

A ``Task`` holds one task's constants (MJCF file, frame skip, reset noise, sizes) and its rules
(observation, vector reward, termination) as functions of a ``Physics`` view: ``qpos``, ``qvel``, the
main body's ``xpos`` and ``cfrc_ext``. The rules take the array namespace ``xp`` and index with
``[..., i]``, so the same code runs on one MJX state in ``jax.numpy`` (float32) and on a batch of
MuJoCo states in ``numpy`` (float64, as Gymnasium computes them). The backends are ``mjx_env.MjxEnv``
(pure JAX) and ``native.NativeEnv`` (MuJoCo's C engine behind a host callback); ``MujocoEnv``
is what they share: the model, ``dt``, the reset noise and the env protocol's sizes.

Gymnasium's step is ``mj_step`` ``frame_skip`` times, then ``mj_rnePostConstraint`` where the task
reads contact forces (Ant); its reset is ``mj_resetData`` then ``set_state(qpos, qvel)``
(``mj_forward``). Quantities derived from positions after a step (``xpos``, ``cfrc_ext``) are
MuJoCo's at the start of the last substep, as in Gymnasium.
"""

from __future__ import annotations

import abc
import functools
import os
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from moiq_jax.envs.base import Env, State

ASSETS = os.path.join(os.path.dirname(__file__), "assets")
BACKENDS = ("mujoco", "mjx")


class Physics(NamedTuple):
    """What the task rules read from a MuJoCo state (arrays of numpy or jax.numpy; leading batch axes
    allowed). ``xpos``: the main body's position (None when the task has none); ``cfrc_ext``: all
    bodies' external contact forces, ``[..., nbody, 6]`` (None unless the task reads them)."""

    qpos: Any
    qvel: Any
    xpos: Any = None
    cfrc_ext: Any = None


class Task(abc.ABC):
    """One task's constants and rules; subclasses set the class constants and the two rules."""

    xml_file: str
    frame_skip: int
    reset_noise_scale: float
    qvel_noise_normal: bool = False  # Gaussian qvel reset noise (HalfCheetah, Ant) instead of uniform
    main_body: str | None = None  # the body whose xpos the rules read (Ant's torso)
    contact_forces: bool = False  # the rules read cfrc_ext (after mj_rnePostConstraint, as Gymnasium)
    reward_dim: int
    observation_size: int
    action_size: int

    def load_model(self) -> mujoco.MjModel:
        """A fresh copy of the task's model (MuJoCo's solver settings)."""
        model = mujoco.MjModel.from_xml_path(os.path.join(ASSETS, self.xml_file))
        if model.nu != self.action_size:
            raise ValueError(f"{self.xml_file} has {model.nu} actuators, expected {self.action_size}")
        return model

    @functools.cached_property
    def mj_model(self) -> mujoco.MjModel:
        """The task's model, loaded once (read it, do not change it)."""
        return self.load_model()

    @property
    def dt(self) -> float:
        """Seconds per env step: the physics timestep times ``frame_skip``, as Gymnasium's ``dt``."""
        return float(self.mj_model.opt.timestep) * self.frame_skip

    @property
    def init_qpos(self) -> np.ndarray:
        """Gymnasium's ``init_qpos``: the model's ``qpos0``, float64."""
        return self.mj_model.qpos0.copy()

    @property
    def main_body_id(self) -> int | None:
        if self.main_body is None:
            return None
        return mujoco.mj_name2id(self.mj_model, mujoco.mjtObj.mjOBJ_BODY, self.main_body)

    @abc.abstractmethod
    def observe(self, p: Physics, xp) -> Any:
        """Gymnasium's ``_get_obs``."""

    @abc.abstractmethod
    def reward_and_done(self, before: Physics, after: Physics, action, xp) -> tuple[Any, Any]:
        """The vector reward of the step from ``before`` to ``after`` under ``action`` (``[..., reward_dim]``)
        and whether ``after`` is terminal (Gymnasium's ``terminated``)."""

    def x_velocity(self, before: Physics, after: Physics) -> Any:
        """Gymnasium's ``x_velocity``: the root's x displacement over the step divided by ``dt``."""
        return (after.qpos[..., 0] - before.qpos[..., 0]) / self.dt


def neg_squared_action(action, xp) -> Any:
    """The control cost divided by its weight, negated: ``-sum(action ** 2)`` (MO-Gymnasium's cost objective)."""
    return -xp.sum(xp.square(action), axis=-1)


class PlanarTask(Task):
    """A planar task whose root is a slider in x: observes ``qpos[1:]`` and ``qvel`` (clipped to
    ``+-clip_qvel`` unless None), as Gymnasium's Hopper, Walker2d and HalfCheetah do."""

    clip_qvel: float | None = None

    def observe(self, p, xp):
        qvel = p.qvel if self.clip_qvel is None else xp.clip(p.qvel, -self.clip_qvel, self.clip_qvel)
        return xp.concatenate([p.qpos[..., 1:], qvel], axis=-1)


class MujocoEnv(Env):
    """A task on one backend; ``backend`` names it. Subclasses implement ``state_at``, ``reset_to``
    (``state_at`` for a batch-free traced start) and ``step``."""

    backend: str

    def __init__(self, task: Task):
        self.task = task
        self.reward_dim = task.reward_dim
        self.observation_size = task.observation_size
        self.action_size = task.action_size

    @property
    def mj_model(self) -> mujoco.MjModel:
        return self.task.mj_model

    @property
    def dt(self) -> float:
        return self.task.dt

    def reset_noise(self, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        """Gymnasium's ``reset_model`` noise: uniform on ``qpos`` and uniform or Gaussian on ``qvel``, of
        scale ``reset_noise_scale``, drawn with ``jax.random`` (float32)."""
        model, task = self.mj_model, self.task
        key_pos, key_vel = jax.random.split(key)
        scale = task.reset_noise_scale
        dq = jax.random.uniform(key_pos, (model.nq,), minval=-scale, maxval=scale)
        if task.qvel_noise_normal:
            dv = scale * jax.random.normal(key_vel, (model.nv,))
        else:
            dv = jax.random.uniform(key_vel, (model.nv,), minval=-scale, maxval=scale)
        return dq, dv

    def reset(self, key):
        """Gymnasium's reset: ``qpos0`` plus noise, zero velocity plus noise, then ``set_state``."""
        dq, dv = self.reset_noise(key)
        return self._start(dq, dv, offset=True)

    def state_at(self, qpos, qvel) -> State:
        """The state Gymnasium's ``set_state(qpos, qvel)`` gives after a reset (time and warm start zero),
        with its observation. Concrete float64 numpy arrays are used exactly by the native backend."""
        model = self.mj_model
        for name, x, n in (("qpos", qpos, model.nq), ("qvel", qvel, model.nv)):
            if np.shape(x) != (n,):
                raise ValueError(f"{type(self.task).__name__}: {name} must have shape ({n},), got {np.shape(x)}")
        return self._start(qpos, qvel, offset=False)

    @abc.abstractmethod
    def _start(self, qpos, qvel, offset: bool) -> State:
        """The state after ``set_state`` at ``qpos``, ``qvel`` (added to ``qpos0`` and zero if ``offset``)."""

    def initial_state(self, env_state, obs) -> State:
        return State(
            env_state=env_state,
            obs=jnp.asarray(obs, jnp.float32),
            reward=jnp.zeros((self.reward_dim,), jnp.float32),
            done=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
        )

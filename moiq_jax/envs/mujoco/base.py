"""The shared base of the MuJoCo envs: Gymnasium v5's locomotion tasks stepped with MJX.

The physics is ``mjx.step`` on a model made with ``mjx.put_model`` from Gymnasium's own MJCF file
(vendored in ``assets/``), run ``frame_skip`` times per env step, as Gymnasium's ``MujocoEnv`` does.
Brax's envs are not used: on CPU with these versions they are about 250x slower than calling MJX
directly (see DESIGN.md). A task subclass gives the file, the sizes, the reset noise, the observation
and the vector reward; everything else lives here.

Solver settings. The models keep MuJoCo's solver settings (Newton, at most 100 iterations and 50
line-search iterations, tolerance 1e-8). MJX's solver is warm-started from the previous step's
accelerations and stops at the tolerance, so it usually needs one to three iterations. Unbatched,
capping them saves little (about 10 % for the hopper), but under ``vmap`` every env waits for the
slowest, so caps matter for throughput (hopper, 64 envs: about 330 env-steps/s at MuJoCo's settings against about 1,500 at 1,024
envs with 2 and 4, on 2 loaded cores). Parity with MuJoCo needs MuJoCo's settings: at 1 iteration and
4 line-search iterations the hopper's observations drift 0.2 from MuJoCo's within 20 steps, at 2 and 4
some hopper episodes and the walker2d (0.4 apart) fail the parity tests. So the defaults are kept;
``solver_iterations`` and ``ls_iterations`` override them.
"""

from __future__ import annotations

import abc
import contextlib
import functools
import io
import os

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

with contextlib.redirect_stdout(io.StringIO()):  # MJX prints a notice when its optional warp backend is absent
    from mujoco import mjx

from moiq_jax.envs.base import Env, State

ASSETS = os.path.join(os.path.dirname(__file__), "assets")


class MujocoEnv(Env):
    """A Gymnasium v5 MuJoCo task on MJX; ``env_state`` is the ``mjx.Data`` after the step.

    Subclasses set ``xml_file``, ``frame_skip``, ``reset_noise_scale``, ``reward_dim``,
    ``observation_size``, ``action_size`` and implement ``observe`` and ``reward_and_done`` (``PlanarEnv`` gives the planar tasks' ``observe``).
    The sizes are class constants so that building an env loads nothing; the model is loaded and
    put on the device on first use. ``solver_iterations`` and ``ls_iterations`` (None: the model's)
    cap the constraint solver.
    """

    xml_file: str
    frame_skip: int
    reset_noise_scale: float
    qvel_noise_normal: bool = False  # Gaussian qvel reset noise (HalfCheetah, Ant) instead of uniform
    deterministic_reset = False

    def __init__(self, solver_iterations: int | None = None, ls_iterations: int | None = None):
        self.solver_iterations = solver_iterations
        self.ls_iterations = ls_iterations

    @functools.cached_property
    def mj_model(self) -> mujoco.MjModel:
        """The native model, with this env's solver settings."""
        model = mujoco.MjModel.from_xml_path(os.path.join(ASSETS, self.xml_file))
        if self.solver_iterations is not None:
            model.opt.iterations = self.solver_iterations
        if self.ls_iterations is not None:
            model.opt.ls_iterations = self.ls_iterations
        if model.nu != self.action_size:
            raise ValueError(f"{self.xml_file} has {model.nu} actuators, expected {self.action_size}")
        return model

    @functools.cached_property
    def mjx_model(self) -> mjx.Model:
        """The device model; built eagerly even when first used inside a trace, so no tracer is cached."""
        with jax.ensure_compile_time_eval():
            return mjx.put_model(self.mj_model)

    @property
    def dt(self) -> float:
        """Seconds per env step: the physics timestep times ``frame_skip``, as Gymnasium's ``dt``."""
        return float(self.mj_model.opt.timestep) * self.frame_skip

    @property
    def init_qpos(self) -> np.ndarray:
        return self.mj_model.qpos0.astype(np.float32)

    # --- what a task defines -------------------------------------------------------------------

    @abc.abstractmethod
    def observe(self, data: mjx.Data) -> jax.Array:
        """Gymnasium's ``_get_obs`` for the state in ``data``."""

    @abc.abstractmethod
    def reward_and_done(self, before: mjx.Data, after: mjx.Data, action: jax.Array) -> tuple[jax.Array, jax.Array]:
        """The vector reward of the step from ``before`` to ``after`` under ``action``, and whether
        ``after`` is terminal (Gymnasium's ``terminated``)."""

    def postprocess(self, data: mjx.Data) -> mjx.Data:
        """Quantities Gymnasium computes after ``mj_step`` (the Ant's contact forces); none by default."""
        return data

    # --- the protocol --------------------------------------------------------------------------

    def data_from_state(self, qpos, qvel) -> mjx.Data:
        """An ``mjx.Data`` at ``qpos``, ``qvel`` with zero controls, as Gymnasium's ``set_state``
        after ``mj_resetData`` (quantities derived from positions are recomputed by the next step)."""
        data = mjx.make_data(self.mjx_model)
        return data.replace(qpos=jnp.asarray(qpos, data.qpos.dtype), qvel=jnp.asarray(qvel, data.qvel.dtype))

    def state_from_data(self, data: mjx.Data) -> State:
        return State(
            env_state=data,
            obs=self.observe(data),
            reward=jnp.zeros((self.reward_dim,), jnp.float32),
            done=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
        )

    def reset(self, key):
        """Gymnasium's ``reset_model``: ``qpos0`` plus uniform noise, zero velocity plus uniform or
        Gaussian noise, both of scale ``reset_noise_scale``."""
        model = self.mj_model
        key_pos, key_vel = jax.random.split(key)
        scale = self.reset_noise_scale
        qpos = jnp.asarray(self.init_qpos) + jax.random.uniform(key_pos, (model.nq,), minval=-scale, maxval=scale)
        if self.qvel_noise_normal:
            qvel = scale * jax.random.normal(key_vel, (model.nv,))
        else:
            qvel = jax.random.uniform(key_vel, (model.nv,), minval=-scale, maxval=scale)
        return self.state_from_data(self.data_from_state(qpos, qvel))

    def step(self, state, action):
        self.check_action(action)
        action = jnp.asarray(action, jnp.float32)
        before = state.env_state
        data = before.replace(ctrl=action.astype(before.ctrl.dtype))
        data = jax.lax.fori_loop(0, self.frame_skip, lambda _, d: mjx.step(self.mjx_model, d), data)
        data = self.postprocess(data)
        reward, done = self.reward_and_done(before, data, action)
        return state.replace(
            env_state=data,
            obs=self.observe(data),
            reward=reward.astype(jnp.float32),
            done=done,
            truncated=jnp.zeros((), bool),  # only a time limit truncates
        )

    # --- terms shared by the tasks -------------------------------------------------------------

    def x_velocity(self, before: mjx.Data, after: mjx.Data) -> jax.Array:
        """Gymnasium's ``x_velocity``: the root's x displacement over the step divided by ``dt``."""
        return (after.qpos[0] - before.qpos[0]) / self.dt


def neg_squared_action(action: jax.Array) -> jax.Array:
    """The control cost divided by its weight, negated: ``-sum(action ** 2)`` (MO-Gymnasium's cost objective)."""
    return -jnp.sum(jnp.square(action))


class PlanarEnv(MujocoEnv):
    """A planar task whose root is a slider in x: observes ``qpos[1:]`` and ``qvel`` (clipped to
    ``+-clip_qvel`` unless None), as Gymnasium's Hopper, Walker2d and HalfCheetah do."""

    clip_qvel: float | None = None

    def observe(self, data):
        qvel = data.qvel if self.clip_qvel is None else jnp.clip(data.qvel, -self.clip_qvel, self.clip_qvel)
        return jnp.concatenate([data.qpos[1:], qvel]).astype(jnp.float32)

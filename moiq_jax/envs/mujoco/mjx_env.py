"""The ``"mjx"`` backend: a task stepped with MJX in pure JAX, for accelerators.

``mjx.step`` on ``mjx.put_model`` of Gymnasium's MJCF, ``frame_skip`` times per env step; ``env_state``
is the ``mjx.Data``. MJX runs in float32 and its contact forces differ from MuJoCo's by a few per cent,
so it equals MuJoCo (and Gymnasium) only for the first steps of an episode (tests/test_mujoco_envs.py).

Solver settings (``mjx_solver``). ``"mujoco"`` keeps MuJoCo's (Newton, at most 100 iterations and 50
line-search iterations, tolerance 1e-8): MJX's solver stops at the tolerance, but under ``vmap`` every
env waits for the slowest, so the caps set the cost on an accelerator. ``"fast"`` caps them (see
``MJX_SOLVERS``), the default; ``solver_iterations`` and ``ls_iterations`` override either. Measured
errors and expert returns: results/mujoco_moiq_speed/README.md.
"""

from __future__ import annotations

import contextlib
import functools
import io

import jax
import jax.numpy as jnp
import mujoco

with contextlib.redirect_stdout(io.StringIO()):  # MJX prints a notice when its optional warp backend is absent
    from mujoco import mjx

from moiq_jax.envs.mujoco.base import MujocoEnv, Physics, Task

# name -> (iterations, ls_iterations); None keeps the model's (MuJoCo's defaults, 100 and 50)
MJX_SOLVERS = {"mujoco": (None, None), "fast": (4, 8)}


class MjxEnv(MujocoEnv):
    """A task on MJX (see the module docstring for ``mjx_solver``, ``solver_iterations``, ``ls_iterations``)."""

    backend = "mjx"

    def __init__(self, task: Task, mjx_solver: str = "fast", solver_iterations: int | None = None,
                 ls_iterations: int | None = None):
        if mjx_solver not in MJX_SOLVERS:
            raise ValueError(f"unknown mjx_solver {mjx_solver!r}; choose one of {', '.join(MJX_SOLVERS)}")
        super().__init__(task)
        preset = MJX_SOLVERS[mjx_solver]
        self.mjx_solver = mjx_solver
        self.solver_iterations = preset[0] if solver_iterations is None else solver_iterations
        self.ls_iterations = preset[1] if ls_iterations is None else ls_iterations

    @functools.cached_property
    def solver_model(self) -> mujoco.MjModel:
        """The task's model with this env's solver caps."""
        model = self.task.load_model()
        if self.solver_iterations is not None:
            model.opt.iterations = self.solver_iterations
        if self.ls_iterations is not None:
            model.opt.ls_iterations = self.ls_iterations
        return model

    @functools.cached_property
    def mjx_model(self) -> mjx.Model:
        """The device model; built eagerly even when first used inside a trace, so no tracer is cached."""
        with jax.ensure_compile_time_eval():
            return mjx.put_model(self.solver_model)

    def physics(self, data: mjx.Data) -> Physics:
        body = self.task.main_body_id
        return Physics(
            qpos=data.qpos,
            qvel=data.qvel,
            xpos=None if body is None else data.xpos[body],
            cfrc_ext=data._impl.cfrc_ext if self.task.contact_forces else None,
        )

    def _start(self, qpos, qvel, offset):
        qpos = jnp.asarray(qpos, jnp.float32)
        qvel = jnp.asarray(qvel, jnp.float32)
        if offset:
            qpos = jnp.asarray(self.task.init_qpos, jnp.float32) + qpos
        data = mjx.make_data(self.mjx_model)
        data = data.replace(qpos=qpos.astype(data.qpos.dtype), qvel=qvel.astype(data.qvel.dtype))
        if self.task.main_body is not None:
            # The rules read xpos, which Gymnasium's set_state computes; MJX's kinematics also normalises
            # the root quaternion in qpos, which set_state leaves as given.
            data = mjx.kinematics(self.mjx_model, data).replace(qpos=data.qpos)
        return self.initial_state(data, self.task.observe(self.physics(data), jnp))

    def step(self, state, action):
        self.check_action(action)
        action = jnp.asarray(action, jnp.float32)
        before = state.env_state
        data = before.replace(ctrl=action.astype(before.ctrl.dtype))
        data = jax.lax.fori_loop(0, self.task.frame_skip, lambda _, d: mjx.step(self.mjx_model, d), data)
        if self.task.contact_forces:
            data = mjx.rne_postconstraint(self.mjx_model, data)  # Gymnasium calls it after mj_step
        after = self.physics(data)
        reward, done = self.task.reward_and_done(self.physics(before), after, action, jnp)
        return state.replace(
            env_state=data,
            obs=self.task.observe(after, jnp).astype(jnp.float32),
            reward=reward.astype(jnp.float32),
            done=done,
            truncated=jnp.zeros((), bool),  # only a time limit truncates
        )


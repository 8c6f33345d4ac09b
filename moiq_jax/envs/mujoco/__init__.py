"""Multi-objective MuJoCo locomotion tasks after Gymnasium v5 and MO-Gymnasium, on two backends:
``"mujoco"`` (MuJoCo's C engine, ``native``) and ``"mjx"`` (MJX, ``mjx_env``); see ``base``.

``native`` is imported here; ``mjx_env`` (which imports MJX) only when an MJX env is built.
"""

from moiq_jax.envs.mujoco.ant import Ant
from moiq_jax.envs.mujoco.base import BACKENDS, MujocoEnv, Physics, PlanarTask, Task
from moiq_jax.envs.mujoco.half_cheetah import HalfCheetah, HalfCheetahV4
from moiq_jax.envs.mujoco.hopper import Hopper
from moiq_jax.envs.mujoco.native import NativeEnv
from moiq_jax.envs.mujoco.walker2d import Walker2d

TASKS: dict[str, type[Task]] = {
    "mo-hopper": Hopper,
    "mo-walker2d": Walker2d,
    "mo-halfcheetah": HalfCheetah,
    "mo-halfcheetah-v4": HalfCheetahV4,
    "mo-ant": Ant,
}


def make_env(task: str, backend: str, **kwargs) -> MujocoEnv:
    """The env of a task (a ``TASKS`` name) on a backend (``BACKENDS``); kwargs go to the backend's env
    (``nthread`` for "mujoco"; ``mjx_solver``, ``solver_iterations``, ``ls_iterations`` for "mjx")."""
    if backend == "mujoco":
        return NativeEnv(TASKS[task](), **kwargs)
    if backend == "mjx":
        from moiq_jax.envs.mujoco.mjx_env import MjxEnv

        return MjxEnv(TASKS[task](), **kwargs)
    raise ValueError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")


__all__ = ["BACKENDS", "TASKS", "Ant", "HalfCheetah", "HalfCheetahV4", "Hopper", "MujocoEnv", "NativeEnv", "Physics", "PlanarTask",
           "Task", "Walker2d", "make_env"]

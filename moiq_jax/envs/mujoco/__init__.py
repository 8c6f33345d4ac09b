"""Multi-objective MuJoCo locomotion envs on MJX, after Gymnasium v5 and MO-Gymnasium (see ``base``)."""

from moiq_jax.envs.mujoco.ant import Ant
from moiq_jax.envs.mujoco.base import MujocoEnv, PlanarEnv
from moiq_jax.envs.mujoco.half_cheetah import HalfCheetah
from moiq_jax.envs.mujoco.hopper import Hopper
from moiq_jax.envs.mujoco.walker2d import Walker2d

__all__ = ["Ant", "HalfCheetah", "Hopper", "MujocoEnv", "PlanarEnv", "Walker2d"]

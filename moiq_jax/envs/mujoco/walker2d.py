"""mo-walker2d: Gymnasium's Walker2d-v5 with MO-Gymnasium's ``mo-walker2d-v5`` vector reward."""

from __future__ import annotations

import jax.numpy as jnp

from moiq_jax.envs.mujoco.base import PlanarEnv, neg_squared_action


class Walker2d(PlanarEnv):
    """A two-legged planar walker (Walker2d-v5: frame skip 4, dt 0.008 s, uniform reset noise 5e-3).

    Observation (17): ``qpos[1:]`` (height, angles) and ``qvel`` clipped to [-10, 10].
    Reward (2), each objective plus the healthy reward 1 while healthy, as ``mo-walker2d-v5``:
    x velocity and ``-sum(action ** 2)``. Terminates when unhealthy: height outside (0.8, 2.0) or
    torso angle outside (-1, 1).
    """

    xml_file = "walker2d_v5.xml"
    frame_skip = 4
    reset_noise_scale = 5e-3
    clip_qvel = 10.0
    reward_dim = 2
    observation_size = 17
    action_size = 6

    def is_healthy(self, data):
        z, angle = data.qpos[1], data.qpos[2]
        return (z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0)

    def reward_and_done(self, before, after, action):
        healthy = self.is_healthy(after)
        reward = jnp.stack([self.x_velocity(before, after), neg_squared_action(action)])
        return reward + healthy.astype(jnp.float32), ~healthy

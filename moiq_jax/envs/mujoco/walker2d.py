"""mo-walker2d: Gymnasium's Walker2d-v5 with MO-Gymnasium's ``mo-walker2d-v5`` vector reward."""

from __future__ import annotations

from moiq_jax.envs.mujoco.base import PlanarTask, neg_squared_action


class Walker2d(PlanarTask):
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

    def is_healthy(self, p, xp):
        z, angle = p.qpos[..., 1], p.qpos[..., 2]
        return (z > 0.8) & (z < 2.0) & (angle > -1.0) & (angle < 1.0)

    def reward_and_done(self, before, after, action, xp):
        healthy = self.is_healthy(after, xp)
        reward = xp.stack([self.x_velocity(before, after), neg_squared_action(action, xp)], axis=-1)
        return reward + healthy[..., None], ~healthy

"""mo-hopper: Gymnasium's Hopper-v5 with MO-Gymnasium's ``mo-hopper-v5`` vector reward."""

from __future__ import annotations

from moiq_jax.envs.mujoco.base import PlanarTask, neg_squared_action


class Hopper(PlanarTask):
    """A one-legged planar hopper (Hopper-v5: frame skip 4, dt 0.008 s, uniform reset noise 5e-3).

    Observation (11): ``qpos[1:]`` (height, angles) and ``qvel`` clipped to [-10, 10].
    Reward (3), each objective plus the healthy reward 1 while healthy, as ``mo-hopper-v5``:
    x velocity, 10 x height above the start, and ``-sum(action ** 2)`` (the control cost over its weight).
    Terminates when unhealthy: height <= 0.7, |torso angle| >= 0.2, or any of ``(qpos, qvel)[2:]``
    outside (-100, 100).
    """

    xml_file = "hopper.xml"
    frame_skip = 4
    reset_noise_scale = 5e-3
    clip_qvel = 10.0
    reward_dim = 3
    observation_size = 11
    action_size = 3

    def is_healthy(self, p, xp):
        z, angle = p.qpos[..., 1], p.qpos[..., 2]
        state = xp.concatenate([p.qpos, p.qvel], axis=-1)[..., 2:]
        return xp.all(xp.abs(state) < 100.0, axis=-1) & (z > 0.7) & (xp.abs(angle) < 0.2)

    def reward_and_done(self, before, after, action, xp):
        healthy = self.is_healthy(after, xp)
        height = 10.0 * (after.qpos[..., 1] - self.init_qpos[1])
        reward = xp.stack([self.x_velocity(before, after), height, neg_squared_action(action, xp)], axis=-1)
        return reward + healthy[..., None], ~healthy

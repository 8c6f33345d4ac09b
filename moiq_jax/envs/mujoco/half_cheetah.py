"""mo-halfcheetah: Gymnasium's HalfCheetah-v5 with MO-Gymnasium's ``mo-halfcheetah-v5`` vector reward; and
``mo-halfcheetah-v4``'s, whose cost objective is a tenth of v5's (MO-Gymnasium's earlier version)."""

from __future__ import annotations

from moiq_jax.envs.mujoco.base import PlanarTask, neg_squared_action


class HalfCheetah(PlanarTask):
    """A planar cheetah (HalfCheetah-v5: frame skip 5, dt 0.05 s, reset noise 0.1: uniform on qpos,
    Gaussian on qvel).

    Observation (17): ``qpos[1:]`` and ``qvel`` (not clipped). Reward (2), as ``mo-halfcheetah-v5``:
    x velocity and ``-cost_scale * sum(action ** 2)`` (``cost_scale`` 1). Never terminates.
    """

    xml_file = "half_cheetah.xml"
    frame_skip = 5
    reset_noise_scale = 0.1
    qvel_noise_normal = True
    reward_dim = 2
    observation_size = 17
    action_size = 6
    cost_scale = 1.0

    def reward_and_done(self, before, after, action, xp):
        velocity = self.x_velocity(before, after)
        reward = xp.stack([velocity, self.cost_scale * neg_squared_action(action, xp)], axis=-1)
        return reward, xp.zeros(velocity.shape, bool)


class HalfCheetahV4(HalfCheetah):
    """The same cheetah with ``mo-halfcheetah-v4``'s reward: its cost objective is Gymnasium's control reward,
    ``-0.1 * sum(action ** 2)`` (v5 divides the 0.1 out). The dynamics of v4 and v5 are the same."""

    cost_scale = 0.1

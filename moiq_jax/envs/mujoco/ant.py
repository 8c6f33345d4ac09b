"""mo-ant: Gymnasium's Ant-v5 with the paper's two objectives, built from ``mo-ant-v5``'s terms."""

from __future__ import annotations

from moiq_jax.envs.mujoco.base import Task, neg_squared_action

CONTACT_COST_WEIGHT = 5e-4
CONTACT_FORCE_RANGE = 1.0


class Ant(Task):
    """A four-legged ant (Ant-v5: frame skip 5, dt 0.05 s, reset noise 0.1: uniform on qpos, Gaussian
    on qvel).

    Observation (105): ``qpos[2:]``, ``qvel`` and the external contact forces ``cfrc_ext`` of the 13
    bodies after the world, clipped to [-1, 1] (Ant-v5's default ``include_cfrc_ext_in_observation``).
    Reward (2): x velocity of the torso and ``-sum(action ** 2)``, each plus the healthy reward 1
    while healthy and minus the contact cost ``5e-4 * sum(clip(cfrc_ext, -1, 1) ** 2)``. These are the
    paper's two objectives. MO-Gymnasium's ``mo-ant-v5`` has three, (x velocity, y velocity,
    ``-sum(action ** 2)``) with the same healthy and contact terms added to each: this env's
    objectives are its objectives 0 and 2 exactly. (``mo-ant-2obj-v5`` is different again:
    x and y velocity with the weighted control cost folded in.)
    Terminates when unhealthy: torso height outside [0.2, 1.0] or a non-finite state.
    """

    xml_file = "ant.xml"
    frame_skip = 5
    reset_noise_scale = 0.1
    qvel_noise_normal = True
    main_body = "torso"  # Ant-v5's velocity is its xpos's (MuJoCo's kinematics at the last substep's start)
    contact_forces = True
    reward_dim = 2
    observation_size = 105
    action_size = 8

    def clipped_contact_forces(self, p, xp):
        return xp.clip(p.cfrc_ext, -CONTACT_FORCE_RANGE, CONTACT_FORCE_RANGE)

    def observe(self, p, xp):
        forces = self.clipped_contact_forces(p, xp)[..., 1:, :]
        forces = forces.reshape(*forces.shape[:-2], -1)
        return xp.concatenate([p.qpos[..., 2:], p.qvel, forces], axis=-1)

    def is_healthy(self, p, xp):
        state = xp.concatenate([p.qpos, p.qvel], axis=-1)
        z = p.qpos[..., 2]
        return xp.all(xp.isfinite(state), axis=-1) & (z >= 0.2) & (z <= 1.0)

    def reward_and_done(self, before, after, action, xp):
        healthy = self.is_healthy(after, xp)
        x_velocity = (after.xpos[..., 0] - before.xpos[..., 0]) / self.dt
        forces = self.clipped_contact_forces(after, xp)
        contact_cost = CONTACT_COST_WEIGHT * xp.sum(xp.square(forces), axis=(-2, -1))
        reward = xp.stack([x_velocity, neg_squared_action(action, xp)], axis=-1)
        return reward + (healthy - contact_cost)[..., None], ~healthy

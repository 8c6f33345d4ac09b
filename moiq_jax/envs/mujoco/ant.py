"""mo-ant: Gymnasium's Ant-v5 with the paper's two objectives, built from ``mo-ant-v5``'s terms."""

from __future__ import annotations

import jax.numpy as jnp

from moiq_jax.envs.mujoco.base import MujocoEnv, mjx, neg_squared_action

CONTACT_COST_WEIGHT = 5e-4
CONTACT_FORCE_RANGE = 1.0


class Ant(MujocoEnv):
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
    reward_dim = 2
    observation_size = 105
    action_size = 8

    def data_from_state(self, qpos, qvel):
        # The velocity term uses the torso's ``xpos``, which Gymnasium's set_state computes; MJX's
        # kinematics also normalises the root quaternion in qpos, which set_state leaves as given.
        data = super().data_from_state(qpos, qvel)
        return mjx.kinematics(self.mjx_model, data).replace(qpos=data.qpos)

    def postprocess(self, data):
        # Gymnasium calls mj_rnePostConstraint after mj_step for the contact forces.
        return mjx.rne_postconstraint(self.mjx_model, data)

    def contact_forces(self, data):
        return jnp.clip(data._impl.cfrc_ext, -CONTACT_FORCE_RANGE, CONTACT_FORCE_RANGE)

    def observe(self, data):
        forces = self.contact_forces(data)[1:].ravel()
        return jnp.concatenate([data.qpos[2:], data.qvel, forces]).astype(jnp.float32)

    def is_healthy(self, data):
        state = jnp.concatenate([data.qpos, data.qvel])
        z = data.qpos[2]
        return jnp.all(jnp.isfinite(state)) & (z >= 0.2) & (z <= 1.0)

    def reward_and_done(self, before, after, action):
        healthy = self.is_healthy(after)
        x_velocity = (after.xpos[1, 0] - before.xpos[1, 0]) / self.dt  # the torso, Ant-v5's main body
        contact_cost = CONTACT_COST_WEIGHT * jnp.sum(jnp.square(self.contact_forces(after)))
        reward = jnp.stack([x_velocity, neg_squared_action(action)])
        return reward + healthy.astype(jnp.float32) - contact_cost, ~healthy

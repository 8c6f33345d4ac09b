"""SAC experts: one per preference, all trained as one vmapped program (``algo="sac"``), saved as a
small parameter file, and their demonstrations recorded in the absorbing-state env that MOIQ learns in.

The experts train in the plain env (termination ends an episode); their demonstrations are recorded
with the absorbing state (paper sec. 4.1.1), the policy seeing the observation without its flag.
Demonstrations use the deterministic (mean) action, so reset noise is what tells episodes apart.
"""

from __future__ import annotations

import json
import os

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization, traverse_util

from moiq_jax.config import Config, tuned
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.networks import networks_of_config

# SAC as in the paper's experts (sec. 5.1, 0.5M steps; its Table 5 sizes) with Stable-Baselines3's SAC
# settings where the paper gives none: equal actor and critic learning rates, a learnt temperature from
# 1.0, 10K random steps first. 16 envs per expert and 16 updates per vectorised step keep SAC's one
# update per env step while the envs and updates run batched.
EXPERT_SETTINGS: dict = {
    "algo": "sac", "total_steps": 500_000, "num_envs": 16, "updates_per_step": 16, "learning_starts": 10_000,
    "buffer_size": 500_000, "actor_lr": 3e-4, "init_alpha": 1.0, "learn_alpha": True, "use_target": True,
    "eval_interval": 50_000, "eval_episodes": 5,
}

# The paper's expert returns (its Table 1, scalarised, mean of 10 demonstrations) per preference above; its
# halfcheetah row stands beside both reward scales of the task.
_PAPER_HALFCHEETAH = (3611.0, 2223.0, 325.0)
PAPER_EXPERT_RETURNS: dict[str, tuple[float, ...]] = {
    "mo-halfcheetah": _PAPER_HALFCHEETAH,
    "mo-halfcheetah-v4": _PAPER_HALFCHEETAH,
    "mo-hopper": (2155.0, 1686.0, 958.0),
    "mo-walker2d": (3706.0, 2442.0, 1110.0),
    "mo-ant": (2629.0, 1269.0, 431.0),
}


def expert_config(env: str, **changes) -> Config:
    """The SAC expert config for ``env``: its tuned preferences, ``EXPERT_SETTINGS``, then ``changes``."""
    return tuned(env, **{**EXPERT_SETTINGS, **changes})


def save_experts(path: str | os.PathLike, config: Config, actor_params) -> None:
    """Write trained experts' actor parameters (leading axis: one model per preference) and their config
    as one .npz (the critics are left out: a policy is all that demonstrations need)."""
    flat = traverse_util.flatten_dict(serialization.to_state_dict(jax.device_get(actor_params)), sep="/")
    with open(path, "wb") as f:
        np.savez_compressed(f, config=np.array(json.dumps(config.to_dict())),
                            **{f"actor/{k}": np.asarray(v) for k, v in flat.items()})


def load_experts(path: str | os.PathLike):
    """``(config, actor_params)`` from a file written by ``save_experts``."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"expert file {os.fspath(path)!r} does not exist")
    with np.load(path, allow_pickle=False) as data:
        if "config" not in data.files:
            raise ValueError(f"{os.fspath(path)!r} is not an expert file written by save_experts (no config)")
        config = Config(**json.loads(str(data["config"])))
        flat = {k[len("actor/"):]: jnp.asarray(data[k]) for k in data.files if k.startswith("actor/")}
    return config, traverse_util.unflatten_dict(flat, sep="/")


def record_demonstrations(config: Config, actor_params, num_demos: int = 10, seed: int = 0) -> Demonstrations:
    """``num_demos`` full-length episodes of each expert (``actor_params`` with a leading model axis, one
    model per ``config.preferences``) in the absorbing-state env, all episodes at once."""
    env = config.make_env(absorbing=True)
    c = config.offpolicy
    nets = networks_of_config(c, env)
    preferences = jnp.asarray(config.preferences, jnp.float32)
    horizon = env.episode_length

    def episode(actor_params, preference, key):
        def step(state, _):
            action = nets.act(actor_params, state.obs[None, :-1], preference)[0]  # without the absorbing flag
            nxt = env.step(state, action)
            return nxt, (state.obs, action, nxt.obs, nxt.reward, nxt.done)

        _, trajectory = jax.lax.scan(step, env.reset(key), None, length=horizon)
        return trajectory

    keys = jax.random.split(jax.random.PRNGKey(seed), (preferences.shape[0], num_demos))
    run = jax.jit(jax.vmap(jax.vmap(episode, in_axes=(None, None, 0))))
    obs, actions, next_obs, rewards, dones = (np.asarray(x) for x in run(actor_params, preferences, keys))
    return Demonstrations(
        obs=obs.astype(np.float32), actions=actions.astype(np.float32), next_obs=next_obs.astype(np.float32),
        rewards=rewards.astype(np.float32), dones=dones.astype(bool),
        lengths=np.full(obs.shape[:2], horizon, np.int32), preferences=np.asarray(preferences),
        env=config.env,
        metadata={"expert": "SAC (moiq_jax.experts.sac)", "absorbing": True, "expert_steps": c.total_steps,
                  "seed": config.seed},
    ).validate(env)

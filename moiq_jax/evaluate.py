"""Evaluation: vector returns of policies over whole episodes, all episodes run in parallel."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from moiq_jax.envs.base import Env
from moiq_jax.envs.wrappers import VmapWrapper

Policy = Callable[[jax.Array, jax.Array], jax.Array]  # (key, obs) -> action


def episode_returns(env: Env, policy: Policy, key: jax.Array, num_episodes: int) -> dict[str, jax.Array]:
    """Run ``num_episodes`` episodes side by side (one per env copy) to their end.

    ``env`` must carry a time limit (``make`` adds one). Returns ``returns`` (num_episodes, reward_dim):
    undiscounted vector returns; ``lengths`` (num_episodes,): steps until done or truncated.
    """
    horizon = env.episode_length
    batched = VmapWrapper(env, num_episodes)

    @jax.jit
    def run(key):
        reset_key, act_key = jax.random.split(key)
        state = batched.reset(reset_key)

        def body(carry, step_key):
            state, returns, lengths, alive = carry
            action = jax.vmap(policy)(jax.random.split(step_key, num_episodes), state.obs)
            nxt = batched.step(state, action)
            returns = returns + alive[:, None] * nxt.reward
            lengths = lengths + alive
            alive = alive & ~(nxt.done | nxt.truncated)
            return (nxt, returns, lengths, alive), None

        init = (
            state,
            jnp.zeros((num_episodes, env.reward_dim), jnp.float32),
            jnp.zeros((num_episodes,), jnp.int32),
            jnp.ones((num_episodes,), bool),
        )
        (_, returns, lengths, _), _ = jax.lax.scan(body, init, jax.random.split(act_key, horizon))
        return {"returns": returns, "lengths": lengths}

    return run(key)


def random_policy(env: Env) -> Policy:
    """Uniform random actions in the env's action space."""
    if env.discrete:
        return lambda key, obs: jax.random.randint(key, (), 0, env.num_actions)
    return lambda key, obs: jax.random.uniform(key, (env.action_size,), minval=-1.0, maxval=1.0)

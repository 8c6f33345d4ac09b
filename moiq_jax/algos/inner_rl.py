"""ADMM's inner RL: the solver each expert runs on the round's common reward, chosen by ``inner_rl``:
exact soft value iteration (``soft_vi``, fast) or PPO (``ppo``, the paper's choice)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from moiq_jax.algos import tabular
from moiq_jax.algos.ppo import ppo_agent
from moiq_jax.algos.tabular import InnerRL
from moiq_jax.config import Config


def soft_vi_agent(mdp: tabular.TabularMDP, config: Config) -> InnerRL:
    """Exact max-ent RL: the agent is its soft Q table, warm-started from the previous round."""
    temperature = config.admm.temperature
    return InnerRL(
        init=lambda key: jnp.zeros((mdp.num_states, mdp.num_actions)),
        improve=lambda q, reward, key: tabular.soft_value_iteration(reward, mdp, config.gamma, temperature, q),
        policy=lambda q: jax.nn.softmax(q / temperature, axis=-1),
    )


SOLVERS = {"soft_vi": soft_vi_agent, "ppo": ppo_agent}


def inner_rl(mdp: tabular.TabularMDP, config: Config) -> InnerRL:
    """The configured inner RL solver for ``mdp``."""
    return SOLVERS[config.admm.inner_rl](mdp, config)

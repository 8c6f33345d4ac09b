"""SAC on the scalarised true reward, with the vector critic: the experts' learner (one model per preference).

The critic ``Q(s, a, w)`` in R^d is fitted per objective to the soft Bellman target
``r + gamma (1 - done) V(s', w)``, with ``V`` the target critic's vector soft value
(``actor_critic.soft_value``: the twin with the smaller scalarised value, minus ``alpha log pi`` on every
objective). Because ``w`` sums to 1, ``w . Q`` then satisfies the soft Bellman equation of the
scalarised reward ``w . r``, so the actor and temperature losses are SAC's unchanged; the vector critic
also says what each objective contributes. Experts learn the task itself: termination ends the episode
(no absorbing state to imitate).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from moiq_jax.algos.actor_critic import soft_value
from moiq_jax.algos.offpolicy import Algorithm, policy_batch
from moiq_jax.networks import Networks, Params, tile


def critic_loss(critic_params, nets: Networks, params: Params, batches, preferences, key, gamma):
    """Soft TD loss summed over experts (leading axis of ``batches``), each the mean over both twins and
    the batch of the squared error summed over objectives."""
    alphas = jax.lax.stop_gradient(jnp.exp(params.log_alpha))

    def one_expert(batch, preference, alpha, key):
        q = nets.critic.apply(critic_params, batch["obs"], batch["action"], tile(preference, batch["obs"].shape[0]))
        next_value = soft_value(nets, params.target_critic, params.actor, alpha, batch["next_obs"], preference, key)
        target = batch["reward"] + gamma * (1.0 - batch["done"])[:, None] * next_value
        error = q - jax.lax.stop_gradient(target)  # (2, N, d)
        return jnp.mean(jnp.sum(error**2, axis=-1)), jnp.mean(q @ preference)

    num_experts = preferences.shape[0]
    losses, q_values = jax.vmap(one_expert)(batches, preferences, alphas, jax.random.split(key, num_experts))
    return jnp.sum(losses), {"td_loss": losses, "q_value": q_values}


def _objective(config):
    def loss(critic_params, nets, params, batches, preferences, hyper, key):
        return critic_loss(critic_params, nets, params, batches, preferences, key, config.gamma)

    return loss


ALGORITHM = Algorithm(sections=("offpolicy",), learns_from_demos=False, one_model_per_expert=True,
                      hyper=lambda config: {}, critic_loss=_objective, sample=policy_batch)

"""The soft actor-critic step every off-policy algorithm here shares (SAC's, with a vector critic):
a critic step on the algorithm's own critic loss, then the actor (paper eq. 10), the temperature, and
the Polyak-averaged target critics. One learnable temperature per expert.

Batches hold every expert at once (leading axis E); the actor and temperature losses are summed over
experts. The vector soft value ``V(s, w) = Q_k(s, a', w) - alpha log pi(a' | s, w) 1`` (``soft_value``)
adds the entropy term to every objective, so ``w . V`` is the usual soft value because w sums to 1.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct

from moiq_jax.networks import Networks, Params, tile


def policy_q(nets: Networks, critic_params, actor_params, obs, preference, key):
    """Every critic's vector values at actions of the current policy: ``Q_k(s, a', w)`` with
    ``a' ~ pi(. | s, w)``, ``(num_critics, N, d)``, and ``log pi(a' | s, w)``, ``(N,)``."""
    action, log_prob = nets.sample(actor_params, obs, preference, key)
    return nets.critic.apply(critic_params, obs, action, tile(preference, obs.shape[0])), log_prob


def soft_value_of(q, log_prob, alpha, preference):
    """``V(s, w) = Q_k(s, a', w) - alpha log pi(a' | s, w) 1`` from the critics' values ``q`` ``(num_critics, N,
    d)`` at policy actions a', where ``k`` is the critic whose scalarised value ``w . Q_k`` is smallest (clipped
    double Q; with one critic, that one)."""
    smaller = jnp.argmin(q @ preference, axis=0)  # (N,)
    q_min = jnp.take_along_axis(q, smaller[None, :, None], axis=0)[0]
    return q_min - alpha * log_prob[:, None]


def soft_value(nets: Networks, critic_params, actor_params, alpha, obs, preference, key):
    """Vector soft value ``V(s, w)`` (``soft_value_of``) with ``a' ~ pi(. | s, w)`` sampled by ``key``. ``(N, d)``."""
    q, log_prob = policy_q(nets, critic_params, actor_params, obs, preference, key)
    return soft_value_of(q, log_prob, alpha, preference)


def actor_loss(actor_params, nets: Networks, params: Params, batches, preferences, key):
    """Eq. 10 summed over experts: ``E_{s ~ D_i, a ~ pi(.|s, w_i)}[alpha_i log pi - min_k w_i . Q_k]``.
    Returns ``(loss, log_probs (E, B))``; the log-probabilities feed the temperature loss."""

    def one_expert(obs, preference, log_alpha, key):
        action, log_prob = nets.sample(actor_params, obs, preference, key)
        scalar_q = jnp.min(nets.critic.apply(params.critic, obs, action, tile(preference, obs.shape[0])) @ preference,
                           axis=0)
        return jnp.mean(jnp.exp(log_alpha) * log_prob - scalar_q), log_prob

    num_experts = preferences.shape[0]
    losses, log_probs = jax.vmap(one_expert)(
        batches["obs"], preferences, jax.lax.stop_gradient(params.log_alpha), jax.random.split(key, num_experts)
    )
    return jnp.sum(losses), log_probs


def temperature_loss(log_alpha, log_probs, target_entropy):
    """SAC's temperature loss per expert, summed: ``-log_alpha_i * E[log pi + target_entropy]``."""
    return -jnp.sum(log_alpha * jnp.mean(jax.lax.stop_gradient(log_probs) + target_entropy, axis=1))


@struct.dataclass
class Learner:
    """Parameters and the optimiser states of critic, actor and temperature."""

    params: Params
    critic_opt: Any
    actor_opt: Any
    alpha_opt: Any


class Optimisers(NamedTuple):
    critic: optax.GradientTransformation
    actor: optax.GradientTransformation
    alpha: optax.GradientTransformation


class Settings(NamedTuple):
    """The step's constants: the entropy target (minus the action size, as SAC), the Polyak rate of the
    target critics, and whether the temperature learns."""

    target_entropy: float
    tau: float
    learn_alpha: bool


def init_learner(nets: Networks, optimisers: Optimisers, key, obs_size, action_size, preferences, init_alpha):
    """Fresh networks (target = online critic) and optimiser states for ``len(preferences)`` experts."""
    critic_key, actor_key = jax.random.split(key)
    obs, action, w = jnp.zeros((1, obs_size)), jnp.zeros((1, action_size)), preferences[:1]
    critic = nets.critic.init(critic_key, obs, action, w)
    actor = nets.actor.init(actor_key, obs, w)
    log_alpha = jnp.full((preferences.shape[0],), jnp.log(init_alpha), jnp.float32)
    params = Params(critic=critic, target_critic=critic, actor=actor, log_alpha=log_alpha,
                    action_scale=nets.action_scale)
    return Learner(params, optimisers.critic.init(critic), optimisers.actor.init(actor), optimisers.alpha.init(log_alpha))


def update(learner: Learner, nets: Networks, optimisers: Optimisers, batches, preferences, key, settings: Settings,
           critic_objective):
    """One step for all experts: the critic on ``critic_objective(critic_params, params, batches,
    preferences, key) -> (loss, metrics)``, the actor (eq. 10), the temperature, then the Polyak targets."""
    critic_key, actor_key = jax.random.split(key)
    params = learner.params
    (loss_q, metrics), grads = jax.value_and_grad(critic_objective, has_aux=True)(
        params.critic, params, batches, preferences, critic_key
    )
    updates, critic_opt = optimisers.critic.update(grads, learner.critic_opt, params.critic)
    params = params.replace(critic=optax.apply_updates(params.critic, updates))

    (loss_pi, log_probs), grads = jax.value_and_grad(actor_loss, has_aux=True)(
        params.actor, nets, params, batches, preferences, actor_key
    )
    updates, actor_opt = optimisers.actor.update(grads, learner.actor_opt, params.actor)
    params = params.replace(actor=optax.apply_updates(params.actor, updates))

    alpha_opt = learner.alpha_opt
    if settings.learn_alpha:
        grads = jax.grad(temperature_loss)(params.log_alpha, log_probs, settings.target_entropy)
        updates, alpha_opt = optimisers.alpha.update(grads, alpha_opt, params.log_alpha)
        params = params.replace(log_alpha=optax.apply_updates(params.log_alpha, updates))

    params = params.replace(target_critic=optax.incremental_update(params.critic, params.target_critic, settings.tau))
    metrics = {**metrics, "critic_loss": loss_q, "actor_loss": loss_pi, "alpha": jnp.exp(params.log_alpha),
               "entropy": -jnp.mean(log_probs, axis=1)}
    return Learner(params, critic_opt, actor_opt, alpha_opt), metrics

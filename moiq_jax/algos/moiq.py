"""MOIQ: multi-objective inverse soft-Q learning (paper sec. 4.2), with IQ-Learn as its one-expert case.

One preference-conditioned network pair serves every expert: the vector critic Q(s, a, w) in R^d and the
actor pi(a | s, w). For expert i with preference w_i the recovered vector reward is
``r_i(s, a, s') = Q(s, a, w_i) - gamma (1 - done) V(s', w_i)``; its critic objective is IQ-Learn's on the
scalar reward ``w_i . r_i`` (eq. 9), and all experts' rewards are tied by the consensus penalty
``beta * mean_batch sum_j ||r_j - r_{j+1}||_2`` over neighbouring preferences on one common batch.
The actor minimises eq. 10 with a learnable temperature per expert, as SAC.

Batches hold every expert at once (leading axis E, experts sorted by preference); each expert's
batch is its expert samples followed by its policy samples, marked by ``is_expert``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax
from flax import struct

from moiq_jax.networks import TanhGaussianActor, TwinVectorCritic, sample_tanh_gaussian


class Networks(NamedTuple):
    critic: TwinVectorCritic
    actor: TanhGaussianActor


@struct.dataclass
class Params:
    """critic, target_critic: twin vector critics; actor; log_alpha: ``[E]`` one temperature per expert."""

    critic: Any
    target_critic: Any
    actor: Any
    log_alpha: jax.Array


class Hyper(NamedTuple):
    """The loss constants that are not swept: discount, chi^2 regulariser strength, entropy target."""

    gamma: float
    alpha_reg: float
    target_entropy: float


def _tile(preference, n):
    return jnp.broadcast_to(preference, (n, preference.shape[-1]))


def soft_value(nets: Networks, critic_params, actor_params, alpha, obs, preference, key):
    """Vector soft value ``V(s, w) = Q_k(s, a', w) - alpha log pi(a' | s, w) 1`` with ``a' ~ pi(. | s, w)``,
    where ``k`` is the twin whose scalarised value ``w . Q_k`` is smaller (clipped double Q). ``(N, d)``."""
    w = _tile(preference, obs.shape[0])
    action, log_prob = sample_tanh_gaussian(key, *nets.actor.apply(actor_params, obs, w))
    q = nets.critic.apply(critic_params, obs, action, w)  # (2, N, d)
    smaller = jnp.argmin(q @ preference, axis=0)  # (N,)
    q_min = jnp.take_along_axis(q, smaller[None, :, None], axis=0)[0]
    return q_min - alpha * log_prob[:, None]


def recovered_rewards(nets: Networks, critic_params, params: Params, alpha, batch, preference, key, gamma):
    """For preference w on ``batch`` (N transitions): the recovered vector rewards of both twins,
    ``r_k = Q_k(s, a, w) - gamma (1 - done) V_target(s', w)``, ``(2, N, d)``, and the value differences
    ``V(s, w) - gamma (1 - done) V_target(s', w)``, ``(N, d)``. ``key`` is split into the sample keys of
    V(s) and V(s'); V(s') uses the target critic and carries no gradient."""
    current_key, next_key = jax.random.split(key)
    w = _tile(preference, batch["obs"].shape[0])
    q = nets.critic.apply(critic_params, batch["obs"], batch["action"], w)
    value = soft_value(nets, critic_params, params.actor, alpha, batch["obs"], preference, current_key)
    next_value = soft_value(nets, params.target_critic, params.actor, alpha, batch["next_obs"], preference, next_key)
    discounted_next = jax.lax.stop_gradient(gamma * (1.0 - batch["done"])[:, None] * next_value)
    return q - discounted_next, value - discounted_next


def iq_learn_loss(reward, value_difference, is_expert, alpha_reg):
    """IQ-Learn's critic loss on scalar rewards (chi^2 divergence, 'value' sampling, online variant):
    ``-E_expert[r] + E_mix[V(s) - gamma V(s')] + E_mix[r^2] / (4 alpha_reg)`` over expert and policy samples."""
    expert = is_expert.astype(reward.dtype)
    expert_term = -jnp.sum(reward * expert) / jnp.sum(expert)
    return expert_term + jnp.mean(value_difference) + jnp.mean(reward**2) / (4.0 * alpha_reg)


def _norm(x):
    """Euclidean norm over the last axis with gradient 0 (a subgradient) at 0 instead of NaN."""
    squared = jnp.sum(x**2, axis=-1)
    positive = squared > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def consensus_penalty(rewards):
    """``mean_batch sum_j ||r_j - r_{j+1}||_2`` for rewards ``(E, ..., N, d)`` of experts sorted by preference."""
    distances = _norm(rewards[1:] - rewards[:-1])  # (E - 1, ..., N)
    return jnp.mean(jnp.sum(distances, axis=0))


def critic_loss(critic_params, nets: Networks, params: Params, batches, preferences, beta, key, hyper: Hyper):
    """Eq. 9 summed over experts plus ``beta`` times the consensus penalty; returns ``(loss, metrics)``.

    Every expert's recovered reward is evaluated on the union of all experts' batches (vmap over
    preferences); expert i's IQ-Learn term uses its own rows, averaged over the two twins as IQ-Learn does.
    """
    num_experts, per_expert = batches["is_expert"].shape
    union = jax.tree_util.tree_map(lambda x: x.reshape(num_experts * per_expert, *x.shape[2:]), batches)
    alphas = jax.lax.stop_gradient(jnp.exp(params.log_alpha))
    rewards, value_differences = jax.vmap(recovered_rewards, in_axes=(None, None, None, 0, None, 0, 0, None))(
        nets, critic_params, params, alphas, union, preferences, jax.random.split(key, num_experts), hyper.gamma
    )  # (E, 2, E*B, d), (E, E*B, d)

    experts = jnp.arange(num_experts)
    own_rewards = rewards.reshape(num_experts, 2, num_experts, per_expert, -1)[experts, :, experts]  # (E, 2, B, d)
    own_values = value_differences.reshape(num_experts, num_experts, per_expert, -1)[experts, experts]  # (E, B, d)
    scalar_rewards = jnp.einsum("ekbd,ed->ekb", own_rewards, preferences)
    scalar_values = jnp.einsum("ebd,ed->eb", own_values, preferences)
    per_twin = jax.vmap(jax.vmap(iq_learn_loss, in_axes=(0, None, None, None)), in_axes=(0, 0, 0, None))(
        scalar_rewards, scalar_values, batches["is_expert"], hyper.alpha_reg
    )  # (E, 2)
    iq_losses = jnp.mean(per_twin, axis=1)
    penalty = consensus_penalty(rewards)
    metrics = {"iq_loss": iq_losses, "penalty": penalty, "expert_reward": jnp.sum(
        scalar_rewards * batches["is_expert"][:, None], axis=(1, 2)) / (2 * jnp.sum(batches["is_expert"], axis=1))}
    return jnp.sum(iq_losses) + beta * penalty, metrics


def actor_loss(actor_params, nets: Networks, params: Params, batches, preferences, key):
    """Eq. 10 summed over experts: ``E_{s ~ D_i, a ~ pi(.|s, w_i)}[alpha_i log pi - min_k w_i . Q_k]``.
    Returns ``(loss, log_probs (E, B))``; the log-probabilities feed the temperature loss."""

    def one_expert(obs, preference, log_alpha, key):
        w = _tile(preference, obs.shape[0])
        action, log_prob = sample_tanh_gaussian(key, *nets.actor.apply(actor_params, obs, w))
        scalar_q = jnp.min(nets.critic.apply(params.critic, obs, action, w) @ preference, axis=0)
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


def init_learner(nets: Networks, optimisers: Optimisers, key, obs_size, action_size, preferences, init_alpha):
    """Fresh networks (target = online critic) and optimiser states for ``len(preferences)`` experts."""
    critic_key, actor_key = jax.random.split(key)
    obs, action, w = jnp.zeros((1, obs_size)), jnp.zeros((1, action_size)), preferences[:1]
    critic = nets.critic.init(critic_key, obs, action, w)
    actor = nets.actor.init(actor_key, obs, w)
    log_alpha = jnp.full((preferences.shape[0],), jnp.log(init_alpha), jnp.float32)
    params = Params(critic=critic, target_critic=critic, actor=actor, log_alpha=log_alpha)
    return Learner(params, optimisers.critic.init(critic), optimisers.actor.init(actor), optimisers.alpha.init(log_alpha))


def update(learner: Learner, nets: Networks, optimisers: Optimisers, batches, preferences, beta, key,
           hyper: Hyper, tau: float, learn_alpha: bool):
    """One MOIQ step for all experts: critic (eq. 9), actor (eq. 10), temperature, then Polyak targets."""
    critic_key, actor_key = jax.random.split(key)
    params = learner.params
    (loss_q, metrics), grads = jax.value_and_grad(critic_loss, has_aux=True)(
        params.critic, nets, params, batches, preferences, beta, critic_key, hyper
    )
    updates, critic_opt = optimisers.critic.update(grads, learner.critic_opt, params.critic)
    params = params.replace(critic=optax.apply_updates(params.critic, updates))

    (loss_pi, log_probs), grads = jax.value_and_grad(actor_loss, has_aux=True)(
        params.actor, nets, params, batches, preferences, actor_key
    )
    updates, actor_opt = optimisers.actor.update(grads, learner.actor_opt, params.actor)
    params = params.replace(actor=optax.apply_updates(params.actor, updates))

    alpha_opt = learner.alpha_opt
    if learn_alpha:
        grads = jax.grad(temperature_loss)(params.log_alpha, log_probs, hyper.target_entropy)
        updates, alpha_opt = optimisers.alpha.update(grads, alpha_opt, params.log_alpha)
        params = params.replace(log_alpha=optax.apply_updates(params.log_alpha, updates))

    params = params.replace(target_critic=optax.incremental_update(params.critic, params.target_critic, tau))
    metrics = {**metrics, "critic_loss": loss_q, "actor_loss": loss_pi, "alpha": jnp.exp(params.log_alpha),
               "entropy": -jnp.mean(log_probs, axis=1)}
    return Learner(params, critic_opt, actor_opt, alpha_opt), metrics

"""MOIQ: multi-objective inverse soft-Q learning (paper sec. 4.2), with IQ-Learn as its one-expert case.

One preference-conditioned network pair serves every expert: the vector critic Q(s, a, w) in R^d and the
actor pi(a | s, w). For expert i with preference w_i the recovered vector reward is
``r_i(s, a, s') = Q(s, a, w_i) - gamma (1 - done) V(s', w_i)``; its critic objective is IQ-Learn's on the
scalar reward ``w_i . r_i`` (eq. 9), and all experts' rewards are tied by the consensus penalty
``beta * mean_batch sum_j ||r_j - r_{j+1}||_2`` over neighbouring preferences on one common batch
drawn from all experts' batches (``shared_batch``). The actor and temperature are SAC's
(``actor_critic``), the actor minimising eq. 10.

Batches hold every expert at once (leading axis E, experts sorted by preference); each expert's
batch is its expert samples followed by its policy samples, marked by ``is_expert``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from moiq_jax.algos.actor_critic import policy_q, soft_value, soft_value_of
from moiq_jax.algos.offpolicy import Algorithm, expert_and_policy_batch
from moiq_jax.evaluate import pearson
from moiq_jax.networks import Networks, Params, tile


def recovered_rewards(nets: Networks, critic_params, params: Params, alpha, batch, preference, key, gamma,
                      use_target: bool = True):
    """For preference w on ``batch`` (N transitions): the recovered vector rewards of both twins,
    ``r_k = Q_k(s, a, w) - gamma (1 - done) V(s', w)``, ``(2, N, d)``, and the discounted next values
    ``gamma (1 - done) V(s', w)``, ``(N, d)``. V(s') samples a' with ``key``; it uses the target critic and
    carries no gradient if ``use_target``, else the online critic ``critic_params``, with gradient."""
    q = nets.critic.apply(critic_params, batch["obs"], batch["action"], tile(preference, batch["obs"].shape[0]))
    next_critic = params.target_critic if use_target else critic_params
    next_value = soft_value(nets, next_critic, params.actor, alpha, batch["next_obs"], preference, key)
    discounted_next = gamma * (1.0 - batch["done"])[:, None] * next_value
    if use_target:
        discounted_next = jax.lax.stop_gradient(discounted_next)
    return q - discounted_next, discounted_next


def iq_learn_loss(reward, value, discounted_next, is_expert, regularised, alpha_reg, gamma, value_term="value"):
    """IQ-Learn's critic loss on scalar rewards (chi^2 divergence, online): ``-E_expert[r] + second term +
    E_mix[r'^2] / (4 alpha_reg)`` over expert and policy samples, the second term ``E_mix[V(s) - gamma V(s')]``
    (``value_term="value"``) or ``(1 - gamma) E_expert[V(s)]`` (``"v0"``, the expert states standing for the
    initial ones, as IQ-Learn's code); ``r' = regularised`` is ``reward``, or on the policy rows the reward at
    the current policy's actions."""
    expert = is_expert.astype(reward.dtype)
    expert_term = -jnp.sum(reward * expert) / jnp.sum(expert)
    if value_term == "v0":
        second = (1.0 - gamma) * jnp.sum(value * expert) / jnp.sum(expert)
    else:
        second = jnp.mean(value - discounted_next)
    return expert_term + second + jnp.mean(regularised**2) / (4.0 * alpha_reg)


def _norm(x):
    """Euclidean norm over the last axis with gradient 0 (a subgradient) at 0 instead of NaN."""
    squared = jnp.sum(x**2, axis=-1)
    positive = squared > 0
    return jnp.where(positive, jnp.sqrt(jnp.where(positive, squared, 1.0)), 0.0)


def consensus_penalty(rewards):
    """``mean_batch sum_j ||r_j - r_{j+1}||_2`` for rewards ``(E, ..., N, d)`` of experts sorted by preference."""
    distances = _norm(rewards[1:] - rewards[:-1])  # (E - 1, ..., N)
    return jnp.mean(jnp.sum(distances, axis=0))


def shared_batch(batches):
    """The penalty's common batch: every ``2E``-th row of each of the ``E`` experts' batches (expert rows,
    then policy rows), so about half an expert batch's size in all, drawn from every expert's data."""
    num_experts = jax.tree_util.tree_leaves(batches)[0].shape[0]
    rows = jax.tree_util.tree_map(lambda x: x[:, :: 2 * num_experts], batches)
    return jax.tree_util.tree_map(lambda x: x.reshape(-1, *x.shape[2:]), rows)


def critic_terms(critic_params, nets: Networks, params: Params, batches, preferences, key, gamma, alpha_reg,
                 use_target, value_term="value", regulariser="replay", penalty_online=False):
    """Eq. 9's terms: each expert's IQ-Learn loss ``[E]``, the consensus penalty, and metrics.

    Expert i's IQ-Learn term uses its own batch (expert and policy rows), averaged over the two twins as
    IQ-Learn does. Its chi^2 regulariser reads the recovered reward at the rows' own actions
    (``regulariser="replay"``), or on the policy rows at actions of the current policy (``"policy"``, as
    IQ-Learn's code for MuJoCo: it holds down Q where the actor acts, not only where it acted), or on every row
    at both (``"both"``: with a target critic it also holds Q at the policy's actions on expert states, where the
    value term alone pushes it down without bound). The penalty compares all experts' recovered rewards on one
    common batch (``shared_batch``): comparing them on the union of all batches would cost E times the IQ
    terms' work for a lower-variance estimate of the same expectation. Each expert's rewards on its own rows and
    on the common rows come from one pass (one V(s') sample per row), unless ``penalty_online`` with
    ``use_target``: then the common rows' V(s') comes from the online critic, with gradient, so that the penalty
    is a function of the current critic alone and does not chase the lagging target.
    """
    num_experts, per_expert = batches["is_expert"].shape
    penalised = num_experts > 1  # static: one expert has no neighbours
    fields = ("obs", "action", "next_obs", "done")
    common = shared_batch({k: batches[k] for k in fields}) if penalised else None
    alphas = jax.lax.stop_gradient(jnp.exp(params.log_alpha))

    separate_common = penalised and penalty_online and use_target  # static

    def one_expert(own, preference, alpha, key):
        value_key, next_key = jax.random.split(key)
        rows = own if common is None or separate_common else jax.tree_util.tree_map(
            lambda a, b: jnp.concatenate([a, b]), own, common)
        rewards, discounted_next = recovered_rewards(nets, critic_params, params, alpha, rows, preference,
                                                     next_key, gamma, use_target)
        if separate_common:
            common_rewards, _ = recovered_rewards(nets, critic_params, params, alpha, common, preference,
                                                  jax.random.fold_in(next_key, 1), gamma, use_target=False)
        else:
            common_rewards = rewards[:, per_expert:]
        q_policy, log_prob = policy_q(nets, critic_params, params.actor, own["obs"], preference, value_key)
        value = soft_value_of(q_policy, log_prob, alpha, preference)
        own_next = discounted_next[:per_expert]
        return rewards[:, :per_expert], value, own_next, common_rewards, q_policy - own_next

    own_rewards, values, discounted_next, common_rewards, policy_rewards = jax.vmap(one_expert)(
        {k: batches[k] for k in fields}, preferences, alphas, jax.random.split(key, num_experts)
    )  # (E, 2, B, d), (E, B, d), (E, B, d), (E, 2, S, d), (E, 2, B, d)
    scalar_rewards = jnp.einsum("ekbd,ed->ekb", own_rewards, preferences)
    regularised = scalar_rewards
    if regulariser != "replay":
        scalar_policy = jnp.einsum("ekbd,ed->ekb", policy_rewards, preferences)
        if regulariser == "policy":
            regularised = jnp.where(batches["is_expert"][:, None], scalar_rewards, scalar_policy)
        else:
            regularised = jnp.concatenate([scalar_rewards, scalar_policy], axis=-1)
    scalar_values, scalar_next = (jnp.einsum("ebd,ed->eb", x, preferences) for x in (values, discounted_next))
    loss = functools.partial(iq_learn_loss, alpha_reg=alpha_reg, gamma=gamma, value_term=value_term)
    per_twin = jax.vmap(jax.vmap(loss, in_axes=(0, None, None, None, 0)))(
        scalar_rewards, scalar_values, scalar_next, batches["is_expert"], regularised
    )  # (E, 2)
    iq_losses = jnp.mean(per_twin, axis=1)
    penalty = consensus_penalty(common_rewards) if penalised else jnp.zeros(())
    expert = batches["is_expert"][:, None]
    metrics = {"iq_loss": iq_losses,
               "expert_reward": jnp.sum(scalar_rewards * expert, axis=(1, 2)) / jnp.sum(expert * 2, axis=(1, 2))}
    return iq_losses, penalty, metrics


def critic_loss(critic_params, nets: Networks, params: Params, batches, preferences, beta, key, gamma, alpha_reg,
                use_target, value_term="value", regulariser="replay", penalty_online=False):
    """Eq. 9 summed over experts plus ``beta`` times the consensus penalty; returns ``(loss, metrics)``."""
    iq_losses, penalty, metrics = critic_terms(critic_params, nets, params, batches, preferences, key, gamma,
                                               alpha_reg, use_target, value_term, regulariser, penalty_online)
    return jnp.sum(iq_losses) + beta * penalty, {**metrics, "penalty": penalty}


def recovered_reward_fn(config, nets: Networks):
    """``fn(params, data, preferences, key) -> [E, M, d]``: the recovered vector reward (the critic loss's own,
    mean of the twins; V(s') from the target critic only when ``use_target``) on each expert's transitions
    ``data`` (``[E, M, ...]``: obs, action, next_obs, done)."""

    def rewards(params, data, prefs, key):
        def one(data_i, preference, alpha, k):
            r, _ = recovered_rewards(nets, params.critic, params, alpha, data_i, preference, k, config.gamma,
                                     config.moiq.use_target)
            return jnp.mean(r, 0)  # over the twins

        return jax.vmap(one)(data, prefs, jnp.exp(params.log_alpha), jax.random.split(key, prefs.shape[0]))

    return rewards


def reward_correlations(config, nets: Networks):
    """At each evaluation: the recovered reward's (``recovered_reward_fn``) Pearson correlations with the true
    one on the demonstrations, scalarised by the expert's preference (``reward_correlation``) and per objective
    (``reward_correlation_objectives``, ``[E, d]``)."""
    rewards_of = recovered_reward_fn(config, nets)

    def metrics(params, extra, expert_data, prefs, key):
        rewards, true = rewards_of(params, expert_data, prefs, key), expert_data["true_reward"]
        scalar = jax.vmap(pearson)(jnp.einsum("emd,ed->em", rewards, prefs), jnp.einsum("emd,ed->em", true, prefs))
        per_objective = jax.vmap(jax.vmap(pearson, in_axes=(1, 1)))(rewards, true)
        return {"reward_correlation": scalar, "reward_correlation_objectives": per_objective}

    return metrics


def _objective(config):
    def loss(critic_params, nets, params, batches, preferences, hyper, key):
        return critic_loss(critic_params, nets, params, batches, preferences, hyper["beta"], key, config.gamma,
                           config.moiq.alpha_reg, config.moiq.use_target, config.moiq.value_term,
                           config.moiq.regulariser, config.moiq.penalty_online)

    return loss


ALGORITHM = Algorithm(sections=("offpolicy", "moiq"), learns_from_demos=True, one_model_per_expert=False,
                      hyper=lambda config: {"beta": config.moiq.beta}, critic_loss=_objective,
                      sample=expert_and_policy_batch, reward_metrics=reward_correlations)



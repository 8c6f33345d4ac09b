"""GAIL (Ho & Ermon, 2016) with a SAC generator: the paper's baseline (sec. 5.3, Table 4), one model per
preference.

A discriminator ``D(s, a) = sigmoid(logit(s, a))`` is trained by binary cross-entropy to tell expert
transitions (label 1) from the policy's (label 0); this is the convention of the ``imitation`` library's
``logits_expert_is_high`` (the GAIL paper labels the policy 1). The generator's reward is
``-log(1 - D(s, a)) = softplus(logit)``, the reward ``imitation`` gives GAIL's generator: positive, and
growing without bound as a transition looks more expert-like. In the absorbing-state env every episode
runs the full time limit, so a positive reward does not reward surviving longer (sec. 4.1.1).

The generator is the experts' SAC (``sac.critic_loss``) with the vector critic: the scalar reward is given in
every objective, so ``w . r`` is the reward itself because ``w`` sums to 1. Unlike ``imitation``, which
stores each transition's reward when it is collected, the reward of a replayed transition is recomputed
with the current discriminator (as Kostrikov et al.'s DAC does), so the generator never learns from a
stale reward.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from moiq_jax.algos import sac
from moiq_jax.algos.offpolicy import TRANSITION_FIELDS, Algorithm, Extra, expert_and_policy_batch
from moiq_jax.evaluate import pearson
from moiq_jax.networks import MLP


class Discriminator(nn.Module):
    """The logit of ``D(s, a)``, the probability that a transition is the expert's; shape ``(...,)``."""

    hidden_sizes: Sequence[int]

    @nn.compact
    def __call__(self, obs, action):
        return MLP(self.hidden_sizes, 1)(jnp.concatenate([obs, action], axis=-1))[..., 0]


@struct.dataclass
class DiscriminatorState:
    """The discriminator's parameters and optimiser state."""

    params: Any
    opt_state: Any


def discriminator_loss(logits, is_expert):
    """Mean binary cross-entropy of ``D = sigmoid(logits)`` with labels 1 for expert rows, 0 for policy rows:
    ``-mean(y log D + (1 - y) log(1 - D))``, written stably as ``softplus(-logit)`` or ``softplus(logit)``."""
    return jnp.mean(jnp.where(is_expert, jax.nn.softplus(-logits), jax.nn.softplus(logits)))


def generator_reward(logits):
    """The generator's reward ``-log(1 - D) = softplus(logit)``: increasing in the logit, positive."""
    return jax.nn.softplus(logits)


def init(module: Discriminator, optimiser: optax.GradientTransformation, key, obs_size: int,
         action_size: int) -> DiscriminatorState:
    """A fresh discriminator and its optimiser state."""
    params = module.init(key, jnp.zeros((1, obs_size)), jnp.zeros((1, action_size)))
    return DiscriminatorState(params, optimiser.init(params))


def update(state: DiscriminatorState, module: Discriminator, optimiser: optax.GradientTransformation, batch):
    """One gradient step on one expert's batch (expert rows and policy rows, marked by ``is_expert``).
    Returns the new state and the loss and accuracies (logit > 0 on expert rows, < 0 on policy rows)
    measured before the step."""

    def loss_fn(params):
        logits = module.apply(params, batch["obs"], batch["action"])
        return discriminator_loss(logits, batch["is_expert"]), logits

    (loss, logits), grads = jax.value_and_grad(loss_fn, has_aux=True)(state.params)
    updates, opt_state = optimiser.update(grads, state.opt_state, state.params)
    expert = batch["is_expert"]
    metrics = {"disc_loss": loss,
               "disc_expert_accuracy": jnp.sum((logits > 0) & expert) / jnp.sum(expert),
               "disc_policy_accuracy": jnp.sum((logits < 0) & ~expert) / jnp.sum(~expert)}
    return DiscriminatorState(optax.apply_updates(state.params, updates), opt_state), metrics


def with_reward(module: Discriminator, params, transitions, reward_dim: int):
    """``transitions`` (policy samples, ``(N, ...)``) with ``reward``: the generator reward in each of
    ``reward_dim`` objectives, ``(N, reward_dim)``, so ``w . reward`` is that reward for every preference w."""
    reward = generator_reward(module.apply(params, transitions["obs"], transitions["action"]))
    return {**transitions, "reward": jnp.broadcast_to(reward[:, None], (*reward.shape, reward_dim))}


def _extra_init(config, env):
    module, optimiser = Discriminator(config.offpolicy.hidden_sizes), optax.adam(config.gail.disc_lr)
    return lambda key, num_experts: jax.vmap(lambda k: init(module, optimiser, k, env.observation_size,
                                                            env.action_size))(jax.random.split(key, num_experts))


def _extra_update(config, env):
    """Train each expert's discriminator on its batch, then hand SAC the policy rows with its reward."""
    module, optimiser = Discriminator(config.offpolicy.hidden_sizes), optax.adam(config.gail.disc_lr)
    batch_size = config.offpolicy.batch_size

    def step(state, batches):
        state, metrics = jax.vmap(lambda d, b: update(d, module, optimiser, b))(state, batches)
        policy = {name: batches[name][:, batch_size:] for name in TRANSITION_FIELDS}
        return state, jax.vmap(lambda p, b: with_reward(module, p, b, env.reward_dim))(state.params, policy), metrics

    return step


def reward_correlations(config, nets):
    """At each evaluation: the discriminator's (scalar) reward against the true scalarised one on the
    demonstrations (``reward_correlation``)."""
    module = Discriminator(config.offpolicy.hidden_sizes)

    def metrics(params, state, expert_data, prefs, key):
        def correlation(disc_params, data_i, preference):
            rewards = generator_reward(module.apply(disc_params, data_i["obs"], data_i["action"]))
            return pearson(rewards, data_i["true_reward"] @ preference)

        return {"reward_correlation": jax.vmap(correlation)(state.params, expert_data, prefs)}

    return metrics


def _objective(config):
    def loss(critic_params, nets, params, batches, preferences, hyper, key):
        return sac.critic_loss(critic_params, nets, params, batches, preferences, key, config.gamma)

    return loss


ALGORITHM = Algorithm(sections=("offpolicy", "gail"), learns_from_demos=True, one_model_per_expert=True,
                      hyper=lambda config: {}, critic_loss=_objective, sample=expert_and_policy_batch,
                      extra=Extra(_extra_init, _extra_update), reward_metrics=reward_correlations)

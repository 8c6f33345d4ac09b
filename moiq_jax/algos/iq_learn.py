"""IQ-Learn (Garg et al., 2021), the paper's baseline: MOIQ's critic loss without the consensus penalty,
one model per expert, each learning from its own demonstrations alone."""

from __future__ import annotations

import jax.numpy as jnp

from moiq_jax.algos import moiq
from moiq_jax.algos.offpolicy import Algorithm, expert_and_policy_batch


def _objective(config):
    def loss(critic_params, nets, params, batches, preferences, hyper, key):
        iq_losses, _, metrics = moiq.critic_terms(critic_params, nets, params, batches, preferences, key,
                                                  config.gamma, config.moiq.alpha_reg, config.moiq.use_target,
                                                  config.moiq.value_term, config.moiq.regulariser)
        return jnp.sum(iq_losses), metrics

    return loss


ALGORITHM = Algorithm(sections=("offpolicy", "moiq"), learns_from_demos=True, one_model_per_expert=True,
                      hyper=lambda config: {}, critic_loss=_objective, sample=expert_and_policy_batch,
                      reward_metrics=moiq.reward_correlations)

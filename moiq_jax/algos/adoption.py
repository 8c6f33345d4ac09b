"""Experts that take over from one another between preferences (``Config.adopt_margin``, SAC's experts only).

Models trained one per preference each get stuck in their own gait; their evaluations' vector returns score
every model under every preference for free. Where another model serves a preference better by a margin,
that preference's model continues from the other's learner and replay, still trained for its own preference.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from moiq_jax.networks import preference_input_moved


def adopt_between_preferences(learner, buffers, returns, best_returns, preferences, margin):
    """``learner`` and ``buffers`` of models trained one per preference (leading model axis), ``returns``
    ``[E, d]`` their latest evaluation's vector returns, ``best_returns`` ``[E]`` each one's best scalarised
    evaluation so far: where another model's latest return, scalarised by model i's preference, beats model i's
    best by more than ``margin`` times its absolute value (its best, not its latest, so that one poor
    evaluation does not hand a model over), model i continues from the best such model's learner (networks,
    optimiser states, temperature) and replay buffer. The taken networks' first layers are moved
    (``preference_input_moved``) so that, fed i's preference, they act as they did fed the donor's. Returns ``(learner, buffers, donor)``, ``donor`` the model each one continues from
    (itself where it adopted nothing)."""
    scores = preferences @ returns.T  # [i, j]: model j's return scalarised by preference i
    best = jnp.argmax(scores, axis=1)
    models = jnp.arange(preferences.shape[0])
    donor = jnp.where(scores[models, best] - best_returns > margin * jnp.abs(best_returns), best, models)
    learner, buffers = jax.tree_util.tree_map(lambda x: x[donor], (learner, buffers))
    old, new = preferences[donor], preferences
    move = jax.vmap(preference_input_moved)
    params = learner.params.replace(actor=move(learner.params.actor, old, new),
                                    critic=move(learner.params.critic, old, new),
                                    target_critic=move(learner.params.target_critic, old, new))
    return learner.replace(params=params), buffers, donor

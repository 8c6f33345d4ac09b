"""The best models a run keeps between evaluations: the model of the best mean scalarised evaluation return
over the experts (one model for all of them, as transfer to other preferences needs), and, where one model
serves all experts, each expert's own best actor (a per-preference reading of "the best model")."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def initial_best(params, num_experts: int, per_expert: bool) -> dict:
    """The best-model fields of a run's state before its first evaluation (``per_expert``: keep each
    expert's best actor too, with a leading expert axis)."""
    fields = {"best_params": params, "best_return": jnp.full((), -jnp.inf, jnp.float32)}
    if per_expert:
        fields["best_actor_per_expert"] = jax.tree_util.tree_map(lambda x: jnp.stack([x] * num_experts), params.actor)
        fields["best_return_per_expert"] = jnp.full((num_experts,), -jnp.inf, jnp.float32)
    return fields


def keep_best(state, params, scalar):
    """``state`` with its best models updated by an evaluation of ``params`` that scored the scalarised
    returns ``scalar`` ``[E]`` (the experts in the state's order)."""
    score = jnp.mean(scalar)
    better = score > state.best_return
    state = state.replace(best_params=jax.tree_util.tree_map(lambda new, old: jnp.where(better, new, old),
                                                             params, state.best_params),
                          best_return=jnp.maximum(score, state.best_return))
    if state.best_actor_per_expert is None:
        return state
    better_each = scalar > state.best_return_per_expert
    return state.replace(
        best_actor_per_expert=jax.tree_util.tree_map(
            lambda new, old: jnp.where(better_each.reshape((-1,) + (1,) * new.ndim), new[None], old),
            params.actor, state.best_actor_per_expert),
        best_return_per_expert=jnp.maximum(scalar, state.best_return_per_expert))

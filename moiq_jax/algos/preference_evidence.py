"""What unlabelled demonstrations say about their experts' preferences on discrete DST: visit counts and
episode behaviours (the data of the preference step in ``preference_inference``), the spread initial
preferences that fix the answer's gauge, the exact interval of preferences a treasure is optimal for under
the true reward, and the record of a run's inferred preferences."""

from __future__ import annotations

import json
import os

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import envs
from moiq_jax.algos import tabular
from moiq_jax.config import Config
from moiq_jax.experts import dst_oracle
from moiq_jax.experts.demonstrations import Demonstrations


def spread_preferences(order, reward_dim: int = 2) -> np.ndarray:
    """Initial preferences for ``len(order)`` experts spread over the two-objective simplex: the expert
    ``order[k]`` gets ``w = [1 - (k + 1)/(n + 1), (k + 1)/(n + 1)]``, so ``order[0]`` weighs objective 0 most."""
    order = np.asarray(order)
    n = len(order)
    if reward_dim != 2:
        raise ValueError(f"spread_preferences orders experts along a line: it needs 2 objectives, got {reward_dim}")
    if n < 1 or sorted(order.tolist()) != list(range(n)):
        raise ValueError(f"order must be a permutation of range(n), got {order.tolist()}")
    k = np.empty(n)
    k[order] = np.arange(1, n + 1) / (n + 1)
    return np.stack([1.0 - k, k], axis=1).astype(np.float32)


def demo_counts(demos, mdp: tabular.TabularMDP, cols: int) -> jax.Array:
    """Undiscounted visit counts per episode ``[E, S + 1, A]`` of each expert's demonstrations, zero in the
    absorbing state (its actions do nothing, so they say nothing about the preference)."""
    counts = tabular.demo_occupancy(demos, mdp, cols, 1.0)
    return counts.at[:, mdp.absorbing].set(0.0)


def demo_exits(demos, mdp: tabular.TabularMDP, cols: int) -> jax.Array:
    """Each demonstrated episode's behaviour ``[E, N, 2]`` as ``greedy_exits`` gives it for policies: the
    state-action index of its transition into the absorbing state (-1 if none) and its steps until then."""
    states = tabular.state_index(jnp.asarray(demos.obs), mdp, cols)
    actions = jnp.asarray(demos.actions)
    real = jnp.arange(states.shape[-1]) < jnp.asarray(demos.lengths)[..., None]
    live = real & (states != mdp.absorbing)
    entering = live & (mdp.next_state[states, actions] == mdp.absorbing)
    index = jnp.where(entering, states * mdp.num_actions + actions, -1).max(-1)
    return jnp.stack([index, live.sum(-1)], axis=-1).astype(jnp.int32)


def true_interval(sea_map, treasure: tuple[int, int]) -> tuple[float, float] | None:
    """``[lo, hi]`` of the first weight ``a`` of ``w = [a, 1 - a]`` for which ``treasure`` is optimal under the
    true reward (exact, from the undiscounted front; ties included), or None if it never is."""
    steps = sea_map.treasure_steps(envs.dst.COMPASS_MOVES)
    value, n = float(sea_map.grid[treasure]), float(steps[treasure])
    lo, hi = 0.0, 1.0
    for cell, m in steps.items():
        # a * (value - v) - (1 - a) * (n - m) >= 0  <=>  a * (value - v + n - m) >= n - m
        slope, need = value - float(sea_map.grid[cell]) + n - m, n - m
        if slope > 0:
            lo = max(lo, need / slope)
        elif slope < 0:
            hi = min(hi, need / slope)
        elif need > 0:
            return None
    return (lo, max(lo, hi)) if lo <= hi + 1e-6 else None


def length_order(counts: np.ndarray) -> np.ndarray:
    """Experts sorted by their demonstrations' mean steps before the absorbing state, longest first."""
    return np.argsort(-np.asarray(counts).sum((-1, -2)), kind="stable")


def inference_inputs(demos: Demonstrations, env, mdp: tabular.TabularMDP, config: Config):
    """What the inference loop reads of ``demos``: discounted occupancies and visit counts ``[E, S+1, A]``,
    episode behaviours ``[E, N, 2]``, and the default initial preferences ``spread_preferences`` with the
    longest-travelling expert weighing objective 0 most (on DST objective 1 is the step cost)."""
    demos.validate(env)
    cols = env.unwrapped.sea_map.cols
    counts = demo_counts(demos, mdp, cols)
    return (tabular.demo_occupancy(demos, mdp, cols, config.gamma), counts, demo_exits(demos, mdp, cols),
            spread_preferences(length_order(counts), env.reward_dim))


def optimal_cells(sea_map, preferences) -> list:
    """The true-optimal treasure cell of every preference (``dst_oracle.optimal_treasure``)."""
    return [dst_oracle.optimal_treasure(sea_map, w)[0] for w in np.asarray(preferences)]


def write_run(result, run_dir: str | None = None, log=print, seed_index: int = 0) -> dict:
    """Log one seed's inferred preferences (of a ``preference_inference.InferenceResult``) per round and at
    the end (with their learned-reward intervals) and, with ``run_dir``, write them to
    ``run_dir/inferred_preferences.json``; returns what it writes."""

    per_round = np.asarray(result.metrics["preferences"][seed_index], np.float64)  # [rounds, E, d]
    for k, prefs in enumerate(per_round):
        log(f"round {k + 1}: preferences {np.round(prefs, 3).tolist()}")
    record = {
        "initial": result.initial[seed_index].tolist(),
        "inferred": per_round[-1].tolist(),
        "interval_learned_reward": result.learned_interval[seed_index].tolist(),
        "per_round": per_round.tolist(),
        "log_likelihood_per_round": np.where(np.isnan(result.metrics["log_likelihood"][seed_index]), None,
                                             result.metrics["log_likelihood"][seed_index]).tolist(),
    }
    log(f"inferred preferences {np.round(per_round[-1], 3).tolist()} (w[0] intervals with the same "
        f"behaviour under the learned reward: {np.round(result.learned_interval[seed_index], 3).tolist()})")
    return save_inferred(record, run_dir)


def save_inferred(record: dict, run_dir: str | None) -> dict:
    """Write an inference run's ``record`` to ``run_dir/inferred_preferences.json`` (nothing without a
    ``run_dir``); returns it."""
    if run_dir is not None:
        os.makedirs(run_dir, exist_ok=True)
        with open(os.path.join(run_dir, "inferred_preferences.json"), "w") as f:
            json.dump(record, f, indent=1)
    return record

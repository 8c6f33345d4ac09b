"""How well a trained inverse soft-Q learner (moiq, iq_learn) recovers the true reward: Pearson correlations of
its recovered reward (the critic loss's own, ``moiq.recovered_reward_fn``) with the true one, on the
demonstrations (``reward_correlations``: what the training evaluations record) or along the trained policy's own
episodes (``rollout_reward_correlations``: the measure of IQ-Learn's code, on which the paper's is built), and
those episodes themselves with both rewards (``policy_episodes``)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax.algos import moiq
from moiq_jax.algos.offpolicy import Algorithm, expert_transitions
from moiq_jax.config import Config
from moiq_jax.envs.wrappers import DoneOnAbsorption
from moiq_jax.evaluate import episode_transitions
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.networks import networks_of_config
from moiq_jax.train import algorithm_of


def _reward_learner(config: Config, measure: str) -> Algorithm:
    algorithm = algorithm_of(config)
    if not isinstance(algorithm, Algorithm) or algorithm.reward_metrics is None or algorithm.extra is not None:
        raise ValueError(f"{config.algo} does not recover its reward from the critic; {measure} reads moiq's and "
                         "iq_learn's")
    return algorithm


def reward_correlations(params, config: Config, demos: Demonstrations | None = None, seed: int = 0) -> dict:
    """How well trained ``params`` (a ``Result``'s ``best_params`` or ``final_params``, experts in the
    config's order) recover the true reward: ``reward_correlation`` ``[E]``, the Pearson correlation of the
    recovered and the true reward on each expert's demonstrations, scalarised by its preference, and
    ``reward_correlation_objectives`` ``[E, d]``, per objective; the same measure the training evaluations
    record. ``demos`` (in the config's preference order) replace the configured ones; ``seed`` draws the
    actions of V(s')."""
    algorithm = _reward_learner(config, "reward_correlations")
    env = config.make_env(absorbing=True)
    data = {k: jnp.asarray(v) for k, v in expert_transitions(load_demonstrations(config, env) if demos is None
                                                              else demos).items()}
    nets = networks_of_config(config.offpolicy, env)
    metrics = algorithm.reward_metrics(config, nets)
    preferences = jnp.asarray(config.preferences, jnp.float32)
    key = jax.random.PRNGKey(seed)
    if algorithm.one_model_per_expert:  # one model per expert, on a leading model axis
        per_model = jax.vmap(lambda p, d, w: metrics(p, None, jax.tree_util.tree_map(lambda x: x[None], d), w[None], key))
        return {k: np.asarray(v[:, 0]) for k, v in jax.jit(per_model)(params, data, preferences).items()}
    return {k: np.asarray(v) for k, v in jax.jit(lambda p: metrics(p, None, data, preferences, key))(params).items()}


def rollout_reward_correlations(params, config: Config, episodes: int = 100, seed: int = 0) -> dict:
    """How well trained ``params`` recover the true reward along their own policy's episodes (``policy_episodes``):
    for each expert's preference, across its ``episodes`` episodes, the Pearson correlation of the recovered and
    the true episode returns, scalarised (``episode_reward_correlation`` ``[E]``) and per objective
    (``episode_reward_correlation_objectives`` ``[E, d]``); over all their steps, ``step_reward_correlation``
    ``[E]``; the scalarised returns themselves, ``episode_returns`` and ``recovered_episode_returns``
    ``[E, episodes]``. A correlation is NaN where a side does not vary (a deterministic env and policy repeat
    one episode)."""
    steps = policy_episodes(params, config, episodes, seed)
    alive = steps["alive"]
    prefs = np.asarray(config.preferences, np.float64)
    recovered, true = (np.where(alive[..., None], steps[k], 0.0).astype(np.float64)
                       for k in ("recovered_reward", "reward"))  # [E, N, T, d]
    recovered_returns, true_returns = recovered.sum(2), true.sum(2)  # [E, N, d]
    scalar = lambda x: np.einsum("e...d,ed->e...", x, prefs)
    on_steps = lambda x: [row[a] for row, a in zip(scalar(x), alive)]  # each expert's steps of its episodes
    return {"episode_reward_correlation": _pearson(scalar(recovered_returns), scalar(true_returns)),
            "episode_reward_correlation_objectives": _pearson(np.moveaxis(recovered_returns, 1, -1),
                                                              np.moveaxis(true_returns, 1, -1)),
            "step_reward_correlation": np.asarray([_pearson(r, t) for r, t in zip(on_steps(recovered), on_steps(true))]),
            "episode_returns": scalar(true_returns), "recovered_episode_returns": scalar(recovered_returns)}


def policy_episodes(params, config: Config, episodes: int = 100, seed: int = 0) -> dict[str, np.ndarray]:
    """Trained ``params``' own episodes at each expert's preference, those of ``evaluate(params, ...,
    episodes, seed)`` (the deterministic policy), in the env it trained in: every step to the time limit as
    arrays ``[E, episodes, T, ...]``: ``obs``, ``action``, ``reward`` (true, vector), ``recovered_reward`` (the
    critic loss's own, vector) and ``alive`` (the step belongs to the episode: with ``absorbing_rollouts``
    every step does, those in the absorbing state after a termination too (their observation's last entry is
    1); without, the episode ends at its termination)."""
    run = _rollout_program(config.replace(seed=0, beta=0.0), episodes)
    return {k: np.asarray(v) for k, v in run(params, jnp.asarray(config.preferences, jnp.float32),
                                             jax.random.PRNGKey(seed)).items()}


@functools.lru_cache(maxsize=4)
def _rollout_program(config: Config, episodes: int):
    """``fn(params, preferences, key) -> policy_episodes``' arrays, jitted once per config up to its seed and
    consensus weight (neither enters it; the caller sets both to one value): a table's runs of one protocol
    share one compiled program (a MuJoCo env steps by a host callback, which JAX's persistent compilation cache
    cannot keep)."""
    algorithm = _reward_learner(config, "policy_episodes (and rollout_reward_correlations)")
    env = config.make_env(absorbing=True)
    env = env if config.offpolicy.absorbing_rollouts else DoneOnAbsorption(env)
    nets = networks_of_config(config.offpolicy, env)
    rewards_of = moiq.recovered_reward_fn(config, nets)

    def one_model(p, prefs, keys, value_key):  # prefs [k, d]: the preferences this model is evaluated at
        policy = lambda w: (lambda _, obs: nets.act(p.actor, obs[None], w)[0])
        steps = jax.vmap(lambda w, k: episode_transitions(env, policy(w), k, episodes))(prefs, keys)  # [k, N, T, ..]
        flat = lambda x: x.reshape(x.shape[0], -1, *x.shape[3:])
        data = {"obs": flat(steps["obs"]), "action": flat(steps["action"]), "next_obs": flat(steps["next_obs"]),
                "done": flat(steps["done"]).astype(jnp.float32)}
        recovered = rewards_of(p, data, prefs, value_key).reshape(steps["reward"].shape)
        return {"obs": steps["obs"], "action": steps["action"], "reward": steps["reward"],
                "recovered_reward": recovered, "alive": steps["alive"]}

    def run(params, preferences, key):
        keys = jax.random.split(key, preferences.shape[0])  # evaluate's episodes
        value_key = jax.random.fold_in(key, 1)
        if algorithm.one_model_per_expert:  # one model per expert, on a leading model axis
            per_model = jax.vmap(lambda p, w, k: one_model(p, w[None], k[None], value_key))
            return jax.tree_util.tree_map(lambda x: x[:, 0], per_model(params, preferences, keys))
        return one_model(params, preferences, keys, value_key)

    return jax.jit(run)


def _pearson(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Pearson correlation along the last axis; NaN where ``x`` or ``y`` is constant there."""
    xc, yc = x - x.mean(-1, keepdims=True), y - y.mean(-1, keepdims=True)
    scale = np.sqrt((xc**2).sum(-1) * (yc**2).sum(-1))
    return np.divide((xc * yc).sum(-1), scale, out=np.full(scale.shape, np.nan), where=scale > 0)

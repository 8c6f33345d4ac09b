"""The off-policy loop, once, for every algorithm (PureJaxRL style): ``make_trainer(config, algorithm)``
builds pure ``init(key)``, ``run_chunk(state, hyper)`` and ``train(key, hyper)``. A chunk is
``eval_interval`` env steps per expert in ``lax.scan`` (vectorised rollouts of all experts into their
replay buffers, then ``updates_per_step`` updates once ``learning_starts`` is passed) and an evaluation.

An ``Algorithm`` says what differs: whether it learns from demonstrations (in the absorbing-state env)
or from the env's reward, whether it trains one model for all experts or one per expert (vmapped), its
critic loss, how it samples a batch, an optional extra learner trained beside it (GAIL's discriminator)
and its reward metrics. ``hyper`` is the pytree of the values a sweep may vary (e.g. ``{"beta": 0.5}``);
it reaches the algorithm's critic loss and nothing else.

Inside, experts are held in the canonical ``preference_order``; everything a chunk reports is put back
in the config's order, so every value keeps the label it was given. What depends on the preference set
(demonstrations, preferences, the permutation ``back`` to the given order) is a ``setup`` pytree, an
input of ``train_with``, so a sweep can vmap over preference sets as it does over seeds.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from moiq_jax import replay
from moiq_jax.algos import actor_critic
from moiq_jax.algos.adoption import adopt_between_preferences
from moiq_jax.algos.best_models import initial_best, keep_best
from moiq_jax.config import Config
from moiq_jax.envs.wrappers import AutoReset, DoneOnAbsorption, VmapWrapper
from moiq_jax.evaluate import preference_returns
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.loading import load_demonstrations, preference_order
from moiq_jax.networks import networks_of_config
from moiq_jax.preferences import check_preferences

TRANSITION_FIELDS = ("obs", "action", "next_obs", "done")  # what the inverse-RL losses see of a transition


class Extra(NamedTuple):
    """A learner trained beside the actor-critic (GAIL's discriminator), for all ``E`` experts at once:
    ``init(config, env)(key, E) -> state``; ``update(config, env)(state, batches) -> (state, batches
    the critic learns from, metrics)``."""

    init: Callable
    update: Callable


class Algorithm(NamedTuple):
    """What one off-policy algorithm adds to the loop.

    sections: the Config sections it reads (validated). learns_from_demos: True, from demonstrations in
    the absorbing-state env; False, from the env's reward (experts). one_model_per_expert: train a model
    per expert (vmapped) instead of one preference-conditioned model for all. hyper(config): its swept
    values, e.g. ``{"beta": config.moiq.beta}``. critic_loss(config): ``loss(critic_params, nets, params,
    batches, preferences, hyper, key) -> (loss, metrics)``. sample: ``policy_batch`` or
    ``expert_and_policy_batch``. reward_metrics(config, nets): ``fn(params, extra, data, preferences, key)
    -> metrics`` at each evaluation, or None."""

    sections: tuple[str, ...]
    learns_from_demos: bool
    one_model_per_expert: bool
    hyper: Callable[[Config], dict]
    critic_loss: Callable
    sample: Callable
    extra: Extra | None = None
    reward_metrics: Callable | None = None


def policy_batch(buffers, expert_data, key, batch_size):
    """Per expert: a batch of its replay buffer (with the env's reward)."""
    policy_key, _ = jax.random.split(key)
    return jax.vmap(replay.sample, in_axes=(0, 0, None))(
        buffers, jax.random.split(policy_key, buffers.size.shape[0]), batch_size)


def expert_and_policy_batch(buffers, expert_data, key, batch_size):
    """Per expert: ``batch_size`` rows of its demonstrations, then as many of its replay buffer, marked by
    ``is_expert``."""
    num_experts = buffers.size.shape[0]
    policy_key, expert_key = jax.random.split(key)
    policy = jax.vmap(replay.sample, in_axes=(0, 0, None))(buffers, jax.random.split(policy_key, num_experts), batch_size)
    policy = {k: policy[k] for k in TRANSITION_FIELDS}
    rows = jax.random.randint(expert_key, (num_experts, batch_size), 0, expert_data["obs"].shape[1])
    expert = jax.tree_util.tree_map(
        lambda x: jnp.take_along_axis(x, rows.reshape(*rows.shape, *([1] * (x.ndim - 2))), axis=1),
        {k: expert_data[k] for k in TRANSITION_FIELDS})
    batches = jax.tree_util.tree_map(lambda e, p: jnp.concatenate([e, p], axis=1), expert, policy)
    is_expert = jnp.arange(2 * batch_size) < batch_size
    return {**batches, "is_expert": jnp.broadcast_to(is_expert, (num_experts, 2 * batch_size))}


@struct.dataclass
class RunnerState:
    """Everything one training run carries between steps (for ``E`` experts of one model)."""

    learner: actor_critic.Learner
    buffers: replay.ReplayBuffer  # leading expert axis
    env_state: Any  # [E, num_envs, ...]
    key: jax.Array
    env_steps: jax.Array
    best_params: Any
    best_return: jax.Array  # mean scalarised evaluation return of best_params
    extra: Any = None  # the algorithm's Extra state, leading expert axis
    best_actor_per_expert: Any = None  # one model for all experts: each one's best actor (best_models), else None
    best_return_per_expert: Any = None


class Trainer(NamedTuple):
    """Pure pieces of one configured training: ``init(key)``, ``run_chunk(state, hyper)`` (eval_interval
    env steps then an evaluation; metrics in the config's expert order), ``train(key, hyper)`` (all
    chunks); ``num_chunks``; ``hyper``: the config's swept values; ``preferences``: the labels, in the
    config's order; ``to_config_order(params, axis, back=None)``: parameters with per-expert entries
    (leading expert axis at ``axis``) put in the config's order (or a setup's, by its ``back``).
    ``train_with(key, hyper, setup)``: ``train`` for another preference set's ``setup(preferences, demos)``;
    ``setup``: the config's."""

    init: Any
    run_chunk: Any
    train: Any
    num_chunks: int
    hyper: dict
    preferences: np.ndarray
    to_config_order: Any
    train_with: Any = None
    setup: Any = None
    make_setup: Any = None


def expert_transitions(demos: Demonstrations) -> dict:
    """Real (unpadded) demo steps as ``[E, M, ...]`` arrays; every expert must have the same count M."""
    mask = demos.mask()
    counts = mask.reshape(mask.shape[0], -1).sum(1)
    if np.any(counts != counts[0]):
        raise ValueError(f"the learner needs equally many demo steps per expert (use the absorbing-state env), "
                         f"got {counts}")
    take = lambda x: np.stack([np.asarray(x)[e][mask[e]] for e in range(mask.shape[0])])
    return {
        "obs": take(demos.obs), "action": take(demos.actions), "next_obs": take(demos.next_obs),
        "done": take(demos.dones).astype(np.float32), "true_reward": take(demos.rewards),
    }


def make_trainer(config: Config, algorithm: Algorithm, demos: Demonstrations | None = None) -> Trainer:
    """Build the pure training functions of ``algorithm`` for ``config`` (demonstrations in the config's
    preference order, loaded from the config when not given)."""
    c = config.offpolicy
    env = config.make_env(absorbing=algorithm.learns_from_demos)
    labels = check_preferences(config.preferences, env.reward_dim)

    def make_setup(preferences, set_demos: Demonstrations | None = None) -> dict:
        """The traced inputs of one preference set: its demos' transitions and its preferences in the
        canonical order, and ``back`` (canonical -> given order); demos in the given order, loaded when None."""
        given = check_preferences(preferences, env.reward_dim)
        order = preference_order(given)  # canonical expert order inside the loop
        data = None
        if algorithm.learns_from_demos:
            if set_demos is None:
                set_demos = load_demonstrations(config.replace(preferences=tuple(map(tuple, given.tolist()))), env)
            data = {k: jnp.asarray(v[order]) for k, v in expert_transitions(set_demos).items()}
        return {"data": data, "preferences": jnp.asarray(given[order]), "back": jnp.asarray(np.argsort(order))}

    default_setup = make_setup(labels, demos)
    num_experts = labels.shape[0]
    ends_at_termination = algorithm.learns_from_demos and not c.absorbing_rollouts
    rollout_env = VmapWrapper(AutoReset(DoneOnAbsorption(env) if ends_at_termination else env), c.num_envs)
    nets = networks_of_config(c, env)
    optimisers = actor_critic.Optimisers(optax.adam(c.critic_lr), optax.adam(c.actor_lr), optax.adam(c.alpha_lr))
    settings = actor_critic.Settings(-float(env.action_size), c.tau, c.learn_alpha)
    critic_loss = algorithm.critic_loss(config)
    extra_init = algorithm.extra and algorithm.extra.init(config, env)
    extra_update = algorithm.extra and algorithm.extra.update(config, env)
    reward_metrics = algorithm.reward_metrics and algorithm.reward_metrics(config, nets)
    iterations_per_chunk = c.eval_interval // c.num_envs
    if c.adopt_margin is not None and (algorithm.learns_from_demos or not algorithm.one_model_per_expert):
        raise ValueError(f"adopt_margin is for experts, one model per preference trained on the env's reward (algo "
                         f"sac), which it compares; {config.algo} "
                         + ("learns from demonstrations and must not see that reward" if algorithm.learns_from_demos
                            else "trains one model for all experts"))

    def init(key, prefs):
        learner_key, env_key, key = jax.random.split(key, 3)
        learner = actor_critic.init_learner(nets, optimisers, learner_key, env.observation_size, env.action_size,
                                            prefs, c.init_alpha)
        example = {"obs": jnp.zeros(env.observation_size), "action": jnp.zeros(env.action_size),
                   "next_obs": jnp.zeros(env.observation_size), "done": jnp.zeros(()),
                   "reward": jnp.zeros(env.reward_dim)}
        buffers = jax.vmap(lambda _: replay.init(example, c.buffer_size))(jnp.arange(prefs.shape[0]))
        env_state = jax.vmap(rollout_env.reset)(jax.random.split(env_key, prefs.shape[0]))
        extra = None
        if extra_init:
            key, extra_key = jax.random.split(key)
            extra = extra_init(extra_key, prefs.shape[0])
        return RunnerState(learner, buffers, env_state, key, jnp.zeros((), jnp.int32), extra=extra,
                           **initial_best(learner.params, prefs.shape[0], not algorithm.one_model_per_expert))

    def env_iteration(state: RunnerState, hyper, expert_data, prefs):
        key, act_key, random_key, update_key = jax.random.split(state.key, 4)
        obs = state.env_state.obs  # [E, num_envs, obs]
        learned, _ = jax.vmap(nets.sample, in_axes=(None, 0, 0, 0))(
            state.learner.params.actor, obs, prefs, jax.random.split(act_key, prefs.shape[0]))
        random = jax.random.uniform(random_key, learned.shape, minval=-1.0, maxval=1.0)
        action = jnp.where(state.env_steps < c.learning_starts, random, learned)
        nxt = jax.vmap(rollout_env.step)(state.env_state, action)
        transitions = {"obs": obs, "action": action, "next_obs": nxt.info["final_obs"],
                       "done": nxt.done.astype(jnp.float32), "reward": nxt.reward}
        buffers = jax.vmap(replay.add)(state.buffers, transitions)
        objective = lambda critic_params, params, batches, p, k: critic_loss(critic_params, nets, params, batches,
                                                                             p, hyper, k)

        def learn(models):
            def one_update(models, k):
                learner, extra = models
                batch_key, step_key = jax.random.split(k)
                batches = algorithm.sample(buffers, expert_data, batch_key, c.batch_size)
                extra_metrics = {}
                if extra_update:
                    extra, batches, extra_metrics = extra_update(extra, batches)
                learner, metrics = actor_critic.update(learner, nets, optimisers, batches, prefs, step_key, settings,
                                                       objective)
                return (learner, extra), {**metrics, **extra_metrics}

            models, metrics = jax.lax.scan(one_update, models, jax.random.split(update_key, c.updates_per_step))
            return models, jax.tree_util.tree_map(lambda m: m[-1], metrics)

        ready = state.env_steps + c.num_envs > c.learning_starts
        (learner, extra), metrics = jax.lax.cond(
            ready, learn, lambda models: (models, jax.tree_util.tree_map(
                lambda s: jnp.zeros(s.shape, s.dtype), jax.eval_shape(learn, models)[1])),
            (state.learner, state.extra))
        metrics = {**metrics, "updated": ready}
        return state.replace(learner=learner, extra=extra, buffers=buffers, env_state=nxt, key=key,
                             env_steps=state.env_steps + c.num_envs), metrics

    def run_chunk(state: RunnerState, hyper, expert_data, prefs):
        state, metrics = jax.lax.scan(lambda s, _: env_iteration(s, hyper, expert_data, prefs), state, None,
                                      length=iterations_per_chunk)
        updated = jnp.maximum(jnp.sum(metrics.pop("updated")), 1)
        metrics = jax.tree_util.tree_map(lambda m: jnp.sum(m, axis=0) / updated, metrics)  # mean over updates
        key, eval_key = jax.random.split(state.key)
        keys = jax.random.split(eval_key)
        params = state.learner.params
        returns = preference_returns(nets, params.actor, env, prefs, keys[1], c.eval_episodes).mean(axis=1)
        scalar = jnp.sum(returns * prefs, axis=-1)
        state = keep_best(state.replace(key=key), params, scalar)
        metrics = {**metrics, "eval_return": returns, "eval_scalar_return": scalar, "env_steps": state.env_steps}
        if reward_metrics:
            metrics.update(reward_metrics(params, state.extra, expert_data, prefs, keys[0]))
        return state, metrics

    def in_config_order(metrics, back):
        """Per-expert metrics (leading axis E) from the canonical order to the given one."""
        return {k: v[back] if v.ndim >= 1 and v.shape[0] == num_experts else v for k, v in metrics.items()}

    if algorithm.one_model_per_expert:  # n single-expert models, vmapped
        def init_all(key, setup=default_setup):
            return jax.vmap(init)(jax.random.split(key, num_experts), setup["preferences"][:, None])

        def chunk_all(state, hyper, setup=default_setup):
            per_model = jax.tree_util.tree_map(lambda x: x[:, None], setup["data"])
            state, metrics = jax.vmap(run_chunk, in_axes=(0, None, 0, 0))(state, hyper, per_model,
                                                                          setup["preferences"][:, None])
            merged = {k: (v[:, 0] if v.ndim >= 2 and v.shape[1] == 1 else v) for k, v in metrics.items()}
            if c.adopt_margin is not None:
                learner, buffers, donor = adopt_between_preferences(
                    state.learner, state.buffers, merged["eval_return"], state.best_return, setup["preferences"],
                    c.adopt_margin)
                state = state.replace(learner=learner, buffers=buffers)
                given_index = jnp.argsort(setup["back"])  # canonical -> the config's expert index
                merged["adopted_from"] = jnp.where(donor == jnp.arange(num_experts), -1, given_index[donor])
            return state, in_config_order(merged, setup["back"])

        def to_config_order(params, axis=0, back=None):
            back = default_setup["back"] if back is None else back
            return jax.tree_util.tree_map(lambda x: jnp.take(x, back, axis=axis), params)
    else:
        def init_all(key, setup=default_setup):
            return init(key, setup["preferences"])

        def chunk_all(state, hyper, setup=default_setup):
            state, metrics = run_chunk(state, hyper, setup["data"], setup["preferences"])
            return state, in_config_order(metrics, setup["back"])

        def to_config_order(params, axis=0, back=None):
            back = default_setup["back"] if back is None else back
            return params.replace(log_alpha=jnp.take(params.log_alpha, back, axis=axis))

    def train_with(key, hyper, setup):
        state = init_all(key, setup)
        return jax.lax.scan(lambda s, _: chunk_all(s, hyper, setup), state, None, length=c.total_steps // c.eval_interval)

    hyper = {name: float(value) for name, value in algorithm.hyper(config).items()}
    return Trainer(init_all, chunk_all, lambda key, hyper: train_with(key, hyper, default_setup),
                   c.total_steps // c.eval_interval, hyper, labels, to_config_order, train_with, default_setup,
                   make_setup)

"""MOIQ with unknown preferences (continuous DST): an outer loop around the off-policy trainer.

The experts' demonstrations come without labels. The loop trains MOIQ (``offpolicy.make_trainer`` with
``moiq.ALGORITHM``) in chunks with the current preferences, which are traced inputs of the trainer's
``setup``, and between chunks runs a *preference step*:

1. every candidate ``w`` of a grid on the simplex gets the behaviour of the learned preference-conditioned
   actor ``pi(a | s, w)`` (the soft-optimal policy of the learned reward for ``w``, amortised over ``w``):
   one greedy rollout from the (deterministic) start, recorded as the cell the episode ends in and its
   steps (``rollout_behaviour``: no reward is read);
2. each expert's demonstrated episodes are replayed in the env and recorded the same way;
3. an expert keeps its preference while the actor at it repeats the largest share of its episodes
   (over the candidates); otherwise it moves to the candidate nearest (L1) its current preference among
   those whose behaviour equals the best-sharing candidate's (discrete DST's "closest" rule,
   ``preference_inference.preference_step``). While no candidate repeats any episode, it stays.

Why an outer loop and not preferences learned with the critic: see results/preference_inference/README.md.
As on discrete DST, the start fixes the answer's gauge: ``spread_preferences`` with the longest-travelling
expert weighing objective 0 most; preferences are identifiable only up to the interval of equal behaviour.
The expert axis keeps the start's canonical order throughout (the replay buffers are held in it).
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax.algos import moiq
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.algos.preference_evidence import save_inferred, spread_preferences
from moiq_jax.algos.preference_inference import simplex_grid
from moiq_jax.config import Config
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.loading import load_unlabelled_demonstrations
from moiq_jax.networks import networks_of_config
from moiq_jax.result import Result
from moiq_jax.runtime import shard_runs

ENVS = ("cdst",)  # deterministic start and dynamics, position observations: one rollout is the behaviour


def rollout_behaviour(env, act) -> jax.Array:
    """``[3]`` int32: the cell ``(row, col)`` of the position an episode of ``env`` (plain, time-limited)
    ends in by termination, ``(-1, -1)`` if it never terminates, and its steps; ``act(t, obs) -> action``."""

    def body(carry, t):
        state, cell, steps, alive = carry
        nxt = env.step(state, act(t, state.obs))
        ended = alive & nxt.done
        cell = jnp.where(ended, jnp.floor(nxt.obs).astype(jnp.int32), cell)
        return (nxt, cell, steps + alive, alive & ~nxt.done), None

    init = (env.reset(jax.random.PRNGKey(0)), jnp.full((2,), -1, jnp.int32), jnp.int32(0), jnp.bool_(True))
    (_, cell, steps, _), _ = jax.lax.scan(body, init, jnp.arange(env.episode_length))
    return jnp.concatenate([cell, steps[None]])


def demo_behaviours(demos: Demonstrations, env) -> jax.Array:
    """``[E, N, 3]``: each demonstrated episode's behaviour, its actions replayed in ``env`` (deterministic)."""
    actions = jnp.asarray(demos.actions)
    replay = lambda episode: rollout_behaviour(env, lambda t, _: episode[jnp.minimum(t, episode.shape[0] - 1)])
    return jax.vmap(jax.vmap(replay))(actions)


def actor_behaviours(nets, actor_params, env, preferences) -> jax.Array:
    """``[K, 3]``: the behaviour of the greedy actor at each preference (observations gain the absorbing
    flag 0, as the learner saw them)."""

    def one(w):
        act = lambda _, obs: nets.act(actor_params, jnp.concatenate([obs, jnp.zeros(1)])[None], w)[0]
        return rollout_behaviour(env, act)

    return jax.vmap(one)(preferences)


def preference_step(candidate_behaviour, candidates, demo_behaviour, current, current_behaviour):
    """Each expert's new preference ``[E, d]`` and the share of its episodes that the behaviour at it repeats
    ``[E]``: kept while the behaviour at ``current`` repeats at least the largest share of any candidate
    (and when no candidate repeats any episode), else the nearest candidate with the best one's behaviour.

    candidate_behaviour ``[K, 3]`` for candidates ``[K, d]``; demo_behaviour ``[E, N, 3]``; current ``[E, d]``
    with its behaviour ``[E, 3]`` (under whichever reward or policy is being asked: the learned actor in the
    loop, the true optimum in tests)."""
    same_as = lambda b: jnp.all(demo_behaviour[:, :, None, :] == b[:, None, :, :], axis=-1).mean(1)
    share = same_as(jnp.broadcast_to(candidate_behaviour, (current.shape[0], *candidate_behaviour.shape)))  # [E, K]
    share_current = same_as(current_behaviour[:, None])[:, 0]  # [E]
    best = jnp.argmax(share, axis=1)
    keep = (share_current >= share.max(1)) | (share.max(1) == 0)
    same = jnp.all(candidate_behaviour[None] == candidate_behaviour[best][:, None], axis=-1)  # [E, K]
    distance = jnp.abs(candidates[None] - current[:, None]).sum(-1)
    nearest = jnp.argmin(jnp.where(same, distance, jnp.inf), axis=1)
    return (jnp.where(keep[:, None], current, candidates[nearest]),
            jnp.where(keep, share_current, share.max(1)))


def spread_start(demo_behaviour, reward_dim: int) -> np.ndarray:
    """``spread_preferences`` with the experts ordered by their episodes' mean steps, longest first."""
    steps = np.asarray(demo_behaviour)[..., 2].mean(1)
    return spread_preferences(np.argsort(-steps, kind="stable"), reward_dim)


def check(config: Config) -> None:
    """Raise ValueError for what the loop does not support."""
    if config.algo != "moiq":
        raise ValueError(f"preference inference with the off-policy loop runs algo 'moiq', got {config.algo!r}")
    if config.env not in ENVS:
        raise ValueError(f"algo 'moiq' infers preferences on {', '.join(ENVS)} (deterministic, one rollout per "
                         f"candidate is its behaviour), got env {config.env!r}")
    c, m = config.offpolicy, config.moiq
    for name, value in (("preference_warmup_steps", m.preference_warmup_steps),
                        ("preference_interval", m.preference_interval)):
        if value % c.eval_interval:
            raise ValueError(f"{name} ({value}) must be a multiple of eval_interval ({c.eval_interval})")
    if m.preference_warmup_steps >= c.total_steps:
        raise ValueError(f"preference_warmup_steps ({m.preference_warmup_steps}) must be below total_steps "
                         f"({c.total_steps}), or no preference step runs")


def train_seeds(config: Config, seeds, demos: Demonstrations | None = None, log=None,
                resolution: int = 20) -> Result:
    """Train MOIQ inferring the preferences, every seed in one vmapped program per chunk. ``demos``: the
    experts' demonstrations (labels, if any, ignored); None: ``load_unlabelled_demonstrations(config)``.
    ``log(line)`` gets each chunk's preferences and returns. The ``Result`` (a run per seed, experts in the
    demonstrations' order) has the trainer's history plus ``preferences`` and ``share`` per chunk; its
    preferences are seed 0's inferred ones; ``extras``: ``inferred_preferences`` ``[seeds, E, d]``,
    ``initial_preferences`` ``[E, d]``, ``demo_behaviour`` ``[E, N, 3]`` and ``demo_return`` ``[E, d]``."""
    check(config)
    config.validate(sections=ALGORITHM.sections)
    start = time.perf_counter()
    env = config.make_env()
    demos = load_unlabelled_demonstrations(config) if demos is None else demos.unlabelled()
    demos.validate(config.make_env(absorbing=True))
    demo_behaviour = jax.jit(demo_behaviours, static_argnums=1)(demos, env)
    initial = spread_start(demo_behaviour, env.reward_dim)
    labelled = config.replace(preferences=tuple(map(tuple, initial.tolist())))
    trainer = make_trainer(labelled, moiq.ALGORITHM, demos.replace(preferences=initial))
    setup, back = trainer.setup, trainer.setup["back"]
    order = np.argsort(np.asarray(back))  # the demonstrations' order -> the trainer's canonical order
    seeds = list(seeds)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    prefs = jnp.broadcast_to(jnp.asarray(initial[order]), (len(seeds), *initial.shape))
    keys, prefs = shard_runs(keys, prefs)
    hyper = {name: jnp.float32(value) for name, value in trainer.hyper.items()}
    state = jax.jit(jax.vmap(lambda k: trainer.init(k, setup)))(keys)
    chunk = jax.jit(jax.vmap(lambda s, p: trainer.run_chunk(s, hyper, {**setup, "preferences": p})))
    candidates = jnp.asarray(simplex_grid(env.reward_dim, resolution))
    canonical_demos = demo_behaviour[order]
    c, m = config.offpolicy, config.moiq
    nets = networks_of_config(c, env)  # the trainer's

    @jax.jit
    @jax.vmap
    def step(actor, current):
        behaviour = actor_behaviours(nets, actor, env, jnp.concatenate([candidates, current]))
        return preference_step(behaviour[: len(candidates)], candidates, canonical_demos, current,
                               behaviour[len(candidates):])

    warmup, interval = m.preference_warmup_steps // c.eval_interval, m.preference_interval // c.eval_interval
    share = jnp.full((len(seeds), initial.shape[0]), jnp.nan)
    history = []
    for index in range(trainer.num_chunks):
        if index >= warmup and (index - warmup) % interval == 0:
            prefs, share = step(state.learner.params.actor, prefs)
        state, metrics = chunk(state, prefs)
        metrics = {**jax.device_get(metrics), "preferences": np.asarray(prefs)[:, back],
                   "share": np.asarray(share)[:, back]}
        history.append(metrics)
        if log is not None:
            shown = lambda x, digits: np.round(np.asarray(x, np.float64), digits).tolist()
            log(f"steps {(index + 1) * c.eval_interval}: preferences {shown(metrics['preferences'], 3)} "
                f"vector returns {shown(metrics['eval_return'], 2)} ({time.perf_counter() - start:.0f}s)")
    stacked = {k: np.stack([h[k] for h in history], axis=1) for k in history[0]}  # [seeds, chunks, ...]
    to_order = jax.vmap(lambda p: trainer.to_config_order(p, 0, back))
    inferred = stacked["preferences"][:, -1]
    return Result(config=config, preferences=inferred[0], history=stacked,
                  final_params=jax.device_get(to_order(state.learner.params)),
                  best_params=jax.device_get(to_order(state.best_params)), best_return=np.asarray(state.best_return),
                  seconds=time.perf_counter() - start, runs={"seed": np.asarray(seeds)},
                  extras={"inferred_preferences": inferred, "initial_preferences": initial,
                          "demo_behaviour": np.asarray(demo_behaviour), "demo_return": demos.mean_returns()})


def write_run(result: Result, run_dir: str | None = None, log=print) -> dict:
    """The inferred preferences of a one-seed ``Result`` of ``train_seeds`` (after ``run``): logged, and with
    ``run_dir`` written to ``run_dir/inferred_preferences.json`` (initial, inferred, per chunk with env steps,
    and per chunk the share of each expert's episodes the actor at its preference repeated at the last step)."""
    per_chunk = np.asarray(result.history["preferences"], np.float64)
    share = np.asarray(result.history["share"], np.float64)
    record = {"initial": np.asarray(result.extras["initial_preferences"]).tolist(), "inferred": per_chunk[-1].tolist(),
              "env_steps": np.asarray(result.history["env_steps"]).tolist(), "per_chunk": per_chunk.tolist(),
              "share_per_chunk": np.where(np.isnan(share), None, share).tolist()}
    log(f"inferred preferences {np.round(per_chunk[-1], 3).tolist()} (initial spread "
        f"{np.round(record['initial'], 3).tolist()})")
    return save_inferred(record, run_dir)


class OuterLoop(NamedTuple):
    """A registry entry run by ``train_seeds`` (not by the off-policy loop's chunk runner)."""

    sections: tuple[str, ...]
    train_seeds: callable


ALGORITHM = OuterLoop(sections=("offpolicy", "moiq"), train_seeds=train_seeds)

"""Infer the experts' preferences from unlabelled demonstrations jointly with the common reward (discrete DST).

Consensus-ADMM MOIRL (``admm.py``) needs each expert's preference ``w_i`` twice: in the x-update's gain
``(rhoE_i - rho_i) w_i`` and in the inner RL's scalar reward ``rbar . w_i``. Here the preferences are
unknown and each round is

1. the ADMM iterations of ``admm.consensus_admm`` with the current preferences (as ``admm.make_train``);
2. the *preference step*: for the new common reward ``rbar``, every candidate ``w`` of a grid on the
   simplex gets its soft-optimal (max-ent) policy by exact soft value iteration (vmapped over the
   candidates), and each expert takes the candidate under which its demonstrated state-actions are most
   likely, ``argmax_w sum_{s,a} n_i(s, a) log pi_w(a|s)`` (``n_i``: undiscounted visit counts, absorbing
   state left out, where every action is the same);
3. the inner RL of ``admm.inner_rl`` for every expert on ``rbar . w_i`` with the new preferences.

The joint problem has exact symmetries, so the initial preferences choose the answer's gauge:

- Swapping the objectives of the reward and of every preference changes nothing (the x-update is
  separable over objectives). With every expert starting at the same preference the objectives of the
  reward stay equal forever and the likelihood is flat: the initial preferences must differ.
  ``spread_preferences`` spreads them over the simplex in an order the caller picks, which fixes which
  objective is which.
- Scaling one objective of the reward by ``c`` and that weight of every preference by ``1/c``
  (renormalised) changes each expert's scalar reward only by a positive factor, i.e. its behaviour not at
  all: from behaviour alone a preference is known only up to the interval of ``w`` over which the optimal
  behaviour is the same, and that interval is measured under the *learned* reward
  (``learned_intervals``). Which point of the true reward's interval it maps to is fixed by the ADMM
  dynamics, not by the data.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import envs
from moiq_jax.algos import admm, tabular
from moiq_jax.algos import preference_evidence as evidence
from moiq_jax.config import Config
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.loading import load_unlabelled_demonstrations
from moiq_jax.result import Result


def simplex_grid(reward_dim: int, resolution: int) -> np.ndarray:
    """All preferences with weights in ``{0, 1/resolution, ..., 1}`` summing to 1, ``[K, reward_dim]``; for two
    objectives ordered by the first weight, decreasing."""
    if reward_dim < 1 or resolution < 1:
        raise ValueError(f"simplex_grid needs reward_dim >= 1 and resolution >= 1, got {reward_dim}, {resolution}")

    def compositions(total, parts):
        if parts == 1:
            return [(total,)]
        return [(k, *rest) for k in range(total, -1, -1) for rest in compositions(total - k, parts - 1)]

    return np.asarray(compositions(resolution, reward_dim), np.float32) / resolution


def candidate_policies(common: jax.Array, candidates: jax.Array, mdp: tabular.TabularMDP, config: Config,
                       q_init: jax.Array | None = None):
    """Soft-optimal Q tables ``[K, S + 1, A]`` and log-policies of ``common . w`` for every candidate ``w``."""
    q_init = jnp.zeros((candidates.shape[0], mdp.num_states, mdp.num_actions)) if q_init is None else q_init
    q = jax.vmap(lambda w, q0: tabular.soft_value_iteration(common @ w, mdp, config.gamma, config.admm.temperature, q0))(
        candidates, q_init)
    return q, jax.nn.log_softmax(q / config.admm.temperature, axis=-1)


def log_likelihoods(log_policies: jax.Array, counts: jax.Array) -> jax.Array:
    """``[E, K]``: mean per-episode log-likelihood of each expert's demonstrated actions under each candidate."""
    return jnp.einsum("esa,ksa->ek", counts, log_policies)


def greedy_exits(q: jax.Array, mdp: tabular.TabularMDP) -> jax.Array:
    """The behaviour of the greedy policies of Q tables ``[K, S + 1, A]`` as ``[K, 2]`` integers: the
    state-action index of the transition into the absorbing state (-1 if never) and the steps until then.
    Equal rows mean the same treasure after the same number of steps (label-free: no reward is read)."""

    def exit_of(q):
        actions = jnp.argmax(q, axis=-1)

        def step(carry, _):
            state, exit_, steps = carry
            action = actions[state]
            nxt = mdp.next_state[state, action]
            entering = (state != mdp.absorbing) & (nxt == mdp.absorbing)
            exit_ = jnp.where(entering, state * mdp.num_actions + action, exit_)
            return (nxt, exit_, steps + (state != mdp.absorbing)), None

        (_, exit_, steps), _ = jax.lax.scan(step, (jnp.int32(mdp.start), jnp.int32(-1), jnp.int32(0)), None,
                                            length=mdp.horizon)
        return jnp.stack([exit_, steps])

    return jax.vmap(exit_of)(q)


def preference_step(common, counts, exits, candidates, current, mdp, config, q_init=None, rule: str = "closest"):
    """Each expert's new preference for the common reward: ``(preferences [E, d], log-likelihood [E], Q [K, ...])``.

    Candidates are ranked first by the share of the expert's episodes (``exits`` ``[E, N, 2]``, from
    ``demo_exits``) whose behaviour the candidate's greedy policy repeats, then by the log-likelihood of
    the demonstrated actions under its soft-optimal policy (the likelihood alone is confounded by the
    scalar reward's scale: a larger ``r . w`` makes every policy more peaked). ``rule="likelihood"``: the
    best candidate. ``rule="closest"``: the candidate nearest (L1) to the expert's ``current`` preference
    among those whose greedy behaviour equals the best one's, so the preference moves no further than the
    behaviour needs (within a behaviour the data cannot tell preferences apart, see the module docstring);
    while no candidate repeats any of the expert's episodes it keeps ``current`` (log-likelihood NaN)."""
    if rule not in ("closest", "likelihood"):
        raise ValueError(f"unknown preference rule {rule!r}; choose 'closest' or 'likelihood'")
    q, log_policies = candidate_policies(common, candidates, mdp, config, q_init)
    loglik = log_likelihoods(log_policies, counts)  # [E, K]
    behaviour = greedy_exits(q, mdp)  # [K, 2]
    share = jnp.all(exits[:, :, None, :] == behaviour[None, None], axis=-1).mean(1)  # [E, K]
    top = share >= share.max(1, keepdims=True)
    best = jnp.argmax(jnp.where(top, loglik, -jnp.inf), axis=1)
    if rule == "likelihood":
        return candidates[best], jnp.take_along_axis(loglik, best[:, None], 1)[:, 0], q
    same = jnp.all(behaviour[None, :, :] == behaviour[best][:, None, :], axis=-1)  # [E, K]
    distance = jnp.abs(candidates[None, :, :] - current[:, None, :]).sum(-1)
    best = jnp.argmin(jnp.where(same, distance, jnp.inf), axis=1)
    # no candidate repeats any demonstrated episode yet: the reward cannot tell, so the preference stays
    keep = share.max(1) == 0
    return (jnp.where(keep[:, None], current, candidates[best]),
            jnp.where(keep, jnp.nan, jnp.take_along_axis(loglik, best[:, None], 1)[:, 0]), q)


def make_infer(config: Config, mdp: tabular.TabularMDP, candidates: jax.Array, infer: bool = True,
               rule: str = "closest", warmup: int = 0):
    """A pure ``run(key, expert_occupancy [E, S+1, A], counts [E, S+1, A], exits [E, N, 2], initial [E, d])`` that ``jax.vmap``
    batches over seeds, returning ``(common reward, final preferences, per-round metrics)``.

    Each round is ``admm.make_train``'s (ADMM iterations, then inner RL) with the preference step between
    the two, from round ``warmup + 1`` on (before it, the reward forms under the initial preferences); with
    ``infer=False`` the preferences stay at ``initial`` and the round is exactly Figure 1's."""
    agent = admm.inner_rl(mdp, config)

    def run(key, expert_occupancy, counts, exits, initial):
        E, d = initial.shape
        shape = (E, mdp.num_states, mdp.num_actions, d)
        init_key, key = jax.random.split(key)
        agents = jax.vmap(agent.init)(jax.random.split(init_key, E))
        consensus = admm.ConsensusState(jnp.zeros(shape), jnp.zeros(shape))
        q_candidates = jnp.zeros((candidates.shape[0], mdp.num_states, mdp.num_actions))

        def round_(carry, inputs):
            consensus, agents, preferences, q_candidates = carry
            key, index = inputs
            consensus = admm.reward_step(consensus, agents, agent, preferences, expert_occupancy, mdp, config)
            if infer:
                stepped, best, q_candidates = preference_step(
                    consensus.common, counts, exits, candidates, preferences, mdp, config, q_candidates, rule)
                preferences = jnp.where(index >= warmup, stepped, preferences)
            else:
                best = jnp.zeros(E)
            agents, _, (returns, _, lengths) = admm.policy_step(agents, agent, consensus.common, preferences, mdp, key)
            metrics = {"preferences": preferences, "log_likelihood": best, "vector_return": returns,
                       "length": lengths}
            return (consensus, agents, preferences, q_candidates), metrics

        carry = (consensus, agents, initial, q_candidates)
        (consensus, _, preferences, _), metrics = jax.lax.scan(round_, carry, (jax.random.split(key, config.admm.rounds),
                                                                              jnp.arange(config.admm.rounds)))
        return consensus.common, preferences, metrics

    return run


def candidate_behaviour(common: jax.Array, candidates: jax.Array, mdp: tabular.TabularMDP, config: Config):
    """Greedy true vector return ``[K, d]`` of every candidate's soft-optimal policy on ``common . w``
    (the behaviour each candidate preference induces under the learned reward; evaluation only)."""
    _, log_policies = candidate_policies(common, candidates, mdp, config)
    returns, _ = jax.vmap(lambda lp: tabular.greedy_rollout(lp, mdp))(log_policies)
    return returns


def learned_interval(behaviour: np.ndarray, candidates: np.ndarray, index: int) -> tuple[float, float]:
    """``[lo, hi]`` of the first weight over the run of consecutive grid candidates around ``index`` whose
    greedy behaviour equals candidate ``index``'s (two objectives; candidates ordered by the first weight)."""
    same = np.all(np.isclose(behaviour, behaviour[index], atol=1e-4), axis=-1)
    lo = hi = index
    while lo > 0 and same[lo - 1]:
        lo -= 1
    while hi < len(same) - 1 and same[hi + 1]:
        hi += 1
    w0 = candidates[:, 0]
    return float(min(w0[lo], w0[hi])), float(max(w0[lo], w0[hi]))


class InferenceResult(NamedTuple):
    """One run per seed (leading axis). preferences ``[seeds, E, d]``: inferred; metrics: name ->
    ``[seeds, rounds, E, ...]`` (``preferences`` per round, ``log_likelihood``, the agents' greedy true
    ``vector_return`` and ``length``); learned_interval ``[seeds, E, 2]``: the first weight's interval around
    the inferred point with the same greedy behaviour under the learned reward; behaviour ``[seeds, E, d]``:
    the inferred preference's greedy true return under the learned reward."""

    config: Config
    initial: np.ndarray
    preferences: np.ndarray
    metrics: dict
    common_reward: np.ndarray
    learned_interval: np.ndarray
    behaviour: np.ndarray


def infer_seeds(config: Config, occupancy, counts, exits, initial, keys, resolution: int = 100,
                infer: bool = True, rule: str = "closest", warmup: int = 0) -> InferenceResult:
    """Run the inference loop for every seed in one vmapped program: ``occupancy`` and ``counts``
    ``[seeds, E, S+1, A]`` (``tabular.demo_occupancy`` with ``config.gamma`` and ``demo_counts``), ``exits``
    ``[seeds, E, N, 2]`` (``demo_exits``), ``initial`` ``[seeds, E, d]``, ``keys`` ``[seeds]``."""
    config.validate()
    mdp = tabular.tabular_mdp(envs.make(config.env, absorbing=True))
    initial = jnp.asarray(initial, jnp.float32)
    if initial.ndim != 3 or initial.shape[:2] != np.shape(counts)[:2]:
        raise ValueError(f"initial preferences have shape {initial.shape}, expected [seeds, experts, d] "
                         f"matching counts {np.shape(counts)}")
    candidates = jnp.asarray(simplex_grid(initial.shape[-1], resolution))
    run = jax.jit(jax.vmap(make_infer(config, mdp, candidates, infer, rule, warmup)))
    common, preferences, metrics = run(keys, jnp.asarray(occupancy), jnp.asarray(counts), jnp.asarray(exits), initial)
    behaviour = np.asarray(jax.jit(jax.vmap(lambda r: candidate_behaviour(r, candidates, mdp, config)))(common))
    index = np.argmin(np.abs(np.asarray(preferences)[..., None, :] - np.asarray(candidates)).sum(-1), -1)  # [seeds, E]
    grid = np.asarray(candidates)
    intervals = np.array([[learned_interval(behaviour[s], grid, i) for i in row] for s, row in enumerate(index)])
    return InferenceResult(
        config=config,
        initial=np.asarray(initial),
        preferences=np.asarray(preferences),
        metrics={k: np.asarray(v) for k, v in metrics.items()},
        common_reward=np.asarray(common),
        learned_interval=intervals,
        behaviour=np.take_along_axis(behaviour, index[..., None], 1),
    )


def infer_and_learn(config: Config, demos: Demonstrations, key: jax.Array, initial=None, resolution: int = 100,
                    warmup: int = 0, rule: str = "closest") -> InferenceResult:
    """Infer every expert's preference from ``demos`` (labels, if any, are ignored) jointly with the common
    reward, ``config.admm.rounds`` rounds on ``config.env`` (a discrete DST map). ``initial`` ``[E, d]``: the
    starting preferences (which fix the gauge, see the module docstring); default: ``spread_preferences``
    (see ``inference_inputs``)."""
    env = envs.make(config.env, absorbing=True)
    mdp = tabular.tabular_mdp(env)
    occupancy, counts, exits, spread = evidence.inference_inputs(demos, env, mdp, config)
    initial = spread if initial is None else np.asarray(initial, np.float32)
    if initial.shape != (demos.num_experts, env.reward_dim):
        raise ValueError(f"initial preferences have shape {initial.shape}, expected "
                         f"[{demos.num_experts}, {env.reward_dim}]: one per expert")
    return infer_seeds(config, occupancy[None], counts[None], exits[None], initial[None], key[None], resolution,
                       rule=rule, warmup=warmup)


def train_seeds(config: Config, seeds) -> Result:
    """ADMM for every seed in one program; with ``infer_preferences``, the experts' preferences are inferred
    (``preference_warmup`` rounds under the spread start, then ``rounds`` rounds with the preference step)
    from their demonstrations with the labels dropped. The ``Result``'s preferences are the inferred ones of
    the first seed; ``history`` adds ``preferences`` and ``log_likelihood`` per round; ``extras`` holds
    ``inferred_preferences [seeds, E, d]``, ``initial_preferences``, ``learned_interval [seeds, E, 2]``,
    ``demo_return [E, d]`` (the demonstrations' mean true return) and ``inference`` (the
    ``InferenceResult``, for ``write_run``)."""
    c = config.admm
    if not config.infer_preferences:
        return admm.train_seeds(config, seeds)
    config.validate(sections=ALGORITHM.sections)
    if not config.env.startswith("dst"):
        raise ValueError(f"algo 'admm' is tabular and needs a discrete DST env, got {config.env!r}")
    start = time.perf_counter()
    env = config.make_env(absorbing=True)
    mdp = tabular.tabular_mdp(env)
    demos = load_unlabelled_demonstrations(config, env)
    occupancy, counts, exits, initial = evidence.inference_inputs(demos, env, mdp, config)
    seeds = list(seeds)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    tile = lambda x: np.broadcast_to(np.asarray(x), (len(seeds), *np.shape(x)))
    inference = infer_seeds(config.replace(rounds=c.preference_warmup + c.rounds), tile(occupancy), tile(counts),
                            tile(exits), tile(initial), keys, c.preference_resolution, rule=c.preference_rule,
                            warmup=c.preference_warmup)
    history = dict(inference.metrics)
    history["return"] = np.einsum("sred,sred->sre", history["vector_return"], history["preferences"])
    return Result(
        config=config, preferences=inference.preferences[0], history=history,
        final_params=inference.common_reward, best_params=None, best_return=history["return"].mean(-1).max(-1),
        seconds=time.perf_counter() - start, runs={"seed": np.asarray(seeds)},
        extras={"inferred_preferences": inference.preferences, "initial_preferences": inference.initial,
                "learned_interval": inference.learned_interval, "demo_return": demos.mean_returns(),
                "inference": inference})


ALGORITHM = admm.Tabular(sections=("admm",), train_seeds=train_seeds)



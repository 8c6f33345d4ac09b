"""Discrete multi-objective IRL with consensus ADMM (paper sec. 4.1, Figure 1), vmapped over experts and seeds.

Every expert i keeps a tabular vector reward ``r_i[S + 1, A, d]`` (grid cells plus the absorbing state)
and an ADMM dual ``u_i``. One *round* is

1. ``admm_iterations`` consensus-ADMM iterations (eq. 7 and 3) with the occupancies held fixed:
   ``r_i <- argmax_r  w_i . (E_rhoE_i[r] - E_rho_i[r]) - (rho/2)||r - rbar + u_i||^2 - (lambda/2)||r||^2``
   subject to ``|r| <= reward_bound``, then ``rbar <- mean_i r_i`` and ``u_i <- u_i + r_i - rbar``;
2. inner RL for every expert on the common reward ``rbar`` scalarised by its preference ``w_i``
   (exact soft value iteration, or PPO as in the paper).

The x-update is closed form. Writing ``g_i[s, a, :] = (rhoE_i - rho_i)[s, a] * w_i`` (the gradient of the
linear term), the objective is a separable concave quadratic, stationary at
``r = (g_i + rho * (rbar - u_i)) / (rho + lambda)``; with the box bound each coordinate's maximiser is
that value clipped to ``[-reward_bound, reward_bound]``. With ``lambda = 0`` every round moves the common
reward by ``admm_iterations / rho`` times the mean of the ``g_i`` (projected on the box): consensus
gradient ascent on the multi-expert IRL objective, so the reward accumulates over rounds.

"Optimal" means optimal on the exact undiscounted front (``pareto_front()``); run with ``gamma = 0.999``
so that on DST the discounted optimum agrees with it for every preference (at 0.99 it does not for
some preferences near [0.6, 0.4]). Agents are evaluated greedily (argmax of their policy) on the true
reward, exactly from the tables.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from moiq_jax.algos import tabular
from moiq_jax.algos.inner_rl import InnerRL, inner_rl, soft_vi_agent  # noqa: F401 (also admm's public names)
from moiq_jax.config import Config
from moiq_jax.evaluate import pearson
from moiq_jax.experts import dst_oracle
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.preferences import check_preferences, preference_sweep
from moiq_jax.result import Result


def x_update(gain: jax.Array, common: jax.Array, dual: jax.Array, rho: jax.Array, reward_l2: float,
             reward_bound: float) -> jax.Array:
    """Closed-form maximiser of ``sum(gain * r) - sum((rho/2) (r - common + dual)^2) - (reward_l2/2)||r||^2``
    over the box ``|r| <= reward_bound`` (eq. 7 with a regulariser and a bound). ``rho`` is a scalar or
    a per-entry penalty (a diagonal metric) broadcasting against ``r``."""
    return jnp.clip((gain + rho * (common - dual)) / (rho + reward_l2), -reward_bound, reward_bound)


@struct.dataclass
class ConsensusState:
    """Per-expert reward tables ``rewards[E, S + 1, A, d]`` and duals ``duals[E, S + 1, A, d]``."""

    rewards: jax.Array
    duals: jax.Array

    @property
    def common(self) -> jax.Array:
        return self.rewards.mean(0)


def reward_gains(preferences: jax.Array, expert_occupancy: jax.Array, policy_occupancy: jax.Array) -> jax.Array:
    """``g_i = (rhoE_i - rho_i) w_i``, shape ``[E, S + 1, A, d]``: the linear term of each expert's x-update."""
    return (expert_occupancy - policy_occupancy)[..., None] * preferences[:, None, None, :]


def consensus_admm(state: ConsensusState, gains: jax.Array, metric: jax.Array, config: Config) -> ConsensusState:
    """``admm_iterations`` iterations of eq. 7 / eq. 3, the x-update vmapped over experts.

    The proximal term uses the penalty ``rho * metric[S + 1, A, 1]`` per entry (the same for all experts,
    so the consensus is still the plain mean); ``metric = 1`` is the paper's ``rho``."""
    update = jax.vmap(x_update, in_axes=(0, None, 0, None, None, None))
    c = config.admm
    rho = c.rho * metric

    def iteration(state, _):
        rewards = update(gains, state.common, state.duals, rho, c.reward_l2, c.reward_bound)
        common = rewards.mean(0)
        return ConsensusState(rewards, state.duals + rewards - common), None

    state, _ = jax.lax.scan(iteration, state, None, length=c.admm_iterations)
    return state


def penalty_metric(expert_occupancy: jax.Array, policy_occupancy: jax.Array, config: Config):
    """The per-entry scale ``[S + 1, A, 1]`` of the ADMM penalty: one plus the mean visit count of expert and
    policy occupancies when ``visit_metric`` (without it the absorbing state, visited ~90 times, moves ~90x
    faster than a path step), else 1."""
    if not config.admm.visit_metric:
        return 1.0
    return 1.0 + (expert_occupancy + policy_occupancy).mean(0)[..., None]


def evaluate_policies(policies, preferences, mdp: tabular.TabularMDP):
    """Greedy undiscounted true return ``[E, d]``, its scalarisation ``[E]`` and episode length ``[E]``."""
    returns, lengths = jax.vmap(lambda p: tabular.greedy_rollout(p, mdp))(policies)
    return returns, (returns * preferences).sum(-1), lengths


def reward_step(consensus: ConsensusState, agents, agent: InnerRL, preferences, expert_occupancy,
                mdp: tabular.TabularMDP, config: Config) -> ConsensusState:
    """A round's reward half: the ADMM iterations against the occupancies of the agents' current policies."""
    policies = jax.vmap(agent.policy)(agents)
    policy_occupancy = jax.vmap(lambda p: tabular.occupancy(p, mdp, config.gamma))(policies)
    gains = reward_gains(preferences, expert_occupancy, policy_occupancy)
    return consensus_admm(consensus, gains, penalty_metric(expert_occupancy, policy_occupancy, config), config)


def policy_step(agents, agent: InnerRL, common: jax.Array, preferences, mdp: tabular.TabularMDP, key):
    """A round's policy half: every expert's inner RL on ``common . w_i``. Returns the agents, the scalar
    rewards ``[E, S + 1, A]`` and ``evaluate_policies`` of the improved agents."""
    scalar = jnp.einsum("sad,ed->esa", common, preferences)
    agents = jax.vmap(agent.improve)(agents, scalar, jax.random.split(key, preferences.shape[0]))
    return agents, scalar, evaluate_policies(jax.vmap(agent.policy)(agents), preferences, mdp)


def make_train(config: Config, mdp: tabular.TabularMDP, preferences: jax.Array):
    """A pure ``train(key, expert_occupancy[E, S + 1, A]) -> (final common reward, per-round metrics)``
    that ``jax.vmap`` can batch over seeds."""
    agent = inner_rl(mdp, config)
    E = preferences.shape[0]
    shape = (E, mdp.num_states, mdp.num_actions, preferences.shape[1])

    def train(key, expert_occupancy):
        visited = expert_occupancy.sum(0) > 0  # state-actions the demonstrations visit
        true_scalar = jnp.einsum("sad,ed->esa", mdp.true_reward, preferences)
        init_key, key = jax.random.split(key)
        agents = jax.vmap(agent.init)(jax.random.split(init_key, E))
        consensus = ConsensusState(jnp.zeros(shape), jnp.zeros(shape))

        def round_(carry, key):
            consensus, agents = carry
            consensus = reward_step(consensus, agents, agent, preferences, expert_occupancy, mdp, config)
            agents, scalar, (returns, scalarised, lengths) = policy_step(agents, agent, consensus.common, preferences,
                                                                         mdp, key)
            metrics = {
                "return": scalarised,
                "vector_return": returns,
                "length": lengths,
                "treasure": returns[:, 0],
                "reward_correlation": jax.vmap(pearson, in_axes=(0, 0, None))(scalar, true_scalar, visited),
                "consensus_gap": jnp.abs(consensus.rewards - consensus.common).max(),
            }
            return (consensus, agents), metrics

        (consensus, _), metrics = jax.lax.scan(round_, (consensus, agents), jax.random.split(key, config.admm.rounds))
        return consensus.common, metrics

    return train


def transfer(common_reward: jax.Array, mdp: tabular.TabularMDP, preferences: jax.Array, config: Config):
    """Solve the common reward scalarised by each preference exactly (soft VI, greedy policy):
    greedy true vector returns ``[P, d]``, scalarised returns ``[P]`` and lengths ``[P]``."""

    def solve(w):
        q = tabular.soft_value_iteration(common_reward @ w, mdp, config.gamma, config.admm.temperature)
        return jax.nn.softmax(q / config.admm.temperature, axis=-1)

    return evaluate_policies(jax.vmap(solve)(preferences), preferences, mdp)


def train_seeds(config: Config, seeds) -> Result:
    """Run ``config`` for every seed in one vmapped program (a ``Result`` with a run axis; ``extras``:
    ``optimal_return [E]``, the best scalarised undiscounted return per expert preference, and
    ``transfer``: the 19 sweep preferences' greedy results on the final common reward and their optimal
    returns). Each seed records its own ``num_demos`` oracle demonstrations per expert (or all use
    ``config.demos``)."""
    config.validate(sections=ALGORITHM.sections)
    if not config.env.startswith("dst"):
        raise ValueError(f"algo 'admm' is tabular and needs a discrete DST env, got {config.env!r}")
    start = time.perf_counter()
    env = config.make_env(absorbing=True)
    sea_map = env.unwrapped.sea_map
    mdp = tabular.tabular_mdp(env)
    preferences = check_preferences(config.preferences, env.reward_dim)
    seeds = list(seeds)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds))
    if config.demos is not None:
        demos = load_demonstrations(config, env)
        occupancy = jnp.broadcast_to(tabular.demo_occupancy(demos, mdp, sea_map.cols, config.gamma),
                                     (len(seeds), len(preferences), mdp.num_states, mdp.num_actions))
    else:
        # one recording call for all seeds: seed k gets episodes [k * num_demos, (k + 1) * num_demos)
        demos = dst_oracle.record_demonstrations(config.env, preferences, config.num_demos * len(seeds),
                                                 jax.random.fold_in(keys[0], 1))
        per_seed = jax.tree_util.tree_map(
            lambda x: jnp.swapaxes(x.reshape(x.shape[0], len(seeds), config.num_demos, *x.shape[2:]), 0, 1),
            {name: getattr(demos, name) for name in ("obs", "actions", "dones", "lengths")},
        )
        occupancy = jax.vmap(lambda d: tabular.demo_occupancy(_Demos(**d), mdp, sea_map.cols, config.gamma))(per_seed)

    run = jax.jit(jax.vmap(make_train(config, mdp, jnp.asarray(preferences))))
    common, metrics = run(keys, occupancy)
    sweep = jnp.asarray(preference_sweep(19))
    returns, scalarised, lengths = jax.jit(jax.vmap(lambda r: transfer(r, mdp, sweep, config)))(common)
    metrics = {k: np.asarray(v) for k, v in metrics.items()}
    return Result(
        config=config, preferences=preferences, history=metrics, final_params=np.asarray(common), best_params=None,
        best_return=metrics["return"].mean(-1).max(-1), seconds=time.perf_counter() - start,
        runs={"seed": np.asarray(seeds)},
        extras={
            "optimal_return": np.array([dst_oracle.optimal_value(sea_map, w) for w in preferences]),
            "transfer": {
                "preferences": np.asarray(sweep),
                "vector_return": np.asarray(returns),
                "return": np.asarray(scalarised),
                "length": np.asarray(lengths),
                "optimal_return": np.array([dst_oracle.optimal_value(sea_map, w) for w in np.asarray(sweep)]),
            },
        },
    )


class _Demos(NamedTuple):
    """The fields of a Demonstrations that ``demo_occupancy`` reads (for per-seed slices inside vmap)."""

    obs: jax.Array
    actions: jax.Array
    dones: jax.Array
    lengths: jax.Array


def train(config: Config) -> Result:
    """``train_seeds(config, [config.seed])``: arrays keep a seed axis of length 1 (``moiq_jax.train`` drops it)."""
    return train_seeds(config, [config.seed])


class Tabular(NamedTuple):
    """A tabular algorithm of the registry: the Config sections it reads and ``train_seeds``."""

    sections: tuple[str, ...]
    train_seeds: callable


ALGORITHM = Tabular(sections=("admm",), train_seeds=train_seeds)

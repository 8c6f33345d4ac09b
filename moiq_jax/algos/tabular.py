"""Exact tabular tools for discrete DST with an absorbing state: the MDP tables, soft value iteration,
occupancy measures (of policies and of demonstrations) and greedy evaluation.

States are the grid cells ``s = row * cols + col`` plus one absorbing state ``S = rows * cols``
(paper sec. 4.1.1): a treasure cell is never occupied, entering it moves to the absorbing state, which
loops to itself with zero true reward. Episodes therefore all last ``horizon`` steps (the time limit),
which makes occupancy measures well defined. Occupancies here are *expected discounted visit counts*
over that horizon, ``sum_{t < H} gamma^t P(s_t = s, a_t = a)``, for demonstrations and policies alike,
so ``E_occupancy[r]`` is the expected discounted return of ``r`` over one episode.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


class InnerRL(NamedTuple):
    """An RL solver for one expert on a tabular scalar reward, all functions pure (vmapped by the caller).

    init(key) -> agent; improve(agent, reward[S + 1, A], key) -> agent; policy(agent) -> probs[S + 1, A].
    """

    init: Callable
    improve: Callable
    policy: Callable


@struct.dataclass
class TabularMDP:
    """DST as tables over ``S + 1`` states (cells plus the absorbing state) and 4 actions."""

    next_state: jax.Array  # [S + 1, A] int32, deterministic
    true_reward: jax.Array  # [S + 1, A, d] the env's vector reward (zero in the absorbing state)
    start: int = struct.field(pytree_node=False, default=0)
    horizon: int = struct.field(pytree_node=False, default=100)

    @property
    def num_states(self) -> int:
        return self.next_state.shape[0]

    @property
    def num_actions(self) -> int:
        return self.next_state.shape[1]

    @property
    def absorbing(self) -> int:
        return self.num_states - 1


def tabular_mdp(env) -> TabularMDP:
    """The tables of a (time-limited) discrete DST env, with terminal cells sent to the absorbing state."""
    next_state, reward, terminal = env.unwrapped.tabular()
    S, A = next_state.shape
    absorbing = S
    next_state = np.where(terminal[next_state], absorbing, next_state)
    next_state = np.concatenate([next_state, np.full((1, A), absorbing)]).astype(np.int32)
    reward = np.concatenate([reward, np.zeros((1, A, reward.shape[-1]), np.float32)])
    return TabularMDP(jnp.asarray(next_state), jnp.asarray(reward), start=0, horizon=env.episode_length)


def state_index(obs: jax.Array, mdp: TabularMDP, cols: int) -> jax.Array:
    """Tabular state of observations ``(row, col[, absorbed flag])`` (last axis)."""
    cell = obs[..., 0].astype(jnp.int32) * cols + obs[..., 1].astype(jnp.int32)
    if obs.shape[-1] == 3:
        cell = jnp.where(obs[..., 2] > 0.5, mdp.absorbing, cell)
    return cell


def soft_value_iteration(reward: jax.Array, mdp: TabularMDP, gamma: float, temperature: float,
                         q_init: jax.Array | None = None, tolerance: float = 1e-4,
                         max_iterations: int = 20_000) -> jax.Array:
    """Soft-optimal ``Q[S + 1, A]`` for a scalar reward table: iterate
    ``Q = r + gamma * V(next)``, ``V = temperature * logsumexp(Q / temperature)`` until the largest change
    is below ``tolerance`` (jit- and vmap-safe; ``q_init`` warm-starts it)."""
    q_init = jnp.zeros_like(reward) if q_init is None else q_init

    def backup(q):
        value = temperature * jax.nn.logsumexp(q / temperature, axis=-1)
        return reward + gamma * value[mdp.next_state]

    def cond(carry):
        _, change, i = carry
        return (change > tolerance) & (i < max_iterations)

    def body(carry):
        q, _, i = carry
        new = backup(q)
        return new, jnp.max(jnp.abs(new - q)), i + 1

    q, _, _ = jax.lax.while_loop(cond, body, (q_init, jnp.array(jnp.inf, reward.dtype), 0))
    return q


def occupancy(policy: jax.Array, mdp: TabularMDP, gamma: float) -> jax.Array:
    """Exact expected discounted visit counts ``[S + 1, A]`` of a stationary ``policy[S + 1, A]`` over
    one episode of ``mdp.horizon`` steps from the start state."""

    def step(dist, discount):
        visits = dist[:, None] * policy
        nxt = jnp.zeros_like(dist).at[mdp.next_state.reshape(-1)].add(visits.reshape(-1))
        return nxt, discount * visits

    start = jnp.zeros((mdp.num_states,), policy.dtype).at[mdp.start].set(1.0)
    _, visits = jax.lax.scan(step, start, gamma ** jnp.arange(mdp.horizon, dtype=policy.dtype))
    return visits.sum(0)


def demo_occupancy(demos, mdp: TabularMDP, cols: int, gamma: float) -> jax.Array:
    """Empirical expected discounted visit counts ``[E, S + 1, A]`` of each expert's demonstrations.

    Demos recorded without the absorbing state (episodes end at the treasure) are completed to the
    horizon in the absorbing state with uniform actions, as ``record_demonstrations`` does for demos
    recorded with it.
    """
    obs = jnp.asarray(demos.obs)
    N, T = obs.shape[1:3]
    steps = jnp.arange(mdp.horizon)
    real = steps[None, None, :] < jnp.asarray(demos.lengths)[:, :, None]  # [E, N, H]
    pad = ((0, 0), (0, 0), (0, mdp.horizon - T))
    states = jnp.pad(state_index(obs, mdp, cols), pad)
    actions = jnp.pad(jnp.asarray(demos.actions), pad)
    terminated = jnp.asarray(demos.dones).any(axis=2)  # [E, N]
    absorbed = ~real & terminated[:, :, None]
    discount = gamma ** steps.astype(jnp.float32)
    one_hot = jax.nn.one_hot(states, mdp.num_states)[..., None] * jax.nn.one_hot(actions, mdp.num_actions)[..., None, :]
    absorbing = jnp.zeros((mdp.num_states, mdp.num_actions)).at[mdp.absorbing].set(1.0 / mdp.num_actions)
    visits = real[..., None, None] * one_hot + absorbed[..., None, None] * absorbing
    return jnp.einsum("enhsa,h->esa", visits, discount) / N


def greedy_rollout(policy: jax.Array, mdp: TabularMDP) -> tuple[jax.Array, jax.Array]:
    """Follow ``argmax policy`` for one episode: ``(undiscounted true vector return [d], episode length)``,
    the length counting steps until the absorbing state is entered (the horizon if it never is)."""
    actions = jnp.argmax(policy, axis=-1)

    def step(state, _):
        action = actions[state]
        return mdp.next_state[state, action], (mdp.true_reward[state, action], state != mdp.absorbing)

    _, (rewards, live) = jax.lax.scan(step, mdp.start, None, length=mdp.horizon)
    return rewards.sum(0), live.sum()

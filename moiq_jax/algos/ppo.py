"""PPO for the inner RL of the consensus-ADMM rounds (the paper's choice), on a tabular reward.

The agent is a small flax actor-critic on one-hot states. Episodes are sampled from the exact tabular
dynamics (``TabularMDP``, the same transitions as the env's ``step`` with the absorbing state), each running
the full time limit; the reward is the learned scalarised table. All functions are pure, so the caller
vmaps them over experts and seeds.

PPO here solves the same max-ent RL problem as soft value iteration (the inner problem of max-ent IRL,
paper eq. 5): the rollout reward is the *soft* reward ``r(s, a) - temperature * log pi(a|s)``, so the
fixed point is ``pi ~ exp(Q_soft / temperature)``. An entropy bonus in the loss instead (scaled against
normalised advantages) lets PPO turn near-deterministic on the first, still meaningless rewards: it then
loops forever on the cells the experts visited, the IRL step answers with a large absorbing-state reward,
and the rounds lock into "end the episode as soon as possible" (all agents at the nearest treasure).
"""

from __future__ import annotations

from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

from moiq_jax.algos.tabular import InnerRL, TabularMDP
from moiq_jax.config import Config


class ActorCritic(nn.Module):
    """Action logits and state value from a one-hot state, from two separate tanh MLPs.

    Separate trunks keep the value regression from overwriting the policy's features (with one shared
    trunk the value loss's gradient was ~2000x the policy loss's and dominated every update)."""

    num_actions: int
    hidden: int

    @nn.compact
    def __call__(self, state_one_hot):
        def trunk(x):
            return nn.tanh(nn.Dense(self.hidden)(nn.tanh(nn.Dense(self.hidden)(x))))

        logits = nn.Dense(self.num_actions, kernel_init=nn.initializers.orthogonal(0.01))(trunk(state_one_hot))
        return logits, nn.Dense(1)(trunk(state_one_hot))[..., 0]


def value_scale(mdp: TabularMDP, config: Config) -> float:
    """A bound on the soft return: ``(reward_bound + temperature * log A) * sum_{t < H} gamma^t``.

    The critic predicts values in these units, so its targets are O(1) whatever the learned reward's scale
    (raw returns reach hundreds, and their gradients would swamp the policy's under the global-norm clip)."""
    horizon = sum(config.gamma**t for t in range(mdp.horizon))
    return (config.admm.reward_bound + config.admm.temperature * float(jnp.log(mdp.num_actions))) * horizon


class PPOAgent(NamedTuple):
    params: dict
    opt_state: optax.OptState


class Batch(NamedTuple):
    states: jax.Array
    actions: jax.Array
    log_probs: jax.Array
    advantages: jax.Array
    returns: jax.Array


def ppo_agent(mdp: TabularMDP, config: Config) -> InnerRL:
    """An ``InnerRL`` running ``ppo_iterations`` PPO updates per round, warm-started across rounds."""
    ppo, temperature = config.admm.ppo, config.admm.temperature
    net = ActorCritic(mdp.num_actions, ppo.hidden)
    optimiser = optax.chain(optax.clip_by_global_norm(0.5), optax.adam(ppo.learning_rate))
    one_hot = jnp.eye(mdp.num_states)
    batch_size = ppo.num_envs * mdp.horizon
    minibatch = batch_size // ppo.minibatches
    scale = value_scale(mdp, config)

    def tables(params):
        """Log-probabilities ``[S + 1, A]`` and values ``[S + 1]`` of every state: the net sees one-hot
        states, so one pass over all ``S + 1`` of them, gathered per sample, is exact and far cheaper than a
        pass per sample."""
        logits, value = net.apply(params, one_hot)
        return jax.nn.log_softmax(logits), value * scale

    def init(key):
        params = net.init(key, one_hot[0])
        return PPOAgent(params, optimiser.init(params))

    def policy(agent):
        return jnp.exp(tables(agent.params)[0])

    def rollout(params, reward, key):
        """``ppo_num_envs`` episodes from the start state with the soft reward; GAE advantages with
        bootstrap at the time limit."""
        log_pi, value = tables(params)

        def step(states, key):
            actions = jax.random.categorical(key, log_pi[states])
            log_probs, values = log_pi[states, actions], value[states]
            soft_reward = reward[states, actions] - temperature * log_probs
            return mdp.next_state[states, actions], (states, actions, log_probs, values, soft_reward)

        start = jnp.full((ppo.num_envs,), mdp.start)
        last, (states, actions, log_probs, values, rewards) = jax.lax.scan(
            step, start, jax.random.split(key, mdp.horizon)
        )
        last_value = value[last]

        def gae(carry, xs):
            advantage, next_value = carry
            value, r = xs
            delta = r + config.gamma * next_value - value
            advantage = delta + config.gamma * ppo.gae_lambda * advantage
            return (advantage, value), advantage

        _, advantages = jax.lax.scan(gae, (jnp.zeros_like(last_value), last_value), (values, rewards), reverse=True)
        flat = lambda x: x.reshape(batch_size)
        return Batch(flat(states), flat(actions), flat(log_probs), flat(advantages), flat(advantages + values))

    def loss(params, batch):
        log_pi, value = tables(params)
        log_probs, values = log_pi[batch.states, batch.actions], value[batch.states]
        ratio = jnp.exp(log_probs - batch.log_probs)
        adv = (batch.advantages - batch.advantages.mean()) / (batch.advantages.std() + 1e-8)
        clipped = jnp.clip(ratio, 1 - ppo.clip, 1 + ppo.clip)
        policy_loss = -jnp.minimum(ratio * adv, clipped * adv).mean()
        value_loss = 0.5 * (((values - batch.returns) / scale) ** 2).mean()
        return policy_loss + 0.5 * value_loss

    def update(agent, key, reward):
        rollout_key, shuffle_key = jax.random.split(key)
        batch = rollout(agent.params, reward, rollout_key)

        def epoch(agent, key):
            order = jax.random.permutation(key, batch_size).reshape(ppo.minibatches, minibatch)

            def minibatch_step(agent, idx):
                grads = jax.grad(loss)(agent.params, jax.tree_util.tree_map(lambda x: x[idx], batch))
                updates, opt_state = optimiser.update(grads, agent.opt_state, agent.params)
                return PPOAgent(optax.apply_updates(agent.params, updates), opt_state), None

            return jax.lax.scan(minibatch_step, agent, order)[0], None

        return jax.lax.scan(epoch, agent, jax.random.split(shuffle_key, ppo.epochs))[0], None

    def improve(agent, reward, key):
        return jax.lax.scan(lambda a, k: update(a, k, reward), agent, jax.random.split(key, ppo.iterations))[0]

    if batch_size % ppo.minibatches:
        raise ValueError(f"ppo_num_envs * horizon = {batch_size} must be divisible by ppo_minibatches")
    return InnerRL(init=init, improve=improve, policy=policy)

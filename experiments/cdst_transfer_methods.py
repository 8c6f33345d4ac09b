"""Four ways to act at the 19 transfer preferences w with one trained MOIQ model on cdst, against the exact
front: the actor's own policy pi(. | s, w) (the paper's), and three that use the learned reward instead.

- GPI (generalised policy improvement over the experts' policies): act with the candidate action (the
  actor's at each expert preference w_j) whose ``max_j min_k w . Q_k(s, a, w_j)`` is highest.
- Selection by the consensus reward: roll out the actor at every transfer and expert preference, score each
  trajectory by the discounted sum of the consensus reward (the experts' mean recovered vector reward), and
  act at w as the rollout with the highest ``w . score``; and the same among the rollouts at the experts'
  preferences alone (the experts' behaviours: with a reward that ranks them right this gets the most that
  imitating them can, 16 of 19).

Each would give, for every w, the best behaviour on offer if the experts' recovered rewards were one common
reward equal (up to scale) to the true one; on cdst that is the Pareto-optimal return for the 16 of the 19
preferences whose optimum some expert showed. They measure how far the learned reward is from that.

    PYTHONPATH=. python experiments/cdst_transfer_methods.py [--seeds 5] [--beta B] [--save PICKLE | --reuse PICKLE]

Trains ``tuned("cdst")`` (at ``--beta`` if given; 100K env steps per expert) for the seeds as one sweep,
then prints per seed the Pareto-optimal counts of the four and every preference's vector returns.
"""

from __future__ import annotations

import argparse
import pathlib
import pickle
import time

import common
import jax
import jax.numpy as jnp
import numpy as np

import moiq_jax
from moiq_jax.algos.moiq import recovered_rewards
from moiq_jax.evaluate import episode_returns
from moiq_jax.networks import deterministic_action, networks_for


def gpi_action(nets, params, obs, preference, expert_preferences):
    """The GPI action at one observation: of the experts' policies' actions, the one with the highest
    ``max_j min_k preference . Q_k(obs, a, w_j)``."""
    means, _ = jax.vmap(lambda w: nets.actor.apply(params.actor, obs[None], w[None]))(expert_preferences)
    candidates = deterministic_action(means[:, 0], nets.action_scale)  # (E, action)

    def score(action):
        q = jax.vmap(lambda w: nets.critic.apply(params.critic, obs[None], action[None], w[None])[:, 0])(
            expert_preferences)  # (E, 2, d)
        return jnp.max(jnp.min(q @ preference, axis=1))

    return candidates[jnp.argmax(jax.vmap(score)(candidates))]


def gpi_returns(params, env, preferences, expert_preferences) -> np.ndarray:
    """Vector returns ``[P, d]`` of one deterministic episode of the GPI policy per preference."""
    nets = networks_for(params)

    def one(preference):
        policy = lambda _, obs: gpi_action(nets, params, obs, preference, expert_preferences)
        return episode_returns(env, policy, jax.random.PRNGKey(0), 1)["returns"][0]

    return np.asarray(jax.jit(jax.vmap(one))(jnp.asarray(preferences, jnp.float32)))


def selected_by_consensus(params, env, preferences, expert_preferences, gamma, experts_only=False) -> np.ndarray:
    """True vector returns ``[P, d]`` of the rollout, among the actor's at ``preferences`` and the experts'
    (or at the experts' alone), whose discounted consensus-reward return scalarised by each preference is highest."""
    nets = networks_for(params)
    alpha = jnp.mean(jnp.exp(params.log_alpha))  # cdst's tuned temperature is fixed and shared
    family = expert_preferences if experts_only else jnp.concatenate([jnp.asarray(preferences, jnp.float32),
                                                                      expert_preferences])

    def rollout(w):
        def step(state, _):
            action = nets.act(params.actor, state.obs[None], w)[0]
            nxt = env.step(state, action)
            return nxt, (state.obs, action, nxt.obs, nxt.done.astype(jnp.float32), nxt.reward)

        _, (obs, action, next_obs, done, reward) = jax.lax.scan(step, env.reset(jax.random.PRNGKey(0)), None,
                                                                length=env.episode_length)
        batch = {"obs": obs, "action": action, "next_obs": next_obs, "done": done}
        rewards = jax.vmap(lambda wj, k: recovered_rewards(nets, params.critic, params, alpha, batch, wj, k, gamma,
                                                           False)[0].mean(0))(
            expert_preferences, jax.random.split(jax.random.PRNGKey(1), expert_preferences.shape[0]))  # (E, T, d)
        discounts = gamma ** jnp.arange(obs.shape[0])
        return jnp.einsum("etd,t->d", rewards, discounts) / expert_preferences.shape[0], reward.sum(0)

    scores, returns = jax.jit(jax.vmap(rollout))(family)
    return np.asarray(returns)[np.argmax(np.asarray(preferences) @ np.asarray(scores).T, axis=1)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--beta", type=float, default=None, help="consensus weight (default: the tuned cdst one)")
    parser.add_argument("--reuse", metavar="PICKLE", help="load the trained sweep from this file instead of training")
    parser.add_argument("--save", metavar="PICKLE", help="save the trained sweep's best parameters to this file")
    args = parser.parse_args()
    common.start(args.seeds)  # one CPU device per run
    cdst = common.CdstSetup() if args.beta is None else common.CdstSetup(beta=args.beta)
    config, demos = cdst.config, cdst.demos
    if args.reuse:
        best_params = pickle.loads(pathlib.Path(args.reuse).read_bytes())
    else:
        start = time.perf_counter()
        best_params = jax.device_get(moiq_jax.sweep(config, seed=range(args.seeds), demos=demos).best_params)
        print(f"trained {args.seeds} seeds in {time.perf_counter() - start:.0f} s")
    if args.save:
        pathlib.Path(args.save).write_bytes(pickle.dumps(best_params))

    env = moiq_jax.envs.make("cdst", absorbing=True)
    preferences = common.TRANSFER_PREFERENCES
    optimal = common.transfer_optima()
    expert_preferences = jnp.asarray(demos.preferences, jnp.float32)
    print(f"beta {config.moiq.beta:g}; columns: preference, return of the actor, of GPI, of selection by consensus reward "
          "among all rollouts and among the experts' behaviours; Pareto-optimal return")
    for seed in range(args.seeds):
        params = common.run_index(best_params, seed)
        direct = moiq_jax.evaluate(params, env, preferences)
        gpi = gpi_returns(params, env, preferences, expert_preferences)
        selected = selected_by_consensus(params, env, preferences, expert_preferences, config.gamma)
        among_experts = selected_by_consensus(params, env, preferences, expert_preferences, config.gamma, True)
        hits = [int(np.all(np.isclose(x, optimal, atol=1e-3), axis=1).sum())
                for x in (direct, gpi, selected, among_experts)]
        print(f"seed {seed}: Pareto-optimal of 19: actor {hits[0]}, GPI {hits[1]}, selected by consensus reward "
              f"{hits[2]}, among the experts' behaviours {hits[3]}")
        for row in zip(preferences, direct, gpi, selected, among_experts, optimal):
            print("  " + " ".join(str(np.round(x, 2)) for x in row))


if __name__ == "__main__":
    main()

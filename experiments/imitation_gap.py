"""Where MOIQ's best model falls short of an expert, why: does its recovered reward rank the expert's
demonstrations above the model's own episodes (then the reward is right and the policy fails to follow it), does
the policy act like the expert on the expert's own states, and how soon do its episodes leave the states the
demonstrations visit?

    PYTHONPATH=. python experiments/imitation_gap.py [--envs ...] [--seeds 3] [--betas 0.5]
        [--protocol cpu_recipe_online_penalty] [--episodes 20] [--no-train] [--out DIR]

Per task, kept run (``--betas`` x seeds, as table1.py reads them) and expert preference w, at the run's best
model, over ``--episodes`` of its own episodes at w (``moiq_jax.policy_episodes``, seed 0):

- ``ratio``: the episodes' mean scalarised true return over the expert's (the demonstrations' mean);
- ``live_steps``: the episodes' mean length before termination (steps after it are the absorbing state's);
- ``recovered_demos`` / ``recovered_own``: the mean scalarised recovered return (the critic loss's reward, to the
  time limit, the absorbing state included) of the expert's demonstrations and of the model's own episodes;
- ``action_gap``: on the demonstrations' states, the mean |policy action - expert action| over the mean
  |expert action|;
- ``on_demo_share``: the share of the episodes' live steps within the demonstrations' spread: a state is within
  it when its distance (each coordinate standardised by the demonstrations' spread) to the nearest
  demonstration state is at most the 95th percentile of the demonstration states' distances to the nearest
  state of another demonstration (so 0.95 for the demonstrations themselves).

Writes ``imitation_gap.csv`` / ``.json`` (default ``results/mujoco_<protocol>/imitation_gap``)."""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np
import paper_mujoco as paper

import moiq_jax
from moiq_jax.algos import moiq
from moiq_jax.algos.offpolicy import expert_transitions
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.networks import networks_of_config

WITHIN_QUANTILE = 0.95  # a state is within the demonstrations' spread up to this quantile of their own distances


def nearest_distances(points: np.ndarray, reference: np.ndarray, groups: np.ndarray | None = None,
                      point_groups: np.ndarray | None = None, chunk: int = 2048) -> np.ndarray:
    """Euclidean distance from each of ``points`` [n, D] to its nearest row of ``reference`` [m, D], leaving out
    the reference rows of the point's own group where ``groups`` [m] and ``point_groups`` [n] are given."""
    ref_sq = (reference**2).sum(1)
    out = np.empty(len(points))
    for start in range(0, len(points), chunk):
        block = points[start:start + chunk]
        squared = (block**2).sum(1)[:, None] + ref_sq[None] - 2.0 * block @ reference.T
        if groups is not None:
            squared[point_groups[start:start + chunk, None] == groups[None]] = np.inf
        out[start:start + chunk] = np.sqrt(np.maximum(squared.min(1), 0.0))
    return out


def demo_spread(demo_obs: np.ndarray):
    """``(within(states [n, D]) -> bool [n])``: whether states lie within the spread of one expert's
    demonstrations ``demo_obs`` [episodes, T, D] (live steps only; see the module's docstring)."""
    episodes, steps, _ = demo_obs.shape
    live = demo_obs[..., -1] == 0  # the absorbing flag
    live_states = demo_obs[live]
    scale = np.maximum(live_states[:, :-1].std(0), 1e-6)
    standard = lambda x: x[:, :-1] / scale
    reference = standard(live_states.astype(np.float64))
    groups = np.broadcast_to(np.arange(episodes)[:, None], (episodes, steps))[live]
    threshold = np.quantile(nearest_distances(reference, reference, groups, groups), WITHIN_QUANTILE)
    return lambda states: nearest_distances(standard(states.astype(np.float64)), reference) <= threshold


def run_gaps(run, episodes: int, demos: dict, spreads: list) -> list[dict]:
    """The measures of the module's docstring for one kept run's best model, one dict per preference, against its
    task's demonstrations ``demos`` (``expert_transitions``) and their ``spreads`` (``demo_spread``, per expert)."""
    config = run.config
    params = run.best_params
    nets = networks_of_config(config.offpolicy, config.make_env(absorbing=True))
    prefs = np.asarray(config.preferences, np.float32)
    demo_rewards = moiq.recovered_reward_fn(config, nets)(params, {k: jnp.asarray(v) for k, v in demos.items()},
                                                           jnp.asarray(prefs), jax.random.PRNGKey(0))
    own = moiq_jax.policy_episodes(params, config, episodes)
    rows = []
    for e, (w, within) in enumerate(zip(prefs, spreads)):
        expert_return = float(demos["true_reward"][e].sum(0) @ w) / config.num_demos
        own_return = float(own["reward"][e].sum(1).mean(0) @ w)
        obs = own["obs"][e]  # [N, T, D]
        live = obs[..., -1] == 0
        expert_actions = jnp.asarray(demos["action"][e])
        actions = nets.act(params.actor, jnp.asarray(demos["obs"][e]), jnp.asarray(w))
        rows.append({
            "ratio": round(own_return / expert_return, 3),
            "own_return": round(own_return, 1),
            "expert_return": round(expert_return, 1),
            "live_steps": round(float(live.sum(1).mean()), 1),
            "recovered_demos": round(float(np.asarray(demo_rewards[e]).sum(0) @ w) / config.num_demos, 1),
            "recovered_own": round(float(own["recovered_reward"][e].sum(1).mean(0) @ w), 1),
            "action_gap": round(float(jnp.abs(actions - expert_actions).mean() / jnp.abs(expert_actions).mean()), 3),
            "on_demo_share": round(float(within(obs[live]).mean()), 3),
        })
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    parser.add_argument("--betas", type=float, nargs="+", default=[0.5], help="the runs' consensus weights")
    parser.add_argument("--episodes", type=int, default=20, help="the best model's own episodes per preference")
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/imitation_gap")
    args = parser.parse_args()
    out = paper.out_dir(args, "imitation_gap")
    episodes = 3 if args.quick else args.episodes

    rows = []
    for env in args.envs:
        result = paper.task_sweep(env, args, betas=tuple(args.betas))
        config = result.config  # every run's demonstrations are the task's: loaded, and their spreads found, once
        demos = expert_transitions(load_demonstrations(config, config.make_env(absorbing=True)))  # [E, M, ...]
        spreads = [demo_spread(obs.reshape(config.num_demos, -1, obs.shape[-1])) for obs in demos["obs"]]
        for beta in args.betas:
            for r in paper.runs_of(result, beta):
                run = result.run(r)
                for w, row in zip(config.preferences, run_gaps(run, episodes, demos, spreads)):
                    rows.append({"env": env, "preference": list(w), "beta": beta, "seed": int(run.config.seed), **row})
                    print(f"{env:<17} {list(w)!s:<16} beta {beta:g} seed {run.config.seed}: return {row['ratio']:6.3f} of the "
                          f"expert, live {row['live_steps']:6.1f} steps | recovered return demos {row['recovered_demos']:9.1f} "
                          f"own {row['recovered_own']:9.1f} | action gap {row['action_gap']:.3f} | within the demos' states "
                          f"{row['on_demo_share']:.3f} of live steps", flush=True)
    paper.write_outputs(out, "imitation_gap", args, rows, episodes=episodes, within_quantile=WITHIN_QUANTILE)


if __name__ == "__main__":
    main()

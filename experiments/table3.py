"""The paper's Table 3 on the MuJoCo tasks: Pearson correlation between MOIQ's recovered reward (at each beta of
``paper_mujoco.MOIQ_BETAS``) and the true reward, scalarised by each expert's preference (and per objective), at
each run's best model, averaged over seeds, in two readings: per step on the experts' demonstrations
(``correlation``; ``moiq_jax.reward_correlations``) and across the best model's own episodes, of the episode
returns (``episode_correlation``; ``moiq_jax.rollout_reward_correlations``: the measure of IQ-Learn's code, on
which the paper's is built), over ``--episodes`` episodes per preference (with the per-step correlation over
their steps beside it).

    PYTHONPATH=. python experiments/table3.py [--envs ...] [--seeds 3] [--betas 5 0.5] [--protocol cpu|paper] [--quick]
        [--episodes 100] [--no-train] [--out DIR]

Reads the same kept runs as table1.py (``--betas``: only those betas' runs); the recovered reward is the critic
loss's (V(s') from the online critic under both protocols). Writes ``table3.csv`` / ``.json`` and ``table3.png``.
"""

from __future__ import annotations

import argparse

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import paper_mujoco as paper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    paper.add_betas_argument(parser)
    parser.add_argument("--episodes", type=int, default=100, help="the best model's episodes per preference")
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/table3")
    args = parser.parse_args()
    out = paper.out_dir(args, "table3")
    betas, sweep_betas = paper.row_and_sweep_betas(args)
    episodes = 3 if args.quick else args.episodes

    rows = []
    for env in args.envs:
        result = paper.task_sweep(env, args, betas=sweep_betas)
        for beta in betas:
            scalar, per_objective = paper.best_model_correlations(result, beta)  # [seeds, E], [seeds, E, d]
            rollouts = paper.best_model_rollout_correlations(result, beta, episodes)
            episode = rollouts["episode_reward_correlation"]  # [seeds, E]; NaN where the returns did not vary
            for e, w in enumerate(result.config.preferences):
                rows.append({"env": env, "preference": list(w), "beta": beta,
                             "correlation": round(float(scalar[:, e].mean()), 3), "std": round(float(scalar[:, e].std()), 3),
                             "per_objective": np.round(per_objective[:, e].mean(0, dtype=np.float64), 3).tolist(),
                             "episode_correlation": round(float(episode[:, e].mean()), 3),
                             "episode_std": round(float(episode[:, e].std()), 3),
                             "episode_per_seed": np.round(episode[:, e], 3).tolist(),
                             "episode_per_objective": np.round(
                                 rollouts["episode_reward_correlation_objectives"][:, e].mean(0), 3).tolist(),
                             "episode_step_correlation": round(float(rollouts["step_reward_correlation"][:, e].mean()), 3),
                             "episodes": episodes, "paper": paper.PAPER_TABLE3[env][e]})
    at_least = {f"beta={beta:g}": sum(r["correlation"] >= r["paper"] for r in rows if r["beta"] == beta)
                for beta in betas}
    at_least_episodes = {f"beta={beta:g}": sum(r["episode_correlation"] >= r["paper"] for r in rows if r["beta"] == beta)
                         for beta in betas}
    paper.write_outputs(out, "table3", args, rows, settings_at_least_the_papers=at_least,
                        settings_at_least_the_papers_across_episodes=at_least_episodes)

    fig, ax = plt.subplots(figsize=(max(6, len(rows)), 3.4), layout="constrained")
    x = np.arange(len(rows))
    ax.bar(x - 0.27, [r["correlation"] for r in rows], 0.27, yerr=[r["std"] for r in rows],
           label="moiq_jax, per step on the demonstrations")
    ax.bar(x, [r["episode_correlation"] for r in rows], 0.27, yerr=[r["episode_std"] for r in rows],
           label="moiq_jax, episode returns of its own episodes")
    ax.bar(x + 0.27, [r["paper"] for r in rows], 0.27, label="paper")
    ax.set_xticks(x, [f"{r['env']}\n{r['preference']}\nbeta={r['beta']:g}" for r in rows], fontsize=6)
    ax.set(ylabel="Pearson correlation", title="Table 3: recovered against true scalarised reward")
    ax.legend()
    fig.savefig(out / "table3.png", dpi=120)

    print(f"{'env':<15} {'preference':<18} {'beta':>4} {'demos, per step':>15} {'own episodes':>15} {'paper':>6}   "
          f"per objective (demos; episodes)   per step on the episodes")
    for r in rows:
        print(f"{r['env']:<15} {r['preference']!s:<18} {r['beta']:4g} {r['correlation']:7.3f} ± {r['std']:5.3f} "
              f"{r['episode_correlation']:7.3f} ± {r['episode_std']:5.3f} {r['paper']:6}   {r['per_objective']}; "
              f"{r['episode_per_objective']}   {r['episode_step_correlation']:.3f}")
    for beta, count in at_least.items():
        print(f"{beta}: correlation at least the paper's in {count} of {len(rows) // len(at_least)} settings per step "
              f"on the demonstrations, {at_least_episodes[beta]} across the best models' episodes ({episodes} each)")


if __name__ == "__main__":
    main()

"""The paper's Figure 3 on the two-objective MuJoCo tasks: the vector returns of MOIQ's best models (each beta of
``paper_mujoco.MOIQ_BETAS``, or of ``--betas``) for the 19 preferences [1 - 0.05k, 0.05k], beside the experts', with
the hypervolume of each.

    PYTHONPATH=. python experiments/figure3.py [--envs ...] [--seeds 3] [--betas 5 0.5] [--protocol cpu|paper] [--quick]
        [--no-train] [--out DIR]

Uses the same cached sweeps as table1.py (``--betas``: only those betas' runs); writes ``figure3.png``,
``figure3.csv`` (every seed and preference) and ``figure3.json`` (hypervolumes). The hypervolume reference point is
the component-wise minimum of all the points compared for that task (experts' and policies'), so the two
hypervolumes measure the same area.
"""

from __future__ import annotations

import argparse
import itertools
import json

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import paper_mujoco as paper

import moiq_jax
from moiq_jax.evaluate import hypervolume
from moiq_jax.preferences import preference_sweep

TWO_OBJECTIVES = tuple(env for env in paper.TASKS if len(paper.moiq_config(env).preferences[0]) == 2)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    paper.add_betas_argument(parser)
    parser.set_defaults(envs=list(TWO_OBJECTIVES))
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per preference")
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/figure3")
    args = parser.parse_args()
    out = paper.out_dir(args, "figure3")
    episodes = 1 if args.quick else args.episodes
    preferences = preference_sweep(19)
    betas, sweep_betas = paper.row_and_sweep_betas(args)

    rows, summary = [], {}
    envs = [env for env in args.envs if env in TWO_OBJECTIVES]
    fig, axes = plt.subplots(1, len(envs), figsize=(5 * len(envs), 4), layout="constrained", squeeze=False)
    for ax, env in zip(axes[0], envs):
        result = paper.task_sweep(env, args, betas=sweep_betas)
        returns = {beta: np.stack([moiq_jax.evaluate(result.run(r).best_params, env, preferences, episodes=episodes)
                                   for r in paper.runs_of(result, beta)]) for beta in betas}  # [seeds, 19, 2]
        experts = paper.expert_returns(env)
        every = np.concatenate([r.reshape(-1, 2) for r in returns.values()] + [experts])
        reference = every.min(0) - 1e-6
        summary[env] = {"expert_hypervolume": round(hypervolume(experts, reference), 2), "reference": reference.tolist(),
                        "hypervolume_per_seed": {f"beta={beta:g}": [round(hypervolume(r, reference), 2) for r in by_seed]
                                                 for beta, by_seed in returns.items()}}
        for (beta, by_seed), marker in zip(returns.items(), itertools.cycle("os^D")):
            for s, seed_returns in zip(result.runs["seed"][paper.runs_of(result, beta)], by_seed):
                rows += [{"env": env, "beta": beta, "seed": int(s), "preference": [round(float(x), 2) for x in w],
                          "vector_return": [round(float(x), 2) for x in r]} for w, r in zip(preferences, seed_returns)]
            mean = by_seed.mean(0)
            points = ax.scatter(mean[:, 1], mean[:, 0], c=preferences[:, 0], cmap="viridis", marker=marker,
                                label=f"MOIQ beta={beta:g}, 19 preferences")
        ax.scatter(experts[:, 1], experts[:, 0], marker="*", s=160, c="k", label="experts")
        volumes = ", ".join(f"{beta} {np.mean(v):.3g}" for beta, v in summary[env]["hypervolume_per_seed"].items())
        ax.set(title=f"{env}: hypervolume\nMOIQ {volumes}\nexperts {summary[env]['expert_hypervolume']:.3g}",
               xlabel="objective 2 return", ylabel="objective 1 (x velocity) return")
        ax.legend(fontsize=7)
    fig.colorbar(points, ax=axes[0].tolist(), label="weight of objective 1")
    fig.savefig(out / "figure3.png", dpi=120)
    paper.write_outputs(out, "figure3", args, rows, **summary)
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()

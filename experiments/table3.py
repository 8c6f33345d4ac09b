"""The paper's Table 3 on the MuJoCo tasks: Pearson correlation between MOIQ's recovered reward (at each beta of
``paper_mujoco.MOIQ_BETAS``) and the true reward on the experts' demonstrations, scalarised by each expert's
preference and per objective, at each run's best model, averaged over seeds.

    PYTHONPATH=. python experiments/table3.py [--envs ...] [--seeds 3] [--betas 5 0.5] [--protocol cpu|paper] [--quick]
        [--no-train] [--out DIR]

Reads the same kept runs as table1.py (``--betas``: only those betas' runs) and computes the correlations at
each run's best model (``moiq_jax.reward_correlations``, the reward of the critic loss: V(s') from the online
critic under both protocols); writes ``table3.csv`` / ``.json`` and ``table3.png``.
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
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/table3")
    args = parser.parse_args()
    out = paper.out_dir(args, "table3")
    betas, sweep_betas = paper.row_and_sweep_betas(args)

    rows = []
    for env in args.envs:
        result = paper.task_sweep(env, args, betas=sweep_betas)
        for beta in betas:
            scalar, per_objective = paper.best_model_correlations(result, beta)  # [seeds, E], [seeds, E, d]
            for e, w in enumerate(result.config.preferences):
                rows.append({"env": env, "preference": list(w), "beta": beta,
                             "correlation": round(float(scalar[:, e].mean()), 3), "std": round(float(scalar[:, e].std()), 3),
                             "per_objective": np.round(per_objective[:, e].mean(0, dtype=np.float64), 3).tolist(),
                             "paper": paper.PAPER_TABLE3[env][e]})
    at_least = {f"beta={beta:g}": sum(r["correlation"] >= r["paper"] for r in rows if r["beta"] == beta)
                for beta in betas}
    paper.write_outputs(out, "table3", args, rows, settings_at_least_the_papers=at_least)

    fig, ax = plt.subplots(figsize=(max(6, len(rows)), 3.4), layout="constrained")
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["correlation"] for r in rows], 0.4, yerr=[r["std"] for r in rows], label="moiq_jax")
    ax.bar(x + 0.2, [r["paper"] for r in rows], 0.4, label="paper")
    ax.set_xticks(x, [f"{r['env']}\n{r['preference']}\nbeta={r['beta']:g}" for r in rows], fontsize=6)
    ax.set(ylabel="Pearson correlation", title="Table 3: recovered against true scalarised reward")
    ax.legend()
    fig.savefig(out / "table3.png", dpi=120)

    print(f"{'env':<15} {'preference':<18} {'beta':>4} {'correlation':>15} {'paper':>6}   per objective")
    for r in rows:
        print(f"{r['env']:<15} {r['preference']!s:<18} {r['beta']:4g} {r['correlation']:7.3f} ± {r['std']:5.3f} "
              f"{r['paper']:6}   {r['per_objective']}")
    for beta, count in at_least.items():
        print(f"{beta}: correlation at least the paper's in {count} of {len(rows) // len(at_least)} settings")


if __name__ == "__main__":
    main()

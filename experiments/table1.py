"""The paper's Table 1 on the MuJoCo tasks: the best model's return of MOIQ (at the paper's beta = 5 and at
this project's, ``paper_mujoco.MOIQ_BETAS``) per task and preference, over 100 evaluation episodes and every
seed (mean, spread and each seed's), next to the experts' and the paper's. Beside it, from the runs' own
evaluations during training (a few episodes each): each preference's best evaluation (``own_best``: the
preferences of one model peak at different times) and the mean over the last 20% of training (``last_window``:
where the run ends). For runs that kept each preference's best actor, the same 100-episode evaluation of
that actor at its preference (``each_best``): a per-preference reading of "the best model", one model per row,
reported beside the one-model reading that the counts use.

    PYTHONPATH=. python experiments/table1.py [--envs mo-hopper ...] [--seeds 3] [--betas 5 0.5] [--protocol PROTOCOL]
        [--quick] [--no-train] [--out DIR]

Reads each task's beta x seed sweep from the kept runs, training those not kept yet (``paper_mujoco.task_sweep``;
with ``--betas``, only those betas' runs), and writes ``table1.csv`` / ``.json`` and ``table1.png`` (MOIQ /
expert per setting) under ``--out``.
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
    parser.add_argument("--episodes", type=int, default=100, help="evaluation episodes per best model")
    paper.add_betas_argument(parser)
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/table1")
    args = parser.parse_args()
    out = paper.out_dir(args, "table1")
    betas, sweep_betas = paper.row_and_sweep_betas(args)
    episodes = 1 if args.quick else args.episodes

    rows = []
    for env in args.envs:
        paper.task_sweep(env, args, betas=sweep_betas)  # trains the runs not kept yet, each beta's seeds at once
        for beta in betas:  # one beta's runs at a time: the per-preference reading needs only theirs to keep it
            result = paper.task_sweep(env, args, betas=(beta,))
            preferences = np.asarray(result.config.preferences)
            expert = (paper.expert_returns(env) * preferences).sum(-1)
            returns = paper.best_model_returns(result, beta, episodes)  # [seeds, E, d]
            scalar = (returns * preferences).sum(-1)
            each = paper.each_preferences_best_returns(result, beta, episodes)
            each_scalar = None if each is None else (each * preferences).sum(-1)
            steps, evaluations = paper.evaluation_returns(result, beta)  # [seeds, evals, E]
            own_best, last_window = evaluations.max(1).mean(0), paper.last_window_mean(steps, evaluations).mean(0)
            for e, w in enumerate(preferences):
                rows.append({"env": env, "preference": w.tolist(), "beta": beta,
                             "moiq_mean": round(float(scalar[:, e].mean()), 2),
                             "moiq_std": round(float(scalar[:, e].std()), 2),
                             "moiq_per_seed": [round(float(x), 2) for x in scalar[:, e]],
                             "expert": round(float(expert[e]), 2),
                             "ratio_to_expert": round(float(scalar[:, e].mean() / expert[e]), 3),
                             "near_expert": paper.near_expert(scalar[:, e].mean(), expert[e]),
                             "own_best": round(float(own_best[e]), 2), "last_window": round(float(last_window[e]), 2),
                             "paper_moiq": paper.PAPER_TABLE1[env][e], "seeds": int(scalar.shape[0]),
                             "episodes": episodes, **each_best_columns(each_scalar, e, expert[e])})
    reached = {f"beta={beta:g}": sum(r["near_expert"] for r in rows if r["beta"] == beta) for beta in betas}
    each_reached = {f"beta={beta:g}": sum(r["each_best_near_expert"] for r in rows if r["beta"] == beta)
                    for beta in betas if all(r["each_best_mean"] is not None for r in rows if r["beta"] == beta)}
    paper.write_outputs(out, "table1", args, rows, settings_at_90_percent_of_expert=reached,
                        settings_at_90_percent_with_each_preferences_best_actor=each_reached)

    fig, ax = plt.subplots(figsize=(max(6, len(rows)), 3.6), layout="constrained")
    ax.bar(range(len(rows)), [r["ratio_to_expert"] for r in rows], yerr=[r["moiq_std"] / abs(r["expert"]) for r in rows])
    ax.axhline(0.9, color="k", linestyle="--", label="90% of expert")
    ax.set_xticks(range(len(rows)), [f"{r['env']}\n{r['preference']}\nbeta={r['beta']:g}" for r in rows], fontsize=6)
    ax.set(ylabel="MOIQ best model / expert return", title="Table 1: MOIQ against the experts")
    ax.legend()
    fig.savefig(out / "table1.png", dpi=120)

    print(f"{'env':<15} {'preference':<18} {'beta':>4} {'MOIQ':>16} {'expert':>9} {'ratio':>6} {'paper MOIQ':>10}"
          f" {'own best':>9} {'last 20%':>9} {'each best (ratio)':>24}")
    for r in rows:
        each = "-" if r["each_best_mean"] is None else \
            f"{r['each_best_mean']:.1f} ± {r['each_best_std']:.1f} ({r['each_best_ratio_to_expert']:.2f})"
        print(f"{r['env']:<15} {r['preference']!s:<18} {r['beta']:4g} {r['moiq_mean']:9.1f} ± {r['moiq_std']:5.1f} "
              f"{r['expert']:9.1f} {r['ratio_to_expert']:6.2f} {r['paper_moiq']:10} {r['own_best']:9.1f}"
              f" {r['last_window']:9.1f} {each:>24}")
    for beta, count in reached.items():
        print(f"{beta}: settings within 10% of the expert's return: {count} of {len(rows) // len(reached)}"
              + (f" (each preference's best actor: {each_reached[beta]})" if beta in each_reached else ""))


def each_best_columns(each_scalar: np.ndarray | None, e: int, expert: float) -> dict:
    """Row ``e``'s columns of each preference's best actor (``[seeds, E]`` scalarised returns; None: not kept)."""
    if each_scalar is None:
        return dict.fromkeys(["each_best_mean", "each_best_std", "each_best_ratio_to_expert", "each_best_near_expert"])
    mean = float(each_scalar[:, e].mean())
    return {"each_best_mean": round(mean, 2), "each_best_std": round(float(each_scalar[:, e].std()), 2),
            "each_best_ratio_to_expert": round(mean / expert, 3), "each_best_near_expert": paper.near_expert(mean, expert)}


if __name__ == "__main__":
    main()

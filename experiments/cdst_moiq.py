"""Continuous DST: MOIQ (the tuned beta, 0.5), its ablation beta = 0 and IQ-Learn (one model per expert),
5 seeds each as vmapped sweeps; the paper's Figure 2 (learning curves), Table 1 (best models) and Figure 3
(transfer over 19 preferences, beside the true Pareto front).

    PYTHONPATH=. python experiments/cdst_moiq.py [--seeds 5] [--steps 100000] [--out results/cdst_moiq]
        [--save sweeps.pkl | --reuse sweeps.pkl]   (keep the trained sweeps / redo only the outputs)

Outputs under ``--out``: ``curves.png``, ``curves.npz`` (evaluation history of every run),
``best_models.csv`` / ``.json`` (best model's returns per method, seed and preference, exact expert
returns beside them), ``transfer.png``, ``transfer.csv`` and ``summary.json`` (acceptance counts).
The config is ``moiq_jax.config.tuned("cdst")``; the best model of a run is the evaluation with the highest
mean scalarised return (checked every ``eval_interval`` env steps, as the paper's checkpoints).
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import pickle
import time

import jax
import matplotlib
import numpy as np

matplotlib.use("Agg")
import common
import matplotlib.pyplot as plt
from common import TRANSFER_PREFERENCES, optimal_for, run_index

import moiq_jax


def best_model_returns(method, swept, preferences) -> np.ndarray:
    """``[seeds, E, d]`` vector returns of each run's best model for the experts' preferences."""
    runs = len(swept["seeds"])
    if method == "IQ-Learn":  # one single-preference model per expert
        return np.stack([np.concatenate([moiq_jax.evaluate(run_index(swept["best_params"], (r, e)), "cdst",
                                                           preferences[e:e + 1]) for e in range(len(preferences))])
                         for r in range(runs)])
    return np.stack([moiq_jax.evaluate(run_index(swept["best_params"], r), "cdst", preferences) for r in range(runs)])


def rounded(x) -> list:
    return np.round(np.asarray(x, np.float64), 4).tolist()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000, help="env steps per expert")
    parser.add_argument("--out", default="results/cdst_moiq")
    parser.add_argument("--reuse", metavar="PICKLE", help="load the sweeps from this file instead of training")
    parser.add_argument("--save", metavar="PICKLE", help="save the sweeps' raw results to this file")
    args = parser.parse_args()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    common.start(args.seeds)  # one CPU device per seed: both sweeps (2 x seeds, seeds runs) shard

    cdst = common.CdstSetup(total_steps=args.steps)
    config, demos, preferences, expert, expert_scalar = cdst.config, cdst.demos, cdst.preferences, cdst.expert, \
        cdst.expert_scalar
    methods = (f"MOIQ beta={config.moiq.beta:g}", "MOIQ beta=0", "IQ-Learn")
    seeds = list(range(args.seeds))

    start = time.perf_counter()
    if args.reuse:
        moiq_sweep, iq_sweep, train_seconds = pickle.loads(pathlib.Path(args.reuse).read_bytes())
    else:
        moiq_sweep = moiq_jax.sweep(config, beta=[config.moiq.beta, 0.0], seed=seeds, demos=demos)
        iq_sweep = moiq_jax.sweep(config.replace(algo="iq_learn"), seed=seeds, demos=demos)
        train_seconds = time.perf_counter() - start
    if args.save:
        pathlib.Path(args.save).write_bytes(pickle.dumps(jax.device_get((moiq_sweep, iq_sweep, train_seconds))))
    print(f"trained 3 methods x {len(seeds)} seeds for {args.steps} env steps per expert in {train_seconds:.0f} s")

    split = len(seeds)  # the MOIQ sweep's runs are the tuned beta (seeds...), then beta 0 (seeds...)
    runs = {methods[0]: slice(0, split), methods[1]: slice(split, 2 * split)}
    swept = {m: {"seeds": moiq_sweep.runs["seed"][s], "best_params": run_index(moiq_sweep.best_params, s),
                 "history": {k: v[s] for k, v in moiq_sweep.history.items()}} for m, s in runs.items()}
    swept["IQ-Learn"] = {"seeds": iq_sweep.runs["seed"], "best_params": iq_sweep.best_params,
                         "history": iq_sweep.history}
    np.savez(out / "curves.npz", **{f"{m}/{k}": v for m in methods for k, v in swept[m]["history"].items()})

    # Figure 2: evaluation return (scalarised) against env steps, mean and std over seeds.
    fig, axes = plt.subplots(1, len(preferences), figsize=(5 * len(preferences), 3.6))
    for e, ax in enumerate(axes):
        for method in methods:
            history = swept[method]["history"]
            steps = history["env_steps"][0]  # [evals], or [evals, models] for IQ-Learn
            steps = steps[:, 0] if steps.ndim > 1 else steps
            curve = history["eval_scalar_return"][:, :, e]
            ax.plot(steps, curve.mean(0), marker=".", label=method)
            ax.fill_between(steps, curve.mean(0) - curve.std(0), curve.mean(0) + curve.std(0), alpha=0.2)
        ax.axhline(expert_scalar[e], color="k", linestyle="--", label="expert")
        ax.set(title=f"cdst [{preferences[e][0]:.2f}, {preferences[e][1]:.2f}]", xlabel="env steps per expert",
               ylabel="scalarised return", ylim=(max(-20.0, ax.get_ylim()[0]), None))
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(out / "curves.png", dpi=120)

    # Table 1: best model per run, re-evaluated with moiq_jax.evaluate.
    rows, summary = [], {"steps_per_expert": args.steps, "seeds": seeds, "train_seconds": train_seconds,
                         "config": config.to_dict()}
    for method in methods:
        returns = best_model_returns(method, swept[method], preferences)  # [seeds, E, d]
        scalar = (returns * preferences).sum(-1)
        exact = np.isclose(scalar, expert_scalar, atol=1e-3)
        summary[method] = {"seeds_with_all_expert_returns": int(exact.all(1).sum()),
                           "mean_scalarised_return": rounded(scalar.mean(0)), "std": rounded(scalar.std(0))}
        for r, seed in enumerate(seeds):
            for e, w in enumerate(preferences):
                rows.append({"method": method, "seed": seed, "preference": rounded(w),
                             "scalarised_return": rounded(scalar[r, e]),
                             "vector_return": rounded(returns[r, e]),
                             "expert_scalarised_return": rounded(expert_scalar[e]),
                             "expert_vector_return": rounded(expert[e]), "expert_level": bool(exact[r, e])})
    with open(out / "best_models.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "best_models.json").write_text(json.dumps(rows, indent=1))

    # Figure 3: transfer of each MOIQ run's best model over 19 preferences, against the exact front.
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    optimal = np.stack([optimal_for(front, w) for w in TRANSFER_PREFERENCES])
    transfer_rows = []
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), layout="constrained")
    for ax, method in zip(axes, methods[:2]):
        params = swept[method]["best_params"]
        transfer = np.stack([moiq_jax.evaluate(run_index(params, r), "cdst", TRANSFER_PREFERENCES)
                             for r in range(len(seeds))])  # [seeds, 19, d]
        hits = np.all(np.isclose(transfer, optimal, atol=1e-3), axis=-1)  # [seeds, 19]
        summary[method]["transfer_pareto_optimal_per_seed"] = hits.sum(1).tolist()
        for r, seed in enumerate(seeds):
            for k, w in enumerate(TRANSFER_PREFERENCES):
                transfer_rows.append({"method": method, "seed": seed, "preference": rounded(w),
                                      "vector_return": rounded(transfer[r, k]),
                                      "optimal_vector_return": rounded(optimal[k]), "pareto_optimal": bool(hits[r, k])})
        ax.plot(front[:, 1], front[:, 0], "k--o", markersize=4, label="true Pareto front")
        mean = transfer.mean(0)
        points = ax.scatter(mean[:, 1], mean[:, 0], c=TRANSFER_PREFERENCES[:, 0], cmap="viridis", zorder=3,
                            label="policy (mean over seeds)")
        ax.set(title=f"{method}\nPareto-optimal of 19, per seed: {hits.sum(1).tolist()}", xlabel="step cost return",
               ylabel="treasure return")
        ax.legend(loc="lower left")
    fig.colorbar(points, ax=axes, label="preference weight of treasure")
    fig.savefig(out / "transfer.png", dpi=120)
    with open(out / "transfer.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(transfer_rows[0]))
        writer.writeheader()
        writer.writerows(transfer_rows)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    print(json.dumps({m: summary[m] for m in methods}, indent=1))


if __name__ == "__main__":
    main()

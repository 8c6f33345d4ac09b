"""Continuous DST: how transfer changes with the number of experts. The paper's three experts against a
two-expert and a five-expert set spanning the same range ([0.9, 0.1] .. [0.1, 0.9]), 5 seeds each, with
``moiq_jax.config.tuned("cdst")``; each run's best model acts at the 19 transfer preferences and is scored by
how many reach their Pareto-optimal return, the mean regret ``w . (optimum - return)`` and the hypervolume of
the returns, beside the nearest-expert rule (act as the exact expert whose preference is nearest).

Sets in one compiled program must have one size (the experts are an array axis), so each size is its own
program: ``moiq_jax.sweep(config, seed=[...], preferences=[set])``, vmapped over the seeds (several sets of
one size would share that program). The script also times, at ``--bench-steps``, the 3-expert sweep against
the same runs one after another (one jitted program called per seed), in the same process.

    PYTHONPATH=. python experiments/cdst_preference_sets.py [--steps 30000] [--seeds 5] [--bench-steps 5000]
        [--out results/cdst_preference_sets]

Outputs under ``--out``: ``transfer.csv`` (per size, seed and preference), ``summary.json`` (per size: mean and
per-seed scores, the nearest-expert rule's, wall times), ``transfer.png``.
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib
import time

import jax
import jax.numpy as jnp
import matplotlib
import numpy as np

matplotlib.use("Agg")
import common
import matplotlib.pyplot as plt
from common import TRANSFER_PREFERENCES

import moiq_jax
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.config import tuned
from moiq_jax.evaluate import preference_returns, transfer_scores
from moiq_jax.experts.cdst_oracle import expert_returns
from moiq_jax.networks import networks_for
from moiq_jax.train import ALGORITHMS

SETS = {
    2: ((0.9, 0.1), (0.1, 0.9)),
    3: ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9)),  # the paper's
    5: ((0.9, 0.1), (0.7, 0.3), (0.5, 0.5), (0.3, 0.7), (0.1, 0.9)),
}


def transfer_returns(best_params, env) -> np.ndarray:
    """``[runs, 19, 2]`` vector returns of every run's best model at the transfer preferences, in one call."""
    nets = networks_for(jax.tree_util.tree_map(lambda x: x[0], best_params))
    prefs = jnp.asarray(TRANSFER_PREFERENCES, jnp.float32)
    run = jax.jit(jax.vmap(lambda actor: preference_returns(nets, actor, env, prefs, jax.random.PRNGKey(0), 1)))
    return np.asarray(run(best_params.actor)).mean(axis=2)


def nearest_expert(preferences) -> np.ndarray:
    """``[19, 2]``: at each transfer preference, the exact return of the expert whose preference is nearest
    (ties: the first in the set's order)."""
    preferences = np.asarray(preferences)
    nearest = np.argmin(np.linalg.norm(TRANSFER_PREFERENCES[:, None] - preferences[None], axis=-1), axis=1)
    return expert_returns(preferences)[nearest]


def score(returns, front) -> dict:
    s = transfer_scores(returns, TRANSFER_PREFERENCES, front)
    return {"optimal": int(s["optimal"].sum()), "mean_regret": float(s["regret"].mean()),
            "hypervolume": s["hypervolume"], "front_hypervolume": s["front_hypervolume"]}


def benchmark(steps: int, seeds: list[int]) -> dict:
    """Wall time of the 3-expert, ``len(seeds)``-seed sweep against the same runs one after another."""
    config = tuned("cdst", total_steps=steps, preferences=SETS[3])
    start = time.perf_counter()
    swept = moiq_jax.sweep(config, seed=seeds, preferences=[SETS[3]])
    sweep_seconds = time.perf_counter() - start
    trainer = make_trainer(config, ALGORITHMS["moiq"])
    train = jax.jit(trainer.train)
    times, best = [], []
    for seed in seeds:
        start = time.perf_counter()
        state, _ = jax.block_until_ready(train(jax.random.PRNGKey(seed), trainer.hyper))
        times.append(time.perf_counter() - start)
        best.append(float(state.best_return))
    return {"best_return_sweep": np.asarray(swept.best_return).tolist(), "best_return_one_after_another": best,
            "steps_per_expert": steps, "runs": len(seeds), "sweep_seconds_with_compile": sweep_seconds,
            "one_after_another_seconds_with_one_compile": float(sum(times)),
            "first_run_seconds_with_compile": times[0], "later_run_seconds": times[1:]}


def write_outputs(out: pathlib.Path, summary: dict, rows: list, returns_by_size: dict, front) -> None:
    """transfer.csv, summary.json and transfer.png of the sizes trained so far."""
    with open(out / "transfer.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))

    fig, axes = plt.subplots(1, len(returns_by_size), figsize=(5 * len(returns_by_size), 4), sharey=True)
    for ax, (size, returns) in zip(np.atleast_1d(axes), returns_by_size.items()):
        ax.plot(front[:, 1], front[:, 0], "k--", marker="s", ms=4, mfc="none", label="true Pareto front")
        nearest = nearest_expert(SETS[size])
        ax.scatter(nearest[:, 1], nearest[:, 0], marker="x", s=60, c="C3", label="nearest-expert rule", zorder=4)
        for seed, r in enumerate(returns):
            ax.scatter(r[:, 1], r[:, 0], c=TRANSFER_PREFERENCES[:, 0], cmap="viridis", s=14, alpha=0.6, zorder=3,
                       label=f"MOIQ best models ({len(returns)} seeds)" if seed == 0 else None)
        m = summary[str(size)]["mean"]
        ax.set(title=f"{size} experts: {m['optimal']:.1f}/19 optimal, regret {m['mean_regret']:.2f}",
               xlabel="objective 2 return (-steps)")
    np.atleast_1d(axes)[0].set_ylabel("objective 1 return (treasure)")
    np.atleast_1d(axes)[0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(out / "transfer.png", dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30_000, help="env steps per expert (paper-like: 100000)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--bench-steps", type=int, default=5_000, help="env steps per expert of the timing")
    parser.add_argument("--out", default="results/cdst_preference_sets")
    args = parser.parse_args()
    common.start(args.seeds)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = list(range(args.seeds))
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    env = tuned("cdst").make_env(absorbing=True)
    summary, rows, returns_by_size = {"steps_per_expert": args.steps, "seeds": seeds}, [], {}
    summary["benchmark"] = bench = benchmark(args.bench_steps, seeds)
    print(f"timing at {bench['steps_per_expert']} steps per expert, 3 experts, {bench['runs']} seeds: one vmapped "
          f"sweep {bench['sweep_seconds_with_compile']:.1f} s (compile included) vs one after another "
          f"{bench['one_after_another_seconds_with_one_compile']:.1f} s (one compile, first run "
          f"{bench['first_run_seconds_with_compile']:.1f} s): "
          f"{bench['one_after_another_seconds_with_one_compile'] / bench['sweep_seconds_with_compile']:.2f}x",
          flush=True)
    total = time.perf_counter()
    for size, preferences in SETS.items():
        config = tuned("cdst", total_steps=args.steps, preferences=preferences)
        start = time.perf_counter()
        swept = moiq_jax.sweep(config, seed=seeds, preferences=[preferences])
        seconds = time.perf_counter() - start
        returns = transfer_returns(swept.best_params, env)  # [seeds, 19, 2]
        returns_by_size[size] = returns
        per_seed = [score(r, front) for r in returns]
        nearest = nearest_expert(preferences)
        expert_scalar = (expert_returns(preferences) * np.asarray(preferences)).sum(1)
        best_scalar = np.asarray(swept.history["eval_scalar_return"]).max(axis=1)  # [seeds, E]
        summary[str(size)] = {
            "preferences": preferences, "sweep_seconds": seconds,
            "experts_exact_seeds": int(np.all(np.abs(best_scalar - expert_scalar) < 1e-3, axis=1).sum()),
            "mean": {k: float(np.mean([s[k] for s in per_seed])) for k in per_seed[0]},
            "per_seed": per_seed, "nearest_expert": score(nearest, front)}
        for seed, run_returns in zip(seeds, returns):
            for w, r in zip(TRANSFER_PREFERENCES, run_returns):
                rows.append({"experts": size, "seed": seed, "preference": json.dumps(np.round(w, 2).tolist()),
                             "vector_return": json.dumps(np.round(r, 4).tolist()),
                             "regret": round(float(w @ (front[np.argmax(front @ w)] - r)), 4)})
        m, n = summary[str(size)]["mean"], summary[str(size)]["nearest_expert"]
        print(f"{size} experts ({seconds:.0f} s, {args.seeds} seeds vmapped): optimal {m['optimal']:.1f} of 19, "
              f"regret {m['mean_regret']:.3f}, hypervolume {m['hypervolume']:.1f} "
              f"(front {m['front_hypervolume']:.1f}); per seed optimal "
              f"{[s['optimal'] for s in summary[str(size)]['per_seed']]}; experts exact in "
              f"{summary[str(size)]['experts_exact_seeds']} of {args.seeds} seeds | nearest-expert rule: optimal "
              f"{n['optimal']}, regret {n['mean_regret']:.3f}, hypervolume {n['hypervolume']:.1f}", flush=True)
        write_outputs(out, summary, rows, returns_by_size, front)  # after every size: a partial run keeps its part
    summary["training_seconds"] = time.perf_counter() - total
    write_outputs(out, summary, rows, returns_by_size, front)
    print(f"written to {out}; training {summary['training_seconds']:.0f} s")


if __name__ == "__main__":
    main()

"""Paper Figure 1: consensus-ADMM MOIRL on discrete DST (mini and default map), 5 seeds in one vmapped
program per map, plus transfer of the learned common reward to the 19 sweep preferences.

Writes under ``results/dst_admm/``: ``rounds.csv`` (per map, seed, round, expert), ``transfer.csv``,
``summary.json`` and ``figure1.png`` (return and length per round, mean and min-max over seeds, against
the optimal policy). Usage: ``python experiments/dst_admm.py [--inner-rl soft_vi|ppo] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import csv
import json
import os

import numpy as np

import moiq_jax
from moiq_jax import Config

SETUPS = {
    "dst-mini": ((0.9, 0.1), (0.1, 0.9)),
    "dst": ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9)),
}
SEEDS = range(5)


def run(inner_rl: str = "soft_vi") -> dict:
    """Train every setup for all seeds; map name -> its sweep's Result."""
    return {
        env: moiq_jax.sweep(Config(env=env, algo="admm", preferences=prefs, gamma=0.999, inner_rl=inner_rl), seed=SEEDS)
        for env, prefs in SETUPS.items()
    }


def summarise(results: dict) -> dict:
    summary = {}
    for env, r in results.items():
        optimal = np.isclose(r.history["return"], r.extras["optimal_return"], atol=1e-3)  # [seeds, rounds, experts]
        t = r.extras["transfer"]
        transfer_ok = np.isclose(t["return"], t["optimal_return"], atol=1e-3)  # [seeds, 19]
        shown = np.unique(np.round(r.history["treasure"][:, -1], 3))
        summary[env] = {
            "seeds_all_experts_optimal_at_round_10": int(optimal[:, -1].all(-1).sum()),
            "first_round_all_seeds_optimal": int(np.argmax(optimal.all((0, 2)))) + 1 if optimal.all((0, 2)).any() else None,
            "final_reward_correlation_mean": r.history["reward_correlation"][:, -1].mean(0).round(3).tolist(),
            "transfer_optimal_per_seed": transfer_ok.sum(-1).tolist(),
            "agent_treasures_at_round_10": shown.tolist(),
        }
    return summary


def _optimal_treasures(env: str, preferences) -> list[float]:
    from moiq_jax import envs
    from moiq_jax.experts import optimal_treasure

    sea_map = envs.make(env).unwrapped.sea_map
    return [float(sea_map.grid[optimal_treasure(sea_map, w)[0]]) for w in preferences]


def write(results: dict, out: str, inner_rl: str) -> dict:
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "rounds.csv"), "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["map", "seed", "round", "preference", "return", "optimal_return", "length", "treasure",
                         "reward_correlation"])
        for env, r in results.items():
            m = r.history
            for s, seed in enumerate(SEEDS):
                for k in range(r.config.admm.rounds):
                    for e, w in enumerate(r.preferences):
                        writer.writerow([env, seed, k + 1, [round(float(x), 2) for x in w], m["return"][s, k, e],
                                         r.extras["optimal_return"][e], m["length"][s, k, e], m["treasure"][s, k, e],
                                         m["reward_correlation"][s, k, e]])
    with open(os.path.join(out, "transfer.csv"), "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["map", "seed", "preference", "treasure", "steps", "return", "optimal_return",
                         "optimal_treasure"])
        for env, r in results.items():
            t = r.extras["transfer"]
            best = _optimal_treasures(env, t["preferences"])
            for s, seed in enumerate(SEEDS):
                for p, w in enumerate(t["preferences"]):
                    writer.writerow([env, seed, [round(float(x), 2) for x in w], t["vector_return"][s, p, 0], t["length"][s, p],
                                     t["return"][s, p], t["optimal_return"][p], best[p]])
    summary = {"inner_rl": inner_rl, **summarise(results)}
    with open(os.path.join(out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    plot(results, os.path.join(out, "figure1.png"), inner_rl)
    return summary


def plot(results: dict, path: str, inner_rl: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(results), figsize=(5 * len(results), 7), squeeze=False)
    for col, (env, r) in enumerate(results.items()):
        rounds = np.arange(1, r.config.admm.rounds + 1)
        for e, w in enumerate(r.preferences):
            for row, key in enumerate(("return", "length")):
                values = r.history[key][:, :, e].astype(float)
                ax = axes[row, col]
                line, = ax.plot(rounds, values.mean(0), marker="o", label=f"w={[round(float(x), 2) for x in w]}")
                ax.fill_between(rounds, values.min(0), values.max(0), color=line.get_color(), alpha=0.2)
                optimum = r.extras["optimal_return"][e] if key == "return" else _optimal_length(r, e)
                ax.axhline(optimum, color=line.get_color(), linestyle="--", linewidth=1)
                ax.set_xlabel("round")
                ax.set_ylabel(f"scalarised {key}" if key == "return" else "episode length")
                ax.set_title(f"{env}: {key} ({inner_rl}; dashed: optimal)")
        axes[0, col].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _optimal_length(r, e) -> float:
    from moiq_jax import envs
    from moiq_jax.experts import optimal_treasure

    sea_map = envs.make(r.config.env).unwrapped.sea_map
    return sea_map.treasure_steps(envs.dst.COMPASS_MOVES)[optimal_treasure(sea_map, r.preferences[e])[0]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inner-rl", default="soft_vi", choices=("soft_vi", "ppo"))
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    out = args.out or os.path.join("results", "dst_admm", args.inner_rl)
    print(json.dumps(write(run(args.inner_rl), out, args.inner_rl), indent=2))


if __name__ == "__main__":
    main()

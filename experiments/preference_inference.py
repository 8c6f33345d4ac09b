"""Infer the experts' preferences from unlabelled demonstrations on discrete DST (mini and default map), 5 seeds.

For every map and preference set, each seed records its own oracle demonstrations (10 per expert), shuffles
the experts and drops the labels. ``preference_inference`` then runs 10 ADMM rounds under preferences spread
over the simplex (longest-travelling expert weighing the treasure most), so that a reward forms, and 10
more alternating with the preference step. Three Figure-1 runs (ADMM with fixed preferences, 10 rounds, same seeds and demos) follow: with the
inferred preferences ("downstream"), with the hidden labels ("labelled") and, as the start's own effect,
with the initial spread ("initial"). Judged by behaviour: does the inferred preference's optimal policy
under the true reward take the expert's treasure (its true interval holds it), does its greedy policy under
the learned reward, and is each agent optimal for the expert's true preference at round 10.

Writes ``results/preference_inference/summary.json`` and ``preference_inference.png``.
Usage: ``python experiments/preference_inference.py [--seeds 5] [--warmup 10] [--rounds 10] [--rule closest]
[--resolution 50] [--maps dst-mini dst] [--sets paper ...] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import Config, envs
from moiq_jax.algos import preference_evidence as evidence
from moiq_jax.algos import preference_inference as pi
from moiq_jax.algos import tabular
from moiq_jax.experts import dst_oracle

PAPER = {"dst-mini": ((0.9, 0.1), (0.1, 0.9)), "dst": ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))}
SETTINGS = {
    "dst-mini": {
        "paper": PAPER["dst-mini"],
        "three": ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9)),  # treasures 16.8, 14 (tie with 16 at 0.5), 1
        "four": ((0.7, 0.3), (0.45, 0.55), (0.38, 0.62), (0.2, 0.8)),  # 16.8, 14, 11, 1
    },
    "dst": {
        "paper": PAPER["dst"],
        "skewed": ((0.95, 0.05), (0.6, 0.4), (0.3, 0.7)),  # 23.7, 22.4 (interval 0.588-0.606), 8.2
        "four": ((0.8, 0.2), (0.55, 0.45), (0.4, 0.6), (0.15, 0.85)),  # 23.7, 19.6, 11.5, 0.7
    },
}
NUM_DEMOS = 10
FIGURE1_ROUNDS = 10  # the downstream, labelled and initial runs: agents optimal at Figure 1's round 10?


def seed_data(env_name: str, preferences, seeds, gamma: float):
    """Per seed: shuffled unlabelled demos' occupancy, counts and exits, the shuffle, and the true preferences."""
    env = envs.make(env_name, absorbing=True)
    mdp, cols = tabular.tabular_mdp(env), env.unwrapped.sea_map.cols
    data = {"occupancy": [], "counts": [], "exits": [], "true": [], "returns": []}
    for seed in seeds:
        demos = dst_oracle.record_demonstrations(env_name, preferences, NUM_DEMOS, jax.random.PRNGKey(1000 + seed))
        order = np.random.default_rng(seed).permutation(len(preferences))
        demos = demos.replace(**{k: np.asarray(getattr(demos, k))[order] for k in
                                 ("obs", "actions", "next_obs", "rewards", "dones", "lengths", "preferences")})
        data["true"].append(np.asarray(demos.preferences))
        data["returns"].append(demos.episode_returns()[:, 0])  # evaluation only
        demos = demos.unlabelled()
        data["occupancy"].append(tabular.demo_occupancy(demos, mdp, cols, gamma))
        data["counts"].append(evidence.demo_counts(demos, mdp, cols))
        data["exits"].append(evidence.demo_exits(demos, mdp, cols))
    return {k: np.stack(v) for k, v in data.items()}


def optimal_at_last_round(result, true, sea_map) -> np.ndarray:
    """``[seeds, E]``: each agent's greedy true return at the last round is optimal for the expert's true preference."""
    scalar = (result.metrics["vector_return"][:, -1] * true).sum(-1)
    best = np.array([[dst_oracle.optimal_value(sea_map, w) for w in row] for row in true])
    return np.isclose(scalar, best, atol=1e-3)


def run_setting(env_name: str, preferences, seeds, rounds: int, warmup: int, rule: str, resolution: int) -> dict:
    config = Config(env=env_name, algo="admm", preferences=preferences, gamma=0.999, rounds=warmup + rounds)
    figure1 = config.replace(rounds=FIGURE1_ROUNDS)
    sea_map = envs.make(env_name).unwrapped.sea_map
    data = seed_data(env_name, preferences, seeds, config.gamma)
    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(list(seeds)))
    initial = np.stack([evidence.spread_preferences(evidence.length_order(c)) for c in data["counts"]])
    inputs = (data["occupancy"], data["counts"], data["exits"])
    start = time.time()
    inferred = pi.infer_seeds(config, *inputs, initial, keys, resolution, infer=True, rule=rule, warmup=warmup)
    seconds = time.time() - start
    runs = {name: pi.infer_seeds(figure1, *inputs, prefs, keys, resolution, infer=False)
            for name, prefs in (("downstream", inferred.preferences), ("labelled", data["true"]), ("initial", initial))}
    true = data["true"]
    per_seed = []
    for s, seed in enumerate(seeds):
        true_cells = evidence.optimal_cells(sea_map, true[s])
        inferred_cells = evidence.optimal_cells(sea_map, inferred.preferences[s])
        experts = []
        for e in range(len(preferences)):
            experts.append({
                "true": true[s, e].round(4).tolist(),
                "initial": initial[s, e].round(4).tolist(),
                "inferred": inferred.preferences[s, e].round(4).tolist(),
                "interval_learned_reward": inferred.learned_interval[s, e].round(4).tolist(),
                "interval_true_reward": np.round(evidence.true_interval(sea_map, true_cells[e]), 4).tolist(),
                # the label's interval under the reward that ADMM learns *with* the labels (Figure 1's reward)
                "interval_labelled_reward": runs["labelled"].learned_interval[s, e].round(4).tolist(),
                "label_matches_labelled_reward": bool(np.allclose(runs["labelled"].behaviour[s, e],
                                                                              data["returns"][s, e], atol=1e-4)),
                "treasure_true": float(sea_map.grid[true_cells[e]]),
                "treasure_inferred_true_reward": float(sea_map.grid[inferred_cells[e]]),
                "treasure_inferred_learned_reward": float(inferred.behaviour[s, e, 0]),
                "demo_return": data["returns"][s, e].round(3).tolist(),
                "matches_true_reward": inferred_cells[e] == true_cells[e],
                "matches_learned_reward": bool(np.allclose(inferred.behaviour[s, e], data["returns"][s, e], atol=1e-4)),
                "preferences_per_round": inferred.metrics["preferences"][s, :, e, 0].round(3).tolist(),
            })
        per_seed.append({"seed": seed, "experts": experts})
    optimal = {name: optimal_at_last_round(r, true, sea_map) for name, r in
               (("joint", inferred), *runs.items())}
    matches = np.array([[x["matches_true_reward"] for x in p["experts"]] for p in per_seed])
    learned = np.array([[x["matches_learned_reward"] for x in p["experts"]] for p in per_seed])
    for s, p in enumerate(per_seed):
        p.update({f"all_optimal_{name}": bool(o[s].all()) for name, o in optimal.items()})
    return {
        "preferences": [list(w) for w in preferences],
        "seeds_all_treasures_match_true_reward": int(matches.all(1).sum()),
        "seeds_all_treasures_match_learned_reward": int(learned.all(1).sum()),
        **{f"seeds_all_optimal_{name}": int(o.all(1).sum()) for name, o in optimal.items()},
        "inference_seconds": round(seconds, 1),
        "per_seed": per_seed,
    }


def plot(summary: dict, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    settings = [(env, name, r) for env, group in summary["settings"].items() for name, r in group.items()]
    cdst = summary.get("cdst")  # written by experiments/preference_inference_cdst.py
    fig, axes = plt.subplots(1, len(settings) + bool(cdst), figsize=(3.6 * (len(settings) + bool(cdst)), 3.8),
                             squeeze=False)
    if cdst:
        plot_cdst(axes[0, -1], cdst)
    for ax, (env, name, r) in zip(axes[0], settings):
        for s, p in enumerate(r["per_seed"]):
            for e, x in enumerate(sorted(p["experts"], key=lambda x: -x["true"][0])):
                y = e + (s - 2) * 0.08
                lo, hi = x["interval_true_reward"]
                ax.plot([lo, hi], [y, y], color="tab:green", linewidth=5, alpha=0.35, solid_capstyle="butt",
                        label="true-reward interval" if s == 0 and e == 0 else None)
                lo, hi = x["interval_learned_reward"]
                ax.plot([lo, hi], [y, y], color="tab:blue", linewidth=1, label="learned-reward interval"
                        if s == 0 and e == 0 else None)
                ax.plot(x["inferred"][0], y, "o" if x["matches_true_reward"] else "x", color="tab:red",
                        label="inferred" if s == 0 and e == 0 else None)
                ax.plot(x["true"][0], y, "|", color="black", markersize=10, label="hidden label" if s == 0 and e == 0
                        else None)
        n = preference_axes(ax, r)
        ax.set_title(f"{env} {name}: treasures match {r['seeds_all_treasures_match_true_reward']}/{n},\n"
                     f"downstream optimal {r['seeds_all_optimal_downstream']}/{n}", fontsize=9)
    axes[0, 0].legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def preference_axes(ax, r: dict) -> int:
    """A panel's axes: w[0] across, one row per expert (largest w[0] first); returns the number of seeds."""
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("w[0] (weight of the treasure)")
    ax.set_yticks(range(len(r["preferences"])))
    ax.set_yticklabels([str(w) for w in sorted(r["preferences"], key=lambda w: -w[0])], fontsize=7)
    return len(r["per_seed"])


def plot_cdst(ax, r: dict) -> None:
    """The cdst panel: per seed and expert the true-reward interval of the expert's behaviour, the learned
    actor's interval at the best evaluation, the preference then in force (o: MOIQ reproduced the expert's
    return there, x: not) and the hidden label."""
    for s, p in enumerate(r["per_seed"]):
        for e, x in enumerate(sorted(p["experts"], key=lambda x: -x["true"][0])):
            y = e + (s - 2) * 0.08
            first = s == 0 and e == 0
            if x["interval_true_reward"]:
                ax.plot(x["interval_true_reward"], [y, y], color="tab:green", linewidth=5, alpha=0.35,
                        solid_capstyle="butt", label="true-reward interval" if first else None)
            if x["interval_learned_actor"]:
                ax.plot(x["interval_learned_actor"], [y, y], color="tab:blue", linewidth=1,
                        label="learned actor's interval" if first else None)
            ax.plot(x["at_best_evaluation"][0], y, "o" if x["matches_best_evaluation"] else "x", color="tab:red",
                    label="inferred" if first else None)
            ax.plot(x["true"][0], y, "|", color="black", markersize=10, label="hidden label" if first else None)
    n = preference_axes(ax, r)
    ax.set_title(f"cdst MOIQ: all experts' returns {r['seeds_all_match_best_evaluation']}/{n},\n"
                 f"true-reward optimum matches {r['seeds_all_inferred_match_true_reward']}/{n}", fontsize=9)
    ax.legend(fontsize=6, loc="upper right")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=10, help="rounds with the preference step")
    parser.add_argument("--warmup", type=int, default=10, help="ADMM rounds under the initial preferences first")
    parser.add_argument("--rule", default="closest", choices=("closest", "likelihood"))
    parser.add_argument("--resolution", type=int, default=50, help="grid steps per unit of w[0]")
    parser.add_argument("--maps", nargs="+", default=list(SETTINGS))
    parser.add_argument("--sets", nargs="+", default=None, help="preference sets to run (default: all)")
    parser.add_argument("--out", default=os.path.join("results", "preference_inference"))
    args = parser.parse_args()
    start = time.time()
    seeds = list(range(args.seeds))
    summary = {"rule": args.rule, "warmup": args.warmup, "rounds": args.rounds, "resolution": args.resolution,
               "num_demos": NUM_DEMOS, "figure1_rounds": FIGURE1_ROUNDS, "settings": {}}
    for env_name in args.maps:
        summary["settings"][env_name] = {}
        for name, prefs in SETTINGS[env_name].items():
            if args.sets and name not in args.sets:
                continue
            result = run_setting(env_name, prefs, seeds, args.rounds, args.warmup, args.rule, args.resolution)
            summary["settings"][env_name][name] = result
            print(env_name, name, {k: v for k, v in result.items() if k.startswith("seeds") or k == "inference_seconds"},
                  flush=True)
    summary["wall_seconds"] = round(time.time() - start, 1)
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "summary.json")
    if os.path.exists(path):  # keep the cdst entry of experiments/preference_inference_cdst.py
        with open(path) as f:
            previous = json.load(f)
        if "cdst" in previous:
            summary["cdst"] = previous["cdst"]
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(summary, f, indent=1)
    plot(summary, os.path.join(args.out, "preference_inference.png"))
    print("wall seconds", summary["wall_seconds"])


if __name__ == "__main__":
    main()

"""Continuous DST: MOIQ inferring the experts' preferences from unlabelled demonstrations, 5 seeds.

The paper's three experts' oracle demonstrations (10 each) lose their labels; ``moiq_preference_inference``
starts from preferences spread by demonstration length (longest-travelling expert weighs the treasure
most), trains MOIQ (``config.tuned("cdst")``, beta 0.5) under them for ``--warmup`` env steps per expert, then
every ``--interval`` steps runs the preference step (keep a preference while the actor at it repeats its
expert's episodes; else move to the nearest grid preference whose actor does). All seeds train as one
vmapped program; the expert order of the input does not matter (the start and the learner's order come from
the demonstrations alone). Judged by behaviour: does MOIQ at the inferred preferences reproduce every expert's
vector return (at the trainer's best evaluation, as ``results/cdst_moiq`` judges labelled runs; also at the
final one and at any after the last preference step), and does the true reward's optimum at the inferred
preference take the expert's treasure in its steps.

Writes the ``cdst`` entry of ``results/preference_inference/summary.json`` (other entries kept) and redraws
``preference_inference.png`` with a cdst panel. Usage: ``python experiments/preference_inference_cdst.py
[--seeds 5] [--steps 100000] [--warmup 50000] [--interval 10000] [--eval-interval 5000] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import jax
import numpy as np

from moiq_jax import envs
from moiq_jax.algos.preference_inference import learned_interval
from moiq_jax.runtime import split_cpu_into_devices, use_compilation_cache

PAPER = ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))
NUM_DEMOS = 10
RESOLUTION = 20  # the preference step's grid: w[0] in steps of 0.05
INTERVAL_RESOLUTION = 100  # the grid of the reported intervals


def true_behaviour(env, w) -> list[int]:
    """The true reward's optimum for ``w`` as a behaviour: its treasure cell and fewest steps (the oracle's)."""
    returns = env.unwrapped.treasure_returns()
    cell = max(returns, key=lambda t: float(np.dot(np.asarray(w, np.float64), returns[t])))
    return [int(cell[0]), int(cell[1]), int(-returns[cell][1])]


def true_interval(env, behaviour) -> list[float]:
    """The range of w[0] whose true optimum is ``behaviour`` (a grid of 1,001 points; contiguous on cdst)."""
    grid = np.linspace(0.0, 1.0, 1001)
    hits = [a for a in grid if true_behaviour(env, (a, 1.0 - a)) == list(behaviour)]
    return [round(float(min(hits)), 3), round(float(max(hits)), 3)] if hits else None


def actor_interval(behaviour, candidates, point, target) -> list[float] | None:
    """The run of grid candidates around the one nearest ``point`` whose actor behaviour equals ``target``."""
    index = int(np.argmin(np.abs(candidates[:, 0] - point[0])))
    if not np.all(behaviour[index] == np.asarray(target)):
        return None
    return list(learned_interval(behaviour, candidates, index))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000, help="env steps per expert")
    parser.add_argument("--warmup", type=int, default=50_000, help="env steps under the spread start")
    parser.add_argument("--interval", type=int, default=10_000, help="env steps between preference steps")
    parser.add_argument("--eval-interval", type=int, default=5_000, help="env steps between evaluations")
    parser.add_argument("--out", default=os.path.join("results", "preference_inference"))
    args = parser.parse_args()
    split_cpu_into_devices(args.seeds)
    use_compilation_cache()
    import jax.numpy as jnp

    from moiq_jax.algos import moiq_preference_inference as mpi
    from moiq_jax.algos.preference_inference import simplex_grid
    from moiq_jax.config import tuned
    from moiq_jax.experts import oracle_demonstrations
    from moiq_jax.networks import networks_of_config

    start = time.time()
    env = envs.make("cdst")
    demos = oracle_demonstrations("cdst", PAPER, NUM_DEMOS).unlabelled()
    expert = demos.mean_returns()  # [E, d], evaluation only
    config = tuned("cdst", algo="moiq", infer_preferences=True, num_demos=NUM_DEMOS, total_steps=args.steps,
                   preference_warmup_steps=args.warmup, preference_interval=args.interval,
                   eval_interval=args.eval_interval)
    result = mpi.train_seeds(config, range(args.seeds), demos=demos, resolution=RESOLUTION,
                             log=lambda line: print(line, flush=True))
    history = result.history
    returns = history["eval_return"]  # [seeds, chunks, E, d]
    match = np.all(np.abs(returns - expert) < 1e-3, axis=-1)  # [seeds, chunks, E]
    best = np.argmax(history["eval_scalar_return"].mean(-1), axis=1)  # the trainer's best-model criterion
    prefs = history["preferences"]  # [seeds, chunks, E, d]
    changed = np.any(np.abs(np.diff(prefs, axis=1)) > 1e-6, axis=(2, 3))  # [seeds, chunks - 1]
    last_change = np.array([np.flatnonzero(c).max() + 1 if c.any() else 0 for c in changed])
    c = config.offpolicy
    nets = networks_of_config(c, env)
    candidates = simplex_grid(2, INTERVAL_RESOLUTION)
    behaviours = np.asarray(jax.jit(jax.vmap(lambda a: mpi.actor_behaviours(nets, a, env, jnp.asarray(candidates))))(
        result.best_params.actor))  # [seeds, K, 3] of the trainer's best model
    demo_behaviour = result.extras["demo_behaviour"][:, 0]  # every expert's episodes are identical
    truths = [true_interval(env, b) for b in demo_behaviour]
    per_seed = []
    for s in range(args.seeds):
        experts = []
        for e, w in enumerate(PAPER):
            inferred = prefs[s, -1, e]
            experts.append({
                "true": list(w), "initial": result.extras["initial_preferences"][e].round(4).tolist(),
                "inferred": inferred.round(4).tolist(), "at_best_evaluation": prefs[s, best[s], e].round(4).tolist(),
                "interval_true_reward": truths[e],
                "interval_learned_actor": actor_interval(behaviours[s], candidates, prefs[s, best[s], e],
                                                         demo_behaviour[e]),
                "demo_return": expert[e].round(3).tolist(),
                "best_evaluation_return": returns[s, best[s], e].round(3).tolist(),
                "final_evaluation_return": returns[s, -1, e].round(3).tolist(),
                "matches_best_evaluation": bool(match[s, best[s], e]),
                "matches_true_reward": true_behaviour(env, inferred) == demo_behaviour[e].tolist(),
                "preferences_per_chunk": prefs[s, :, e, 0].round(4).tolist(),
                "share_per_chunk": [None if np.isnan(x) else float(x) for x in history["share"][s, :, e]],
            })
        per_seed.append({"seed": s, "best_evaluation_steps": int(history["env_steps"][s, best[s]]),
                         "last_preference_change_steps": int(history["env_steps"][s, last_change[s]])
                         if last_change[s] else None, "experts": experts})
    summary = {
        "preferences": [list(w) for w in PAPER], "num_demos": NUM_DEMOS, "steps": args.steps, "warmup": args.warmup,
        "interval": args.interval, "resolution": RESOLUTION, "beta": config.moiq.beta,
        "seeds_all_match_best_evaluation": int(match[np.arange(args.seeds), best].all(-1).sum()),
        "seeds_all_match_final_evaluation": int(match[:, -1].all(-1).sum()),
        "seeds_all_match_after_last_preference_step": int(sum(match[s, last_change[s]:].all(-1).any()
                                                              for s in range(args.seeds))),
        "seeds_all_inferred_match_true_reward": int(sum(all(x["matches_true_reward"] for x in p["experts"])
                                                        for p in per_seed)),
        "seeds_preferences_moved": int(changed.any(1).sum()),
        "train_seconds": round(result.seconds, 1), "wall_seconds": round(time.time() - start, 1),
        "per_seed": per_seed,
    }
    path = os.path.join(args.out, "summary.json")
    whole = {"settings": {}}
    if os.path.exists(path):
        with open(path) as f:
            whole = json.load(f)
    whole["cdst"] = summary
    os.makedirs(args.out, exist_ok=True)
    with open(path, "w") as f:
        json.dump(whole, f, indent=1)
    from preference_inference import plot  # experiments/preference_inference.py (this script's folder)

    plot(whole, os.path.join(args.out, "preference_inference.png"))
    print(json.dumps({k: v for k, v in summary.items() if k != "per_seed"}))


if __name__ == "__main__":
    main()

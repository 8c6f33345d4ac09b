"""What the transfer goal on continuous DST asks of a learner that imitates three experts: per transfer
preference, the exact optimum, the experts' behaviour a perfect learned reward would pick, and the scalarised
margin that pick has over the next-best expert behaviour; then, for each method of a ``cdst_moiq.py`` run,
how many preferences get the optimum, how many get some Pareto-front point, and the mean regret
``w . (optimum - return)``, beside two references that learn nothing: the best expert behaviour (a perfect
reward) and the behaviour of the expert whose preference is nearest.

    PYTHONPATH=. python experiments/cdst_transfer_ceiling.py [--transfer results/cdst_moiq/transfer.csv]
"""

from __future__ import annotations

import argparse
import collections
import csv
import json

import numpy as np
from common import TRANSFER_PREFERENCES, optimal_for

import moiq_jax
from moiq_jax.config import tuned
from moiq_jax.experts.cdst_oracle import expert_returns


def scores(returns, front, preferences) -> dict:
    """Optimal count, on-front count and mean regret of vector ``returns`` ``[P, d]`` at ``preferences``."""
    returns, optimal = np.asarray(returns), np.stack([optimal_for(front, w) for w in preferences])
    on_front = (np.abs(returns[:, None] - front[None]).max(-1) < 1e-3).any(1)
    return {"optimal": int(np.all(np.isclose(returns, optimal, atol=1e-3), axis=1).sum()),
            "on_front": int(on_front.sum()),
            "regret": float(np.mean(np.sum(preferences * (optimal - returns), axis=1)))}


def summary(score: dict) -> str:
    return f"{score['optimal']} optimal, {score['on_front']} on the front; regret {score['regret']:.3f}"


def expert_references(expert_preferences, expert_vectors, preferences) -> dict:
    """Vector returns ``[P, d]`` of the two learning-free references: the best expert behaviour for each
    preference, and the behaviour of the expert whose preference is nearest."""
    best = expert_vectors[np.argmax(preferences @ expert_vectors.T, axis=1)]
    nearest = np.argmin(np.linalg.norm(preferences[:, None] - expert_preferences[None], axis=-1), axis=1)
    return {"best expert behaviour": best, "nearest expert's behaviour": expert_vectors[nearest]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transfer", default="results/cdst_moiq/transfer.csv", help="cdst_moiq.py's transfer.csv")
    args = parser.parse_args()
    front = np.asarray(moiq_jax.envs.make("cdst").unwrapped.pareto_front())
    expert_preferences = np.asarray(tuned("cdst").preferences)
    expert_vectors = expert_returns(expert_preferences)
    preferences = TRANSFER_PREFERENCES

    references = expert_references(expert_preferences, expert_vectors, preferences)

    print("preference, optimum, best expert behaviour, its margin over the next expert behaviour")
    for w, best in zip(preferences, references["best expert behaviour"]):
        values = np.sort(expert_vectors @ w)[::-1]
        print(f"  {np.round(w, 2)} {optimal_for(front, w)} {best} {values[0] - values[1]:.3f}")

    print("of the 19: optimal for the preference, on the front; mean regret")
    for name, returns in references.items():
        print(f"  {name}: {summary(scores(returns, front, preferences))}")
    runs = collections.defaultdict(list)
    with open(args.transfer, newline="") as f:
        for row in csv.DictReader(f):
            runs[row["method"], int(row["seed"])].append(json.loads(row["vector_return"]))
    for (method, seed), returns in runs.items():
        print(f"  {method}, seed {seed}: {summary(scores(returns, front, preferences))}")


if __name__ == "__main__":
    main()

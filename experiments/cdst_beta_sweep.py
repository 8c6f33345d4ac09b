"""Which consensus weight helps MOIQ on cdst: best-model scalarised returns, whether all three experts are
matched exactly, and transfer (Pareto-optimal of the 19 preferences) per beta and seed, 100K env steps per
expert, all runs as one vmapped sweep.

    PYTHONPATH=. python experiments/cdst_beta_sweep.py 0.5,1,2 [--set NAME=VALUE ...] [--seeds 5] [--steps 100000]

Prints one line per run (beta, seed, scalarised returns, all exact, transfer count), then a JSON summary.
"""

from __future__ import annotations

import argparse
import ast
import json
import time

import cdst_moiq
import numpy as np

import moiq_jax
from moiq_jax.algos import moiq_train
from moiq_jax.config import tuned
from moiq_jax.experts.cdst_oracle import expert_returns


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("betas", help="comma-separated consensus weights")
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                        help="config fields over tuned('cdst'), values as Python literals (e.g. updates_per_step=2)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000, help="env steps per expert")
    args = parser.parse_args()
    betas = [float(b) for b in args.betas.split(",")]
    moiq_train.split_cpu_into_devices(len(betas) * args.seeds)  # one CPU device per run
    moiq_train.use_compilation_cache()  # a rerun loads the compiled programs
    changes = {name: ast.literal_eval(value) for name, value in (item.split("=", 1) for item in args.set)}
    config = tuned("cdst", total_steps=args.steps, **changes)
    print("config:", changes, flush=True)
    demos = moiq_train.load_demonstrations(config)
    preferences = np.asarray(demos.preferences)
    expert = (expert_returns(preferences) * preferences).sum(1)
    start = time.perf_counter()
    swept = moiq_train.sweep(config, beta=betas, seed=range(args.seeds), demos=demos)
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    optimal = np.stack([cdst_moiq.optimal_for(front, w) for w in cdst_moiq.TRANSFER_PREFERENCES])
    summary = {"seconds": time.perf_counter() - start}
    for run, (beta, seed) in enumerate(zip(swept["betas"], swept["seeds"])):
        params = cdst_moiq.run_index(swept["best_params"], run)
        scalar = (moiq_jax.evaluate(params, "cdst", preferences) * preferences).sum(1)
        transfer = moiq_jax.evaluate(params, "cdst", cdst_moiq.TRANSFER_PREFERENCES)
        hits = int(np.all(np.isclose(transfer, optimal, atol=1e-3), axis=1).sum())
        exact = bool(np.allclose(scalar, expert, atol=1e-3))
        summary[f"{beta}-{seed}"] = {"scalar": np.round(scalar, 2).tolist(), "exact": exact, "transfer": hits}
        print(beta, seed, np.round(scalar, 2), exact, hits, flush=True)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()

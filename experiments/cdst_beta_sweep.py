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

import common
import numpy as np

import moiq_jax


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("betas", help="comma-separated consensus weights")
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE",
                        help="config fields over tuned('cdst'), values as Python literals (e.g. updates_per_step=2)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000, help="env steps per expert")
    args = parser.parse_args()
    betas = [float(b) for b in args.betas.split(",")]
    common.start(len(betas) * args.seeds)  # one CPU device per run
    changes = {name: ast.literal_eval(value) for name, value in (item.split("=", 1) for item in args.set)}
    cdst = common.CdstSetup(total_steps=args.steps, **changes)
    print("config:", changes, flush=True)
    preferences, expert = cdst.preferences, cdst.expert_scalar
    start = time.perf_counter()
    swept = moiq_jax.sweep(cdst.config, beta=betas, seed=range(args.seeds), demos=cdst.demos)
    optimal = common.transfer_optima()
    summary = {"seconds": time.perf_counter() - start}
    for run, (beta, seed) in enumerate(zip(swept.runs["beta"], swept.runs["seed"])):
        params = common.run_index(swept.best_params, run)
        scalar = (moiq_jax.evaluate(params, "cdst", preferences) * preferences).sum(1)
        transfer = moiq_jax.evaluate(params, "cdst", common.TRANSFER_PREFERENCES)
        hits = int(np.all(np.isclose(transfer, optimal, atol=1e-3), axis=1).sum())
        exact = bool(np.allclose(scalar, expert, atol=1e-3))
        summary[f"{beta}-{seed}"] = {"scalar": np.round(scalar, 2).tolist(), "exact": exact, "transfer": hits}
        print(beta, seed, np.round(scalar, 2), exact, hits, flush=True)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()

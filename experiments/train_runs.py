"""Train part of a task's MOIQ sweep (some betas x seeds of ``paper_mujoco.task_sweep``'s grid) under a
protocol, one checkpointed sweep per beta, so that a sweep longer than a session is trained in parts, each
part resumable after a crash by the same command.

    PYTHONPATH=. python experiments/train_runs.py --env mo-halfcheetah --betas 0.5 5 --seed-list 0 1 [--protocol cpu]

Each beta's runs are trained in ``<cache>/<protocol>/<env>-moiq-beta<beta>``.
"""

from __future__ import annotations

import argparse
import pathlib

import paper_mujoco as paper

import moiq_jax
from moiq_jax.runtime import split_cpu_into_devices, use_compilation_cache
from moiq_jax.train import SWEEP_FILE


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, choices=paper.ENVS)
    parser.add_argument("--betas", type=float, nargs="+", default=list(paper.BETAS))
    parser.add_argument("--seed-list", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--protocol", default="cpu", choices=[p for p in paper.PROTOCOLS if p != "quick"])
    parser.add_argument("--cache", default="results/mujoco/sweeps")
    args = parser.parse_args()
    split_cpu_into_devices(len(args.seed_list))
    use_compilation_cache()
    config = paper.moiq_config(args.env, args.protocol)
    for beta in args.betas:
        run_dir = pathlib.Path(args.cache) / args.protocol / f"{args.env}-moiq-beta{beta:g}"
        result = moiq_jax.sweep(config, run_dir=str(run_dir), resume=(run_dir / SWEEP_FILE).exists(),
                                beta=[beta], seed=args.seed_list)
        print(f"{args.env} beta {beta:g} seeds {args.seed_list}: trained in {result.seconds:.0f}s ({run_dir})")


if __name__ == "__main__":
    main()

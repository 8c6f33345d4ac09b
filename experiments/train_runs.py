"""Train part of a task's sweep (some betas x seeds of one of ``paper_mujoco.SWEEPS``) under a protocol and keep
each finished run in the archive, so that a sweep longer than a session is trained in parts, each resumable
after a crash by the same command; the table and figure scripts then read the runs.

    PYTHONPATH=. python experiments/train_runs.py --env mo-halfcheetah --betas 0.5 5 --seed-list 0 1 [--protocol cpu]
    PYTHONPATH=. python experiments/train_runs.py --env mo-hopper --sweep iq_learn-1demo --seed-list 0

Runs the archive already holds are skipped; each beta's missing seeds train as one checkpointed sweep
(``paper_mujoco.train_runs``).
"""

from __future__ import annotations

import argparse

import paper_mujoco as paper

from moiq_jax.runtime import parse_args_on_cores


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, choices=paper.TASKS)
    parser.add_argument("--sweep", default="moiq", choices=paper.SWEEPS,
                        help="; ".join(f"{name}: {what}" for name, what in paper.SWEEPS.items()))
    parser.add_argument("--betas", type=float, nargs="+", help="default: all the sweep's (none for gail, iq_learn)")
    parser.add_argument("--seed-list", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--protocol", default="cpu", choices=[p for p in paper.PROTOCOLS if p != "quick"])
    parser.add_argument("--quick", action="store_true", help="the CI smoke size (kept under <cache>/quick/runs)")
    parser.add_argument("--cache", default="results/mujoco/sweeps", help="where runs train (checkpointed)")
    parser.add_argument("--archive", help="where finished runs are kept; default results/mujoco_<protocol>/runs")
    args = parse_args_on_cores(parser)
    config, sweep_betas = paper.sweep_of(args.env, paper.protocol_of(args), args.sweep)
    if sweep_betas is None and args.betas:
        parser.error(f"the {args.sweep} sweep has no beta")
    betas = sweep_betas if args.betas is None else args.betas
    trained = paper.train_runs(args.env, args, args.sweep, config, betas, args.seed_list)
    print(f"{args.env}: {len(trained)} runs trained, the others of the {len(betas or [None])} x "
          f"{len(args.seed_list)} asked for were kept already")


if __name__ == "__main__":
    main()

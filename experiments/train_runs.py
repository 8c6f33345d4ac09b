"""Train part of a task's MOIQ sweep (some betas x seeds of ``paper_mujoco.task_sweep``'s grid) under a
protocol and keep each finished run in the archive, so that a sweep longer than a session is trained in
parts, each resumable after a crash by the same command; the table and figure scripts then read the runs.

    PYTHONPATH=. python experiments/train_runs.py --env mo-halfcheetah --betas 0.5 5 --seed-list 0 1 [--protocol cpu]

Runs the archive already holds are skipped; each beta's missing seeds train as one checkpointed sweep
(``paper_mujoco.train_runs``).
"""

from __future__ import annotations

import argparse

import paper_mujoco as paper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, choices=paper.ENVS)
    parser.add_argument("--betas", type=float, nargs="+", default=list(paper.BETAS))
    parser.add_argument("--seed-list", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--protocol", default="cpu", choices=[p for p in paper.PROTOCOLS if p != "quick"])
    parser.add_argument("--cache", default="results/mujoco/sweeps", help="where runs train (checkpointed)")
    parser.add_argument("--archive", help="where finished runs are kept; default results/mujoco_<protocol>/runs")
    args = parser.parse_args()
    args.quick = False
    config = paper.moiq_config(args.env, args.protocol)
    trained = paper.train_runs(args.env, args, "moiq", config, args.betas, args.seed_list)
    print(f"{args.env}: {len(trained)} runs trained, the others of the {len(args.betas)} x {len(args.seed_list)} "
          f"asked for were kept already")


if __name__ == "__main__":
    main()

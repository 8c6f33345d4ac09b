"""What each kept MOIQ run did during training, read from its metrics (no evaluation, no training): per
preference the model chosen on the mean (what Table 1 re-evaluates), each preference's own best and the mean
of the last 20% of training, as 5-episode evaluations over the expert's return; and the consensus penalty and
critic loss (first, peak, last), the figures that say whether the penalty climbs.

    PYTHONPATH=. python experiments/run_summary.py results/mujoco_cpu_recipe_online_penalty/runs [--csv FILE]
    PYTHONPATH=. python experiments/run_summary.py --run-dirs RUN_DIR ... [--csv FILE]

Reads every ``<env>-moiq/<run>`` folder of the archive (``paper_mujoco.train_runs`` keeps them there), or the
``metrics.csv`` and ``config.json`` of run directories of ``moiq train`` (a pilot outside any protocol; its wall
time is not recorded there).
"""

from __future__ import annotations

import argparse
import csv
import json
import pathlib

import numpy as np
import paper_mujoco as paper

from moiq_jax.archive import RESULT_FILE, load_result
from moiq_jax.plots import read_metrics


def run_rows(folder: pathlib.Path, env: str, expert_vectors: np.ndarray) -> list[dict]:
    """One row per preference of the run kept in ``folder``; ``expert_vectors`` [E, d]: the experts' returns."""
    run = load_result(folder)
    history = {k: np.asarray(v) for k, v in run.history.items()}
    return summary_rows(env, folder.name, np.asarray(run.preferences), history["env_steps"],
                        history["eval_scalar_return"], history["penalty"], history["critic_loss"], run.seconds,
                        expert_vectors)


def run_dir_rows(run_dir: pathlib.Path) -> list[dict]:
    """One row per preference of a run directory of ``moiq train`` (its metrics.csv, one row per evaluation and
    preference, and its config.json's env), against the committed demonstrations of that env."""
    metrics = read_metrics(str(run_dir))
    env = json.loads((run_dir / "config.json").read_text())["env"]
    preferences = np.asarray([[float(w) for w in label.split()] for label in metrics.labels])
    per_step = lambda name: metrics.values[name][:, 0]  # the same for every preference (one model)
    return summary_rows(env, run_dir.name, preferences, metrics.steps, metrics.values["eval_scalar_return"],
                        per_step("penalty"), per_step("critic_loss"), None, paper.expert_returns(env))


def summary_rows(env: str, name: str, preferences: np.ndarray, steps: np.ndarray, returns: np.ndarray,
                 penalty: np.ndarray, critic_loss: np.ndarray, seconds: float | None,
                 expert_vectors: np.ndarray) -> list[dict]:
    """The rows of one run from its evaluations ``returns`` [evals, E] at ``steps`` and its per-evaluation
    ``penalty`` and ``critic_loss``; ``expert_vectors`` [E, d]: the experts' returns."""
    chosen = int(np.argmax(returns.mean(axis=1)))
    experts = (expert_vectors * preferences).sum(-1)  # each expert under its own preference
    last = paper.last_window_mean(steps, returns, axis=0)

    def ratio(value: float, expert: float) -> float:  # nan where the expert's return is about zero (stands)
        return round(value / abs(expert), 3) if abs(expert) >= 1 else float("nan")

    rows = []
    for e, preference in enumerate(preferences):
        expert = float(experts[e])
        rows.append({
            "env": env, "run": name, "preference": [round(float(w), 2) for w in preference],
            "env_steps": int(steps[-1]), "seconds": None if seconds is None else round(float(seconds)),
            "expert": round(expert, 1),
            "chosen_step": int(steps[chosen]), "chosen": round(float(returns[chosen, e]), 1),
            "chosen_ratio": ratio(float(returns[chosen, e]), expert),
            "own_best": round(float(returns[:, e].max()), 1),
            "own_best_ratio": ratio(float(returns[:, e].max()), expert),
            "last20": round(float(last[e]), 1), "last20_ratio": ratio(float(last[e]), expert),
            "penalty_first": round(float(penalty[0]), 3), "penalty_peak": round(float(penalty.max()), 3),
            "penalty_last": round(float(penalty[-1]), 3), "critic_loss_peak": round(float(critic_loss.max()), 2),
        })
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("archive", type=pathlib.Path, nargs="?",
                        help="a protocol's runs folder (results/mujoco_<protocol>/runs)")
    parser.add_argument("--run-dirs", type=pathlib.Path, nargs="+", default=[],
                        help="run directories of `moiq train` (MOIQ on a MuJoCo task), read from their metrics.csv")
    parser.add_argument("--csv", type=pathlib.Path, help="also write the rows here")
    args = parser.parse_args()
    if args.archive is None and not args.run_dirs:
        parser.error("give an archive of kept runs or --run-dirs")
    rows = []
    if args.archive is not None:
        folders = sorted(args.archive.glob(f"*-moiq/*/{RESULT_FILE}"))
        if not folders:
            raise SystemExit(f"{args.archive} holds no kept MOIQ runs (<env>-moiq/<run>/{RESULT_FILE})")
        envs = {path: path.parent.parent.name.removesuffix("-moiq") for path in folders}
        expert_vectors = {env: paper.expert_returns(env) for env in set(envs.values())}  # each demos file read once
        rows = [row for path, env in envs.items() for row in run_rows(path.parent, env, expert_vectors[env])]
    rows += [row for run_dir in args.run_dirs for row in run_dir_rows(run_dir)]
    print(f"{'env':<15} {'run':<15} {'preference':<16} {'expert':>8} {'chosen (step)':>17} {'own best':>14} "
          f"{'last 20%':>14} {'penalty first/peak/last':>24} {'critic loss peak':>17}")
    for r in rows:
        print(f"{r['env']:<15} {r['run']:<15} {r['preference']!s:<16} {r['expert']:8.0f} "
              f"{r['chosen']:7.0f} ({r['chosen_step'] // 1000:>3}K) {r['chosen_ratio']:5.2f} "
              f"{r['own_best']:7.0f} {r['own_best_ratio']:5.2f} {r['last20']:7.0f} {r['last20_ratio']:5.2f} "
              f"{r['penalty_first']:8.2f} {r['penalty_peak']:7.2f} {r['penalty_last']:7.2f} {r['critic_loss_peak']:17.2f}")
    print("returns: 5-episode evaluations during training, scalarised, then / |expert| (the demonstrations' mean)")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()

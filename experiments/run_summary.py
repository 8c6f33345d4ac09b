"""What each kept MOIQ run did during training, read from its metrics (no evaluation, no training): per
preference the model chosen on the mean (what Table 1 re-evaluates), each preference's own best and the mean
of the last 20% of training, as 5-episode evaluations over the expert's return; and the consensus penalty and
critic loss (first, peak, last), the figures that say whether the penalty climbs.

    PYTHONPATH=. python experiments/run_summary.py results/mujoco_cpu_recipe_online_penalty/runs [--csv FILE]

Reads every ``<env>-moiq/<run>`` folder of the archive (``paper_mujoco.train_runs`` keeps them there).
"""

from __future__ import annotations

import argparse
import csv
import pathlib

import numpy as np
import paper_mujoco as paper

from moiq_jax.archive import RESULT_FILE, load_result


def run_rows(folder: pathlib.Path, env: str, expert_vectors: np.ndarray) -> list[dict]:
    """One row per preference of the run kept in ``folder``; ``expert_vectors`` [E, d]: the experts' returns."""
    run = load_result(folder)
    history = run.history
    steps = np.asarray(history["env_steps"])
    returns = np.asarray(history["eval_scalar_return"])  # [evals, E]
    chosen = int(np.argmax(returns.mean(axis=1)))
    experts = (expert_vectors * np.asarray(run.preferences)).sum(-1)  # each expert under its own preference
    last = paper.last_window_mean(steps, returns, axis=0)
    penalty, critic_loss = (np.asarray(history[k]) for k in ("penalty", "critic_loss"))

    def ratio(value: float, expert: float) -> float:  # nan where the expert's return is about zero (stands)
        return round(value / abs(expert), 3) if abs(expert) >= 1 else float("nan")

    rows = []
    for e, preference in enumerate(np.asarray(run.preferences)):
        expert = float(experts[e])
        rows.append({
            "env": env, "run": folder.name, "preference": [round(float(w), 2) for w in preference],
            "env_steps": int(steps[-1]), "seconds": round(float(run.seconds)), "expert": round(expert, 1),
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
    parser.add_argument("archive", type=pathlib.Path, help="a protocol's runs folder (results/mujoco_<protocol>/runs)")
    parser.add_argument("--csv", type=pathlib.Path, help="also write the rows here")
    args = parser.parse_args()
    folders = sorted(args.archive.glob(f"*-moiq/*/{RESULT_FILE}"))
    if not folders:
        raise SystemExit(f"{args.archive} holds no kept MOIQ runs (<env>-moiq/<run>/{RESULT_FILE})")
    envs = {path: path.parent.parent.name.removesuffix("-moiq") for path in folders}
    expert_vectors = {env: paper.expert_returns(env) for env in set(envs.values())}  # each demos file read once
    rows = [row for path, env in envs.items() for row in run_rows(path.parent, env, expert_vectors[env])]
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

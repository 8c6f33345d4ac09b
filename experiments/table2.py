"""The paper's Table 2 on the MuJoCo tasks: MOIQ with beta = 0 against beta = 5, as the EWMA (alpha 0.1)
of the scalarised evaluation return at the end of training, averaged over seeds.

The EWMA starts at the first evaluation (the policy before learning), whose weight at the end is 0.9^(n - 1)
for n evaluations: about 3e-5 for the paper's 100, but 0.135 for the cpu protocol's 20, enough to pull the
end value far towards the untrained policy's. So each beta's mean return over the evaluations of the last
20% of training (``beta<b>_last``, ``paper_mujoco.last_window_mean``) is reported beside it, and the JSON
records that weight.

    PYTHONPATH=. python experiments/table2.py [--envs ...] [--seeds 3] [--protocol cpu|paper] [--quick] [--out DIR]

Uses the same cached sweeps as table1.py; writes ``table2.csv`` / ``.json`` and ``table2.png`` (EWMA
curves of both betas per setting).
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import paper_mujoco as paper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/table2")
    args = parser.parse_args()
    out = paper.out_dir(args, "table2")

    rows, curves = [], {}
    for env in args.envs:
        result = paper.task_sweep(env, args)
        raw = {beta: paper.evaluation_returns(result, beta) for beta in paper.BETAS}  # (steps, [seeds, evals, E])
        steps = raw[5.0][0]
        smoothed = {beta: (steps, paper.ewma(returns, axis=1)) for beta, (_, returns) in raw.items()}
        last = {beta: paper.last_window_mean(steps, returns) for beta, (_, returns) in raw.items()}
        first_weight = (1 - paper.EWMA_ALPHA) ** (len(steps) - 1)
        project = paper.PROJECT_BETA
        for e, w in enumerate(result.config.preferences):
            final = {beta: float(curve[:, -1, e].mean()) for beta, (_, curve) in smoothed.items()}
            change = 100 * (final[5.0] - final[0.0]) / abs(final[0.0])
            rows.append({"env": env, "preference": list(w), "beta0": round(final[0.0], 2), "beta5": round(final[5.0], 2),
                         "change_percent": round(change, 2), f"beta{project:g}": round(final[project], 2),
                         f"change_percent_beta{project:g}": round(100 * (final[project] - final[0.0]) / abs(final[0.0]), 2),
                         **{f"beta{beta:g}_last": round(float(last[beta][:, e].mean()), 2) for beta in paper.BETAS},
                         "env_steps": int(steps[-1]),
                         "paper_beta0": paper.PAPER_TABLE2[env][e][0], "paper_beta5": paper.PAPER_TABLE2[env][e][1]})
            curves[(env, e)] = (steps, {beta: curve[:, :, e] for beta, (_, curve) in smoothed.items()})
    better = sum(r["beta5"] > r["beta0"] for r in rows)
    project = f"beta{paper.PROJECT_BETA:g}"
    better_project = sum(r[project] > r["beta0"] for r in rows)
    last_better = sum(r["beta5_last"] > r["beta0_last"] for r in rows)
    paper.write_outputs(out, "table2", args, rows, settings_where_beta5_beats_beta0=better,
                        **{f"settings_where_{project}_beats_beta0": better_project},
                        settings_where_beta5_beats_beta0_last=last_better, first_evaluation_weight=round(first_weight, 6),
                        last_window=f"evaluations after {1 - paper.LAST_WINDOW:.0%} of the env steps")

    fig, axes = plt.subplots(1, len(curves), figsize=(3.2 * len(curves), 3), layout="constrained", squeeze=False)
    for ax, ((env, e), (steps, by_beta)) in zip(axes[0], curves.items()):
        for beta, runs in by_beta.items():
            ax.plot(steps, runs.mean(0), label=f"beta={beta:g}")
        ax.set_xlabel("env steps per expert")
        ax.set_title(f"{env}\n{list(paper.moiq_config(env).preferences[e])}", fontsize=8)
    axes[0][0].set_ylabel("EWMA scalarised return")
    axes[0][0].legend()
    fig.savefig(out / "table2.png", dpi=120)

    print(f"{'env':<15} {'preference':<18} {'beta=0':>9} {'beta=5':>9} {'change':>8} {project:>9} {'change':>8}"
          "   paper: beta=0 beta=5")
    for r in rows:
        print(f"{r['env']:<15} {r['preference']!s:<18} {r['beta0']:9.1f} {r['beta5']:9.1f} {r['change_percent']:7.1f}%"
              f" {r[project]:9.1f} {r['change_percent_' + project]:7.1f}%   {r['paper_beta0']:>12} {r['paper_beta5']:>6}")
    print(f"beta = 5 beats beta = 0 in {better} of {len(rows)} settings (paper: 10 of 15); {project}: {better_project}")
    print(f"the first evaluation's weight in the EWMA at the end: {first_weight:.3g}; mean over the last "
          f"{paper.LAST_WINDOW:.0%} of training (beta 0 / 5 / {paper.PROJECT_BETA:g}):")
    for r in rows:
        lasts = " / ".join(f"{r[f'beta{b:g}_last']:.1f}" for b in (0.0, 5.0, paper.PROJECT_BETA))
        print(f"{r['env']:<15} {r['preference']!s:<18} {lasts}")
    print(f"beta = 5 beats beta = 0 over the last {paper.LAST_WINDOW:.0%}: {last_better} of {len(rows)}")


if __name__ == "__main__":
    main()

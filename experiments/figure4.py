"""The paper's Figure 4 on the MuJoCo tasks: MOIQ (one model; the paper's beta = 5 and this
project's) against IQ-Learn (one model per
preference) from 1 demonstration per preference, EWMA (alpha 0.1) of the scalarised evaluation return, mean
and spread over seeds (the paper used 3).

    PYTHONPATH=. python experiments/figure4.py [--envs ...] [--seeds 3] [--protocol cpu|paper] [--quick] [--out DIR]

Both sweeps are cached beside table1.py's. Writes ``figure4.png`` and ``figure4.json`` (first evaluation's
return, final EWMA return, and mean return over the last 20% of training, per method and setting).
"""

from __future__ import annotations

import argparse
import json

import paper_mujoco as paper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    parser.set_defaults(seeds=3)
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/figure4")
    args = parser.parse_args()
    out = paper.out_dir(args, "figure4")

    def methods_of(env):
        moiq = paper.task_sweep(env, args, "moiq-1demo")
        return {**{f"MOIQ beta={beta:g}": paper.evaluation_returns(moiq, beta) for beta in paper.MOIQ_BETAS},
                "IQ-Learn": paper.evaluation_returns(paper.task_sweep(env, args, "iq_learn-1demo"), None)}

    returns = paper.curves_figure(args.envs, methods_of, out / "figure4.png", note=", 1 demonstration")
    paper.write_outputs(out, "figure4", args, None, **returns)
    print(json.dumps(returns, indent=1))


if __name__ == "__main__":
    main()

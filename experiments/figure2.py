"""The paper's Figure 2 on the MuJoCo tasks: learning curves of MOIQ (one model; the paper's beta =
5 and this project's) against GAIL (one
model per preference), 10 demonstrations per preference, EWMA (alpha 0.1) of the scalarised evaluation return,
mean and spread over seeds, with the experts' returns.

    PYTHONPATH=. python experiments/figure2.py [--envs ...] [--seeds 3] [--protocol cpu|paper] [--quick] [--out DIR]

MOIQ's runs are table1.py's cached sweep; GAIL's (paper_mujoco.gail_config) are cached beside them. Writes
``figure2.png`` and ``figure2.json`` (final EWMA return, and mean return over the last
20% of training, per method and setting).
"""

from __future__ import annotations

import argparse
import json

import paper_mujoco as paper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/figure2")
    args = parser.parse_args()
    out = paper.out_dir(args, "figure2")

    def methods_of(env):
        gail = paper.task_sweep(env, args, "gail", paper.gail_config(env, paper.protocol_of(args)), betas=None)
        moiq = paper.task_sweep(env, args)
        return {**{f"MOIQ beta={beta:g}": paper.evaluation_returns(moiq, beta) for beta in paper.MOIQ_BETAS},
                "GAIL": paper.evaluation_returns(gail, None)}

    final, last = paper.curves_figure(args.envs, methods_of, out / "figure2.png")
    paper.write_outputs(out, "figure2", args, None, final_ewma_return=final, final_last_window_return=last)
    print(json.dumps({"final_ewma_return": final, "final_last_window_return": last}, indent=1))


if __name__ == "__main__":
    main()

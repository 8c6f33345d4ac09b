"""The paper's Figure 2 on the MuJoCo tasks: learning curves of MOIQ (one model; the paper's beta =
5 and this project's) against GAIL (one
model per preference), 10 demonstrations per preference, EWMA (alpha 0.1) of the scalarised evaluation return,
mean and spread over seeds, with the experts' returns.

    PYTHONPATH=. python experiments/figure2.py [--envs ...] [--seeds 3] [--protocol cpu|paper] [--quick] [--out DIR]
        [--gail-protocol PROTOCOL]

MOIQ's runs are table1.py's cached sweep; GAIL's (paper_mujoco.gail_config) are cached beside them, or read from
``--gail-protocol``'s archive where GAIL's config is the same under both protocols (they differ in MOIQ alone). Writes
``figure2.png`` and ``figure2.json`` (first evaluation's return, final EWMA return, and mean return over the
last 20% of training, per method and setting).
"""

from __future__ import annotations

import argparse
import json

import paper_mujoco as paper


def gail_args(args, env: str) -> argparse.Namespace:
    """The command line under which GAIL's runs of ``env`` are read (or trained): ``args`` itself, or, with
    ``--gail-protocol``, that protocol's (its default archive), which must configure GAIL exactly as ``args``'s."""
    if args.gail_protocol is None or args.quick:
        return args
    ours, theirs = (paper.gail_config(env, p).to_dict() for p in (paper.protocol_of(args), args.gail_protocol))
    differ = sorted(k for k in ours if ours[k] != theirs[k])
    if differ:
        raise SystemExit(f"GAIL on {env} differs between the {paper.protocol_of(args)} and {args.gail_protocol} "
                         f"protocols ({', '.join(differ)}): their runs cannot be shared")
    return argparse.Namespace(**{**vars(args), "protocol": args.gail_protocol, "archive": None})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    paper.add_arguments(parser)
    parser.add_argument("--out", help="default: results/mujoco_<protocol>/figure2")
    parser.add_argument("--gail-protocol", choices=[p for p in paper.PROTOCOLS if p != "quick"],
                        help="read GAIL's runs from this protocol's archive (its GAIL config must be the same)")
    args = parser.parse_args()
    out = paper.out_dir(args, "figure2")

    def methods_of(env):
        gail = paper.task_sweep(env, gail_args(args, env), "gail")
        moiq = paper.task_sweep(env, args, betas=paper.MOIQ_BETAS)
        return {**{f"MOIQ beta={beta:g}": paper.evaluation_returns(moiq, beta) for beta in paper.MOIQ_BETAS},
                "GAIL": paper.evaluation_returns(gail, None)}

    returns = paper.curves_figure(args.envs, methods_of, out / "figure2.png")
    paper.write_outputs(out, "figure2", args, None, **returns,
                        gail_protocol=paper.protocol_of(gail_args(args, args.envs[0])))
    print(json.dumps(returns, indent=1))


if __name__ == "__main__":
    main()

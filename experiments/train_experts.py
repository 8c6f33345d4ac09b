"""SAC experts for a MuJoCo task, one per paper preference in one vmapped program, and 10 demonstrations
of each (paper sec. 5.1), compared with the paper's expert returns (its Table 1).

    PYTHONPATH=. python experiments/train_experts.py --env mo-hopper [--total-steps N] [--num-envs 128]
        [--updates-per-step 64] [--adopt-margin 0.1] [--time-limit SECONDS] [--run-dir DIR [--resume]]
        [--no-demos] [--out experiments/demos] [--cpu-cores 0]
    PYTHONPATH=. python experiments/train_experts.py --env mo-hopper --record   (demos from saved experts)

Training writes, after every evaluation, ``<out>/<env>-experts.npz`` (the best evaluated actor of each
expert and the config; ``save_experts``) and ``<out>/<env>-training.json`` (evaluation history, env
steps, seconds, device), so a run cut short keeps its experts. Then (or with ``--record``, from those
files) it writes ``<out>/<env>.npz`` (Demonstrations in the absorbing-state env, for
``moiq train --demos``) and ``<out>/<env>-experts.json`` (each expert's vector and scalarised
demonstration return beside the paper's). ``--time-limit`` stops training after the first evaluation
past that many seconds. With ``--run-dir`` the whole training state (replay buffers included) is
checkpointed after every evaluation, and ``--resume`` continues a cut run from its last one (the same
command with ``--resume`` added). The training record counts wall and process CPU seconds, both
summed over resumed parts.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import jax
import numpy as np

import moiq_jax
from moiq_jax.experts import sac
from moiq_jax.runtime import host_description, parse_args_on_cores


def train(args, out: pathlib.Path) -> None:
    changes = {name: getattr(args, name) for name in ("total_steps", "eval_interval", "learning_starts", "num_envs",
                                                      "updates_per_step", "seed", "adopt_margin")
               if getattr(args, name) is not None}
    config = sac.expert_config(args.env, **changes)
    config = config.replace(buffer_size=min(config.offpolicy.buffer_size, config.offpolicy.total_steps))
    device = jax.devices()[0]
    training = out / f"{args.env}-training.json"
    earlier = json.loads(training.read_text()) if args.resume and training.exists() else {}
    wall_before, cpu_before = earlier.get("seconds", 0.0), earlier.get("cpu_seconds", 0.0)
    print(f"{args.env}: SAC experts for {config.preferences}, up to {config.offpolicy.total_steps:,} env steps each, "
          f"on {device.platform} ({device.device_kind})", flush=True)
    start, cpu_start = time.perf_counter(), time.process_time()
    hosts = list(dict.fromkeys([*earlier.get("hosts", []), host_description()]))  # one per resumed part

    def keep(state, history):
        sac.save_experts(out / f"{args.env}-experts.npz", config, state.best_params.actor)
        steps = int(np.max(history[-1]["env_steps"]))
        record = {"env": args.env, "device": f"{device.platform} ({device.device_kind})",
                  "hosts": hosts,
                  "seconds": round(wall_before + time.perf_counter() - start, 1),
                  "cpu_seconds": round(cpu_before + time.process_time() - cpu_start, 1),
                  "env_steps_per_expert": steps,
                  "config": config.to_dict(),
                  "history": {k: [np.asarray(h[k], np.float64).round(3).tolist() if k in h else None for h in history]
                              for k in ("env_steps", "eval_scalar_return", "eval_return", "alpha", "adopted_from")}}
        training.write_text(json.dumps(record, indent=1))
        for expert, donor in enumerate(np.asarray(history[-1].get("adopted_from", [])).tolist()):
            if donor >= 0:
                print(f"  expert {config.preferences[expert]} continues from expert {config.preferences[donor]}'s "
                      "learner and replay", flush=True)
        print(f"  saved the best experts after {steps:,} env steps each ({record['seconds']:.0f}s wall, "
              f"{record['cpu_seconds']:.0f}s CPU)", flush=True)

    until = None if args.time_limit is None else (lambda _: time.perf_counter() - start > args.time_limit)
    moiq_jax.train(config, until=until, on_chunk=keep, run_dir=args.run_dir, resume=args.resume)


def record(args, out: pathlib.Path) -> None:
    config, actor = sac.load_experts(out / f"{args.env}-experts.npz")
    demos = sac.record_demonstrations(config, actor, args.num_demos, seed=config.seed)
    demos.save(out / f"{args.env}.npz")
    training = out / f"{args.env}-training.json"
    summary = json.loads(training.read_text()) if training.exists() else {}
    preferences = np.asarray(config.preferences)
    returns = demos.mean_returns().astype(np.float64)
    paper = sac.PAPER_EXPERT_RETURNS[args.env]
    summary["experts"] = [
        {"preference": w.tolist(), "vector_return": r.round(1).tolist(), "scalar_return": round(float(w @ r), 1),
         "paper_expert_return": p, "ratio_to_paper": round(float(w @ r) / p, 3)}
        for w, r, p in zip(preferences, returns, paper)]
    (out / f"{args.env}-experts.json").write_text(json.dumps(summary, indent=1))
    steps = summary.get("env_steps_per_expert")
    print(f"{args.env}: {args.num_demos} demonstrations per expert"
          + (f" (experts trained {steps:,} env steps each on {summary['device']})" if steps else ""))
    print(f"  {'preference':<18} {'demo return (vector)':<28} {'scalarised':>10} {'paper':>8} {'ratio':>6}")
    for e in summary["experts"]:
        print(f"  {e['preference']!s:<18} {e['vector_return']!s:<28} {e['scalar_return']:10.1f} "
              f"{e['paper_expert_return']:8.0f} {e['ratio_to_paper']:6.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", required=True, choices=sorted(sac.PAPER_EXPERT_RETURNS))
    parser.add_argument("--total-steps", type=int, help="env steps per expert (default: sac.EXPERT_SETTINGS)")
    parser.add_argument("--eval-interval", type=int)
    parser.add_argument("--learning-starts", type=int)
    parser.add_argument("--num-envs", type=int, help="parallel envs per expert")
    parser.add_argument("--updates-per-step", type=int, help="gradient updates per vectorised env step")
    parser.add_argument("--seed", type=int)
    parser.add_argument("--adopt-margin", type=float,
                        help="an expert another beats under its preference by more than this fraction of its best "
                             "evaluation continues from that one's learner (moiq_jax.algos.adoption; default: never)")
    parser.add_argument("--num-demos", type=int, default=10)
    parser.add_argument("--time-limit", type=float, help="stop after the first evaluation past this many seconds")
    parser.add_argument("--run-dir", help="checkpoint the training state here after every evaluation")
    parser.add_argument("--resume", action="store_true", help="continue the run in --run-dir from its last checkpoint")
    parser.add_argument("--no-demos", action="store_true", help="train only; record later with --record")
    parser.add_argument("--record", action="store_true", help="record demonstrations from saved experts only")
    parser.add_argument("--out", default="experiments/demos")
    args = parse_args_on_cores(parser)
    if args.resume and not args.run_dir:
        parser.error("--resume needs the --run-dir of the run to continue")
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if not args.record:
        train(args, out)
    if not args.no_demos:
        record(args, out)


if __name__ == "__main__":
    main()

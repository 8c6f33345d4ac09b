"""The ``moiq`` command."""

from __future__ import annotations

import argparse
import sys

import numpy as np


def _cmd_envs(args) -> int:
    from moiq_jax import envs

    specs = sorted(envs.registered().items())
    width = max(len("name"), *(len(name) for name, _ in specs))
    print(f"{'name':<{width}} {'obs':>4} {'actions':<13} {'reward_dim':>10} {'episode':>8}  description")
    for name, env_spec in specs:
        env = envs.make(name)
        actions = f"{env.num_actions} discrete" if env.discrete else f"{env.action_size}-D box"
        print(f"{name:<{width}} {env.observation_size:>4} {actions:<13} {env.reward_dim:>10} "
              f"{env_spec.episode_length:>8}  {env_spec.description}")
    return 0


def _format_vector(v) -> str:
    return "(" + ", ".join(f"{x:8.2f}" for x in np.asarray(v)) + ")"


def _cmd_rollout(args) -> int:
    import jax

    from moiq_jax import envs
    from moiq_jax.evaluate import episode_returns, random_policy

    env = envs.make(args.env)
    key = jax.random.key(args.seed)
    if args.policy == "random":
        out = episode_returns(env, random_policy(env), key, args.episodes)
        returns, lengths = np.asarray(out["returns"]), np.asarray(out["lengths"])
        print(f"{args.episodes} random-policy episodes of {args.env}: vector returns (objective 1, objective 2, ...)")
        for i, (ret, length) in enumerate(zip(returns, lengths)):
            print(f"  episode {i:3d}  return {_format_vector(ret)}  length {length:3d}")
        print(f"  mean         return {_format_vector(returns.mean(0))}  length {lengths.mean():5.1f}")
        return 0
    base = env.unwrapped
    if not hasattr(base, "optimal_policy"):
        print(f"error: env {args.env!r} has no optimal policy; use --policy random", file=sys.stderr)
        return 2
    print(f"optimal policy to each treasure of {args.env}: return (treasure, -steps) vs the exact front")
    front = {tuple(p) for p in base.pareto_front().tolist()}
    for treasure in base.sea_map.treasures():
        policy = base.optimal_policy(treasure)
        out = episode_returns(env, lambda k, obs, p=policy: p(obs), key, 1)
        ret = np.asarray(out["returns"][0])
        tag = "on the front" if tuple(ret.tolist()) in front else "dominated"
        print(f"  treasure at {treasure}: return {_format_vector(ret)}  {tag}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="moiq", description="Multi-objective inverse RL from several experts, in JAX.")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("envs", help="list the registered envs with their sizes")
    p.set_defaults(func=_cmd_envs)

    p = sub.add_parser("rollout", help="run a policy in an env and print vector returns")
    p.add_argument("--env", default="cdst", help="registered env name (see `moiq envs`); default: cdst")
    p.add_argument("--policy", choices=["random", "optimal"], default="random",
                   help="random actions, or the exact optimal policy to each treasure (DST-style envs)")
    p.add_argument("--episodes", type=int, default=8, help="episodes run side by side (random policy); default: 8")
    p.add_argument("--seed", type=int, default=0, help="random seed; default: 0")
    p.set_defaults(func=_cmd_rollout)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

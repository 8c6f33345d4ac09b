"""Wall time per 100K env steps of MOIQ on mo-hopper (3 experts, one model) against IQ-Learn (3 models), in
the same run, from the committed demonstrations.

    python benchmarks/mujoco_moiq_speed.py [--steps 4992] [--hidden 256 256] [--batch-size 256]

Both are compiled ahead (compile times printed apart) and timed over ``--steps`` env steps per expert, then
scaled to 100K; the config is experiments/paper_mujoco.py's (16 envs per expert, 16 updates per vectorised
step, evaluations excluded by one evaluation per run).
"""

from __future__ import annotations

import argparse
import pathlib
import platform
import time

import jax
import jax.numpy as jnp

from moiq_jax.algos import moiq_train
from moiq_jax.config import tuned

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "demos" / "mo-hopper.npz"


def seconds_per_run(config) -> tuple[float, float]:
    """(compile seconds, run seconds) of one whole ``train(key, beta)`` of ``config``."""
    trainer = moiq_train.make_train(config)
    key, beta = jax.random.PRNGKey(0), jnp.float32(config.beta)
    start = time.perf_counter()
    program = jax.jit(trainer.train).lower(key, beta).compile()
    compiled = time.perf_counter() - start
    start = time.perf_counter()
    jax.block_until_ready(program(key, beta))
    return compiled, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4_992, help="env steps per expert (a multiple of 16)")
    parser.add_argument("--hidden", type=int, nargs="+", default=[256, 256])
    parser.add_argument("--batch-size", type=int, default=256)
    args = parser.parse_args()
    config = tuned("mo-hopper", demos=str(DEMOS), total_steps=args.steps, eval_interval=args.steps, num_envs=16,
                   updates_per_step=16, learning_starts=0, buffer_size=args.steps, eval_episodes=1,
                   hidden_sizes=tuple(args.hidden), batch_size=args.batch_size)
    device = jax.devices()[0]
    print(f"{platform.machine()}, jax {jax.__version__} on {device.platform} ({device.device_kind}); mo-hopper, "
          f"3 experts, hidden {config.hidden_sizes}, batch {config.batch_size}, {args.steps} env steps per expert")
    times = {}
    for name, run_config in (("MOIQ (one model)", config), ("IQ-Learn (3 models)", config.replace(algo="iq_learn", beta=0.0))):
        compiled, seconds = seconds_per_run(run_config)
        times[name] = seconds * 100_000 / args.steps
        print(f"{name:<20} {times[name]:9.1f} s per 100K env steps per expert (compile {compiled:.0f} s)", flush=True)
    moiq, iq_learn = times.values()
    print(f"IQ-Learn / MOIQ wall time: {iq_learn / moiq:.2f}x")


if __name__ == "__main__":
    main()

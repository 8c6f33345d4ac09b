"""Compile time and wall time per 100K env steps per expert of MOIQ on mo-hopper (3 experts, one model) with
each MuJoCo backend, in the same run, from the committed demonstrations.

    python benchmarks/mujoco_moiq_speed.py [--backends mujoco mjx] [--steps 512] [--hidden 256 256]
        [--batch-size 256] [--iq-learn]

The whole ``train(key, hyper)`` program is compiled ahead (compile time printed apart) and timed over
``--steps`` env steps per expert, then scaled to 100K; the config is experiments/paper_mujoco.py's (16 envs
per expert, 16 updates per vectorised step, evaluations excluded by one evaluation per run), so the time
includes the updates, which cost most. ``--iq-learn`` adds IQ-Learn (3 models) on each backend.
"""

from __future__ import annotations

import argparse
import pathlib
import platform
import time

import jax
import jax.numpy as jnp

from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.config import tuned
from moiq_jax.train import algorithm_of

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "demos" / "mo-hopper.npz"


def seconds_per_run(config, backend: str) -> tuple[float, float]:
    """(compile seconds, run seconds) of one whole ``train(key, hyper)`` of ``config`` on ``backend``."""
    trainer = make_trainer(config.replace(env_backend=backend), algorithm_of(config))
    key, hyper = jax.random.PRNGKey(0), {name: jnp.float32(value) for name, value in trainer.hyper.items()}
    start = time.perf_counter()
    program = jax.jit(trainer.train).lower(key, hyper).compile()
    compiled = time.perf_counter() - start
    start = time.perf_counter()
    jax.block_until_ready(program(key, hyper))
    return compiled, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["mujoco", "mjx"], choices=["mujoco", "mjx"])
    parser.add_argument("--steps", type=int, default=512, help="env steps per expert (a multiple of 16)")
    parser.add_argument("--hidden", type=int, nargs="+", default=[256, 256])
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--iq-learn", action="store_true", help="also time IQ-Learn (3 models)")
    args = parser.parse_args()
    config = tuned("mo-hopper", demos=str(DEMOS), total_steps=args.steps, eval_interval=args.steps, num_envs=16,
                   updates_per_step=16, learning_starts=0, buffer_size=args.steps, eval_episodes=1,
                   hidden_sizes=tuple(args.hidden), batch_size=args.batch_size)
    device = jax.devices()[0]
    print(f"{platform.machine()}, jax {jax.__version__} on {device.platform} ({device.device_kind}); mo-hopper, "
          f"3 experts, hidden {config.offpolicy.hidden_sizes}, batch {config.offpolicy.batch_size}, {args.steps} env "
          "steps per expert")
    runs = [("MOIQ (one model)", config)]
    if args.iq_learn:
        runs.append(("IQ-Learn (3 models)", config.replace(algo="iq_learn", beta=0.0)))
    for backend in args.backends:
        for name, run_config in runs:
            compiled, seconds = seconds_per_run(run_config, backend)
            per_100k = seconds * 100_000 / args.steps
            print(f"{name:<20} env backend {backend!r:<8} compile {compiled:6.1f} s, {per_100k:9.1f} s per 100K env "
                  "steps per expert", flush=True)


if __name__ == "__main__":
    main()

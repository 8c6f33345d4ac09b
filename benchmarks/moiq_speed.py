"""MOIQ speed on continuous DST, in one run: throughput of ``train``, a vmapped sweep against the same
runs one after another, and the wall time until the policy reaches the experts' exact returns.

    python benchmarks/moiq_speed.py [--steps 10000] [--seeds 5] [--expert-steps 100000] [--cpu-devices N]

- Throughput: one compiled ``train(key, beta)`` of the cdst default config for ``--steps`` env steps per
  expert (compiled ahead, so compile time is reported apart): env steps/s (all experts) and updates/s.
- Sweep: betas {the tuned one, 0} x ``--seeds`` seeds for ``--steps`` steps as one vmapped program (``moiq_jax.sweep``'s
  program, its runs sharded over ``--cpu-devices`` host devices, by default one per run as ``moiq sweep`` does;
  in a child process, since the split must precede JAX's start) against the same runs one after another with
  one compiled single-run program on JAX's default single CPU device, in this process; both timed after
  compilation, compile times printed too; then both with compilation: separate runs with JAX's persistent
  compilation cache, as the ``moiq`` command keeps it (the first compiles, the others load the program;
  both timed in fresh processes), and without it (each ``train(config)`` call compiles its own program).
- One core: the single run, and ``--seeds`` runs vmapped, with the process pinned to one core: what
  spreading the runs over the cores alone would give, and what vmap gives per core.
- FLOP rate: XLA's count of one update's floating-point operations turned into GFLOP/s of the single run
  and of the sweep, beside a large matrix product's rate on the same cores (the most they give).
- Time to expert return: ``moiq_jax.train`` (compile included) until an evaluation in which every expert's
  deterministic policy gets exactly its expert's scalarised return, or ``--expert-steps`` steps.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import subprocess
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

import moiq_jax
from moiq_jax.algos import actor_critic, moiq
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.config import tuned
from moiq_jax.experts.cdst_oracle import expert_returns
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.networks import networks_for, observation_size
from moiq_jax.runtime import shard_runs, split_cpu_into_devices, use_compilation_cache
from moiq_jax.train import run_grid


def compiled(fn, *args):
    """``fn`` compiled ahead for ``args``, and the seconds compiling took."""
    start = time.perf_counter()
    program = jax.jit(fn).lower(*args).compile()
    return program, time.perf_counter() - start


def timed(program, *args):
    start = time.perf_counter()
    jax.block_until_ready(program(*args))
    return time.perf_counter() - start


def update_flops(config, learner) -> float:
    """XLA's floating-point operation count of one MOIQ update (all experts) at ``config``'s sizes."""
    c = config.offpolicy
    nets = networks_for(learner.params)
    optimisers = actor_critic.Optimisers(optax.adam(c.critic_lr), optax.adam(c.actor_lr), optax.adam(c.alpha_lr))
    settings = actor_critic.Settings(-float(nets.actor.action_size), c.tau, c.learn_alpha)
    num_experts, rows = len(config.preferences), 2 * c.batch_size
    obs, action = observation_size(learner.params), nets.actor.action_size
    batches = {"obs": jnp.zeros((num_experts, rows, obs)), "action": jnp.zeros((num_experts, rows, action)),
               "next_obs": jnp.zeros((num_experts, rows, obs)), "done": jnp.zeros((num_experts, rows)),
               "is_expert": jnp.tile(jnp.arange(rows) < c.batch_size, (num_experts, 1))}
    loss = moiq.ALGORITHM.critic_loss(config)

    def step(learner, batches, preferences, beta, key):
        objective = lambda critic, params, b, p, k: loss(critic, nets, params, b, p, {"beta": beta}, k)
        return actor_critic.update(learner, nets, optimisers, batches, preferences, key, settings, objective)

    cost = jax.jit(step).lower(learner, batches=batches, preferences=jnp.asarray(config.preferences),
                               beta=jnp.float32(config.moiq.beta), key=jax.random.PRNGKey(0)).compile().cost_analysis()
    return (cost[0] if isinstance(cost, list) else cost)["flops"]


def matmul_gflops(size: int = 2048, repeats: int = 10) -> float:
    """GFLOP/s of a large float32 matrix product on JAX's default device: what this machine's cores give
    at best, the yardstick for the updates' small products."""
    a = jnp.ones((size, size), jnp.float32)
    program, _ = compiled(lambda x: x @ x, a)
    seconds = min(timed(program, a) for _ in range(repeats))
    return 2 * size**3 / seconds / 1e9


def num_updates(config) -> int:
    """Gradient updates of one run: ``updates_per_step`` per vectorised env step once warm-up is over."""
    c = config.offpolicy
    iterations = c.total_steps // c.num_envs
    ready = sum((i + 1) * c.num_envs > c.learning_starts for i in range(iterations))
    return ready * c.updates_per_step


def timed_config(steps: int):
    """The tuned cdst config of the timed runs: ``steps`` env steps per expert."""
    return tuned("cdst").replace(total_steps=steps, eval_interval=min(steps, 5_000))


def timed_trainer(steps: int):
    """The timed config and its trainer, built from the config's demonstrations (for the child processes)."""
    config = timed_config(steps)
    return config, make_trainer(config, moiq.ALGORITHM, load_demonstrations(config))


def hyper(beta) -> dict:
    """The swept values of a MOIQ program: the consensus weight."""
    return {"beta": jnp.asarray(beta, jnp.float32)}


def sweep_grid(config, seeds: int) -> tuple[jax.Array, dict]:
    """Keys and hyperparameters of the sweep: {the tuned beta, 0} x ``seeds`` seeds."""
    runs = run_grid({"beta": [config.moiq.beta, 0.0], "seed": range(seeds)})
    return jnp.stack([jax.random.PRNGKey(int(seed)) for seed in runs["seed"]]), hyper(runs["beta"])


def in_child(call: str) -> dict:
    """``moiq_speed.<call>`` run in a fresh Python process without ``XLA_FLAGS`` (for settings that must
    precede JAX's start or its first compilation), and the JSON it printed."""
    script = (f"import json, sys; sys.path.insert(0, {str(pathlib.Path(__file__).parent)!r}); import moiq_speed; "
              f"print(json.dumps(moiq_speed.{call}))")
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR")}
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def compile_in_this_process(steps: int, cache_dir: str) -> dict:
    """Seconds to compile the single-run program with JAX's persistent compilation cache in ``cache_dir``
    (as the ``moiq`` command uses it): a compilation when the folder is new, a load when it holds the program."""
    use_compilation_cache(cache_dir)
    _, trainer = timed_trainer(steps)
    return {"compile": compiled(trainer.train, jax.random.PRNGKey(1), hyper(0.0))[1]}


def on_one_core(steps: int, seeds: int) -> dict:
    """With this process pinned to one core (call in a fresh process, before JAX starts its threads): run
    seconds of the single-run program, and of ``seeds`` runs as one vmapped program. The first says what one
    run gets from the other cores (so what spreading separate runs over the cores alone could give), the second
    what vmap gains per core."""
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    config, trainer = timed_trainer(steps)
    key, beta = jax.random.PRNGKey(0), hyper(config.moiq.beta)
    program, _ = compiled(trainer.train, key, beta)
    keys, betas = jnp.stack([jax.random.PRNGKey(seed) for seed in range(seeds)]), hyper([config.moiq.beta] * seeds)
    swept, _ = compiled(jax.vmap(trainer.train), keys, betas)
    return {"run": timed(program, key, beta), "vmapped": timed(swept, keys, betas)}


def sweep_in_this_process(steps: int, seeds: int, cpu_devices: int) -> dict:
    """With the CPU split into ``cpu_devices`` devices (call in a fresh process), the compile and run seconds
    of the sharded, vmapped sweep."""
    split_cpu_into_devices(cpu_devices)
    config, trainer = timed_trainer(steps)
    keys, betas = shard_runs(*sweep_grid(config, seeds))
    swept, compile_seconds = compiled(jax.vmap(trainer.train), keys, betas)
    return {"devices": jax.device_count(), "compile": compile_seconds, "run": timed(swept, keys, betas)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10_000, help="env steps per expert of the timed runs")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per beta in the sweep comparison")
    parser.add_argument("--expert-steps", type=int, default=100_000, help="step limit of the time-to-expert run")
    parser.add_argument("--cpu-devices", type=int, default=None,
                        help="devices the CPU is split into for the sweep (default: one per run, as `moiq sweep`)")
    args = parser.parse_args()

    config = timed_config(args.steps)
    demos = load_demonstrations(config)
    num_experts, c = len(config.preferences), config.offpolicy
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {jax.device_count()} "
          f"{jax.default_backend()} device(s); cdst, {num_experts} experts, hidden {c.hidden_sizes}, batch "
          f"{c.batch_size}+{c.batch_size} per expert, {c.num_envs} envs per expert")

    trainer = make_trainer(config, moiq.ALGORITHM, demos)
    key, beta = jax.random.PRNGKey(0), hyper(config.moiq.beta)
    single, compile_single = compiled(trainer.train, key, beta)
    seconds = timed(single, key, beta)
    updates = num_updates(config)
    print(f"train: {num_experts * args.steps / seconds:,.0f} env steps/s ({args.steps / seconds:,.0f} per expert), "
          f"{updates / seconds:,.0f} updates/s ({1e3 * seconds / updates:.2f} ms per update incl. env steps and "
          f"evaluations; {args.steps} steps per expert in {seconds:.1f} s, compile {compile_single:.1f} s)")

    keys, betas = sweep_grid(config, args.seeds)
    runs = len(keys)
    sequential_seconds = sum(timed(single, keys[r], jax.tree_util.tree_map(lambda x, r=r: x[r], betas))
                             for r in range(runs))
    sweep = in_child(f"sweep_in_this_process({args.steps}, {args.seeds}, {args.cpu_devices or runs})")
    print(f"sweep of {runs} runs (betas {config.moiq.beta:g}, 0 x {args.seeds} seeds): vmapped, CPU split into "
          f"{sweep['devices']} devices, {sweep['run']:.1f} s (compile {sweep['compile']:.1f} s) vs one after another "
          f"on JAX's default CPU device {sequential_seconds:.1f} s: {sequential_seconds / sweep['run']:.2f}x faster")
    with tempfile.TemporaryDirectory() as cache_dir:
        cold, warm = (in_child(f"compile_in_this_process({args.steps}, {cache_dir!r})")["compile"] for _ in range(2))
    swept = sweep["run"] + sweep["compile"]
    cached = sequential_seconds + cold + (runs - 1) * warm  # `moiq train` calls: the first compiles, the rest load
    uncached = sequential_seconds + runs * compile_single  # train(config) calls without the cache: a compile each
    print(f"with compilation: sweep {swept:.1f} s vs {runs} separate runs {cached:.1f} s with JAX's persistent "
          f"compilation cache as `moiq train` keeps it (the first compiles in {cold:.1f} s, the others load theirs in "
          f"{warm:.1f} s): {cached / swept:.2f}x faster; without the cache ({runs} x {compile_single:.1f} s of "
          f"compilation) {uncached:.1f} s: {uncached / swept:.2f}x")
    one_core = in_child(f"on_one_core({args.steps}, {args.seeds})")
    cores = len(os.sched_getaffinity(0))
    print(f"one core: one run {one_core['run']:.1f} s against {seconds:.1f} s on all {cores} (the {runs} runs spread "
          f"one per core at that pace, without vmap, would be {cores * seconds / one_core['run']:.2f}x faster than one "
          f"after another; the vmapped sweep: {sequential_seconds / sweep['run']:.2f}x); {args.seeds} runs vmapped "
          f"{one_core['vmapped']:.1f} s against {args.seeds * one_core['run']:.1f} s one after another: "
          f"{args.seeds * one_core['run'] / one_core['vmapped']:.2f}x from vmap per core")
    flops = update_flops(config, trainer.init(key).learner)
    single_rate, sweep_rate, peak = flops * updates / seconds / 1e9, flops * updates * runs / sweep["run"] / 1e9, matmul_gflops()
    print(f"one update: {flops / 1e6:.0f} MFLOP (XLA's count); updates ran at {single_rate:.1f} GFLOP/s in one run and "
          f"{sweep_rate:.1f} GFLOP/s in the sweep, against {peak:.0f} GFLOP/s of a 2048x2048 float32 matrix product "
          f"here ({100 * single_rate / peak:.0f}% and {100 * sweep_rate / peak:.0f}%; a 3x sweep needs "
          f"{100 * 3 * single_rate / peak:.0f}%)")

    target = (expert_returns(np.asarray(config.preferences)) * np.asarray(config.preferences)).sum(1)
    reached = lambda metrics: np.allclose(metrics["eval_scalar_return"], target, atol=1e-3)
    expert_config = tuned("cdst").replace(total_steps=args.expert_steps)
    result = moiq_jax.train(expert_config, demos, log=None, until=reached)
    steps = int(result.history["env_steps"][-1])
    if reached({k: v[-1] for k, v in result.history.items()}):
        print(f"time to expert return (all {num_experts} preferences exact): {result.seconds:.1f} s "
              f"({steps} env steps per expert, compile included)")
    else:
        print(f"expert return not reached in {steps} env steps per expert ({result.seconds:.1f} s); final "
              f"scalarised returns {np.round(result.history['eval_scalar_return'][-1], 2).tolist()} vs expert "
              f"{np.round(target, 2).tolist()}")


if __name__ == "__main__":
    main()

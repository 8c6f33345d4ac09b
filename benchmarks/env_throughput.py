"""Env steps per second: moiq_jax's jitted, vmapped envs against MO-Gymnasium's Python loop, same run.

    python benchmarks/env_throughput.py [--num-envs 4096] [--steps 1000] [--gym-seconds 5]
    python benchmarks/env_throughput.py --mujoco [--mujoco-envs 1 64 1024] [--mujoco-steps 20]

Random actions are drawn inside the measured loop on both sides (one draw per step for the whole
batch, as Gymnasium draws one per step); episodes auto-reset on both sides.
"""

from __future__ import annotations

import argparse
import platform
import time

import jax

from moiq_jax import envs


def random_actions(env, key, num_envs):
    if env.discrete:
        return jax.random.randint(key, (num_envs,), 0, env.num_actions)
    return jax.random.uniform(key, (num_envs, env.action_size), minval=-1.0, maxval=1.0)


def jax_steps_per_second(name: str, num_envs: int, steps: int, repeats: int = 3) -> float:
    """Steps/s of ``num_envs`` copies of env ``name`` stepped ``steps`` times inside one ``lax.scan``."""
    env = envs.make(name)
    batched = envs.VmapWrapper(envs.AutoReset(env), num_envs)

    @jax.jit
    def run(key):
        def body(state, k):
            action = random_actions(env, k, num_envs)
            nxt = batched.step(state, action)
            return nxt, nxt.reward.sum()

        _, rewards = jax.lax.scan(body, batched.reset(key), jax.random.split(key, steps))
        return rewards.sum()

    run(jax.random.key(0)).block_until_ready()  # compile
    best = float("inf")
    for i in range(repeats):
        start = time.perf_counter()
        run(jax.random.key(i + 1)).block_until_ready()
        best = min(best, time.perf_counter() - start)
    return num_envs * steps / best


def gym_steps_per_second(gym_id: str, seconds: float) -> float:
    """Steps/s of one MO-Gymnasium env in a Python loop with random actions, resetting at episode ends."""
    import mo_gymnasium as mo_gym

    env = mo_gym.make(gym_id)
    env.reset(seed=0)
    env.action_space.seed(0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(1000):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
        steps += 1000
    return steps / (time.perf_counter() - start)


MUJOCO_ENVS = {
    "mo-hopper": "mo-hopper-v5",
    "mo-walker2d": "mo-walker2d-v5",
    "mo-halfcheetah": "mo-halfcheetah-v5",
    "mo-ant": "mo-ant-v5",
}


def mujoco_report(names, batch_sizes, steps, gym_seconds) -> None:
    """Env-steps/s of the MJX envs at each batch size against MO-Gymnasium's Python loop, same run."""
    for name in names:
        theirs = gym_steps_per_second(MUJOCO_ENVS[name], gym_seconds) if gym_seconds > 0 else None
        if theirs is not None:
            print(f"{name:<15} MO-Gymnasium (Python loop): {theirs:10,.0f} env-steps/s", flush=True)
        for num_envs in batch_sizes:
            ours = jax_steps_per_second(name, num_envs, steps, repeats=1)
            ratio = f"  ({ours / theirs:5.2f}x MO-Gymnasium)" if theirs is not None else ""
            print(f"{name:<15} moiq_jax {num_envs:6d} envs:        {ours:10,.0f} env-steps/s{ratio}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--gym-seconds", type=float, default=5.0,
                        help="seconds of MO-Gymnasium's loop to time; 0 skips it (where it is not installed)")
    parser.add_argument("--mujoco", action="store_true", help="benchmark the MJX MuJoCo envs instead of DST")
    parser.add_argument("--mujoco-envs", nargs="+", default=list(MUJOCO_ENVS), choices=list(MUJOCO_ENVS))
    parser.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 1024])
    parser.add_argument("--mujoco-steps", type=int, default=20, help="steps per measured scan (MuJoCo envs)")
    args = parser.parse_args()

    print(f"machine: {platform.machine()}, jax {jax.__version__} on {jax.devices()[0].platform}, "
          f"{jax.device_count()} device(s)")
    if args.mujoco:
        mujoco_report(args.mujoco_envs, args.batch_sizes, args.mujoco_steps, args.gym_seconds)
        return
    ours = jax_steps_per_second("dst", args.num_envs, args.steps)
    theirs = gym_steps_per_second("deep-sea-treasure-v0", args.gym_seconds)
    print(f"dst   moiq_jax ({args.num_envs} envs, vmap in lax.scan): {ours:14,.0f} env-steps/s")
    print(f"dst   MO-Gymnasium (Python loop):                {theirs:14,.0f} env-steps/s")
    print(f"dst   ratio: {ours / theirs:,.0f}x (goal: at least 100x)")
    cdst = jax_steps_per_second("cdst", args.num_envs, args.steps)
    print(f"cdst  moiq_jax ({args.num_envs} envs, vmap in lax.scan): {cdst:14,.0f} env-steps/s")


if __name__ == "__main__":
    main()

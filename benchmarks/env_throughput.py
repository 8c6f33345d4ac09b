"""Env steps per second: moiq_jax's jitted, vmapped envs against MO-Gymnasium's Python loop, same run.

    python benchmarks/env_throughput.py [--num-envs 4096] [--steps 1000] [--gym-seconds 5]
    python benchmarks/env_throughput.py --mujoco [--mujoco-envs mo-hopper ...] [--batch-sizes 1 64 1024]
        [--mjx-batch-sizes 64] [--mujoco-env-steps 20000]

Random actions are drawn inside the measured loop on both sides (one draw per step for the whole
batch, as Gymnasium draws one per step); episodes auto-reset on both sides.
"""

from __future__ import annotations

import argparse
import platform
import time

import jax
import numpy as np

from moiq_jax import envs


def random_actions(env, key, num_envs):
    if env.discrete:
        return jax.random.randint(key, (num_envs,), 0, env.num_actions)
    return jax.random.uniform(key, (num_envs, env.action_size), minval=-1.0, maxval=1.0)


def jax_steps_per_second(name: str, num_envs: int, steps: int, repeats: int = 3, **make_kwargs) -> float:
    """Steps/s of ``num_envs`` copies of env ``name`` stepped ``steps`` times inside one ``lax.scan``."""
    env = envs.make(name, **make_kwargs)
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


def gym_steps_per_second(gym_id: str, seconds: float) -> tuple[float, float]:
    """Steps/s of one MO-Gymnasium env in a Python loop with random actions, resetting at episode ends,
    and the mean length of the episodes that ended."""
    import mo_gymnasium as mo_gym

    env = mo_gym.make(gym_id)
    env.reset(seed=0)
    env.action_space.seed(0)
    steps, episodes, start = 0, 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(1000):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset()
                episodes += 1
        steps += 1000
    return steps / (time.perf_counter() - start), steps / max(episodes, 1)


def rollout_steps_per_second(name: str, num_envs: int, steps: int, repeats: int = 3) -> float:
    """Env-steps/s of raw ``mujoco.rollout.Rollout`` on all CPUs: ``num_envs`` open-loop random-control
    rollouts of ``steps`` env steps (``frame_skip`` physics steps each) from ``qpos0``, in one call: MuJoCo C's
    limit here (no resets, no rewards, no JAX). Give ``steps`` the random-action episodes' mean length, so
    that the states visited (and so the contacts solved) are those of the auto-reset workload."""
    import mujoco
    from mujoco import rollout

    from moiq_jax.envs.mujoco import TASKS
    from moiq_jax.envs.mujoco.native import default_threads

    task = TASKS[name]()
    model, nthread = task.mj_model, default_threads()
    data = [mujoco.MjData(model) for _ in range(nthread)]
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    state0 = np.zeros(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data[0], state0, spec)
    rng = np.random.default_rng(0)
    control = np.repeat(rng.uniform(-1, 1, (num_envs, steps, 1, model.nu)), task.frame_skip, axis=2)
    control = control.reshape(num_envs, steps * task.frame_skip, model.nu)
    best = float("inf")
    with rollout.Rollout(nthread=nthread) as pool:
        for _ in range(repeats):
            start = time.perf_counter()
            pool.rollout(model, data, np.tile(state0, (num_envs, 1)), control)
            best = min(best, time.perf_counter() - start)
    return num_envs * steps / best


MUJOCO_ENVS = {
    "mo-hopper": "mo-hopper-v5",
    "mo-walker2d": "mo-walker2d-v5",
    "mo-halfcheetah": "mo-halfcheetah-v5",
    "mo-ant": "mo-ant-v5",
}


def mujoco_report(names, batch_sizes, env_steps, mjx_envs, gym_seconds) -> None:
    """Env-steps/s of each MuJoCo task: the native backend at each batch size, MJX, MO-Gymnasium's Python
    loop and raw ``mujoco.rollout``, measured in this run, with ratios."""
    for name in names:
        theirs, length = gym_steps_per_second(MUJOCO_ENVS[name], max(gym_seconds, 1.0))
        length = round(length)
        raw = rollout_steps_per_second(name, max(64, env_steps // length), length)
        print(f"{name:<15} random-action episodes: {length} steps on average (MO-Gymnasium)")
        rows = [("MO-Gymnasium (Python loop, 1 env)", theirs if gym_seconds > 0 else None),
                (f"raw mujoco.rollout, episodes of {length}", raw)]
        for num_envs in batch_sizes:
            steps = min(2000, max(10, env_steps // num_envs))
            rows.append((f"native {num_envs} envs", jax_steps_per_second(name, num_envs, steps, backend="mujoco")))
        for num_envs in mjx_envs:
            ours = jax_steps_per_second(name, num_envs, 10, repeats=1, backend="mjx")
            rows.append((f"mjx {num_envs} envs (solver 'fast')", ours))
        for what, rate in rows:
            if rate is None:
                continue
            ratios = f"{rate / theirs:6.2f}x MO-Gymnasium" if gym_seconds > 0 else ""
            ratios += f"  {rate / raw:5.2f}x raw rollout"
            print(f"{name:<15} {what:<36} {rate:10,.0f} env-steps/s  {ratios}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=4096)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--gym-seconds", type=float, default=5.0,
                        help="seconds of MO-Gymnasium's loop to time; 0 skips it (DST; MuJoCo: 1 s for episode lengths)")
    parser.add_argument("--mujoco", action="store_true", help="benchmark the MuJoCo envs (both backends) instead")
    parser.add_argument("--mujoco-envs", nargs="+", default=list(MUJOCO_ENVS), choices=list(MUJOCO_ENVS))
    parser.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 1024], help="native backend")
    parser.add_argument("--mjx-batch-sizes", type=int, nargs="*", default=[64])
    parser.add_argument("--mujoco-env-steps", type=int, default=20_000,
                        help="env steps per measured scan (all envs; 10 to 2,000 steps each)")
    args = parser.parse_args()

    print(f"machine: {platform.machine()}, jax {jax.__version__} on {jax.devices()[0].platform}, "
          f"{jax.device_count()} device(s)")
    if args.mujoco:
        mujoco_report(args.mujoco_envs, args.batch_sizes, args.mujoco_env_steps, args.mjx_batch_sizes,
                      args.gym_seconds)
        return
    ours = jax_steps_per_second("dst", args.num_envs, args.steps)
    theirs = gym_steps_per_second("deep-sea-treasure-v0", args.gym_seconds)[0]
    print(f"dst   moiq_jax ({args.num_envs} envs, vmap in lax.scan): {ours:14,.0f} env-steps/s")
    print(f"dst   MO-Gymnasium (Python loop):                {theirs:14,.0f} env-steps/s")
    print(f"dst   ratio: {ours / theirs:,.0f}x (goal: at least 100x)")
    cdst = jax_steps_per_second("cdst", args.num_envs, args.steps)
    print(f"cdst  moiq_jax ({args.num_envs} envs, vmap in lax.scan): {cdst:14,.0f} env-steps/s")


if __name__ == "__main__":
    main()

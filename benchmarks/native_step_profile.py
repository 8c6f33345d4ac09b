"""Where one batched step of the native MuJoCo backend spends its time, against raw ``mujoco.rollout``.

    python benchmarks/native_step_profile.py [--env mo-hopper] [--num-envs 64] [--calls 300]

Per call of ``num_envs`` env steps, in ms: the step inside a jitted ``lax.scan`` with auto-reset (as
``env_throughput.py`` times it), the host function ``Simulator.step`` alone, its MuJoCo work
(``Simulator.run_chunks`` on all threads and on one), and raw ``mujoco.rollout`` for as many env steps in
episodes of the random-action length. The scan's excess over the host function is JAX's ``pure_callback``
round trip; the host function's excess over ``run_chunks`` is the task's rules and the state's conversions.
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np
from env_throughput import MUJOCO_ENVS, gym_steps_per_second, jax_steps_per_second, rollout_steps_per_second

from moiq_jax import envs
from moiq_jax.envs.mujoco.native import simulator


def ms_per_call(fn, calls: int, repeats: int = 5) -> float:
    """The best of ``repeats`` mean times of ``calls`` calls (as the scan and rollout figures are best of 3)."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - start) / calls * 1e3)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="mo-hopper", choices=list(MUJOCO_ENVS))
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--calls", type=int, default=100, help="per repeat; best of 5 repeats")
    args = parser.parse_args()
    n = args.num_envs

    env = envs.make(args.env, backend="mujoco")
    state = envs.VmapWrapper(envs.AutoReset(env), n).reset(jax.random.key(0))
    sim, one_thread = env.sim, simulator(type(env.task), 1)
    bits, pending = np.asarray(state.env_state.bits), np.asarray(state.env_state.pending)
    action = np.random.default_rng(0).uniform(-1, 1, (n, env.action_size)).astype(np.float32)
    values = env.values(state)
    inputs = np.concatenate([values[:, :sim.nstate], action.astype(np.float64)], axis=1)
    out = np.empty_like(values)
    cfrc = np.empty((n, env.mj_model.nbody, 6)) if sim.task.contact_forces else None

    length = round(gym_steps_per_second(MUJOCO_ENVS[args.env], 1.0)[1])
    rows = [
        ("step in a jitted lax.scan (auto-reset)", n / jax_steps_per_second(args.env, n, 400, backend="mujoco") * 1e3),
        ("host Simulator.step", ms_per_call(lambda: sim.step(bits, pending, action), args.calls)),
        (f"MuJoCo work, {sim.nthread} threads (run_chunks)", ms_per_call(lambda: sim.run_chunks(n, inputs, out, cfrc),
                                                                       args.calls)),
        ("MuJoCo work, 1 thread", ms_per_call(lambda: one_thread.run_chunks(n, inputs, out, cfrc), args.calls)),
        (f"raw mujoco.rollout, episodes of {length}", n / rollout_steps_per_second(args.env, max(64, n), length) * 1e3),
    ]
    print(f"{args.env}, {n} envs: ms per call of {n} env steps (jax {jax.__version__} on {jax.devices()[0].platform})")
    raw = rows[-1][1]
    for what, ms in rows:
        print(f"  {what:<42} {ms:7.3f} ms   {ms / raw:5.2f}x raw rollout")
    scan, host, work = (ms for _, ms in rows[:3])
    print(f"  {'JAX pure_callback round trip (scan - host)':<42} {scan - host:7.3f} ms")
    print(f"  {'rules and conversions (host - MuJoCo work)':<42} {host - work:7.3f} ms")


if __name__ == "__main__":
    main()

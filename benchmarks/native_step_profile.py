"""Where one batched step of the native MuJoCo backend spends its time, against raw ``mujoco.rollout``.

    python benchmarks/native_step_profile.py [--env mo-hopper] [--num-envs 64] [--batches 200]

Per call of ``num_envs`` env steps, in ms: the step inside a jitted ``lax.scan`` with auto-reset (as
``env_throughput.py`` times it); then, over the inputs that scan's first ``batches`` calls received
(so the same states and contacts), the host function ``Simulator.step`` alone and its MuJoCo work
(``Simulator.advance``) on each engine the task allows, on all threads and on one; and raw
``mujoco.rollout`` for as many env steps in episodes of the random-action length. The scan's excess
over the host function is the callback's round trip and the scan's own XLA work (actions, resets);
the host function's excess over the MuJoCo work is the task's rules and the state's conversions. Last,
the fixed cost per call of ``pure_callback`` and of ``buffer_callback`` (which the step uses on a CPU), each
with a callback that only fills the step's outputs with constants.
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from env_throughput import MUJOCO_ENVS, gym_steps_per_second, jax_steps_per_second, rollout_steps_per_second

from moiq_jax import envs
from moiq_jax.envs.mujoco.native import ENGINES, simulator


def ms_per_call(fn, batches: list, repeats: int = 5) -> float:
    """The best of ``repeats`` mean times of ``fn(*batch)`` over ``batches`` (the scan and rollout figures are
    best of 3)."""
    fn(*batches[0])
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for batch in batches:
            fn(*batch)
        best = min(best, (time.perf_counter() - start) / len(batches) * 1e3)
    return best


def constant_callback_ms(env, batch, kind: str, calls: int = 1000) -> float:
    """ms per call of a host callback that only fills the step's outputs with constants, ``calls`` calls in a jitted
    ``lax.scan`` over the envs of ``batch`` (bits, pending, action): the fixed cost of ``pure_callback`` or
    ``buffer_callback`` alone."""
    from jax.experimental.buffer_callback import buffer_callback

    sim = env.sim
    outputs = sim.step(*batch)
    shapes = tuple(jax.ShapeDtypeStruct(x.shape[1:], x.dtype) for x in outputs)

    def fill(ctx, out, *inputs):
        for buffer, value in zip(out, outputs):
            np.asarray(buffer)[...] = value

    def one(bits, pending, action):
        if kind == "pure_callback":
            return jax.pure_callback(lambda *inputs: outputs, shapes, bits, pending, action, vmap_method="broadcast_all")
        return buffer_callback(fill, shapes, vmap_method="broadcast_all")(bits, pending, action)

    @jax.jit
    def run(bits, pending, action):
        def body(carry, _):
            bits, _, reward, done = jax.vmap(one)(*carry)
            return (bits, carry[1] + reward.sum(), carry[2]), done.sum()

        return jax.lax.scan(body, (bits, pending, action), None, length=calls)[1].sum()

    bits, pending, action = (jnp.asarray(x) for x in batch)
    run(bits, pending, action).block_until_ready()
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        run(bits, pending, action).block_until_ready()
        best = min(best, time.perf_counter() - start)
    return best / calls * 1e3


def visited_inputs(env, n: int, count: int) -> list:
    """The (bits, pending, action) of the first ``count`` steps of ``n`` auto-reset envs under random actions."""
    batched = envs.VmapWrapper(envs.AutoReset(env), n)
    step, state = jax.jit(batched.step), batched.reset(jax.random.key(0))
    rng, visited = np.random.default_rng(0), []
    for _ in range(count):
        action = rng.uniform(-1, 1, (n, env.action_size)).astype(np.float32)
        visited.append((np.asarray(state.env_state.bits), np.asarray(state.env_state.pending), action))
        state = step(state, action)
    return visited


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="mo-hopper", choices=list(MUJOCO_ENVS))
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--batches", type=int, default=200, help="visited inputs timed, best of 5 passes")
    args = parser.parse_args()
    n = args.num_envs

    env = envs.make(args.env, backend="mujoco").unwrapped
    sim = env.sim
    visited = visited_inputs(env, n, args.batches)
    cfrc = np.empty((n, env.mj_model.nbody, 6)) if sim.task.contact_forces else None
    out = np.empty((n, sim.width))

    work = [(sim.inputs_of(*batch)[2],) for batch in visited]
    engines = [engine for engine in ENGINES if engine == "loop" or not sim.task.contact_forces]
    length = round(gym_steps_per_second(MUJOCO_ENVS[args.env], 1.0)[1])
    rows = [
        ("step in a jitted lax.scan (auto-reset)", n / jax_steps_per_second(args.env, n, 400, backend="mujoco") * 1e3),
        ("host Simulator.step", ms_per_call(sim.step, visited)),
    ]
    for engine in sorted(engines, key=lambda e: e != sim.engine):  # the env's own engine first
        for nthread in dict.fromkeys((sim.nthread, 1)):
            worker = simulator(type(sim.task), nthread, engine)
            rows.append((f"MuJoCo work, {engine} engine, {nthread} thread{'s' * (nthread > 1)}",
                         ms_per_call(lambda inputs, w=worker: w.advance(n, inputs, out, cfrc), work)))
    rows.append((f"raw mujoco.rollout, episodes of {length}",
                 n / rollout_steps_per_second(args.env, max(64, n), length) * 1e3))
    print(f"{args.env}, {n} envs: ms per call of {n} env steps (jax {jax.__version__} on {jax.devices()[0].platform}, "
          f"mujoco {mujoco.__version__}; the env's engine: {sim.engine})")
    raw = rows[-1][1]
    for what, ms in rows:
        print(f"  {what:<44} {ms:7.3f} ms   {ms / raw:5.2f}x raw rollout")
    scan, host, own_work = (ms for _, ms in rows[:3])
    print(f"  {'callback round trip and XLA work (scan - host)':<44} {scan - host:7.3f} ms")
    for kind in ("pure_callback", "buffer_callback"):
        print(f"  {f'a {kind} filling constants, per call':<44} {constant_callback_ms(env, visited[0], kind):7.3f} ms")
    print(f"  {'rules and conversions (host - MuJoCo work)':<44} {host - own_work:7.3f} ms")


if __name__ == "__main__":
    main()

"""MJX's solver presets against the native (MuJoCo C) backend: one-step errors from identical states, and
the committed SAC experts' mean returns on each backend, in the same run.

    python benchmarks/mjx_solver.py [--tasks mo-hopper ...] [--solvers mujoco fast] [--states 64]
        [--episodes 20] [--expert-solvers fast]

One-step errors: ``--states`` states visited by random-action episodes of the native backend (auto-reset,
after 10-40 steps), each started on both backends with ``state_at(qpos, qvel)`` (MJX: float32) and stepped
once with the same random action; the largest and the median absolute difference of the observation and of
the reward vector. Expert returns: each committed expert (experiments/demos/<task>-experts.npz) for
``--episodes`` episodes to termination or the time limit (``evaluate.preference_returns``), deterministic
actions, the same reset keys on both backends; the mean vector return, the mean scalarised one with its standard
error (episodes' standard deviation / sqrt(episodes)), and the relative gap of the scalarised means with the
standard error of that difference (the two means taken as independent: the episodes diverge chaotically).
"""

from __future__ import annotations

import argparse
import pathlib
import platform
import time

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import envs
from moiq_jax.evaluate import preference_returns
from moiq_jax.experts import sac as sac_experts
from moiq_jax.networks import networks_of_config

DEMOS = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "demos"
TASKS = ("mo-hopper", "mo-walker2d", "mo-halfcheetah", "mo-ant")


def visited_states(name: str, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """float64 (qpos, qvel) of ``count`` native states after 10-40 random steps, and one action for each."""
    env = envs.AutoReset(envs.make(name, backend="mujoco"))
    base = env.unwrapped
    keys = jax.random.split(jax.random.key(0), count)
    steps = np.random.default_rng(0).integers(10, 41, count)

    @jax.jit
    def run(key, actions):
        return jax.lax.scan(lambda s, a: (env.step(s, a), None), env.reset(key), actions)[0]

    actions = np.random.default_rng(1).uniform(-1, 1, (count, 41, env.action_size)).astype(np.float32)
    qpos, qvel = [], []
    for i in range(count):
        state = run(keys[i], actions[i, :steps[i]])
        q, v = base.qpos_qvel(state)
        qpos.append(q)
        qvel.append(v)
    return np.array(qpos), np.array(qvel), actions[:, -1]


def one_step(env, qpos, qvel, actions):
    """(obs, reward) after one step of each start state (qpos, qvel) under its action, batched."""
    base = env.unwrapped
    if base.backend == "mujoco":
        starts = [base.state_at(q, v) for q, v in zip(qpos, qvel)]  # float64, exact
        start = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *starts)
    else:
        start = jax.jit(jax.vmap(base.state_at))(jnp.asarray(qpos, jnp.float32), jnp.asarray(qvel, jnp.float32))
    out = jax.jit(jax.vmap(base.step))(start, jnp.asarray(actions))
    return np.asarray(out.obs), np.asarray(out.reward)


def expert_returns(name: str, episodes: int, **make_kwargs) -> tuple[np.ndarray, np.ndarray]:
    """(preferences [experts, d], vector returns [experts, episodes, d]) of the committed experts."""
    config, actor = sac_experts.load_experts(DEMOS / f"{name}-experts.npz")
    env = envs.make(name, **make_kwargs)
    c = config.offpolicy
    nets = networks_of_config(c, env)
    preferences = jnp.asarray(config.preferences, jnp.float32)

    def one_expert(actor_params, preference, key):
        return preference_returns(nets, actor_params, env, preference[None], key, episodes)[0]

    keys = jax.random.split(jax.random.key(7), preferences.shape[0])
    return np.asarray(preferences), np.asarray(jax.jit(jax.vmap(one_expert))(actor, preferences, keys))


def scalarised_mean_and_error(preferences: np.ndarray, returns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per expert, the mean scalarised return over ``returns``' episodes and its standard error."""
    scalarised = np.einsum("ed,etd->et", preferences, returns)
    return scalarised.mean(1), scalarised.std(1, ddof=1) / np.sqrt(scalarised.shape[1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    parser.add_argument("--solvers", nargs="*", default=["mujoco", "fast"], help="MJX presets for one-step errors")
    parser.add_argument("--states", type=int, default=64)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--expert-solvers", nargs="*", default=["fast"], help="MJX presets for expert returns")
    args = parser.parse_args()
    print(f"{platform.machine()}, jax {jax.__version__} on {jax.devices()[0].platform}")
    for name in args.tasks:
        qpos, qvel, actions = visited_states(name, args.states)
        native_obs, native_reward = one_step(envs.make(name, backend="mujoco"), qpos, qvel, actions)
        for solver in args.solvers:
            obs, reward = one_step(envs.make(name, backend="mjx", mjx_solver=solver), qpos, qvel, actions)
            d_obs, d_reward = np.abs(obs - native_obs).max(1), np.abs(reward - native_reward).max(1)
            print(f"{name:<15} one step, mjx {solver:<6} vs native ({args.states} states): |obs| max "
                  f"{d_obs.max():.2e} median {np.median(d_obs):.2e}; |reward| max {d_reward.max():.2e} "
                  f"median {np.median(d_reward):.2e}", flush=True)
        if not (DEMOS / f"{name}-experts.npz").exists():
            print(f"{name:<15} no committed experts", flush=True)
            continue
        start = time.perf_counter()
        preferences, native_returns = expert_returns(name, args.episodes, backend="mujoco")
        seconds = time.perf_counter() - start
        native_mean, native_error = scalarised_mean_and_error(preferences, native_returns)
        print(f"{name:<15} experts, native:     " + "  ".join(
            f"{np.round(r.mean(0, dtype=np.float64), 1).tolist()} (w.r {m:8.1f} ± {e:.1f})"
            for r, m, e in zip(native_returns, native_mean, native_error)) + f"  [{seconds:.0f} s]", flush=True)
        for solver in args.expert_solvers:
            start = time.perf_counter()
            _, returns = expert_returns(name, args.episodes, backend="mjx", mjx_solver=solver)
            seconds = time.perf_counter() - start
            mean, error = scalarised_mean_and_error(preferences, returns)
            gaps = (mean - native_mean) / np.abs(native_mean)
            gap_errors = np.hypot(error, native_error) / np.abs(native_mean)
            print(f"{name:<15} experts, mjx {solver:<6}: " + "  ".join(
                f"{np.round(r.mean(0, dtype=np.float64), 1).tolist()} (w.r {m:8.1f} ± {e:.1f}, {100 * g:+.1f} ± {100 * ge:.1f}%)"
                for r, m, e, g, ge in zip(returns, mean, error, gaps, gap_errors)) + f"  [{seconds:.0f} s]",
                flush=True)


if __name__ == "__main__":
    main()

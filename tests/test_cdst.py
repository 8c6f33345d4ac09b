"""Continuous DST: exact front, optimal policies, walls, and jit/vmap invariance."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import envs
from moiq_jax.envs.cdst import PositionState
from moiq_jax.evaluate import episode_returns, random_policy


@pytest.fixture(scope="module")
def env():
    return envs.make("cdst")


def at(env, position):
    start = env.reset(jax.random.key(0))
    return start.replace(env_state=PositionState(jnp.asarray(position, jnp.float32)))


def test_optimal_policy_collects_each_front_point_exactly(env):
    base = env.unwrapped
    collected = {}
    for treasure, expected in base.treasure_returns().items():
        policy = base.optimal_policy(treasure)
        out = episode_returns(env, lambda key, obs, p=policy: p(obs), jax.random.key(0), 1)
        np.testing.assert_array_equal(np.asarray(out["returns"][0]), expected)
        assert int(out["lengths"][0]) == -expected[1]
        collected[treasure] = expected
    front = base.pareto_front()
    assert {tuple(p) for p in front.tolist()} <= {tuple(v.tolist()) for v in collected.values()}
    np.testing.assert_allclose(
        front,
        [[0.7, -1], [8.2, -3], [11.5, -5], [15.1, -7], [16.1, -9], [20.3, -17], [22.4, -21], [23.7, -23]],
        atol=1e-5,
    )


def test_paper_experts_take_three_distinct_treasures(env):
    front = env.unwrapped.pareto_front()
    chosen = [front[np.argmax(front @ np.array(w))] for w in ([0.9, 0.1], [0.5, 0.5], [0.1, 0.9])]
    np.testing.assert_allclose(chosen, [[23.7, -23], [15.1, -7], [0.7, -1]], atol=1e-5)


def test_front_is_not_beaten_by_a_brute_force_search_over_finer_actions(env):
    """Breadth-first search over positions, stepping the env itself with 25 actions on a quarter-speed grid:
    no treasure is reached in fewer steps than ``treasure_returns`` says."""
    actions = jnp.array(list(itertools.product([-1.0, -0.5, 0.0, 0.5, 1.0], repeat=2)), jnp.float32)
    step_all = jax.jit(jax.vmap(lambda pos, a: env.step(at(env, pos), a)))
    frontier = {(0.5, 0.5)}
    seen = set(frontier)
    fewest = {}
    for steps in range(1, 24):
        pos = np.array(sorted(frontier), np.float32)
        pairs_pos = np.repeat(pos, len(actions), axis=0)
        pairs_act = np.tile(np.asarray(actions), (len(pos), 1))
        out = step_all(jnp.asarray(pairs_pos), jnp.asarray(pairs_act))
        new_pos, done = np.asarray(out.env_state.position), np.asarray(out.done)
        frontier = set()
        for p, d in zip(map(tuple, new_pos.tolist()), done):
            if d:
                fewest.setdefault((int(p[0]), int(p[1])), steps)
            elif p not in seen:
                seen.add(p)
                frontier.add(p)
    expected = {t: int(-v[1]) for t, v in env.unwrapped.treasure_returns().items()}
    assert fewest == expected


def test_walls_and_sea_floor_cannot_be_crossed(env):
    # Up-left from near the corner would leave the map; from the start it reaches the corner exactly.
    nxt = env.step(at(env, [0.25, 0.25]), jnp.array([-1.0, -1.0]))
    np.testing.assert_array_equal(nxt.obs, [0.25, 0.25])
    np.testing.assert_array_equal(env.step(env.reset(jax.random.key(0)), jnp.array([-1.0, -1.0])).obs, [0.0, 0.0])
    np.testing.assert_array_equal(nxt.reward, [0.0, -1.0])
    # Left from (5.5, 6.25) would enter the rock cell (5, 5).
    nxt = env.step(at(env, [5.5, 6.25]), jnp.array([0.0, -1.0]))
    np.testing.assert_array_equal(nxt.obs, [5.5, 6.25])
    # Down from the bottom-right cell would go below the sea floor.
    nxt = env.step(at(env, [10.75, 10.5]), jnp.array([1.0, 0.0]))
    np.testing.assert_array_equal(nxt.obs, [10.75, 10.5])
    # A free move is taken exactly.
    nxt = env.step(at(env, [5.5, 6.25]), jnp.array([0.5, 1.0]))
    np.testing.assert_array_equal(nxt.obs, [5.75, 6.75])


def test_random_rollouts_stay_in_free_water_under_jit_and_vmap(env):
    batched = envs.VmapWrapper(envs.AutoReset(env), 256)
    grid = env.unwrapped.sea_map.grid
    rows, cols = grid.shape
    policy = random_policy(env)

    @jax.jit
    def run(key):
        def body(state, k):
            action = jax.vmap(policy)(jax.random.split(k, 256), state.obs)
            nxt = batched.step(state, action)
            return nxt, nxt.info["final_obs"]

        return jax.lax.scan(body, batched.reset(key), jax.random.split(key, 300))[1]

    positions = np.asarray(run(jax.random.key(1))).reshape(-1, 2)
    assert np.all(positions >= 0) and np.all(positions[:, 0] < rows) and np.all(positions[:, 1] < cols)
    cells = np.floor(positions).astype(int)
    assert not np.any(grid[cells[:, 0], cells[:, 1]] == -10)


def test_jit_and_vmap_give_the_same_steps_as_plain_python(env):
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, size=(4, 30, 2)).astype(np.float32)

    def python_rollout(seq):
        state, out = env.reset(jax.random.key(0)), []
        for a in seq:
            state = env.step(state, a)
            out.append(np.concatenate([np.asarray(state.obs), np.asarray(state.reward), [state.done, state.truncated]]))
        return np.stack(out)

    def jax_rollout(seq):
        def body(state, a):
            nxt = env.step(state, a)
            row = jnp.concatenate([nxt.obs, nxt.reward, jnp.stack([nxt.done, nxt.truncated]).astype(jnp.float32)])
            return nxt, row

        return jax.lax.scan(body, env.reset(jax.random.key(0)), seq)[1]

    batched = np.asarray(jax.jit(jax.vmap(jax_rollout))(jnp.asarray(actions)))
    for i in range(len(actions)):
        np.testing.assert_array_equal(batched[i], python_rollout(actions[i]))


@pytest.mark.parametrize("action", [np.array([1.5, 0.0]), np.array([0.0, np.nan]), np.array([1.0]), np.array([0.1, 0.1, 0.1])])
def test_continuous_action_outside_space_is_rejected(env, action):
    with pytest.raises(ValueError, match="ContinuousDeepSeaTreasure"):
        env.step(env.reset(jax.random.key(0)), action)


def test_optimal_policy_of_a_non_treasure_is_an_error(env):
    with pytest.raises(ValueError, match="not a treasure cell"):
        env.unwrapped.optimal_policy((0, 5))

"""Discrete DST against MO-Gymnasium's deep-sea-treasure-v0, step by step."""

import jax
import jax.numpy as jnp
import mo_gymnasium as mo_gym
import numpy as np
import pytest

from moiq_jax import envs

NUM_SEQUENCES = 1000
HORIZON = 110  # past the 100-step limit, so truncation is exercised


def random_action_sequences(seed: int) -> np.ndarray:
    """Half uniform, half biased toward down/right so that deep treasures and the time limit are reached."""
    rng = np.random.default_rng(seed)
    uniform = rng.integers(0, 4, size=(NUM_SEQUENCES // 2, HORIZON))
    biased = rng.choice(4, size=(NUM_SEQUENCES - NUM_SEQUENCES // 2, HORIZON), p=[0.1, 0.3, 0.1, 0.5])
    return np.concatenate([uniform, biased]).astype(np.int32)


def jax_rollouts(env, actions: np.ndarray):
    """Observations, rewards, terminated, truncated of every step of every sequence (no reset)."""

    def one(seq):
        def body(state, a):
            nxt = env.step(state, a)
            return nxt, (nxt.obs, nxt.reward, nxt.done, nxt.truncated)

        return jax.lax.scan(body, env.reset(jax.random.key(0)), seq)[1]

    return jax.tree_util.tree_map(np.asarray, jax.jit(jax.vmap(one))(jnp.asarray(actions)))


@pytest.mark.parametrize(
    "name, gym_id, float_state, seed",
    [
        ("dst", "deep-sea-treasure-v0", False, 0),
        ("dst-concave", "deep-sea-treasure-concave-v0", False, 1),
        ("dst", "deep-sea-treasure-v0", True, 2),
    ],
)
def test_matches_mo_gymnasium_step_by_step(name, gym_id, float_state, seed):
    actions = random_action_sequences(seed)
    obs, rewards, terminated, truncated = jax_rollouts(envs.make(name, float_state=float_state), actions)
    reference = mo_gym.make(gym_id, float_state=float_state)
    treasures_seen, truncations = set(), 0
    for i, seq in enumerate(actions):
        ref_obs, _ = reference.reset(seed=i)
        np.testing.assert_array_equal(envs.make(name, float_state=float_state).reset(jax.random.key(0)).obs, ref_obs)
        for t, a in enumerate(seq):
            ref_obs, ref_reward, ref_term, ref_trunc, _ = reference.step(int(a))
            assert obs[i, t].dtype == ref_obs.dtype
            np.testing.assert_array_equal(obs[i, t], ref_obs, err_msg=f"obs, sequence {i} step {t}")
            np.testing.assert_array_equal(rewards[i, t], ref_reward, err_msg=f"reward, sequence {i} step {t}")
            assert terminated[i, t] == ref_term and truncated[i, t] == ref_trunc, (i, t)
            if ref_term:
                treasures_seen.add(float(ref_reward[0]))
            if ref_term or ref_trunc:
                truncations += bool(ref_trunc)
                break
    # The comparison is only as strong as what it visited: most treasures and some time limits.
    assert len(treasures_seen) >= 7, treasures_seen
    assert truncations > 0


@pytest.mark.parametrize("name, gym_id", [("dst", "deep-sea-treasure-v0"), ("dst-concave", "deep-sea-treasure-concave-v0")])
def test_pareto_front_matches_mo_gymnasium(name, gym_id):
    ours = envs.make(name).unwrapped.pareto_front()
    theirs = np.array(mo_gym.make(gym_id).unwrapped.pareto_front(gamma=1.0), dtype=np.float32)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-6)


def test_mini_map_front_is_convex_and_splits_the_paper_experts():
    env = envs.make("dst-mini").unwrapped
    front = env.pareto_front()
    np.testing.assert_allclose(front, [[1, -1], [7, -3], [11, -5], [14, -7], [16, -9], [16.8, -10]], atol=1e-5)
    # Every point is the unique optimum of some linear preference: it wins for a weight in the sweep.
    weights = np.linspace(0.0, 1.0, 2001)
    winners = {int(np.argmax(front @ np.array([w, 1 - w]))) for w in weights}
    assert winners == set(range(len(front)))
    assert np.argmax(front @ [0.1, 0.9]) == 0 and np.argmax(front @ [0.9, 0.1]) == len(front) - 1


@pytest.mark.parametrize("name, gym_id", [("dst", "deep-sea-treasure-v0"), ("dst-concave", "deep-sea-treasure-concave-v0")])
def test_tabular_model_matches_mo_gymnasium_from_every_cell(name, gym_id):
    env = envs.make(name).unwrapped
    next_state, reward, terminal = env.tabular()
    reference = mo_gym.make(gym_id).unwrapped
    reference.reset(seed=0)
    grid, cols = env.sea_map.grid, env.sea_map.cols
    for (r, c), value in np.ndenumerate(grid):
        if value == -10:
            continue
        for a in range(4):
            reference.current_state = np.array([r, c], np.int32)
            ref_obs, ref_reward, ref_term, _, _ = reference.step(a)
            s = r * cols + c
            assert divmod(int(next_state[s, a]), cols) == tuple(ref_obs.tolist()), (r, c, a)
            np.testing.assert_array_equal(reward[s, a], ref_reward)
            assert terminal[next_state[s, a]] == ref_term


def test_unknown_env_lists_known_ones():
    with pytest.raises(ValueError, match=r"unknown env 'dts'.*cdst, dst, dst-concave, dst-mini"):
        envs.make("dts")


@pytest.mark.parametrize(
    "grid, message",
    [
        ([[0, 0, 1], [0, 0]], "not rectangular"),
        ([[0, 0], [0, -3]], "rock \\(-10\\), water \\(0\\) or a positive treasure"),
        ([[-10, 1], [0, 0]], "start cell"),
        ([[0, 0], [0, 0]], "no treasure"),
        ([[0, np.nan], [1, 0]], "NaN"),
    ],
)
def test_bad_maps_are_rejected(grid, message):
    with pytest.raises(ValueError, match=message):
        envs.DeepSeaTreasure(grid)


@pytest.mark.parametrize("action", [4, -1, np.array([1, 2]), 1.0])
def test_discrete_action_outside_space_is_rejected(action):
    env = envs.make("dst")
    with pytest.raises(ValueError, match="DeepSeaTreasure"):
        env.step(env.reset(jax.random.key(0)), action)

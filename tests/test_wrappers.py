"""Time limit, absorbing state, auto-reset and batching."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import envs

DOWN, RIGHT = 1, 3


def run(env, actions, key=0):
    """All states of a scanned rollout from reset."""

    def body(state, a):
        nxt = env.step(state, a)
        return nxt, nxt

    return jax.lax.scan(body, env.reset(jax.random.key(key)), jnp.asarray(actions))[1]


def test_time_limit_truncates_at_the_limit_and_counts_steps():
    env = envs.make("dst", episode_length=7)
    states = run(env, jnp.full((9,), 0, jnp.int32))  # up: never terminates
    np.testing.assert_array_equal(states.info["steps"], np.arange(1, 10))
    np.testing.assert_array_equal(states.truncated, np.arange(1, 10) >= 7)
    assert not np.any(states.done)


def test_absorbing_state_gives_fixed_length_episodes_with_the_same_return():
    plain = envs.make("dst")
    absorbing = envs.make("dst", absorbing=True)
    assert absorbing.observation_size == plain.observation_size + 1
    actions = jnp.array([RIGHT, DOWN, DOWN] + [0] * 97, jnp.int32)  # 8.2 treasure at step 3
    states = run(absorbing, actions)
    # Never done; the episode ends only by the time limit, after exactly 100 steps.
    assert not np.any(states.done)
    np.testing.assert_array_equal(states.truncated, np.arange(1, 101) == 100)
    # The terminating step pays the treasure and lands in the absorbing state, which then pays nothing.
    np.testing.assert_array_equal(states.reward[:3], np.float32([[0, -1], [0, -1], [8.2, -1]]))
    np.testing.assert_array_equal(states.reward[3:], np.zeros((97, 2)))
    np.testing.assert_array_equal(states.obs[2:], np.tile([0.0, 0.0, 1.0], (98, 1)))
    np.testing.assert_array_equal(states.obs[:2], [[0, 1, 0], [1, 1, 0]])
    np.testing.assert_array_equal(states.info["absorbed"], np.arange(100) >= 2)
    # Same undiscounted return as the plain env's episode.
    plain_states = run(plain, actions[:3])
    assert bool(plain_states.done[2])
    np.testing.assert_allclose(states.reward.sum(0), plain_states.reward.sum(0))


def test_absorbing_state_is_left_untouched_by_later_actions():
    env = envs.make("cdst", absorbing=True)
    actions = jnp.concatenate([jnp.array([[1.0, 0.0]]), jnp.ones((20, 2))])  # 0.7 treasure at step 1
    states = run(env, actions)
    np.testing.assert_array_equal(states.env_state.position[1:], np.tile(states.env_state.position[0], (20, 1)))
    np.testing.assert_array_equal(states.reward[1:], np.zeros((20, 2)))


def test_done_on_absorption_ends_the_episode_at_termination():
    env = envs.AutoReset(envs.DoneOnAbsorption(envs.make("dst", absorbing=True)))
    actions = jnp.array([RIGHT, DOWN, DOWN, RIGHT, DOWN, DOWN], jnp.int32)  # the 8.2 treasure at step 3, twice
    states = run(env, actions)
    # The terminating step is done, pays the treasure and ends the episode: no step in the absorbing state.
    np.testing.assert_array_equal(states.done, [False, False, True] * 2)
    assert not np.any(states.truncated)
    np.testing.assert_array_equal(states.reward[:3], np.float32([[0, -1], [0, -1], [8.2, -1]]))
    np.testing.assert_array_equal(states.reward[3:], states.reward[:3])
    np.testing.assert_array_equal(states.obs[2], [0, 0, 0])  # the new episode's start (flag kept, 0)
    np.testing.assert_array_equal(states.info["steps"], [1, 2, 0] * 2)


def test_auto_reset_starts_a_new_episode_and_keeps_the_final_observation():
    env = envs.AutoReset(envs.make("dst", episode_length=5))
    states = run(env, jnp.array([DOWN] + [0] * 7, jnp.int32))  # treasure 0.7 at step 1, then 5-step limits
    # Step 1 terminated: reward and done kept, obs is the new episode's start, final_obs the treasure cell.
    assert bool(states.done[0])
    np.testing.assert_array_equal(states.reward[0], np.float32([0.7, -1]))
    np.testing.assert_array_equal(states.obs[0], [0, 0])
    np.testing.assert_array_equal(states.info["final_obs"][0], [1, 0])
    np.testing.assert_array_equal(states.info["steps"], [0, 1, 2, 3, 4, 0, 1, 2])
    np.testing.assert_array_equal(states.truncated, [False, False, False, False, False, True, False, False])


def test_vmap_wrapper_batches_and_checks_actions():
    env = envs.VmapWrapper(envs.make("cdst"), 3)
    state = env.reset(jax.random.key(0))
    assert state.obs.shape == (3, 2) and state.reward.shape == (3, 2)
    nxt = env.step(state, jnp.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]))
    np.testing.assert_array_equal(nxt.obs, [[1.0, 0.5], [0.5, 1.0], [0.5, 0.5]])
    with pytest.raises(ValueError, match=r"shape \(3, 2\)"):
        env.step(state, jnp.zeros((2, 2)))


@pytest.mark.parametrize("bad", [0, -3])
def test_wrapper_sizes_must_be_positive(bad):
    with pytest.raises(ValueError, match="at least 1"):
        envs.make("dst", episode_length=bad)
    with pytest.raises(ValueError, match="at least 1"):
        envs.VmapWrapper(envs.make("dst"), bad)

"""The MJX envs against MO-Gymnasium's v5 MuJoCo envs.

Parity: from the same qpos/qvel (MO-Gymnasium's own resets) and the same actions, the observation,
every reward component, terminated and truncated match step by step, to ``|ours - theirs| <= ATOL +
RTOL * |theirs|``, for the first ``parity_steps`` steps of each episode (or until MO-Gymnasium
terminates). MJX runs in float32, MuJoCo in float64.

The horizons differ by env because MJX 3.17 and MuJoCo 4.0.0 compute different contact forces in
some contacts (same contact points and distances, constraint forces apart by a few per cent: the Ant
with its 0.01 contact margin, and the HalfCheetah), and rollouts are chaotic, so differences grow
once feet touch the ground: the hopper and walker2d match for 30 steps, the HalfCheetah for 8, the
Ant for its first step from a reset, in the air (its legs reach the ground within the contact margin
during the second step; a step is compared only while neither side's observation shows a contact
force). The Ant's contact terms are checked by the statistics only.

Statistics: over ``EPISODES`` random-action episodes of at most ``HORIZON`` steps on each side, the
mean return vector and the mean episode length agree to four standard errors (plus 1e-3).

One compiled function per env, ``jit(vmap(scan(step)))``, serves both tests (and is the
jit + vmap + scan test).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import envs

mo_gym = pytest.importorskip("mo_gymnasium")

EPISODES = 32  # envs per batch, on both sides
HORIZON = 100  # steps per rollout and time limit on both sides
ATOL = RTOL = 2e-3

# name -> (MO-Gymnasium id, columns of its reward that are ours, parity steps, contact forces in the obs)
CASES = {
    "mo-hopper": ("mo-hopper-v5", [0, 1, 2], 30, None),
    "mo-walker2d": ("mo-walker2d-v5", [0, 1], 30, None),
    "mo-halfcheetah": ("mo-halfcheetah-v5", [0, 1], 8, None),
    "mo-ant": ("mo-ant-v5", [0, 2], 1, slice(27, None)),
}


class Rollouts:
    """One env's compiled batched rollout and MO-Gymnasium's counterpart."""

    def __init__(self, name: str):
        self.name = name
        self.gym_id, self.columns, self.parity_steps, self.contact_forces = CASES[name]
        self.env = envs.make(name, episode_length=HORIZON)
        base = self.env.unwrapped

        def start(key, qpos, qvel):
            state = self.env.reset(key)
            fresh = base.state_from_data(base.data_from_state(qpos, qvel))
            return state.replace(env_state=fresh.env_state, obs=fresh.obs)

        def rollout(state, actions):
            def body(state, action):
                state = self.env.step(state, action)
                return state, (state.obs, state.reward, state.done, state.truncated)

            return jax.lax.scan(body, state, actions)[1]

        self.start = jax.jit(jax.vmap(start))
        self.reset = jax.jit(jax.vmap(self.env.reset))
        self.rollout = jax.jit(jax.vmap(rollout))

    def gym(self):
        return mo_gym.make(self.gym_id, max_episode_steps=HORIZON)

    def actions(self, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        return rng.uniform(-1, 1, (EPISODES, HORIZON, self.env.action_size)).astype(np.float32)


@pytest.fixture(scope="module", params=list(CASES))
def rollouts(request):
    return Rollouts(request.param)


def test_sizes_match_gymnasium(rollouts):
    gym_env = rollouts.gym()
    assert rollouts.env.observation_size == gym_env.observation_space.shape[0]
    assert rollouts.env.action_size == gym_env.action_space.shape[0]
    assert rollouts.env.reward_dim == len(rollouts.columns)
    base = rollouts.env.unwrapped
    assert base.dt == pytest.approx(gym_env.unwrapped.dt)
    assert not base.deterministic_reset


def test_reset_noise_matches_gymnasium(rollouts):
    """Reset noise: uniform on qpos, uniform or Gaussian on qvel, of the task's scale."""
    base = rollouts.env.unwrapped
    states = jax.vmap(base.reset)(jax.random.split(jax.random.key(0), 2000))
    qpos = np.asarray(states.env_state.qpos) - base.mj_model.qpos0
    qvel = np.asarray(states.env_state.qvel)
    scale = base.reset_noise_scale
    assert np.abs(qpos).max() <= scale + 1e-6
    np.testing.assert_allclose(qpos.std(0), scale / np.sqrt(3), rtol=0.1)
    if base.qvel_noise_normal:
        np.testing.assert_allclose(qvel.std(0), scale, rtol=0.1)
    else:
        assert np.abs(qvel).max() <= scale + 1e-6
        np.testing.assert_allclose(qvel.std(0), scale / np.sqrt(3), rtol=0.1)
    assert np.abs(qpos.mean(0)).max() < 0.1 * scale and np.abs(qvel.mean(0)).max() < 0.1 * scale


def test_steps_match_mo_gymnasium(rollouts):
    """Same start states and actions: obs, reward vector, terminated and truncated match step by step."""
    gym_env = rollouts.gym()
    qpos, qvel, first_obs = [], [], []
    for seed in range(EPISODES):
        obs, _ = gym_env.reset(seed=seed)
        qpos.append(gym_env.unwrapped.data.qpos.copy())
        qvel.append(gym_env.unwrapped.data.qvel.copy())
        first_obs.append(obs)
    keys = jax.random.split(jax.random.key(0), EPISODES)
    start = rollouts.start(keys, jnp.asarray(np.array(qpos), jnp.float32), jnp.asarray(np.array(qvel), jnp.float32))
    np.testing.assert_allclose(np.asarray(start.obs), np.array(first_obs), atol=ATOL, rtol=RTOL)
    actions = rollouts.actions(seed=1)
    obs, reward, done, truncated = map(np.asarray, rollouts.rollout(start, jnp.asarray(actions)))

    compared = 0
    for i in range(EPISODES):
        gym_env.reset(seed=i)
        for t in range(rollouts.parity_steps):
            their_obs, their_reward, terminated, their_truncated, _ = gym_env.step(actions[i, t])
            if rollouts.contact_forces is not None and (
                    their_obs[rollouts.contact_forces].any() or obs[i, t, rollouts.contact_forces].any()):
                break  # MJX's contact forces differ from MuJoCo 4.0's: compare the flight before contact
            where = f"{rollouts.name} episode {i} step {t}"
            np.testing.assert_allclose(obs[i, t], their_obs, atol=ATOL, rtol=RTOL, err_msg=where)
            np.testing.assert_allclose(reward[i, t], their_reward[rollouts.columns], atol=ATOL, rtol=RTOL,
                                       err_msg=where)
            assert (done[i, t], truncated[i, t]) == (terminated, their_truncated), where
            compared += 1
            if terminated:
                break
    assert compared >= EPISODES * (1 if rollouts.contact_forces else 8)


def _episode_statistics(rewards, ends):
    """Per-episode returns up to and including the first end, and lengths, from ``[E, T]`` arrays."""
    steps = np.arange(rewards.shape[1])
    length = np.where(ends.any(1), ends.argmax(1) + 1, rewards.shape[1])
    live = steps[None, :] < length[:, None]
    return (rewards * live[..., None]).sum(1), length


def _agree(ours, theirs, what):
    se = np.sqrt(ours.var(0, ddof=1) / len(ours) + theirs.var(0, ddof=1) / len(theirs))
    gap = np.abs(ours.mean(0) - theirs.mean(0))
    assert np.all(gap <= 4 * se + 1e-3), f"{what}: ours {ours.mean(0)}, MO-Gymnasium {theirs.mean(0)}, se {se}"


def test_random_rollout_statistics_match_mo_gymnasium(rollouts):
    """Independent random-action episodes from each side's own resets: mean returns and lengths agree."""
    start = rollouts.reset(jax.random.split(jax.random.key(1), EPISODES))
    _, reward, done, truncated = map(np.asarray, rollouts.rollout(start, jnp.asarray(rollouts.actions(seed=2))))
    assert truncated[:, -1].all() and not truncated[:, :-1].any()  # the time limit, on the last step
    our_returns, our_lengths = _episode_statistics(reward, done | truncated)

    gym_env = rollouts.gym()
    gym_env.action_space.seed(3)
    their_returns, their_lengths = [], []
    for seed in range(EPISODES):
        gym_env.reset(seed=1000 + seed)
        total, steps, over = 0.0, 0, False
        while not over:
            _, r, terminated, truncated_, _ = gym_env.step(gym_env.action_space.sample())
            total, steps, over = total + r[rollouts.columns], steps + 1, terminated or truncated_
        their_returns.append(total)
        their_lengths.append(steps)
    assert max(their_lengths) <= HORIZON
    _agree(our_returns, np.array(their_returns), f"{rollouts.name} mean return")
    _agree(our_lengths.astype(float), np.array(their_lengths, float), f"{rollouts.name} mean length")

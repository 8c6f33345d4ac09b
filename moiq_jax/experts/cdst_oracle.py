"""Continuous-DST experts: the exact optimal deterministic policy for each preference, and their
demonstrations recorded in the absorbing-state env so every episode has the same length (sec. 4.1.1)."""

from __future__ import annotations

import jax
import numpy as np

from moiq_jax import envs
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.preferences import check_preferences

ENV_NAME = "cdst"


def best_treasure(env, preference) -> tuple[tuple[int, int], np.ndarray]:
    """The treasure cell whose fastest return maximises ``preference . return``, and that return."""
    returns = env.unwrapped.treasure_returns()
    cell = max(returns, key=lambda t: float(np.dot(preference, returns[t])))
    return cell, returns[cell]


def expert_returns(preferences) -> np.ndarray:
    """``[E, d]`` exact vector returns of the optimal experts for ``preferences``."""
    env = envs.make(ENV_NAME)
    return np.stack([best_treasure(env, np.asarray(w))[1] for w in preferences])


def record_demonstrations(preferences, num_demos: int = 10) -> Demonstrations:
    """``num_demos`` episodes of the optimal policy of every preference in the absorbing-state cdst.

    The env and the policies are deterministic, so an expert's episodes are identical; episodes run the
    full time limit (the absorbing state follows the treasure), so all lengths equal it.
    """
    prefs = check_preferences(preferences, 2)
    env = envs.make(ENV_NAME, absorbing=True)
    horizon = env.episode_length

    def record(policy):
        def step(state, _):
            action = policy(state.obs[:2])  # the position; the absorbing flag is last
            nxt = env.step(state, action)
            return nxt, (state.obs, action, nxt.obs, nxt.reward, nxt.done)

        _, trajectory = jax.lax.scan(step, env.reset(jax.random.PRNGKey(0)), None, length=horizon)
        return trajectory

    per_expert = [record(env.unwrapped.optimal_policy(best_treasure(env, w)[0])) for w in prefs]
    obs, actions, next_obs, rewards, dones = (
        np.repeat(np.stack([np.asarray(t[i]) for t in per_expert])[:, None], num_demos, axis=1) for i in range(5)
    )
    return Demonstrations(
        obs=obs.astype(np.float32),
        actions=actions.astype(np.float32),
        next_obs=next_obs.astype(np.float32),
        rewards=rewards.astype(np.float32),
        dones=dones.astype(bool),
        lengths=np.full((len(prefs), num_demos), horizon, np.int32),
        preferences=prefs,
        env=ENV_NAME,
        metadata={"expert": "exact optimal policy (cdst oracle)", "absorbing": True},
    ).validate(env)


"""Continuous-DST experts: the exact optimal deterministic policy for each preference, and their
demonstrations recorded in the absorbing-state env so every episode has the same length (sec. 4.1.1).

Many shortest paths reach a treasure; the experts take one that keeps clear of hazards (``clear_actions``),
so that a learner imitating them up to small action errors does not fall into a neighbouring treasure or
against rock: every path point lies on the lattice, and a point on a cell border next to a hazard is
lost to the smallest error to that side.
"""

from __future__ import annotations

import jax
import numpy as np

from moiq_jax import envs
from moiq_jax.envs.cdst import RESOLUTION, lattice_policy
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.preferences import check_preferences

ENV_NAME = "cdst"


def best_treasure(env, preference) -> tuple[tuple[int, int], np.ndarray]:
    """The treasure cell whose fastest return maximises ``preference . return``, and that return."""
    returns = env.unwrapped.treasure_returns()
    cell = max(returns, key=lambda t: float(np.dot(preference, returns[t])))
    return cell, returns[cell]


def hazards_near(sea_map, point, treasure) -> int:
    """How many of the cells touching lattice ``point`` (position ``point / RESOLUTION``; up to 4 when it
    lies on cell borders) are rock, a treasure other than ``treasure``, or outside the map."""
    cells = {tuple((np.asarray(point) + np.asarray(offset)) // RESOLUTION)
             for offset in ((0, 0), (-1, 0), (0, -1), (-1, -1))
             if all((point[i] + offset[i]) % RESOLUTION == RESOLUTION - 1 or offset[i] == 0 for i in range(2))}
    count = 0
    for r, c in cells:
        inside = 0 <= r < sea_map.rows and 0 <= c < sea_map.cols
        count += (not inside) or ((r, c) != tuple(treasure) and sea_map.grid[r, c] != 0)
    return count


def clear_actions(env, treasure) -> np.ndarray:
    """Table over lattice points of king-move actions on a shortest path to ``treasure``, choosing among
    the shortest moves the one whose next point touches the fewest hazards (``hazards_near``)."""
    sea_map = env.unwrapped.sea_map
    return env.unwrapped.optimal_actions(treasure, prefer=lambda point: hazards_near(sea_map, point, treasure))


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

    per_expert = [record(lattice_policy(clear_actions(env, best_treasure(env, w)[0]))) for w in prefs]
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
        metadata={"expert": "exact optimal policy, hazard-clear path (cdst oracle)", "absorbing": True},
    ).validate(env)


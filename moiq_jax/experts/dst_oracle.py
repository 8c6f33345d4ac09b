"""Oracle experts for discrete Deep Sea Treasure (paper sec. 5.1) and their demonstrations.

"Optimal" throughout means optimal on the exact *undiscounted* front (``pareto_front()``, rows
``(treasure, -steps)``): the optimal treasure for a preference ``w`` maximises ``w . (treasure, -steps)``.
On every DST map here the shortest path to a treasure is a staircase of right and down moves, so the
oracle below is optimal in that sense.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import envs
from moiq_jax.envs.dst import ROCK
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.preferences import check_preferences

DOWN, RIGHT = 1, 3


def optimal_treasure(sea_map, preference) -> tuple[tuple[int, int], float]:
    """The treasure cell that maximises ``preference . (treasure, -steps)`` and that value.

    Ties (e.g. 15.1 at 8 steps and 16.1 at 9 steps for [0.5, 0.5] on the default map) go to the
    nearer treasure; both have the same scalarised return.
    """
    w = np.asarray(preference, np.float64)
    steps = sorted(sea_map.treasure_steps(envs.dst.COMPASS_MOVES).items(), key=lambda item: item[1])
    values = [w @ (float(sea_map.grid[cell]), -float(n)) for cell, n in steps]
    best = int(np.argmax(values))
    return steps[best][0], float(values[best])


def optimal_value(sea_map, preference) -> float:
    """The best scalarised undiscounted return ``max_front preference . (treasure, -steps)``."""
    return float((sea_map.pareto_front(envs.dst.COMPASS_MOVES) @ np.asarray(preference, np.float64)).max())


def _free_run(sea_map, cell, step, target) -> int:
    """How many cells can be entered in a row from ``cell`` along ``step`` before the map border, rock or
    a treasure other than ``target`` (entering one would end the episode) blocks the way."""
    grid = sea_map.grid
    (r, c), (dr, dc), n = cell, step, 0
    while True:
        r, c = r + dr, c + dc
        if not (0 <= r < sea_map.rows and 0 <= c < sea_map.cols) or grid[r, c] == ROCK:
            return n
        if grid[r, c] > 0 and (r, c) != target:
            return n
        n += 1


def oracle_policy(sea_map, preference) -> np.ndarray:
    """The paper's stochastic optimal policy as a table ``[cells, 4]`` of action probabilities.

    In cell (r, c) it moves down with probability proportional to ``min(d_y^b, d_y^t)`` and right with
    probability proportional to ``min(d_x^b, d_x^t)``: distance to the border (see ``_free_run``) and to
    the target treasure along each axis. Cells off the staircase to the target (never visited) and
    treasure cells get a uniform row.
    """
    target, _ = optimal_treasure(sea_map, preference)
    table = np.full((sea_map.rows * sea_map.cols, 4), 0.25)
    for r in range(sea_map.rows):
        for c in range(sea_map.cols):
            if sea_map.grid[r, c] != 0:
                continue
            down = min(_free_run(sea_map, (r, c), (1, 0), target), max(target[0] - r, 0))
            right = min(_free_run(sea_map, (r, c), (0, 1), target), max(target[1] - c, 0))
            if down + right > 0:
                table[r * sea_map.cols + c] = 0.0
                table[r * sea_map.cols + c, DOWN] = down / (down + right)
                table[r * sea_map.cols + c, RIGHT] = right / (down + right)
    return table


def record_demonstrations(env_name: str, preferences, num_demos: int, key: jax.Array,
                          absorbing: bool = True) -> Demonstrations:
    """Sample ``num_demos`` episodes of the oracle expert of every preference, all at once (vmapped).

    With ``absorbing=True`` (the default, paper sec. 4.1.1) the env has an absorbing state, every episode
    runs to the time limit and the absorbing state's actions are uniform; otherwise episodes end at the
    treasure and are padded.
    """
    env = envs.make(env_name, absorbing=absorbing)
    sea_map = env.unwrapped.sea_map
    prefs = check_preferences(preferences, env.reward_dim)
    tables = jnp.asarray(np.stack([oracle_policy(sea_map, w) for w in prefs]), jnp.float32)
    horizon = env.episode_length

    def episode(table, key):
        def step(state, key):
            row, col = state.obs[0].astype(jnp.int32), state.obs[1].astype(jnp.int32)
            action = jax.random.choice(key, 4, p=table[row * sea_map.cols + col])
            if absorbing:  # the absorbing state's actions do nothing: the expert picks them uniformly
                action = jnp.where(state.info["absorbed"], jax.random.randint(key, (), 0, 4), action)
            nxt = env.step(state, action)
            return nxt, (state.obs, action, nxt.obs, nxt.reward, nxt.done, nxt.done | nxt.truncated)

        _, (obs, actions, next_obs, rewards, dones, ends) = jax.lax.scan(
            step, env.reset(key), jax.random.split(key, horizon)
        )
        length = jnp.argmax(ends) + 1
        return obs, actions, next_obs, rewards, dones, length

    keys = jax.random.split(key, (len(prefs), num_demos))
    out = jax.jit(jax.vmap(jax.vmap(episode, in_axes=(None, 0))))(tables, keys)
    obs, actions, next_obs, rewards, dones, lengths = (np.asarray(x) for x in out)
    mask = np.arange(horizon)[None, None, :] < lengths[:, :, None]
    return Demonstrations(
        obs=np.where(mask[..., None], obs, 0).astype(np.float32),
        actions=np.where(mask, actions, 0).astype(np.int32),
        next_obs=np.where(mask[..., None], next_obs, 0).astype(np.float32),
        rewards=np.where(mask[..., None], rewards, 0).astype(np.float32),
        dones=dones & mask,
        lengths=lengths.astype(np.int32),
        preferences=prefs,
        env=env_name,
        metadata={"expert": "dst_oracle", "absorbing": absorbing, "num_demos": num_demos},
    ).validate(env)

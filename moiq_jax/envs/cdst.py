"""Continuous Deep Sea Treasure: DST's map, treasures and step cost with a continuous position and a
2-D velocity action.

Rules (exact):
- Cell (row i, col j) of the map is the square ``[i, i + 1) x [j, j + 1)`` of positions ``(y, x)``;
  ``y`` grows downward (depth) and ``x`` to the right, matching the map's (row, col) indexing.
- The submarine starts at the centre of cell (0, 0): position ``(0.5, 0.5)``.
- The action is a velocity ``(v_y, v_x) in [-1, 1]^2`` (checked outside jit, clipped inside jit); a
  step moves by ``SPEED * action``, at most half a cell per axis.
- If the candidate position lies outside the map (``y < 0``, ``y >= rows``, ``x < 0`` or ``x >= cols``)
  or in a rock cell, the move is not made and the submarine stays where it was (as in discrete DST).
  Only the position after the step is checked, not the path between.
- If the (new) position lies in a treasure cell, the episode ends and the step's reward is
  ``(treasure value, -1)``; otherwise it is ``(0, -1)``.
- Observation: the position ``(y, x)`` as float32. ``make`` adds a 100-step time limit.

Exact front. Let ``q = floor(2 * position)``, the point of the half-cell lattice below the position;
its cell is ``q // 2``. A step changes each coordinate of ``2 * position`` by at most 1, so it changes
each coordinate of ``q`` by at most 1: any trajectory visits cells along a path of king moves (the 8
neighbours) on the lattice. Conversely the actions in ``{-1, 0, 1}^2`` move exactly one lattice point
in any of those 8 directions. So the fewest steps to a treasure are the breadth-first-search
distance over king moves on the lattice, avoiding rock and other treasures (``pareto_front``), and
``optimal_policy`` attains them. Half-cell speed keeps the three experts of the paper distinct on the
convex map: preferences [0.9, 0.1], [0.5, 0.5] and [0.1, 0.9] take the treasures 23.7 (23 steps),
15.1 (7 steps) and 0.7 (1 step).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from moiq_jax.envs.base import Env, State
from moiq_jax.envs.dst import CONVEX_MAP, KING_MOVES, ROCK, SeaMap

SPEED = 0.5  # cells per step per axis at |action| = 1
RESOLUTION = 2  # lattice points per cell side: 1 / SPEED


@struct.dataclass
class PositionState:
    position: jax.Array  # (y, x), float32


class ContinuousDeepSeaTreasure(Env):
    """Continuous Deep Sea Treasure; see the module docstring for the rules."""

    deterministic_reset = True
    reward_dim = 2
    observation_size = 2
    action_size = 2

    def __init__(self, sea_map=CONVEX_MAP):
        self.sea_map = sea_map if isinstance(sea_map, SeaMap) else SeaMap(sea_map)
        self._grid = jnp.asarray(self.sea_map.grid)
        self._bounds = jnp.array([self.sea_map.rows, self.sea_map.cols], jnp.float32)

    def pareto_front(self) -> np.ndarray:
        """Exact undiscounted front ``(treasure, -steps)`` of this map."""
        return self.sea_map.pareto_front(KING_MOVES, RESOLUTION)

    def treasure_returns(self) -> dict[tuple[int, int], np.ndarray]:
        """For every reachable treasure cell, the undiscounted return ``(treasure, -fewest steps)`` of
        reaching it as fast as possible: front points and dominated treasures alike."""
        steps = self.sea_map.treasure_steps(KING_MOVES, RESOLUTION)
        return {t: np.array([self.sea_map.grid[t], -s], np.float32) for t, s in steps.items()}

    def reset(self, key):
        del key  # the start is always the centre of cell (0, 0)
        position = jnp.full((2,), 0.5, jnp.float32)
        return State(
            env_state=PositionState(position),
            obs=position,
            reward=jnp.zeros((2,), jnp.float32),
            done=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
        )

    def _cell_of(self, position):
        return jnp.clip(jnp.floor(position).astype(jnp.int32), 0, self._bounds.astype(jnp.int32) - 1)

    def step(self, state, action):
        self.check_action(action)
        action = jnp.clip(jnp.asarray(action, jnp.float32), -1.0, 1.0)
        candidate = state.env_state.position + SPEED * action
        inside = jnp.all((candidate >= 0.0) & (candidate < self._bounds))
        cell = self._cell_of(candidate)
        valid = inside & (self._grid[cell[0], cell[1]] != ROCK)
        position = jnp.where(valid, candidate, state.env_state.position)
        here = self._cell_of(position)
        value = self._grid[here[0], here[1]]
        found = value > 0
        reward = jnp.stack([jnp.where(found, value, 0.0), jnp.float32(-1.0)]).astype(jnp.float32)
        return state.replace(
            env_state=PositionState(position),
            obs=position,
            reward=reward,
            done=found,
            truncated=jnp.zeros((), bool),  # only a time limit truncates
        )

    def optimal_actions(self, treasure: tuple[int, int], prefer=None) -> np.ndarray:
        """Table ``[rows * 2, cols * 2, 2]`` over lattice points of king-move actions that follow a
        shortest path to ``treasure`` without touching another treasure (zeros where unreachable).
        Among several shortest moves it takes the first in ``KING_MOVES`` order, or with ``prefer``
        (lattice point -> number) the first whose next point has the smallest ``prefer`` value."""
        treasure = tuple(int(i) for i in treasure)
        if treasure not in self.sea_map.treasures():
            raise ValueError(f"{treasure} is not a treasure cell; treasures: {self.sea_map.treasures()}")
        dist = self.sea_map.distances_to(treasure, KING_MOVES, RESOLUTION)
        height, width = dist.shape
        table = np.zeros((height, width, 2), np.float32)
        for y in range(height):
            for x in range(width):
                if dist[y, x] <= 0:
                    continue
                moves = [(dy, dx) for dy, dx in KING_MOVES if 0 <= y + dy < height and 0 <= x + dx < width
                         and dist[y + dy, x + dx] == dist[y, x] - 1]
                if moves:
                    table[y, x] = moves[0] if prefer is None else min(moves, key=lambda m: prefer((y + m[0], x + m[1])))
        return table

    def optimal_policy(self, treasure: tuple[int, int]):
        """A deterministic jittable policy ``obs -> action`` that reaches ``treasure`` in the fewest steps."""
        return lattice_policy(self.optimal_actions(treasure))


def lattice_policy(table):
    """The deterministic jittable policy ``position -> table[lattice point below the position]`` for a
    table of actions over lattice points, ``[rows * RESOLUTION, cols * RESOLUTION, 2]``."""
    table = jnp.asarray(table)
    limit = jnp.array(table.shape[:2]) - 1

    def policy(obs):
        point = jnp.clip(jnp.floor(RESOLUTION * obs).astype(jnp.int32), 0, limit)
        return table[point[0], point[1]]

    return policy

"""Deep Sea Treasure (discrete), identical to MO-Gymnasium's ``deep-sea-treasure-v0``.

A submarine starts at the top-left cell (row 0, col 0) of a grid. Actions: 0 up, 1 down, 2 left,
3 right. A move that would leave the grid or enter rock (-10) is not made. Entering a treasure cell
ends the episode. Every step's reward is ``(treasure value or 0, -1)``. Observation: ``(row, col)``
as int32, or ``0.1 * (row, col)`` as float32 with ``float_state=True``. MO-Gymnasium adds a 100-step
time limit; ``make`` does the same.
"""

from __future__ import annotations

from collections import deque

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from moiq_jax.envs.base import Env, State

ROCK = -10.0

# Yang et al.'s convex map, as in MO-Gymnasium.
CONVEX_MAP = np.array(
    [
        [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [0.7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, 8.2, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, -10, 11.5, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, -10, -10, 14.0, 15.1, 16.1, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 19.6, 20.3, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, 22.4, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, -10, 23.7, 0],
    ],
    dtype=np.float32,
)

# MO-Gymnasium's concave map: same layout, values whose front is concave.
CONCAVE_MAP = np.array(
    [
        [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [1.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, 2.0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, -10, 3.0, 0, 0, 0, 0, 0, 0, 0, 0],
        [-10, -10, -10, 5.0, 8.0, 16.0, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 0, 0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, 24.0, 50.0, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, 0, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, 74.0, 0, 0],
        [-10, -10, -10, -10, -10, -10, -10, -10, -10, 124.0, 0],
    ],
    dtype=np.float32,
)

# The 6x6 mini map of the paper's sec. 4.1.2, in the same staircase style. Its undiscounted front
# (treasure, -steps) is (1, -1), (7, -3), (11, -5), (14, -7), (16, -9), (16.8, -10): every point is on
# the convex hull, so each one is the unique optimum of some linear preference. Expert [0.1, 0.9]
# takes the first treasure, expert [0.9, 0.1] the last.
MINI_MAP = np.array(
    [
        [0, 0, 0, 0, 0, 0],
        [1.0, 0, 0, 0, 0, 0],
        [-10, 7.0, 0, 0, 0, 0],
        [-10, -10, 11.0, 0, 0, 0],
        [-10, -10, -10, 14.0, 0, 0],
        [-10, -10, -10, -10, 16.0, 16.8],
    ],
    dtype=np.float32,
)

# Lattice moves as (d_row, d_col). Discrete DST's actions are the four compass moves; continuous DST
# can reach any of the eight neighbouring points of its half-cell lattice in one step (see cdst.py).
COMPASS_MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))
KING_MOVES = tuple((dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if (dr, dc) != (0, 0))


class SeaMap:
    """A validated DST map with the start at (0, 0): cells are rock (-10), water (0) or treasure (> 0).

    Knows its treasures and the fewest steps to each one for a set of moves, hence the exact
    undiscounted Pareto front. Searches run over a lattice of ``resolution`` points per cell side
    (1 for discrete DST: points are cells); lattice point ``(y, x)`` lies in cell
    ``(y // resolution, x // resolution)`` and the start is the point ``(resolution // 2,) * 2``.
    Moves may not enter rock or leave the map; entering a treasure ends the episode.
    """

    def __init__(self, grid):
        try:
            array = np.array(grid, dtype=np.float32)
        except ValueError as err:
            raise ValueError(f"sea map is not rectangular: every row must have the same length ({err})") from None
        if array.ndim != 2 or array.shape[0] < 1 or array.shape[1] < 1:
            raise ValueError(f"sea map must be a non-empty 2-D grid (rows x cols), got shape {array.shape}")
        if not np.all(np.isfinite(array)):
            raise ValueError("sea map has NaN or infinite cells")
        bad = (array != ROCK) & (array < 0)
        if np.any(bad):
            raise ValueError(
                f"sea map cells must be rock (-10), water (0) or a positive treasure; bad cells at "
                f"{np.argwhere(bad).tolist()}"
            )
        if array[0, 0] != 0:
            raise ValueError(f"the start cell (0, 0) must be water, got {array[0, 0]}")
        if not np.any(array > 0):
            raise ValueError("sea map has no treasure")
        self.grid = array
        self.rows, self.cols = array.shape

    def treasures(self) -> list[tuple[int, int]]:
        """Treasure cells (row, col) in row-major order."""
        return [tuple(int(i) for i in rc) for rc in np.argwhere(self.grid > 0)]

    def lattice(self, resolution: int) -> np.ndarray:
        """The map value at every lattice point, shape ``(rows * resolution, cols * resolution)``."""
        return np.kron(self.grid, np.ones((resolution, resolution), np.float32))

    def _search(self, sources, moves, enterable, expandable) -> np.ndarray:
        """Breadth-first steps from the nearest of ``sources`` to every lattice point (-1 where unreachable)."""
        dist = -np.ones(enterable.shape, dtype=np.int64)
        queue = deque()
        for point in sources:
            dist[point] = 0
            queue.append(point)
        height, width = enterable.shape
        while queue:
            y, x = queue.popleft()
            if not expandable[y, x]:
                continue
            for dy, dx in moves:
                ny, nx = y + dy, x + dx
                if 0 <= ny < height and 0 <= nx < width and enterable[ny, nx] and dist[ny, nx] < 0:
                    dist[ny, nx] = dist[y, x] + 1
                    queue.append((ny, nx))
        return dist

    def distances_from_start(self, moves, resolution: int = 1) -> np.ndarray:
        """Fewest steps from the start to every lattice point: rock cannot be entered, and a treasure
        is reached but not left (it ends the episode)."""
        values = self.lattice(resolution)
        start = (resolution // 2, resolution // 2)
        return self._search([start], moves, values != ROCK, values <= 0)

    def distances_to(self, treasure, moves, resolution: int = 1) -> np.ndarray:
        """Fewest steps from every lattice point to the cell ``treasure`` without entering rock or
        another treasure. The move sets are symmetric, so this searches outward from the treasure."""
        r, c = treasure
        values = self.lattice(resolution)
        enterable = values == 0
        enterable[r * resolution:(r + 1) * resolution, c * resolution:(c + 1) * resolution] = True
        sources = [(r * resolution + i, c * resolution + j) for i in range(resolution) for j in range(resolution)]
        return self._search(sources, moves, enterable, enterable)

    def treasure_steps(self, moves, resolution: int = 1) -> dict[tuple[int, int], int]:
        """Fewest steps from the start to each reachable treasure cell."""
        dist = self.distances_from_start(moves, resolution)
        steps = {}
        for r, c in self.treasures():
            block = dist[r * resolution:(r + 1) * resolution, c * resolution:(c + 1) * resolution]
            if np.any(block >= 0):
                steps[(r, c)] = int(block[block >= 0].min())
        return steps

    def pareto_front(self, moves, resolution: int = 1) -> np.ndarray:
        """Exact undiscounted Pareto front: rows ``(treasure, -steps)``, sorted by steps."""
        points = sorted(
            {(float(self.grid[t]), -float(s)) for t, s in self.treasure_steps(moves, resolution).items()},
            key=lambda p: -p[1],
        )
        front = [p for p in points if not any(q != p and q[0] >= p[0] and q[1] >= p[1] for q in points)]
        return np.array(front, dtype=np.float32).reshape(-1, 2)


@struct.dataclass
class GridState:
    position: jax.Array  # (row, col), int32


class DeepSeaTreasure(Env):
    """Discrete Deep Sea Treasure; see the module docstring for the rules."""

    deterministic_reset = True
    reward_dim = 2
    observation_size = 2
    num_actions = 4

    def __init__(self, sea_map=CONVEX_MAP, float_state: bool = False):
        self.sea_map = sea_map if isinstance(sea_map, SeaMap) else SeaMap(sea_map)
        self.float_state = bool(float_state)
        # ``step`` is a lookup in the tabular model: one source of truth for the dynamics, and the
        # fewest operations per step.
        next_state, reward, terminal = self.tabular()
        self._next_state, self._reward, self._terminal = map(jnp.asarray, (next_state, reward, terminal))
        cells = np.arange(self.sea_map.rows * self.sea_map.cols)
        self._positions = jnp.asarray(np.stack(np.divmod(cells, self.sea_map.cols), axis=1), jnp.int32)

    def pareto_front(self) -> np.ndarray:
        """Exact undiscounted front ``(treasure, -steps)`` of this map."""
        return self.sea_map.pareto_front(COMPASS_MOVES)

    def _observe(self, position):
        return position.astype(jnp.float32) * 0.1 if self.float_state else position

    def reset(self, key):
        del key  # the start is always (0, 0)
        position = jnp.zeros((2,), jnp.int32)
        return State(
            env_state=GridState(position),
            obs=self._observe(position),
            reward=jnp.zeros((2,), jnp.float32),
            done=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
        )

    def step(self, state, action):
        self.check_action(action)
        action = jnp.clip(jnp.asarray(action, jnp.int32), 0, self.num_actions - 1)
        position = state.env_state.position
        cell = position[0] * self.sea_map.cols + position[1]
        next_cell = self._next_state[cell, action]
        position = self._positions[next_cell]
        reward = self._reward[cell, action]
        found = self._terminal[next_cell]
        return state.replace(
            env_state=GridState(position),
            obs=self._observe(position),
            reward=reward,
            done=found,
            truncated=jnp.zeros((), bool),  # only a time limit truncates
        )

    def tabular(self):
        """The MDP as tables over cells ``s = row * cols + col`` (rock cells included, never reached).

        Returns ``(next_state[S, A], reward[S, A, 2], terminal[S])``; ``step`` looks its dynamics up here.
        """
        rows, cols = self.sea_map.rows, self.sea_map.cols
        grid = self.sea_map.grid
        S = rows * cols
        next_state = np.zeros((S, self.num_actions), np.int32)
        reward = np.zeros((S, self.num_actions, 2), np.float32)
        for r in range(rows):
            for c in range(cols):
                for a, (dr, dc) in enumerate(COMPASS_MOVES):
                    nr, nc = r + dr, c + dc
                    if not (0 <= nr < rows and 0 <= nc < cols) or grid[nr, nc] == ROCK:
                        nr, nc = r, c
                    next_state[r * cols + c, a] = nr * cols + nc
                    reward[r * cols + c, a] = (max(float(grid[nr, nc]), 0.0), -1.0)
        terminal = (grid > 0).reshape(-1)
        return next_state, reward, terminal

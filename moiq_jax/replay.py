"""A jittable replay buffer: a pytree of fixed-size arrays with a write position and a fill count.

Every function is pure, so buffers live inside ``lax.scan`` and ``jax.vmap`` over a leading axis gives
one buffer per expert (``jax.vmap(replay.add)``, ``jax.vmap(replay.sample)``).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct


@struct.dataclass
class ReplayBuffer:
    """``data``: a pytree whose leaves have a leading ``capacity`` axis; ``position``: the next row to
    write; ``size``: rows holding transitions (at most capacity)."""

    data: Any
    position: jax.Array
    size: jax.Array

    @property
    def capacity(self) -> int:
        return jax.tree_util.tree_leaves(self.data)[0].shape[0]


def init(example: Any, capacity: int) -> ReplayBuffer:
    """An empty buffer for transitions shaped like ``example`` (one transition, no batch axis)."""
    data = jax.tree_util.tree_map(lambda x: jnp.zeros((capacity, *jnp.shape(x)), jnp.asarray(x).dtype), example)
    return ReplayBuffer(data, jnp.zeros((), jnp.int32), jnp.zeros((), jnp.int32))


def add(buffer: ReplayBuffer, batch: Any) -> ReplayBuffer:
    """Write a batch of transitions (leading axis n <= capacity), overwriting the oldest when full."""
    n = jax.tree_util.tree_leaves(batch)[0].shape[0]
    rows = (buffer.position + jnp.arange(n)) % buffer.capacity
    data = jax.tree_util.tree_map(lambda store, x: store.at[rows].set(x), buffer.data, batch)
    return ReplayBuffer(
        data, (buffer.position + n) % buffer.capacity, jnp.minimum(buffer.size + n, buffer.capacity)
    )


def sample(buffer: ReplayBuffer, key: jax.Array, batch_size: int) -> Any:
    """``batch_size`` transitions drawn uniformly with replacement from the filled rows."""
    rows = jax.random.randint(key, (batch_size,), 0, jnp.maximum(buffer.size, 1))
    return jax.tree_util.tree_map(lambda store: store[rows], buffer.data)

"""The environment protocol: pure functions of an explicit state, with a vector reward.

Every env is a stateless object with ``reset(key) -> State`` and ``step(state, action) -> State``;
both are pure, so they jit, ``vmap`` over envs and run inside ``lax.scan``.
"""

from __future__ import annotations

import abc
from typing import Any

import jax
import numpy as np
from flax import struct


@struct.dataclass
class State:
    """One step of an env.

    env_state: the env's own pytree (positions, physics state); opaque to learners.
    obs: the observation after the step.
    reward: the vector reward of the step, shape ``(reward_dim,)``, float32.
    done: True when the step reached a terminal state (Gymnasium's ``terminated``).
    truncated: True when a time limit ended the episode.
    info: extra arrays (wrappers keep their bookkeeping here); its keys never change between steps.
    """

    env_state: Any
    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    truncated: jax.Array
    info: dict = struct.field(default_factory=dict)


def is_concrete(x) -> bool:
    """True when ``x`` holds values (not a tracer), so it can be checked in Python."""
    return not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(x))


class Env(abc.ABC):
    """A multi-objective env. Subclasses set ``reward_dim``, ``observation_size`` and either
    ``num_actions`` (discrete) or ``action_size`` (continuous, actions in [-1, 1])."""

    reward_dim: int
    observation_size: int
    num_actions: int | None = None
    action_size: int | None = None
    deterministic_reset: bool = False  # True when reset ignores its key (AutoReset then draws no keys)

    @property
    def discrete(self) -> bool:
        return self.num_actions is not None

    @abc.abstractmethod
    def reset(self, key: jax.Array) -> State: ...

    @abc.abstractmethod
    def step(self, state: State, action: jax.Array) -> State: ...

    @property
    def unwrapped(self) -> Env:
        return self

    def check_action(self, action, batch_shape: tuple = ()) -> None:
        """Raise ValueError when a concrete action is outside the action space; tracers pass."""
        if not is_concrete(action):
            return
        a = np.asarray(action)
        name = type(self.unwrapped).__name__
        if self.discrete:
            if a.shape != batch_shape:
                raise ValueError(f"{name}: expected a discrete action of shape {batch_shape}, got shape {a.shape}")
            if not np.issubdtype(a.dtype, np.integer) or np.any(a < 0) or np.any(a >= self.num_actions):
                raise ValueError(
                    f"{name}: actions are integers in [0, {self.num_actions}), got {a.ravel()[:8].tolist()}"
                )
        else:
            expected = (*batch_shape, self.action_size)
            if a.shape != expected:
                raise ValueError(f"{name}: expected an action of shape {expected}, got shape {a.shape}")
            if not np.all(np.isfinite(a)) or np.any(np.abs(a) > 1.0 + 1e-6):
                raise ValueError(f"{name}: actions must be finite and in [-1, 1], got max |a| = {np.abs(a).max()}")


class Wrapper(Env):
    """An env that delegates to an inner env; override what changes."""

    def __init__(self, env: Env):
        self.env = env

    def __getattr__(self, name):
        # Only reached for attributes the wrapper does not define: sizes, pareto_front, maps...
        if name == "env":
            raise AttributeError(name)
        return getattr(self.env, name)

    @property
    def reward_dim(self) -> int:
        return self.env.reward_dim

    @property
    def observation_size(self) -> int:
        return self.env.observation_size

    @property
    def num_actions(self):
        return self.env.num_actions

    @property
    def action_size(self):
        return self.env.action_size

    @property
    def unwrapped(self) -> Env:
        return self.env.unwrapped

    @property
    def deterministic_reset(self) -> bool:
        return self.env.deterministic_reset

    def reset(self, key: jax.Array) -> State:
        return self.env.reset(key)

    def step(self, state: State, action: jax.Array) -> State:
        return self.env.step(state, action)


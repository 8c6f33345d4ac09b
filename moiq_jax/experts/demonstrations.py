"""The Demonstrations dataset: expert transitions for several experts, each with its preference or unlabelled.

Arrays are padded to ``[experts, episodes, steps, ...]`` so that learners can ``vmap`` over experts;
``lengths[e, n]`` says how many steps of episode ``n`` of expert ``e`` are real. A file is one ``.npz``
holding the arrays and a JSON ``metadata`` entry (env name, who made it). Unlabelled demonstrations
(``preferences=None``, for learners that infer the preferences) are saved without a ``preferences`` array.
"""

from __future__ import annotations

import json
import os
import zipfile

import jax
import numpy as np
from flax import struct

from moiq_jax.preferences import check_preferences

ARRAY_FIELDS = ("obs", "actions", "next_obs", "rewards", "dones", "lengths", "preferences")
REQUIRED_FIELDS = ARRAY_FIELDS[:-1]  # a file without preferences holds unlabelled demonstrations


@struct.dataclass
class Demonstrations:
    """Expert transitions, padded to ``[E experts, N episodes, T steps]``.

    obs, next_obs: ``[E, N, T, obs_size]`` float32. actions: ``[E, N, T, action_size]`` float32 for
    continuous envs, ``[E, N, T]`` int32 for discrete ones. rewards: ``[E, N, T, d]`` true vector rewards
    (for evaluation only; learners never see them). dones: ``[E, N, T]`` bool, terminated (not
    truncated). lengths: ``[E, N]`` int32 real steps per episode. preferences: ``[E, d]`` float32, or None
    for unlabelled demonstrations. env: the registered env name the demos were recorded in.
    """

    obs: jax.Array
    actions: jax.Array
    next_obs: jax.Array
    rewards: jax.Array
    dones: jax.Array
    lengths: jax.Array
    preferences: jax.Array | None
    env: str = struct.field(pytree_node=False, default="")
    metadata: dict = struct.field(pytree_node=False, default_factory=dict)

    @property
    def labelled(self) -> bool:
        return self.preferences is not None

    @property
    def num_experts(self) -> int:
        return np.shape(self.lengths)[0]

    @property
    def num_episodes(self) -> int:
        return self.lengths.shape[1]

    @property
    def reward_dim(self) -> int:
        return np.shape(self.preferences)[1] if self.labelled else np.shape(self.rewards)[-1]

    def unlabelled(self) -> Demonstrations:
        """The same demonstrations without their preferences."""
        return self.replace(preferences=None)

    def mask(self) -> np.ndarray:
        """``[E, N, T]`` True on real (non-padding) steps."""
        steps = np.arange(self.obs.shape[2])
        return steps[None, None, :] < np.asarray(self.lengths)[:, :, None]

    def episode_returns(self) -> np.ndarray:
        """``[E, N, d]`` undiscounted true vector return of every episode."""
        return (np.asarray(self.rewards) * self.mask()[..., None]).sum(axis=2)

    def mean_returns(self) -> np.ndarray:
        """``[E, d]`` each expert's mean vector return over its episodes."""
        return self.episode_returns().mean(axis=1)

    def validate(self, env=None) -> Demonstrations:
        """Check shapes, preferences and values; with ``env``, check they fit it. Returns self."""
        obs, actions = np.asarray(self.obs), np.asarray(self.actions)
        if obs.ndim != 4:
            raise ValueError(f"demos: obs must be [experts, episodes, steps, obs_size], got shape {obs.shape}")
        E, N, T, _ = obs.shape
        if self.labelled and (np.ndim(self.preferences) != 2 or np.shape(self.preferences)[0] != E):
            raise ValueError(f"demos: preferences have shape {np.shape(self.preferences)}, expected [{E}, d]: one per "
                             f"expert of obs {obs.shape} (or None for unlabelled demonstrations)")
        expected = {
            "next_obs": obs.shape,
            "rewards": (E, N, T, self.reward_dim),
            "dones": (E, N, T),
            "lengths": (E, N),
        }
        for name, shape in expected.items():
            got = np.shape(getattr(self, name))
            if got != shape:
                raise ValueError(f"demos: {name} has shape {got}, expected {shape} to match obs {obs.shape}")
        if actions.shape[:3] != (E, N, T) or actions.ndim not in (3, 4):
            raise ValueError(f"demos: actions have shape {actions.shape}, expected [{E}, {N}, {T}] or [{E}, {N}, {T}, A]")
        lengths = np.asarray(self.lengths)
        if np.any(lengths < 1) or np.any(lengths > T):
            raise ValueError(f"demos: episode lengths must be in [1, {T}], got {lengths.min()}..{lengths.max()}")
        if self.labelled:
            check_preferences(np.asarray(self.preferences), self.reward_dim, what="demos: preferences")
        mask = self.mask()
        for name in ("obs", "next_obs", "actions", "rewards"):
            values = np.asarray(getattr(self, name))[mask]
            if not np.all(np.isfinite(values)):
                raise ValueError(f"demos: {name} holds NaN or inf values on {int((~np.isfinite(values)).sum())} entries")
        if env is not None:
            self._check_fits(env)
        return self

    def _check_fits(self, env) -> None:
        name = self.env or "the demos' env"
        if self.obs.shape[-1] != env.observation_size:
            raise ValueError(
                f"demos: observations have size {self.obs.shape[-1]} but the env has observation_size "
                f"{env.observation_size} (recorded in {name}; with or without the absorbing-state flag?)"
            )
        if self.reward_dim != env.reward_dim:
            raise ValueError(f"demos: reward_dim {self.reward_dim} does not match the env's {env.reward_dim}")
        if env.discrete:
            if self.actions.ndim != 3:
                raise ValueError(f"demos: a discrete env needs integer actions [E, N, T], got shape {self.actions.shape}")
        elif self.actions.ndim != 4 or self.actions.shape[-1] != env.action_size:
            raise ValueError(f"demos: actions have shape {self.actions.shape}, the env needs action_size {env.action_size}")

    def save(self, path: str | os.PathLike) -> None:
        """Write one ``.npz`` with the arrays and a JSON ``metadata`` entry."""
        self.validate()
        meta = {**self.metadata, "env": self.env, "format": "moiq_jax.Demonstrations/1"}
        arrays = {name: np.asarray(getattr(self, name)) for name in ARRAY_FIELDS if getattr(self, name) is not None}
        with open(path, "wb") as f:
            np.savez_compressed(f, metadata=np.array(json.dumps(meta)), **arrays)

    @classmethod
    def load(cls, path: str | os.PathLike, env=None) -> Demonstrations:
        """Read a file written by ``save`` and validate it (against ``env`` when given); a file without
        preferences gives unlabelled demonstrations (``preferences=None``)."""
        if not os.path.exists(path):
            raise FileNotFoundError(f"demos file {os.fspath(path)!r} does not exist")
        if not zipfile.is_zipfile(path):  # np.load would call other bytes "pickled data"
            raise ValueError(f"demos file {os.fspath(path)!r} is corrupt or not a .npz written by moiq_jax")
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = [name for name in (*REQUIRED_FIELDS, "metadata") if name not in data.files]
                if missing:
                    raise ValueError(f"demos file {os.fspath(path)!r} lacks {missing}; was it written by Demonstrations.save?")
                arrays = {name: data[name] if name in data.files else None for name in ARRAY_FIELDS}
                meta = json.loads(str(data["metadata"]))
        except (zipfile.BadZipFile, OSError, EOFError, json.JSONDecodeError) as err:
            raise ValueError(f"demos file {os.fspath(path)!r} is corrupt or not a .npz written by moiq_jax: {err}") from None
        env_name = meta.pop("env", "")
        meta.pop("format", None)
        return cls(**arrays, env=env_name, metadata=meta).validate(env)

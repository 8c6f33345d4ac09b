"""Registered envs by name, and ``make`` which builds one with its time limit."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from moiq_jax.envs.base import Env
from moiq_jax.envs.cdst import ContinuousDeepSeaTreasure
from moiq_jax.envs.dst import CONCAVE_MAP, CONVEX_MAP, MINI_MAP, DeepSeaTreasure
from moiq_jax.envs.wrappers import AbsorbingState, TimeLimit


@dataclasses.dataclass(frozen=True)
class EnvSpec:
    name: str
    factory: Callable[..., Env]
    episode_length: int
    description: str


_REGISTRY: dict[str, EnvSpec] = {}


def register(name: str, factory: Callable[..., Env], episode_length: int, description: str) -> None:
    if name in _REGISTRY:
        raise ValueError(f"env {name!r} is already registered")
    _REGISTRY[name] = EnvSpec(name, factory, episode_length, description)


def registered() -> dict[str, EnvSpec]:
    """Name -> spec of every registered env."""
    return dict(_REGISTRY)


def spec(name: str) -> EnvSpec:
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; known envs: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def make(name: str, episode_length: int | None = None, absorbing: bool = False, **kwargs) -> Env:
    """Build a registered env with its time limit (``episode_length`` overrides the default).

    ``absorbing=True`` puts an absorbing state after termination (paper sec. 4.1.1), so every episode
    runs to the time limit. Other keyword arguments go to the env's constructor.
    """
    env_spec = spec(name)
    env = env_spec.factory(**kwargs)
    if absorbing:
        env = AbsorbingState(env)
    return TimeLimit(env, env_spec.episode_length if episode_length is None else episode_length)


register("dst", lambda **kw: DeepSeaTreasure(CONVEX_MAP, **kw), 100,
         "Deep Sea Treasure, convex map (MO-Gymnasium deep-sea-treasure-v0)")
register("dst-concave", lambda **kw: DeepSeaTreasure(CONCAVE_MAP, **kw), 100,
         "Deep Sea Treasure, concave map (MO-Gymnasium deep-sea-treasure-concave-v0)")
register("dst-mini", lambda **kw: DeepSeaTreasure(MINI_MAP, **kw), 100,
         "Deep Sea Treasure, 6x6 mini map (paper sec. 4.1.2)")
register("cdst", lambda **kw: ContinuousDeepSeaTreasure(CONVEX_MAP, **kw), 100,
         "Continuous Deep Sea Treasure: 2-D position, 2-D velocity action, convex map")


def _mujoco(class_name: str) -> Callable[..., Env]:
    """A factory that imports the MuJoCo envs (and MJX) only when one is built."""

    def factory(**kwargs) -> Env:
        from moiq_jax.envs import mujoco

        return getattr(mujoco, class_name)(**kwargs)

    return factory


register("mo-hopper", _mujoco("Hopper"), 1000,
         "MJX Hopper-v5: (x velocity, 10 x height, -|a|^2) + healthy (MO-Gymnasium mo-hopper-v5)")
register("mo-walker2d", _mujoco("Walker2d"), 1000,
         "MJX Walker2d-v5: (x velocity, -|a|^2) + healthy (MO-Gymnasium mo-walker2d-v5)")
register("mo-halfcheetah", _mujoco("HalfCheetah"), 1000,
         "MJX HalfCheetah-v5: (x velocity, -|a|^2) (MO-Gymnasium mo-halfcheetah-v5)")
register("mo-ant", _mujoco("Ant"), 1000,
         "MJX Ant-v5: (x velocity, -|a|^2) + healthy - contact cost (mo-ant-v5's objectives 0 and 2)")

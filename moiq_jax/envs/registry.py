"""Registered envs by name, and ``make`` which builds one with its time limit."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax

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
    backends: tuple[str, ...] = ()  # physics backends (MuJoCo tasks: "mujoco", "mjx"); () for pure-JAX envs


_REGISTRY: dict[str, EnvSpec] = {}


def register(name: str, factory: Callable[..., Env], episode_length: int, description: str,
             backends: tuple[str, ...] = ()) -> None:
    """Register an env; one with ``backends`` has a factory taking ``backend=`` (one of them)."""
    if name in _REGISTRY:
        raise ValueError(f"env {name!r} is already registered")
    _REGISTRY[name] = EnvSpec(name, factory, episode_length, description, tuple(backends))


def registered() -> dict[str, EnvSpec]:
    """Name -> spec of every registered env."""
    return dict(_REGISTRY)


def spec(name: str) -> EnvSpec:
    if name not in _REGISTRY:
        raise ValueError(f"unknown env {name!r}; known envs: {', '.join(sorted(_REGISTRY))}")
    return _REGISTRY[name]


def backends(name: str) -> tuple[str, ...]:
    """The physics backends env ``name`` can run on, the default first where there is a choice;
    ``()`` for envs written in JAX alone (they take no ``backend``)."""
    env_spec = spec(name)
    if not env_spec.backends:
        return ()
    default = default_backend()
    return tuple(sorted(env_spec.backends, key=lambda b: b != default))


def default_backend() -> str:
    """The MuJoCo backend ``make`` picks when given none: ``"mujoco"`` (MuJoCo's C engine) when JAX's
    default device is a CPU, ``"mjx"`` on an accelerator."""
    return "mujoco" if jax.default_backend() == "cpu" else "mjx"


def make(name: str, episode_length: int | None = None, absorbing: bool = False, backend: str | None = None,
         **kwargs) -> Env:
    """Build a registered env with its time limit (``episode_length`` overrides the default).

    ``absorbing=True`` puts an absorbing state after termination (paper sec. 4.1.1), so every episode
    runs to the time limit. ``backend`` picks the physics of an env that has several (``backends(name)``;
    None: ``default_backend()``); envs without any take only None. Other keyword arguments go to the env's
    constructor.
    """
    env_spec = spec(name)
    if env_spec.backends:
        backend = default_backend() if backend is None else backend
        if backend not in env_spec.backends:
            raise ValueError(f"env {name!r} has backends {', '.join(env_spec.backends)}; got {backend!r}")
        env = env_spec.factory(backend=backend, **kwargs)
    elif backend is not None:
        raise ValueError(f"env {name!r} is written in JAX and has no backend choice; got backend={backend!r}")
    else:
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


def _mujoco(name: str) -> Callable[..., Env]:
    """A factory that imports the MuJoCo envs (and MJX, for its backend) only when one is built."""

    def factory(backend: str, **kwargs) -> Env:
        from moiq_jax.envs import mujoco

        return mujoco.make_env(name, backend, **kwargs)

    return factory


_MUJOCO_BACKENDS = ("mujoco", "mjx")
register("mo-hopper", _mujoco("mo-hopper"), 1000,
         "Hopper-v5: (x velocity, 10 x height, -|a|^2) + healthy (MO-Gymnasium mo-hopper-v5)", _MUJOCO_BACKENDS)
register("mo-walker2d", _mujoco("mo-walker2d"), 1000,
         "Walker2d-v5: (x velocity, -|a|^2) + healthy (MO-Gymnasium mo-walker2d-v5)", _MUJOCO_BACKENDS)
register("mo-halfcheetah", _mujoco("mo-halfcheetah"), 1000,
         "HalfCheetah-v5: (x velocity, -|a|^2) (MO-Gymnasium mo-halfcheetah-v5)", _MUJOCO_BACKENDS)
register("mo-halfcheetah-v4", _mujoco("mo-halfcheetah-v4"), 1000,
         "HalfCheetah: (x velocity, -0.1 |a|^2) (MO-Gymnasium mo-halfcheetah-v4)", _MUJOCO_BACKENDS)
register("mo-ant", _mujoco("mo-ant"), 1000,
         "Ant-v5: (x velocity, -|a|^2) + healthy - contact cost (mo-ant-v5's objectives 0 and 2)", _MUJOCO_BACKENDS)

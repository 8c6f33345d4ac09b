"""Pure-functional multi-objective environments with vector rewards."""

from moiq_jax.envs.base import Env, State, Wrapper
from moiq_jax.envs.cdst import ContinuousDeepSeaTreasure
from moiq_jax.envs.dst import CONCAVE_MAP, CONVEX_MAP, MINI_MAP, DeepSeaTreasure, SeaMap
from moiq_jax.envs.registry import EnvSpec, backends, default_backend, make, register, registered, spec
from moiq_jax.envs.wrappers import AbsorbingState, AutoReset, DoneOnAbsorption, TimeLimit, VmapWrapper

__all__ = [
    "CONCAVE_MAP",
    "CONVEX_MAP",
    "MINI_MAP",
    "AbsorbingState",
    "AutoReset",
    "ContinuousDeepSeaTreasure",
    "DeepSeaTreasure",
    "DoneOnAbsorption",
    "Env",
    "EnvSpec",
    "SeaMap",
    "State",
    "TimeLimit",
    "VmapWrapper",
    "Wrapper",
    "backends",
    "default_backend",
    "make",
    "register",
    "registered",
    "spec",
]

"""moiq_jax: multi-objective inverse RL from several experts with different preferences, in JAX."""

from moiq_jax import envs
from moiq_jax.evaluate import episode_returns

__version__ = "0.1.0"
__all__ = ["envs", "episode_returns"]

"""moiq_jax: multi-objective inverse RL from several experts with different preferences, in JAX."""

from moiq_jax import envs
from moiq_jax.archive import load_result, save_result, stack_results
from moiq_jax.config import Config
from moiq_jax.evaluate import episode_returns, evaluate
from moiq_jax.experts import Demonstrations
from moiq_jax.result import Result
from moiq_jax.reward_recovery import policy_episodes, reward_correlations, rollout_reward_correlations
from moiq_jax.train import sweep, train

__version__ = "0.1.0"
__all__ = ["Config", "Demonstrations", "Result", "envs", "episode_returns", "evaluate", "load_result",
           "policy_episodes", "reward_correlations", "rollout_reward_correlations", "save_result", "stack_results", "sweep", "train"]

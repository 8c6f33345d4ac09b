"""Expert policies and their demonstrations."""

from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.experts.dst_oracle import optimal_treasure, oracle_policy, record_demonstrations

__all__ = ["Demonstrations", "optimal_treasure", "oracle_policy", "record_demonstrations"]

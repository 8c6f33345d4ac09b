"""Expert policies and their demonstrations."""

from moiq_jax.experts.demonstrations import Demonstrations

__all__ = ["Demonstrations"]

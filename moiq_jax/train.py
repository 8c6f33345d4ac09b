"""``train(config)``: run the configured algorithm end to end."""

from __future__ import annotations

import importlib

from moiq_jax.config import Config

# algo name -> module exposing ``train(config) -> result``
_ENTRY_POINTS: dict[str, str] = {"admm": "moiq_jax.algos.admm"}


def train(config: Config):
    """Validate ``config`` and run its algorithm; returns that algorithm's result."""
    config.validate()
    if config.algo not in _ENTRY_POINTS:
        raise NotImplementedError(f"algo {config.algo!r} is not available yet")
    return importlib.import_module(_ENTRY_POINTS[config.algo]).train(config)

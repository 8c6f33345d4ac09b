"""``train(config)``: run the configured algorithm end to end."""

from __future__ import annotations

import importlib

from moiq_jax.config import Config

# algo name -> module exposing ``train(config) -> result``
_ENTRY_POINTS: dict[str, str] = {
    "admm": "moiq_jax.algos.admm",
    "moiq": "moiq_jax.algos.moiq_train",
    "iq_learn": "moiq_jax.algos.moiq_train",  # the same program with one model per expert and beta = 0
    "sac": "moiq_jax.algos.moiq_train",  # experts: the same program on the true reward, one model per preference
    "gail": "moiq_jax.algos.moiq_train",  # the same program: SAC on a discriminator's reward, one model per expert
}


def train(config: Config, **options):
    """Validate ``config`` and run its algorithm; returns that algorithm's result.

    ``options`` go to the algorithm's ``train``; for moiq, iq_learn, sac and gail: ``run_dir`` (logs and checkpoints),
    ``resume``, ``progress`` (a progress bar) and ``log`` (a print function, or None)."""
    config.validate()
    if config.algo not in _ENTRY_POINTS:
        raise NotImplementedError(f"algo {config.algo!r} is not available yet")
    return importlib.import_module(_ENTRY_POINTS[config.algo]).train(config, **options)


def sweep(config: Config, **values):
    """Train every combination of the given values (``beta=[...]``, ``seed=[...]``) as one vmapped
    program; see ``moiq_jax.algos.moiq_train.sweep``."""
    config.validate()
    if config.algo == "admm":
        raise NotImplementedError("sweep is available for moiq, iq_learn, sac and gail, not admm")
    unknown = set(values) - {"beta", "seed"}
    if unknown:
        raise ValueError(f"sweep varies beta and seed only, got {sorted(unknown)}")
    from moiq_jax.algos.moiq_train import sweep as moiq_sweep

    return moiq_sweep(config, **values)

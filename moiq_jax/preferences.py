"""Preferences: non-negative weights over the objectives that sum to 1 (linear scalarisation)."""

from __future__ import annotations

import numpy as np

TOLERANCE = 1e-5


def check_preferences(preferences, reward_dim: int, what: str = "preferences") -> np.ndarray:
    """Return ``preferences`` as a float32 ``[n, reward_dim]`` array, or raise a ValueError saying what is wrong."""
    prefs = np.asarray(preferences, dtype=np.float64)
    if prefs.ndim == 1:
        prefs = prefs[None]
    if prefs.ndim != 2 or prefs.shape[0] < 1:
        raise ValueError(f"{what}: expected a list of preference vectors, got shape {prefs.shape}")
    if prefs.shape[1] != reward_dim:
        raise ValueError(
            f"{what}: each preference needs {reward_dim} weights (one per objective), got {prefs.shape[1]}: "
            f"{prefs.tolist()}"
        )
    if not np.all(np.isfinite(prefs)):
        raise ValueError(f"{what}: weights must be finite, got {prefs.tolist()}")
    if np.any(prefs < 0):
        raise ValueError(f"{what}: weights must be non-negative, got {prefs.tolist()}")
    sums = prefs.sum(axis=1)
    if np.any(np.abs(sums - 1.0) > TOLERANCE):
        raise ValueError(f"{what}: each preference must sum to 1, got sums {np.round(sums, 6).tolist()}")
    return prefs.astype(np.float32)


def preference_sweep(num: int = 19) -> np.ndarray:
    """The paper's transfer preferences ``[1 - k / (num + 1), k / (num + 1)]`` for k = 1..num (two objectives)."""
    k = np.arange(1, num + 1) / (num + 1)
    return np.stack([1.0 - k, k], axis=1).astype(np.float32)

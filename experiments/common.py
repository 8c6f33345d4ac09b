"""What every experiment script shares: the host set-up (CPU devices, compilation cache), the cdst
set-up (tuned config, demonstrations, exact expert returns, the 19 transfer preferences and their optima),
and picking one run out of a sweep's ``Result``. Scripts train through the public API (``moiq_jax.train``,
``moiq_jax.sweep``, ``moiq_jax.evaluate``)."""

from __future__ import annotations

import jax
import numpy as np

import moiq_jax
from moiq_jax.config import Config, tuned
from moiq_jax.experts.cdst_oracle import expert_returns
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.runtime import split_cpu_into_devices, use_compilation_cache

TRANSFER_PREFERENCES = np.array([[1 - 0.05 * k, 0.05 * k] for k in range(1, 20)])


def start(runs: int | None = None) -> None:
    """Before any JAX computation: one CPU device per run of the coming sweeps (when ``runs`` is given),
    and the persistent compilation cache, so that a rerun loads its programs instead of compiling them."""
    if runs is not None:
        split_cpu_into_devices(runs)
    use_compilation_cache()


def run_index(tree, index):
    """Run (or ``(run, expert)``) ``index`` of a pytree with a leading run axis."""
    return jax.tree_util.tree_map(lambda x: x[index], tree)


def optimal_for(front: np.ndarray, preference) -> np.ndarray:
    """The front point maximising ``preference . return``."""
    return front[np.argmax(front @ preference)]


def transfer_optima() -> np.ndarray:
    """``[19, 2]`` the exact cdst front's best return for each transfer preference."""
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    return np.stack([optimal_for(front, w) for w in TRANSFER_PREFERENCES])


class CdstSetup:
    """cdst's tuned config with ``changes``, its demonstrations (config order), the experts' preferences
    ``[E, 2]``, exact vector returns ``[E, 2]`` and scalarised returns ``[E]``."""

    def __init__(self, **changes):
        self.config: Config = tuned("cdst", **changes)
        self.demos = load_demonstrations(self.config)
        self.preferences = np.asarray(self.demos.preferences)
        self.expert = expert_returns(self.preferences)
        self.expert_scalar = (self.expert * self.preferences).sum(1)

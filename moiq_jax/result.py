"""``Result``: what training returns, for every algorithm, one run or a sweep."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from moiq_jax.config import Config


@dataclasses.dataclass
class Result:
    """config; preferences ``[E, d]``: the experts' labels, in the config's order, which is the order of
    every per-expert entry below; history: name -> values per evaluation (off-policy: per chunk of
    ``eval_interval`` env steps; ADMM: per round), per-expert entries with an expert axis after it;
    final_params and best_params (by mean scalarised evaluation return; ADMM: the common reward table and
    None); best_return; seconds of wall-clock time.

    A sweep's result has a leading run axis on history, params and best_return, and ``runs``: each swept
    name (``seed``, ``beta``...) -> its value per run; a sweep over preference sets adds ``set`` (its index)
    and ``preferences`` ``[runs, E, d]`` (the run's labels, as ``preferences`` then is). ``extras``: what only one algorithm has, as it gives them
    (ADMM: ``optimal_return [E]`` and ``transfer``, the 19 sweep preferences' results with a seed axis)."""

    config: Config
    preferences: np.ndarray
    history: dict[str, np.ndarray]
    final_params: Any
    best_params: Any
    best_return: np.ndarray
    seconds: float = 0.0
    runs: dict[str, np.ndarray] | None = None
    extras: dict = dataclasses.field(default_factory=dict)

    def run(self, index: int) -> Result:
        """Run ``index`` of a sweep, as the result of that one run."""
        import jax

        if self.runs is None:
            raise ValueError("run(index) takes one run of a sweep; this result is a single run")
        pick = lambda tree: None if tree is None else jax.tree_util.tree_map(lambda x: x[index], tree)
        values = {name: v[index].item() for name, v in self.runs.items() if name not in ("set", "preferences")}
        preferences = np.asarray(self.preferences)
        if "preferences" in self.runs:
            preferences = np.asarray(self.runs["preferences"][index])
            values["preferences"] = tuple(tuple(float(x) for x in w) for w in preferences.tolist())
        return dataclasses.replace(self, config=self.config.replace(**values), preferences=preferences,
                                   history=pick(self.history),
                                   final_params=pick(self.final_params), best_params=pick(self.best_params),
                                   best_return=np.asarray(self.best_return)[index], runs=None)

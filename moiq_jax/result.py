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
    (ADMM: ``optimal_return [E]`` and ``transfer``, the 19 sweep preferences' results with a seed axis).

    One model for all experts (moiq) also keeps, per expert, the actor of that expert's
    best scalarised evaluation return (``best_actor_per_expert``, expert axis after any run axis) and that
    return (``best_return_per_expert [E]``): the model a per-preference reading of "the best model" takes.
    None where each expert has its own model (its ``best_params`` are already that)."""

    config: Config
    preferences: np.ndarray
    history: dict[str, np.ndarray]
    final_params: Any
    best_params: Any
    best_return: np.ndarray
    seconds: float = 0.0
    runs: dict[str, np.ndarray] | None = None
    extras: dict = dataclasses.field(default_factory=dict)
    best_actor_per_expert: Any = None
    best_return_per_expert: np.ndarray | None = None

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
                                   best_return=np.asarray(self.best_return)[index], runs=None,
                                   best_actor_per_expert=pick(self.best_actor_per_expert),
                                   best_return_per_expert=pick(self.best_return_per_expert))

    def expert_best_params(self, expert: int):
        """The best model of expert ``expert`` (in the config's order) alone: ``best_params`` with that expert's
        best actor, ``best_actor_per_expert[expert]`` (one run of one model for all experts)."""
        import jax

        if self.runs is not None:
            raise ValueError("expert_best_params takes one run; take a sweep's run with run(index) first")
        if self.best_actor_per_expert is None:
            raise ValueError(f"this {self.config.algo} result keeps no per-expert best actor (one model per expert: "
                             "its best_params are each expert's own; or a run saved before they were kept)")
        return self.best_params.replace(actor=jax.tree_util.tree_map(lambda x: x[expert], self.best_actor_per_expert))

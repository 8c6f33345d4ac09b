"""Demonstrations for a run, loaded and ordered in one place (MOIQ, its baselines and ADMM use it).

``load_demonstrations(config)`` returns the experts in the config's preference order, so that every
result is reported under the label the user gave. ``preference_order`` is the one canonical order
(descending, first objective first) in which learners hold the experts: the consensus penalty pairs
neighbours in it, and the same experts given in any order train identically.
"""

from __future__ import annotations

import jax
import numpy as np

from moiq_jax.config import Config
from moiq_jax.experts import oracle_demonstrations
from moiq_jax.experts.demonstrations import Demonstrations

EPISODE_FIELDS = ("obs", "actions", "next_obs", "rewards", "dones", "lengths")


def preference_order(preferences) -> np.ndarray:
    """The permutation that sorts ``preferences`` ``[E, d]`` descending, first objective first."""
    return np.lexsort(np.asarray(preferences).T[::-1])[::-1]


def take_experts(demos: Demonstrations, index) -> Demonstrations:
    """The experts ``index`` of ``demos``, in that order."""
    return jax.tree_util.tree_map(lambda x: np.asarray(x)[np.asarray(index)], demos)


def match_preferences(recorded, given, source: str) -> np.ndarray:
    """For each ``given`` preference, the index of the equal ``recorded`` one: the given set may be any of the
    recorded experts (all of them, in any order, or some, e.g. one expert's IQ-Learn); one not recorded raises."""
    recorded, given = np.asarray(recorded, np.float64), np.asarray(given, np.float64)
    index = []
    for w in given:
        close = np.flatnonzero(np.all(np.abs(recorded - w) <= 1e-5, axis=1)) if len(recorded) else []
        if len(close) != 1:
            shown = sorted(map(tuple, np.round(recorded, 6).tolist()))
            raise ValueError(f"the demos in {source} are of preferences {shown}; the configured "
                             f"{tuple(np.round(w, 6).tolist())} is not one of them; set --preferences to some of them")
        index.append(int(close[0]))
    if len(set(index)) != len(index):
        raise ValueError(f"the configured preferences name one of the demos in {source} twice")
    return np.asarray(index)


def first_episodes(demos: Demonstrations, config: Config) -> Demonstrations:
    """The first ``config.num_demos`` episodes per expert of the configured file's ``demos``; too few raise."""
    if demos.num_episodes < config.num_demos:
        raise ValueError(f"the demos in {config.demos!r} hold {demos.num_episodes} episodes per expert, fewer "
                         f"than num_demos = {config.num_demos}")
    return demos.replace(**{name: np.asarray(getattr(demos, name))[:, : config.num_demos] for name in EPISODE_FIELDS})


def load_demonstrations(config: Config, env=None) -> Demonstrations:
    """The first ``num_demos`` episodes per expert of the configured demos file (the experts of the config's
    preferences, all of the file's or some, in any order), or fresh oracle demonstrations; experts in
    ``config.preferences`` order."""
    if config.demos is None:
        sorted_prefs = np.asarray(config.preferences)[preference_order(config.preferences)]
        demos = oracle_demonstrations(config.env, sorted_prefs, config.num_demos, config.seed)
        return take_experts(demos, np.argsort(preference_order(config.preferences)))
    env = config.make_env(absorbing=True) if env is None else env
    demos = Demonstrations.load(config.demos, env)
    if getattr(demos, "preferences", None) is None:
        raise ValueError(f"the demos in {config.demos!r} carry no preferences; this learner needs labelled demos")
    index = match_preferences(demos.preferences, config.preferences, repr(config.demos))
    return take_experts(first_episodes(demos, config), index)


def load_unlabelled_demonstrations(config: Config, env=None) -> Demonstrations:
    """The demonstrations of a run that infers its experts' preferences, labels dropped: the first
    ``num_demos`` episodes per expert of the configured file (labelled or not), or fresh oracle
    demonstrations of the experts ``config.preferences`` names (whose labels are then hidden)."""
    if config.demos is None:
        return oracle_demonstrations(config.env, config.preferences, config.num_demos, config.seed).unlabelled()
    env = config.make_env(absorbing=True) if env is None else env
    demos = Demonstrations.load(config.demos, env)
    return first_episodes(demos, config).unlabelled()

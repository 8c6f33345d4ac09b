"""Import and export expert trajectories in the pickle format of IQ-Learn's original code (Div99/IQ-Learn).

Format, as written by IQ-Learn's ``iq_learn/expert_generation.py`` and read by its
``iq_learn/dataset/expert_dataset.py``: one pickled dict per expert with keys ``states``, ``next_states``,
``actions``, ``rewards``, ``dones`` (a sequence per trajectory of per-step values: observation arrays, action
arrays or ints, float rewards, bool dones) and ``lengths`` (an int per trajectory). ``dones`` is Gym's old
``done``, so the time limit sets it too. IQ-Learn trains on ``expert.demos`` trajectories drawn at random
from a file, keeping every ``expert.subsample_freq``-th step; ``load_iq_learn`` keeps every step.

IQ-Learn is single-objective, so imports and exports differ from ``Demonstrations`` in three ways:

- rewards: a file with a vector reward of the env's ``reward_dim`` per step is taken as is; a scalar
  reward is copied to every objective, so that ``w . r`` (preferences sum to 1) is the file's reward; the
  per-objective returns of such demos mean nothing. ``metadata["rewards"]`` says which, per file.
  ``save_iq_learn`` writes the scalarised reward ``w . r``.
- time limit: a ``done`` on a trajectory's step number ``episode_length`` (the env's time limit) is read
  as truncation, not termination; an episode that terminates exactly then is read as truncated too.
- absorbing state: IQ-Learn observations have no absorbing flag. ``absorbing=True`` (the env MOIQ trains
  in) appends the 0.0 flag, turns a termination into a move to the absorbing state and runs the episode
  there to the time limit with zero reward and zero actions, as ``envs.AbsorbingState`` would.
  ``save_iq_learn`` undoes this: it drops the flag and the absorbing steps and marks the termination
  ``done``; the observation the episode terminated on is not kept in absorbing-state demos, so that
  step's ``next_states`` entry is zeros (IQ-Learn masks it by ``done``).

Pickles run code when loaded: load only files you trust.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Sequence

import numpy as np

from moiq_jax import envs
from moiq_jax.experts.demonstrations import Demonstrations
from moiq_jax.preferences import check_preferences

IQ_LEARN_KEYS = ("states", "next_states", "actions", "rewards", "dones", "lengths")
STEP_KEYS = IQ_LEARN_KEYS[:-1]
SCALAR_REWARDS = "scalar reward copied to every objective"
VECTOR_REWARDS = "vector reward from the file"


def read_trajectories(path: str | os.PathLike, num_trajectories: int | None = None) -> dict[str, list]:
    """The first ``num_trajectories`` (all when None) trajectories of an IQ-Learn pickle, per key, with every
    key present and every trajectory's per-step entries as many as its ``lengths`` entry."""
    name = os.fspath(path)
    if not os.path.exists(name):
        raise FileNotFoundError(f"IQ-Learn file {name!r} does not exist")
    try:
        with open(name, "rb") as f:
            data = pickle.load(f)
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, IndexError, TypeError, ValueError) as err:
        raise ValueError(f"IQ-Learn file {name!r} is not a readable pickle: {err!r}") from None
    if not isinstance(data, dict):
        raise TypeError(f"IQ-Learn file {name!r} holds a {type(data).__name__}, not a dict of trajectories")
    missing = [key for key in IQ_LEARN_KEYS if key not in data]
    if missing:
        raise ValueError(f"IQ-Learn file {name!r} lacks the keys {missing} (it has {sorted(map(str, data))})")
    counts = {key: len(data[key]) for key in IQ_LEARN_KEYS}
    if len(set(counts.values())) != 1:
        raise ValueError(f"IQ-Learn file {name!r}: the keys hold different numbers of trajectories: {counts}")
    available = counts["lengths"]
    wanted = available if num_trajectories is None else num_trajectories
    if not 1 <= wanted <= available:
        raise ValueError(f"IQ-Learn file {name!r} holds {available} trajectories, cannot take {wanted}")
    trajectories = {key: list(data[key])[:wanted] for key in IQ_LEARN_KEYS}
    for i, length in enumerate(trajectories["lengths"]):
        if int(length) < 1:
            raise ValueError(f"IQ-Learn file {name!r}: trajectory {i} has length {length}")
        for key in STEP_KEYS:
            if len(trajectories[key][i]) != int(length):
                raise ValueError(f"IQ-Learn file {name!r}: trajectory {i} has {len(trajectories[key][i])} {key} "
                                 f"entries but lengths[{i}] = {int(length)}")
    return trajectories


def _as_array(values, dtype, what: str) -> np.ndarray:
    """``np.asarray(values, dtype)``, or a ValueError naming ``what``."""
    try:
        return np.asarray(values, dtype)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{what}: cannot be read as {np.dtype(dtype).name} numbers: {err}") from None


def _per_step(values, shape: tuple[int, ...], dtype, what: str, hint: str = "") -> np.ndarray:
    """``values`` (one entry per step) as an array of ``shape``, or a ValueError naming ``what``."""
    array = _as_array(values, dtype, what)
    if array.size != np.prod(shape):
        raise ValueError(f"{what}: expected {shape[1:] or 'one value'} per step, got an array of shape "
                         f"{array.shape}{hint}")
    return array.reshape(shape)


def _episode(trajectories: dict, i: int, where: str, env, absorbing: bool) -> dict[str, np.ndarray]:
    """Trajectory ``i`` as arrays fit for ``env`` (absorbing-state env or not), with its reward kind."""
    n = int(trajectories["lengths"][i])
    what = f"{where}: trajectory {i}"
    plain_size = env.observation_size - absorbing
    hint = f" ({env.unwrapped.__class__.__name__} observes {plain_size} values; IQ-Learn files hold no absorbing flag)"
    obs = _per_step(trajectories["states"][i], (n, plain_size), np.float32, f"{what} states", hint)
    next_obs = _per_step(trajectories["next_states"][i], (n, plain_size), np.float32, f"{what} next_states", hint)
    if env.discrete:
        actions = _per_step(trajectories["actions"][i], (n,), np.int32, f"{what} actions")
    else:
        actions = _per_step(trajectories["actions"][i], (n, env.action_size), np.float32, f"{what} actions")
    raw_rewards = _as_array(trajectories["rewards"][i], np.float32, f"{what} rewards")
    if raw_rewards.size == n:
        rewards, kind = np.repeat(raw_rewards.reshape(n, 1), env.reward_dim, axis=1), SCALAR_REWARDS
    else:
        rewards, kind = _per_step(raw_rewards, (n, env.reward_dim), np.float32, f"{what} rewards"), VECTOR_REWARDS
    dones = _per_step(trajectories["dones"][i], (n,), bool, f"{what} dones").copy()
    if n == env.episode_length:
        dones[-1] = False  # Gym's time limit, not termination
    if dones[:-1].any():
        raise ValueError(f"{what} is done at step {int(np.argmax(dones))}, before its last step {n - 1}")
    if absorbing:
        if n > env.episode_length:
            raise ValueError(f"{what} has {n} steps, more than {env.episode_length}, the time limit of the "
                             f"absorbing-state env")
        obs, next_obs, actions, rewards, dones = _into_absorbing_state(env, obs, next_obs, actions, rewards, dones)
    return {"obs": obs, "actions": actions, "next_obs": next_obs, "rewards": rewards, "dones": dones,
            "kind": kind}


def _into_absorbing_state(env, obs, next_obs, actions, rewards, dones):
    """One episode with the absorbing flag appended; if it terminated, its last step moves to the absorbing
    state, which it keeps (zero reward, zero action) until the time limit."""
    flag = np.zeros((len(obs), 1), np.float32)
    obs, next_obs = np.concatenate([obs, flag], axis=1), np.concatenate([next_obs, flag], axis=1)
    if not dones[-1]:
        return obs, next_obs, actions, rewards, dones
    absorbing = np.asarray(env.absorbing_obs())
    next_obs[-1] = absorbing
    tail = env.episode_length - len(obs)
    stay = np.repeat(absorbing[None], tail, axis=0)
    return (np.concatenate([obs, stay]), np.concatenate([next_obs, stay]),
            np.concatenate([actions, np.zeros((tail, *actions.shape[1:]), actions.dtype)]),
            np.concatenate([rewards, np.zeros((tail, rewards.shape[1]), np.float32)]),
            np.zeros(env.episode_length, bool))


def _pad(episodes: list[np.ndarray], steps: int) -> np.ndarray:
    """Episodes stacked along a new first axis, zero-padded along steps to ``steps``."""
    return np.stack([np.pad(x, [(0, steps - len(x))] + [(0, 0)] * (x.ndim - 1)) for x in episodes])


def load_iq_learn(paths: Sequence[str | os.PathLike], preferences, env_name: str, *, absorbing: bool = True,
                  num_trajectories: int | None = None) -> Demonstrations:
    """Demonstrations from IQ-Learn pickles, one file per expert, the expert of ``preferences[e]`` in
    ``paths[e]``, validated against ``envs.make(env_name, absorbing=absorbing)``.

    Every file must hold as many trajectories as the others, or give ``num_trajectories`` to take that many
    from the start of each. See the module docstring for how rewards, dones and the absorbing state are read.
    """
    env = envs.make(env_name, absorbing=absorbing)
    prefs = check_preferences(preferences, env.reward_dim, what="load_iq_learn: preferences")
    paths = list(paths)
    if len(paths) != len(prefs):
        raise ValueError(f"load_iq_learn: {len(paths)} files for {len(prefs)} preferences; give one file per "
                         f"preference (IQ-Learn files hold one single-objective expert each)")
    per_expert, kinds = [], []
    for path in paths:
        trajectories = read_trajectories(path, num_trajectories)
        episodes = [_episode(trajectories, i, repr(os.fspath(path)), env, absorbing)
                    for i in range(len(trajectories["lengths"]))]
        file_kinds = {episode.pop("kind") for episode in episodes}
        if len(file_kinds) > 1:
            raise ValueError(f"IQ-Learn file {os.fspath(path)!r} mixes scalar and vector rewards")
        per_expert.append(episodes)
        kinds.append(file_kinds.pop())
    counts = [len(episodes) for episodes in per_expert]
    if len(set(counts)) != 1:
        raise ValueError(f"load_iq_learn: the files hold {counts} trajectories; pass num_trajectories to take "
                         f"equally many from each")
    lengths = np.array([[len(episode["obs"]) for episode in episodes] for episodes in per_expert], np.int32)
    steps = int(lengths.max())
    fields = {key: np.stack([_pad([episode[key] for episode in episodes], steps) for episodes in per_expert])
              for key in ("obs", "actions", "next_obs", "rewards", "dones")}
    return Demonstrations(
        **fields, lengths=lengths, preferences=prefs, env=env_name,
        metadata={"expert": "IQ-Learn expert pickles", "iq_learn_files": [os.fspath(p) for p in paths],
                  "rewards": kinds, "absorbing": absorbing},
    ).validate(env)


def save_iq_learn(demos: Demonstrations, expert_index: int, path: str | os.PathLike) -> None:
    """Write expert ``expert_index``'s episodes as an IQ-Learn pickle with the scalarised reward ``w . r``.

    Values are plain Python lists, floats, ints and bools, so the file loads under any NumPy version
    (arrays pickled by NumPy 2 name ``numpy._core``, which the NumPy 1.x of IQ-Learn's setup lacks).
    ``path`` must end in ``.pkl``, the ending IQ-Learn reads as a pickle. Demos recorded in the
    absorbing-state env are converted as the module docstring says.
    """
    demos.validate()
    if not 0 <= expert_index < demos.num_experts:
        raise IndexError(f"save_iq_learn: expert_index {expert_index} is not in [0, {demos.num_experts})")
    if not os.fspath(path).endswith(".pkl"):
        raise ValueError(f"save_iq_learn: {os.fspath(path)!r} must end in .pkl, the ending IQ-Learn reads as a pickle")
    plain_size = envs.make(demos.env).observation_size
    obs_size = demos.obs.shape[-1]
    if obs_size not in (plain_size, plain_size + 1):
        raise ValueError(f"save_iq_learn: observations have size {obs_size}, but {demos.env} observes {plain_size} "
                         f"({plain_size + 1} with the absorbing flag)")
    absorbing = obs_size == plain_size + 1
    preference = np.asarray(demos.preferences[expert_index])
    trajectories = {key: [] for key in IQ_LEARN_KEYS}
    for n, length in enumerate(np.asarray(demos.lengths[expert_index])):
        obs, actions, next_obs, rewards, dones = (np.asarray(x[expert_index, n, :length]) for x in (
            demos.obs, demos.actions, demos.next_obs, demos.rewards, demos.dones))
        if absorbing:
            live = int(np.argmax(obs[:, -1] == 1.0)) if np.any(obs[:, -1] == 1.0) else int(length)
            terminated = bool(next_obs[live - 1, -1] == 1.0)
            obs, actions, next_obs, rewards = obs[:live, :-1], actions[:live], next_obs[:live, :-1], rewards[:live]
            dones = np.arange(live) == live - 1 if terminated else np.zeros(live, bool)
        trajectories["states"].append(obs.tolist())
        trajectories["next_states"].append(next_obs.tolist())
        trajectories["actions"].append(actions.tolist())
        trajectories["rewards"].append((rewards @ preference).tolist())
        trajectories["dones"].append(dones.tolist())
        trajectories["lengths"].append(len(obs))
    with open(path, "wb") as f:
        pickle.dump(trajectories, f, protocol=4)

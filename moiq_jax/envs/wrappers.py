"""Env wrappers: time limit, absorbing state, auto-reset and batching.

The usual stack is ``VmapWrapper(AutoReset(TimeLimit(AbsorbingState(env))))``; ``make`` builds the inner
two, trainers add the outer two (and ``DoneOnAbsorption`` between, when asked).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from moiq_jax.envs.base import Env, Wrapper


def _select(pred, on_true, on_false):
    """Leaf-wise ``where(pred, on_true, on_false)`` for a scalar predicate over matching pytrees."""
    return jax.tree_util.tree_map(lambda t, f: jnp.where(pred, t, f), on_true, on_false)


class TimeLimit(Wrapper):
    """Sets ``truncated`` once ``episode_length`` steps have run, as Gymnasium's TimeLimit does
    (so a step can be both terminated and truncated). Counts steps in ``info['steps']``."""

    def __init__(self, env: Env, episode_length: int):
        if episode_length < 1:
            raise ValueError(f"episode_length must be at least 1, got {episode_length}")
        super().__init__(env)
        self.episode_length = int(episode_length)

    def reset(self, key):
        state = self.env.reset(key)
        return state.replace(info={**state.info, "steps": jnp.zeros((), jnp.int32)})

    def step(self, state, action):
        steps = state.info["steps"] + 1
        nxt = self.env.step(state, action)
        truncated = nxt.truncated | (steps >= self.episode_length)
        return nxt.replace(truncated=truncated, info={**nxt.info, "steps": steps})


class AbsorbingState(Wrapper):
    """Replaces termination by a move to one absorbing state (paper sec. 4.1.1, after Kostrikov et al.).

    The observation gains a last entry, 1.0 in the absorbing state and 0.0 elsewhere; the absorbing
    observation is all zeros but that flag. The step that terminates the inner env returns its reward
    and the absorbing observation; every later step stays there with zero true reward. ``done`` is
    never set, so episodes end only by the time limit and all have the same length.
    ``info['absorbed']`` says whether the state is the absorbing one.
    """

    @property
    def observation_size(self) -> int:
        return self.env.observation_size + 1

    def absorbing_obs(self) -> jax.Array:
        return jnp.zeros((self.observation_size,), jnp.float32).at[-1].set(1.0)

    def _observe(self, obs, absorbed):
        live = jnp.concatenate([obs.astype(jnp.float32), jnp.zeros((1,), jnp.float32)])
        return jnp.where(absorbed, self.absorbing_obs(), live)

    def reset(self, key):
        state = self.env.reset(key)
        absorbed = jnp.zeros((), bool)
        return state.replace(obs=self._observe(state.obs, absorbed), info={**state.info, "absorbed": absorbed})

    def step(self, state, action):
        was_absorbed = state.info["absorbed"]
        nxt = self.env.step(state, action)
        absorbed = was_absorbed | nxt.done
        return nxt.replace(
            env_state=_select(was_absorbed, state.env_state, nxt.env_state),
            obs=self._observe(nxt.obs, absorbed),
            reward=jnp.where(was_absorbed, jnp.zeros_like(nxt.reward), nxt.reward),
            done=jnp.zeros_like(nxt.done),
            info={**nxt.info, "absorbed": absorbed},
        )


class DoneOnAbsorption(Wrapper):
    """Marks the step of an ``AbsorbingState`` env that moves into the absorbing state as done, so that an
    episode ends at termination (with V(s') = 0 there, as IQ-Learn's own code treats terminations) instead of
    going on in the absorbing state; the observations keep the absorbing flag, so a policy sees the same
    inputs either way."""

    def step(self, state, action):
        nxt = self.env.step(state, action)
        return nxt.replace(done=nxt.done | (nxt.info["absorbed"] & ~state.info["absorbed"]))


class AutoReset(Wrapper):
    """Starts a new episode after a step that is done or truncated.

    The returned state keeps that step's reward, done and truncated but holds the new episode's
    observation; the observation the episode ended on is ``info['final_obs']`` (use it as next_obs).
    Reset keys are drawn from ``info['rng']``, except for envs whose reset is deterministic, which
    draw none (a key split per env and step is most of the cost of a cheap env).
    """

    def reset(self, key):
        key, sub = jax.random.split(key)
        state = self.env.reset(sub)
        return state.replace(info={**state.info, "rng": key, "final_obs": state.obs})

    def step(self, state, action):
        nxt = self.env.step(state, action)
        if self.env.deterministic_reset:
            key = sub = state.info["rng"]
        else:
            key, sub = jax.random.split(state.info["rng"])
        fresh = self.env.reset(sub)
        fresh_info = {**fresh.info, "rng": key, "final_obs": nxt.obs}
        ended = nxt.done | nxt.truncated
        return nxt.replace(
            env_state=_select(ended, fresh.env_state, nxt.env_state),
            obs=jnp.where(ended, fresh.obs, nxt.obs),
            info=_select(ended, fresh_info, {**nxt.info, "rng": key, "final_obs": nxt.obs}),
        )


class VmapWrapper(Wrapper):
    """``num_envs`` copies of an env stepped together with ``jax.vmap``; every array gains a leading axis."""

    def __init__(self, env: Env, num_envs: int):
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        super().__init__(env)
        self.num_envs = int(num_envs)

    def reset(self, key):
        return jax.vmap(self.env.reset)(jax.random.split(key, self.num_envs))

    def step(self, state, action):
        self.env.check_action(action, batch_shape=(self.num_envs,))
        return jax.vmap(self.env.step)(state, action)

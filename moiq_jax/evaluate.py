"""Evaluation: vector returns of policies over whole episodes, all episodes run in parallel;
``evaluate(params, env, preferences)`` for trained MOIQ / IQ-Learn parameters."""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax.envs.base import Env
from moiq_jax.envs.wrappers import VmapWrapper

Policy = Callable[[jax.Array, jax.Array], jax.Array]  # (key, obs) -> action


def _run_episodes(env: Env, policy: Policy, key: jax.Array, num_episodes: int, record: bool):
    """``num_episodes`` episodes side by side to the time limit: ``({"returns", "lengths"}, steps)``, the steps
    ``[episode_length, num_episodes, ...]`` when ``record``, else None."""
    batched = VmapWrapper(env, num_episodes)
    reset_key, act_key = jax.random.split(key)

    def body(carry, step_key):
        state, returns, lengths, alive = carry
        action = jax.vmap(policy)(jax.random.split(step_key, num_episodes), state.obs)
        nxt = batched.step(state, action)
        step = None
        if record:
            step = {"obs": state.obs, "action": action, "next_obs": nxt.obs, "reward": nxt.reward, "done": nxt.done,
                    "alive": alive}
        returns = returns + alive[:, None] * nxt.reward
        lengths = lengths + alive
        alive = alive & ~(nxt.done | nxt.truncated)
        return (nxt, returns, lengths, alive), step

    init = (
        batched.reset(reset_key),
        jnp.zeros((num_episodes, env.reward_dim), jnp.float32),
        jnp.zeros((num_episodes,), jnp.int32),
        jnp.ones((num_episodes,), bool),
    )
    (_, returns, lengths, _), steps = jax.lax.scan(body, init, jax.random.split(act_key, env.episode_length))
    return {"returns": returns, "lengths": lengths}, steps


def episode_returns(env: Env, policy: Policy, key: jax.Array, num_episodes: int) -> dict[str, jax.Array]:
    """Run ``num_episodes`` episodes side by side (one per env copy) to their end.

    ``env`` must carry a time limit (``make`` adds one). Returns ``returns`` (num_episodes, reward_dim):
    undiscounted vector returns; ``lengths`` (num_episodes,): steps until done or truncated.
    """
    return jax.jit(lambda k: _run_episodes(env, policy, k, num_episodes, record=False)[0])(key)


def episode_transitions(env: Env, policy: Policy, key: jax.Array, num_episodes: int) -> dict[str, jax.Array]:
    """Jittable: every step of ``num_episodes`` episodes run side by side to the time limit (those of
    ``episode_returns`` for the same key), as arrays ``[num_episodes, env.episode_length, ...]``: ``obs``,
    ``action``, ``next_obs``, ``reward`` (true vector reward), ``done`` (terminated) and ``alive`` (the step
    belongs to the episode: no earlier step was done or truncated)."""
    _, steps = _run_episodes(env, policy, key, num_episodes, record=True)
    return jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), steps)


def pearson(x: jax.Array, y: jax.Array, mask: jax.Array | None = None) -> jax.Array:
    """Pearson correlation of ``x`` and ``y`` (over the entries where ``mask`` is True, when given): how
    well a recovered reward matches the true one up to scale and offset."""
    weights = jnp.ones_like(x) if mask is None else mask.astype(x.dtype)
    weights = weights / weights.sum()
    xc, yc = x - (weights * x).sum(), y - (weights * y).sum()
    return (weights * xc * yc).sum() / jnp.sqrt((weights * xc**2).sum() * (weights * yc**2).sum() + 1e-12)


def hypervolume(points, reference) -> float:
    """The area dominated by ``points`` (two objectives, both maximised) above ``reference``: how much of
    the return space a set of policies' vector returns covers. Points not above the reference add nothing."""
    points, reference = np.asarray(points, np.float64), np.asarray(reference, np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or reference.shape != (2,):
        raise ValueError(f"hypervolume takes [n, 2] points and a 2-vector reference, got {points.shape}, {reference.shape}")
    points = points[np.all(points > reference, axis=1)]
    area, covered = 0.0, reference[1]
    for x, y in points[np.argsort(-points[:, 0])]:  # best first objective first: a staircase of rectangles
        if y > covered:
            area += (x - reference[0]) * (y - covered)
            covered = y
    return float(area)


def random_policy(env: Env) -> Policy:
    """Uniform random actions in the env's action space."""
    if env.discrete:
        return lambda key, obs: jax.random.randint(key, (), 0, env.num_actions)
    return lambda key, obs: jax.random.uniform(key, (env.action_size,), minval=-1.0, maxval=1.0)


def preference_returns(nets, actor_params, env: Env, preferences, key, num_episodes: int) -> jax.Array:
    """Jittable: vector returns ``[P, num_episodes, d]`` of the deterministic preference-conditioned
    policy ``nets.act`` (``networks.Networks``) for each of the ``P`` preferences."""

    def one(preference, k):
        policy = lambda _, obs: nets.act(actor_params, obs[None], preference)[0]
        return episode_returns(env, policy, k, num_episodes)["returns"]

    return jax.vmap(one)(preferences, jax.random.split(key, preferences.shape[0]))


def evaluate(params, env: Env | str, preferences, episodes: int = 1, seed: int = 0) -> np.ndarray:
    """Mean undiscounted vector returns ``[P, d]`` over ``episodes`` episodes of the deterministic policy
    of trained MOIQ parameters (``Result.best_params`` or ``final_params``) for each preference.

    ``env`` is an env or a registered name; a name is made with the absorbing state, as in training
    (a policy trained with it observes the absorbing flag). Preferences may be any, not just the experts'.
    """
    from moiq_jax.networks import networks_for, observation_size

    env = _absorbing_env(env) if isinstance(env, str) else env
    expected = observation_size(params)
    if expected != env.observation_size:
        raise ValueError(f"the policy observes {expected} values but the env gives {env.observation_size}; "
                         "was it trained with the absorbing state (envs.make(name, absorbing=True))?")
    run = _evaluation_program(env, networks_for(params), episodes)
    prefs = jnp.asarray(preferences, jnp.float32)
    return np.asarray(run(params.actor, prefs, jax.random.PRNGKey(seed)).mean(axis=1))


@functools.lru_cache(maxsize=8)
def _absorbing_env(name: str) -> Env:
    """``envs.make(name, absorbing=True)``, one per name and process, so that ``evaluate`` calls on the same
    name share their compiled programs (a MuJoCo env's step is a host callback of its own simulator, which
    JAX's persistent compilation cache cannot keep)."""
    from moiq_jax import envs

    return envs.make(name, absorbing=True)


@functools.lru_cache(maxsize=16)
def _evaluation_program(env: Env, nets, episodes: int):
    """``preference_returns`` jitted for one env, network shape and episode count, the actor parameters,
    preferences and key its inputs: ``evaluate`` compiles it once per preference count, not once per call."""
    return jax.jit(lambda actor, prefs, key: preference_returns(nets, actor, env, prefs, key, episodes))


def nondominated(points) -> np.ndarray:
    """The points ``[n, d]`` (all objectives maximised) that no other point dominates, without duplicates:
    the front a set of returns traces."""
    points = np.unique(np.asarray(points, np.float64), axis=0)
    dominated = [np.any(np.all(points >= p, axis=1) & np.any(points > p, axis=1)) for p in points]
    return points[~np.asarray(dominated, bool)]


def transfer_scores(returns, preferences, front=None, reference=None) -> dict:
    """How well vector ``returns`` ``[P, 2]`` reached at ``preferences`` transfer: the front they trace, its
    ``hypervolume`` above ``reference`` (default: the true front's worst value per objective minus 1, so
    every front point counts; else the returns' own), and where the true ``front`` is known, per
    preference the ``regret`` ``w . (optimum - return)`` and whether the return is ``optimal`` (regret <= 1e-3)."""
    returns, preferences = np.asarray(returns, np.float64), np.asarray(preferences, np.float64)
    if reference is None:
        reference = (returns if front is None else np.asarray(front)).min(axis=0) - 1.0
    out = {"front": nondominated(returns), "reference": np.asarray(reference, np.float64)}
    out["hypervolume"] = hypervolume(returns, out["reference"])
    if front is not None:
        front = np.asarray(front, np.float64)
        optimum = front[np.argmax(preferences @ front.T, axis=1)]
        regret = np.sum(preferences * (optimum - returns), axis=1)
        out.update(optimum=optimum, regret=regret, optimal=regret <= 1e-3,
                   front_hypervolume=hypervolume(front, out["reference"]))
    return out

"""Preference-conditioned networks: vector critics Q_k(s, a, w) in R^d (a twin pair, or one) and a tanh-Gaussian actor
pi(a | s, w), the ``Networks`` pair every off-policy algorithm trains, its ``Params``, and what builds
them (``networks_of_sizes``, ``networks_of_config``, or ``networks_for`` from trained parameters). The preference w is an
input, so one network serves every expert."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import struct, traverse_util

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0


class MLP(nn.Module):
    """ReLU hidden layers, then a linear output layer of ``out_size``."""

    hidden_sizes: Sequence[int]
    out_size: int

    @nn.compact
    def __call__(self, x):
        for size in self.hidden_sizes:
            x = nn.relu(nn.Dense(size)(x))
        return nn.Dense(self.out_size)(x)


class VectorCritic(nn.Module):
    """Q(s, a, w): one value per objective, shape ``(..., reward_dim)``."""

    hidden_sizes: Sequence[int]
    reward_dim: int

    @nn.compact
    def __call__(self, obs, action, preference):
        return MLP(self.hidden_sizes, self.reward_dim)(jnp.concatenate([obs, action, preference], axis=-1))


class VectorCritics(nn.Module):
    """``count`` independent vector critics, output ``(count, ..., reward_dim)``: two (SAC's clipped double Q,
    the default) or one (IQ-Learn's single critic for MuJoCo); every loss takes the smaller or the mean over
    them, so one critic is the same code."""

    hidden_sizes: Sequence[int]
    reward_dim: int
    count: int = 2

    @nn.compact
    def __call__(self, obs, action, preference):
        twins = nn.vmap(
            VectorCritic,
            variable_axes={"params": 0},
            split_rngs={"params": True},
            in_axes=None,
            out_axes=0,
            axis_size=self.count,
        )
        return twins(self.hidden_sizes, self.reward_dim)(obs, action, preference)


class TanhGaussianActor(nn.Module):
    """pi(a | s, w): a diagonal Gaussian squashed by tanh into [-1, 1]; returns ``(mean, log_std)``."""

    hidden_sizes: Sequence[int]
    action_size: int

    @nn.compact
    def __call__(self, obs, preference):
        out = MLP(self.hidden_sizes, 2 * self.action_size)(jnp.concatenate([obs, preference], axis=-1))
        mean, log_std = jnp.split(out, 2, axis=-1)
        return mean, jnp.clip(log_std, LOG_STD_MIN, LOG_STD_MAX)


def tanh_gaussian_log_prob(pre_tanh, mean, log_std):
    """log pi(tanh(u)) for the pre-squash sample ``u``: the Gaussian log-density of u minus the log
    Jacobian ``sum log(1 - tanh(u)^2)``, written stably as ``2 (log 2 - u - softplus(-2u))``."""
    gaussian = -0.5 * ((pre_tanh - mean) / jnp.exp(log_std)) ** 2 - log_std - 0.5 * jnp.log(2.0 * jnp.pi)
    log_jacobian = 2.0 * (jnp.log(2.0) - pre_tanh - jax.nn.softplus(-2.0 * pre_tanh))
    return jnp.sum(gaussian - log_jacobian, axis=-1)


def sample_tanh_gaussian(key, mean, log_std):
    """A reparameterised sample ``a = tanh(mean + std * eps)`` and its log-probability."""
    pre_tanh = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape, mean.dtype)
    return jnp.tanh(pre_tanh), tanh_gaussian_log_prob(pre_tanh, mean, log_std)


def sample_action(key, mean, log_std, action_scale: float = 1.0):
    """An action of the policy ``clip(action_scale * tanh(u), -1, 1)`` with ``u ~ N(mean, std)``, and the
    log-density of the unclipped ``action_scale * tanh(u)``.

    With ``action_scale > 1`` the policy reaches the faces of the action box ``[-1, 1]`` at finite ``u``
    (tanh alone reaches them only as ``u -> inf``, which the entropy term prevents); tasks whose optimal
    actions are full-speed moves, as continuous DST's, need exactly +-1. The clip is the env's own.
    """
    action, log_prob = sample_tanh_gaussian(key, mean, log_std)
    return jnp.clip(action_scale * action, -1.0, 1.0), log_prob - mean.shape[-1] * jnp.log(action_scale)


def deterministic_action(mean, action_scale: float = 1.0):
    """The evaluation action of the same policy: ``clip(action_scale * tanh(mean), -1, 1)``."""
    return jnp.clip(action_scale * jnp.tanh(mean), -1.0, 1.0)


def tile(preference, n):
    """One preference ``(d,)`` repeated for ``n`` rows: ``(n, d)``."""
    return jnp.broadcast_to(preference, (n, preference.shape[-1]))


class Networks(NamedTuple):
    """The critic and actor modules; ``action_scale`` widens the actor's tanh range before the env's clip
    (see ``sample_action``)."""

    critic: VectorCritics
    actor: TanhGaussianActor
    action_scale: float = 1.0

    def sample(self, actor_params, obs, preference, key):
        """Actions ``(N, action)`` and log-probabilities ``(N,)`` of pi(. | obs, w) for one preference w."""
        return sample_action(key, *self.actor.apply(actor_params, obs, tile(preference, obs.shape[0])),
                             self.action_scale)

    def act(self, actor_params, obs, preference):
        """The deterministic (evaluation) actions ``(N, action)`` for one preference."""
        mean, _ = self.actor.apply(actor_params, obs, tile(preference, obs.shape[0]))
        return deterministic_action(mean, self.action_scale)


@struct.dataclass
class Params:
    """critic, target_critic: the vector critics; actor; log_alpha: ``[E]`` one temperature per expert;
    action_scale (static): the actor's, so ``networks_for`` can rebuild the policy from the parameters."""

    critic: Any
    target_critic: Any
    actor: Any
    log_alpha: jax.Array
    action_scale: float = struct.field(pytree_node=False, default=1.0)


def _layer_sizes(module_params) -> list[tuple[int, int]]:
    """(inputs, outputs) of each Dense layer of an MLP's parameters, in order (a critics axis is ignored)."""
    mlp = _dense_layers(module_params)
    layers = sorted(mlp, key=lambda name: int(name.split("_")[1]))
    return [tuple(mlp[name]["kernel"].shape[-2:]) for name in layers]


def _dense_layers(module_params) -> dict:
    """The ``Dense_<i>`` entries of an MLP's parameters, below the module and critics levels."""
    mlp = module_params
    while "Dense_0" not in mlp:  # {"params": {"MLP_0": {...}}}, or with the critics' vmap level between
        (mlp,) = mlp.values()
    return mlp


def preference_input_moved(module_params, old, new):
    """An actor's or critics' parameters that, fed the preference ``new``, compute what ``module_params``
    computed fed ``old``: the first layer's bias absorbs ``(old - new) @ W_w``, ``W_w`` the kernel's rows of
    the preference (the input's last ones). For a model trained on one preference, whose preference input
    is a constant, taken over for another preference (``algos.adoption``)."""
    flat = traverse_util.flatten_dict(module_params)
    for path in [p for p in flat if p[-2:] == ("Dense_0", "bias")]:
        kernel = flat[path[:-1] + ("kernel",)]
        flat[path] = flat[path] + jnp.einsum("d,...dh->...h", old - new, kernel[..., -old.shape[-1]:, :])
    return traverse_util.unflatten_dict(flat)


def networks_of_sizes(hidden_sizes, reward_dim: int, action_size: int, action_scale: float = 1.0,
                      num_critics: int = 2) -> Networks:
    """Fresh critics and actor modules of the given layer widths for an env's reward and action sizes."""
    return Networks(VectorCritics(hidden_sizes, reward_dim, num_critics), TanhGaussianActor(hidden_sizes, action_size),
                    action_scale)


def networks_of_config(offpolicy, env) -> Networks:
    """Fresh networks of an off-policy config's sizes (``hidden_sizes``, ``action_scale``, ``num_critics``) for
    ``env``'s reward and action sizes: the networks every trainer of that config builds."""
    return networks_of_sizes(offpolicy.hidden_sizes, env.reward_dim, env.action_size, offpolicy.action_scale,
                             offpolicy.num_critics)


def networks_for(params: Params) -> Networks:
    """The networks ``params`` belong to, read from their shapes: hidden sizes, action and reward sizes, and
    the number of critics."""
    actor_layers, critic_layers = _layer_sizes(params.actor), _layer_sizes(params.critic)
    hidden = tuple(out for _, out in actor_layers[:-1])
    num_critics = _dense_layers(params.critic)["Dense_0"]["kernel"].shape[0]
    return networks_of_sizes(hidden, critic_layers[-1][1], actor_layers[-1][1] // 2, params.action_scale, num_critics)


def observation_size(params: Params) -> int:
    """The observation size the actor of ``params`` takes (its input is the observation and the preference)."""
    return _layer_sizes(params.actor)[0][0] - _layer_sizes(params.critic)[-1][1]

"""GAIL: the discriminator loss and the generator reward against their formulas."""

import jax
import jax.numpy as jnp
import numpy as np
import optax

from moiq_jax.algos import gail

LOGITS = np.array([-30.0, -3.0, -0.5, 0.0, 0.2, 2.0, 8.0])


def test_discriminator_loss_is_binary_cross_entropy_with_expert_labelled_one():
    is_expert = np.array([True, False, True, False, True, True, False])
    d = 1.0 / (1.0 + np.exp(-LOGITS.astype(np.float64)))  # D(s, a): the probability of "expert"
    expected = -np.mean(np.where(is_expert, np.log(d), np.log1p(-d)))
    np.testing.assert_allclose(gail.discriminator_loss(jnp.asarray(LOGITS), jnp.asarray(is_expert)), expected, rtol=1e-6)


def test_generator_reward_is_minus_log_one_minus_d_and_increasing():
    d = 1.0 / (1.0 + np.exp(-LOGITS.astype(np.float64)))
    reward = np.asarray(gail.generator_reward(jnp.asarray(LOGITS)))
    np.testing.assert_allclose(reward, -np.log1p(-d), rtol=1e-5, atol=1e-12)
    assert np.all(np.diff(reward) > 0) and np.all(reward > 0)


def test_update_separates_expert_from_policy_actions_and_reward_is_in_every_objective():
    module, optimiser = gail.Discriminator((16,)), optax.adam(1e-2)
    state = gail.init(module, optimiser, jax.random.PRNGKey(0), obs_size=3, action_size=2)
    k = jax.random.split(jax.random.PRNGKey(1), 2)
    obs = jax.random.normal(k[0], (64, 3))
    action = jnp.concatenate([jnp.full((32, 2), 0.5), jax.random.uniform(k[1], (32, 2), minval=-1, maxval=0)])
    batch = {"obs": obs, "action": action, "is_expert": jnp.arange(64) < 32}
    step = jax.jit(lambda s: gail.update(s, module, optimiser, batch))
    _, first = step(state)
    for _ in range(200):
        state, metrics = step(state)
    assert metrics["disc_loss"] < 0.1 * first["disc_loss"]
    assert metrics["disc_expert_accuracy"] == 1.0 and metrics["disc_policy_accuracy"] == 1.0
    policy = {"obs": obs[32:], "action": action[32:]}
    rewarded = gail.with_reward(module, state.params, policy, reward_dim=3)
    logits = module.apply(state.params, policy["obs"], policy["action"])
    np.testing.assert_allclose(rewarded["reward"], np.repeat(np.asarray(jax.nn.softplus(logits))[:, None], 3, 1))
    np.testing.assert_array_equal(rewarded["obs"], policy["obs"])

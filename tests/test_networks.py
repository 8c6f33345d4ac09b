import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax.networks import (
    Params,
    TanhGaussianActor,
    VectorCritics,
    networks_for,
    networks_of_config,
    networks_of_sizes,
    preference_input_moved,
    sample_tanh_gaussian,
    tanh_gaussian_log_prob,
)


def test_twin_critic_shapes_and_independent_twins():
    critic = VectorCritics(hidden_sizes=(8, 8), reward_dim=2)
    obs, act, w = jnp.ones((5, 3)), jnp.zeros((5, 2)), jnp.full((5, 2), 0.5)
    params = critic.init(jax.random.PRNGKey(0), obs, act, w)
    q = critic.apply(params, obs, act, w)
    assert q.shape == (2, 5, 2)
    assert not np.allclose(q[0], q[1])  # the two critics start from different weights


def test_one_critic_and_networks_read_back_from_parameters():
    for num_critics in (1, 2):
        nets = networks_of_sizes((8, 4), 3, 2, action_scale=1.5, num_critics=num_critics)
        critic = nets.critic.init(jax.random.PRNGKey(0), jnp.ones((5, 4)), jnp.zeros((5, 2)), jnp.full((5, 3), 1 / 3))
        assert nets.critic.apply(critic, jnp.ones((5, 4)), jnp.zeros((5, 2)), jnp.full((5, 3), 1 / 3)).shape == \
            (num_critics, 5, 3)
        actor = nets.actor.init(jax.random.PRNGKey(1), jnp.ones((1, 4)), jnp.full((1, 3), 1 / 3))
        params = Params(critic=critic, target_critic=critic, actor=actor, log_alpha=jnp.zeros(1), action_scale=1.5)
        assert networks_for(params) == nets


def test_networks_of_config_take_the_configs_sizes_and_the_envs():
    from moiq_jax.config import OffPolicyConfig
    from moiq_jax.envs import make

    env = make("cdst")
    config = OffPolicyConfig(hidden_sizes=(16, 8), action_scale=2.0, num_critics=1)
    assert networks_of_config(config, env) == networks_of_sizes((16, 8), env.reward_dim, env.action_size, 2.0, 1)
    assert networks_of_config(config, env) != networks_of_config(OffPolicyConfig(), env)


def test_actor_conditions_on_preference():
    actor = TanhGaussianActor(hidden_sizes=(8,), action_size=2)
    obs = jnp.ones((4, 3))
    params = actor.init(jax.random.PRNGKey(1), obs, jnp.full((4, 2), 0.5))
    mean_a, _ = actor.apply(params, obs, jnp.tile(jnp.array([0.9, 0.1]), (4, 1)))
    mean_b, _ = actor.apply(params, obs, jnp.tile(jnp.array([0.1, 0.9]), (4, 1)))
    assert mean_a.shape == (4, 2) and not np.allclose(mean_a, mean_b)


def test_moved_preference_input_computes_the_same_outputs_fed_the_new_preference():
    nets = networks_of_sizes((8, 8), reward_dim=3, action_size=2)
    obs, action = jax.random.normal(jax.random.PRNGKey(0), (5, 4)), jax.random.uniform(jax.random.PRNGKey(1), (5, 2))
    old, new = jnp.array([0.8, 0.1, 0.1]), jnp.array([0.1, 0.1, 0.8])
    tile = lambda w: jnp.tile(w, (5, 1))
    actor = nets.actor.init(jax.random.PRNGKey(2), obs, tile(old))
    critics = nets.critic.init(jax.random.PRNGKey(3), obs, action, tile(old))
    moved_actor, moved_critics = preference_input_moved(actor, old, new), preference_input_moved(critics, old, new)
    for before, after in zip(nets.actor.apply(actor, obs, tile(old)), nets.actor.apply(moved_actor, obs, tile(new))):
        np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(nets.critic.apply(moved_critics, obs, action, tile(new)),
                               nets.critic.apply(critics, obs, action, tile(old)), rtol=1e-5, atol=1e-6)
    # Only the first layer's bias moves, and by the preference rows of its kernel.
    changed = [a is not b and not np.array_equal(a, b) for a, b in zip(jax.tree_util.tree_leaves(critics),
                                                                       jax.tree_util.tree_leaves(moved_critics))]
    assert sum(changed) == 1
    assert not np.allclose(nets.actor.apply(actor, obs, tile(new))[0], nets.actor.apply(actor, obs, tile(old))[0])


def test_tanh_gaussian_density_integrates_to_one_and_matches_naive_formula():
    mean, log_std = jnp.array([0.3]), jnp.array([-0.2])
    # Density over a in (-1, 1) through u = atanh(a): integrates to 1.
    a = jnp.linspace(-1 + 1e-6, 1 - 1e-6, 200_001)
    log_p = tanh_gaussian_log_prob(jnp.arctanh(a)[:, None], mean, log_std)
    assert abs(float(jnp.trapezoid(jnp.exp(log_p), a)) - 1.0) < 1e-3
    # Equals the textbook change of variables where that is numerically safe.
    u = jnp.linspace(-3, 3, 13)[:, None]
    std = jnp.exp(log_std)
    naive = (
        -0.5 * ((u - mean) / std) ** 2 - jnp.log(std * jnp.sqrt(2 * jnp.pi)) - jnp.log(1 - jnp.tanh(u) ** 2)
    ).sum(-1)
    np.testing.assert_allclose(tanh_gaussian_log_prob(u, mean, log_std), naive, rtol=1e-5, atol=1e-5)


def test_sample_is_squashed_and_log_prob_consistent():
    mean, log_std = jnp.zeros((1000, 2)), jnp.full((1000, 2), 1.0)
    action, log_prob = sample_tanh_gaussian(jax.random.PRNGKey(2), mean, log_std)
    assert action.shape == (1000, 2) and log_prob.shape == (1000,)
    assert np.all(np.abs(action) <= 1.0) and np.all(np.isfinite(log_prob))
    pre_tanh = mean + jnp.exp(log_std) * jax.random.normal(jax.random.PRNGKey(2), mean.shape)
    np.testing.assert_allclose(log_prob, tanh_gaussian_log_prob(pre_tanh, mean, log_std), rtol=1e-6)

"""MOIQ losses against independent formulas: IQ-Learn for one expert, the consensus penalty and its gradient."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from moiq_jax.algos import actor_critic, moiq
from moiq_jax.networks import (
    Networks,
    TanhGaussianActor,
    VectorCritics,
    sample_tanh_gaussian,
    tanh_gaussian_log_prob,
)

GAMMA, ALPHA_REG = 0.9, 0.5
NETS = Networks(VectorCritics((16, 16), 2), TanhGaussianActor((16, 16), 2))
ONE_CRITIC = Networks(VectorCritics((16, 16), 2, count=1), TanhGaussianActor((16, 16), 2))


def critic_loss(critic, params, batches, prefs, beta, key, use_target=True, value_term="value", regulariser="replay",
                nets=NETS):
    return moiq.critic_loss(critic, nets, params, batches, prefs, beta, key, GAMMA, ALPHA_REG, use_target, value_term,
                            regulariser)


def _learner(preferences, key=0, nets=NETS):
    opt = actor_critic.Optimisers(optax.adam(1e-3), optax.adam(1e-3), optax.adam(1e-3))
    learner = actor_critic.init_learner(nets, opt, jax.random.PRNGKey(key), 3, 2, preferences, init_alpha=0.2)
    # A target critic different from the online one, so the test sees which is used where.
    target = nets.critic.init(jax.random.PRNGKey(key + 100), jnp.zeros((1, 3)), jnp.zeros((1, 2)), preferences[:1])
    return learner.replace(params=learner.params.replace(target_critic=target)), opt


def _batches(num_experts, per_expert, key=1):
    k = jax.random.split(jax.random.PRNGKey(key), 4)
    shape = (num_experts, per_expert)
    return {
        "obs": jax.random.normal(k[0], (*shape, 3)),
        "action": jax.random.uniform(k[1], (*shape, 2), minval=-1, maxval=1),
        "next_obs": jax.random.normal(k[2], (*shape, 3)),
        "done": (jax.random.uniform(k[3], shape) < 0.2).astype(jnp.float32),
        "is_expert": jnp.tile(jnp.arange(per_expert) < per_expert // 2, (num_experts, 1)),
    }


def _iq_learn_reference(critic, params, alpha, batch, w, key, use_target=True, value_term="value",
                        regulariser="replay", nets=NETS):
    """IQ-Learn's critic loss written out with scalar critics, as in its reference implementation: V(s')
    from the target critic, or with ``use_target=False`` from the online ``critic`` (with gradient); its
    second term ``value`` (expert and policy states) or ``v0`` (expert states as initial ones); its chi^2
    regulariser on the policy rows at their stored actions, or (``"policy"``) at the current policy's action
    (the one V(s) samples), or (``"both"``) on every row at both."""
    current_key, next_key = jax.random.split(key)
    n = batch["obs"].shape[0]
    ws = jnp.tile(w, (n, 1))

    def twins_and_v(critic_params, obs, k):
        action, log_prob = sample_tanh_gaussian(k, *nets.actor.apply(params.actor, obs, ws))
        q = nets.critic.apply(critic_params, obs, action, ws) @ w
        return q, jnp.min(q, axis=0) - alpha * log_prob

    q_policy, v = twins_and_v(critic, batch["obs"], current_key)
    y = GAMMA * (1 - batch["done"]) * twins_and_v(params.target_critic if use_target else critic,
                                                        batch["next_obs"], next_key)[1]
    losses = []
    expert = batch["is_expert"]
    for q, q_at_policy in zip(nets.critic.apply(critic, batch["obs"], batch["action"], ws) @ w, q_policy):
        r = q - y
        second = (v - y).mean() if value_term == "value" else (1 - GAMMA) * v[expert].mean()
        regularised = {"replay": r, "policy": jnp.where(expert, r, q_at_policy - y),
                       "both": jnp.concatenate([r, q_at_policy - y])}[regulariser]
        losses.append(-r[expert].mean() + second + (regularised**2).mean() / (4 * ALPHA_REG))
    return sum(losses) / len(losses)


@pytest.mark.parametrize("use_target,value_term,regulariser,nets", [
    (True, "value", "replay", NETS), (False, "value", "replay", NETS), (True, "v0", "replay", NETS),
    (False, "v0", "replay", NETS), (True, "value", "policy", NETS), (False, "value", "policy", NETS),
    (True, "value", "policy", ONE_CRITIC), (True, "value", "both", NETS), (False, "v0", "both", ONE_CRITIC)])
def test_one_expert_loss_and_gradient_are_iq_learns_for_any_beta(use_target, value_term, regulariser, nets):
    prefs = jnp.array([[0.7, 0.3]])
    learner, _ = _learner(prefs, nets=nets)
    params, batches, key = learner.params, _batches(1, 8), jax.random.PRNGKey(5)
    reference = lambda critic: _iq_learn_reference(
        critic, params, 0.2, jax.tree_util.tree_map(lambda x: x[0], batches), prefs[0], jax.random.split(key, 1)[0],
        use_target, value_term, regulariser, nets)
    expected, expected_grad = jax.value_and_grad(reference)(params.critic)
    for beta in (0.0, 5.0):  # one expert has no neighbours: the penalty vanishes
        (loss, metrics), grad = jax.value_and_grad(critic_loss, has_aux=True)(
            params.critic, params, batches, prefs, beta, key, use_target, value_term, regulariser, nets)
        # atol: this float32 loss is a sum of larger terms that cancel to ~2e-3, so its last bits follow the CPU's
        # summation order (one parametrisation differed by 3.7e-8, rtol 2e-5, on an AMD EPYC machine)
        np.testing.assert_allclose(loss, expected, rtol=1e-5, atol=1e-7)
        assert float(metrics["penalty"]) == 0.0
        for got, want in zip(jax.tree_util.tree_leaves(grad), jax.tree_util.tree_leaves(expected_grad)):
            np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-6)


def test_penalty_is_zero_with_zero_gradient_for_equal_rewards():
    shared = jax.random.normal(jax.random.PRNGKey(0), (6, 2))
    rewards = jnp.stack([shared] * 3)
    assert float(moiq.consensus_penalty(rewards)) == 0.0
    grad = jax.grad(moiq.consensus_penalty)(rewards)
    assert np.all(np.isfinite(grad)) and np.all(grad == 0.0)


def test_penalty_value_and_gradient_match_closed_form():
    rewards = np.asarray(jax.random.normal(jax.random.PRNGKey(3), (3, 5, 2)), np.float64)
    diffs = rewards[1:] - rewards[:-1]  # (2, 5, 2)
    norms = np.linalg.norm(diffs, axis=-1)
    np.testing.assert_allclose(moiq.consensus_penalty(jnp.asarray(rewards)), norms.sum(0).mean(), rtol=1e-5)
    unit = diffs / norms[..., None] / rewards.shape[1]  # d||r_{j+1} - r_j|| / d r_{j+1}, averaged over the batch
    expected = np.zeros_like(rewards)
    expected[1:] += unit
    expected[:-1] -= unit
    np.testing.assert_allclose(jax.grad(moiq.consensus_penalty)(jnp.asarray(rewards)), expected, rtol=1e-4, atol=1e-6)


def test_critic_loss_penalty_ties_experts_and_beta_scales_it():
    prefs = jnp.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])
    learner, _ = _learner(prefs)
    batches, key = _batches(3, 8), jax.random.PRNGKey(2)
    loss0, m0 = critic_loss(learner.params.critic, learner.params, batches, prefs, 0.0, key)
    loss5, _ = critic_loss(learner.params.critic, learner.params, batches, prefs, 5.0, key)
    assert float(m0["penalty"]) > 0
    np.testing.assert_allclose(loss5 - loss0, 5.0 * m0["penalty"], rtol=1e-4)
    np.testing.assert_allclose(loss0, m0["iq_loss"].sum(), rtol=1e-6)


def _penalty_reference(critic, params, batches, prefs, key, online):
    """The consensus penalty written out on the common batch (rows 0 and 6 of each expert's 8): expert j's rewards
    ``Q(s, a, w_j) - gamma (1 - done) V(s', w_j)`` with V(s') from the target critic and a' drawn, as for its own
    rows, from the noise of one pass over its own rows followed by the common ones; or (``online``) from the
    online ``critic`` with a' drawn in a pass of the common rows alone."""
    common = {k: batches[k][:, ::6].reshape(6, *batches[k].shape[2:]) for k in ("obs", "action", "next_obs", "done")}
    rewards = []
    for j, expert_key in enumerate(jax.random.split(key, 3)):
        next_key = jax.random.split(expert_key)[1]
        if online:
            rows, noise_key, next_critic = common, jax.random.fold_in(next_key, 1), critic
        else:
            rows = {k: jnp.concatenate([batches[k][j], common[k]]) for k in common}
            noise_key, next_critic = next_key, params.target_critic
        ws = jnp.tile(prefs[j], (rows["obs"].shape[0], 1))
        mean, log_std = NETS.actor.apply(params.actor, rows["next_obs"], ws)
        pre_tanh = mean + jnp.exp(log_std) * jax.random.normal(noise_key, mean.shape)
        q_next = NETS.critic.apply(next_critic, rows["next_obs"], jnp.tanh(pre_tanh), ws)  # (2, N, 2)
        q_next = jnp.where((q_next[0] @ prefs[j] <= q_next[1] @ prefs[j])[:, None], q_next[0], q_next[1])
        v_next = q_next - 0.2 * tanh_gaussian_log_prob(pre_tanh, mean, log_std)[:, None]
        r = NETS.critic.apply(critic, rows["obs"], rows["action"], ws) - GAMMA * (1 - rows["done"])[:, None] * v_next
        rewards.append(r[:, -6:])  # (2 twins, 6 common rows, 2)
    return jnp.mean(sum(jnp.linalg.norm(rewards[j + 1] - rewards[j], axis=-1) for j in range(2)))


def test_penalty_compares_every_experts_rewards_on_the_shared_rows():
    prefs = jnp.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])
    learner, _ = _learner(prefs)
    params, batches, key = learner.params, _batches(3, 8), jax.random.PRNGKey(7)
    np.testing.assert_array_equal(batches["obs"][:, ::6].reshape(6, 3)[1], batches["obs"][0, 6])
    _, metrics = critic_loss(params.critic, params, batches, prefs, 5.0, key)
    np.testing.assert_allclose(metrics["penalty"], _penalty_reference(params.critic, params, batches, prefs, key,
                                                                      online=False), rtol=1e-4)


def test_online_penalty_reads_the_online_critic_with_gradient_and_leaves_the_iq_terms():
    """``penalty_online``: the common rows' V(s') from the online critic, differentiated; the IQ terms keep the
    target critic's V(s') (the same losses as without it)."""
    prefs = jnp.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])
    learner, _ = _learner(prefs)
    params, batches, key = learner.params, _batches(3, 8), jax.random.PRNGKey(7)
    terms = lambda critic, online: moiq.critic_terms(critic, NETS, params, batches, prefs, key, GAMMA, ALPHA_REG,
                                                     True, penalty_online=online)
    (target_iq, target_penalty, _), (online_iq, online_penalty, _) = terms(params.critic, False), terms(params.critic, True)
    np.testing.assert_allclose(online_iq, target_iq, rtol=1e-6)
    reference = lambda critic: _penalty_reference(critic, params, batches, prefs, key, online=True)
    np.testing.assert_allclose(online_penalty, reference(params.critic), rtol=1e-4)
    assert abs(float(online_penalty) - float(target_penalty)) > 1e-3  # a different critic gives V(s')
    got = jax.grad(lambda critic: terms(critic, True)[1])(params.critic)
    for got_leaf, want in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(jax.grad(reference)(params.critic))):
        np.testing.assert_allclose(got_leaf, want, rtol=1e-4, atol=1e-6)


def test_update_runs_jitted_for_all_experts_and_moves_targets_slowly():
    prefs = jnp.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])
    learner, opt = _learner(prefs)
    settings = actor_critic.Settings(target_entropy=-2.0, tau=0.005, learn_alpha=True)
    objective = lambda critic, params, b, p, k: critic_loss(critic, params, b, p, 5.0, k)
    step = jax.jit(lambda lrn, b, k: actor_critic.update(lrn, NETS, opt, b, prefs, k, settings, objective))
    new, metrics = step(learner, _batches(3, 8), jax.random.PRNGKey(4))
    assert metrics["iq_loss"].shape == (3,) and metrics["alpha"].shape == (3,)
    assert all(np.isfinite(float(metrics[k])) for k in ("critic_loss", "actor_loss", "penalty"))
    old_t, new_t, new_c = (jax.tree_util.tree_leaves(p)[0] for p in (
        learner.params.target_critic, new.params.target_critic, new.params.critic))
    np.testing.assert_allclose(new_t, 0.995 * old_t + 0.005 * new_c, rtol=1e-5, atol=1e-7)
    assert not np.allclose(new.params.log_alpha, learner.params.log_alpha)

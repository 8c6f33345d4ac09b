"""SAC experts: the vector soft-TD loss against its formula, learning per-objective values, reaching the exact
cdst optimum, and expert files and demonstrations that reproduce the trained policies."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import moiq_jax
from moiq_jax.algos import actor_critic, offpolicy, sac
from moiq_jax.algos.adoption import adopt_between_preferences
from moiq_jax.config import tuned
from moiq_jax.experts import sac as sac_experts
from moiq_jax.experts.cdst_oracle import expert_returns
from moiq_jax.networks import networks_of_config, networks_of_sizes

NETS = networks_of_sizes((16, 16), reward_dim=2, action_size=2)
PREFS = jnp.array([[0.9, 0.1], [0.2, 0.8]])


def _learner(lr=1e-3):
    opt = actor_critic.Optimisers(optax.adam(lr), optax.adam(lr), optax.adam(lr))
    learner = actor_critic.init_learner(NETS, opt, jax.random.PRNGKey(0), 3, 2, PREFS, init_alpha=0.3)
    target = NETS.critic.init(jax.random.PRNGKey(7), jnp.zeros((1, 3)), jnp.zeros((1, 2)), PREFS[:1])
    return learner.replace(params=learner.params.replace(target_critic=target)), opt


def _batches(n, key=1):
    k = jax.random.split(jax.random.PRNGKey(key), 5)
    return {"obs": jax.random.normal(k[0], (2, n, 3)), "action": jax.random.uniform(k[1], (2, n, 2), minval=-1, maxval=1),
            "next_obs": jax.random.normal(k[2], (2, n, 3)), "reward": jax.random.normal(k[3], (2, n, 2)),
            "done": (jax.random.uniform(k[4], (2, n)) < 0.3).astype(jnp.float32)}


def test_critic_loss_is_the_soft_td_error_per_objective_with_the_target_critic():
    learner, _ = _learner()
    params, batches, key = learner.params, _batches(8), jax.random.PRNGKey(3)
    loss, metrics = sac.critic_loss(params.critic, NETS, params, batches, PREFS, key, 0.9)

    expected = []
    for e, k in enumerate(jax.random.split(key, 2)):  # written out: twin Q's, clipped double-Q soft target
        b, w, alpha = {name: v[e] for name, v in batches.items()}, PREFS[e], jnp.exp(params.log_alpha[e])
        tiled = jnp.tile(w, (8, 1))
        q = NETS.critic.apply(params.critic, b["obs"], b["action"], tiled)
        next_action, log_prob = NETS.sample(params.actor, b["next_obs"], w, k)
        next_q = NETS.critic.apply(params.target_critic, b["next_obs"], next_action, tiled)
        smaller = jnp.where((next_q[0] @ w <= next_q[1] @ w)[:, None], next_q[0], next_q[1])
        target = b["reward"] + 0.9 * (1 - b["done"])[:, None] * (smaller - alpha * log_prob[:, None])
        expected.append(np.mean(np.sum((np.asarray(q) - np.asarray(target)) ** 2, axis=-1)))
    np.testing.assert_allclose(metrics["td_loss"], expected, rtol=1e-5)
    np.testing.assert_allclose(loss, sum(expected), rtol=1e-5)


def test_vector_critic_learns_each_objectives_terminal_reward():
    """On terminal transitions the soft-TD fixed point is Q(s, a, w) = r per objective, for any preference."""
    learner, opt = _learner(lr=3e-3)
    batches = {**_batches(16), "done": jnp.ones((2, 16))}
    batches["reward"] = jnp.stack([batches["obs"][..., 0], -2.0 * batches["action"][..., 1]], axis=-1)
    settings = actor_critic.Settings(target_entropy=-2.0, tau=0.005, learn_alpha=True)
    objective = lambda critic, params, b, p, k: sac.critic_loss(critic, NETS, params, b, p, k, 0.9)
    step = jax.jit(lambda lrn, k: actor_critic.update(lrn, NETS, opt, batches, PREFS, k, settings, objective))
    for k in jax.random.split(jax.random.PRNGKey(5), 1500):
        learner, _ = step(learner, k)
    for e in range(2):
        q = NETS.critic.apply(learner.params.critic, batches["obs"][e], batches["action"][e], jnp.tile(PREFS[e], (16, 1)))
        np.testing.assert_allclose(q, np.broadcast_to(batches["reward"][e], q.shape), atol=0.05)


@pytest.fixture(scope="module")
def cdst_experts():
    config = tuned("cdst", algo="sac", total_steps=8_000, eval_interval=4_000, learning_starts=1_000, actor_lr=3e-4,
                   init_alpha=0.1, learn_alpha=True, use_target=True)
    return config, moiq_jax.train(config, log=None)


def test_sac_experts_reach_the_exact_cdst_optimum(cdst_experts):
    config, result = cdst_experts
    best = result.history["eval_return"][np.argmax(result.history["eval_scalar_return"], axis=0), np.arange(3)]
    optimum = expert_returns(config.preferences)
    # [0.5, 0.5] and [0.1, 0.9]: the treasure 15.1 in 7 steps and 0.7 in 1 step, exactly. ([0.9, 0.1]'s
    # 23.7 lies 23 steps away past nearer treasures; SAC's exploration rarely finds it in 8K steps.)
    np.testing.assert_allclose(best[1:], optimum[1:], atol=1e-4)
    assert "reward_correlation" not in result.history  # experts recover no reward


def test_expert_file_round_trip_and_demonstrations_replay_the_policies(cdst_experts, tmp_path):
    config, result = cdst_experts
    path = tmp_path / "experts.npz"
    sac_experts.save_experts(path, config, result.best_params.actor)
    loaded_config, actor = sac_experts.load_experts(path)
    assert loaded_config == config
    for a, b in zip(jax.tree_util.tree_leaves(actor), jax.tree_util.tree_leaves(result.best_params.actor)):
        np.testing.assert_array_equal(a, b)
    demos = sac_experts.record_demonstrations(loaded_config, actor, num_demos=2)
    demos.validate(moiq_jax.envs.make("cdst", absorbing=True))
    assert demos.lengths.tolist() == [[100, 100]] * 3
    # cdst is deterministic: each demonstration's return is its expert's evaluation return.
    best_eval = np.argmax(result.history["eval_scalar_return"], axis=0)
    np.testing.assert_allclose(demos.mean_returns(), result.history["eval_return"][best_eval, np.arange(3)], atol=1e-4)


def test_load_experts_rejects_other_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        sac_experts.load_experts(tmp_path / "missing.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="not an expert file"):
        sac_experts.load_experts(tmp_path / "other.npz")


def _marked_runner_state(prefs):
    """A fresh per-preference SAC runner state for cdst whose replay buffers hold their model's index."""
    config = tuned("cdst", algo="sac", hidden_sizes=(16, 16), buffer_size=64, total_steps=400, eval_interval=200,
                   learning_starts=100)
    trainer = offpolicy.make_trainer(config, sac.ALGORITHM)
    state = trainer.init(jax.random.PRNGKey(0), trainer.make_setup(prefs))
    marked = jax.tree_util.tree_map(lambda x: x + jnp.arange(3).reshape(-1, *[1] * (x.ndim - 1)).astype(x.dtype),
                                    state.buffers)
    env = config.make_env()
    return state.replace(buffers=marked), networks_of_config(config.offpolicy, env), env.observation_size


def test_a_model_another_serves_better_takes_over_its_learner_and_replay():
    prefs = jnp.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])
    state, nets, obs_size = _marked_runner_state(prefs)
    # Model 0 returns [2, 2]; model 1 [5, 5] scores 5 under model 0's preference, 2.5x model 0's own 2.
    returns = jnp.array([[2.0, 2.0], [5.0, 5.0], [1.0, 9.0]])
    best = jnp.array([2.0, 5.0, 8.2])  # each model's best scalarised evaluation: here its latest
    learner, buffers, donor = adopt_between_preferences(state.learner, state.buffers, returns, best, prefs, margin=1.4)
    assert donor.tolist() == [1, 1, 2]
    obs = jax.random.normal(jax.random.PRNGKey(4), (6, obs_size))
    action = jax.random.uniform(jax.random.PRNGKey(5), (6, 2), minval=-1, maxval=1)
    at = lambda tree, i: jax.tree_util.tree_map(lambda x: x[i], tree)
    before, after = state.learner.params, learner.params
    # Fed its own preference, model 0 now acts and values as model 1 did fed model 1's.
    np.testing.assert_allclose(nets.act(at(after.actor, 0), obs, prefs[0]), nets.act(at(before.actor, 1), obs, prefs[1]),
                               atol=1e-5)
    for critic in ("critic", "target_critic"):
        np.testing.assert_allclose(
            nets.critic.apply(at(getattr(after, critic), 0), obs, action, jnp.tile(prefs[0], (6, 1))),
            nets.critic.apply(at(getattr(before, critic), 1), obs, action, jnp.tile(prefs[1], (6, 1))), atol=1e-5)
    take = lambda tree, rows: jax.tree_util.tree_leaves(jax.tree_util.tree_map(lambda x: x[jnp.array(rows)], tree))
    for new, old in zip(take((buffers, learner.actor_opt, learner.critic_opt, learner.params.log_alpha), [0, 1, 2]),
                        take((state.buffers, state.learner.actor_opt, state.learner.critic_opt,
                              state.learner.params.log_alpha), [1, 1, 2])):
        np.testing.assert_array_equal(new, old)  # model 0 holds model 1's replay and optimiser states
    for new, old in zip(take(learner, [1, 2]), take(state.learner, [1, 2])):
        np.testing.assert_array_equal(new, old)  # the others are untouched
    # Under the margin (3 more than 2 is not over 1.6 x 2), nothing is taken over; nor when model 0's best
    # evaluation (4.6) is within the margin of model 1's score, however poor its latest one.
    for margin, best_of_0 in ((1.6, 2.0), (0.1, 4.6)):
        learner, buffers, donor = adopt_between_preferences(state.learner, state.buffers, returns,
                                                            best.at[0].set(best_of_0), prefs, margin)
        assert donor.tolist() == [0, 1, 2]
        for new, old in zip(jax.tree_util.tree_leaves((learner, buffers)),
                            jax.tree_util.tree_leaves((state.learner, state.buffers))):
            np.testing.assert_array_equal(new, old)
    assert adopt_between_preferences(state.learner, state.buffers, returns, best.at[0].set(4.5), prefs, 0.1)[2].tolist() \
        == [1, 1, 2]


def test_adoption_runs_in_training_and_only_for_sac_experts():
    config = tuned("cdst", algo="sac", total_steps=800, eval_interval=400, learning_starts=200, buffer_size=800,
                   hidden_sizes=(8, 8), batch_size=8, adopt_margin=0.0,
                   preferences=((0.1, 0.9), (0.9, 0.1), (0.5, 0.5)))  # not the loop's order: labels must follow
    result = moiq_jax.train(config, log=None)
    adopted = result.history["adopted_from"]
    assert adopted.shape == (2, 3) and set(adopted.ravel().tolist()) <= {-1, 0, 1, 2}
    assert all(a != i for row in adopted for i, a in enumerate(row))  # -1, or another expert (config order)
    scores = result.history["eval_return"] @ np.asarray(config.preferences).T  # [chunk, model j, preference i]
    best = np.maximum.accumulate(result.history["eval_scalar_return"], axis=0)  # each model's best so far
    for chunk in range(2):  # a model adopts exactly when another beats its best under its preference (margin 0)
        others = np.where(np.eye(3, dtype=bool), -np.inf, scores[chunk])  # [model j, preference i], j != i
        np.testing.assert_array_equal(adopted[chunk] >= 0, others.max(axis=0) > best[chunk])
        np.testing.assert_array_equal(adopted[chunk][adopted[chunk] >= 0], others.argmax(axis=0)[adopted[chunk] >= 0])
    with pytest.raises(ValueError, match="must not see that reward"):
        moiq_jax.train(config.replace(algo="iq_learn"), log=None)
    with pytest.raises(ValueError, match="must not see that reward"):
        moiq_jax.train(config.replace(algo="moiq"), log=None)
    with pytest.raises(ValueError, match="adopt_margin must be >= 0"):
        moiq_jax.train(config.replace(adopt_margin=-0.5), log=None)

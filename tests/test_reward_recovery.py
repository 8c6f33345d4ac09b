"""The recovered reward's correlation with the true one along the policy's own episodes (the measure of
IQ-Learn's code): it reads the episodes ``evaluate`` runs, in the env the learner trained in, and is NaN where
the episodes do not vary."""

import jax
import numpy as np
import optax
import pytest

import moiq_jax
from moiq_jax import reward_recovery
from moiq_jax.algos import actor_critic
from moiq_jax.networks import networks_of_config

HOPPER = moiq_jax.Config(env="mo-hopper", preferences=((0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.1, 0.8)),
                         hidden_sizes=(16,))


def fresh_params(config, seed=0):
    """Untrained MOIQ parameters for ``config`` (a policy that falls early on the hopper)."""
    env = config.make_env(absorbing=True)
    nets = networks_of_config(config.offpolicy, env)
    adam = optax.adam(1e-3)
    learner = actor_critic.init_learner(nets, actor_critic.Optimisers(adam, adam, adam), jax.random.PRNGKey(seed),
                                        env.observation_size, env.action_size,
                                        np.asarray(config.preferences, np.float32), 0.2)
    return learner.params


@pytest.fixture(scope="module")
def hopper():
    params = fresh_params(HOPPER)
    return params, moiq_jax.rollout_reward_correlations(params, HOPPER, episodes=6, seed=3)


def test_rollout_correlations_read_evaluates_episodes_and_correlate_their_returns(hopper):
    params, measured = hopper
    prefs = np.asarray(HOPPER.preferences)
    assert measured["episode_returns"].shape == measured["recovered_episode_returns"].shape == (3, 6)
    evaluated = moiq_jax.evaluate(params, "mo-hopper", prefs, episodes=6, seed=3)  # [E, d] mean vector returns
    np.testing.assert_allclose(measured["episode_returns"].mean(1), (evaluated * prefs).sum(1), rtol=1e-5)
    assert np.ptp(measured["episode_returns"], axis=1).min() > 0  # random starts: the episodes differ
    for e in range(3):
        expected = np.corrcoef(measured["recovered_episode_returns"][e], measured["episode_returns"][e])[0, 1]
        assert measured["episode_reward_correlation"][e] == pytest.approx(expected, abs=1e-9)
    for name in ("episode_reward_correlation", "episode_reward_correlation_objectives", "step_reward_correlation"):
        assert np.all(np.abs(measured[name]) <= 1)


def test_policy_episodes_are_evaluates_then_the_absorbing_states(hopper):
    """The episodes' steps give ``evaluate``'s vector returns; after the (early) fall every step is the
    absorbing state's (flagged in the observation's last entry): one observation and one action per
    preference, no true reward, and a recovered reward of its own."""
    params, _ = hopper
    steps = moiq_jax.policy_episodes(params, HOPPER, episodes=6, seed=3)
    assert steps["obs"].shape[:3] == steps["recovered_reward"].shape[:3] == steps["alive"].shape == (3, 6, 1000)
    assert steps["alive"].all()  # the absorbing state's steps belong to the episode, to the time limit
    evaluated = moiq_jax.evaluate(params, "mo-hopper", HOPPER.preferences, episodes=6, seed=3)
    np.testing.assert_allclose(steps["reward"].sum(2).mean(1), evaluated, rtol=1e-5, atol=1e-4)
    absorbed = steps["obs"][..., -1] == 1
    assert np.all(absorbed.sum(2) > 0) and np.all(absorbed[..., 0] == 0)  # every episode falls, none at once
    for e in range(3):
        for name in ("obs", "action"):
            after = steps[name][e][absorbed[e]]
            np.testing.assert_allclose(after, np.broadcast_to(after[0], after.shape), atol=1e-6)
        assert np.all(steps["reward"][e][absorbed[e]] == 0)
        assert not np.allclose(steps["recovered_reward"][e][~absorbed[e]], steps["recovered_reward"][e][absorbed[e]][0])


def test_runs_of_one_protocol_share_one_compiled_program(hopper, compiled_programs):
    """Run after run of one protocol (other parameters, seeds and consensus weights, as a table reads them)
    compiles no new program, and the seed and beta of the config change nothing measured."""
    params, measured = hopper
    other, config = fresh_params(HOPPER, seed=1), HOPPER.replace(seed=4, beta=5.0)
    with compiled_programs() as names:
        again = moiq_jax.rollout_reward_correlations(params, config, episodes=6, seed=3)
        new = moiq_jax.rollout_reward_correlations(other, config, episodes=6, seed=7)
    assert names.count("jit(run)") == 0  # the fixture's program served both
    for name in measured:
        np.testing.assert_array_equal(again[name], measured[name])
    assert not np.array_equal(new["recovered_episode_returns"], measured["recovered_episode_returns"])
    reward_recovery._rollout_program.cache_clear()
    with compiled_programs() as names:
        afresh = moiq_jax.rollout_reward_correlations(other, config, episodes=6, seed=7)
    assert names.count("jit(run)") == 1
    for name in new:
        np.testing.assert_array_equal(afresh[name], new[name])


def test_without_absorbing_rollouts_the_episodes_end_at_termination(hopper):
    """The learner that trained on episodes ending at termination is measured on them: the true returns are the
    same (the absorbing state has no true reward), the recovered ones leave out the absorbing steps."""
    params, measured = hopper
    ending = moiq_jax.rollout_reward_correlations(params, HOPPER.replace(absorbing_rollouts=False), episodes=6, seed=3)
    np.testing.assert_allclose(ending["episode_returns"], measured["episode_returns"], rtol=1e-6)
    assert np.min(np.abs(ending["recovered_episode_returns"] - measured["recovered_episode_returns"])) > 1e-3


def test_a_repeated_episode_has_no_correlation_and_other_learners_are_refused():
    config = moiq_jax.Config(hidden_sizes=(8,))  # cdst: one start, a deterministic policy, one episode repeated
    measured = moiq_jax.rollout_reward_correlations(fresh_params(config), config, episodes=3)
    assert np.all(np.ptp(measured["episode_returns"], axis=1) == 0)
    assert np.all(np.isnan(measured["episode_reward_correlation"]))
    assert np.all(np.isnan(measured["episode_reward_correlation_objectives"]))
    for measure in (moiq_jax.rollout_reward_correlations, moiq_jax.policy_episodes):
        with pytest.raises(ValueError, match="gail does not recover its reward from the critic; policy_episodes"):
            measure(fresh_params(config), config.replace(algo="gail"))

"""CI-sized MOIQ training: the loop runs end to end, the baselines share it, and a sweep equals its runs."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import moiq_jax
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.config import tuned
from moiq_jax.evaluate import preference_returns
from moiq_jax.experts.loading import load_demonstrations
from moiq_jax.networks import networks_for
from moiq_jax.runtime import pin_to_cores
from moiq_jax.train import ALGORITHMS, validate

TINY = moiq_jax.Config(total_steps=40, eval_interval=20, num_envs=2, learning_starts=10, batch_size=8,
                       hidden_sizes=(8,), buffer_size=64, num_demos=1)


@pytest.fixture(scope="module")
def demos():
    return load_demonstrations(TINY)


@pytest.fixture(scope="module")
def trained(demos):
    return moiq_jax.train(TINY.replace(action_scale=1.1), demos, log=None)


def test_train_smoke_moiq(trained):
    result = trained
    h = result.history
    assert h["eval_return"].shape == (2, 3, 2) and h["iq_loss"].shape == (2, 3) and h["alpha"].shape == (2, 3)
    np.testing.assert_array_equal(h["env_steps"], [20, 40])
    assert np.all(np.isfinite(h["critic_loss"])) and np.all(h["penalty"] > 0)
    assert np.isfinite(result.best_return) and result.best_return == h["eval_scalar_return"].mean(1).max()


def test_evaluate_reproduces_the_best_models_training_evaluation(trained):
    result = trained
    best = int(np.argmax(result.history["eval_scalar_return"].mean(1)))
    returns = moiq_jax.evaluate(result.best_params, "cdst", TINY.preferences)
    np.testing.assert_allclose(returns, result.history["eval_return"][best], rtol=1e-6)
    transfer = moiq_jax.evaluate(result.best_params, "cdst", [[1 - 0.05 * k, 0.05 * k] for k in range(1, 20)])
    assert transfer.shape == (19, 2) and np.all(transfer[:, 1] <= -1)  # every episode costs at least one step
    with pytest.raises(ValueError, match="absorbing"):
        moiq_jax.evaluate(result.best_params, moiq_jax.envs.make("cdst"), TINY.preferences)


def test_evaluate_compiles_once_per_preference_count(trained, compiled_programs):
    """Evaluations of one env name, network shape and episode count share one program: parameters and
    preferences are its inputs, so a script evaluating run after run compiles once (per preference count)."""
    others = [[0.3, 0.7], [0.6, 0.4], [0.95, 0.05]]
    with compiled_programs() as names:
        best = moiq_jax.evaluate(trained.best_params, "cdst", TINY.preferences, episodes=3)
        final = moiq_jax.evaluate(trained.final_params, "cdst", others, episodes=3)
        five = moiq_jax.evaluate(trained.best_params, "cdst", [*TINY.preferences, *others[:2]], episodes=3)
    assert names.count("jit(<lambda>)") == 2  # three preferences, then five
    nets = networks_for(trained.best_params)
    env = moiq_jax.envs.make("cdst", absorbing=True)
    direct = lambda params, prefs: jax.jit(lambda: preference_returns(
        nets, params.actor, env, jnp.asarray(prefs, jnp.float32), jax.random.PRNGKey(0), 3))().mean(axis=1)
    np.testing.assert_array_equal(best, direct(trained.best_params, TINY.preferences))
    np.testing.assert_array_equal(final, direct(trained.final_params, others))
    np.testing.assert_array_equal(five[:3], best)


def test_sweeps_of_one_config_share_one_compiled_chunk(tmp_path, compiled_programs):
    """Checkpointed sweeps of one config that differ only in beta (a script trains beta after beta) compile
    their chunk once, and the reuse carries nothing from one sweep to the next: beta 0 after a beta-5 sweep
    ends bit for bit as the first sweep of beta 0, on a program built afresh, did."""
    config = TINY.replace(seed=7)
    sweep = lambda name, beta: moiq_jax.sweep(config, run_dir=str(tmp_path / name), log=None, beta=[beta], seed=[0, 1])
    with compiled_programs() as names:
        first, other, again = sweep("first", 0.0), sweep("other", 5.0), sweep("again", 0.0)
    assert names.count("jit(chunk_all)") == 1
    for name in ("critic_loss", "eval_return", "penalty"):
        np.testing.assert_array_equal(again.history[name], first.history[name])
    for a, b in zip(jax.tree_util.tree_leaves(again.best_params), jax.tree_util.tree_leaves(first.best_params)):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(other.history["critic_loss"], first.history["critic_loss"])


def test_each_experts_best_actor_is_the_actor_of_its_best_evaluation():
    """One model for all experts keeps, per expert, the actor of that expert's best scalarised evaluation
    (in the config's expert order, given here out of the canonical one): evaluating it reproduces that
    evaluation, and it is the actor the run had after that chunk."""
    config = tuned("cdst", total_steps=1200, eval_interval=200, hidden_sizes=(8, 8), batch_size=8, learning_starts=60,
                   buffer_size=600, preferences=((0.1, 0.9), (0.5, 0.5), (0.9, 0.1)))
    actors = []
    result = moiq_jax.train(config, log=None, on_chunk=lambda state, _: actors.append(
        jax.device_get(state.learner.params.actor)))
    scalar = result.history["eval_scalar_return"]  # [evals, E]
    np.testing.assert_array_equal(result.best_return_per_expert, scalar.max(0))
    best = scalar.argmax(0)
    assert len(set(best.tolist())) > 1  # the experts peak at different evaluations: the test tells them apart
    for e in range(3):
        params = result.expert_best_params(e)
        for x, y in zip(jax.tree_util.tree_leaves(params.actor), jax.tree_util.tree_leaves(actors[best[e]])):
            np.testing.assert_array_equal(x, y)
        returns = moiq_jax.evaluate(params, "cdst", config.preferences)
        np.testing.assert_allclose(returns[e], result.history["eval_return"][best[e], e], rtol=1e-6)


def test_iq_learn_trains_one_model_per_expert_without_penalty(demos):
    result = moiq_jax.train(TINY.replace(algo="iq_learn"), demos, log=None)
    assert result.history["iq_loss"].shape == (2, 3)
    assert "penalty" not in result.history
    assert result.final_params.log_alpha.shape == (3, 1)  # three models of one expert each
    assert result.best_actor_per_expert is None  # each model's best_params are its expert's own
    with pytest.raises(ValueError, match="keeps no per-expert best actor"):
        result.expert_best_params(0)


def _best_evaluation(result):
    return int(np.argmax(result.history["eval_scalar_return"].mean(1)))


def _with_target_moved(params):
    return params.replace(target_critic=jax.tree_util.tree_map(lambda x: 1.5 * x, params.target_critic))


def test_reward_correlations_of_trained_params_use_the_critic_losss_own_reward(trained, demos):
    """The correlations recomputed from the best model match the ones recorded at its evaluation (up to the
    sampled actions of V(s')); V(s') comes from the target critic exactly when the config says so."""
    config = TINY.replace(action_scale=1.1)  # trained: moiq, V(s') from the target critic
    correlations = moiq_jax.reward_correlations(trained.best_params, config, demos)
    best = _best_evaluation(trained)
    assert correlations["reward_correlation"].shape == (3,) and correlations["reward_correlation_objectives"].shape == (3, 2)
    np.testing.assert_allclose(correlations["reward_correlation"], trained.history["reward_correlation"][best], atol=0.15)
    moved = moiq_jax.reward_correlations(_with_target_moved(trained.best_params), config, demos)
    assert np.max(np.abs(moved["reward_correlation"] - correlations["reward_correlation"])) > 0.1

    online = TINY.replace(algo="iq_learn", use_target=False)  # one model per expert, V(s') from the online critic
    result = moiq_jax.train(online, demos, log=None)
    correlations = moiq_jax.reward_correlations(result.best_params, online, demos)
    np.testing.assert_allclose(correlations["reward_correlation"],
                               result.history["reward_correlation"][_best_evaluation(result)], atol=0.15)
    moved = moiq_jax.reward_correlations(_with_target_moved(result.best_params), online, demos)
    np.testing.assert_array_equal(moved["reward_correlation"], correlations["reward_correlation"])
    with pytest.raises(ValueError, match="gail does not recover its reward from the critic"):
        moiq_jax.reward_correlations(result.best_params, TINY.replace(algo="gail"), demos)


def test_validate_rejects_negative_beta():
    with pytest.raises(ValueError, match="beta"):
        validate(TINY.replace(beta=-1.0))
    with pytest.raises(ValueError, match="value_term must be one of value, v0, got 'v1'"):
        validate(TINY.replace(value_term="v1"))
    with pytest.raises(ValueError, match="regulariser must be one of replay, policy, both, got 'expert'"):
        validate(TINY.replace(regulariser="expert"))
    with pytest.raises(ValueError, match="num_critics must be 1 or 2, got 3"):
        validate(TINY.replace(num_critics=3))


def test_one_critic_with_the_policy_regulariser_trains_and_evaluates(demos):
    """IQ-Learn's MuJoCo recipe (one critic, the regulariser at the policy's actions, V(s') from the target):
    its parameters hold one critic, and evaluating them rebuilds that network and reproduces the run's own
    evaluation of its best model."""
    config = TINY.replace(num_critics=1, regulariser="policy", use_target=True)
    result = moiq_jax.train(config, demos, log=None)
    assert jax.tree_util.tree_leaves(result.best_params.critic)[0].shape[0] == 1
    assert np.all(np.isfinite(result.history["critic_loss"]))
    returns = moiq_jax.evaluate(result.best_params, "cdst", config.preferences)
    np.testing.assert_allclose(returns, result.history["eval_return"][_best_evaluation(result)], rtol=1e-4, atol=1e-4)


@pytest.fixture(scope="module")
def swept(demos):
    return moiq_jax.sweep(TINY, beta=[0.0, 5.0], seed=[3], demos=demos)


def test_sweep_equals_separate_runs(demos, swept):
    train = jax.jit(make_trainer(TINY, ALGORITHMS["moiq"], demos).train)
    np.testing.assert_array_equal(swept.runs["beta"], [0.0, 5.0])
    np.testing.assert_array_equal(swept.runs["seed"], [3, 3])
    for run, beta in enumerate([0.0, 5.0]):
        state, history = train(jax.random.PRNGKey(3), {"beta": jnp.float32(beta)})
        np.testing.assert_allclose(swept.history["critic_loss"][run], history["critic_loss"], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(swept.history["eval_return"][run], history["eval_return"], rtol=1e-4, atol=1e-4)
        np.testing.assert_allclose(swept.best_return[run], state.best_return, rtol=1e-5)
        np.testing.assert_allclose(swept.best_return_per_expert[run], state.best_return_per_expert, rtol=1e-5)
    assert not np.allclose(swept.history["critic_loss"][0], swept.history["critic_loss"][1])


def test_sweep_rejects_values_the_algorithm_does_not_have(demos):
    with pytest.raises(ValueError, match="a sweep of iq_learn varies seed; got \\['beta'\\]"):
        moiq_jax.sweep(TINY.replace(algo="iq_learn"), beta=[0.0, 5.0], demos=demos)


def _sweep_in_a_fresh_process(setup: str, check: str = "") -> np.ndarray:
    """The critic losses of ``swept``'s sweep, run in a new Python process after ``setup`` (which configures JAX
    before its first computation), with the assertions ``check`` on the sweep ``s``."""
    script = "; ".join(filter(None, [
        "import os, jax, moiq_jax; from moiq_jax import Config", setup,
        f"s = moiq_jax.sweep(Config(**{TINY.to_dict()!r}), beta=[0.0, 5.0], seed=[3])", check,
        "print(s.history['critic_loss'].tolist())"]))
    env = {**{k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}, "PYTHONPATH": os.getcwd()}
    out = subprocess.run([sys.executable, "-c", script], check=False, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return np.array(eval(out.stdout.strip().splitlines()[-1]))


def test_sweep_sharded_over_two_host_devices_matches(swept):
    sharded = _sweep_in_a_fresh_process(
        "from moiq_jax.runtime import split_cpu_into_devices; split_cpu_into_devices(2); assert jax.device_count() == 2",
        "assert len(jax.tree_util.tree_leaves(s.best_params)[0].sharding.device_set) == 2")
    np.testing.assert_allclose(sharded, swept.history["critic_loss"], rtol=1e-4, atol=1e-5)


def test_a_run_pinned_to_one_core_single_threaded_matches(swept):
    pinned = _sweep_in_a_fresh_process(
        "from moiq_jax.runtime import pin_to_cores; from moiq_jax.envs.mujoco.native import default_threads; "
        "pin_to_cores([0]); assert os.sched_getaffinity(0) == {0} and default_threads() == 1; "
        "assert 'intra_op_parallelism_threads=1' in os.environ['XLA_FLAGS']")
    np.testing.assert_allclose(pinned, swept.history["critic_loss"], rtol=1e-4, atol=1e-5)


def test_pin_to_cores_refuses_cores_it_cannot_use_and_a_started_jax():
    with pytest.raises(ValueError, match="not all among the cores this process may use"):
        pin_to_cores([10_000])
    jax.numpy.zeros(1).block_until_ready()
    with pytest.raises(ValueError, match="before JAX's first computation"):
        pin_to_cores([min(os.sched_getaffinity(0))])


def test_num_demos_takes_the_first_episodes_of_a_demos_file(tmp_path):
    source = moiq_jax.experts.oracle_demonstrations("dst-mini", [(0.9, 0.1), (0.1, 0.9)], num_demos=4, seed=3)
    source.save(tmp_path / "d.npz")
    config = moiq_jax.Config(env="dst-mini", preferences=((0.9, 0.1), (0.1, 0.9)), demos=str(tmp_path / "d.npz"))
    one = load_demonstrations(config.replace(num_demos=1))
    assert one.num_episodes == 1
    np.testing.assert_array_equal(one.actions[:, 0], source.actions[:, 0])
    with pytest.raises(ValueError, match="hold 4 episodes per expert, fewer than num_demos = 5"):
        load_demonstrations(config.replace(num_demos=5))


@pytest.mark.parametrize("absorbing_rollouts", [True, False])
def test_rollouts_go_on_in_the_absorbing_state_only_when_asked(absorbing_rollouts):
    """Random hoppers fall within a few dozen steps: rollouts that go on in the absorbing state fill most of
    the replay with its self-loops; rollouts that end at termination hold none, and a done per fall."""
    config = moiq_jax.Config(env="mo-hopper", preferences=((0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.1, 0.8)),
                             demos="experiments/demos/mo-hopper.npz", num_demos=1, total_steps=400, num_envs=4,
                             learning_starts=400, eval_interval=400, eval_episodes=1, batch_size=8, hidden_sizes=(8,),
                             buffer_size=400, absorbing_rollouts=absorbing_rollouts)
    trainer = make_trainer(config, ALGORITHMS["moiq"])
    state, _ = jax.jit(trainer.run_chunk)(trainer.init(jax.random.PRNGKey(0)), trainer.hyper)
    data = jax.tree_util.tree_map(np.asarray, state.buffers.data)
    absorbed, absorbed_next, done = data["obs"][..., -1] == 1, data["next_obs"][..., -1] == 1, data["done"] == 1
    falls = (absorbed_next & ~absorbed).sum(1)  # [experts]: moves from a live state into the absorbing one
    assert np.all(falls >= 4)  # every expert's four envs fell at least once
    if absorbing_rollouts:
        assert not np.any(done) and np.all(absorbed.sum(1) > 200)  # most of the 400 rows are self-loops
    else:
        assert not np.any(absorbed)
        np.testing.assert_array_equal(done, absorbed_next)  # done exactly on the falls

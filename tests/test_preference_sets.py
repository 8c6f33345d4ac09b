"""Sweeps over preference sets: every (set, seed) combination as one vmapped program equals the runs made
separately (labels in the order each set was given), and sets or demos files that do not fit get clear errors."""

import jax
import numpy as np
import pytest

import moiq_jax
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.experts import oracle_demonstrations
from moiq_jax.train import ALGORITHMS

TINY = moiq_jax.Config(total_steps=40, eval_interval=20, num_envs=2, learning_starts=10, batch_size=8,
                       hidden_sizes=(8,), buffer_size=64, num_demos=1, beta=2.0)
SETS = (((0.9, 0.1), (0.1, 0.9)), ((0.2, 0.8), (0.8, 0.2)))  # the second ascending: its labels must come back


@pytest.fixture(scope="module")
def swept():
    return moiq_jax.sweep(TINY, seed=[0, 1], preferences=SETS)


def test_set_by_seed_sweep_equals_the_four_runs_made_separately(swept):
    np.testing.assert_array_equal(swept.runs["set"], [0, 0, 1, 1])
    np.testing.assert_array_equal(swept.runs["seed"], [0, 1, 0, 1])
    np.testing.assert_allclose(swept.runs["preferences"], np.asarray(SETS)[[0, 0, 1, 1]])
    for s, preferences in enumerate(SETS):
        config = TINY.replace(preferences=preferences)
        trainer = make_trainer(config, ALGORITHMS["moiq"])
        train = jax.jit(trainer.train)
        for seed in (0, 1):
            run = 2 * s + seed
            state, history = train(jax.random.PRNGKey(seed), trainer.hyper)
            for name in ("critic_loss", "penalty", "eval_return", "eval_scalar_return"):
                np.testing.assert_allclose(swept.history[name][run], history[name], rtol=1e-4, atol=1e-4)
            np.testing.assert_allclose(swept.best_return[run], state.best_return, rtol=1e-5)
            np.testing.assert_allclose(swept.final_params.log_alpha[run],
                                       trainer.to_config_order(state.learner.params).log_alpha, rtol=1e-4, atol=1e-6)
            one = swept.run(run)
            assert one.config.preferences == preferences and one.config.seed == seed
            np.testing.assert_allclose(one.preferences, preferences)
    # each label's evaluation is its own: the return scalarised by the run's labels, in the given order
    np.testing.assert_allclose(swept.history["eval_scalar_return"],
                               np.einsum("rted,red->rte", swept.history["eval_return"], swept.runs["preferences"]),
                               rtol=1e-5, atol=1e-4)
    assert not np.allclose(swept.history["critic_loss"][0], swept.history["critic_loss"][2])


def test_sets_of_different_sizes_are_refused():
    with pytest.raises(ValueError, match=r"same number of experts .* sizes \[2, 3\]"):
        moiq_jax.sweep(TINY, preferences=[SETS[0], ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))])
    with pytest.raises(ValueError, match="preference set 1: .*sum to 1"):
        moiq_jax.sweep(TINY, preferences=[SETS[0], ((0.9, 0.2), (0.1, 0.9))])


def test_demos_files_must_fit_their_sets(tmp_path):
    path = str(tmp_path / "a.npz")
    oracle_demonstrations("cdst", SETS[0], 1, 0).save(path)
    with pytest.raises(ValueError, match="preference set 1: the demos in .* are of preferences"):
        moiq_jax.sweep(TINY, preferences=SETS, demos=[path, path])
    with pytest.raises(ValueError, match="2 preference sets need one demonstrations file each, got 1"):
        moiq_jax.sweep(TINY, preferences=SETS, demos=[path])

"""Preference inference on discrete DST: the preference step, the exact true-reward intervals, the joint loop's
symmetries and its agreement with Figure 1's ADMM when the preferences are held at the labels."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import Config, envs
from moiq_jax.algos import admm, tabular
from moiq_jax.algos import preference_evidence as evidence
from moiq_jax.algos import preference_inference as pi
from moiq_jax.experts import dst_oracle

PREFS = ((0.9, 0.1), (0.45, 0.55), (0.1, 0.9))  # mini map: treasures 16.8, 14 and 1


@pytest.fixture(scope="module")
def mini():
    env = envs.make("dst-mini", absorbing=True)
    config = Config(env="dst-mini", algo="admm", preferences=PREFS, gamma=0.999, rounds=3)
    demos = dst_oracle.record_demonstrations("dst-mini", PREFS, 5, jax.random.PRNGKey(3))
    mdp = tabular.tabular_mdp(env)
    return env.unwrapped.sea_map, mdp, config, demos


def test_simplex_grid_and_spread():
    grid = pi.simplex_grid(3, 4)
    assert grid.shape == (15, 3) and np.allclose(grid.sum(1), 1) and len(np.unique(grid, axis=0)) == 15
    np.testing.assert_allclose(pi.simplex_grid(2, 4)[:, 0], [1, 0.75, 0.5, 0.25, 0])
    np.testing.assert_allclose(evidence.spread_preferences([2, 0, 1])[:, 0], [0.5, 0.25, 0.75])
    with pytest.raises(ValueError, match="permutation"):
        evidence.spread_preferences([0, 0, 1])
    with pytest.raises(ValueError, match="2 objectives"):
        evidence.spread_preferences([0, 1], reward_dim=3)


def test_true_interval_is_exact():
    sea_map = envs.make("dst").unwrapped.sea_map
    np.testing.assert_allclose(evidence.true_interval(sea_map, (4, 4)), (1 / 2.1, 0.5), atol=1e-6)  # 15.1 at 8 steps
    np.testing.assert_allclose(evidence.true_interval(sea_map, (10, 9)), (2 / 3.3, 1.0), atol=1e-6)  # 23.7
    np.testing.assert_allclose(evidence.true_interval(sea_map, (7, 7)), (1 / 1.7, 1 / 1.7), atol=1e-6)  # 20.3: ties only
    for a in np.linspace(0.01, 0.99, 25):  # the interval of each preference's optimal treasure holds it
        lo, hi = evidence.true_interval(sea_map, dst_oracle.optimal_treasure(sea_map, (a, 1 - a))[0])
        assert lo - 1e-6 <= a <= hi + 1e-6


def test_preference_step_recovers_the_experts_behaviour_under_the_true_reward(mini):
    sea_map, mdp, config, demos = mini
    config = config.replace(temperature=0.05)  # soft-optimal = optimal at the true reward's scale
    counts = evidence.demo_counts(demos, mdp, sea_map.cols)
    exits = evidence.demo_exits(demos, mdp, sea_map.cols)
    assert float(counts[:, mdp.absorbing].sum()) == 0.0
    np.testing.assert_allclose(counts.sum((1, 2)), [10, 7, 1])  # steps to each expert's treasure
    np.testing.assert_array_equal(exits[..., 1], [[10] * 5, [7] * 5, [1] * 5])
    assert np.all(exits[2, :, 0] == 0 * 4 + 1)  # the [0.1, 0.9] expert leaves state 0 moving down
    grid = jnp.asarray(pi.simplex_grid(2, 20))
    for rule in ("likelihood", "closest"):
        start = jnp.full((3, 2), 0.5)
        inferred, loglik, _ = pi.preference_step(mdp.true_reward, counts, exits, grid, start, mdp, config,
                                                 rule=rule)
        assert evidence.optimal_cells(sea_map, inferred) == evidence.optimal_cells(sea_map, PREFS), (rule, inferred)
        assert np.all(np.asarray(loglik) <= 0) and float(loglik[0]) < -1  # the oracle's staircase is stochastic
    with pytest.raises(ValueError, match="unknown preference rule"):
        pi.preference_step(mdp.true_reward, counts, exits, grid, start, mdp, config, rule="nearest")


def test_closest_rule_keeps_a_preference_whose_behaviour_is_already_the_experts(mini):
    sea_map, mdp, config, demos = mini
    config = config.replace(temperature=0.05)
    counts, exits = evidence.demo_counts(demos, mdp, sea_map.cols), evidence.demo_exits(demos, mdp, sea_map.cols)
    grid = jnp.asarray(pi.simplex_grid(2, 20))
    current = jnp.asarray([[0.6, 0.4], [0.45, 0.55], [0.0, 1.0]])  # inside each expert's true interval
    inferred, _, _ = pi.preference_step(mdp.true_reward, counts, exits, grid, current, mdp, config, rule="closest")
    np.testing.assert_allclose(inferred, current, atol=1e-6)


def test_joint_loop_symmetries_and_labelled_agreement(mini):
    sea_map, mdp, config, demos = mini
    config = config.replace(preferences=PREFS[::2], rounds=6)
    two = demos.replace(**{k: np.asarray(getattr(demos, k))[::2] for k in
                           ("obs", "actions", "next_obs", "rewards", "dones", "lengths", "preferences")})
    occupancy = tabular.demo_occupancy(two, mdp, sea_map.cols, config.gamma)
    counts, exits = evidence.demo_counts(two, mdp, sea_map.cols), evidence.demo_exits(two, mdp, sea_map.cols)
    spread = evidence.spread_preferences(evidence.length_order(counts))
    np.testing.assert_allclose(spread[:, 0], [2 / 3, 1 / 3], atol=1e-6)  # the longer-travelling expert first
    initial = np.stack([spread, spread[:, ::-1], np.full((2, 2), 0.5, np.float32)])
    key = jax.random.PRNGKey(0)
    result = pi.infer_seeds(config, np.stack([occupancy] * 3), np.stack([counts] * 3), np.stack([exits] * 3), initial,
                            jnp.stack([key] * 3), resolution=20)
    # swapping the objectives of the initial preferences mirrors the answer and the reward exactly
    np.testing.assert_allclose(result.preferences[1], result.preferences[0][:, ::-1], atol=1e-6)
    np.testing.assert_allclose(result.common_reward[1], result.common_reward[0][..., ::-1], atol=1e-5)
    # equal initial preferences keep the reward's objectives equal: nothing tells the experts apart
    np.testing.assert_allclose(result.common_reward[2][..., 0], result.common_reward[2][..., 1])
    # from the spread start the inferred preferences' greedy behaviour under the learned reward is the experts'
    np.testing.assert_allclose(result.behaviour[0], two.episode_returns()[:, 0], atol=1e-5)
    # with the preferences held at the labels the loop is Figure 1's ADMM round for round
    labelled = pi.infer_seeds(config, occupancy[None], counts[None], exits[None], np.asarray(PREFS[::2], np.float32)[None],
                              key[None], resolution=20, infer=False)
    reference = jax.jit(admm.make_train(config, mdp, jnp.asarray(PREFS[::2])))(key, occupancy)[1]
    np.testing.assert_allclose(labelled.metrics["vector_return"][0], reference["vector_return"], atol=1e-5)
    np.testing.assert_allclose(labelled.metrics["preferences"][0, -1], PREFS[::2], atol=1e-6)


def test_infer_and_learn_checks_its_inputs(mini):
    _, _, config, demos = mini
    with pytest.raises(ValueError, match=r"expected \[3, 2\]: one per expert"):
        pi.infer_and_learn(config, demos.unlabelled(), jax.random.PRNGKey(0), initial=np.full((2, 2), 0.5))


def test_write_run_logs_every_round_and_writes_the_run_directory(tmp_path):
    import json

    rounds = np.array([[[0.5, 0.5], [0.3, 0.7]], [[0.6, 0.4], [0.2, 0.8]]], np.float32)
    result = pi.InferenceResult(
        config=None, initial=rounds[:1], preferences=rounds[-1:], common_reward=None, behaviour=None,
        metrics={"preferences": rounds[None], "log_likelihood": np.array([[[np.nan, -2.0], [-1.0, -0.5]]])},
        learned_interval=np.array([[[0.5, 1.0], [0.0, 0.4]]]))
    lines = []
    record = evidence.write_run(result, tmp_path / "run", log=lines.append)
    assert lines[0] == "round 1: preferences [[0.5, 0.5], [0.3, 0.7]]" and len(lines) == 3
    written = json.loads((tmp_path / "run" / "inferred_preferences.json").read_text())
    assert written == record and written["log_likelihood_per_round"][0] == [None, -2.0]
    np.testing.assert_allclose(written["inferred"], [[0.6, 0.4], [0.2, 0.8]])


def test_cli_infers_preferences_from_an_unlabelled_demos_file(tmp_path, mini):
    """`moiq train --algo admm --infer-preferences` on a file without labels: every agent repeats its expert's
    demonstrated return, the rows are labelled by the inferred preferences, and the file holds them per round."""
    import csv
    import json

    from moiq_jax.cli import main

    _, _, _, demos = mini
    path = tmp_path / "unlabelled.npz"
    demos.unlabelled().save(path)
    run_dir = tmp_path / "run"
    assert main(["train", "--env", "dst-mini", "--algo", "admm", "--gamma", "0.999", "--demos", str(path),
                 "--num-demos", "5", "--infer-preferences", "--rounds", "10", "--preference-warmup", "10",
                 "--preferences", "0.5,0.5", "0.6,0.4", "0.4,0.6", "--run-dir", str(run_dir)]) == 0
    record = json.loads((run_dir / "inferred_preferences.json").read_text())
    assert len(record["per_round"]) == 20
    inferred = np.asarray(record["inferred"])
    np.testing.assert_allclose(inferred.sum(1), 1.0, atol=1e-6)
    with open(run_dir / "metrics.csv") as f:
        last = [row for row in csv.DictReader(f) if row["round"] == "20"]
    assert [row["preference"] for row in last] == [" ".join(f"{w:g}" for w in np.float32(p)) for p in inferred]
    returns = np.asarray([[float(row["vector_return_0"]), float(row["vector_return_1"])] for row in last])
    np.testing.assert_allclose(returns, demos.mean_returns(), atol=1e-5)  # each agent takes its expert's treasure

"""MOIQ with inferred preferences on continuous DST: behaviours from rollouts and demo replays, the preference
step under cdst's true reward (checked exactly against the oracle), the errors, and the CLI at smoke size."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import Config, envs
from moiq_jax.algos import moiq_preference_inference as mpi
from moiq_jax.algos.preference_inference import simplex_grid
from moiq_jax.config import tuned
from moiq_jax.envs.cdst import lattice_policy
from moiq_jax.experts import oracle_demonstrations
from moiq_jax.experts.cdst_oracle import best_treasure, clear_actions

PAPER = ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))  # treasures 23.7 (23 steps), 15.1 (7), 0.7 (1)


@pytest.fixture(scope="module")
def cdst():
    env = envs.make("cdst")
    demos = oracle_demonstrations("cdst", PAPER, 2)
    return env, demos, np.asarray(mpi.demo_behaviours(demos, env))


def true_behaviour(env, w) -> list[int]:
    """The true reward's optimal behaviour for ``w``: its treasure cell and fewest steps (exact, the oracle's)."""
    cell, ret = best_treasure(env, np.asarray(w))
    return [cell[0], cell[1], int(-ret[1])]


def test_demo_replay_and_policy_rollout_give_the_oracle_behaviour(cdst):
    env, _, demo = cdst
    expected = [true_behaviour(env, w) for w in PAPER]
    np.testing.assert_array_equal(demo, np.repeat(np.asarray(expected)[:, None], 2, axis=1))
    assert [b[2] for b in expected] == [23, 7, 1]
    policy = lattice_policy(clear_actions(env, best_treasure(env, np.asarray(PAPER[1]))[0]))
    np.testing.assert_array_equal(mpi.rollout_behaviour(env, lambda t, obs: policy(obs)), expected[1])
    never = mpi.rollout_behaviour(env, lambda t, obs: jnp.zeros(2))  # stays at the start: never ends
    np.testing.assert_array_equal(never, [-1, -1, env.episode_length])


def test_preference_step_recovers_the_experts_behaviour_under_the_true_reward(cdst):
    """From the spread start (by demo length), with the true reward's optimal behaviour per candidate, every
    inferred preference's optimum takes its expert's treasure in its steps; a preference whose optimum already
    does stays, one that does not moves to the nearest candidate that does."""
    env, _, demo = cdst
    start = mpi.spread_start(demo, 2)
    np.testing.assert_allclose(start, [[0.75, 0.25], [0.5, 0.5], [0.25, 0.75]])
    candidates = simplex_grid(2, 20)
    behaviour = np.asarray([true_behaviour(env, w) for w in candidates])
    current = np.asarray([true_behaviour(env, w) for w in start])
    new, share = mpi.preference_step(jnp.asarray(behaviour), jnp.asarray(candidates), jnp.asarray(demo),
                                     jnp.asarray(start), jnp.asarray(current))
    new = np.asarray(new)
    np.testing.assert_allclose(share, 1.0)
    for e, w in enumerate(PAPER):
        assert true_behaviour(env, new[e]) == true_behaviour(env, w)
        if current[e].tolist() == true_behaviour(env, w):
            np.testing.assert_allclose(new[e], start[e])
        else:
            repeats = np.all(behaviour == true_behaviour(env, w), axis=1)
            nearest = np.abs(candidates[repeats] - start[e]).sum(1).min()
            assert np.abs(new[e] - start[e]).sum() == pytest.approx(nearest)
    moved = np.any(np.abs(new - start) > 1e-6, axis=1)
    assert moved.any() and not moved.all()  # the case exercises both branches
    # no candidate repeats an episode: the preference stays
    kept, _ = mpi.preference_step(jnp.full_like(jnp.asarray(behaviour), -2), jnp.asarray(candidates),
                                  jnp.asarray(demo), jnp.asarray(start), jnp.full((3, 3), -2))
    np.testing.assert_allclose(kept, start)


def test_unsupported_combinations_raise(cdst):
    import moiq_jax

    with pytest.raises(ValueError, match="moiq inferring preferences reads its demonstrations from config.demos"):
        moiq_jax.train(Config(algo="moiq", infer_preferences=True), demos=cdst[1])
    with pytest.raises(ValueError, match="infer_preferences runs with algo admm or moiq"):
        Config(algo="sac", infer_preferences=True).validate()
    with pytest.raises(ValueError, match="infers preferences on cdst"):
        mpi.check(Config(env="mo-hopper", algo="moiq", infer_preferences=True))
    with pytest.raises(ValueError, match="must be below total_steps"):
        mpi.check(tuned("cdst", infer_preferences=True, total_steps=50_000))
    with pytest.raises(ValueError, match="multiple of eval_interval"):
        mpi.check(tuned("cdst", infer_preferences=True, preference_interval=7_000))
    with pytest.raises(ValueError, match="preference_interval must be positive"):
        Config(preference_interval=0).validate(sections=("moiq",))


def test_cli_trains_moiq_inferring_preferences_from_an_unlabelled_file(tmp_path, cdst, capsys):
    """`moiq train --env cdst --algo moiq --infer-preferences --demos unlabelled.npz` at smoke size: the
    preferences start at the spread, are logged per chunk and written; labels are not needed."""
    from moiq_jax.cli import main

    _, demos, _ = cdst
    path = tmp_path / "unlabelled.npz"
    demos.unlabelled().save(path)
    run_dir = tmp_path / "run"
    flags = ["--total-steps", "200", "--eval-interval", "100", "--learning-starts", "100", "--num-envs", "1",
             "--preference-warmup-steps", "100", "--preference-interval", "100", "--hidden-sizes", "8",
             "--batch-size", "8", "--buffer-size", "200", "--updates-per-step", "1"]
    assert main(["train", "--env", "cdst", "--algo", "moiq", "--infer-preferences", "--demos", str(path),
                 "--num-demos", "2", *flags, "--run-dir", str(run_dir)]) == 0
    record = json.loads((run_dir / "inferred_preferences.json").read_text())
    np.testing.assert_allclose(record["initial"], [[0.75, 0.25], [0.5, 0.5], [0.25, 0.75]])
    assert record["env_steps"] == [100, 200] and len(record["per_chunk"]) == 2
    assert record["share_per_chunk"][0] == [None] * 3 and len(record["share_per_chunk"][1]) == 3
    np.testing.assert_allclose(np.sum(record["inferred"], axis=1), 1.0, atol=1e-6)
    assert (run_dir / "metrics.csv").exists()
    out = capsys.readouterr().out
    assert "steps 100: preferences" in out and "inferred preferences" in out
    assert main(["train", "--env", "cdst", "--algo", "moiq", "--infer-preferences", "--seeds", "2", *flags,
                 "--run-dir", str(tmp_path / "two")]) == 2
    assert "drop --resume/--seeds" in capsys.readouterr().err

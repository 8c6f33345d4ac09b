"""Demonstrations recorded from the DST oracle: save/load round trip and clear errors on bad files."""

import jax
import numpy as np
import pytest

from moiq_jax import Demonstrations, envs
from moiq_jax.experts import oracle_demonstrations, record_demonstrations


@pytest.fixture(scope="module")
def demos():
    return record_demonstrations("dst-mini", [[0.9, 0.1], [0.1, 0.9]], 4, jax.random.PRNGKey(0))


def test_round_trip(tmp_path, demos):
    path = tmp_path / "demos.npz"
    demos.save(path)
    loaded = Demonstrations.load(path, envs.make("dst-mini", absorbing=True))
    for name in ("obs", "actions", "next_obs", "rewards", "dones", "lengths", "preferences"):
        np.testing.assert_array_equal(np.asarray(getattr(loaded, name)), np.asarray(getattr(demos, name)))
    assert loaded.env == "dst-mini" and loaded.metadata["expert"] == "dst_oracle"
    np.testing.assert_allclose(loaded.episode_returns()[:, 0], [[16.8, -10.0], [1.0, -1.0]], atol=1e-5)


def test_bad_files_give_clear_errors(tmp_path, demos):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        Demonstrations.load(tmp_path / "missing.npz")
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file")
    with pytest.raises(ValueError, match="corrupt"):
        Demonstrations.load(garbage)
    partial = tmp_path / "partial.npz"
    np.savez(partial, obs=np.asarray(demos.obs))
    with pytest.raises(ValueError, match="lacks"):
        Demonstrations.load(partial)
    path = tmp_path / "demos.npz"
    demos.save(path)
    with pytest.raises(ValueError, match="absorbing"):  # recorded with the absorbing flag, loaded without
        Demonstrations.load(path, envs.make("dst-mini"))
    bad = demos.replace(preferences=np.array([[0.9, 0.3], [0.1, 0.9]], np.float32))
    with pytest.raises(ValueError, match="sum to 1"):
        bad.save(tmp_path / "bad.npz")


def test_demos_with_another_number_of_objectives_do_not_fit_the_env():
    demos = oracle_demonstrations("cdst", [[0.9, 0.1], [0.1, 0.9]], num_demos=1)
    three = demos.replace(rewards=np.concatenate([demos.rewards, np.zeros_like(demos.rewards[..., :1])], -1),
                          preferences=np.array([[0.8, 0.1, 0.1], [0.1, 0.1, 0.8]], np.float32))
    three.validate()  # consistent in itself
    with pytest.raises(ValueError, match="reward_dim 3 does not match the env's 2"):
        three.validate(envs.make("cdst", absorbing=True))


def test_unlabelled_demos_round_trip_and_validate(tmp_path, demos):
    unlabelled = demos.unlabelled()
    assert not unlabelled.labelled and unlabelled.num_experts == 2 and unlabelled.reward_dim == 2
    path = tmp_path / "unlabelled.npz"
    unlabelled.save(path)
    with np.load(path) as data:
        assert "preferences" not in data.files
    loaded = Demonstrations.load(path, envs.make("dst-mini", absorbing=True))
    assert loaded.preferences is None and loaded.num_experts == 2
    np.testing.assert_array_equal(np.asarray(loaded.actions), np.asarray(demos.actions))
    # a labelled file still loads with its preferences
    demos.save(tmp_path / "labelled.npz")
    np.testing.assert_allclose(Demonstrations.load(tmp_path / "labelled.npz").preferences, [[0.9, 0.1], [0.1, 0.9]])


def test_preferences_of_the_wrong_shape_give_clear_errors(demos):
    with pytest.raises(ValueError, match=r"expected \[2, d\]: one per expert"):
        demos.replace(preferences=np.array([[0.9, 0.1]], np.float32)).validate()
    with pytest.raises(ValueError, match=r"expected \[2, d\]"):
        demos.replace(preferences=np.array([0.9, 0.1], np.float32)).validate()
    with pytest.raises(ValueError, match="rewards has shape"):  # 3 weights but 2-objective rewards
        demos.replace(preferences=np.full((2, 3), 1 / 3, np.float32)).validate()
    with pytest.raises(ValueError, match="lengths has shape"):
        demos.unlabelled().replace(lengths=np.asarray(demos.lengths)[:1]).validate()

"""IQ-Learn's expert pickles: hand-built files load to the expected arrays, export -> import round trips,
the absorbing state and time limit conventions, and clear errors on bad files."""

import pickle
from collections import defaultdict

import jax
import numpy as np
import pytest

from moiq_jax.experts import load_iq_learn, oracle_demonstrations, record_demonstrations, save_iq_learn
from moiq_jax.experts.iq_learn_format import SCALAR_REWARDS, VECTOR_REWARDS

PREFS = [[0.9, 0.1], [0.1, 0.9]]


def write_iq_learn_file(path, episodes):
    """Pickle ``episodes`` (lists of (state, next_state, action, reward, done) steps) as IQ-Learn's
    expert_generation.py does: a defaultdict(list) of per-trajectory tuples, and the lengths."""
    trajectories = defaultdict(list)
    for steps in episodes:
        states, next_states, actions, rewards, dones = zip(*steps)
        for key, values in zip(("states", "next_states", "actions", "rewards", "dones"),
                               (states, next_states, actions, rewards, dones)):
            trajectories[key].append(values)
        trajectories["lengths"].append(len(steps))
    with open(path, "wb") as f:
        pickle.dump(trajectories, f)
    return path


def cdst_episode(num_steps, terminated, reward=-1.0, state_size=2):
    """A cdst-shaped trajectory: float64 states, float32 actions, float rewards, bool dones (as Gym gives)."""
    states = [np.full(state_size, 0.1 * t) for t in range(num_steps + 1)]
    return [(states[t], states[t + 1], np.array([0.5, -0.5], np.float32) * (t % 2), reward, terminated and
             t == num_steps - 1) for t in range(num_steps)]


def scalarised_returns(demos):
    """``[E, N]`` every episode's return scalarised by its expert's preference."""
    return (demos.episode_returns() * np.asarray(demos.preferences)[:, None]).sum(-1)


@pytest.fixture(scope="module")
def cdst_demos():
    return oracle_demonstrations("cdst", PREFS, num_demos=2)


def test_a_hand_built_file_loads_to_the_expected_arrays(tmp_path):
    path = write_iq_learn_file(tmp_path / "expert.pkl", [cdst_episode(3, terminated=True), cdst_episode(2, False)])
    demos = load_iq_learn([path], [PREFS[0]], "cdst", absorbing=False)
    assert demos.obs.shape == (1, 2, 3, 2) and demos.actions.shape == (1, 2, 3, 2)
    np.testing.assert_array_equal(demos.lengths, [[3, 2]])
    np.testing.assert_allclose(demos.obs[0, 0], [[0.0, 0.0], [0.1, 0.1], [0.2, 0.2]])
    np.testing.assert_allclose(demos.next_obs[0, 1, :2], [[0.1, 0.1], [0.2, 0.2]])
    np.testing.assert_array_equal(demos.actions[0, 0], [[0.0, 0.0], [0.5, -0.5], [0.0, 0.0]])
    np.testing.assert_array_equal(demos.dones, [[[False, False, True], [False, False, False]]])
    np.testing.assert_array_equal(demos.rewards[0, 1], [[-1.0, -1.0], [-1.0, -1.0], [0.0, 0.0]])  # copied, padded
    np.testing.assert_allclose(demos.episode_returns()[0] @ PREFS[0], [-3.0, -2.0])
    assert demos.obs.dtype == np.float32 and demos.metadata["rewards"] == [SCALAR_REWARDS]


def test_vector_rewards_are_kept(tmp_path):
    episode = [(s, n, a, np.array([r, 2.0 * r]), d) for s, n, a, r, d in cdst_episode(2, terminated=True)]
    demos = load_iq_learn([write_iq_learn_file(tmp_path / "expert.pkl", [episode])], [PREFS[0]], "cdst",
                          absorbing=False)
    np.testing.assert_array_equal(demos.rewards[0, 0], [[-1.0, -2.0], [-1.0, -2.0]])
    assert demos.metadata["rewards"] == [VECTOR_REWARDS]


def test_absorbing_adds_the_flag_and_runs_terminated_episodes_in_the_absorbing_state(tmp_path):
    path = write_iq_learn_file(tmp_path / "expert.pkl", [cdst_episode(3, terminated=True), cdst_episode(2, False)])
    demos = load_iq_learn([path], [PREFS[0]], "cdst")
    assert demos.obs.shape == (1, 2, 100, 3)
    np.testing.assert_array_equal(demos.lengths, [[100, 2]])
    absorbing = [0.0, 0.0, 1.0]
    np.testing.assert_allclose(demos.obs[0, 0, :3], [[0.0, 0.0, 0.0], [0.1, 0.1, 0.0], [0.2, 0.2, 0.0]])
    np.testing.assert_array_equal(demos.next_obs[0, 0, 2], absorbing)  # the terminating step
    np.testing.assert_array_equal(demos.obs[0, 0, 3:], np.tile(absorbing, (97, 1)))
    np.testing.assert_array_equal(demos.next_obs[0, 0, 3:], np.tile(absorbing, (97, 1)))
    np.testing.assert_array_equal(demos.rewards[0, 0, 3:], 0.0)
    np.testing.assert_array_equal(demos.actions[0, 0, 3:], 0.0)
    assert not np.asarray(demos.dones).any()
    np.testing.assert_allclose(demos.next_obs[0, 1, 1], [0.2, 0.2, 0.0])  # not terminated: no absorbing state


def test_a_done_at_the_time_limit_is_truncation(tmp_path):
    path = write_iq_learn_file(tmp_path / "expert.pkl", [cdst_episode(100, terminated=True)])
    plain = load_iq_learn([path], [PREFS[0]], "cdst", absorbing=False)
    assert not np.asarray(plain.dones).any()
    absorbing = load_iq_learn([path], [PREFS[0]], "cdst")
    assert absorbing.lengths[0, 0] == 100 and absorbing.next_obs[0, 0, -1, -1] == 0.0


def test_export_writes_iq_learn_layout_with_plain_python_values(tmp_path, cdst_demos):
    save_iq_learn(cdst_demos, 0, tmp_path / "expert.pkl")
    with open(tmp_path / "expert.pkl", "rb") as f:
        trajectories = pickle.load(f)
    assert set(trajectories) == {"states", "next_states", "actions", "rewards", "dones", "lengths"}
    length = trajectories["lengths"][0]
    assert isinstance(length, int) and 1 < length < 100  # cut where the absorbing state begins
    assert all(len(trajectories[key][0]) == length for key in trajectories if key != "lengths")
    assert trajectories["dones"][0] == [False] * (length - 1) + [True]
    assert len(trajectories["states"][0][0]) == 2 and isinstance(trajectories["rewards"][0][0], float)
    assert trajectories["next_states"][0][-1] == [0.0, 0.0]  # absorbing demos do not keep the terminal observation
    np.testing.assert_allclose(sum(trajectories["rewards"][0]), cdst_demos.episode_returns()[0, 0] @ PREFS[0],
                               rtol=1e-5)


def test_absorbing_round_trip(tmp_path, cdst_demos):
    paths = [tmp_path / f"expert{e}.pkl" for e in range(2)]
    for e, path in enumerate(paths):
        save_iq_learn(cdst_demos, e, path)
    loaded = load_iq_learn(paths, PREFS, "cdst")
    for name in ("obs", "next_obs", "dones", "lengths"):
        np.testing.assert_array_equal(np.asarray(getattr(loaded, name)), np.asarray(getattr(cdst_demos, name)))
    live = np.asarray(cdst_demos.obs)[..., -1] == 0.0  # the absorbing state's actions are not kept
    np.testing.assert_array_equal(np.asarray(loaded.actions)[live], np.asarray(cdst_demos.actions)[live])
    np.testing.assert_allclose(scalarised_returns(loaded), scalarised_returns(cdst_demos), rtol=1e-5)


def test_discrete_round_trip_without_absorbing_state(tmp_path):
    demos = record_demonstrations("dst-mini", PREFS, 3, jax.random.PRNGKey(0), absorbing=False)
    paths = [tmp_path / f"expert{e}.pkl" for e in range(2)]
    for e, path in enumerate(paths):
        save_iq_learn(demos, e, path)
    loaded = load_iq_learn(paths, PREFS, "dst-mini", absorbing=False)
    steps = int(np.asarray(demos.lengths).max())  # padded to the longest episode, not to the time limit
    assert loaded.obs.shape[2] == steps
    np.testing.assert_array_equal(loaded.lengths, demos.lengths)
    for name in ("obs", "next_obs", "actions", "dones"):
        np.testing.assert_array_equal(np.asarray(getattr(loaded, name)), np.asarray(getattr(demos, name))[:, :, :steps])
    assert loaded.actions.dtype == np.int32
    np.testing.assert_allclose(scalarised_returns(loaded), scalarised_returns(demos), rtol=1e-5)


def test_bad_files_give_clear_errors(tmp_path):
    good = write_iq_learn_file(tmp_path / "good.pkl", [cdst_episode(3, terminated=True)])
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_iq_learn([tmp_path / "missing.pkl"], [PREFS[0]], "cdst")
    (tmp_path / "garbage.pkl").write_bytes(b"not a pickle")
    with pytest.raises(ValueError, match="not a readable pickle"):
        load_iq_learn([tmp_path / "garbage.pkl"], [PREFS[0]], "cdst")
    (tmp_path / "list.pkl").write_bytes(pickle.dumps([1, 2]))
    with pytest.raises(TypeError, match="holds a list, not a dict"):
        load_iq_learn([tmp_path / "list.pkl"], [PREFS[0]], "cdst")
    with open(good, "rb") as f:
        trajectories = dict(pickle.load(f))

    def load_changed(**changes):
        path = tmp_path / "changed.pkl"
        path.write_bytes(pickle.dumps({key: value for key, value in {**trajectories, **changes}.items()
                                       if value is not None}))
        return load_iq_learn([path], [PREFS[0]], "cdst")

    with pytest.raises(ValueError, match=r"lacks the keys \['next_states', 'dones'\]"):
        load_changed(next_states=None, dones=None)
    with pytest.raises(ValueError, match=r"trajectory 0 has 3 states entries but lengths\[0\] = 4"):
        load_changed(lengths=[4])
    with pytest.raises(ValueError, match="different numbers of trajectories"):
        load_changed(rewards=trajectories["rewards"] * 2)
    with pytest.raises(ValueError, match="before its last step"):
        load_changed(dones=[(True, False, False)])
    with pytest.raises(ValueError, match="observes 2 values"):
        load_changed(states=[[np.zeros(3)] * 3])
    with pytest.raises(ValueError, match="2 files for 1 preferences"):
        load_iq_learn([good, good], [PREFS[0]], "cdst")
    with pytest.raises(ValueError, match="more than 100"):
        load_iq_learn([write_iq_learn_file(tmp_path / "long.pkl", [cdst_episode(101, False)])], [PREFS[0]], "cdst")
    two = write_iq_learn_file(tmp_path / "two.pkl", [cdst_episode(3, True), cdst_episode(2, False)])
    with pytest.raises(ValueError, match="pass num_trajectories"):
        load_iq_learn([good, two], PREFS, "cdst")
    assert load_iq_learn([good, two], PREFS, "cdst", num_trajectories=1).num_episodes == 1


def test_bad_exports_give_clear_errors(tmp_path, cdst_demos):
    with pytest.raises(IndexError, match="expert_index 2"):
        save_iq_learn(cdst_demos, 2, tmp_path / "expert.pkl")
    with pytest.raises(ValueError, match="must end in .pkl"):
        save_iq_learn(cdst_demos, 0, tmp_path / "expert.npz")

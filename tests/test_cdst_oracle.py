import numpy as np

from moiq_jax import envs
from moiq_jax.experts import cdst_oracle

PAPER_PREFS = [[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]]


def test_expert_returns_are_the_documented_treasures():
    np.testing.assert_allclose(cdst_oracle.expert_returns(PAPER_PREFS), [[23.7, -23], [15.1, -7], [0.7, -1]], rtol=1e-6)


def test_demonstrations_reach_the_exact_expert_returns_with_fixed_length(tmp_path):
    demos = cdst_oracle.record_demonstrations(PAPER_PREFS, num_demos=4)
    env = envs.make("cdst", absorbing=True)
    assert demos.obs.shape == (3, 4, env.episode_length, 3) and demos.actions.shape == (3, 4, 100, 2)
    assert np.all(demos.lengths == 100) and not demos.dones.any()
    returns = demos.episode_returns()
    np.testing.assert_allclose(returns, np.repeat(cdst_oracle.expert_returns(PAPER_PREFS)[:, None], 4, 1), rtol=1e-5)
    # After the treasure the demonstrator sits in the absorbing state (flag set, zero reward).
    absorbed = demos.next_obs[..., -1] == 1.0
    np.testing.assert_array_equal(absorbed.sum(axis=2)[:, 0], [101 - 23, 101 - 7, 101 - 1])  # from the treasure step on
    demos.save(tmp_path / "d.npz")
    assert demos.load(tmp_path / "d.npz", env).num_experts == 3

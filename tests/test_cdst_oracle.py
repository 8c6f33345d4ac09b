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


def test_hazards_count_the_rock_treasure_and_outside_cells_a_lattice_point_touches():
    sea_map = envs.make("cdst").unwrapped.sea_map
    assert cdst_oracle.hazards_near(sea_map, (8, 12), (10, 9)) == 1  # (4.0, 6.0): corner of treasure (4, 5)
    assert cdst_oracle.hazards_near(sea_map, (8, 12), (4, 5)) == 0  # ... unless that is the target
    assert cdst_oracle.hazards_near(sea_map, (0, 1), (1, 0)) == 1  # (0.0, 0.5): on the map's top edge
    assert cdst_oracle.hazards_near(sea_map, (1, 1), (1, 0)) == 0  # (0.5, 0.5): a cell centre
    assert cdst_oracle.hazards_near(sea_map, (10, 2), (1, 0)) == 4  # (5.0, 1.0): amid rock


def test_expert_paths_avoid_hazard_borders_where_a_shortest_path_can():
    env = envs.make("cdst")
    demos = cdst_oracle.record_demonstrations(PAPER_PREFS, num_demos=1)
    live = demos.obs[0, 0, :23, :2]  # the [0.9, 0.1] expert's 23 steps to the treasure 23.7 at (10, 9)
    touching = [cdst_oracle.hazards_near(env.unwrapped.sea_map, tuple((2 * p).astype(int)), (10, 9)) for p in live]
    assert sum(touching) == 3, touching  # only the unavoidable diagonal corners (4, 6), (7, 8) and (9, 9)
    corner_first = env.unwrapped.optimal_policy((10, 9))  # the env's first-found tie-break hugs the top edge
    assert np.asarray(corner_first(live[0])).tolist() == [-1.0, 1.0]

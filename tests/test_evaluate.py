"""Evaluation statistics."""

import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax.evaluate import hypervolume, pearson


def test_pearson_matches_numpy_with_and_without_a_mask():
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(6, 4)), rng.normal(size=(6, 4))
    np.testing.assert_allclose(pearson(jnp.asarray(x), jnp.asarray(y)), np.corrcoef(x.ravel(), y.ravel())[0, 1],
                               rtol=1e-5)
    mask = rng.random((6, 4)) > 0.4
    np.testing.assert_allclose(pearson(jnp.asarray(x), jnp.asarray(y), jnp.asarray(mask)),
                               np.corrcoef(x[mask], y[mask])[0, 1], rtol=1e-5)
    # Invariant to scale and offset of either side: a recovered reward only has to match up to them.
    np.testing.assert_allclose(pearson(jnp.asarray(3 * x + 2), jnp.asarray(y)), pearson(jnp.asarray(x), jnp.asarray(y)),
                               rtol=1e-5)


def test_hypervolume_of_a_staircase_and_against_a_grid_count():
    # One point: its rectangle. Two non-dominated points: two rectangles minus their overlap.
    assert hypervolume([[3.0, 2.0]], [0.0, 0.0]) == 6.0
    assert hypervolume([[3.0, 1.0], [1.0, 3.0], [0.5, 0.5], [-1.0, 9.0]], [0.0, 0.0]) == 3.0 + 1.0 * 2.0
    rng = np.random.default_rng(0)
    points, reference = rng.uniform(0, 1, (12, 2)), np.array([0.1, 0.05])
    grid = np.stack(np.meshgrid(*(np.linspace(0, 1, 801)[:-1] + 1 / 1600,) * 2), -1).reshape(-1, 2)
    dominated = (grid[:, None] <= points[None]).all(-1).any(-1) & (grid > reference).all(-1)
    assert hypervolume(points, reference) == pytest.approx(dominated.mean(), abs=2e-3)
    with pytest.raises(ValueError, match="2-vector reference"):
        hypervolume(points, [0.0, 0.0, 0.0])

"""Evaluation statistics."""

import jax.numpy as jnp
import numpy as np

from moiq_jax.evaluate import pearson


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

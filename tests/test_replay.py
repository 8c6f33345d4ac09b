import jax
import jax.numpy as jnp
import numpy as np

from moiq_jax import replay


def _batch(start, n):
    values = jnp.arange(start, start + n, dtype=jnp.float32)
    return {"obs": jnp.stack([values, -values], 1), "done": values > 100}


def test_add_wraps_around_and_counts():
    buf = replay.init({"obs": jnp.zeros(2), "done": jnp.zeros((), bool)}, capacity=5)
    buf = replay.add(buf, _batch(0, 3))
    assert int(buf.size) == 3 and int(buf.position) == 3
    buf = jax.jit(replay.add)(buf, _batch(3, 4))  # rows 3, 4, 0, 1
    assert int(buf.size) == 5 and int(buf.position) == 2
    np.testing.assert_array_equal(buf.data["obs"][:, 0], [5, 6, 2, 3, 4])
    assert buf.data["done"].dtype == bool


def test_sample_draws_only_filled_rows():
    buf = replay.init({"obs": jnp.zeros(2), "done": jnp.zeros((), bool)}, capacity=100)
    buf = replay.add(buf, _batch(1, 7))
    drawn = replay.sample(buf, jax.random.PRNGKey(0), 500)
    assert drawn["obs"].shape == (500, 2)
    assert set(np.asarray(drawn["obs"][:, 0]).tolist()) == set(range(1, 8))


def test_one_buffer_per_expert_by_vmap():
    example = {"obs": jnp.zeros(2), "done": jnp.zeros((), bool)}
    bufs = jax.vmap(lambda _: replay.init(example, 10))(jnp.arange(3))
    batches = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), _batch(0, 2), _batch(10, 2), _batch(20, 2))
    bufs = jax.vmap(replay.add)(bufs, batches)
    drawn = jax.vmap(replay.sample, in_axes=(0, 0, None))(bufs, jax.random.split(jax.random.PRNGKey(1), 3), 50)
    assert drawn["obs"].shape == (3, 50, 2)
    for expert in range(3):
        assert set(np.asarray(drawn["obs"][expert, :, 0]).tolist()) <= {10 * expert, 10 * expert + 1}

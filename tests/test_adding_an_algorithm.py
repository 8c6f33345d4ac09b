"""The README's "Adding an algorithm" example, run as written: one module and one registry line give an
algorithm that trains, sweeps its own hyperparameter and reports under the preferences' labels."""

import pathlib
import re
import types

import numpy as np

import moiq_jax
from moiq_jax.train import ALGORITHMS

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"
TINY = moiq_jax.Config(algo="sqil", total_steps=40, eval_interval=20, num_envs=2, learning_starts=10, batch_size=8,
                       hidden_sizes=(8,), buffer_size=64, num_demos=1, preferences=((0.1, 0.9), (0.9, 0.1)))


def readme_module():
    section = README.read_text().split("## Adding an algorithm")[1].split("\n## ")[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.DOTALL)
    module = types.ModuleType("sqil")
    exec(compile(code, "README.md", "exec"), module.__dict__)  # noqa: S102 (the README's own example)
    return module


def test_the_readme_example_trains_and_sweeps(monkeypatch):
    sqil = readme_module()
    monkeypatch.setitem(ALGORITHMS, "sqil", sqil.ALGORITHM)  # the one registry line
    swept = moiq_jax.sweep(TINY, expert_reward=[0.0, 1.0], seed=[0])
    np.testing.assert_array_equal(swept.runs["expert_reward"], [0.0, 1.0])
    np.testing.assert_allclose(swept.preferences, TINY.preferences)
    history = swept.history
    assert history["eval_return"].shape == (2, 2, 2, 2) and history["td_loss"].shape == (2, 2, 2)
    assert np.all(np.isfinite(history["critic_loss"]))
    # with no expert reward the critic fits zero rewards only; with it the losses differ
    assert not np.allclose(history["td_loss"][0], history["td_loss"][1])

"""Preference validation and the run config."""

import numpy as np
import pytest

from moiq_jax import Config
from moiq_jax.preferences import check_preferences, preference_sweep
from moiq_jax.train import validate


@pytest.mark.parametrize(
    "prefs, message",
    [
        ([[0.5, 0.3, 0.2]], "needs 2 weights"),
        ([[1.2, -0.2]], "non-negative"),
        ([[0.6, 0.6]], "sum to 1"),
        ([[np.nan, 1.0]], "finite"),
    ],
)
def test_bad_preferences_say_what_is_wrong(prefs, message):
    with pytest.raises(ValueError, match=message):
        check_preferences(prefs, reward_dim=2)


def test_good_preferences_pass_as_float32_rows():
    out = check_preferences([0.25, 0.75], reward_dim=2)
    assert out.dtype == np.float32 and out.shape == (1, 2)


def test_sweep_is_the_papers_19_preferences():
    sweep = preference_sweep()
    assert sweep.shape == (19, 2)
    np.testing.assert_allclose(sweep[0], [0.95, 0.05], atol=1e-6)
    np.testing.assert_allclose(sweep[-1], [0.05, 0.95], atol=1e-6)
    np.testing.assert_allclose(sweep.sum(1), 1.0, atol=1e-6)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"env": "cdts"}, "unknown env 'cdts'"),
        ({"algo": "gail2"}, "unknown algo 'gail2'"),
        ({"preferences": ((0.5, 0.6),)}, "sum to 1"),
        ({"num_demos": 0}, "num_demos"),
        ({"gamma": 1.0}, "gamma"),
    ],
)
def test_config_validation(changes, message):
    with pytest.raises(ValueError, match=message):
        validate(Config().replace(**changes))


def test_config_turns_lists_into_tuples():
    cfg = Config(preferences=[[0.9, 0.1], [0.1, 0.9]])
    assert cfg.preferences == ((0.9, 0.1), (0.1, 0.9))
    hash(cfg)

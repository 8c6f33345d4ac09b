"""experiments/cdst_transfer_ceiling.py: its scores and learning-free references on the exact cdst front,
against numbers worked out by hand from the front's treasures."""

import csv
import os
import pathlib
import subprocess
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))

import cdst_transfer_ceiling as ceiling

import moiq_jax
from moiq_jax.experts.cdst_oracle import expert_returns

EXPERT_PREFERENCES = np.array([[0.9, 0.1], [0.5, 0.5], [0.1, 0.9]])


def front():
    return np.asarray(moiq_jax.envs.make("cdst").unwrapped.pareto_front())


def test_the_optimum_itself_scores_every_preference_with_no_regret():
    optimal = np.stack([ceiling.optimal_for(front(), w) for w in ceiling.TRANSFER_PREFERENCES])
    assert ceiling.scores(optimal, front(), ceiling.TRANSFER_PREFERENCES) == {"optimal": 19, "on_front": 19,
                                                                               "regret": 0.0}


def test_an_off_front_return_counts_nowhere_and_its_regret_is_the_scalarised_gap():
    w = np.array([[0.5, 0.5]])
    score = ceiling.scores([[15.1, -8.0]], front(), w)
    assert (score["optimal"], score["on_front"]) == (0, 0)
    np.testing.assert_allclose(score["regret"], 0.5, atol=1e-5)


def test_the_best_expert_behaviour_misses_only_the_three_preferences_whose_optimum_no_expert_showed():
    references = ceiling.expert_references(EXPERT_PREFERENCES, expert_returns(EXPERT_PREFERENCES),
                                           ceiling.TRANSFER_PREFERENCES)
    best = ceiling.scores(references["best expert behaviour"], front(), ceiling.TRANSFER_PREFERENCES)
    # 8.2 at 3 steps is optimal at w1 = 0.35, 0.3, 0.25; the best shown behaviours there (15.1/-7, 15.1/-7,
    # 0.7/-1) fall short by 0.185, 0.73 and 0.375.
    assert best["optimal"] == 16 and best["on_front"] == 19
    np.testing.assert_allclose(best["regret"], (0.185 + 0.73 + 0.375) / 19, atol=1e-5)
    nearest = references["nearest expert's behaviour"]
    np.testing.assert_allclose(nearest[0], [23.7, -23.0], atol=1e-5)  # [0.95, 0.05]: the [0.9, 0.1] expert's
    np.testing.assert_allclose(nearest[8], [15.1, -7.0], atol=1e-5)  # [0.55, 0.45]: the [0.5, 0.5] expert's
    np.testing.assert_allclose(nearest[-1], [0.7, -1.0], atol=1e-5)  # [0.05, 0.95]: the [0.1, 0.9] expert's


def test_the_script_scores_each_run_of_a_transfer_csv(tmp_path):
    path = tmp_path / "transfer.csv"
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=["method", "seed", "preference", "vector_return"])
        writer.writeheader()
        for w in ceiling.TRANSFER_PREFERENCES:
            writer.writerow({"method": "always 0.7", "seed": 3, "preference": list(w), "vector_return": [0.7, -1.0]})
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "cdst_transfer_ceiling.py"), "--transfer",
                          str(path)], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout
    line = next(x for x in out.splitlines() if x.strip().startswith("always 0.7, seed 3"))
    assert "4 optimal, 19 on the front" in line  # 0.7/-1 is optimal at w1 = 0.2 ... 0.05

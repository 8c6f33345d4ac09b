"""`moiq sweep --preference-sets` and `moiq eval --preferences` through the real console script."""

import json
import shutil
import subprocess

import numpy as np
import pytest

import moiq_jax
from moiq_jax.evaluate import hypervolume
from moiq_jax.preferences import preference_sweep

MOIQ = shutil.which("moiq")
pytestmark = pytest.mark.skipif(MOIQ is None, reason="the package is not installed (pip install -e .)")
SMALL = ["--total-steps", "600", "--eval-interval", "300", "--hidden-sizes", "8", "8", "--batch-size", "8",
         "--learning-starts", "50", "--buffer-size", "600", "--num-demos", "1"]


def moiq(*args):
    return subprocess.run([MOIQ, *args], check=False, capture_output=True, text=True, timeout=300)


def test_sweep_over_preference_sets_writes_one_directory_per_set_and_seed(tmp_path):
    out = moiq("sweep", "--preference-sets", "0.9,0.1 0.1,0.9", "0.2,0.8 0.8,0.2", *SMALL, "--out", str(tmp_path / "s"))
    assert out.returncode == 0, out.stderr
    runs = sorted(p.name for p in (tmp_path / "s").iterdir() if (p / "metrics.csv").exists())
    assert runs == ["beta0.5-set0-seed0", "beta0.5-set1-seed0"]
    for name, labels in (("beta0.5-set0-seed0", [[0.9, 0.1], [0.1, 0.9]]), ("beta0.5-set1-seed0", [[0.2, 0.8], [0.8, 0.2]])):
        assert json.loads((tmp_path / "s" / name / "config.json").read_text())["preferences"] == labels
    assert "set 0 ['[0.9, 0.1]', '[0.1, 0.9]']" in out.stdout and "set 1 ['[0.2, 0.8]', '[0.8, 0.2]']" in out.stdout


def test_sets_of_different_sizes_and_unmatched_demos_are_clear_errors(tmp_path):
    out = moiq("sweep", "--preference-sets", "0.9,0.1 0.1,0.9", "0.9,0.1 0.5,0.5 0.1,0.9", "--out", str(tmp_path / "a"))
    assert out.returncode == 2 and "same number of experts" in out.stderr and "[2, 3]" in out.stderr
    out = moiq("sweep", "--preference-sets", "0.9,0.1 0.1,0.9", "0.2,0.8 0.8,0.2", "--demos", "a.npz",
               "--out", str(tmp_path / "b"))
    assert out.returncode == 2 and "2 preference sets need one demonstrations file each, got 1" in out.stderr


def test_eval_at_any_preferences_writes_regret_front_and_hypervolume(tmp_path):
    run_dir = tmp_path / "run"
    out = moiq("train", *SMALL, "--no-progress", "--run-dir", str(run_dir))
    assert out.returncode == 0, out.stderr
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    for given, expected in ((["19"], preference_sweep(19)), (["0.7,0.3", "0.3,0.7"], [[0.7, 0.3], [0.3, 0.7]])):
        out = moiq("eval", str(run_dir), "--preferences", *given)
        assert out.returncode == 0, out.stderr
        t = json.loads((run_dir / "transfer.json").read_text())
        preferences, returns = np.array(t["preferences"]), np.array(t["returns"])
        np.testing.assert_allclose(preferences, expected, atol=1e-6)
        optimum = front[np.argmax(preferences @ front.T, axis=1)]
        np.testing.assert_allclose(t["regret"], np.sum(preferences * (optimum - returns), axis=1), atol=1e-5)
        assert t["optimal"] == sum(t["pareto_optimal"]) == int(np.sum(np.array(t["regret"]) <= 1e-3))
        assert t["hypervolume"] == pytest.approx(hypervolume(returns, front.min(0) - 1.0))
        traced = np.array(t["front"])  # the returns' non-dominated ones
        assert all(any(np.all(r <= p) for p in traced) for r in returns)
    assert f"transfer: {t['optimal']} of 2 swept preferences" in out.stdout
    out = moiq("eval", str(run_dir), "--preferences", "many")
    assert out.returncode == 2 and "--preferences: a count like 19 or vectors like 0.9,0.1" in out.stderr
    out = moiq("plot", str(run_dir))
    assert out.returncode == 0, out.stderr
    assert (run_dir / "transfer_run.png").stat().st_size > 0


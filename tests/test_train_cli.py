"""`moiq train` through the real console script: kill, resume, divergence and bad input."""

import json
import os
import shutil
import signal
import subprocess
import time

import jax
import numpy as np
import pytest

import moiq_jax
from moiq_jax.algos.offpolicy import make_trainer
from moiq_jax.checkpoint import Checkpoints
from moiq_jax.config import tuned
from moiq_jax.train import algorithm_of

MOIQ = shutil.which("moiq")
pytestmark = pytest.mark.skipif(MOIQ is None, reason="the package is not installed (pip install -e .)")

# Eight chunks of 300 env steps; tiny networks so that compilation dominates.
SMALL = {"total_steps": 2400, "eval_interval": 300, "hidden_sizes": (8, 8), "batch_size": 8, "learning_starts": 60,
         "buffer_size": 2400}
FLAGS = [*(arg for name, value in SMALL.items() for arg in ("--" + name.replace("_", "-"), *map(str, np.atleast_1d(value)))),
         "--no-progress"]


def latest_state(run_dir, config):
    like = jax.jit(make_trainer(config, algorithm_of(config)).init)(jax.random.PRNGKey(config.seed))
    checkpoints = Checkpoints(os.path.join(run_dir, "checkpoints"))
    try:
        return checkpoints.latest_step(), checkpoints.restore(like)[0]
    finally:
        checkpoints.close()


def test_a_killed_run_resumes_to_the_same_result(tmp_path):
    config = tuned("cdst", **SMALL)  # what the CLI builds from the flags
    reference_dir = tmp_path / "reference"
    moiq_jax.train(config, run_dir=str(reference_dir), log=None)

    run_dir = tmp_path / "killed"
    process = subprocess.Popen([MOIQ, "train", *FLAGS, "--run-dir", str(run_dir)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    latest = run_dir / "checkpoints" / "latest"
    deadline = time.time() + 240
    while time.time() < deadline and process.poll() is None:
        steps = [int(p.name) for p in latest.iterdir() if p.name.isdigit()] if latest.exists() else []
        if any(s > 0 for s in steps):
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    killed_at, _ = latest_state(run_dir, config)
    assert 0 < killed_at < config.offpolicy.total_steps, f"the run was not stopped mid-way (last checkpoint {killed_at})"

    out = subprocess.run([MOIQ, "train", "--resume", str(run_dir), "--no-progress"], check=False,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "returns per preference" in out.stdout

    # Same metrics, row for row, and the same final training state, bit for bit.
    assert (run_dir / "metrics.csv").read_text() == (reference_dir / "metrics.csv").read_text()
    step_a, reference = latest_state(reference_dir, config)
    step_b, resumed = latest_state(run_dir, config)
    assert step_a == step_b == config.offpolicy.total_steps
    for a, b in zip(jax.tree.leaves(reference), jax.tree.leaves(resumed)):
        if jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key):
            a, b = jax.random.key_data(a), jax.random.key_data(b)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    # `moiq eval` restores the best parameters and evaluates the experts' and the 19 swept preferences.
    out = subprocess.run([MOIQ, "eval", str(run_dir)], check=False, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    transfer = json.loads((run_dir / "transfer.json").read_text())
    preferences, returns = np.array(transfer["preferences"]), np.array(transfer["returns"])
    assert preferences.shape == returns.shape == (3 + 19, 2)
    front = moiq_jax.envs.make("cdst").unwrapped.pareto_front()
    optimal = [bool(w @ r >= (front @ w).max() - 1e-3) for w, r in zip(preferences, returns)]
    assert transfer["pareto_optimal"] == optimal
    assert f"transfer: {sum(optimal[3:])} of 19 swept preferences" in out.stdout


def test_divergence_stops_with_the_step_and_keeps_the_last_good_checkpoint(tmp_path):
    run_dir = tmp_path / "nan"
    out = subprocess.run([MOIQ, "train", *FLAGS, "--critic-lr", "1e8", "--actor-lr", "1e8", "--run-dir", str(run_dir)],
                         check=False, capture_output=True, text=True, timeout=300)
    assert out.returncode == 3
    assert "training diverged: non-finite" in out.stderr and "critic_loss" in out.stderr
    assert "env step 300; the last good checkpoint is at env step 0" in out.stderr
    step, state = latest_state(run_dir, tuned("cdst", **SMALL, critic_lr=1e8, actor_lr=1e8))
    assert step == 0
    assert all(np.all(np.isfinite(x)) for x in jax.tree.leaves(state.learner.params))


def test_a_rerun_loads_its_programs_from_the_compilation_cache(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}

    def train(name, cache):
        out = subprocess.run([MOIQ, "train", *FLAGS, "--total-steps", "600", "--run-dir", str(tmp_path / name)],
                             env={**env, "HOME": str(tmp_path / "home"), "MOIQ_COMPILATION_CACHE": cache},
                             check=False, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        return (tmp_path / name / "metrics.csv").read_text()

    cache = tmp_path / "xla"
    first = train("first", str(cache))
    entries = sorted(p.name for p in cache.iterdir())
    assert any(name.endswith("-cache") for name in entries)  # the first run stored its programs
    assert train("second", str(cache)) == first
    assert sorted(p.name for p in cache.iterdir()) == entries  # the rerun compiled nothing new to store
    train("off", "")  # an empty MOIQ_COMPILATION_CACHE: no cache, not even the default folder
    assert not (tmp_path / "home" / ".cache" / "moiq_jax").exists()


def moiq(*args):
    return subprocess.run([MOIQ, *args], check=False, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--env", "hopper"], "unknown env 'hopper'; known envs:"),
        (["--algo", "airl"], "unknown algo 'airl'"),
        (["--preferences", "0.9,0.1,0.0"], "each preference needs 2 weights"),
        (["--preferences", "0.9,0.2"], "must sum to 1"),
        (["--preferences", "1.5,-0.5"], "non-negative"),
        (["--beta", "-1"], "beta must be non-negative"),
        (["--demos", "missing.npz"], "demos file 'missing.npz' does not exist"),
        (["--env-backend", "mjx"], "env_backend 'mjx' is not a backend of 'cdst' (none: it is pure JAX)"),
        (["--env", "mo-hopper", "--env-backend", "brax"], "env_backend 'brax' is not a backend of 'mo-hopper' (mujoco"),
        (["--algo", "admm", "--env", "dst", "--infer-preferences", "--preference-rule", "nearest"],
         "unknown preference_rule 'nearest'"),
    ],
)
def test_bad_input_is_a_clear_error(args, message, tmp_path):
    out = moiq("train", *args, "--run-dir", str(tmp_path / "run"))
    assert out.returncode == 2, out.stderr
    assert message in out.stderr


def test_an_existing_run_dir_needs_resume(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{}")
    out = moiq("train", "--run-dir", str(tmp_path / "run"))
    assert out.returncode == 2
    assert "already exists; continue it with `moiq train --resume" in out.stderr

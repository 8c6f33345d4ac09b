"""A sweep survives a crash: `moiq sweep` killed with SIGKILL and continued by `moiq sweep --resume` ends bit
for bit where an uninterrupted sweep does; so does ``moiq_jax.sweep(..., run_dir, resume=True)``; and a
directory or arguments that do not fit are clear errors."""

import fcntl
import os
import shutil
import signal
import subprocess
import time

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import moiq_jax
from moiq_jax.checkpoint import Checkpoints
from moiq_jax.cli import main
from moiq_jax.config import tuned
from moiq_jax.train import ALGORITHMS, make_trainer

MOIQ = shutil.which("moiq")

# Eight chunks of 300 env steps; tiny networks so that compilation dominates.
SMALL = {"total_steps": 2400, "eval_interval": 300, "hidden_sizes": (8, 8), "batch_size": 8, "learning_starts": 60,
         "buffer_size": 2400}
FLAGS = [arg for name, value in SMALL.items() for arg in ("--" + name.replace("_", "-"), *map(str, np.atleast_1d(value)))]
SWEEP = ["--betas", "0", "5", "--seeds", "2"]
RUNS = ["beta0-seed0", "beta0-seed1", "beta5-seed0", "beta5-seed1"]


def moiq(*args):
    return subprocess.run([MOIQ, *args], check=False, capture_output=True, text=True, timeout=300)


def table(stdout: str, out_dir) -> str:
    """The final table `moiq sweep` prints, with its directory taken out."""
    return stdout[stdout.index("runs; scalarised returns"):].replace(str(out_dir), "OUT")


def final_state(out_dir, config):
    """The newest checkpoint of a sweep directory: its step and the state of all four runs."""
    trainer = make_trainer(config, ALGORITHMS["moiq"])
    setup = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 4), trainer.setup)
    like = jax.jit(jax.vmap(trainer.init))(jnp.zeros((4, 2), jnp.uint32), setup)
    checkpoints = Checkpoints(os.path.join(out_dir, "checkpoints"))
    try:
        return checkpoints.latest_step(), checkpoints.restore(like)[0]
    finally:
        checkpoints.close()


@pytest.mark.skipif(MOIQ is None, reason="the package is not installed (pip install -e .)")
def test_a_killed_sweep_resumes_to_the_same_result(tmp_path):
    reference = moiq("sweep", *SWEEP, *FLAGS, "--out", str(tmp_path / "reference"))
    assert reference.returncode == 0, reference.stderr

    # The sweep is held right after its first chunk's checkpoint: its stdout is a pipe of one page that this
    # test fills but for the first line, so the sweep blocks printing the first chunk's line; then it is killed.
    out_dir = tmp_path / "killed"
    read, write = os.pipe()
    fcntl.fcntl(write, fcntl.F_SETPIPE_SZ, 4096)
    os.write(write, b"." * (fcntl.fcntl(write, fcntl.F_GETPIPE_SZ) - len(f"sweep directory: {out_dir}\n") - 8))
    process = subprocess.Popen([MOIQ, "sweep", *SWEEP, *FLAGS, "--out", str(out_dir)], stdout=write,
                               stderr=subprocess.DEVNULL)
    os.close(write)
    first = out_dir / "checkpoints" / "latest" / str(SMALL["eval_interval"])
    deadline = time.time() + 300
    while time.time() < deadline and process.poll() is None and not first.exists():
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    os.close(read)
    config = tuned("cdst", **SMALL)
    killed_at, _ = final_state(out_dir, config)
    assert killed_at == SMALL["eval_interval"], f"the sweep was not stopped after its first chunk ({killed_at})"

    resumed = moiq("sweep", "--resume", str(out_dir))
    assert resumed.returncode == 0, resumed.stderr
    assert table(resumed.stdout, out_dir) == table(reference.stdout, tmp_path / "reference")
    # The same run directories, with the same config and metrics row for row ...
    for run in RUNS:
        for name in ("config.json", "metrics.csv"):
            assert (out_dir / run / name).read_text() == (tmp_path / "reference" / run / name).read_text(), (run, name)
    rows = (out_dir / "beta5-seed1" / "metrics.csv").read_text().splitlines()
    assert len(rows) == 1 + 8 * 3  # a header, then 8 evaluations x 3 experts, each once
    # ... and the same final state of every run (parameters, optimisers, buffers, keys), bit for bit.
    step_a, a = final_state(tmp_path / "reference", config)
    step_b, b = final_state(out_dir, config)
    assert step_a == step_b == SMALL["total_steps"]
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


class Crash(Exception):
    pass


def test_a_sweep_cut_after_a_chunk_resumes_in_python(tmp_path):
    config = tuned("cdst", **{**SMALL, "total_steps": 1200})  # four chunks
    values = {"beta": [0.0, 5.0], "seed": [1]}

    def crash_after_two_chunks(line):
        if "steps 600:" in line:
            raise Crash

    run_dir = str(tmp_path / "sweep")
    with pytest.raises(Crash):
        moiq_jax.sweep(config, run_dir=run_dir, log=crash_after_two_chunks, **values)
    with pytest.raises(ValueError, match="already holds a sweep; continue it with resume=True"):
        moiq_jax.sweep(config, run_dir=run_dir, log=None, **values)
    with pytest.raises(ValueError, match=r"holds a sweep of other swept values \(saved \{'beta': \[0.0, 5.0\]"):
        moiq_jax.sweep(config, run_dir=run_dir, resume=True, log=None, beta=[0.0, 1.0], seed=[1])
    with pytest.raises(ValueError, match="holds a sweep of other config .*total_steps: saved 1200, given 2400"):
        moiq_jax.sweep(config.replace(total_steps=2400), run_dir=run_dir, resume=True, log=None, **values)
    lines = []
    resumed = moiq_jax.sweep(config, run_dir=run_dir, resume=True, log=lines.append, **values)
    assert [line.split("]")[1].split(":")[0] for line in lines] == [" steps 900", " steps 1200"]  # two chunks left
    whole = moiq_jax.sweep(config, run_dir=str(tmp_path / "whole"), log=None, **values)  # uninterrupted
    for name in whole.history:
        assert resumed.history[name].dtype == whole.history[name].dtype, name
        np.testing.assert_array_equal(resumed.history[name], whole.history[name], err_msg=name)
    assert resumed.history["eval_return"].shape == (2, 4, 3, 2)  # runs, evaluations, experts, objectives
    for x, y in zip(jax.tree.leaves((resumed.final_params, resumed.best_params, resumed.best_return)),
                    jax.tree.leaves((whole.final_params, whole.best_params, whole.best_return))):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    np.testing.assert_array_equal(resumed.runs["beta"], [0.0, 5.0])


def test_a_sweep_resumes_from_its_demonstrations_moved_but_not_from_others(tmp_path):
    """A cut sweep continues with its demonstrations file at another path (another checkout), and is refused with
    a file of other demonstrations at the saved path's name."""
    preferences = ((0.9, 0.1), (0.1, 0.9))
    first = tmp_path / "checkout_a" / "d.npz"
    first.parent.mkdir()
    demos = moiq_jax.experts.oracle_demonstrations("cdst", preferences, num_demos=2, seed=0)
    demos.save(first)
    config = tuned("cdst", **{**SMALL, "total_steps": 600}, preferences=preferences, num_demos=2, demos=str(first))
    run_dir = str(tmp_path / "sweep")

    def crash_after_one_chunk(line):
        if "steps 300:" in line:
            raise Crash

    with pytest.raises(Crash):
        moiq_jax.sweep(config, run_dir=run_dir, log=crash_after_one_chunk, seed=[0])
    moved = tmp_path / "checkout_b" / "d.npz"
    moved.parent.mkdir()
    shutil.copy(first, moved)
    other = tmp_path / "checkout_c" / "d.npz"
    other.parent.mkdir()
    swapped = jax.tree.map(lambda x: x[::-1], demos)  # each expert's episodes under the other's preference
    swapped.replace(preferences=demos.preferences).save(other)
    with pytest.raises(ValueError, match="holds a sweep of other demonstrations"):
        moiq_jax.sweep(config.replace(demos=str(other)), run_dir=run_dir, resume=True, log=None, seed=[0])
    lines = []
    resumed = moiq_jax.sweep(config.replace(demos=str(moved)), run_dir=run_dir, resume=True, log=lines.append,
                             seed=[0])
    assert [line.split("]")[1].split(":")[0] for line in lines] == [" steps 600"]  # the one chunk left
    assert resumed.history["env_steps"][0, -1] == 600


def test_resume_errors_are_clear(tmp_path, capsys):
    def error(*args):
        assert main(list(args)) == 2
        return capsys.readouterr().err

    assert "is not a sweep directory (no sweep.json" in error("sweep", "--resume", str(tmp_path))
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "config.json").write_text("{}")
    assert ("is a run of `moiq train`; continue it with `moiq train --resume"
            in error("sweep", "--resume", str(tmp_path / "run")))
    (tmp_path / "sweep").mkdir()
    (tmp_path / "sweep" / "sweep.json").write_text("{}")
    assert ("--resume continues the sweep's saved config and swept values; drop ['--total-steps', '--betas']"
            in error("sweep", "--resume", str(tmp_path / "sweep"), "--betas", "1", "--total-steps", "600"))
    assert "already exists; continue it with `moiq sweep --resume" in error("sweep", "--out", str(tmp_path / "sweep"))
    message = error("train", "--resume", str(tmp_path / "sweep"))
    assert "is a sweep directory" in message and "moiq sweep --resume" in message
    with pytest.raises(ValueError, match="resume=True continues the sweep saved in run_dir; give run_dir"):
        moiq_jax.sweep(tuned("cdst"), resume=True, seed=[0])
    with pytest.raises(ValueError, match="is not a sweep directory"):
        moiq_jax.sweep(tuned("cdst", **SMALL), run_dir=str(tmp_path / "run"), resume=True, seed=[0])

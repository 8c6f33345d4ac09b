"""Run infrastructure: orbax checkpoints, the run log, and configs from files and flags."""

import argparse
import csv
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from moiq_jax import Config
from moiq_jax.checkpoint import Checkpoints
from moiq_jax.cli import add_config_flags, config_from_args
from moiq_jax.config import tuned
from moiq_jax.runlog import RunLog


def test_checkpoints_round_trip_state_and_keep_the_newest(tmp_path):
    checkpoints = Checkpoints(tmp_path / "ckpt", keep=2)
    state = {"w": jnp.arange(6.0).reshape(2, 3), "key": jax.random.key(3), "count": jnp.int32(0)}
    for step in (10, 20, 30):
        checkpoints.save(step, {**state, "count": jnp.int32(step)}, {"chunk": step // 10, "history": [1.5, 2.5]})
    assert checkpoints.latest_step() == 30
    assert sorted(int(p.name) for p in (tmp_path / "ckpt" / "latest").iterdir() if p.name.isdigit()) == [20, 30]
    restored, meta = checkpoints.restore(state)
    np.testing.assert_array_equal(restored["w"], state["w"])
    assert int(restored["count"]) == 30 and meta == {"chunk": 3, "history": [1.5, 2.5]}
    np.testing.assert_array_equal(jax.random.key_data(restored["key"]), jax.random.key_data(state["key"]))
    # The restored key draws the same numbers.
    assert float(jax.random.uniform(restored["key"])) == float(jax.random.uniform(state["key"]))
    checkpoints.save_best(20, {"p": jnp.ones(3)}, {"return": 4.5})
    params, meta = checkpoints.restore_best({"p": jnp.zeros(3)})
    np.testing.assert_array_equal(params["p"], np.ones(3))
    assert meta == {"return": 4.5}
    checkpoints.close()


def test_checkpoints_keep_zero_size_arrays(tmp_path):
    """MJX states hold empty arrays (``act`` of a model without activations), which orbax cannot write."""
    checkpoints = Checkpoints(tmp_path / "ckpt")
    state = {"act": jnp.zeros((4, 0)), "qpos": jnp.arange(3.0), "nested": {"empty": jnp.zeros((0,), jnp.int32)}}
    checkpoints.save(5, state, {"chunk": 1})
    checkpoints.save_best(5, state, {})
    for restored, _ in (checkpoints.restore(state), checkpoints.restore_best(state)):
        assert restored["act"].shape == (4, 0) and restored["nested"]["empty"].dtype == jnp.int32
        np.testing.assert_array_equal(restored["qpos"], state["qpos"])
    checkpoints.close()


def test_restore_without_checkpoint_is_a_clear_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint to resume"):
        Checkpoints(tmp_path / "empty").restore({"w": jnp.zeros(2)})


def test_run_log_writes_config_csv_and_tensorboard_and_resumes_cleanly(tmp_path):
    config = Config(preferences=[[0.9, 0.1], [0.1, 0.9]])
    metrics = {"eval_vector_return": np.array([[1.0, -2.0], [3.0, -4.0]]), "alpha": np.array([0.1, 0.2]), "loss": 7.0}
    run = RunLog(tmp_path, config, total_steps=30, progress=False)
    for step in (10, 20, 30):
        run.log(step, {**metrics, "loss": float(step)})
    run.close()
    assert json.loads((tmp_path / "config.json").read_text())["preferences"] == [[0.9, 0.1], [0.1, 0.9]]
    rows = read_rows(tmp_path / "metrics.csv")
    assert len(rows) == 6
    assert rows[1] == {"env_steps": "10", "expert": "1", "preference": "0.1 0.9", "alpha": "0.2",
                       "eval_vector_return_0": "3.0", "eval_vector_return_1": "-4.0", "loss": "10.0"}
    assert list((tmp_path / "tensorboard").iterdir())
    # Resuming from step 20 drops the rows of step 30, then appends without a second header.
    run = RunLog(tmp_path, config, total_steps=30, resume_step=20, progress=False)
    run.log(30, {**metrics, "loss": 99.0})
    run.close()
    rows = read_rows(tmp_path / "metrics.csv")
    assert [r["env_steps"] for r in rows] == ["10", "10", "20", "20", "30", "30"]
    assert rows[-1]["loss"] == "99.0"
    # A resumed run that logs a new metric: one header over all rows, the earlier rows' cells empty.
    run = RunLog(tmp_path, config, total_steps=40, resume_step=30, progress=False)
    run.log(40, {**metrics, "adopted_from": np.array([-1, 0])})
    run.close()
    rows = read_rows(tmp_path / "metrics.csv")
    assert [r["env_steps"] for r in rows] == ["10", "10", "20", "20", "30", "30", "40", "40"]
    assert [r["adopted_from"] for r in rows] == [""] * 6 + ["-1.0", "0.0"]
    assert rows[-1]["loss"] == "7.0" and rows[-1]["eval_vector_return_1"] == "-4.0"
    # Later rows go under that header by name, although their own columns come in another order.
    run = RunLog(tmp_path, config, total_steps=50, resume_step=40, progress=False)
    run.log(50, {**metrics, "loss": 8.0, "adopted_from": np.array([1, -1])})
    run.close()
    header, *_ = (tmp_path / "metrics.csv").read_text().splitlines()
    assert header.split(",")[-1] == "adopted_from"
    rows = read_rows(tmp_path / "metrics.csv")
    assert [(r["env_steps"], r["adopted_from"], r["loss"]) for r in rows[-4:]] == [
        ("40", "-1.0", "7.0"), ("40", "0.0", "7.0"), ("50", "1.0", "8.0"), ("50", "-1.0", "8.0")]


def read_rows(path):
    return list(csv.DictReader(path.read_text().splitlines()))


def parse(*argv):
    parser = argparse.ArgumentParser()
    add_config_flags(parser)
    return config_from_args(parser.parse_args(list(argv)))


def test_flags_set_config_fields_and_override_a_config_file(tmp_path):
    cfg = parse("--beta", "3", "--preferences", "0.9,0.1", "0.1,0.9", "--no-learn-alpha", "--hidden-sizes", "64", "64")
    assert cfg == tuned("cdst", beta=3.0, preferences=((0.9, 0.1), (0.1, 0.9)), learn_alpha=False, hidden_sizes=(64, 64))
    assert parse().offpolicy.hidden_sizes == tuned("cdst").offpolicy.hidden_sizes  # the CLI starts from the env's tuned settings
    (tmp_path / "run.yaml").write_text("env: dst-mini\nalgo: admm\nrounds: 4\npreferences: [[0.9, 0.1], [0.1, 0.9]]\n")
    cfg = parse("--config", str(tmp_path / "run.yaml"), "--rounds", "6")
    assert (cfg.env, cfg.algo, cfg.admm.rounds, cfg.preferences) == ("dst-mini", "admm", 6, ((0.9, 0.1), (0.1, 0.9)))
    (tmp_path / "run.json").write_text(json.dumps({"beta": 0.0}))
    assert parse("--config", str(tmp_path / "run.json")).moiq.beta == 0.0
    cfg = parse("--env-backend", "mujoco", "--ppo-iterations", "3")
    assert cfg.env_backend == "mujoco" and cfg.admm.ppo.iterations == 3
    assert parse("--adopt-margin", "0.1").offpolicy.adopt_margin == 0.1 and parse().offpolicy.adopt_margin is None


def test_bad_config_files_name_the_problem(tmp_path):
    (tmp_path / "bad.json").write_text(json.dumps({"betta": 1.0}))
    with pytest.raises(ValueError, match=r"unknown fields \['betta'\]"):
        parse("--config", str(tmp_path / "bad.json"))
    with pytest.raises(ValueError, match="does not exist"):
        parse("--config", str(tmp_path / "missing.yaml"))

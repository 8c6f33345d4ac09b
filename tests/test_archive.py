"""Saved results: a sweep's runs saved one by one, read back and joined, equal the sweep (parameters, history,
swept values) and evaluate to the same returns; joining runs of different sweeps, or unfinished ones, is a
clear error."""

import os
import pathlib
import sys

import jax
import numpy as np
import pytest

import moiq_jax
from moiq_jax.archive import PARAMS_FILE, PER_EXPERT_FILE, RESULT_FILE, load_result, save_result, stack_results
from moiq_jax.config import tuned
from moiq_jax.runtime import host_description

ROOT = pathlib.Path(__file__).resolve().parents[1]
SMALL = {"total_steps": 600, "eval_interval": 300, "hidden_sizes": (8, 8), "batch_size": 8, "learning_starts": 60,
         "buffer_size": 600}


@pytest.fixture(scope="module")
def sweep():
    return moiq_jax.sweep(tuned("cdst", **SMALL), beta=[0.0, 5.0], seed=[0, 3])


def test_saved_runs_join_into_the_sweep(sweep, tmp_path):
    for i in range(4):
        save_result(sweep.run(i), tmp_path / f"run{i}")
    loaded = [load_result(tmp_path / f"run{i}") for i in range(4)]
    assert loaded[2].config == sweep.run(2).config and loaded[2].config.moiq.beta == 5.0 and loaded[3].config.seed == 3
    joined = stack_results(loaded)
    np.testing.assert_array_equal(joined.runs["beta"], sweep.runs["beta"])
    np.testing.assert_array_equal(joined.runs["seed"], sweep.runs["seed"])
    for x, y in zip(jax.tree.leaves(joined.best_params), jax.tree.leaves(sweep.best_params)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert joined.best_params.action_scale == sweep.best_params.action_scale
    for name, values in sweep.history.items():
        np.testing.assert_array_equal(joined.history[name], values, err_msg=name)
        assert joined.history[name].dtype == np.asarray(values).dtype, name
    np.testing.assert_array_equal(joined.best_return, sweep.best_return)
    np.testing.assert_array_equal(joined.best_return_per_expert, sweep.best_return_per_expert)
    for x, y in zip(jax.tree.leaves(joined.best_actor_per_expert), jax.tree.leaves(sweep.best_actor_per_expert)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    np.testing.assert_array_equal(joined.preferences, sweep.preferences)
    prefs = sweep.config.preferences
    np.testing.assert_allclose(moiq_jax.evaluate(joined.run(3).best_params, "cdst", prefs),
                               moiq_jax.evaluate(sweep.run(3).best_params, "cdst", prefs))
    # a whole sweep saves and loads with its run axis too
    save_result(sweep, tmp_path / "sweep")
    whole = load_result(tmp_path / "sweep")
    assert whole.config == sweep.config
    np.testing.assert_array_equal(whole.runs["beta"], sweep.runs["beta"])
    np.testing.assert_array_equal(whole.history["eval_return"], sweep.history["eval_return"])


def test_joining_other_sweeps_or_unfinished_runs_is_an_error(sweep, tmp_path):
    run = sweep.run(0)
    other = run.__class__(**{**run.__dict__, "config": run.config.replace(critic_lr=1e-3)})
    with pytest.raises(ValueError, match="run 1 is not of the same sweep as run 0: its config differs in critic_lr"):
        stack_results([run, other])
    short = run.__class__(**{**run.__dict__, "history": {k: v[:1] for k, v in run.history.items()}})
    with pytest.raises(ValueError, match="run 1 has other evaluations than run 0"):
        stack_results([run, short])
    with pytest.raises(ValueError, match="joins single runs"):
        stack_results([sweep])
    # a run saved before each expert's best actor was kept joins others without that reading
    older = run.__class__(**{**run.__dict__, "best_actor_per_expert": None, "best_return_per_expert": None})
    save_result(older, tmp_path / "older")
    assert not (tmp_path / "older" / PER_EXPERT_FILE).exists()
    joined = stack_results([load_result(tmp_path / "older"), sweep.run(1)])
    assert joined.best_actor_per_expert is None and joined.best_return_per_expert is None
    assert stack_results([sweep.run(0), sweep.run(1)]).best_return_per_expert.shape == (2, 3)
    with pytest.raises(FileNotFoundError, match="holds no saved result"):
        load_result(tmp_path)
    # a save cut before its record is written leaves no result behind
    save_result(run, tmp_path / "cut")
    (tmp_path / "cut" / RESULT_FILE).unlink()
    assert (tmp_path / "cut" / PARAMS_FILE).exists()
    with pytest.raises(FileNotFoundError):
        load_result(tmp_path / "cut")
    admm = moiq_jax.train(tuned("dst", algo="admm", rounds=1))
    with pytest.raises(TypeError, match="admm.s has no network parameters"):
        save_result(admm, tmp_path / "admm")


def test_compare_runs_tells_a_rerun_from_another_run(sweep, tmp_path):
    """experiments/compare_runs.py: a run saved twice is the same run bit for bit; another seed differs in its
    config, history and best model by the amounts numpy finds; a history changed at one evaluation is found there."""
    sys.path.insert(0, str(ROOT / "experiments"))
    from compare_runs import compare, report

    run = sweep.run(0)
    for name, result in (("a", run), ("b", run), ("seed3", sweep.run(1))):
        save_result(result, tmp_path / name)
        (tmp_path / name / "demos.sha256").write_text("abc123  demos.npz\n")
    same = compare(tmp_path / "a", tmp_path / "b")
    assert same["hosts"] == [host_description()] * 2 and f"host: {host_description()}\n" in report(same)
    assert same["config_differs_in"] == [] and same["same_demonstrations"]
    assert same["metrics_differing"] == {} and same["first_differing_evaluation"] is None
    assert same["metrics_identical"] == sorted(run.history)
    assert same["best_model_identical"] and same["best_model_largest_difference"] == 0.0 and same["each_best_identical"]

    other = compare(tmp_path / "a", tmp_path / "seed3")
    assert sweep.run(1).config.seed == 3 and other["config_differs_in"] == ["seed"]
    a, b = run.history["eval_scalar_return"], sweep.run(1).history["eval_scalar_return"]
    rows_differ = [i for i in range(len(a)) if not np.array_equal(a[i], b[i])]
    assert other["metrics_differing"]["eval_scalar_return"] == {
        "first_evaluation": rows_differ[0], "largest": pytest.approx(float(np.max(np.abs(a - b))), rel=1e-6)}
    assert not other["best_model_identical"] and other["each_best_identical"] is False
    leaves = zip(jax.tree.leaves(run.best_params), jax.tree.leaves(sweep.run(1).best_params))
    assert other["best_model_largest_difference"] == pytest.approx(max(float(np.max(np.abs(x - y))) for x, y in leaves))

    changed = {**run.history, "eval_scalar_return": run.history["eval_scalar_return"].copy()}
    changed["eval_scalar_return"][1, 0] += 1.0
    save_result(run.__class__(**{**run.__dict__, "history": changed}), tmp_path / "changed")
    moved = compare(tmp_path / "a", tmp_path / "changed")
    assert list(moved["metrics_differing"]) == ["eval_scalar_return"] and moved["best_model_identical"]
    assert moved["metrics_differing"]["eval_scalar_return"] == {"first_evaluation": 1, "largest": pytest.approx(1.0)}
    assert moved["first_differing_evaluation"]["env_steps"] == int(run.history["env_steps"][1])
    assert not moved["same_demonstrations"]  # "changed" has no digest file
    text = report(moved)
    assert "history differs in eval_scalar_return: from evaluation 2, by up to 1" in text
    assert f"first differing evaluation: 2 ({int(run.history['env_steps'][1]):,} env steps" in text


def test_host_description_names_the_cpu_and_its_vector_extensions():
    """The host a run is saved on: the first processor's model, family and model, and which of the vector
    extensions XLA may use it has, as /proc/cpuinfo lists them."""
    text = host_description()
    assert text.endswith(f", {os.cpu_count()} cores")
    if not os.path.exists("/proc/cpuinfo"):
        return
    block = pathlib.Path("/proc/cpuinfo").read_text().split("\n\n")[0]
    fields = {k.strip(): v.strip() for k, _, v in (line.partition(":") for line in block.splitlines())}
    assert text.startswith(f"{fields['model name']} (family {fields['cpu family']}, model {fields['model']}), ")
    flags = set(fields["flags"].split())
    for extension in ("avx512f", "avx2", "fma", "avx"):
        assert (f" {extension} " in text or f" {extension}," in text) == (extension in flags), extension

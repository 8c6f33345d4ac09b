"""Preferences keep their labels in any order: the same experts given ascending, descending and shuffled
train identically (the learner holds them in one canonical order, so the consensus penalty pairs the
same neighbours) and every expert's results are printed and written under its own preference."""

import csv

import numpy as np
import pytest

import moiq_jax
from moiq_jax.cli import _print_returns_against_experts
from moiq_jax.experts.loading import load_demonstrations, preference_order

TINY = moiq_jax.Config(total_steps=40, eval_interval=20, num_envs=2, learning_starts=10, batch_size=8,
                       hidden_sizes=(8,), buffer_size=64, num_demos=1, action_scale=2.5)
ORDERS = {"descending": ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9)),
          "ascending": ((0.1, 0.9), (0.5, 0.5), (0.9, 0.1)),
          "shuffled": ((0.5, 0.5), (0.1, 0.9), (0.9, 0.1))}


def label(w) -> str:
    return " ".join(f"{x:g}" for x in w)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = {}
    for name, preferences in ORDERS.items():
        config = TINY.replace(preferences=preferences)
        run_dir = tmp_path_factory.mktemp(name)
        result = moiq_jax.train(config, run_dir=str(run_dir), log=None)
        with open(run_dir / "metrics.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        out[name] = config, result, rows
    return out


def test_preference_order_is_descending_first_objective_first():
    np.testing.assert_array_equal(preference_order(ORDERS["shuffled"]), [2, 0, 1])
    demos = load_demonstrations(TINY.replace(preferences=ORDERS["ascending"]))
    np.testing.assert_allclose(demos.preferences, ORDERS["ascending"])
    assert demos.mean_returns()[2, 0] == pytest.approx(23.7)  # [0.9, 0.1]'s expert reaches the far treasure


def test_some_experts_of_a_demos_file_load_alone(tmp_path):
    path = str(tmp_path / "three.npz")
    load_demonstrations(TINY.replace(preferences=ORDERS["descending"])).save(path)
    every = load_demonstrations(TINY.replace(preferences=ORDERS["descending"], demos=path))
    some = load_demonstrations(TINY.replace(preferences=((0.1, 0.9), (0.9, 0.1)), demos=path))
    np.testing.assert_allclose(some.preferences, [[0.1, 0.9], [0.9, 0.1]])
    np.testing.assert_array_equal(some.actions, np.asarray(every.actions)[[2, 0]])
    np.testing.assert_array_equal(some.rewards, np.asarray(every.rewards)[[2, 0]])
    with pytest.raises(ValueError, match=r"the configured \(0.2, 0.8\) is not one of them"):
        load_demonstrations(TINY.replace(preferences=((0.9, 0.1), (0.2, 0.8)), demos=path))
    with pytest.raises(ValueError, match="name one of the demos in .* twice"):
        load_demonstrations(TINY.replace(preferences=((0.9, 0.1), (0.9, 0.1)), demos=path))


def test_metrics_csv_rows_are_the_same_under_the_same_labels(runs):
    by_label = {}
    for name, (config, result, rows) in runs.items():
        assert [r["preference"] for r in rows[:3]] == [label(w) for w in config.preferences]  # the config's order
        by_label[name] = {(r["env_steps"], r["preference"]): {k: v for k, v in r.items() if k != "expert"} for r in rows}
        np.testing.assert_allclose(result.preferences, config.preferences)
    assert by_label["ascending"] == by_label["descending"] == by_label["shuffled"]
    # the parameters' per-expert entries (learnt temperatures) follow the labels too
    alphas = {name: dict(zip(map(label, config.preferences), np.asarray(result.final_params.log_alpha).tolist()))
              for name, (config, result, _) in runs.items()}
    assert alphas["ascending"] == alphas["descending"] == alphas["shuffled"]
    assert len(set(alphas["ascending"].values())) == 3  # they differ per expert, so the check can see a swap
    # each row's scalarised return is its own vector return scalarised by its own label
    for config, _, rows in runs.values():
        for r in rows:
            w = [float(x) for x in r["preference"].split()]
            vector = [float(r["eval_return_0"]), float(r["eval_return_1"])]
            assert float(r["eval_scalar_return"]) == pytest.approx(np.dot(w, vector), abs=1e-4)


def test_printed_table_rows_are_the_same_under_the_same_labels(runs, capsys):
    tables = {}
    for name, (config, result, _) in runs.items():
        _print_returns_against_experts(config, result)
        lines = capsys.readouterr().out.splitlines()[2:]
        assert [line.split("]")[0].strip() + "]" for line in lines] == [
            "[" + ", ".join(f"{x:g}" for x in w) + "]" for w in config.preferences]
        tables[name] = sorted(lines)
    assert tables["ascending"] == tables["descending"] == tables["shuffled"]
    far = next(line for line in tables["ascending"] if line.strip().startswith("[0.9, 0.1]"))
    assert "23.70" in far  # the far treasure's expert is shown under its own preference

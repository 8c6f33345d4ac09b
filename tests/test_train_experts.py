"""experiments/train_experts.py end to end on mo-hopper at smoke size: a run cut by --time-limit, resumed from
its checkpoint with experts adopting between preferences, demonstrations recorded from the saved experts, and
the experts run in MO-Gymnasium by check_experts.py, each record consistent with the others."""

import json
import os
import pathlib
import subprocess
import sys

import numpy as np

from moiq_jax.experts import Demonstrations
from moiq_jax.runtime import host_description

ROOT = pathlib.Path(__file__).resolve().parents[1]


def train_experts(*args, script="train_experts.py"):
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / script), "--env", "mo-hopper", *args],
                         capture_output=True, text=True, timeout=600, env={**os.environ, "PYTHONPATH": str(ROOT)},
                         check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


def test_cut_resumed_adopting_run_then_demonstrations(tmp_path):
    run = ["--total-steps", "24", "--eval-interval", "8", "--num-envs", "8", "--updates-per-step", "1",
           "--learning-starts", "8", "--adopt-margin", "0", "--run-dir", str(tmp_path / "run"), "--out", str(tmp_path),
           "--no-demos"]
    first = train_experts(*run, "--time-limit", "0")
    assert "steps 8:" in first and "steps 16:" not in first  # cut after its first evaluation
    part = json.loads((tmp_path / "mo-hopper-training.json").read_text())
    resumed = train_experts(*run, "--resume")
    assert "steps 8:" not in resumed and "steps 24:" in resumed
    training = json.loads((tmp_path / "mo-hopper-training.json").read_text())
    history = training["history"]
    assert [steps[0] for steps in history["env_steps"]] == [8, 16, 24] and training["env_steps_per_expert"] == 24
    assert training["cpu_seconds"] > part["cpu_seconds"] and training["config"]["adopt_margin"] == 0.0
    assert part["hosts"] == training["hosts"] == [host_description()]  # both parts on this host, named once
    labels = [tuple(w) for w in training["config"]["preferences"]]
    preferences = np.asarray(labels)
    expected_lines = []
    best = np.maximum.accumulate(history["eval_scalar_return"], axis=0)  # each expert's best evaluation so far
    for returns, adopted, best_now in zip(history["eval_return"], history["adopted_from"], best):
        scores = preferences @ np.asarray(returns).T  # [preference i, expert j]
        # (the record rounds to 3 decimals: an expert's own latest score may show a hair above its best)
        expected = [int(np.argmax(row)) if np.argmax(row) != i and row.max() > best_now[i] + 1e-2 else -1
                    for i, row in enumerate(scores)]
        assert adopted == expected
        expected_lines += [f"  expert {labels[i]} continues from expert {labels[donor]}'s learner and replay"
                           for i, donor in enumerate(expected) if donor >= 0]
    assert expected_lines  # at margin 0 some expert beats another under its preference in a smoke run
    assert [line for line in (first + resumed).splitlines() if "continues from" in line] == expected_lines

    progress = subprocess.run([sys.executable, str(ROOT / "experiments" / "expert_progress.py"), str(tmp_path / "run")],
                              capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)},
                              check=True).stdout
    name = lambda w: "[" + ", ".join(f"{x:g}" for x in w) + "]"
    for i, w in enumerate(labels):  # each expert's row of its own scores, as the training record has them
        assert f"| {name(w)} | " + " | ".join(f"{s[i]:,.0f}" for s in history["eval_scalar_return"]) + " |" in progress
    moves = [f"- after {int(steps[0]):,} steps: {name(labels[expert])} continued from {name(labels[int(donor)])}"
             for steps, adopted in zip(history["env_steps"], history["adopted_from"])
             for expert, donor in enumerate(adopted) if donor >= 0]
    assert [line for line in progress.splitlines() if line.startswith("- after")] == moves

    recorded = train_experts("--record", "--num-demos", "2", "--out", str(tmp_path))
    demos = Demonstrations.load(tmp_path / "mo-hopper.npz")
    assert demos.obs.shape[:2] == (3, 2) and demos.env == "mo-hopper"
    experts = json.loads((tmp_path / "mo-hopper-experts.json").read_text())["experts"]
    for expert, w, ret in zip(experts, preferences, demos.mean_returns()):
        assert expert["scalar_return"] == round(float(w @ ret), 1) and f"{expert['scalar_return']:10.1f}" in recorded

    checked = train_experts("--episodes", "2", "--demos", str(tmp_path), script="check_experts.py")
    report = json.loads((tmp_path / "mo-hopper-check.json").read_text())
    absorbed = demos.obs[..., -1].max(axis=-1) > 0  # the demonstrations' absorbing-state flag
    for expert, w, demo_returns, fell in zip(report["experts"], preferences, demos.rewards.sum(2), absorbed):
        np.testing.assert_allclose(expert["demo_scalar_returns"], demo_returns @ w, atol=0.06)
        assert expert["demo_episodes_fallen"] == int(fell.sum())
        assert abs(expert["gym_scalar_return"] - np.mean(expert["gym_scalar_returns"])) <= 0.1
        assert 0 <= expert["gym_episodes_fallen"] <= 2
        assert f"{expert['gym_episodes_fallen']:2d}/{expert['demo_episodes_fallen']:<2d}" in checked
    # A 24-step hopper falls: its 1,000-step episodes in the absorbing-state env and in MO-Gymnasium end early.
    assert absorbed.all() and all(e["gym_episodes_fallen"] == 2 for e in report["experts"])
    # Held-out episodes: from reset seed 1, the first episode is the one above from seed 1, in a file of its own.
    train_experts("--episodes", "1", "--first-seed", "1", "--demos", str(tmp_path), "--out", str(tmp_path / "held.json"),
                  script="check_experts.py")
    held = json.loads((tmp_path / "held.json").read_text())
    assert held["first_seed"] == 1 and json.loads((tmp_path / "mo-hopper-check.json").read_text()) == report
    for expert, seen in zip(held["experts"], report["experts"]):
        assert expert["gym_scalar_returns"] == seen["gym_scalar_returns"][1:]

"""The `moiq` console script, run as a real subprocess."""

import json
import shutil
import subprocess

import numpy as np
import pytest

MOIQ = shutil.which("moiq")
pytestmark = pytest.mark.skipif(MOIQ is None, reason="the package is not installed (pip install -e .)")


def moiq(*args):
    return subprocess.run([MOIQ, *args], check=False, capture_output=True, text=True, timeout=300)


def test_envs_lists_every_registered_env_with_sizes():
    out = moiq("envs")
    assert out.returncode == 0, out.stderr
    rows = {line.split()[0]: line.split() for line in out.stdout.splitlines()[1:]}
    assert rows["dst"][1:6] == ["2", "4", "discrete", "2", "100"]
    assert rows["cdst"][1:6] == ["2", "2-D", "box", "2", "100"]
    assert {"dst-concave", "dst-mini"} <= set(rows)


def test_optimal_rollout_prints_the_exact_front():
    out = moiq("rollout", "--env", "cdst", "--policy", "optimal")
    assert out.returncode == 0, out.stderr
    assert "treasure at (10, 9): return (   23.70,   -23.00)  on the front" in out.stdout
    assert "treasure at (4, 3): return (   14.00,    -7.00)  dominated" in out.stdout
    assert out.stdout.count("on the front") == 8


def test_random_rollout_prints_vector_returns_consistent_with_lengths():
    out = moiq("rollout", "--env", "dst", "--episodes", "5", "--seed", "3")
    assert out.returncode == 0, out.stderr
    episodes = [line for line in out.stdout.splitlines() if line.strip().startswith("episode")]
    assert len(episodes) == 5
    for line in episodes:
        step_cost = float(line.split("return (")[1].split(")")[0].split(",")[1])
        length = int(line.split("length")[1])
        assert step_cost == -length  # each step costs exactly 1


def test_unknown_env_is_a_clear_error():
    out = moiq("rollout", "--env", "nope")
    assert out.returncode == 2
    assert "unknown env 'nope'; known envs: cdst, dst, dst-concave, dst-mini, mo-ant, mo-halfcheetah, mo-halfcheetah-v4, mo-hopper, mo-walker2d" in out.stderr


def test_demos_records_the_exact_experts_and_describes_the_file(tmp_path):
    out = moiq("demos", "--env", "cdst", "--num-demos", "2", "--out", str(tmp_path / "d.npz"))
    assert out.returncode == 0, out.stderr
    for line in ("[0.9, 0.1]   (   23.70,   -23.00)    19.03", "[0.5, 0.5]   (   15.10,    -7.00)     4.05",
                 "[0.1, 0.9]   (    0.70,    -1.00)    -0.83"):
        assert line in out.stdout
    info = moiq("demos", "--info", str(tmp_path / "d.npz"))
    assert info.returncode == 0 and "3 experts x 2 demonstrations of cdst" in info.stdout


def write_demos_with(path, source, **changes):
    """A demos file like ``source`` with some arrays replaced, written without validation."""
    with np.load(source) as data:
        arrays = {k: data[k] for k in data.files}
    arrays.update(changes)
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def test_bad_demos_files_are_clear_errors(tmp_path):
    good = tmp_path / "good.npz"
    assert moiq("demos", "--env", "cdst", "--num-demos", "1", "--out", str(good)).returncode == 0
    (tmp_path / "corrupt.npz").write_bytes(b"not a zip file")
    with np.load(good) as data:
        obs = data["obs"].copy()
    obs[0, 0, 0] = np.nan
    write_demos_with(tmp_path / "nan.npz", good, obs=obs)
    mini = tmp_path / "mini.npz"
    assert moiq("demos", "--env", "dst-mini", "--preferences", "0.9,0.1", "0.1,0.9", "--num-demos", "1",
                "--out", str(mini)).returncode == 0
    cases = [
        (["--demos", str(tmp_path / "corrupt.npz")], "is corrupt or not a .npz written by moiq_jax"),
        (["--demos", str(tmp_path / "nan.npz")], "obs holds NaN or inf values"),
        (["--demos", str(mini), "--preferences", "0.9,0.1", "0.1,0.9"], "the env needs action_size 2"),
        (["--demos", str(good), "--preferences", "0.8,0.2", "0.5,0.5", "0.1,0.9"],
         "the configured (0.8, 0.2) is not one of them; set --preferences to some of them"),
    ]
    for i, (args, message) in enumerate(cases):
        out = moiq("train", *args, "--run-dir", str(tmp_path / f"run{i}"), "--no-progress")
        assert out.returncode == 2, (args, out.stderr[-2000:])
        assert message in out.stderr, (args, out.stderr[-2000:])


def test_plot_draws_learning_curves_over_seeds(tmp_path):
    import matplotlib.image

    from moiq_jax import Config
    from moiq_jax.plots import read_metrics
    from moiq_jax.runlog import RunLog

    config = Config()
    for seed in range(2):
        run = RunLog(tmp_path / f"seed{seed}", config.replace(seed=seed), total_steps=200, progress=False)
        for step in (100, 200):
            run.log(step, {"eval_scalar_return": np.array([step / 10, -1.0 - seed, 0.5]) + seed})
        run.close()
    metrics = read_metrics(str(tmp_path / "seed1"))
    assert metrics.step_name == "env_steps"
    np.testing.assert_array_equal(metrics.steps, [100, 200])
    assert metrics.labels == ["0.9 0.1", "0.5 0.5", "0.1 0.9"]
    np.testing.assert_array_equal(metrics.values["eval_scalar_return"], [[11.0, -1.0, 1.5], [21.0, -1.0, 1.5]])
    out = moiq("plot", str(tmp_path / "seed0"), str(tmp_path / "seed1"), "--out", str(tmp_path / "plots"))
    assert out.returncode == 0, out.stderr
    image = matplotlib.image.imread(tmp_path / "plots" / "learning_curves.png")
    assert image.shape[0] > 300 and image.shape[1] > 500


def test_sweep_writes_one_run_directory_per_beta_and_seed(tmp_path):
    from moiq_jax.plots import read_metrics

    out = moiq("sweep", "--betas", "0", "5", "--seeds", "1", "--total-steps", "600", "--eval-interval", "300",
               "--hidden-sizes", "8", "8", "--batch-size", "8", "--learning-starts", "50", "--buffer-size", "600",
               "--out", str(tmp_path / "sweep"))
    assert out.returncode == 0, out.stderr
    runs = sorted(p.name for p in (tmp_path / "sweep").iterdir() if (p / "metrics.csv").exists())
    assert runs == ["beta0-seed0", "beta5-seed0"]  # beside the sweep's checkpoints and sweep.json
    for beta in ("0", "5"):
        metrics = read_metrics(str(tmp_path / "sweep" / f"beta{beta}-seed0"))
        np.testing.assert_array_equal(metrics.steps, [300, 600])
        line = next(row for row in out.stdout.splitlines() if row.strip().startswith(f"beta {beta} "))
        final = [float(x) for x in line.split("final (")[1].split(")")[0].split(",")]
        np.testing.assert_allclose(final, metrics.values["eval_scalar_return"][-1], atol=0.006)
    config = (tmp_path / "sweep" / "beta5-seed0" / "config.json").read_text()
    assert '"beta": 5.0' in config


def test_train_admm_reaches_the_optimum_and_logs_every_round(tmp_path):
    from moiq_jax.plots import read_metrics

    out = moiq("train", "--env", "dst-mini", "--algo", "admm", "--preferences", "0.9,0.1", "0.1,0.9",
               "--gamma", "0.999", "--run-dir", str(tmp_path / "admm"))
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines() if "optimum" in line and line.strip().startswith("[")]
    assert len(rows) == 2
    for row in rows:
        assert row[-1] == row[-3]  # scalarised return == optimum, as printed
    metrics = read_metrics(str(tmp_path / "admm"))
    assert metrics.step_name == "round"
    np.testing.assert_array_equal(metrics.steps, np.arange(1, 11))
    np.testing.assert_allclose(metrics.values["return"][-1], [14.12, -0.8], atol=1e-4)


def test_train_sac_experts_then_record_their_demonstrations(tmp_path):
    from moiq_jax.experts import Demonstrations

    run_dir = tmp_path / "experts"
    out = moiq("train", "--algo", "sac", "--total-steps", "800", "--eval-interval", "400", "--learning-starts", "200",
               "--buffer-size", "800", "--hidden-sizes", "8", "8", "--batch-size", "8", "--run-dir", str(run_dir),
               "--adopt-margin", "0.25", "--no-progress")
    assert out.returncode == 0, out.stderr
    assert json.loads((run_dir / "config.json").read_text())["adopt_margin"] == 0.25
    assert "adopted_from" in (run_dir / "metrics.csv").read_text().splitlines()[0]
    assert "[0.1, 0.9]" in out.stdout and f"moiq demos --experts {run_dir / 'experts.npz'}" in out.stdout
    demos = moiq("demos", "--experts", str(run_dir / "experts.npz"), "--num-demos", "2", "--out", str(tmp_path / "d.npz"))
    assert demos.returncode == 0, demos.stderr
    recorded = Demonstrations.load(tmp_path / "d.npz")
    assert recorded.env == "cdst" and recorded.obs.shape[:3] == (3, 2, 100)
    for w, ret in zip(recorded.preferences, recorded.mean_returns()):  # the printed returns are the file's
        assert f"{float(np.dot(w, ret)):8.2f}" in demos.stdout
    missing = moiq("demos", "--experts", str(tmp_path / "none.npz"))
    assert missing.returncode == 2 and "does not exist" in missing.stderr


def test_demos_imports_iq_learn_pickles(tmp_path):
    from moiq_jax.experts import Demonstrations, oracle_demonstrations, save_iq_learn

    source = oracle_demonstrations("cdst", [(0.9, 0.1), (0.1, 0.9)], num_demos=2)
    files = [str(tmp_path / f"expert{e}.pkl") for e in range(2)]
    for e, path in enumerate(files):
        save_iq_learn(source, e, path)
    out = moiq("demos", "--env", "cdst", "--import-iq-learn", *files, "--preferences", "0.9,0.1", "0.1,0.9",
               "--out", str(tmp_path / "d.npz"))
    assert out.returncode == 0, out.stderr
    imported = Demonstrations.load(tmp_path / "d.npz")
    scalar = lambda d: (d.mean_returns() * np.asarray(d.preferences)).sum(-1)
    np.testing.assert_allclose(scalar(imported), scalar(source), atol=1e-4)
    assert "19.03" in out.stdout and "-0.83" in out.stdout
    no_prefs = moiq("demos", "--env", "cdst", "--import-iq-learn", *files)
    assert no_prefs.returncode == 2 and "needs --preferences" in no_prefs.stderr

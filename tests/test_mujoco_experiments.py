"""The MuJoCo experiment scripts (Tables 1-3, Figures 2-4) end to end in their --quick mode on one task: one
MOIQ sweep, kept run by run, serves them all, and each writes its CSV, JSON and PNG with numbers consistent across
them; a run missing from the archive is trained alone, and a kept run of another config is an error."""

import csv
import json
import os
import pathlib
import shutil
import subprocess
import sys

import jax
import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def run(script, tmp_path, *extra, ok=True):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / script), "--quick", "--envs", "mo-halfcheetah",
                          "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "mujoco_quick" / script[:-3]),
                          *extra], capture_output=True, text=True, timeout=900, env=env, check=False)
    assert (out.returncode == 0) == ok, out.stderr[-3000:]
    return out.stdout if ok else out.stderr


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("paper")
    scripts = ("table1.py", "table2.py", "table3.py", "figure3.py", "figure2.py", "figure4.py")
    return tmp_path, {script: run(script, tmp_path) for script in scripts}


def test_one_sweep_serves_every_script(outputs):
    tmp_path, printed = outputs
    for beta in ("5", "0", "0.5"):  # one checkpointed sweep per beta
        assert f"trained moiq (quick protocol) beta{beta}-seed0, beta{beta}-seed1 (" in printed["table1.py"]
        assert (tmp_path / "cache" / "quick" / f"mo-halfcheetah-moiq-beta{beta}-seeds0-1" / "sweep.json").exists()
    assert all("trained" not in printed[s] for s in ("table2.py", "table3.py", "figure3.py"))  # read from the archive
    assert "trained gail (quick protocol) seed0, seed1 (" in printed["figure2.py"]
    assert printed["figure2.py"].count("trained") == 1  # MOIQ's curves are table1.py's runs
    for sweep in ("moiq-1demo (quick protocol) beta5-seed0", "moiq-1demo (quick protocol) beta0.5-seed0",
                  "iq_learn-1demo (quick protocol) seed0"):
        assert f"trained {sweep}" in printed["figure4.py"]
    kept = tmp_path / "cache" / "quick" / "runs" / "mo-halfcheetah-moiq"
    assert sorted(p.name for p in kept.iterdir()) == [f"beta{b}-seed{s}" for b in ("0", "0.5", "5") for s in (0, 1)]
    for run in kept.iterdir():  # small files only, with the demonstrations' digest
        assert sorted(p.name for p in run.iterdir()) == ["best_actor_per_expert.npz", "best_params.npz", "demos.sha256",
                                                         "history.npz", "result.json"]
        assert sum(p.stat().st_size for p in run.iterdir()) < 200_000


def test_tables_and_figure_files(outputs):
    tmp_path, _ = outputs
    for name in ("table1", "table2", "table3", "figure3", "figure2", "figure4"):
        for ext in ("csv", "json", "png") if name not in ("figure2", "figure4") else ("json", "png"):
            assert (tmp_path / "mujoco_quick" / name / f"{name}.{ext}").stat().st_size > 0
        record = json.loads((tmp_path / "mujoco_quick" / name / f"{name}.json").read_text())
        assert record["protocol"] == "quick"
        made = record["provenance"]  # the command that wrote it, at which commit
        assert made["command"].startswith(f"python {ROOT / 'experiments' / name}.py --quick --envs mo-halfcheetah")
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                                check=False)
        assert made["commit"] == (commit.stdout.strip() if commit.returncode == 0 else None)
        assert made["wall_seconds"] > 0 and made["machine"].endswith(f"on {jax.devices()[0].platform}")
    with open(tmp_path / "mujoco_quick" / "table1" / "table1.csv") as f:
        rows = list(csv.DictReader(f))
    assert [(r["beta"], r["preference"]) for r in rows] == [(beta, w) for beta in ("5.0", "0.5")
                                                            for w in ("[0.9, 0.1]", "[0.5, 0.5]", "[0.1, 0.9]")]
    assert {r["protocol"] for r in rows} == {"quick"}
    for r in rows:  # the ratio is the mean return over the committed experts' return
        assert float(r["ratio_to_expert"]) == pytest.approx(float(r["moiq_mean"]) / float(r["expert"]), rel=0.02, abs=2e-3)
        per_seed = json.loads(r["moiq_per_seed"])  # one best model per seed, their mean and spread the columns'
        assert len(per_seed) == 2
        assert (np.mean(per_seed), np.std(per_seed)) == pytest.approx((float(r["moiq_mean"]), float(r["moiq_std"])), abs=0.02)
    kept = tmp_path / "cache" / "quick" / "runs" / "mo-halfcheetah-moiq"
    for beta, beta_rows in (("5", rows[:3]), ("0.5", rows[3:])):  # own best and last 20%, from the kept evaluations
        history = [np.load(kept / f"beta{beta}-seed{seed}" / "history.npz") for seed in (0, 1)]
        evaluations = np.stack([h["eval_scalar_return"] for h in history])  # [seeds, evals, E]
        late = history[0]["env_steps"] > 0.8 * history[0]["env_steps"][-1]
        assert [float(r["own_best"]) for r in beta_rows] == pytest.approx(evaluations.max(1).mean(0), abs=0.01)
        assert [float(r["last_window"]) for r in beta_rows] == pytest.approx(evaluations[:, late].mean((0, 1)), abs=0.01)
        for seed, h in zip((0, 1), history):  # each preference's best actor was kept at its best evaluation
            record = json.loads((kept / f"beta{beta}-seed{seed}" / "result.json").read_text())
            assert record["best_return_per_expert"] == pytest.approx(h["eval_scalar_return"].max(0), abs=1e-4)
    table1 = json.loads((tmp_path / "mujoco_quick" / "table1" / "table1.json").read_text())
    for r in table1["rows"]:  # the per-preference reading beside the one-model one
        assert r["each_best_ratio_to_expert"] == pytest.approx(r["each_best_mean"] / r["expert"], rel=0.02, abs=2e-3)
    assert table1["settings_at_90_percent_with_each_preferences_best_actor"] == {
        f"beta={b}": sum(r["each_best_near_expert"] for r in table1["rows"] if r["beta"] == float(b)) for b in ("5", "0.5")}
    table2 = json.loads((tmp_path / "mujoco_quick" / "table2" / "table2.json").read_text())
    assert table2["settings_where_beta5_beats_beta0"] == sum(r["beta5"] > r["beta0"] for r in table2["rows"])
    for beta in ("0", "5", "0.5"):  # the last-20% column, recomputed from the kept runs' evaluations
        history = [np.load(kept / f"beta{beta}-seed{seed}" / "history.npz") for seed in (0, 1)]
        steps = history[0]["env_steps"]
        last = np.stack([h["eval_scalar_return"][steps > 0.8 * steps[-1]] for h in history])  # [seeds, evals, E]
        assert [r[f"beta{beta}_last"] for r in table2["rows"]] == pytest.approx(last.mean((0, 1)), abs=0.01)
    assert table2["first_evaluation_weight"] == pytest.approx(0.9 ** (len(steps) - 1), abs=1e-6)
    table3 = json.loads((tmp_path / "mujoco_quick" / "table3" / "table3.json").read_text())
    assert all(-1 <= r["correlation"] <= 1 and len(r["per_objective"]) == 2 for r in table3["rows"])
    for r in table3["rows"]:  # the best models' own episodes: 3 per preference in --quick, per seed
        assert -1 <= r["episode_correlation"] <= 1 and r["episodes"] == 3 and len(r["episode_per_seed"]) == 2
        assert r["episode_correlation"] == pytest.approx(np.mean(r["episode_per_seed"]), abs=1e-3)
    assert table3["settings_at_least_the_papers_across_episodes"] == {
        f"beta={b}": sum(r["episode_correlation"] >= r["paper"] for r in table3["rows"] if r["beta"] == float(b))
        for b in ("5", "0.5")}
    figure3 = json.loads((tmp_path / "mujoco_quick" / "figure3" / "figure3.json").read_text())["mo-halfcheetah"]
    assert [len(v) for v in figure3["hypervolume_per_seed"].values()] == [2, 2] and figure3["expert_hypervolume"] > 0
    for name, baseline in (("figure2", "GAIL"), ("figure4", "IQ-Learn")):  # final EWMA return per method
        record = json.loads((tmp_path / "mujoco_quick" / name / f"{name}.json").read_text())
        for final in (record["first_evaluation_return"], record["final_ewma_return"], record["final_last_window_return"]):
            assert list(final["mo-halfcheetah"]) == ["[0.9, 0.1]", "[0.5, 0.5]", "[0.1, 0.9]"]
            assert all(list(m) == ["MOIQ beta=5", "MOIQ beta=0.5", baseline] for m in final["mo-halfcheetah"].values())
    table2_last = {tuple(json.loads(w)): r for w, r in
                   json.loads((tmp_path / "mujoco_quick" / "figure2" / "figure2.json").read_text())
                   ["final_last_window_return"]["mo-halfcheetah"].items()}
    for r in table2["rows"]:  # Figure 2's MOIQ runs are Table 2's
        assert table2_last[tuple(r["preference"])]["MOIQ beta=5"] == pytest.approx(r["beta5_last"], abs=0.01)
    first = json.loads((tmp_path / "mujoco_quick" / "figure2" / "figure2.json").read_text())["first_evaluation_return"]
    history = [np.load(kept / f"beta5-seed{seed}" / "history.npz") for seed in (0, 1)]  # where the runs start from
    assert [m["MOIQ beta=5"] for m in first["mo-halfcheetah"].values()] == pytest.approx(
        np.mean([h["eval_scalar_return"][0] for h in history], 0), abs=0.01)


def test_paper_summary_reads_every_table(outputs):
    """paper_summary.py assembles Tables 1-3 from the committed cdst results and the MuJoCo outputs, with the
    paper's numbers and per row whether its claim holds, judged from the numbers in that row."""
    tmp_path, _ = outputs
    shutil.copytree(ROOT / "results" / "cdst_moiq", tmp_path / "cdst_moiq")
    task = tmp_path / "mujoco_quick" / "mo-halfcheetah" / "table1"  # a per-task run supersedes the all-task one
    task.mkdir(parents=True, exist_ok=True)
    record = json.loads((tmp_path / "mujoco_quick" / "table1" / "table1.json").read_text())
    record["rows"][0]["moiq_mean"] = 1234.5
    (task / "table1.json").write_text(json.dumps(record))
    more = {**record, "rows": [{**record["rows"][1], "moiq_mean": 777.0, "seeds": 5},  # more seeds: replaces row 1
                               {**record["rows"][2], "moiq_mean": -1.0}]}  # as many seeds: row 2 stays
    (task.parent / "table1_more_seeds").mkdir()
    (task.parent / "table1_more_seeds" / "table1.json").write_text(json.dumps(more))
    rerun = {**record, "rows": [{**r, "moiq_mean": 100.0 + i} for i, r in enumerate(record["rows"][3:])]}
    for name, content in (("table1", rerun),  # a second set of runs: its rows beside the main ones, counted apart
                          ("table3", json.loads((tmp_path / "mujoco_quick" / "table3" / "table3.json").read_text()))):
        (task.parent / f"{name}_rerun").mkdir()
        (task.parent / f"{name}_rerun" / f"{name}.json").write_text(json.dumps(content))
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "paper_summary.py"), "--results", str(tmp_path),
                          "--out", str(tmp_path / "paper")], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    with open(tmp_path / "paper" / "table1.csv") as f:
        table1 = list(csv.DictReader(f))
    assert [(r["env"], r["protocol"]) for r in table1] == ([("cdst", "cdst_moiq")] * 6 + [("mo-halfcheetah", "quick")] * 6
                                                           + [("mo-halfcheetah", "quick rerun")] * 3)
    assert [(r["beta"], float(r["moiq"])) for r in table1[12:]] == [(str(r["beta"]), 100.0 + i)
                                                                    for i, r in enumerate(record["rows"][3:])]
    cdst = {(r["preference"], r["beta"]): r for r in table1 if r["env"] == "cdst"}
    assert float(cdst[("[0.9, 0.1]", "0.5")]["moiq"]) == 19.03 and cdst[("[0.9, 0.1]", "0.5")]["claim_holds"] == "True"
    assert float(cdst[("[0.1, 0.9]", "5.0")]["moiq"]) < -0.83 and float(cdst[("[0.1, 0.9]", "5.0")]["paper_moiq"]) == -1.73
    near = lambda value, expert: str(float(value) >= float(expert) - 0.1 * abs(float(expert)))
    for r in table1:  # within 10% of the expert, judged on the difference (negative returns included)
        assert r["claim_holds"] == near(r["moiq"], r["expert"])
    each = {(str(r["preference"]), float(r["beta"])): r["each_best_mean"] for r in record["rows"]}  # own best actors
    for r in table1[6:12]:
        assert float(r["each_best"]) == pytest.approx(each[(r["preference"], float(r["beta"]))], abs=0.01)
        assert r["claim_holds_each_best"] == near(r["each_best"], r["expert"])
    assert {r["each_best"] for r in table1[:6]} == {""}  # continuous DST's results did not keep them
    with open(tmp_path / "paper" / "table2.csv") as f:  # each row says over how many seeds it was averaged
        assert [(r["env"], r["seeds"]) for r in csv.DictReader(f)] == [("cdst", "5")] * 3 + [("mo-halfcheetah", "2")] * 3
    with open(tmp_path / "paper" / "table3.csv") as f:
        table3 = list(csv.DictReader(f))
        assert [r["protocol"] for r in table3] == ["quick"] * 6 + ["quick rerun"] * 6
        for r in table3:  # each reading judged on its own column
            assert r["seeds"] == "2"
            assert r["claim_holds"] == str(float(r["correlation"]) >= float(r["paper"]))
            assert r["claim_holds_episodes"] == str(float(r["episode_correlation"]) >= float(r["paper"]))
    assert float(table1[6]["moiq"]) == 1234.5
    assert (float(table1[7]["moiq"]), table1[7]["seeds"]) == (777.0, "5")
    assert (float(table1[8]["moiq"]), table1[8]["seeds"]) == (record["rows"][2]["moiq_mean"], "2")
    with open(tmp_path / "paper" / "figure3.csv") as f:
        figure3 = list(csv.DictReader(f))
    volumes = json.loads((tmp_path / "mujoco_quick" / "figure3" / "figure3.json").read_text())["mo-halfcheetah"]
    assert [r["beta"] for r in figure3] == ["5.0", "0.5"]
    for r in figure3:
        per_seed = volumes["hypervolume_per_seed"][f"beta={float(r['beta']):g}"]
        assert float(r["hypervolume"]) == pytest.approx(sum(per_seed) / 2, abs=0.01)
    for name, baseline in (("figure2", "gail"), ("figure4", "iq-learn")):
        with open(tmp_path / "paper" / f"{name}.csv") as f:
            rows = list(csv.DictReader(f))
        assert [r["preference"] for r in rows] == ["[0.9, 0.1]", "[0.5, 0.5]", "[0.1, 0.9]"]
        for r in rows:
            for end in ("", "_last"):
                moiq, other = float(r[f"moiq beta=5{end}"]), float(r[f"{baseline}{end}"])
                assert r[f"claim_holds{end}"] == str(moiq >= other - 0.1 * abs(other))
    summary = (tmp_path / "paper" / "summary.md").read_text()
    assert all(f"## {name}" in summary for name in ("Table 2", "Figure 2", "Figure 3", "Figure 4"))
    held = sum(r["claim_holds"] == "True" for r in table1[12:])
    assert f"| quick rerun | 0.5 | {held} of 3 | mo-halfcheetah |" in summary


def test_paper_summary_tells_rows_made_from_replaced_demonstrations():
    """A row made from demonstrations replaced since is marked and left out of the claim count: by git where the
    output names the commit that wrote it, else by its Table 1 expert returns against the committed demos'."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import paper_mujoco as paper
    import paper_summary

    env = "mo-hopper"
    preferences = paper.moiq_config(env).preferences
    experts = paper.expert_returns(env)
    rows = [{"env": env, "preference": list(w), "expert": round(float(experts[e] @ np.asarray(w)), 2)}
            for e, w in enumerate(preferences)]
    assert paper_summary.demos_of(env, {"rows": rows}) == "committed"
    moved = [{**r, "expert": r["expert"] + 5.0} if e == 1 else r for e, r in enumerate(rows)]
    assert paper_summary.demos_of(env, {"rows": moved}) == "replaced"
    assert paper_summary.demos_of(env, {"rows": []}) is None
    git = lambda *a: subprocess.run(["git", "-C", str(ROOT), *a], capture_output=True, text=True, check=False)
    last_change = git("log", "-1", "--format=%H", "--", f"experiments/demos/{env}.npz").stdout.strip()
    if last_change:  # a git checkout: the commit before the demonstrations' last change made them "replaced"
        before = git("rev-parse", f"{last_change}^").stdout.strip()
        assert paper_summary.demos_of(env, {"provenance": {"commit": before}, "rows": rows}) == "replaced"
        assert paper_summary.demos_of(env, {"provenance": {"commit": last_change}, "rows": moved}) == "committed"
    table = [{"claim_holds": True, "demos": "replaced"}, {"claim_holds": True, "demos": "committed"},
             {"claim_holds": False, "demos": None}]
    assert paper_summary.markdown("T", table, ["demos"])[-2] == (
        "The paper's claim holds in 1 of 2 rows checked (not counted: 1 rows made from demonstrations since replaced).")
    table = [{**r, "env": env, "protocol": protocol, "beta": 0.5}
             for r, env, protocol in zip(table, ("mo-ant", "mo-hopper", "mo-ant"), ("p", "p", "q"))]
    assert paper_summary.claims_by_protocol(table)[2:4] == ["| p | 0.5 | 1 of 1 | mo-hopper |",
                                                            "| q | 0.5 | 0 of 1 | mo-ant |"]


def test_imitation_gap_reads_the_kept_runs(outputs):
    """imitation_gap.py measures each kept run's best model against its experts without training: the return
    ratio is the model's own return over the committed demonstrations', the shares and lengths are in range."""
    tmp_path, _ = outputs
    printed = run("imitation_gap.py", tmp_path, "--no-train", "--betas", "0.5")
    assert "trained" not in printed
    record = json.loads((tmp_path / "mujoco_quick" / "imitation_gap" / "imitation_gap.json").read_text())
    sys.path.insert(0, str(ROOT / "experiments"))
    import paper_mujoco as paper

    experts = paper.expert_returns("mo-halfcheetah")
    rows = record["rows"]
    assert [(r["seed"], r["preference"]) for r in rows] == [(s, list(w)) for s in (0, 1)
                                                            for w in ((0.9, 0.1), (0.5, 0.5), (0.1, 0.9))]
    for e, r in enumerate(rows):
        assert r["expert_return"] == pytest.approx(float(experts[e % 3] @ np.asarray(r["preference"])), abs=0.1)
        if abs(r["expert_return"]) > 10:  # the standing expert's -0.24 is rounded to -0.2 in the row
            assert r["ratio"] == pytest.approx(r["own_return"] / r["expert_return"], rel=2e-3, abs=2e-3)
        assert 0 <= r["on_demo_share"] <= 1 and 0 < r["live_steps"] <= 1000 and r["action_gap"] > 0


def test_demo_spread_is_the_demonstrations_own():
    """A state is within the demonstrations' spread up to their own leave-one-episode-out distances: about 95% of
    the states of one more demonstration are, few of those of a policy beside them are; the nearest distances
    are the brute-force ones."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import imitation_gap

    rng = np.random.default_rng(0)
    points, reference = rng.normal(size=(300, 4)), rng.normal(size=(500, 4))
    brute = np.sqrt(((points[:, None] - reference[None]) ** 2).sum(-1))
    np.testing.assert_allclose(imitation_gap.nearest_distances(points, reference, chunk=64), brute.min(1), rtol=1e-9)
    groups, point_groups = np.arange(500) % 5, np.arange(300) % 5
    brute[point_groups[:, None] == groups[None]] = np.inf
    np.testing.assert_allclose(imitation_gap.nearest_distances(points, reference, groups, point_groups, chunk=64),
                               brute.min(1), rtol=1e-9)
    scale = np.asarray([1.0, 10.0, 0.1, 1.0, 1.0])
    episode = lambda n, shift=0.0: np.concatenate([(rng.normal(size=(n, 200, 5)) + shift) * scale,
                                                   np.zeros((n, 200, 1))], -1)  # live states: absorbing flag 0
    within = imitation_gap.demo_spread(episode(10))
    another = within(episode(1).reshape(-1, 6)).mean()  # one more demonstration: as near as they are to each other
    assert 0.85 <= another <= 1.0
    assert within(episode(1, shift=2.0).reshape(-1, 6)).mean() < 0.3  # a policy beside the demonstrations


def test_a_missing_run_is_trained_alone_and_a_foreign_one_refused(outputs):
    tmp_path, _ = outputs
    archive = tmp_path / "archive"
    shutil.copytree(tmp_path / "cache" / "quick" / "runs", archive)
    shutil.rmtree(archive / "mo-halfcheetah-moiq" / "beta0-seed1")
    error = run("table2.py", tmp_path, "--archive", str(archive), "--no-train", ok=False)
    assert "mo-halfcheetah-moiq does not hold the runs beta0-seed1 (--no-train)" in error
    run("table1.py", tmp_path, "--archive", str(archive), "--no-train", "--betas", "0.5", "--out", str(tmp_path / "b"))
    run("table3.py", tmp_path, "--archive", str(archive), "--no-train", "--betas", "0.5", "--out", str(tmp_path / "b"))
    run("figure3.py", tmp_path, "--archive", str(archive), "--no-train", "--betas", "0.5", "--out", str(tmp_path / "b"))
    for table in ("table1", "table3"):  # beta 0.5's rows, from its runs alone
        with open(tmp_path / "b" / f"{table}.csv") as f:
            assert [r["beta"] for r in csv.DictReader(f)] == ["0.5"] * 3, table
    with open(tmp_path / "b" / "figure3.csv") as f:
        assert {r["beta"] for r in csv.DictReader(f)} == {"0.5"}
    assert list(json.loads((tmp_path / "b" / "figure3.json").read_text())["mo-halfcheetah"]["hypervolume_per_seed"]) \
        == ["beta=0.5"]
    printed = run("table2.py", tmp_path, "--archive", str(archive))
    assert "trained moiq (quick protocol) beta0-seed1 (" in printed and printed.count("trained moiq") == 1
    assert (archive / "mo-halfcheetah-moiq" / "beta0-seed1" / "result.json").exists()
    record = archive / "mo-halfcheetah-moiq" / "beta5-seed0" / "result.json"
    saved = json.loads(record.read_text())
    record.write_text(json.dumps({**saved, "config": {**saved["config"], "critic_lr": 1e-3}}))
    error = run("table2.py", tmp_path, "--archive", str(archive), ok=False)
    assert "beta5-seed0 holds a run of another config (critic_lr); move it away to retrain" in error
    record.write_text(json.dumps(saved))
    (record.parent / "demos.sha256").write_text("0" * 64)
    error = run("table2.py", tmp_path, "--archive", str(archive), ok=False)
    assert "beta5-seed0 holds a run trained on other demonstrations" in error


def test_table1_reads_each_preferences_best_actor_for_the_betas_whose_runs_kept_it(outputs):
    """Runs saved before each preference's best actor was kept, beside newer ones of another beta: the
    per-preference reading is still given for the beta whose runs all kept it, and nothing else changes."""
    tmp_path, _ = outputs
    archive = tmp_path / "archive_mixed"
    shutil.copytree(tmp_path / "cache" / "quick" / "runs", archive)
    for seed in (0, 1):  # beta 5's runs as saved before they kept it
        folder = archive / "mo-halfcheetah-moiq" / f"beta5-seed{seed}"
        (folder / "best_actor_per_expert.npz").unlink()
        record = json.loads((folder / "result.json").read_text())
        (folder / "result.json").write_text(json.dumps({**record, "best_return_per_expert": None}))
    run("table1.py", tmp_path, "--archive", str(archive), "--no-train", "--out", str(tmp_path / "mixed"))
    mixed = json.loads((tmp_path / "mixed" / "table1.json").read_text())
    full = json.loads((tmp_path / "mujoco_quick" / "table1" / "table1.json").read_text())
    assert [r["beta"] for r in mixed["rows"]] == [r["beta"] for r in full["rows"]] == [5.0] * 3 + [0.5] * 3
    for r, f in zip(mixed["rows"], full["rows"]):
        assert r["moiq_mean"] == pytest.approx(f["moiq_mean"], abs=0.01)  # the one model's reading as before
        expected = None if r["beta"] == 5.0 else pytest.approx(f["each_best_mean"], abs=0.01)
        assert r["each_best_mean"] == expected
    assert list(mixed["settings_at_90_percent_with_each_preferences_best_actor"]) == ["beta=0.5"]


def test_run_summary_reads_what_the_runs_recorded(outputs):
    """run_summary.py: per run and preference, the model chosen on the mean (the trainer's best), each
    preference's own best, the last 20% and the penalty's peak, from the kept runs' metrics."""
    tmp_path, _ = outputs
    archive = tmp_path / "cache" / "quick" / "runs"
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "run_summary.py"), str(archive), "--csv",
                          str(tmp_path / "runs.csv")], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    with open(tmp_path / "runs.csv") as f:
        rows = list(csv.DictReader(f))
    assert sorted({r["run"] for r in rows}) == [f"beta{b}-seed{s}" for b in ("0", "0.5", "5") for s in (0, 1)]
    for name in ("beta5-seed1", "beta0.5-seed0"):
        run = [r for r in rows if r["run"] == name]
        history = np.load(archive / "mo-halfcheetah-moiq" / name / "history.npz")
        record = json.loads((archive / "mo-halfcheetah-moiq" / name / "result.json").read_text())
        returns, steps = history["eval_scalar_return"], history["env_steps"]
        chosen = [float(r["chosen"]) for r in run]
        assert np.mean(chosen) == pytest.approx(record["best_return"], abs=0.1)  # the trainer's best model
        assert int(run[0]["chosen_step"]) == steps[np.argmax(returns.mean(1))]
        assert [float(r["own_best"]) for r in run] == pytest.approx(returns.max(0), abs=0.06)
        assert [float(r["last20"]) for r in run] == pytest.approx(returns[steps > 0.8 * steps[-1]].mean(0), abs=0.06)
        assert float(run[0]["penalty_peak"]) == pytest.approx(history["penalty"].max(), abs=1e-3)
    assert "mo-halfcheetah  beta5-seed1" in out.stdout

    from moiq_jax.archive import load_result
    from moiq_jax.cli import _write_history

    kept = load_result(archive / "mo-halfcheetah-moiq" / "beta0.5-seed0")  # the same run as `moiq train` logs it
    run_dir = tmp_path / "logged" / "pilot"
    _write_history(str(run_dir), kept.config, kept, np.asarray(kept.history["env_steps"]))
    out = subprocess.run([sys.executable, str(ROOT / "experiments" / "run_summary.py"), "--run-dirs", str(run_dir),
                          "--csv", str(tmp_path / "logged.csv")], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    with open(tmp_path / "logged.csv") as f:
        logged = list(csv.DictReader(f))
    same = lambda row: {k: v for k, v in row.items() if k not in ("run", "seconds")}
    assert [same(r) for r in logged] == [same(r) for r in rows if r["run"] == "beta0.5-seed0"]
    assert {(r["run"], r["seconds"]) for r in logged} == {("pilot", "")}  # `moiq train` does not log its wall time


@pytest.mark.parametrize("protocol",
                         ["paper", "cpu", "cpu_recipe", "cpu_recipe_online_penalty", "cpu_recipe_fast_actor",
                          "cpu_recipe_mid_actor", "cpu_recipe_long"])
def test_each_protocol_configures_what_its_record_names(protocol):
    """Every protocol's MOIQ config holds each setting its output files name, and GAIL under it keeps the paper's
    Table 4 generator (twin critics, target critic) whatever critic recipe MOIQ uses."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import paper_mujoco as paper

    for env in paper.TASKS:
        moiq = paper.moiq_config(env, protocol).validate().to_dict()
        gail = paper.gail_config(env, protocol).validate().to_dict()
        for name, value in paper.protocol_settings(protocol).items():
            assert moiq[name] == value, (env, name)
        assert (gail["num_critics"], gail["use_target"], gail["actor_lr"], gail["tau"]) == (2, True, 3e-4, 0.05)


def test_each_cpu_recipe_protocol_differs_from_its_base_in_what_its_name_says():
    """cpu_recipe is IQ-Learn's MuJoCo critic recipe for 300K steps; each later protocol changes one thing of
    cpu_recipe_online_penalty (the penalty's online critic, the actor rate, the step count) and nothing else."""
    sys.path.insert(0, str(ROOT / "experiments"))
    import paper_mujoco as paper

    recipe = paper.moiq_config("mo-hopper", "cpu_recipe").to_dict()
    assert (recipe["num_critics"], recipe["use_target"], recipe["regulariser"], recipe["total_steps"]) == (
        1, True, "both", 300_000)
    online_penalty = paper.moiq_config("mo-hopper", "cpu_recipe_online_penalty").to_dict()
    assert {k for k in recipe if online_penalty[k] != recipe[k]} == {"penalty_online"}  # the one difference
    assert (online_penalty["penalty_online"], recipe["penalty_online"]) == (True, False)

    def changes(protocol):
        config = paper.moiq_config("mo-hopper", protocol).to_dict()
        return {k: v for k, v in config.items() if v != online_penalty[k]}

    assert changes("cpu_recipe_fast_actor") == {"actor_lr": 3e-4}
    assert changes("cpu_recipe_mid_actor") == {"actor_lr": 1e-4}
    assert changes("cpu_recipe_long") == {"total_steps": 500_000, "buffer_size": 500_000}


def test_figure2_shares_gail_runs_only_between_protocols_that_configure_gail_alike():
    """GAIL has no consensus penalty: under cpu_recipe_online_penalty it is cpu_recipe's GAIL, whose kept runs
    figure2.py may then read (``--gail-protocol``); a protocol with other GAIL settings is refused, naming them."""
    import argparse
    sys.path.insert(0, str(ROOT / "experiments"))
    import figure2
    import paper_mujoco as paper

    args = argparse.Namespace(protocol="cpu_recipe_online_penalty", gail_protocol="cpu_recipe", quick=False,
                              archive="elsewhere", seeds=1)
    for env in paper.TASKS:
        assert paper.gail_config(env, "cpu_recipe") == paper.gail_config(env, "cpu_recipe_online_penalty") == \
            paper.gail_config(env, "cpu_recipe_fast_actor")
        shared = figure2.gail_args(args, env)
        assert (shared.protocol, shared.archive, args.protocol) == ("cpu_recipe", None, "cpu_recipe_online_penalty")
        assert paper.archive_of(shared) == pathlib.Path("results/mujoco_cpu_recipe/runs")
    with pytest.raises(SystemExit, match="total_steps"):
        figure2.gail_args(argparse.Namespace(**{**vars(args), "protocol": "cpu"}), "mo-hopper")
    own = argparse.Namespace(**{**vars(args), "gail_protocol": None})
    assert figure2.gail_args(own, "mo-hopper") is own  # without the flag GAIL's runs are the protocol's own


def test_train_runs_trains_any_scripts_sweep_in_parts(outputs):
    """train_runs.py trains the runs of any script's sweep (here Figure 4's IQ-Learn, pinned to one core) that the
    archive lacks, which the script then reads without training; the script's --no-train error names that
    command; a beta for a sweep without one, and a core the process may not use, are refused."""
    tmp_path, _ = outputs
    archive = tmp_path / "archive-parts"
    shutil.copytree(tmp_path / "cache" / "quick" / "runs", archive)
    shutil.rmtree(archive / "mo-halfcheetah-iq_learn-1demo" / "seed1")
    figure4 = ("figure4.py", tmp_path, "--archive", str(archive), "--no-train", "--out", str(tmp_path / "f4"))
    error = run(*figure4, ok=False)
    assert ("mo-halfcheetah-iq_learn-1demo does not hold the runs seed1 (--no-train); `PYTHONPATH=. python "
            "experiments/train_runs.py --env mo-halfcheetah --sweep iq_learn-1demo --quick --seed-list ...`") in error

    def train_runs(*extra):
        return subprocess.run([sys.executable, str(ROOT / "experiments" / "train_runs.py"), "--quick", "--env",
                               "mo-halfcheetah", "--cache", str(tmp_path / "cache"), "--archive", str(archive), *extra],
                              capture_output=True, text=True, timeout=900, env={**os.environ, "PYTHONPATH": str(ROOT)},
                              check=False)

    refused = train_runs("--sweep", "gail", "--betas", "5")
    assert refused.returncode == 2 and "the gail sweep has no beta" in refused.stderr
    refused = train_runs("--cpu-cores", "100000")
    assert refused.returncode == 2 and "cores [100000] are not all among the cores this process may use" in refused.stderr
    trained = train_runs("--sweep", "iq_learn-1demo", "--seed-list", "0", "1", "--cpu-cores", "0")
    assert trained.returncode == 0, trained.stderr[-3000:]
    assert "trained iq_learn-1demo (quick protocol) seed1 (" in trained.stdout and "1 runs trained" in trained.stdout
    record = json.loads((archive / "mo-halfcheetah-iq_learn-1demo" / "seed1" / "result.json").read_text())
    assert (record["config"]["algo"], record["config"]["num_demos"], record["config"]["seed"]) == ("iq_learn", 1, 1)
    run(*figure4)
    final = json.loads((tmp_path / "f4" / "figure4.json").read_text())["final_ewma_return"]["mo-halfcheetah"]
    assert len(final) == 3 and all("IQ-Learn" in by_method for by_method in final.values())
